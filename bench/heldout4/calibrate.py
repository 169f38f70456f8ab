"""``python -m bench.heldout4.calibrate``: how often each controller of the fourth set of
held-out worlds fails alone (no shield is built), per world and seed, in the episodes before
and after the warm-up that a shielded evaluation would use, as a Markdown table: the same
table as :mod:`bench.heldout.calibrate` prints for the first set.

Example::

    python -m bench.heldout4.calibrate --seeds 6000-6008 --episodes 250 --warmup 50
"""

from __future__ import annotations

from bench.heldout.calibrate import calibrate
from bench.heldout4 import NAMES, world


def main() -> None:
    calibrate(NAMES, world, __doc__.splitlines()[0])


if __name__ == "__main__":
    main()
