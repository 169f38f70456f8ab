"""One e-FSM model and its action reviser, driven one step at a time (docs/api.md, "One step").

:class:`Shield` is what the service holds per model: it clusters the observation, recognises
the belief, learns the transition of each stream and flags unfavourable states, and hands the
proposed action to its reviser (:mod:`app.core.revisers`). Many streams share one model; each
stream keeps only its previous step. A step is validated completely before anything changes,
so a refused step leaves no trace. Its snapshot and its views are :mod:`app.core.snapshot`'s
and :mod:`app.core.views`'.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from app.core import actions, revisers, snapshot, views
from app.core.belief import Belief, recognise
from app.core.clustering import NEW, REPLACED, STATES, EvolvingClusterer
from app.core.config import ShieldConfig, TransitionConfig
from app.core.decision import Decision
from app.core.errors import (
    InvalidAction,
    InvalidConfig,
    InvalidObservation,
    ShieldError,
    UnknownCriterion,
)
from app.core.flags import StateFlags
from app.core.history import History
from app.core.lazy_tpm import LazyTransitions
from app.core.observation import ObservationSpace
from app.core.observation import check as check_observation
from app.core.step import Learned, learn_and_decide, observe
from app.core.stream import Counters, StepInput, StreamState
from app.core.tpm import DenseTransitions, TransitionModel

FloatArray = npt.NDArray[np.float64]
# Observations beyond this magnitude are refused: their squares (distances, potentials) would
# overflow float64 long before they could mean anything physical.
MAX_MAGNITUDE = 1e12
# What the compiled step is given in place of a part the configuration lacks (the dense TPM,
# a reviser that decides in Python): empty arrays of the types it expects, never read.
_NO_TRANSITIONS = LazyTransitions(1, TransitionConfig(), 1).arrays()
_NO_INDEX = np.zeros(0, dtype=np.int64)
_NO_FLOATS = np.zeros(0)
_NO_VERDICTS = np.zeros(0, dtype=np.int64)
_NO_RISKS = np.zeros((0, 0))
_NUMBERS = (int, float, np.floating)


class Shield:
    """An evolving finite state machine (e-FSM) with its action reviser."""

    def __init__(self, config: ShieldConfig | None = None) -> None:
        self.config = config if config is not None else ShieldConfig()
        cfg = self.config
        if cfg.transitions.on_replace == "reset" and cfg.limits.tpm_backend == "dense":
            raise InvalidConfig(
                "on_replace='reset' needs the lazy TPM backend", field="transitions.on_replace"
            )
        self.space = ObservationSpace(cfg.observation)
        self._dim = self.space.dim
        self._names = tuple(c.name for c in cfg.criteria)
        self._top_k = cfg.limits.belief_top_k
        self.reset()

    def reset(self) -> None:
        """Forget everything: no states, no streams, counters at zero, a new reviser."""
        cfg = self.config
        self.clusterer = EvolvingClusterer(cfg.clustering, self.space.size, cfg.limits.max_states)
        self.transitions: TransitionModel = self._new_transitions()
        self.flags = StateFlags(
            cfg.reviser.flags, cfg.limits.max_states, len(cfg.criteria), cfg.reviser.flag_min_rate
        )
        self.streams: dict[str, StreamState] = {}  # least recently stepped first
        self._free_slots: list[int] = []  # slots of streams that ended, reused first
        self.counters = Counters(
            interventions={c.name: 0 for c in cfg.criteria},
            failures={c.name: 0 for c in cfg.criteria},
        )
        self.history = History(len(cfg.criteria))
        self.reviser = revisers.make(self)

    def _new_transitions(self) -> TransitionModel:
        cfg = self.config
        q = cfg.action.n_bins
        if cfg.limits.tpm_backend == "dense":
            return DenseTransitions(q, cfg.transitions)
        return LazyTransitions(q, cfg.transitions, cfg.limits.max_states)

    @property
    def n_states(self) -> int:
        """Number of states found so far."""
        return self.clusterer.n_states

    def normalise(self, observation: FloatArray) -> FloatArray:
        """Physical units to the clustering space (:class:`ObservationSpace`)."""
        return self.space.normalise(observation)

    def physical(self, z: FloatArray) -> FloatArray:
        """The clustering space back to physical units (:class:`ObservationSpace`)."""
        return self.space.physical(z)

    # --- one step --------------------------------------------------------------------------

    def step(
        self,
        observation: Sequence[float] | FloatArray,
        action: float | None,
        *,
        stream: str = "0",
        event: str | None = None,
        done: bool = False,
        applied_action: float | None = None,
        learn: bool = True,
        shadow: bool = False,
    ) -> Decision:
        """Learn from one observation and answer the proposed action (docs/api.md, "One step")."""
        return self.apply(
            self.validate(
                observation,
                action,
                stream=stream,
                event=event,
                done=done,
                applied_action=applied_action,
                learn=learn,
                shadow=shadow,
            )
        )

    def validate(
        self,
        observation: Sequence[float] | FloatArray,
        action: float | None,
        *,
        stream: str = "0",
        event: str | None = None,
        done: bool = False,
        applied_action: float | None = None,
        learn: bool = True,
        shadow: bool = False,
    ) -> StepInput:
        """Check a step without changing anything; raise a :class:`ShieldError` naming the field."""
        try:
            z = np.array(observation, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise InvalidObservation(
                "observation must be a list of numbers", field="observation"
            ) from error
        if z.shape != (self._dim,):
            raise InvalidObservation(
                f"observation must hold {self._dim} numbers, got shape {list(z.shape)}",
                field="observation",
            )
        problem = check_observation(z, MAX_MAGNITUDE)
        if problem == 1:
            raise InvalidObservation(
                "observation must be finite (no NaN or infinity)", field="observation"
            )
        if problem == 2:
            raise InvalidObservation(
                f"observation values must lie within +-{MAX_MAGNITUDE:g}", field="observation"
            )
        if not isinstance(stream, str) or not 1 <= len(stream) <= 128:
            raise ShieldError("stream must be a string of 1 to 128 characters", field="stream")
        criterion = None
        if event is not None:
            criterion = self.config.criterion_index(event)
            if criterion is None:
                known = ", ".join(c.name for c in self.config.criteria)
                raise UnknownCriterion(
                    f"unknown criterion {event!r} (known: {known})", field="event"
                )
        if action is None and not done:
            raise InvalidAction("action is required unless done is true", field="action")
        checked = None if action is None else self._check_action(action, "action")
        applied = (
            None if applied_action is None else self._check_action(applied_action, "applied_action")
        )
        spec = self.config.action
        return StepInput(  # positional: on the per-step path
            z,
            checked,
            0 if checked is None else actions.encode(checked, spec),
            stream,
            criterion,
            bool(done),
            -1 if applied is None else actions.encode(applied, spec),
            bool(learn),
            bool(shadow),
        )

    def _check_action(self, value: float, name: str) -> float:
        spec = self.config.action
        if type(value) is not float:  # (the common case, checked first: it is per step)
            if isinstance(value, bool) or not isinstance(value, _NUMBERS):
                raise InvalidAction(f"{name} must be a number", field=name)
            value = float(value)
        if not math.isfinite(value):
            raise InvalidAction(f"{name} must be finite", field=name)
        if not spec.low <= value <= spec.high:
            if spec.out_of_range == "reject":
                raise InvalidAction(
                    f"{name} {value} lies outside [{spec.low}, {spec.high}]", field=name
                )
            value = min(max(value, spec.low), spec.high)
        return value

    def apply(self, step: StepInput) -> Decision:
        """Carry out a validated step: two compiled calls (:mod:`app.core.step`) around what
        only Python does (a new state grows every per-state table), then the reviser's
        decision."""
        if not step.learn:
            return self._what_if(step)
        cfg = self.config
        clusterer = self.clusterer
        n = int(clusterer.counts[STATES])
        if n == clusterer.centres_t.shape[1]:
            clusterer.make_room()
        size = min(n + 1, self._top_k)
        z = np.empty(self.space.size)
        index = np.empty(size, dtype=np.int64)
        prob = np.empty(size)
        # clustering, then Eq. 1 recognition on the states after it
        kind, at, m, recognised = observe(
            step.observation, self.space.arrays(), clusterer.arrays(), self._top_k, index, prob, z
        )
        is_new = kind == NEW
        if is_new:  # a new state expands every TPM
            self._add_state()
        elif kind == REPLACED and cfg.transitions.on_replace == "reset":
            self.transitions.reset_row(at)  # A16
        belief = Belief(index, prob) if m == size else Belief(index[:m], prob[:m])
        state = self._stream(step.stream)
        reviser = self.reviser
        reviser.begin(step, state)
        learned = self._learn(step, state, belief, z, recognised, is_new)
        counters = self.counters
        counters.steps += 1
        counters.model_version += 1
        if step.event is not None:
            counters.failures[self._names[step.event]] += 1

        if step.done:
            counters.episodes += 1
            reviser.end_episode(state)
            self.history.record(self.totals())
            closing = self._closing(step, recognised, is_new, state.step)
            if cfg.transitions.across_episodes:  # A13 literal: the next reset is learned
                state.belief, state.recognised, state.step, state.z = belief, recognised, 0, z
            else:
                self._end_stream(step.stream)
            return closing

        decision = reviser.decide(step, state, belief, z, recognised, is_new, learned)
        state.belief, state.recognised, state.z = belief, recognised, z
        state.proposed_bin = step.action_bin
        state.step += 1
        if decision.revised and not decision.shadow:
            counters.interventions[decision.verdict] += 1
        return decision

    def _learn(
        self,
        step: StepInput,
        state: StreamState,
        belief: Belief,
        z: FloatArray,
        recognised: int,
        is_new: bool,
    ) -> Learned:
        """What the step learns from the stream's previous one (Eqs. 3-4 under the action
        behind the transition; the risk label of the action applied, for a reviser that
        learns one) and the flags of the recognised state, then a compiled reviser's
        decision (:func:`app.core.step.learn_and_decide`)."""
        prev, reviser = state.belief, self.reviser
        transition_bin = self._transition_bin(state, is_new, step.applied_bin)
        risk_bin = -1
        if prev is not None and state.z is not None and reviser.compiled:
            # (a stream restored from a snapshot of the paper's reviser lacks z)
            risk_bin = state.applied_bin if step.applied_bin < 0 else step.applied_bin
        decide = reviser.compiled and not step.done
        by_bin, verdicts = reviser.outputs() if decide else (_NO_RISKS, _NO_VERDICTS)
        tpm = self.transitions
        lazy = tpm if isinstance(tpm, LazyTransitions) else None
        at = (
            recognised,
            state.recognised != recognised,
            -1 if step.event is None else step.event,
            step.done,
            state.slot,
            transition_bin if lazy is not None else -1,
            risk_bin,
            decide,
            step.action_bin,
        )
        while True:
            out = learn_and_decide(
                _NO_TRANSITIONS if lazy is None else lazy.arrays(),
                self.flags.arrays(),
                reviser.step_arrays(),
                _NO_INDEX if prev is None else prev.index,
                _NO_FLOATS if prev is None else prev.prob,
                _NO_FLOATS if state.z is None else state.z,
                belief.index,
                belief.prob,
                z,
                at,
                by_bin,
                verdicts,
            )
            if not out[0]:
                break
            assert lazy is not None
            lazy.compact(out[0])
        if lazy is None and transition_bin >= 0:
            assert prev is not None
            self.transitions.learn_one(prev, transition_bin, belief)
        if out[1]:
            self.flags.changed()
        return Learned(*out, by_bin, verdicts)

    def _transition_bin(self, state: StreamState, is_new: bool, applied_bin: int) -> int:
        """The action behind the stream's transition into this step, or -1 when none is
        learned."""
        cfg = self.config.transitions
        if state.belief is None:
            return -1  # first step of an episode: no tau (A13)
        if is_new and cfg.on_new_state == "skip":
            return -1  # A3 (a): tau and gamma have different sizes
        # (A3 (b) pads tau with a 0 for the new state: implicit in the sparse belief)
        if applied_bin >= 0:
            return applied_bin
        if cfg.action_source == "executed":  # A8
            return state.applied_bin
        return state.proposed_bin  # A8 literal: the controller's proposal

    def _stream(self, name: str) -> StreamState:
        """The stream's state, now its most recent; a new stream beyond ``max_streams``
        makes the model forget the least recently used one (as if its episode had ended)."""
        state = self.streams.pop(name, None)
        if state is None:
            if len(self.streams) >= self.config.limits.max_streams:
                self._end_stream(next(iter(self.streams)))
                self.counters.streams_expired += 1
            state = StreamState(self._new_slot())
        self.streams[name] = state
        return state

    def _new_slot(self) -> int:
        """A free slot in the tables kept per stream: one a stream left, else the next."""
        slot = (
            self._free_slots.pop()
            if self._free_slots
            else (len(self.streams) + len(self._free_slots))
        )
        self.reviser.reserve(slot)
        return slot

    def _end_stream(self, name: str) -> None:
        """Forget a stream (its episode ended, or it expired); its slot is free again."""
        slot = self.streams.pop(name).slot
        self.reviser.forget(name, slot)
        self._free_slots.append(slot)

    def _add_state(self) -> None:
        """A state was created: every per-state table grows by one."""
        self.transitions.add_state()
        self.flags.add_state()
        self.reviser.add_state()

    def _what_if(self, step: StepInput) -> Decision:
        """``learn=False``: answer from the model as it is, changing nothing (noise included)."""
        state = self.streams.get(step.stream) or StreamState(-1)
        if self.n_states == 0:
            if step.done:
                return self._closing(step, None, False, state.step)
            return Decision(
                action=step.action,
                proposed=step.action,
                revised=False,
                reason="cold_start",
                verdict="ok",
                risk=self.reviser.no_risk(),
                threshold=None,
                candidates=(),
                state=None,
                n_states=0,
                new_state=False,
                episode=self.counters.episodes,
                step=state.step,
                model_version=self.counters.model_version,
                stream=step.stream,
                shadow=step.shadow,
                suggested=step.action,
            )
        z = self.normalise(step.observation)
        belief = recognise(
            self.clusterer.sq_distances(z),
            self.clusterer.variances(),
            self.config.limits.belief_top_k,
        )
        if step.done:
            return self._closing(step, belief.argmax(), False, state.step)
        return self.reviser.what_if(step, state, belief, z)

    def _closing(
        self, step: StepInput, recognised: int | None, is_new: bool, index: int
    ) -> Decision:
        return Decision(
            action=None,
            proposed=step.action,
            revised=False,
            reason="done",
            verdict="ok",
            risk=self.reviser.no_risk(),
            threshold=None,
            candidates=(),
            state=recognised,
            n_states=self.n_states,
            new_state=is_new,
            episode=self.counters.episodes,
            step=index,
            model_version=self.counters.model_version,
            stream=step.stream,
            shadow=step.shadow,
            suggested=None,
        )

    def totals(self) -> list[int]:
        """The model's totals now, in the columns of :class:`~app.core.history.History`."""
        c = self.counters
        return [
            c.episodes,
            c.steps,
            self.n_states,
            *(c.interventions[n] for n in self._names),
            *(c.failures[n] for n in self._names),
        ]

    # --- views and persistence (:mod:`app.core.views`, :mod:`app.core.snapshot`) -----------

    def states(self) -> dict[str, Any]:
        """Every state, as arrays (:func:`app.core.views.states`)."""
        return views.states(self)

    def state_view(self, index: int) -> dict[str, Any]:
        """One state, as plain data (:func:`app.core.views.state`)."""
        return views.state(self, index)

    def failure_points(self) -> dict[str, FloatArray]:
        """Where the reviser keeps each criterion's failures
        (:func:`app.core.views.failure_points`)."""
        return views.failure_points(self)

    def history_view(self) -> dict[str, Any]:
        """The totals at the end of episodes (:func:`app.core.views.history`)."""
        return views.history(self)

    def next_states(self, index: int, top: int = 5) -> list[list[tuple[int, float]]]:
        """For each action, the ``top`` most likely next states of ``index`` (row of Eq. 2)."""
        return views.next_states(self, index, top)

    def snapshot(self) -> dict[str, Any]:
        """Everything the model is, as plain data and numpy arrays (:mod:`app.core.snapshot`)."""
        return snapshot.take(self)

    @classmethod
    def from_snapshot(
        cls, data: dict[str, Any], check: Callable[[ShieldConfig], None] | None = None
    ) -> Shield:
        """Rebuild a shield that makes exactly the decisions the original would make
        (:func:`app.core.snapshot.restore`; ``check``, a server's bounds, judges the
        configuration before any array is built)."""
        return snapshot.restore(cls, data, check)
