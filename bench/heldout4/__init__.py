"""A fourth set of held-out worlds for issue #68, one of each kind it names, of other physics
than the first three sets (``bench/heldout``, ``bench/heldout2``, ``bench/heldout3``) and than
the tuning worlds: a slow failure on either side of one action
(:mod:`~bench.heldout4.furnace`), an unstable system whose saving direction depends on the
state (:mod:`~bench.heldout4.monorail`), and a runaway and an extinction on either side of an
unstable operating point (:mod:`~bench.heldout4.arc`).

Each module gives the environment, its fixed controller and two
:class:`~bench.worlds.harness.World` records that :func:`bench.worlds.harness.run` runs:
``WORLD``, configured as a new user would with a direction per criterion, and
``WORLD_BOUNDED``, the same with a bound per failure. The controllers were calibrated alone;
README.md beside this module gives the rule that keeps these worlds held out.
"""

from __future__ import annotations

from bench.heldout import select
from bench.worlds.harness import World

NAMES = ("furnace", "monorail", "arc")


def world(name: str, bounded: bool = False) -> World:
    """The held-out world ``name`` of the fourth set, with a bound per failure when
    ``bounded``."""
    return select(__name__, NAMES, name, bounded)
