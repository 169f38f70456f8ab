"""The e-FSM step of two commits side by side: did a change make the core faster?

Each commit is checked out into a temporary git worktree; a child process per commit and round
imports that commit's ``app`` and runs the same workloads on the same models (built by this
checkout's ``bench/core_step.py``, so both commits see identical inputs). Rounds alternate
between the commits so that drift of the machine falls on both. Workloads per size n:

* ``inspect``: two states flagged, the reviser active: learn, then predict and inspect the
  proposed action (the service benchmark's step);
* ``search``: every state flagged and the strongest acceleration proposed, so each step
  inspects all the actions below it (the worst case of Alg. 2).

    python bench/core_versions.py c5d9b04 HEAD --rounds 5 --json bench/results/core_versions.json
"""

from __future__ import annotations

import argparse
import copy
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


def child(round_index: int) -> None:
    """Time every workload once with the ``app`` first on sys.path; print JSON."""
    from app.core import Shield

    spec = importlib.util.spec_from_file_location("core_step", ROOT / "bench" / "core_step.py")
    assert spec is not None and spec.loader is not None
    core_step = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(core_step)
    build, steps, variant = core_step.build, core_step.steps, core_step.variant

    out: dict[str, float] = {}
    for n in SIZES:
        data = build(n)
        for workload, count in STEPS.items():
            snapshot = variant(data, "search") if workload == "search" else copy.deepcopy(data)
            if workload == "inspect":
                snapshot["flags"]["flags"][:2] = [1, 2]
                snapshot["config"]["reviser"]["activate_after_episodes"] = 0
            kind = "search" if workload == "search" else "inspect"
            warm = Shield.from_snapshot(snapshot)  # first calls pay for imports and caches
            for z, a in steps(20, 10_000 + round_index, kind):
                warm.step(z, a)
            shield = Shield.from_snapshot(snapshot)
            block = steps(count, round_index, kind)
            start = time.perf_counter()
            for z, a in block:
                shield.step(z, a)
            out[f"{n}/{workload}"] = (time.perf_counter() - start) / count * 1e6
    import app

    assert Path(app.__file__).parent.parent == Path.cwd(), "the commit's app was not imported"
    print(json.dumps(out))


def run_round(tree: Path, round_index: int) -> dict[str, float]:
    code = (f"import runpy, sys; sys.path.insert(0, {str(tree)!r}); "
            f"runpy.run_path({__file__!r})['child']({round_index})")
    result = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                            text=True, cwd=tree)
    timings: dict[str, float] = json.loads(result.stdout.strip().splitlines()[-1])
    return timings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", help="the baseline commit")
    parser.add_argument("head", help="the commit measured against it")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()

    revs = {name: subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                                 capture_output=True, text=True).stdout.strip()
            for name, rev in (("base", args.base), ("head", args.head))}
    with tempfile.TemporaryDirectory() as tmp:
        trees = {name: Path(tmp) / name for name in revs}
        for name, rev in revs.items():
            subprocess.run(["git", "worktree", "add", "--detach", str(trees[name]), rev],
                           cwd=ROOT, check=True, capture_output=True)
        try:
            rounds: dict[str, list[dict[str, float]]] = {name: [] for name in revs}
            for r in range(args.rounds):
                for name in revs:
                    rounds[name].append(run_round(trees[name], r))
                print(f"round {r + 1}/{args.rounds} done", flush=True)
        finally:
            for tree in trees.values():
                subprocess.run(["git", "worktree", "remove", "--force", str(tree)], cwd=ROOT,
                               check=False, capture_output=True)

    keys = list(rounds["base"][0])
    result: dict[str, Any] = {"base": revs["base"], "head": revs["head"], "rounds": args.rounds,
                              "python": platform.python_version(), "rows": []}
    print(f"\n{args.rounds} rounds, alternating; median of round means (us per step); "
          f"{platform.machine()}, Python {platform.python_version()}\n")
    print(f"| states | workload | {revs['base']} (us) | {revs['head']} (us) | speed-up |")
    print("|---:|---|---:|---:|---:|")
    for key in keys:
        base = statistics.median(r[key] for r in rounds["base"])
        head = statistics.median(r[key] for r in rounds["head"])
        n, workload = key.split("/")
        result["rows"].append({"states": int(n), "workload": workload, "base_us": base,
                               "head_us": head})
        print(f"| {n} | {workload} | {base:.0f} | {head:.0f} | {base / head:.2f}x |")
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
