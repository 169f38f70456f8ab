"""The paper's reviser (``reviser.method: paper``): Alg. 1 (variant threshold), Alg. 3
(inspect), Alg. 2 (search), the k-step prediction of Eqs. 5-7 and the revision noise
(docs/algorithm.md), on the e-FSM's transition matrices and flags.

Verdicts are integers: ``OK`` (-1) or the index of the criterion an action is predicted to
meet, which is also its priority (0 = highest).
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
import numpy.typing as npt

from app.core import actions
from app.core.belief import Belief, top_k
from app.core.config import ReviserConfig
from app.core.decision import Candidate, Decision
from app.core.revisers.base import Reviser
from app.core.stream import StepInput, StreamState
from app.core.tpm import TransitionModel

if TYPE_CHECKING:
    from app.core.shield import Shield
    from app.core.step import Learned

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
OK = -1


def variant_threshold(pred: FloatArray) -> float:
    """Alg. 1: ``X = sort(pred, desc)``, ``E = sum_j j X(j)``, ``rho_t = X(floor(E))``.

    A peaked prediction (E < 2) gives the maximum; a diffuse one a small threshold, so that
    more states count as likely.
    """
    # ascending sort (predictions are a few sorted runs: timsort wins); X(r) = s[n - r], so
    # E = sum_r r X(r) = sum_i (n - i) s[i]
    s = np.sort(pred, kind="stable")
    n = s.size
    expected_rank = float(np.sum(_descending_ranks(n) * s))  # not BLAS: a fixed order
    index = min(max(int(math.floor(expected_rank)), 1), n)  # guard against round-off
    return float(s[n - index])


@functools.lru_cache(maxsize=4)
def _descending_ranks(n: int) -> FloatArray:
    """[n, n-1, ..., 1]: the rank in descending order of each ascending position."""
    ranks = np.arange(n, 0, -1, dtype=np.float64)
    ranks.flags.writeable = False
    return ranks


def inspect(
    pred: FloatArray,
    threshold: float,
    flagged: tuple[IntArray, IntArray],
    rule: Literal["any", "first_index"],
) -> int:
    """Alg. 3: the criterion an action is predicted to meet, or ``OK``.

    ``flagged`` holds the flagged states (ascending) and their flags. ``any``: the
    highest-priority flag among all states at or above the threshold. ``first_index``: the
    literal loop, which answers with the first such state by index.
    """
    index, flags = flagged
    if rule == "first_index":
        first = int(np.argmax(pred >= threshold))  # one exists: threshold <= max(pred)
        at = int(np.searchsorted(index, first))
        return int(flags[at]) - 1 if at < index.size and index[at] == first else OK
    likely = flags[pred[index] >= threshold]
    return int(likely.min()) - 1 if likely.size else OK


def risk(pred: FloatArray, flagged: tuple[IntArray, IntArray], n_criteria: int) -> FloatArray:
    """Predicted probability mass on the states of each criterion."""
    index, flags = flagged
    mass = np.bincount(flags, weights=pred[index], minlength=n_criteria + 1)[1:]
    return np.asarray(mass, dtype=np.float64)


def predict_ahead(
    model: TransitionModel,
    belief: Belief,
    action_bin: int,
    config: ReviserConfig,
    k: int,
) -> FloatArray:
    """Eqs. 5-7: one step under the action, then ``horizon - 1`` steps of the marginal TPM.

    ``P* = (1/q) sum_r P^r`` (Eq. 7, uniform action prior). ``iterate`` applies it
    ``horizon - 1`` times (A11); ``single`` applies it once, as Eq. 6 is written. Each
    propagated distribution is truncated to its top-k states like a belief.
    """
    pred = model.predict(belief, action_bin, config.transpose)
    extra = config.horizon - 1 if config.multi_step == "iterate" else min(config.horizon - 1, 1)
    for _ in range(extra):
        pred = model.predict_marginal(top_k(np.maximum(pred, 0.0), k), config.transpose)
    return pred


def search(
    start_bin: int,
    verdict: int,
    directions: Sequence[str | None],
    n_bins: int,
    literal: bool,
    assess: Callable[[int], int],
) -> tuple[int, list[tuple[int, int]]]:
    """Alg. 2: step through the bins away from the predicted criterion until it clears.

    A ``decrease`` criterion (collision) searches slower actions, an ``increase`` one (large
    distance) faster ones. The fixed form (A6) stops at the last bin instead of the
    literal ``r > 0`` off-by-one, and steps back when the search runs into a criterion of
    higher priority (an upward search that meets a collision). Returns the chosen bin and the
    ``(bin, verdict)`` of every candidate tried.
    """
    step = -1 if directions[verdict] == "decrease" else 1
    r, current, tried = start_bin, verdict, []
    while current == verdict:
        nxt = r + step
        if not 0 <= nxt < n_bins:
            if literal and step < 0:
                r = -1  # the literal loop reaches r = 0 (1-based), below every bin
            break
        r = nxt
        current = assess(r)
        tried.append((r, current))
        if not literal and current != OK and current < verdict:
            r -= step
            break
    return r, tried


def noise_std(config: ReviserConfig, a_max: float, episode: int) -> float:
    """Std of N(0, V) with ``V = a_max / max(1, K * episode)``, V a variance or a std
    (``noise``; docs/algorithm.md)."""
    v = a_max / max(1.0, config.noise_k * episode)
    return math.sqrt(v) if config.noise == "variance" else v


class PaperReviser(Reviser):
    """Algs. 1-3 on the proposed action, and the revision with its noise: after each
    learning step, in Python, on the e-FSM's transitions and flags."""

    def __init__(self, shield: Shield) -> None:
        super().__init__(shield)
        cfg = shield.config
        self.config = cfg.reviser
        self.directions = [c.direction for c in cfg.criteria]
        # the paper's a_max bounds a range symmetric about 0: the half-width, so that the
        # revision noise follows the width of any range, not where it lies
        self.a_max = (cfg.action.high - cfg.action.low) / 2
        self.rng = np.random.default_rng(cfg.reviser.seed)

    def decide(
        self,
        step: StepInput,
        state: StreamState,
        belief: Belief,
        z: FloatArray,
        recognised: int,
        new_state: bool,
        learned: Learned,
    ) -> Decision:
        decision = self._decide(step, state, belief, recognised, new_state, self.rng)
        assert decision.action is not None
        state.applied_bin = (
            step.action_bin
            if decision.action == step.action
            else actions.encode(decision.action, self.shield.config.action)
        )
        return decision

    def what_if(
        self, step: StepInput, state: StreamState, belief: Belief, z: FloatArray
    ) -> Decision:
        return self._decide(step, state, belief, belief.argmax(), False, copy.deepcopy(self.rng))

    def _decide(
        self,
        step: StepInput,
        state: StreamState,
        belief: Belief,
        recognised: int,
        new_state: bool,
        rng: np.random.Generator,
    ) -> Decision:
        shield, cfg = self.shield, self.config
        proposed = step.action
        assert proposed is not None
        flags = shield.flags
        flagged = flags.flagged()
        spec = shield.config.action

        def assess(action_bin: int) -> tuple[int, float, FloatArray]:
            pred = predict_ahead(
                shield.transitions, belief, action_bin, cfg, shield.config.limits.belief_top_k
            )
            threshold = variant_threshold(pred)
            return inspect(pred, threshold, flagged, cfg.inspect), threshold, pred

        counters = shield.counters
        common: dict[str, Any] = dict(
            proposed=proposed,
            state=recognised,
            n_states=shield.n_states,
            new_state=new_state,
            episode=counters.episodes,
            step=state.step,
            model_version=counters.model_version,
            stream=step.stream,
            shadow=step.shadow,
        )
        if flagged[0].size == 0:
            return Decision(
                action=proposed,
                revised=False,
                reason="cold_start",
                verdict="ok",
                risk=self.no_risk(),
                threshold=None,
                candidates=(),
                suggested=proposed,
                **common,
            )
        start = step.action_bin
        verdict, threshold, pred = assess(start)
        mass = risk(pred, flagged, len(self.names))
        record: dict[str, Any] = dict(
            verdict=self._verdict_name(verdict),
            risk={name: float(m) for name, m in zip(self.names, mass, strict=True)},
            threshold=threshold,
        )
        active = counters.episodes >= cfg.activate_after_episodes
        if verdict == OK or not active:
            return Decision(
                action=proposed,
                revised=False,
                reason="pass" if active else "inactive",
                candidates=(),
                suggested=proposed,
                **record,
                **common,
            )
        final, tried = search(
            start,
            verdict,
            self.directions,
            spec.n_bins,
            cfg.search == "literal",
            lambda r: assess(r)[0],
        )
        noise = float(rng.normal(0.0, noise_std(cfg, self.a_max, counters.episodes)))
        slower = self.directions[verdict] == "decrease"
        revised = min(max(actions.decode(final, spec) + noise, spec.low), spec.high)
        if cfg.one_sided:
            revised = min(revised, proposed) if slower else max(revised, proposed)
        candidates = tuple(
            Candidate(actions.decode(r, spec), r, self._verdict_name(v)) for r, v in tried
        )
        return Decision(
            action=proposed if step.shadow else revised,
            revised=True,
            reason="revised_safety" if slower else "revised_speed",
            candidates=candidates,
            suggested=revised,
            **record,
            **common,
        )

    def _verdict_name(self, verdict: int) -> str:
        return "ok" if verdict == OK else self.names[verdict]

    def snapshot(self) -> dict[str, Any]:
        return {**super().snapshot(), "rng": copy.deepcopy(self.rng.bit_generator.state)}

    def restore(self, data: dict[str, Any]) -> None:
        self.rng.bit_generator.state = data["rng"]
