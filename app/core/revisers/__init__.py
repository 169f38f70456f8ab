"""The action revisers: the part of a shield that answers a proposed action.

Each reviser is one module and one subclass of :class:`Reviser` (:mod:`app.core.revisers.base`
says what a shield asks of it), found here by the configuration's ``reviser.method``:

- ``risk`` (the default, :mod:`app.core.revisers.risk`): each action's probability that any
  failure follows, learned per state from outcomes, decided inside the compiled step;
- ``paper`` (:mod:`app.core.revisers.paper`): the paper's Algs. 1-3 on the e-FSM's transition
  matrices and flags.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from app.core.revisers.base import Reviser
from app.core.revisers.paper import PaperReviser
from app.core.revisers.risk import RiskReviser

if TYPE_CHECKING:
    from app.core.shield import Shield

REVISERS: dict[str, type[Reviser]] = {"risk": RiskReviser, "paper": PaperReviser}


def make(shield: Shield) -> Reviser:
    """The reviser ``shield``'s configuration names, for that shield."""
    return REVISERS[shield.config.reviser.method](shield)


__all__ = ["REVISERS", "PaperReviser", "Reviser", "RiskReviser", "make"]
