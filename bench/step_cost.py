"""Cost of one step of the default shield (the risk reviser) as the model grows.

For each size n a model is built through the core's own API (n states spread over the
normalised observation cube, 20 learned transitions and 40 labelled steps of the local risk
model per state along a random walk, one in 200 a failure; the reach's dynamics along the same
walk, and its failure points where failures lie in a world, at two faces of the cube), then it
runs the step the service runs for every request: validate, normalise, cluster, recognise,
learn the transition, the step's risk label and its dynamics, read the risk and the reach of
every action and decide. ``--reach-horizon 0`` leaves the reach out (the local model alone).

Two workloads: ``keep``, a smooth controller whose proposals the shield mostly keeps, and
``revise``, the strongest acceleration every step, which the shield replaces where braking is
safer (each revision writes its candidates into the decision record).

Reported: the median over rounds of the mean time per step, and its ratio to the smallest
model's in the same run.

    python bench/step_cost.py                        # 10, 1000 and 5000 states
    python bench/step_cost.py --sizes 10 1000 --rounds 3 --steps 2000
    python bench/step_cost.py --reach-horizon 0      # without the reach
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.core import LimitsConfig, ReviserConfig, RiskConfig, Shield, ShieldConfig  # noqa: E402
from app.core.belief import recognise  # noqa: E402
from app.core.revisers import RiskReviser  # noqa: E402
from bench.core_step import spread  # noqa: E402

SEED = 0
CRITERIA = ("collision", "large_distance")


def build(n: int, seed: int = SEED, reach_horizon: int = RiskConfig().reach_horizon) -> Shield:
    """A default shield of n states with a learned history, the reviser active."""
    config = ShieldConfig(
        reviser=ReviserConfig(seed=seed, activate_after_episodes=0),
        risk=RiskConfig(reach_horizon=reach_horizon),
        limits=LimitsConfig(max_states=n),
    )
    rng = np.random.default_rng(seed)
    shield = spread(config, n, rng)
    variances = shield.clusterer.variances()
    k = config.limits.belief_top_k
    z = rng.uniform(0, 1, 3)
    prev = recognise(shield.clusterer.sq_distances(z), variances, k)
    reviser = shield.reviser
    assert isinstance(reviser, RiskReviser)
    for t in range(40 * n):
        before, z = z, np.clip(z + rng.normal(0, 0.05, 3), 0, 1)
        belief = recognise(shield.clusterer.sq_distances(z), variances, k)
        action = int(rng.integers(20))
        if t % 2 == 0:
            shield.transitions.learn_one(prev, action, belief)
        failure = int(rng.integers(2)) if rng.random() < 0.005 else None
        reviser.local_risk.learn(0, prev, before, action, failure, ended=False)
        # the reach's failures lie where failures lie in a world: at an edge of the space
        edge = 0 if z[1] < 0.03 else 1 if z[1] > 0.97 else None
        reviser.local_risk.learn_motion(
            prev, before, action, z, edge if rng.random() < 0.2 else None
        )
        prev = belief
    reviser.local_risk.forget(0)  # the slot the shield's first stream takes
    return shield


def steps(count: int, seed: int, workload: str) -> list[tuple[list[float], float]]:
    """Observations drifting through the cube (physical units) and the proposals."""
    rng = np.random.default_rng(seed + 1)
    z = rng.uniform(0, 1, 3)
    high = np.array(ShieldConfig().observation.high)
    action, out = 0.0, []
    for _ in range(count):
        z = np.clip(z + rng.normal(0, 0.03, 3), 0, 1)
        action = float(np.clip(action + rng.normal(0, 0.2), -2, 2))
        out.append(([float(v) for v in z * high], 2.0 if workload == "revise" else action))
    return out


def time_steps(shield: Shield, block: list[tuple[list[float], float]]) -> tuple[float, float]:
    """Seconds per step, and the share of steps revised."""
    revised = 0
    start = time.perf_counter()
    for z, a in block:
        revised += shield.step(z, a).revised
    return (time.perf_counter() - start) / len(block), revised / len(block)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10, 1000, 5000])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=5000)
    parser.add_argument(
        "--reach-horizon",
        type=int,
        default=RiskConfig().reach_horizon,
        help="the reach's rollout (0: the local model alone)",
    )
    args = parser.parse_args()
    rows: list[dict[str, Any]] = []
    for n in args.sizes:
        shield = build(n, reach_horizon=args.reach_horizon)
        time_steps(shield, steps(200, SEED + 99, "keep"))  # compiled and warm
        row: dict[str, Any] = {"states": n}
        for workload in ("keep", "revise"):
            times, share = [], 0.0
            for r in range(args.rounds):
                t, share = time_steps(shield, steps(args.steps, SEED + r, workload))
                times.append(t)
            row[workload] = (statistics.median(times) * 1e6, share)
        rows.append(row)
    print(
        f"seed {SEED}, reach horizon {args.reach_horizon}; {args.rounds} rounds of "
        f"{args.steps} steps; "
        f"median of round means; {platform.machine()}, numpy {np.__version__}, "
        f"Python {platform.python_version()}\n"
    )
    print(
        "| states | keep: step (us) | x smallest | revised | revise: step (us) | x smallest "
        "| revised |"
    )
    print("|---:|---:|---:|---:|---:|---:|---:|")
    base = rows[0]
    for row in rows:
        cells = [
            f"{row[w][0]:.1f} | {row[w][0] / base[w][0]:.2f} | {row[w][1]:.0%}"
            for w in ("keep", "revise")
        ]
        print(f"| {row['states']} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
