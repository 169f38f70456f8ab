"""The e-FSM step of two commits side by side: did a change make the core faster?

Each commit is checked out into a temporary git worktree; a child process per commit and round
imports that commit's ``app`` and runs the same workloads on the same models (built by this
checkout's ``bench/core_step.py``, so both commits see identical inputs). Rounds alternate
between the commits so that drift of the machine falls on both. Workloads per size n:

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
    return {**config, **{section: {**config.get(section, {}), **fields}
                         for section, fields in overrides.items()}}


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


def child(round_index: int, training: str, shield_json: str) -> None:
    """Time every workload once with the ``app`` first on sys.path; print JSON of the times
    and the digests."""
    from app.core import Shield, ShieldConfig
    from app.service import codec

    spec = importlib.util.spec_from_file_location("core_step", ROOT / "bench" / "core_step.py")
    assert spec is not None and spec.loader is not None
    core_step = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(core_step)
    build, steps, variant = core_step.build, core_step.steps, core_step.variant

    def digest(shield: Shield, decisions: list[Any]) -> str:
        h = hashlib.sha256()
        for d in decisions:
            h.update(repr(d).encode())
        h.update(codec.to_npz(shield.snapshot()))
        return h.hexdigest()[:16]

    overrides = json.loads(shield_json)
    out: dict[str, float] = {}
    digests: dict[str, str] = {}
    for n in SIZES:
        data = build(n)
        for workload, count in STEPS.items():
            snapshot = variant(data, "search") if workload == "search" else copy.deepcopy(data)
            if workload == "inspect":
                snapshot["flags"]["flags"][:2] = [1, 2]
                snapshot["config"]["reviser"]["activate_after_episodes"] = 0
            snapshot["config"] = with_overrides(snapshot["config"], overrides)
            kind = "search" if workload == "search" else "inspect"
            warm = Shield.from_snapshot(snapshot)  # first calls pay for imports and caches
            for z, a in steps(20, 10_000 + round_index, kind):
                warm.step(z, a)
            shield = Shield.from_snapshot(snapshot)
            block = steps(count, round_index, kind)
            start = time.perf_counter()
            decisions = [shield.step(z, a) for z, a in block]
            out[f"{n}/{workload}"] = (time.perf_counter() - start) / count * 1e6
            digests[f"{n}/{workload}"] = digest(shield, decisions)
    calls = json.loads(Path(training).read_text())
    shield = Shield(ShieldConfig.from_dict(with_overrides(TRAINING_SHIELD, overrides)))
    start = time.perf_counter()
    decisions = [shield.step(z, a, **options) for z, a, options in calls]
    out["training"] = (time.perf_counter() - start) / len(calls) * 1e6
    digests["training"] = digest(shield, decisions)
    import app

    assert Path(app.__file__).parent.parent == Path.cwd(), "the commit's app was not imported"
    print(json.dumps({"us": out, "digests": digests, "training_states": shield.n_states}))


def run_round(tree: Path, round_index: int, training: Path, shield: str) -> dict[str, Any]:
    code = (f"import runpy, sys; sys.path.insert(0, {str(tree)!r}); "
            f"runpy.run_path({__file__!r})['child']({round_index}, {str(training)!r}, "
            f"{shield!r})")
    result = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                            text=True, cwd=tree)
    measured: dict[str, Any] = json.loads(result.stdout.strip().splitlines()[-1])
    return measured


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", help="the baseline commit")
    parser.add_argument("head", help="the commit measured against it")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=40,
                        help="episodes of the recorded training")
    parser.add_argument("--shield", default="{}",
                        help="shield overrides (JSON) laid over every workload's configuration")
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()
    overrides = json.loads(args.shield)

    revs = {name: subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                                 capture_output=True, text=True).stdout.strip()
            for name, rev in (("base", args.base), ("head", args.head))}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {name: Path(tmp) / name for name in revs}
        for name, rev in revs.items():
            subprocess.run(["git", "worktree", "add", "--detach", str(trees[name]), rev],
                           cwd=ROOT, check=True, capture_output=True)
        training = Path(tmp) / "training.json"
        recorded = record_training(args.episodes, training, overrides)
        print(f"recorded {recorded} shield steps of {args.episodes} training episodes",
              flush=True)
        try:
            rounds: dict[str, list[dict[str, Any]]] = {name: [] for name in revs}
            for r in range(args.rounds):
                for name in revs:
                    rounds[name].append(run_round(trees[name], r, training, args.shield))
                print(f"round {r + 1}/{args.rounds} done", flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                               check=False, capture_output=True)

    keys = list(rounds["base"][0]["us"])
    result: dict[str, Any] = {"base": revs["base"], "head": revs["head"], "rounds": args.rounds,
                              "training_steps": recorded, "shield": overrides,
                              "python": platform.python_version(),
                              "rows": []}
    print(f"\n{args.rounds} rounds, alternating; median of round means (us per step); "
          f"{platform.machine()}, Python {platform.python_version()}; shield overrides "
          f"{args.shield}\n")
    print(f"| states | workload | {revs['base']} (us) | {revs['head']} (us) | speed-up "
          "| identical decisions |")
    print("|---:|---|---:|---:|---:|---|")
    for key in keys:
        base = statistics.median(r["us"][key] for r in rounds["base"])
        head = statistics.median(r["us"][key] for r in rounds["head"])
        # rounds draw their own steps: compare the two commits round by round
        identical = all(b["digests"][key] == h["digests"][key]
                        for b, h in zip(rounds["base"], rounds["head"], strict=True))
        n, workload = key.split("/") if "/" in key else (
            str(rounds["base"][0]["training_states"]), key)  # training: the states it ends with
        result["rows"].append({"states": int(n), "workload": workload, "base_us": base,
                               "head_us": head, "identical": identical})
        print(f"| {n} | {workload} | {base:.0f} | {head:.0f} | {base / head:.2f}x "
              f"| {'yes' if identical else 'NO'} |")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
