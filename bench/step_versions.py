"""The risk reviser's step of two commits, block by block in turns: did a change slow it down?

Each commit is checked out into a temporary git worktree, where a child process imports that
commit's ``app`` and its own ``bench/step_cost.py`` and builds that benchmark's models (same
seeds, so the same models where the two cores agree). The two children stay alive and take
turns, block by block (1,000 steps of the keep or the revise workload), so that a drift of the
machine's speed falls on both; each pair must revise the same share of steps (else the commits
decide differently and the run stops). Reported per size and workload: the median of the
blocks' mean step in each, and the median of the pairs' ratios. Pin it to one core
(``taskset -c 1``) and leave the machine quiet.

    python bench/step_versions.py 586bc3c HEAD --blocks 40
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SIZES = (10, 1000)
WORKLOADS = ("keep", "revise")
CHILD = """
import json, sys
sys.path.insert(0, sys.argv[1])
from bench.step_cost import SEED, build, steps, time_steps
models = {}
for line in sys.stdin:
    n, workload, r = (int(v) if v.isdigit() else v for v in line.split())
    if n not in models:
        models[n] = build(n)
        time_steps(models[n], steps(300, SEED + 99, "keep"))  # compiled and warm
    print(json.dumps(time_steps(models[n], steps(1000, SEED + r, workload))), flush=True)
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("base", help="the baseline commit")
    parser.add_argument("head", help="the commit measured against it")
    parser.add_argument("--blocks", type=int, default=40, help="blocks per size and workload")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        trees = {name: Path(tmp) / name for name in ("base", "head")}
        for name, rev in (("base", args.base), ("head", args.head)):
            subprocess.run(
                ["git", "worktree", "add", "--detach", str(trees[name]), rev],
                cwd=ROOT,
                check=True,
                capture_output=True,
            )
        children = {
            name: subprocess.Popen(
                [sys.executable, "-c", CHILD, str(tree)],
                cwd=tree,
                text=True,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
            )
            for name, tree in trees.items()
        }

        def block(name: str, request: str) -> tuple[float, float]:
            child = children[name]
            assert child.stdin is not None and child.stdout is not None
            child.stdin.write(request + "\n")
            child.stdin.flush()
            seconds, share = json.loads(child.stdout.readline())
            return float(seconds), float(share)

        print(f"{args.base} against {args.head}; {args.blocks} blocks of 1,000 steps in turns\n")
        print("| states | workload | base (us) | head (us) | head / base |")
        print("|---:|---|---:|---:|---:|")
        try:
            for n in SIZES:
                for workload in WORKLOADS:
                    times: dict[str, list[float]] = {"base": [], "head": []}
                    for r in range(args.blocks):
                        shares = {}
                        for name in ("base", "head")[:: 1 if r % 2 == 0 else -1]:
                            seconds, shares[name] = block(name, f"{n} {workload} {r}")
                            times[name].append(seconds)
                        if shares["base"] != shares["head"]:
                            raise SystemExit(f"the commits decide differently: {shares}")
                    ratios = [h / b for b, h in zip(times["base"], times["head"], strict=True)]
                    base, head = (statistics.median(times[k]) * 1e6 for k in ("base", "head"))
                    print(
                        f"| {n} | {workload} | {base:.1f} | {head:.1f} "
                        f"| {statistics.median(ratios):.3f} |",
                        flush=True,
                    )
        finally:
            for child in children.values():
                if child.stdin is not None:
                    child.stdin.close()
                child.wait(60)
            for tree in trees.values():
                subprocess.run(
                    ["git", "worktree", "remove", "--force", str(tree)],
                    cwd=ROOT,
                    check=False,
                    capture_output=True,
                )


if __name__ == "__main__":
    main()
