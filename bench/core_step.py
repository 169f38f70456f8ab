"""Cost of one step of the paper's reviser as the model grows: the lazy TPMs against the dense one.

For each size n a model is built through the core's own API (n states spread over the
normalised observation cube, 20 transitions learned per state along a random walk), then both
backends run the same steps in two workloads whose work does not depend on n:

* ``inspect``: learn from the observation, then predict and inspect the proposed action once
  (one flagged state per criterion, the reviser not yet active): the common step;
* ``search``: every state flagged for collision and the strongest acceleration proposed, so
  each step learns and then inspects all 20 actions (Alg. 2 runs down to the last bin).

Reported: the median over rounds of the mean time per step, and the memory held by the
matrices. The dense baseline is the straightforward stable form of Eqs. 3-4
(``app.core.tpm.DenseTransitions``), built from the lazy model's matrices.

    python bench/core_step.py                 # 50, 500, 2000, 5000 states
    python bench/core_step.py --sizes 50 500 --rounds 3
"""

from __future__ import annotations

import argparse
import copy
import json
import platform
import statistics
import time
from typing import Any

import numpy as np

from app.core import LimitsConfig, ReviserConfig, Shield, ShieldConfig
from app.core.belief import recognise
from app.core.clustering import EvolvingClusterer
from app.core.lazy_tpm import LazyTransitions
from app.core.tpm import DenseTransitions

SEED = 0


def spread(config: ShieldConfig, n: int, rng: np.random.Generator) -> Shield:
    """A shield of ``config`` whose n states are spread uniformly over the normalised
    observation cube, every per-state table grown for them and nothing learned yet."""
    shield = Shield(config)
    centres = rng.uniform(0.0, 1.0, (n, 3))
    shield.clusterer = EvolvingClusterer.restore(
        config.clustering,
        3,
        n,
        {
            "k": 10 * n,
            "beta": centres.sum(axis=0) * 10,
            "sigma": float((centres**2).sum()) * 10,
            "capacity_hits": 0,
            "centres": centres,
            "sq_norms": np.array([float(c @ c) for c in centres]),
            "potentials": np.full(n, 0.5),
            "radii": np.full(n, 0.6 / n ** (1 / 3)),
            "support": np.full(n, 10),
            "scatter": np.full(n, 0.01),
        },
    )
    for _ in range(n):
        shield._add_state()
    return shield


def build(n: int, seed: int = SEED) -> dict[str, Any]:
    """The snapshot of a lazy-backend model of the paper's reviser with n states and a
    learned history."""
    config = ShieldConfig.paper(
        reviser=ReviserConfig(method="paper", seed=seed), limits=LimitsConfig(max_states=n)
    )
    rng = np.random.default_rng(seed)
    shield = spread(config, n, rng)
    variances = shield.clusterer.variances()
    z = rng.uniform(0, 1, 3)
    prev = recognise(shield.clusterer.sq_distances(z), variances, config.limits.belief_top_k)
    for _ in range(20 * n):
        z = np.clip(z + rng.normal(0, 0.05, 3), 0, 1)
        belief = recognise(shield.clusterer.sq_distances(z), variances, config.limits.belief_top_k)
        shield.transitions.learn_one(prev, int(rng.integers(20)), belief)
        prev = belief
    return shield.snapshot()


def variant(data: dict[str, Any], workload: str) -> dict[str, Any]:
    """The snapshot set up for one workload (see the module docstring)."""
    data = copy.deepcopy(data)
    flags = data["flags"]["flags"]
    if workload == "inspect":
        flags[:2] = [1, 2]
        data["config"]["reviser"]["activate_after_episodes"] = 10**9
    else:
        flags[:] = 1
        data["config"]["reviser"]["activate_after_episodes"] = 0
    return data


