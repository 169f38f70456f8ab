"""One e-FSM model and its action reviser, driven one step at a time (docs/api.md, "One step").

:class:`Shield` is what the service holds per model: it clusters the observation, recognises
the belief, learns the transition of each stream, flags unfavourable states and revises the
proposed action. Many streams share one model; each stream keeps only its previous step. A
step is validated completely before anything changes, so a refused step leaves no trace.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np
import numpy.typing as npt

from app.core import _stored as stored
from app.core import actions, reach, reviser, risk
from app.core.belief import Belief, recognise
from app.core.clustering import NEW, REPLACED, STATES, EvolvingClusterer
from app.core.config import ShieldConfig, TransitionConfig
from app.core.errors import (
    InvalidAction,
    InvalidConfig,
    InvalidObservation,
    InvalidSnapshot,
    ShieldError,
    UnknownCriterion,
)
from app.core.flags import StateFlags
from app.core.history import EPISODES, N_STATES, STEPS, TOTALS, History
from app.core.lazy_tpm import LazyTransitions
from app.core.local_risk import LocalRisk
from app.core.observation import ObservationSpace
from app.core.observation import check as check_observation
from app.core.record import COLUMNS as RECORD_COLUMNS
from app.core.record import PASSED, REVISED, Record
from app.core.step import learn_and_decide, observe
from app.core.tpm import DenseTransitions, TransitionModel
from app.core.trial import AUDITED, LONGEST, NONE, Trial

FloatArray = npt.NDArray[np.float64]
SNAPSHOT_FORMAT = 4
# Observations beyond this magnitude are refused: their squares (distances, potentials) would
# overflow float64 long before they could mean anything physical.
MAX_MAGNITUDE = 1e12
# What the compiled step is given in place of a part the configuration lacks (the dense TPM,
# the paper's reviser): empty arrays of the types it expects, never read.
_NO_TRANSITIONS = LazyTransitions(1, TransitionConfig(), 1).arrays()
_NO_RISK = LocalRisk(1, 1, 1, 1, 1, 1, 1).arrays()
_NO_INDEX = np.zeros(0, dtype=np.int64)
_NO_FLOATS = np.zeros(0)
_NO_VERDICTS = np.zeros(0, dtype=np.int64)
_NO_RISKS = np.zeros((0, 0))
_NUMBERS = (int, float, np.floating)


@dataclass(slots=True)
class Candidate:
    """An action the reviser inspected: the bin's action (the paper's reviser: its midpoint;
    the risk reviser: the midpoint, the range's end for an end bin), the bin, its verdict and
    (for the risk reviser) its risk per criterion."""

    action: float
    bin: int
    verdict: str
    risk: dict[str, float] | None = None


class RiskCandidates(Sequence[Candidate]):
    """The bins the risk reviser passed over, from the proposal's neighbour to the bin
    applied, built on first use from the step's risk and verdict per bin (most callers never
    read them). ``bin_actions`` are the bins' actions and ``verdicts_named`` the criteria's
    names then ``"ok"``, so that a verdict (-1: ok) indexes its name."""

    def __init__(
        self,
        bins: range,
        by_bin: FloatArray,
        verdicts: npt.NDArray[np.int64],
        names: Sequence[str],
        bin_actions: Sequence[float],
        verdicts_named: Sequence[str],
    ) -> None:
        self._bins, self._by_bin, self._verdicts = bins, by_bin, verdicts
        self._names, self._actions, self._verdicts_named = names, bin_actions, verdicts_named
        self._built: tuple[Candidate, ...] | None = None

    def _all(self) -> tuple[Candidate, ...]:
        if self._built is None:
            self._built = tuple(Candidate(**record) for record in self.records())
        return self._built

    def records(self) -> list[dict[str, Any]]:
        """The candidates as JSON-able records (what :meth:`Decision.to_dict` writes), made
        straight from the arrays: the service's per-step path."""
        names, rows, verdicts = self._names, self._by_bin.tolist(), self._verdicts.tolist()
        bin_actions, named = self._actions, self._verdicts_named
        return [
            {
                "action": bin_actions[r],
                "bin": r,
                "verdict": named[verdicts[r]],
                "risk": {name: risk for name, risk in zip(names, rows[r], strict=True)},
            }
            for r in self._bins
        ]  # (a comprehension builds a small dict faster than dict())

    def __iter__(self) -> Iterator[Candidate]:
        return iter(self._all())

    @overload
    def __getitem__(self, i: int) -> Candidate: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Candidate, ...]: ...

    def __getitem__(self, i: int | slice) -> Candidate | tuple[Candidate, ...]:
        return self._all()[i]

    def __len__(self) -> int:
        return len(self._bins)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Sequence) and self._all() == tuple(other)

    def __repr__(self) -> str:
        return repr(self._all())


