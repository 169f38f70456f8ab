"""The e-FSM step of two commits side by side: did a change make the core faster?

Each commit is checked out into a temporary git worktree; a child process per commit imports
that commit's ``app`` and runs the same workloads on the same models (built by this checkout's
``bench/core_step.py``, so both commits see identical inputs). Both children stay alive and
take turns, workload by workload, so that each pair of measurements is a few seconds apart and
a drift of the machine's speed (large on shared virtual machines) falls on both; the speed-up
is the median of the pairs' ratios. Workloads per size n:

* ``inspect``: two states flagged, the reviser active: learn, then predict and inspect the
  proposed action (the service benchmark's step);
* ``search``: every state flagged and the strongest acceleration proposed, so each step
  inspects all the actions below it (the worst case of Alg. 2);

and ``training``: every shield step of a shielded DDPG training (in-process, the reviser active
from the first episode, seed 1000), recorded once by this checkout and replayed into an empty
model by each commit: the inputs a shield meets in the paper's experiment, where models keep a
handful of states.

``--shield JSON`` lays shield overrides over every workload's configuration (for example
``'{"reviser": {"horizon": 2}}'``, the two-step prediction) to time a path the defaults skip.

Each child also hashes every decision and the final snapshot of each workload: the table says
whether the two commits decided identically, bit for bit.

    python bench/core_versions.py c5d9b04 HEAD --rounds 5 --json bench/results/core_versions.json
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import importlib.util
import json
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
SIZES = (10, 50, 1000, 5000)
STEPS = {"inspect": 300, "search": 60}
TRAINING_SHIELD = {"reviser": {"activate_after_episodes": 0}}


def with_overrides(config: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    """``config`` with the sections of ``overrides`` laid over its own."""
    return {
        **config,
        **{section: {**config.get(section, {}), **fields} for section, fields in overrides.items()},
    }


def record_training(episodes: int, path: Path, overrides: dict[str, Any]) -> int:
    """Every shield step of a shielded DDPG training of ``episodes`` episodes, as JSON."""
    sys.path.insert(0, str(ROOT))  # the client package, not bench/client.py beside this file
    import torch

    from app.core import ShieldConfig
    from client.agents.ddpg import DDPG, DDPGConfig
    from client.experiment.runner import play
    from client.shield import LocalShield
    from client.shield.wrapper import ShieldWrapper
    from client.sim import lead
    from client.sim.car_following import CarFollowingEnv

    torch.set_num_threads(1)
    calls: list[tuple[list[float], float | None, dict[str, Any]]] = []
    local = LocalShield(ShieldConfig.from_dict(with_overrides(TRAINING_SHIELD, overrides)))

    class Recording:
        def revise(self, observation: Any, action: float | None, **options: Any) -> Any:
            calls.append(([float(v) for v in observation], action, options))
            return local.revise(observation, action, **options)

        def close(self) -> None:
            local.close()

    env = ShieldWrapper(CarFollowingEnv(lead=lead.cmap("train")), Recording())
    agent = DDPG(DDPGConfig(), 1000)
    obs, _ = env.reset(seed=1000)
    for _ in range(episodes):
        _, obs = play(env, agent, obs, agent)
        obs, _ = env.reset()
    path.write_text(json.dumps(calls))
    return len(calls)


def child(training: str, shield_json: str) -> None:
    """Time workloads on request, with the ``app`` first on sys.path: each line
    ``ROUND KEY`` of stdin runs workload KEY once on that round's steps, and each answer is one
    JSON line of stdout with the time per step and the digest of the decisions."""
    from app.core import Shield, ShieldConfig
    from app.service import codec

    spec = importlib.util.spec_from_file_location("core_step", ROOT / "bench" / "core_step.py")
    assert spec is not None and spec.loader is not None
    core_step = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(core_step)
    steps, variant = core_step.steps, core_step.variant
    import app

    assert Path(app.__file__).parent.parent == Path.cwd(), "the commit's app was not imported"

    def digest(shield: Shield, decisions: list[Any]) -> str:
        h = hashlib.sha256()
        for d in decisions:
            h.update(repr(d).encode())
        h.update(codec.to_npz(shield.snapshot()))
        return h.hexdigest()[:16]

    overrides = json.loads(shield_json)
    calls = json.loads(Path(training).read_text())
    built: dict[int, dict[str, Any]] = {}

    def snapshot(n: int, workload: str) -> dict[str, Any]:
        if n not in built:
            built[n] = core_step.build(n)
        data = variant(built[n], "search") if workload == "search" else copy.deepcopy(built[n])
        if workload == "inspect":
            data["flags"]["flags"][:2] = [1, 2]
            data["config"]["reviser"]["activate_after_episodes"] = 0
        data["config"] = with_overrides(data["config"], overrides)
        return data

    for line in sys.stdin:
        round_index, key = line.split()
        if key == "training":
            shield = Shield(ShieldConfig.from_dict(with_overrides(TRAINING_SHIELD, overrides)))
            start = time.perf_counter()
            decisions = [shield.step(z, a, **options) for z, a, options in calls]
            us = (time.perf_counter() - start) / len(calls) * 1e6
        else:
            size, workload = key.split("/")
            data = snapshot(int(size), workload)
            warm = Shield.from_snapshot(data)  # first calls pay for imports and caches
            for z, a in steps(20, 10_000 + int(round_index), workload):
                warm.step(z, a)
            shield = Shield.from_snapshot(data)
            block = steps(STEPS[workload], int(round_index), workload)
            start = time.perf_counter()
            decisions = [shield.step(z, a) for z, a in block]
            us = (time.perf_counter() - start) / len(block) * 1e6
        print(
            json.dumps({"us": us, "digest": digest(shield, decisions), "states": shield.n_states}),
            flush=True,
        )


class Worker:
    """One commit's child process, kept alive between requests."""

    def __init__(self, tree: Path, training: Path, shield: str) -> None:
        code = (
            f"import runpy, sys; sys.path.insert(0, {str(tree)!r}); "
            f"runpy.run_path({__file__!r})['child']({str(training)!r}, {shield!r})"
        )
        self.process = subprocess.Popen(
            [sys.executable, "-c", code],
            cwd=tree,
            text=True,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
        )

    def time(self, round_index: int, key: str) -> dict[str, Any]:
        assert self.process.stdin is not None and self.process.stdout is not None
        self.process.stdin.write(f"{round_index} {key}\n")
        self.process.stdin.flush()
        answer = self.process.stdout.readline()
        if not answer:
            raise RuntimeError(f"the worker for {key} stopped (exit {self.process.wait()})")
        measured: dict[str, Any] = json.loads(answer)
        return measured

    def close(self) -> None:
        if self.process.stdin is not None:
            self.process.stdin.close()
        self.process.wait(60)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", help="the baseline commit")
    parser.add_argument("head", help="the commit measured against it")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument(
        "--episodes", type=int, default=40, help="episodes of the recorded training"
    )
    parser.add_argument(
        "--shield",
        default="{}",
        help="shield overrides (JSON) laid over every workload's configuration",
    )
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()
    overrides = json.loads(args.shield)

    revs = {
        name: subprocess.run(
            ["git", "rev-parse", "--short", rev],
            cwd=ROOT,
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
        for name, rev in (("base", args.base), ("head", args.head))
    }
    with tempfile.TemporaryDirectory() as tmp:
        trees = {name: Path(tmp) / name for name in revs}
        for name, rev in revs.items():
            subprocess.run(
                ["git", "worktree", "add", "--detach", str(trees[name]), rev],
                cwd=ROOT,
                check=True,
                capture_output=True,
            )
        training = Path(tmp) / "training.json"
        recorded = record_training(args.episodes, training, overrides)
        print(f"recorded {recorded} shield steps of {args.episodes} training episodes", flush=True)
        keys = [f"{n}/{w}" for n in SIZES for w in STEPS] + ["training"]
        workers = {name: Worker(trees[name], training, args.shield) for name in revs}
        try:
            rounds: dict[str, dict[str, list[dict[str, Any]]]] = {
                name: {key: [] for key in keys} for name in revs
            }
            for r in range(args.rounds):
                for key in keys:  # the two take turns, first one then the other
                    for name in list(revs)[:: 1 if r % 2 == 0 else -1]:
                        rounds[name][key].append(workers[name].time(r, key))
                print(f"round {r + 1}/{args.rounds} done", flush=True)
        finally:
            for worker in workers.values():
                worker.close()
            for tree in trees.values():
                subprocess.run(
                    ["git", "worktree", "remove", "--force", str(tree)],
                    cwd=ROOT,
                    check=False,
                    capture_output=True,
                )

    result: dict[str, Any] = {
        "base": revs["base"],
        "head": revs["head"],
        "rounds": args.rounds,
        "training_steps": recorded,
        "shield": overrides,
        "python": platform.python_version(),
        "rows": [],
    }
    print(
        f"\n{args.rounds} rounds, the two commits taking turns workload by workload; "
        f"medians of the rounds (us per step) and of the paired ratios; {platform.machine()}, "
        f"Python {platform.python_version()}; shield overrides {args.shield}\n"
    )
    print(
        f"| states | workload | {revs['base']} (us) | {revs['head']} (us) | speed-up "
        "| identical decisions |"
    )
    print("|---:|---|---:|---:|---:|---|")
    for key in keys:
        base, head = rounds["base"][key], rounds["head"][key]
        # rounds draw their own steps: compare the two commits round by round
        identical = all(b["digest"] == h["digest"] for b, h in zip(base, head, strict=True))
        speed_up = statistics.median(b["us"] / h["us"] for b, h in zip(base, head, strict=True))
        n, workload = (
            key.split("/") if "/" in key else (str(base[0]["states"]), key)
        )  # training: the states it ends with
        row = {
            "states": int(n),
            "workload": workload,
            "base_us": statistics.median(b["us"] for b in base),
            "head_us": statistics.median(h["us"] for h in head),
            "speed_up": speed_up,
            "identical": identical,
        }
        result["rows"].append(row)
        print(
            f"| {n} | {workload} | {row['base_us']:.0f} | {row['head_us']:.0f} "
            f"| {speed_up:.2f}x | {'yes' if identical else 'NO'} |"
        )
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
