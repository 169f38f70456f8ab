"""The e-FSM and its action reviser in numpy and numba (Han, Nageshrao, Filev, Özgüner, IFAC 2020).

This package knows nothing of HTTP, pydantic or torch: the service and the client both build
on it. Start with :class:`Shield` and :class:`ShieldConfig`.
"""

from app.core import (
    _cache_folder,  # noqa: F401  (first: numba needs a cache folder)
    compiled,
)
from app.core.config import (
    ActionSpec,
    Bound,
    ClusteringConfig,
    Criterion,
    LimitsConfig,
    ObservationSpec,
    ReviserConfig,
    RiskConfig,
    ShieldConfig,
    TransitionConfig,
)
from app.core.decision import Candidate, Decision
from app.core.errors import (
    InvalidAction,
    InvalidConfig,
    InvalidObservation,
    InvalidSnapshot,
    ShieldError,
    UnknownCriterion,
)
from app.core.shield import Shield

compiled.keep_cache_current()  # before any kernel loads from the cache (app.core.compiled)

__all__ = [
    "ActionSpec",
    "Bound",
    "Candidate",
    "ClusteringConfig",
    "Criterion",
    "Decision",
    "InvalidAction",
    "InvalidConfig",
    "InvalidObservation",
    "InvalidSnapshot",
    "LimitsConfig",
    "ObservationSpec",
    "ReviserConfig",
    "RiskConfig",
    "Shield",
    "ShieldConfig",
    "ShieldError",
    "TransitionConfig",
    "UnknownCriterion",
]
