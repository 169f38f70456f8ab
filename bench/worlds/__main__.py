"""``python -m bench.worlds``: failures per 100 episodes after the warm-up, with and without
the shield, on the held-out worlds (none of them was used to choose a default) or, by name or
all at once as ``tuning``, on the tuning worlds (:mod:`bench.worlds.tuning`).

Example::

    python -m bench.worlds --seeds 1000,1001,1002 --episodes 150 --out results/worlds/risk.json
    python -m bench.worlds --overrides '{"reviser": {"method": "paper"}}'
    python -m bench.worlds --worlds tuning --seeds 0,1
    python -m bench.worlds --worlds highway,highway_too_slow --seeds 0 --episodes 60
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import importlib.util
import json
import platform
from pathlib import Path

from app.core import ShieldConfig, compiled
from bench.worlds.harness import World, compare, summary_line

WORLDS = ("braking_lead", "pendulum", "wall", "lane")


def world_named(name: str) -> World:
    """A world of #44 by module name, one of #68's held-out worlds as ``heldout_NAME``,
    ``heldout2_NAME`` (the second set), ``heldout3_NAME`` (the third) or ``heldout4_NAME``
    (the fourth; with its bounds: ``heldout_NAME_bounded``), or a tuning world by its name in
    :data:`bench.worlds.tuning.WORLDS` (``tuning_*``, and highway-env's ``highway*``)."""
    for prefix, package in (
        ("heldout_", "bench.heldout"),
        ("heldout2_", "bench.heldout2"),
        ("heldout3_", "bench.heldout3"),
        ("heldout4_", "bench.heldout4"),
    ):
        if name.startswith(prefix):  # heldout_pile, heldout3_fusion_bounded, ...
            base = name.removeprefix(prefix)
            try:
                found: World = importlib.import_module(package).world(
                    base.removesuffix("_bounded"), base.endswith("_bounded")
                )
            except ValueError as error:
                raise SystemExit(str(error)) from None
            return found
    if name.startswith(("tuning_", "highway")):
        from bench.worlds.tuning import WORLDS as TUNING  # the simulator's lead data, on demand

        if name not in TUNING:
            raise SystemExit(f"no tuning world {name!r}; there are {', '.join(TUNING)}")
        if name.startswith("highway") and importlib.util.find_spec("highway_env") is None:
            from bench.worlds.highway import INSTALL

            raise SystemExit(f"the world {name!r} needs highway-env: {INSTALL}")
        return TUNING[name]
    if name not in WORLDS:
        raise SystemExit(f"no held-out world {name!r}; there are {', '.join(WORLDS)}")
    world: World = importlib.import_module(f"bench.worlds.{name}").WORLD
    return world


def merged(base: ShieldConfig, overrides: dict[str, dict[str, object]]) -> ShieldConfig:
    """``base`` with each section's fields replaced by ``overrides``."""
    data = base.to_dict()
    for section, fields in overrides.items():
        data[section] = {**data[section], **fields}
    return ShieldConfig.from_dict(data)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", default=",".join(WORLDS))
    parser.add_argument("--seeds", default="1000,1001,1002")
    parser.add_argument("--episodes", type=int, default=150)
    parser.add_argument("--warmup", type=int, default=50)
    parser.add_argument("--overrides", default="{}", help="shield overrides as JSON")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    overrides = json.loads(args.overrides)
    results = []
    names = args.worlds.split(",")
    if names == ["tuning"]:
        from bench.worlds.tuning import WORLDS as TUNING

        names = [name for name in TUNING if name.startswith("tuning_")]  # not highway-env's
    for name in names:
        world = world_named(name)
        config = merged(world.config, overrides)
        result = compare(
            dataclasses.replace(world, config=config), seeds, args.episodes, args.warmup
        )
        print(summary_line(result), flush=True)
        results.append(result)
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(
            json.dumps(
                {
                    "overrides": overrides,
                    "machine": platform.processor() or platform.machine(),
                    "core": compiled.version(),
                    "results": results,
                },
                indent=1,
            )
        )


if __name__ == "__main__":
    main()