@dataclass(slots=True)
class Decision:
    """The decision record of one step (docs/api.md). Built on every step, so a plain slotted
    record: a frozen dataclass's constructor costs about three times as much."""

    action: float | None
    proposed: float | None
    revised: bool
    reason: str
    verdict: str
    risk: dict[str, float]
    threshold: float | None
    candidates: Sequence[Candidate]
    state: int | None
    n_states: int
    new_state: bool
    episode: int
    step: int
    model_version: int
    stream: str
    shadow: bool = False
    suggested: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-able data, written out by hand: this is on the service's per-step path."""
        return {
            "action": self.action,
            "proposed": self.proposed,
            "revised": self.revised,
            "reason": self.reason,
            "verdict": self.verdict,
            "risk": self.risk,
            "threshold": self.threshold,
            "candidates": (
                self.candidates.records()
                if isinstance(self.candidates, RiskCandidates)
                else [
                    {"action": c.action, "bin": c.bin, "verdict": c.verdict, "risk": c.risk}
                    for c in self.candidates
                ]
            ),
            "state": self.state,
            "n_states": self.n_states,
            "new_state": self.new_state,
            "episode": self.episode,
            "step": self.step,
            "model_version": self.model_version,
            "stream": self.stream,
            "shadow": self.shadow,
            "suggested": self.suggested,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Decision:
        """The inverse of :meth:`to_dict`."""
        fields = dict(data)
        fields["candidates"] = tuple(Candidate(**c) for c in data["candidates"])
        return cls(**fields)


@dataclass(slots=True)
class StepInput:
    """A validated step: what :meth:`Shield.apply` consumes (made on every step: a plain
    slotted record, not a frozen one, whose constructor costs several times as much)."""

    observation: FloatArray
    action: float | None
    action_bin: int  # the proposal's bin (0 without a proposal)
    stream: str
    event: int | None
    done: bool
    applied_bin: int  # the bin of the action the controller applied, if it says (-1: not)
    learn: bool
    shadow: bool


@dataclass
class StreamState:
    """What a stream remembers between its steps: tau and the action behind the transition,
    and its slot in the tables kept per stream (the local risk model's unlabelled steps)."""

    slot: int
    belief: Belief | None = None
    applied_bin: int = 0
    proposed_bin: int = 0
    step: int = 0
    recognised: int = -1  # the belief's most likely state, -1 without a belief
    z: FloatArray | None = None  # the normalised observation behind ``belief``
    arm: int = NONE  # the episode's arm in the shield's trial of itself (:mod:`app.core.trial`)
    failed: bool = False  # whether a failure happened in the episode so far


@dataclass
class Counters:
    """Totals of a model's life."""

    steps: int = 0
    episodes: int = 0
    model_version: int = 0
    interventions: dict[str, int] = field(default_factory=dict)
    failures: dict[str, int] = field(default_factory=dict)  # events learned, per criterion
    streams_expired: int = 0  # streams forgotten to stay within max_streams


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
        self._directions = [c.direction for c in cfg.criteria]
        self._safe_steps = risk.safe_steps(self._directions)
        self._names = tuple(c.name for c in cfg.criteria)
        self._verdicts_named = (*self._names, "ok")  # a verdict's name by its index (-1: ok)
        # the risk reviser applies a bin at its midpoint, the end bins at the range's ends: a
        # criterion's safest action is the end of the range (not half a bin short of it)
        spec = cfg.action
        self._bin_actions = [
            spec.low,
            *(actions.decode(r, spec) for r in range(1, spec.n_bins - 1)),
            spec.high,
        ]
        # the reviser's decision on a proposal: the risk reviser's (the default) or the paper's
        self._by_risk = cfg.reviser.method == "risk"
        self._decide = self._decide_by_risk if self._by_risk else self._decide_by_flags
        self._top_k = cfg.limits.belief_top_k
        self._risk_shape = (cfg.action.n_bins, len(self._names))  # actions x criteria
        # the paper's a_max bounds a range symmetric about 0: the half-width, so that the
        # revision noise follows the width of any range, not where it lies
        self._a_max = (cfg.action.high - cfg.action.low) / 2
        self.reset()

    def reset(self) -> None:
        """Forget everything: no states, no streams, counters at zero, the seed's generator."""
        cfg = self.config
        self.clusterer = EvolvingClusterer(cfg.clustering, self.space.size, cfg.limits.max_states)
        self.transitions: TransitionModel = self._new_transitions()
        self.flags = StateFlags(
            cfg.reviser.flags, cfg.limits.max_states, len(cfg.criteria), cfg.reviser.flag_min_rate
        )
        self.local_risk = self._new_local_risk()
        self.record = Record(self._record_window())
        self.trial = Trial(cfg.reviser.seed)
        self.streams: dict[str, StreamState] = {}  # least recently stepped first
        self._free_slots: list[int] = []  # slots of streams that ended, reused first
        self._model_arrays: tuple[Any, ...] = ()  # see _arrays
        self._parts: tuple[Any, ...] = ()  # the parts' arrays it was gathered from
        self.counters = Counters(
            interventions={c.name: 0 for c in cfg.criteria},
            failures={c.name: 0 for c in cfg.criteria},
        )
        self.history = History(len(cfg.criteria))
        self._rng = np.random.default_rng(cfg.reviser.seed)

    def _new_local_risk(self) -> LocalRisk | None:
        cfg = self.config
        if cfg.reviser.method != "risk":
            return None
        return LocalRisk(
            self.space.size,
            len(cfg.criteria),
            cfg.action.n_bins,
            cfg.risk.horizon,
            cfg.limits.max_states,
            cfg.limits.belief_top_k,
            cfg.limits.max_streams,
            cfg.risk.reach_horizon,
            cfg.risk.reach_radius,
            self._bounds(),
        )

    def _record_window(self) -> int:
        """The steps within which a failure counts against a decision in the shield's own
        record (:mod:`app.core.record`): the farther of the risk's horizon and the reach's."""
        return max(self.config.risk.horizon, self.config.risk.reach_horizon)

    def _bounds(self) -> FloatArray:
        """The criteria's bounds in the clustering space (:func:`app.core.reach.no_bounds`'s
        layout)."""
        cfg = self.config
        bounds = reach.no_bounds(len(cfg.criteria))
        for c, criterion in enumerate(cfg.criteria):
            bound = criterion.bound
            if bound is None:
                continue
            dimension = cfg.observation.names.index(bound.observation)
            bounds[c, 0] = dimension
            if bound.below is not None:
                bounds[c, 1] = self.space.along(dimension, bound.below)
            if bound.above is not None:
                bounds[c, 2] = self.space.along(dimension, bound.above)
        return bounds

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
        only Python does (a new state grows every per-state table)."""
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
        space = self.space
        kind, at, m, recognised = observe(
            step.observation,
            space.raw,
            space.scales,
            space.features,
            z,
            *clusterer.arrays(),
            self._top_k,
            index,
            prob,
        )
        is_new = kind == NEW
        if is_new:  # a new state expands every TPM
            self._add_state()
        elif kind == REPLACED and cfg.transitions.on_replace == "reset":
            self.transitions.reset_row(at)  # A16
        belief = Belief(index, prob) if m == size else Belief(index[:m], prob[:m])
        state = self._stream(step.stream)
        if self._by_risk:
            self._enter_trial(state, step)
            if step.event is not None or step.done:
                self.record.settle(step.stream, step.event is not None)
        decide = self._by_risk and not step.done
        by_bin, verdicts = _NO_RISKS, _NO_VERDICTS
        if decide:
            by_bin = np.empty(self._risk_shape)
            verdicts = np.empty(self._risk_shape[0], dtype=np.int64)
        decided, limit, worst, final, kept = self._learn(
            step, state, belief, z, recognised, is_new, decide, by_bin, verdicts
        )
        self.counters.steps += 1
        self.counters.model_version += 1
        if step.event is not None:
            self.counters.failures[self._names[step.event]] += 1

        if step.done:
            self.counters.episodes += 1
            self.trial.count(state.arm, state.failed)
            self.history.record(self._totals())
            closing = self._closing(step, recognised, is_new, state.step)
            if cfg.transitions.across_episodes:  # A13 literal: the next reset is learned
                state.belief, state.recognised, state.step, state.z = belief, recognised, 0, z
            else:
                self._end_stream(step.stream)
            return closing

        if self._by_risk:
            decision = self._risk_decision(
                step,
                by_bin,
                verdicts,
                decided,
                limit,
                worst,
                final,
                kept,
                recognised,
                is_new,
                state.step,
            )
        else:
            decision = self._decide_by_flags(
                step, z, belief, recognised, is_new, state.step, self._rng
            )
        assert decision.action is not None and step.action is not None
        state.belief, state.recognised, state.z = belief, recognised, z
        state.proposed_bin = step.action_bin
        if decision.action == step.action:
            state.applied_bin = step.action_bin
        elif self._by_risk:  # the bin it chose (at its action, ``_bin_actions``)
            state.applied_bin = final
        else:
            state.applied_bin = actions.encode(decision.action, cfg.action)
        state.step += 1
        if self._by_risk and state.arm != AUDITED:  # (an audited episode is the trial's)
            spared = 1.0
            for value in decision.risk.values():
                spared *= 1.0 - value
            self.record.note(step.stream, recognised, decision.action != step.action, 1.0 - spared)
        if decision.revised and not decision.shadow:
            self.counters.interventions[decision.verdict] += 1
        return decision

    def _learn(
        self,
        step: StepInput,
        state: StreamState,
        belief: Belief,
        z: FloatArray,
        recognised: int,
        is_new: bool,
        decide: bool,
        by_bin: FloatArray,
        verdicts: npt.NDArray[np.int64],
    ) -> tuple[bool, float, int, int, bool]:
        """What the step learns from the stream's previous one (Eqs. 3-4 under the action
        behind the transition; the risk label of the action applied, :mod:`app.core.local_risk`,
        the risk reviser's only) and the flags of the recognised state, then, if ``decide``,
        the risk reviser's decision: whether it decided (a failure was learned), and the
        decision (:func:`app.core.risk.decide`)."""
        prev = state.belief
        transition_bin = self._transition_bin(state, is_new, step.applied_bin)
        risk_bin = -1
        if prev is not None and state.z is not None and self.local_risk is not None:
            # (a stream restored from a snapshot of the paper's reviser lacks z)
            risk_bin = state.applied_bin if step.applied_bin < 0 else step.applied_bin
        tpm = self.transitions
        lazy = isinstance(tpm, LazyTransitions)
        while True:
            needed, changed, decided, limit, worst, final, kept = learn_and_decide(
                *self._arrays(),  # type: ignore[call-arg]  # (mypy cannot count a star-tuple)
                _NO_INDEX if prev is None else prev.index,
                _NO_FLOATS if prev is None else prev.prob,
                _NO_FLOATS if state.z is None else state.z,
                belief.index,
                belief.prob,
                z,
                recognised,
                state.recognised != recognised,
                -1 if step.event is None else step.event,
                step.done,
                state.slot,
                transition_bin if lazy else -1,
                risk_bin,
                decide,
                step.action_bin,
                by_bin,
                verdicts,
            )
            if not needed:
                break
            assert isinstance(tpm, LazyTransitions)
            tpm.compact(needed)
        if not lazy and transition_bin >= 0:
            assert prev is not None
            self.transitions.learn_one(prev, transition_bin, belief)
        if changed:
            self.flags.changed()
        return decided, limit, worst, final, kept

    def _enter_trial(self, state: StreamState, step: StepInput) -> None:
        """The stream's episode in the shield's trial of itself (:mod:`app.core.trial`): its
        arm drawn on its first step, once a failure was learned and an episode has ended (and
        the reviser is active); an audit ended when it runs too long; a failure noted."""
        counters = self.counters
        if state.step == 0:
            state.arm, state.failed = NONE, False
            local = self.local_risk
            if (
                not step.done
                and counters.episodes > 0
                and local is not None
                and local.any_failure
                and counters.episodes >= self.config.reviser.activate_after_episodes
            ):
                state.arm = self.trial.draw(counters.steps)
        elif state.arm == AUDITED and state.step > LONGEST * counters.steps / max(
            counters.episodes, 1
        ):
            state.arm = NONE
        if step.event is not None:
            state.failed = True

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
        if self.local_risk is not None:
            self.local_risk.reserve(slot)
        return slot

    def _end_stream(self, name: str) -> None:
        """Forget a stream (its episode ended, or it expired); its slot is free again."""
        slot = self.streams.pop(name).slot
        if self.local_risk is not None:
            self.local_risk.forget(slot)
        self.record.forget(name)
        self._free_slots.append(slot)

    def _add_state(self) -> None:
        """A state was created: every per-state table grows by one."""
        self.transitions.add_state()
        self.flags.add_state()
        if self.local_risk is not None:
            self.local_risk.add_state()
            self.record.add_state()

    def _arrays(self) -> tuple[Any, ...]:
        """The settings and arrays :func:`~app.core.step.learn_and_decide` takes before the
        step's own: gathered again only when a part hands out other arrays (a state added,
        the TPM pool compacted, a stream's slot reserved)."""
        tpm, local = self.transitions, self.local_risk
        parts = (
            tpm.arrays() if isinstance(tpm, LazyTransitions) else _NO_TRANSITIONS,
            _NO_RISK if local is None else local.arrays(),
            self.flags.arrays(),
        )
        old = self._parts
        if not old or parts[0] is not old[0] or parts[1] is not old[1] or parts[2] is not old[2]:
            cfg = self.config
            self._parts = parts
            self._model_arrays = (
                cfg.transitions.learning_rate,
                *parts[0],
                cfg.risk.horizon,
                *parts[1],
                *parts[2],
                cfg.reviser.flags == "rate",
                cfg.reviser.flag_min_rate,
                self._safe_steps,
                cfg.risk.threshold,
                cfg.risk.margin,
                0 if local is None else cfg.risk.reach_horizon,
                cfg.risk.reach_radius,
            )
        return self._model_arrays

    def _what_if(self, step: StepInput) -> Decision:
        """``learn=False``: answer from the model as it is, changing nothing (noise included)."""
        state = self.streams.get(step.stream) or StreamState(-1)
        if self.n_states == 0:
            return (
                self._closing(step, None, False, state.step)
                if step.done
                else Decision(
                    action=step.action,
                    proposed=step.action,
                    revised=False,
                    reason="cold_start",
                    verdict="ok",
                    risk=self._risk(None),
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
            )
        z = self.normalise(step.observation)
        belief = recognise(
            self.clusterer.sq_distances(z),
            self.clusterer.variances(),
            self.config.limits.belief_top_k,
        )
        if step.done:
            return self._closing(step, belief.argmax(), False, state.step)
        rng = copy.deepcopy(self._rng)
        return self._decide(step, z, belief, belief.argmax(), False, state.step, rng)

    def _closing(
        self, step: StepInput, recognised: int | None, is_new: bool, index: int
    ) -> Decision:
        return Decision(
            action=None,
            proposed=step.action,
            revised=False,
            reason="done",
            verdict="ok",
            risk=self._risk(None),
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

    def _risk(self, pred: FloatArray | None) -> dict[str, float]:
        names = [c.name for c in self.config.criteria]
        if pred is None:
            return dict.fromkeys(names, 0.0)
        mass = reviser.risk(pred, self.flags.flagged(), len(names))
        return {name: float(m) for name, m in zip(names, mass, strict=True)}

    def _decide_by_flags(
        self,
        step: StepInput,
        z: FloatArray,
        belief: Belief,
        recognised: int,
        is_new: bool,
        index: int,
        rng: np.random.Generator,
    ) -> Decision:
        """Algs. 1-3 on the proposed action, and the revision with its noise (``z``, the
        normalised observation, is for the risk reviser's local model)."""
        cfg = self.config
        proposed = step.action
        assert proposed is not None
        flagged = self.flags.flagged()
        q = cfg.action.n_bins

        def assess(action_bin: int) -> tuple[int, float, FloatArray]:
            pred = reviser.predict_ahead(
                self.transitions, belief, action_bin, cfg.reviser, cfg.limits.belief_top_k
            )
            threshold = reviser.variant_threshold(pred)
            verdict = reviser.inspect(pred, threshold, flagged, cfg.reviser.inspect)
            return verdict, threshold, pred

        common: dict[str, Any] = dict(
            proposed=proposed,
            state=recognised,
            n_states=self.n_states,
            new_state=is_new,
            episode=self.counters.episodes,
            step=index,
            model_version=self.counters.model_version,
            stream=step.stream,
            shadow=step.shadow,
        )
        if flagged[0].size == 0:
            return Decision(
                action=proposed,
                revised=False,
                reason="cold_start",
                verdict="ok",
                risk=self._risk(None),
                threshold=None,
                candidates=(),
                suggested=proposed,
                **common,
            )
        start = step.action_bin
        verdict, threshold, pred = assess(start)
        record: dict[str, Any] = dict(
            verdict=self._verdict_name(verdict), risk=self._risk(pred), threshold=threshold
        )
        active = self.counters.episodes >= cfg.reviser.activate_after_episodes
        if verdict == reviser.OK or not active:
            reason = "pass" if active else "inactive"
            return Decision(
                action=proposed,
                revised=False,
                reason=reason,
                candidates=(),
                suggested=proposed,
                **record,
                **common,
            )

        final, tried = reviser.search(
            start,
            verdict,
            self._directions,
            q,
            cfg.reviser.search == "literal",
            lambda r: assess(r)[0],
        )
        std = reviser.noise_std(cfg.reviser, self._a_max, self.counters.episodes)
        noise = float(rng.normal(0.0, std))
        slower = self._directions[verdict] == "decrease"
        revised = actions.decode(final, cfg.action) + noise
        revised = min(max(revised, cfg.action.low), cfg.action.high)
        if cfg.reviser.one_sided:
            revised = min(revised, proposed) if slower else max(revised, proposed)
        candidates = tuple(
            Candidate(actions.decode(r, cfg.action), r, self._verdict_name(v)) for r, v in tried
        )
        reason = "revised_safety" if slower else "revised_speed"
        return Decision(
            action=proposed if step.shadow else revised,
            revised=True,
            reason=reason,
            candidates=candidates,
            suggested=revised,
            **record,
            **common,
        )

    def _decide_by_risk(
        self,
        step: StepInput,
        z: FloatArray,
        belief: Belief,
        recognised: int,
        is_new: bool,
        index: int,
        rng: np.random.Generator,
    ) -> Decision:
        """The risk reviser on a step that learns nothing (``learn=False``; a step that
        learns decides in its compiled call, :meth:`_learn`). No noise: ``rng`` is not drawn
        from."""
        local = self.local_risk
        assert local is not None
        by_bin = np.empty(self._risk_shape)
        verdicts = np.empty(self._risk_shape[0], dtype=np.int64)
        decided = local.any_failure
        limit, worst, final, kept = (
            local.decide(
                belief,
                z,
                step.action_bin,
                self.config.risk.threshold,
                self.config.risk.margin,
                self._safe_steps,
                by_bin,
                verdicts,
            )
            if decided
            else (0.0, 0, 0, False)
        )
        return self._risk_decision(
            step, by_bin, verdicts, decided, limit, worst, final, kept, recognised, is_new, index
        )

    def _risk_decision(
        self,
        step: StepInput,
        by_bin: FloatArray,
        verdicts: npt.NDArray[np.int64],
        decided: bool,
        limit: float,
        worst: int,
        final: int,
        kept: bool,
        recognised: int,
        is_new: bool,
        index: int,
    ) -> Decision:
        """The risk reviser's decision record (:mod:`app.core.local_risk`,
        :mod:`app.core.risk`): the proposal kept unless its risk is over the threshold and
        beyond the margin of the safest action's; then the nearest allowed bin, at its
        midpoint (an end bin at the range's end). Before any failure was learned (not
        ``decided``): a cold start."""
        cfg = self.config
        proposed = step.action
        assert proposed is not None
        names = self._names
        action = suggested = proposed
        candidates: Sequence[Candidate] = ()
        revised = False
        threshold: float | None = None
        if not decided:
            risks, verdict, reason = self._risk(None), "ok", "cold_start"
        else:
            start = step.action_bin
            threshold = limit
            risks = {name: by_bin.item(start, c) for c, name in enumerate(names)}
            verdict = "ok" if kept else names[worst]
            if self.counters.episodes < cfg.reviser.activate_after_episodes:
                reason = "inactive"
            elif kept:
                reason = "pass"
            elif (stream := self.streams.get(step.stream)) is not None and stream.arm == AUDITED:
                # an episode the shield leaves to the controller, to compare (app.core.trial)
                suggested, reason = self._bin_actions[final], "audit"
            elif self.record.backs_off(recognised):
                # its revisions here were followed by more failures than the proposals
                suggested, reason = self._bin_actions[final], "backed_off"
            else:
                way = 1 if final > start else -1
                candidates = RiskCandidates(
                    range(start + way, final + way, way),
                    by_bin,
                    verdicts,
                    names,
                    self._bin_actions,
                    self._verdicts_named,
                )
                suggested = self._bin_actions[final]
                action = proposed if step.shadow else suggested
                reason = "revised_safety" if final < start else "revised_speed"
                revised = True
        counters = self.counters
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
            self.clusterer.n_states,
            is_new,
            counters.episodes,
            index,
            counters.model_version,
            step.stream,
            step.shadow,
            suggested,
        )

    def _verdict_name(self, verdict: int) -> str:
        return "ok" if verdict == reviser.OK else self.config.criteria[verdict].name

    # --- views and persistence -------------------------------------------------------------

    def states(self) -> dict[str, Any]:
        """Every state: centre in physical units, spread (normalised std), flag, visits,
        entries, and failures (states x criteria)."""
        names = [None] + [c.name for c in self.config.criteria]
        return {
            "centre": self.physical(self.clusterer.centres),
            "spread": np.sqrt(self.clusterer.variances()),
            "flag": [names[f] for f in self.flags.flags],
            "visits": self.flags.visits.copy(),
            "entries": self.flags.entries.copy(),
            "failures": self.flags.failures.copy(),
            "support": self.clusterer.support,
            "record": self._record_counts(),
            "backed_off": self._backed_off(),
        }

    def _record_counts(self) -> npt.NDArray[np.int64]:
        """The shield's own record per state (:data:`app.core.record.COLUMNS`): zeros for the
        paper's reviser, which keeps none."""
        if self.local_risk is None:
            return np.zeros((self.n_states, len(RECORD_COLUMNS)), dtype=np.int64)
        return self.record.counts.copy()

    def _backed_off(self) -> npt.NDArray[np.bool_]:
        """Per state, whether the risk reviser passes proposals there because its revisions
        were followed by more failures than the proposals (:mod:`app.core.record`)."""
        if self.local_risk is None:
            return np.zeros(self.n_states, dtype=bool)
        return self.record.backed_off()

    def failure_points(self) -> dict[str, FloatArray]:
        """Per criterion, the observations (physical units) where the reach keeps its
        failures (:mod:`app.core.reach`): none without the reach."""
        local = self.local_risk
        if local is None or self.config.risk.reach_horizon == 0:
            return {c.name: np.zeros((0, self.space.size)) for c in self.config.criteria}
        return {
            c.name: self.physical(local.failure_points(i))
            for i, c in enumerate(self.config.criteria)
        }

    def state_view(self, index: int) -> dict[str, Any]:
        """One state: centre in physical units, spread, flag, visits, entries, failures by
        criterion, and the shield's own record there (:mod:`app.core.record`)."""
        names = [None] + [c.name for c in self.config.criteria]
        failures = self.flags.failures[index]
        return {
            "index": index,
            "centre": [float(v) for v in self.physical(self.clusterer.centres[index])],
            "spread": float(np.sqrt(self.clusterer.variances()[index])),
            "flag": names[int(self.flags.flags[index])],
            "visits": int(self.flags.visits[index]),
            "entries": int(self.flags.entries[index]),
            "failures": {
                c.name: int(f) for c, f in zip(self.config.criteria, failures, strict=True)
            },
            "record": dict(zip(RECORD_COLUMNS, self._record_counts()[index].tolist(), strict=True)),
            "backed_off": self.local_risk is not None and self.record.backs_off(index),
        }

    def _totals(self) -> list[int]:
        """The model's totals now, in the columns of :class:`~app.core.history.History`."""
        c = self.counters
        return [
            c.episodes,
            c.steps,
            self.n_states,
            *(c.interventions[n] for n in self._names),
            *(c.failures[n] for n in self._names),
        ]

    def history_view(self) -> dict[str, Any]:
        """The totals at the end of episodes (:mod:`app.core.history`), one list per column,
        and the totals now."""
        rows, k, c = self.history.rows, len(self._names), self.counters
        return {
            "stride": self.history.stride,
            "limit": self.history.limit,
            "episodes": rows[:, EPISODES].tolist(),
            "steps": rows[:, STEPS].tolist(),
            "n_states": rows[:, N_STATES].tolist(),
            "interventions": {n: rows[:, TOTALS + i].tolist() for i, n in enumerate(self._names)},
            "failures": {n: rows[:, TOTALS + k + i].tolist() for i, n in enumerate(self._names)},
            "totals": {
                "episodes": c.episodes,
                "steps": c.steps,
                "n_states": self.n_states,
                "model_version": c.model_version,
                "interventions": dict(c.interventions),
                "failures": dict(c.failures),
            },
        }

    def next_states(self, index: int, top: int = 5) -> list[list[tuple[int, float]]]:
        """For each action, the ``top`` most likely next states of ``index`` (row of Eq. 2)."""
        one_hot = Belief(np.array([index]), np.array([1.0]))
        out = []
        for a in range(self.config.action.n_bins):
            row = self.transitions.predict(one_hot, a, True)  # P^T e_i = row i
            best = np.argsort(-row, kind="stable")[:top]
            out.append([(int(j), float(row[j])) for j in best])
        return out

    def snapshot(self) -> dict[str, Any]:
        """Everything the model is, as plain data and numpy arrays."""
        return {
            "format": SNAPSHOT_FORMAT,
            "config": self.config.to_dict(),
            "counters": {
                "steps": self.counters.steps,
                "episodes": self.counters.episodes,
                "model_version": self.counters.model_version,
                "interventions": dict(self.counters.interventions),
                "failures": dict(self.counters.failures),
                "streams_expired": self.counters.streams_expired,
            },
            "history": self.history.snapshot(),
            "rng": copy.deepcopy(self._rng.bit_generator.state),
            "clustering": self.clusterer.snapshot(),
            "transitions": self.transitions.snapshot(),
            "flags": self.flags.snapshot(),
            "local_risk": None
            if self.local_risk is None
            else self.local_risk.snapshot({name: s.slot for name, s in self.streams.items()}),
            "record": None if self.local_risk is None else self.record.snapshot(),
            "trial": None if self.local_risk is None else self.trial.snapshot(),
            "streams": {
                name: {
                    "index": None if s.belief is None else s.belief.index.copy(),
                    "prob": None if s.belief is None else s.belief.prob.copy(),
                    "applied_bin": s.applied_bin,
                    "proposed_bin": s.proposed_bin,
                    "step": s.step,
                    "z": None if s.z is None else s.z.copy(),
                    "arm": s.arm,
                    "failed": s.failed,
                }
                for name, s in self.streams.items()
            },
        }

    @classmethod
    def from_snapshot(
        cls, data: dict[str, Any], check: Callable[[ShieldConfig], None] | None = None
    ) -> Shield:
        """Rebuild a shield that makes exactly the decisions the original would make.

        Every part is checked before it is used (:mod:`app.core._stored`): sizes against the
        configuration, numbers finite and in range, probabilities in [0, 1] and beliefs summing
        to 1, counts no larger than the learning steps that made them. ``check`` (a server's
        bounds) judges the configuration before any array is built; its
        :class:`InvalidConfig` is refused like the configuration's own."""
        if not isinstance(data, dict) or data.get("format") not in (2, 3, SNAPSHOT_FORMAT):
            raise InvalidSnapshot(f"expected snapshot format {SNAPSHOT_FORMAT}", field="format")
        try:
            return cls._restore(data, check)
        except InvalidConfig as error:
            raise InvalidSnapshot(
                f"its configuration: {error.message}",
                field=f"config.{error.field}" if error.field else "config",
            ) from error
        except ShieldError:
            raise
        except (
            KeyError,
            TypeError,
            ValueError,
            IndexError,
            OverflowError,
            AttributeError,
        ) as error:
            raise InvalidSnapshot(f"snapshot is incomplete or inconsistent: {error!r}") from error

    @classmethod
    def _restore(cls, data: dict[str, Any], check: Callable[[ShieldConfig], None] | None) -> Shield:
        config = ShieldConfig.from_stored(data["config"])
        if check is not None:
            check(config)
        self = cls(config)
        cfg = self.config
        counters = data["counters"]
        steps = stored.integer(counters["steps"], "counters.steps", high=stored.MAX_COUNT)
        self.counters = Counters(
            steps=steps,
            episodes=stored.integer(counters["episodes"], "counters.episodes", high=steps),
            model_version=stored.integer(
                counters["model_version"], "counters.model_version", high=stored.MAX_COUNT
            ),
            interventions={
                c.name: stored.integer(
                    counters["interventions"][c.name],
                    f"counters.interventions.{c.name}",
                    high=steps,
                )
                for c in cfg.criteria
            },
            streams_expired=stored.integer(
                counters.get("streams_expired", 0), "counters.streams_expired", high=steps
            ),
        )
        self._rng.bit_generator.state = data["rng"]
        limit = cfg.limits.max_states
        self.clusterer = EvolvingClusterer.restore(
            cfg.clustering, self.space.size, limit, data["clustering"]
        )
        tpm = data["transitions"]
        if tpm["backend"] != cfg.limits.tpm_backend:
            raise InvalidSnapshot(
                f"the matrices are {tpm['backend']!r}, the configuration's "
                f"backend {cfg.limits.tpm_backend!r}",
                field="transitions.backend",
            )
        if tpm["backend"] == "dense":
            self.transitions = DenseTransitions.restore(cfg.action.n_bins, cfg.transitions, tpm)
        else:
            self.transitions = LazyTransitions.restore(
                cfg.action.n_bins, cfg.transitions, limit, tpm
            )
        self.flags = StateFlags.restore(
            cfg.reviser.flags, limit, len(cfg.criteria), cfg.reviser.flag_min_rate, data["flags"]
        )
        n = self.clusterer.n_states
        if self.transitions.n_states != n or self.flags.flags.shape[0] != n:
            raise InvalidSnapshot("states, matrices and flags disagree on the state count")
        self._restore_history(data)
        streams = data["streams"]
        if len(streams) > cfg.limits.max_streams:
            raise InvalidSnapshot(f"more than {cfg.limits.max_streams} streams", field="streams")
        self.streams = {
            str(name): self._restore_stream(f"streams.{name}", s, n, slot)
            for slot, (name, s) in enumerate(streams.items())
        }
        self._restore_risk(data, n)
        self._check_counts()
        return self

    def _check_counts(self) -> None:
        """Refuse counts beyond the learning steps behind them: each learning step
        clusters one observation (``clustering.k``), which one state absorbs (its support and
        visits), and the local model learns it once (its tries)."""
        steps, k = self.counters.steps, self.clusterer.k
        flags, clusterer = self.flags, self.clusterer

        def total(counts: npt.NDArray[np.int64]) -> float:  # (in floats: no sum overflows)
            return float(counts.sum(dtype=np.float64))

        parts: list[tuple[str, float, int]] = [
            ("clustering.k", k, steps),
            ("clustering.capacity_hits", clusterer.capacity_hits, k),
            ("clustering.support", total(clusterer.support), k),
            ("flags.visits", total(flags.visits), steps),
            ("counters.failures", sum(self.counters.failures.values()), steps),
        ]
        if self.local_risk is not None:
            parts.append(("local_risk.tried", total(self.local_risk.tried), steps))
            parts.append(("local_risk.failures", total(self.local_risk.failures), steps))
            parts.append(("record.counts", total(self.record.counts[:, [REVISED, PASSED]]), steps))
        for field_name, count, most in parts:
            if count > most:
                raise InvalidSnapshot(
                    f"{count:.0f} counted, more than the {most} learning steps behind it",
                    field=field_name,
                )
        if (flags.entries > flags.visits).any():
            raise InvalidSnapshot("a state entered more often than visited", field="flags.entries")
        if (flags.failures.sum(axis=1, dtype=np.float64) > flags.visits).any():
            raise InvalidSnapshot("a state's failures exceed its visits", field="flags.failures")

    def _restore_history(self, data: dict[str, Any]) -> None:
        """The failure counters and the history; a snapshot written before them (they are
        optional keys: older versions of the core ignore them) starts them from what it holds:
        the failures its states counted, and one row of the totals now."""
        failures = data["counters"].get("failures")
        self.counters.failures = (
            {
                c.name: int(f)
                for c, f in zip(self.config.criteria, self.flags.failures.sum(axis=0), strict=True)
            }
            if failures is None
            else {
                c.name: stored.integer(failures[c.name], f"counters.failures.{c.name}")
                for c in self.config.criteria
            }
        )
        self.history = History(len(self._names))
        if data.get("history") is not None:
            self.history = History.restore(len(self._names), data["history"], self._totals())
        elif self.counters.episodes:
            self.history.record(self._totals())

    def _restore_stream(self, field: str, data: dict[str, Any], n: int, slot: int) -> StreamState:
        """One stream's state in ``slot``, its belief and bins checked against the model's
        sizes."""
        if not 1 <= len(field) - len("streams.") <= 128:
            raise InvalidSnapshot("stream names have 1 to 128 characters", field=field)
        belief = None
        if data["index"] is not None:
            index = stored.ints(data["index"], f"{field}.index", high=n - 1).ravel()
            prob = stored.floats(data["prob"], f"{field}.prob", index.shape, low=0.0, high=1.0)
            if not index.size or np.unique(index).size != index.size:
                raise InvalidSnapshot("a belief names distinct states", field=f"{field}.index")
            stored.distribution(prob, f"{field}.prob")
            belief = Belief(index, prob)
        q = self.config.action.n_bins
        return StreamState(
            slot,
            belief,
            stored.integer(data["applied_bin"], f"{field}.applied_bin", high=q - 1),
            stored.integer(data["proposed_bin"], f"{field}.proposed_bin", high=q - 1),
            stored.integer(data["step"], f"{field}.step", high=self.counters.steps),
            -1 if belief is None else belief.argmax(),
            None
            if belief is None or data.get("z") is None
            else stored.floats(data["z"], f"{field}.z", (self.space.size,)),
            # (a snapshot from before the trial: no episode in it)
            stored.integer(data.get("arm", NONE), f"{field}.arm", low=NONE, high=AUDITED),
            stored.boolean(data.get("failed", False), f"{field}.failed"),
        )

    def _restore_risk(self, data: dict[str, Any], n: int) -> None:
        """The risk reviser's local model (a snapshot of format 3 also holds the counts of the
        model removed since, which this version does not read)."""
        if self.local_risk is not None:
            slots = {name: s.slot for name, s in self.streams.items()}
            self.local_risk = LocalRisk.restore(self.local_risk, n, slots, data["local_risk"])
            self.record = Record.restore(self._record_window(), n, self.streams, data.get("record"))
            self.trial = Trial.restore(
                self.config.reviser.seed, data.get("trial"), self.counters.episodes
            )
