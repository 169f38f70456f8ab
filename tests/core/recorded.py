"""A long closed-loop sequence through the shield, recorded once, to check that the core
decides as it did when the recording was made (``tests/data/recorded-*.npz``).

A toy car-following loop: the lead speeds up and slows down at random, the controller
proposes a noisy, often reckless acceleration, the shield revises it, and a collision or a gap
over 200 m ends the episode. Everything is drawn from one seeded generator and the applied
action feeds back into the world, so a single different decision changes the rest.

    python -m tests.core.recorded        # rewrite the recordings from the current core
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import RiskConfig, Shield, ShieldConfig

DATA = Path(__file__).parent.parent / "data"
STEPS = 12_000
EPISODE = 400  # steps before an episode ends without a failure
# the default criteria without their bounds, as before bounds were declared
UNBOUNDED = tuple(dataclasses.replace(c, bound=None) for c in ShieldConfig().criteria)
PRESETS: dict[str, Callable[[], ShieldConfig]] = {
    "default": ShieldConfig,
    "paper": ShieldConfig.paper,
    # the default before the reach and its bounds (recorded by the core at 6f6cc72,
    # again when the risk reviser's end bins began applying the range's ends)
    "no-reach": lambda: ShieldConfig(criteria=UNBOUNDED, risk=RiskConfig(reach_horizon=0)),
}


def preset(name: str) -> ShieldConfig:
    """The recorded configurations, each reviser activated after 5 episodes."""
    config = PRESETS[name]()
    return dataclasses.replace(
        config, reviser=dataclasses.replace(config.reviser, activate_after_episodes=5)
    )


def drive(config: ShieldConfig, steps: int = STEPS, seed: int = 0) -> dict[str, npt.NDArray[Any]]:
    """Run the loop on a new shield of ``config`` (:func:`run`)."""
    return run(Shield(config), steps, seed)


def run(shield: Shield, steps: int = STEPS, seed: int = 0) -> dict[str, npt.NDArray[Any]]:
    """Run the loop; per step the applied action, recognised state, state count, whether the
    step was revised, why and the verdict, and the closing snapshot's local risk weights (empty
    without the risk reviser)."""
    rng = np.random.default_rng(seed)
    applied = np.full(steps, np.nan)
    state = np.full(steps, -1, dtype=np.int64)
    n_states = np.zeros(steps, dtype=np.int64)
    revised = np.zeros(steps, dtype=bool)
    reason = np.zeros(steps, dtype="U16")
    verdict = np.zeros(steps, dtype="U16")
    gap, v_ego, v_lead, target, lag, start = 40.0, 15.0, 15.0, 20.0, 0.0, 0
    for t in range(steps):
        observation = [v_ego, gap, v_lead]
        event = "collision" if gap <= 0 else "large_distance" if gap > 200 else None
        if event is not None or t - start == EPISODE:
            decision = shield.step(observation, None, event=event, done=True)
            gap, v_ego, v_lead = rng.uniform(10, 80), rng.uniform(5, 25), rng.uniform(5, 25)
            target, lag, start = rng.uniform(0, 40), rng.uniform(-3, 5), t + 1
        else:  # a controller that hangs back by `lag` m/s and barely minds the gap
            reckless = 0.4 * (v_lead - v_ego - lag) + 0.005 * (gap - target) + rng.normal(0, 1.5)
            decision = shield.step(observation, float(np.clip(reckless, -3, 3)))
            assert decision.action is not None
            applied[t] = decision.action
            lead = -6.0 if rng.random() < 0.01 else 0.1 * (20 - v_lead) + rng.normal(0, 1.0)
            v_lead = float(np.clip(v_lead + 0.25 * lead, 0, 32))
            v_ego = float(np.clip(v_ego + 0.25 * decision.action, 0, 32))
            gap += 0.25 * (v_lead - v_ego)
        state[t] = -1 if decision.state is None else decision.state
        n_states[t] = decision.n_states
        revised[t] = decision.revised
        reason[t], verdict[t] = decision.reason, decision.verdict
    snapshot = shield.snapshot()
    local = snapshot["local_risk"]
    return {
        "applied": applied,
        "state": state,
        "n_states": n_states,
        "revised": revised,
        "reason": reason,
        "verdict": verdict,
        "local_theta": np.zeros(0) if local is None else local["theta"],
    }


def path(name: str) -> Path:
    """Where the recording of a preset lies."""
    return DATA / f"recorded-{name}.npz"


if __name__ == "__main__":  # python -m tests.core.recorded [NAME ...]: those, or every one
    import sys

    for name in sys.argv[1:] or PRESETS:
        # mypy matches the arrays against savez_compressed's allow_pickle: bool as well
        np.savez_compressed(path(name), **drive(preset(name)))  # type: ignore[arg-type]
        print(f"wrote {path(name)}")  # noqa: T201
