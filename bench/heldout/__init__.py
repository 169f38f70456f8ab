"""Held-out worlds for issue #68, one of each kind it names: a slow failure on either side of
one action (:mod:`~bench.heldout.greenhouse`), an unstable system whose saving direction
depends on the state (:mod:`~bench.heldout.bicycle`), and a runaway and an extinction on either
side of an unstable operating point (:mod:`~bench.heldout.pile`).

Each module gives the environment, its fixed controller and two
:class:`~bench.worlds.harness.World` records that :func:`bench.worlds.harness.run` runs:
``WORLD``, configured as a new user would with a direction per criterion, and
``WORLD_BOUNDED``, the same with a bound per failure. The controllers were calibrated alone;
README.md beside this module gives the rule that keeps these worlds held out.
"""

from __future__ import annotations

import importlib

from bench.worlds.harness import World

NAMES = ("greenhouse", "bicycle", "pile")


def world(name: str, bounded: bool = False) -> World:
    """The held-out world ``name``, with a bound per failure when ``bounded``."""
    return select(__name__, NAMES, name, bounded)


def select(package: str, names: tuple[str, ...], name: str, bounded: bool) -> World:
    """The world ``name`` of a set of held-out worlds (``package``, whose modules ``names``
    each give ``WORLD`` and ``WORLD_BOUNDED``), with a bound per failure when ``bounded``."""
    if name not in names:
        raise ValueError(f"no held-out world {name!r} in {package}; there are {', '.join(names)}")
    module = importlib.import_module(f"{package}.{name}")
    found: World = module.WORLD_BOUNDED if bounded else module.WORLD
    return found
