"""A server's bounds on a model (:mod:`app.service.limits`): the memory estimate holds a full
model's tables, and each bound names the field to lower."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.core import InvalidConfig, Shield, ShieldConfig
from app.service.limits import STREAM_OVERHEAD, ModelLimits, table_bytes

LEARNED = ("_pool_cols", "_pool_vals")  # the lazy matrices' learned entries: not estimated


def array_bytes(value: Any, seen: set[int]) -> int:
    """The bytes of every numpy array a model holds (each buffer once), but the learned
    entries'."""
    if id(value) in seen:
        return 0
    seen.add(id(value))
    if isinstance(value, np.ndarray):
        return value.nbytes if value.base is None else 0
    if isinstance(value, dict):
        return sum(array_bytes(v, seen) for v in value.values())
    if isinstance(value, list | tuple):
        return sum(array_bytes(v, seen) for v in value)
    attributes = getattr(value, "__dict__", None)
    if attributes is None and hasattr(value, "__slots__"):
        attributes = {a: getattr(value, a) for a in value.__slots__ if hasattr(value, a)}
    return sum(array_bytes(v, seen) for k, v in (attributes or {}).items() if k not in LEARNED)


@pytest.mark.parametrize(
    "overrides",
    [
        {},
        {"limits": {"tpm_backend": "dense"}},
        {"reviser": {"method": "paper"}},
        {"action": {"step": 0.05}, "risk": {"horizon": 50}, "limits": {"belief_top_k": 4}},
    ],
)
def test_the_estimate_holds_a_full_model_s_tables(overrides: dict[str, Any]) -> None:
    limits = {"max_states": 16, "max_streams": 20, **overrides.get("limits", {})}
    config = ShieldConfig.from_dict(
        {**overrides, "limits": limits, "clustering": {"epsilon": 0.001}}
    )
    shield, rng = Shield(config), np.random.default_rng(0)
    for i in range(1500):  # every state and stream taken, failures learned
        shield.step(
            rng.uniform([0, 0, 0], [32, 50, 32]).tolist(),
            float(rng.uniform(-2, 2)),
            stream=str(i % 25),
            event="collision" if i % 97 == 0 else None,
        )
    assert shield.n_states == 16 and len(shield.streams) == 20
    held = array_bytes(shield, set())
    estimate = table_bytes(config) - 20 * STREAM_OVERHEAD  # the arrays alone
    assert held <= estimate <= 1.5 * held, (held, estimate)


@pytest.mark.parametrize(
    ("limits", "overrides", "field"),
    [
        (ModelLimits(max_states=1000), {"limits": {"max_states": 1001}}, "limits.max_states"),
        (ModelLimits(max_action_bins=40), {"action": {"step": 0.05}}, "action.step"),
        (ModelLimits(max_dimensions=2), {}, "observation.names"),
        (ModelLimits(max_model_bytes=2**20), {}, "limits.max_states"),
    ],
)
def test_each_bound_names_the_field_to_lower(
    limits: ModelLimits, overrides: dict[str, Any], field: str
) -> None:
    config = ShieldConfig.from_dict(overrides)
    with pytest.raises(InvalidConfig) as refused:
        limits.check(config)
    assert refused.value.field == field
    ModelLimits().check(ShieldConfig())  # the defaults fit the default bounds