def densify(data: dict[str, Any]) -> Shield:
    """The same model on the dense backend."""
    lazy = Shield.from_snapshot(data)
    tpm = lazy.transitions
    assert isinstance(tpm, LazyTransitions)
    q = lazy.config.action.n_bins
    dense = DenseTransitions.restore(
        q,
        lazy.config.transitions,
        {
            "P": np.stack([tpm.matrix(a) for a in range(q)]),
            "F_o": np.stack([tpm.row_mass(a) for a in range(q)]),
        },
    )
    data = {**data, "transitions": dense.snapshot()}
    data["config"] = copy.deepcopy(data["config"])
    data["config"]["limits"]["tpm_backend"] = "dense"
    return Shield.from_snapshot(data)


def steps(count: int, seed: int, workload: str) -> list[tuple[list[float], float]]:
    """Observations drifting through the cube (physical units) and the proposals."""
    rng = np.random.default_rng(seed + 1)
    z = rng.uniform(0, 1, 3)
    high = np.array(ShieldConfig().observation.high)  # the cube the model's states fill
    out = []
    for _ in range(count):
        z = np.clip(z + rng.normal(0, 0.03, 3), 0, 1)
        action = 2.0 if workload == "search" else float(rng.uniform(-2, 2))
        out.append(([float(v) for v in z * high], action))
    return out


def time_steps(shield: Shield, block: list[tuple[list[float], float]]) -> tuple[float, float]:
    """Seconds per step, and actions inspected per step."""
    inspected = 0
    start = time.perf_counter()
    for z, a in block:
        decision = shield.step(z, a)
        inspected += 1 + len(decision.candidates) if decision.threshold is not None else 0
    return (time.perf_counter() - start) / len(block), inspected / len(block)


def matrix_bytes(shield: Shield) -> int:
    tpm = shield.transitions
    if isinstance(tpm, DenseTransitions):
        return int(tpm.P.nbytes + tpm.F_o.nbytes)
    assert isinstance(tpm, LazyTransitions)
    return tpm.nbytes()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[50, 500, 2000, 5000])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--dense-steps", type=int, default=20)
    parser.add_argument("--json", help="also write the results here")
    args = parser.parse_args()

    rows = []
    for n in args.sizes:
        data = build(n)
        row: dict[str, Any] = {"states": n}
        for workload in ("inspect", "search"):
            lazy = Shield.from_snapshot(variant(data, workload))
            dense = densify(variant(data, workload))
            lazy_times, dense_times = [], []
            for r in range(args.rounds):
                block = steps(args.steps, SEED + r, workload)
                t, per_step = time_steps(lazy, block)
                lazy_times.append(t)
                dense_times.append(time_steps(dense, block[: args.dense_steps])[0])
            row[workload] = {
                "lazy_us": statistics.median(lazy_times) * 1e6,
                "dense_us": statistics.median(dense_times) * 1e6,
                "inspected_per_step": per_step,
            }
        row["lazy_mb"] = matrix_bytes(lazy) / 2**20
        row["dense_mb"] = matrix_bytes(dense) / 2**20
        rows.append(row)
        print(f"n={n}: done", flush=True)

    print(
        f"\nseed {SEED}; {args.rounds} rounds of {args.steps} steps (dense: "
        f"{args.dense_steps}); median of round means; {platform.machine()}, "
        f"numpy {np.__version__}, Python {platform.python_version()}\n"
    )
    for workload in ("inspect", "search"):
        base = rows[0][workload]["lazy_us"]
        print(
            f"workload {workload!r} "
            f"({rows[0][workload]['inspected_per_step']:.0f} actions inspected per step)\n"
        )
        print("| states | lazy step (us) | vs smallest | dense step (us) | dense / lazy |")
        print("|---:|---:|---:|---:|---:|")
        for row in rows:
            w = row[workload]
            print(
                f"| {row['states']} | {w['lazy_us']:.0f} | {w['lazy_us'] / base:.2f}x "
                f"| {w['dense_us']:.0f} | {w['dense_us'] / w['lazy_us']:.1f}x |"
            )
        print()
    print("| states | lazy matrices (MB) | dense matrices (MB) |")
    print("|---:|---:|---:|")
    for row in rows:
        print(f"| {row['states']} | {row['lazy_mb']:.1f} | {row['dense_mb']:.1f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=2)


if __name__ == "__main__":
    main()
