"""The risk reviser (``reviser.method: risk``, the default): each action's probability that any
failure follows, from the local risk model and the reach (:mod:`app.core.local_risk`,
:mod:`app.core.reach`, the rule of :mod:`app.core.risk`), decided inside the compiled step; the
shield's own record of its revisions (:mod:`app.core.record`) and its trial of itself over whole
episodes (:mod:`app.core.trial`) decide whether a revision is applied.

A decision keeps the proposal unless its total risk is over the threshold and beyond the margin
of the safest action's; then the nearest allowed bin, at its midpoint (an end bin at the range's
end). Before any failure was learned every risk is 0: a cold start.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt

from app.core import actions, reach
from app.core.belief import Belief
from app.core.decision import Candidate, Decision, RiskCandidates
from app.core.local_risk import LocalRisk
from app.core.record import PASSED, REVISED, Record
from app.core.revisers.base import Reviser
from app.core.risk import safe_steps
from app.core.step import Learned
from app.core.stream import StepInput, StreamState
from app.core.trial import AUDITED, LONGEST, NONE, Trial

if TYPE_CHECKING:
    from app.core.shield import Shield

FloatArray = npt.NDArray[np.float64]


class RiskReviser(Reviser):
    """The local risk model and the reach, the record and the trial, of one e-FSM."""

    compiled = True

    def __init__(self, shield: Shield) -> None:
        super().__init__(shield)
        cfg = shield.config
        self.config = cfg.risk
        self.activate_after = cfg.reviser.activate_after_episodes
        self.seed = cfg.reviser.seed
        self.safe = safe_steps([c.direction for c in cfg.criteria])
        spec = cfg.action
        # a bin is applied at its midpoint, the end bins at the range's ends: a criterion's
        # safest action is the end of the range (not half a bin short of it)
        self.bin_actions = [
            spec.low,
            *(actions.decode(r, spec) for r in range(1, spec.n_bins - 1)),
            spec.high,
        ]
        self.verdicts_named = (*self.names, "ok")  # a verdict's name by its index (-1: ok)
        self.local_risk = LocalRisk(
            shield.space.size,
            len(cfg.criteria),
            spec.n_bins,
            cfg.risk.horizon,
            cfg.limits.max_states,
            cfg.limits.belief_top_k,
            cfg.limits.max_streams,
            cfg.risk.reach_horizon,
            cfg.risk.reach_radius,
            self._bounds(),
        )
        # a failure counts against a decision within the farther of the two horizons
        self.record = Record(max(cfg.risk.horizon, cfg.risk.reach_horizon))
        self.trial = Trial(self.seed)
        self._parts: tuple[Any, ...] = ()
        self._arrays: tuple[Any, ...] = ()

    def _bounds(self) -> FloatArray:
        """The criteria's bounds in the clustering space (:func:`app.core.reach.no_bounds`'s
        layout)."""
        cfg, space = self.shield.config, self.shield.space
        bounds = reach.no_bounds(len(cfg.criteria))
        for c, criterion in enumerate(cfg.criteria):
            bound = criterion.bound
            if bound is None:
                continue
            dimension = cfg.observation.names.index(bound.observation)
            bounds[c, 0] = dimension
            if bound.below is not None:
                bounds[c, 1] = space.along(dimension, bound.below)
            if bound.above is not None:
                bounds[c, 2] = space.along(dimension, bound.above)
        return bounds

    # --- a step ----------------------------------------------------------------------------

    def step_arrays(self) -> tuple[Any, ...]:
        parts = self.local_risk.arrays()
        if parts is not self._parts:
            cfg = self.config
            self._parts = parts
            self._arrays = (parts, self.safe, float(cfg.threshold), float(cfg.margin))
        return self._arrays

    def begin(self, step: StepInput, state: StreamState) -> None:
        """The stream's episode in the trial (:mod:`app.core.trial`): its arm drawn on its
        first step, once a failure was learned and an episode has ended (and the reviser is
        active); an audit ended when it runs too long; a failure noted, and the record's
        pending steps settled by a failure or the episode's end."""
        counters = self.shield.counters
        if state.step == 0:
            state.arm, state.failed = NONE, False
            if (
                not step.done
                and counters.episodes > 0
                and self.local_risk.any_failure
                and counters.episodes >= self.activate_after
            ):
                state.arm = self.trial.draw(counters.steps)
        elif state.arm == AUDITED and state.step > LONGEST * counters.steps / max(
            counters.episodes, 1
        ):
            state.arm = NONE
        if step.event is not None:
            state.failed = True
        if step.event is not None or step.done:
            self.record.settle(step.stream, step.event is not None)

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
        """The decision the compiled step made (``learned``), as a record; the step noted in
        the record unless the episode is audited."""
        decision = self._record(step, state, learned, recognised, new_state)
        action = decision.action
        state.applied_bin = step.action_bin if action == step.action else learned.final
        if state.arm != AUDITED:  # (an audited episode is the trial's)
            spared = 1.0
            for value in decision.risk.values():
                spared *= 1.0 - value
            self.record.note(step.stream, recognised, action != step.action, 1.0 - spared)
        return decision

    def what_if(
        self, step: StepInput, state: StreamState, belief: Belief, z: FloatArray
    ) -> Decision:
        """The decision on a step that learns nothing, in its own compiled call."""
        local = self.local_risk
        by_bin, verdicts = self.outputs()
        decided = local.any_failure
        limit, worst, final, kept = (
            local.decide(
                belief,
                z,
                step.action_bin,
                self.config.threshold,
                self.config.margin,
                self.safe,
                by_bin,
                verdicts,
            )
            if decided
            else (0.0, 0, 0, False)
        )
        learned = Learned(0, False, decided, limit, worst, final, kept, by_bin, verdicts)
        return self._record(step, state, learned, belief.argmax(), False)

    def _record(
        self,
        step: StepInput,
        state: StreamState,
        learned: Learned,
        recognised: int,
        new_state: bool,
    ) -> Decision:
        """The decision record of the rule's outcome (:func:`app.core.risk.decide`):
        the proposal, unless the rule revised it and the episode is not audited nor the
        record backs off here (``suggested`` then says what it would have applied)."""
        proposed = step.action
        assert proposed is not None
        names, by_bin, final = self.names, learned.by_bin, learned.final
        action = suggested = proposed
        candidates: Sequence[Candidate] = ()
        revised = False
        threshold: float | None = None
        counters = self.shield.counters
        if not learned.decided:
            risks, verdict, reason = self.no_risk(), "ok", "cold_start"
        else:
            start = step.action_bin
            threshold = learned.threshold
            risks = {name: by_bin.item(start, c) for c, name in enumerate(names)}
            verdict = "ok" if learned.kept else names[learned.worst]
            if counters.episodes < self.activate_after:
                reason = "inactive"
            elif learned.kept:
                reason = "pass"
            elif state.arm == AUDITED:
                # an episode the shield leaves to the controller, to compare (app.core.trial)
                suggested, reason = self.bin_actions[final], "audit"
            elif self.record.backs_off(recognised):
                # its revisions here were followed by more failures than the proposals
                suggested, reason = self.bin_actions[final], "backed_off"
            else:
                way = 1 if final > start else -1
                candidates = RiskCandidates(
                    range(start + way, final + way, way),
                    by_bin,
                    learned.verdicts,
                    names,
                    self.bin_actions,
                    self.verdicts_named,
                )
                suggested = self.bin_actions[final]
                action = proposed if step.shadow else suggested
                reason = "revised_safety" if final < start else "revised_speed"
                revised = True
        return Decision(  # positional: on the per-step path, and half the cost of keywords
            action,
            proposed,
            revised,
            reason,
            verdict,
            risks,
            threshold,
            candidates,
            recognised,
            self.shield.n_states,
            new_state,
            counters.episodes,
            state.step,
            counters.model_version,
            step.stream,
            step.shadow,
            suggested,
        )

    def end_episode(self, state: StreamState) -> None:
        self.trial.count(state.arm, state.failed)

    # --- the model's tables ----------------------------------------------------------------

    def add_state(self) -> None:
        self.local_risk.add_state()
        self.record.add_state()

    def reserve(self, slot: int) -> None:
        self.local_risk.reserve(slot)

    def forget(self, stream: str, slot: int) -> None:
        self.local_risk.forget(slot)
        self.record.forget(stream)

    # --- snapshot --------------------------------------------------------------------------

    def snapshot(self) -> dict[str, Any]:
        slots = {name: s.slot for name, s in self.shield.streams.items()}
        return {
            **super().snapshot(),
            "local_risk": self.local_risk.snapshot(slots),
            "record": self.record.snapshot(),
            "trial": self.trial.snapshot(),
        }

    def restore(self, data: dict[str, Any]) -> None:
        """The local model, the record and the trial (a snapshot of format 3 also holds the
        counts of a model removed since, which this version does not read; one from before
        the record or the trial: nothing recorded, nothing counted)."""
        shield = self.shield
        n, streams = shield.n_states, shield.streams
        slots = {name: s.slot for name, s in streams.items()}
        self.local_risk = LocalRisk.restore(self.local_risk, n, slots, data["local_risk"])
        self.record = Record.restore(self.record.window, n, streams, data.get("record"))
        self.trial = Trial.restore(self.seed, data.get("trial"), shield.counters.episodes)

    def counted(self) -> list[tuple[str, float]]:
        def total(counts: npt.NDArray[np.int64]) -> float:  # (in floats: no sum overflows)
            return float(counts.sum(dtype=np.float64))

        return [
            ("local_risk.tried", total(self.local_risk.tried)),
            ("local_risk.failures", total(self.local_risk.failures)),
            ("record.counts", total(self.record.counts[:, [REVISED, PASSED]])),
        ]

    # --- views -----------------------------------------------------------------------------

    def record_counts(self) -> npt.NDArray[np.int64]:
        return self.record.counts.copy()

    def backed_off(self) -> npt.NDArray[np.bool_]:
        return self.record.backed_off()

    def backs_off(self, state: int) -> bool:
        return self.record.backs_off(state)

    def failure_points(self, criterion: int) -> FloatArray:
        if self.config.reach_horizon == 0:
            return super().failure_points(criterion)
        return self.local_risk.failure_points(criterion)

    def trial_view(self) -> dict[str, dict[str, int]]:
        return self.trial.view()
