"""Configuration of one e-FSM model: frozen dataclasses with the paper's car-following values.

Every gap of the paper is a named switch (docs/algorithm.md lists them with the choice made);
:meth:`ShieldConfig.paper_literal` sets all of them to the literal reading. Values are checked
on construction and errors name the dotted field at fault (checked here, not by pydantic, so
that the core needs numpy and numba alone; the service validates its requests with pydantic).
Stored configurations carry their format's ``version``; :meth:`ShieldConfig.from_stored` migrates
older ones (:mod:`app.core.migrations`).

Every number is finite and lies in a documented range (docs/api.md, "Configuration ranges"):
bounds within the observations' own +-1e12, ranges no narrower than :data:`MIN_SPAN`, and sizes
(dimensions, action bins, criteria, belief states) that bound every array a model holds, so
that no accepted configuration can overflow a sum or square, or exhaust memory by its shape.
A server may allow less (``app.settings.Settings``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import UnionType
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

from app.core.errors import InvalidConfig

Direction = Literal["decrease", "increase", None]  # None: none known

MAX_PHYSICAL = 1e12  # [observation / action units] largest bound, as for observations
MIN_SPAN = 1e-6  # [same units] narrowest range high - low that a dimension or feature spans
MAX_WEIGHT = 1e6  # largest magnitude of a feature's weights and divisors
MAX_DIMENSIONS = 1024  # observation names and features together (a request's largest observation)
MAX_BINS = 4096  # action bins q
MAX_CRITERIA = 64
MAX_TOP_K = 256  # belief states kept (limits.belief_top_k)
MAX_NAME = 64  # [characters] of an observation, feature or criterion name


def _check(ok: bool, field_name: str, message: str) -> None:
    if not ok:
        raise InvalidConfig(message, field=field_name)


def _check_range(low: float, high: float, field_name: str) -> None:
    """A range of physical values: both ends within +-MAX_PHYSICAL, at least MIN_SPAN wide."""
    _check(
        all(math.isfinite(v) and abs(v) <= MAX_PHYSICAL for v in (low, high)),
        field_name,
        f"bounds are finite and within +-{MAX_PHYSICAL:g}",
    )
    _check(high - low >= MIN_SPAN, "high", f"high must exceed low by at least {MIN_SPAN:g}")


def _check_name(name: str, field_name: str) -> None:
    _check(0 < len(name) <= MAX_NAME, field_name, f"a name has 1 to {MAX_NAME} characters")


@dataclass(frozen=True)
class Feature:
    """A derived dimension of the observation x that the states are found in.

    Its value is ``w . x``, or the ratio ``(w . x) / max(d . x, floor)`` when ``divide_by``
    (d) is given: a closing speed is ``v_lead - v_ego`` (weights ``(-1, 0, 1)``); a time
    headway is ``headway / max(v_ego, 1 m/s)``. The value is clipped to ``[low, high]`` and
    scaled by that range like every other dimension, so a feature that grows without bound
    near a limit (a ratio) cannot dominate the distances.
    """

    name: str
    weights: tuple[float, ...]
    low: float
    high: float
    divide_by: tuple[float, ...] = ()
    floor: float = 1.0

    def __post_init__(self) -> None:
        _check_name(self.name, "name")
        for name, values in (("weights", self.weights), ("divide_by", self.divide_by)):
            _check(
                all(abs(w) <= MAX_WEIGHT for w in values),
                name,  # (NaN fails it too)
                f"weights are finite and within +-{MAX_WEIGHT:g}",
            )
        _check_range(self.low, self.high, "low")
        _check(
            1e-9 <= self.floor <= MAX_PHYSICAL, "floor", f"floor lies in [1e-9, {MAX_PHYSICAL:g}]"
        )


@dataclass(frozen=True)
class ObservationSpec:
    """The e-FSM observation z_t (Eq. 12) and the bounds that normalise it.

    z is scaled to ``(z - low) / (high - low)`` before clustering, so that no dimension
    dominates the distances. A first reading divided by (32, 200, 32); the default
    divides the headway by 50 m instead: with 200 m a state spanned tens of metres of headway
    and the reviser could not tell the seconds before a crash from ordinary following
    (results/README.md, "The headway scale"; tuned on seeds 0-2). Headways above 50 m simply
    normalise above 1.

    ``knee`` (not in the paper) gives a dimension a positive knee k within which it counts
    more, so that close headways get finer states than far ones; 0 (or an empty ``knee``)
    keeps a dimension linear. Every unit within k of zero counts twice, ``x + clip(x, -k, k)``,
    scaled by the bounds as if linear: the close range spans twice as much of the clustering
    space and the far range keeps its resolution. The default knee of 20 m on the headway
    gives the seconds before a crash states of their own (docs/lab/research-log.md).
    """

    names: tuple[str, ...] = ("v_ego", "headway", "v_lead")
    low: tuple[float, ...] = (0.0, 0.0, 0.0)  # [m/s, m, m/s]
    high: tuple[float, ...] = (32.0, 50.0, 32.0)  # [m/s, m, m/s]
    knee: tuple[float, ...] = (0.0, 20.0, 0.0)  # [m/s, m, m/s]; empty or one per name

    features: tuple[Feature, ...] = ()
    cluster_raw: bool = True  # cluster the (scaled) observation itself beside the features

    def __post_init__(self) -> None:
        _check(len(self.names) >= 1, "names", "at least one observation dimension is needed")
        _check(
            len(self.names) + len(self.features) <= MAX_DIMENSIONS,
            "names",
            f"at most {MAX_DIMENSIONS} names and features together",
        )
        _check(len(set(self.names)) == len(self.names), "names", "names must be unique")
        for i, name in enumerate(self.names):
            _check_name(name, f"names.{i}")
        _check(len(self.low) == len(self.names), "low", "low needs one bound per name")
        _check(len(self.high) == len(self.names), "high", "high needs one bound per name")
        for i, (lo, hi) in enumerate(zip(self.low, self.high, strict=True)):
            try:
                _check_range(lo, hi, f"low.{i}")
            except InvalidConfig as error:
                error.field = f"{error.field}.{i}" if error.field == "high" else error.field
                raise
        _check(
            len(self.knee) in (0, len(self.names)),
            "knee",
            "knee is empty or one per name (the default is for the paper's three names)",
        )
        _check(
            all(0 <= k <= MAX_PHYSICAL for k in self.knee),
            "knee",  # (NaN fails it too)
            f"every knee lies in [0, {MAX_PHYSICAL:g}]",
        )
        for i, feature in enumerate(self.features):
            _check(
                len(feature.weights) == len(self.names),
                f"features.{i}.weights",
                "a feature needs one weight per observation name",
            )
            _check(
                len(feature.divide_by) in (0, len(self.names)),
                f"features.{i}.divide_by",
                "divide_by is empty or one weight per observation name",
            )
        _check(
            self.cluster_raw or bool(self.features),
            "cluster_raw",
            "without the raw observation, at least one feature is needed",
        )
        names = list(self.names) + [f.name for f in self.features]
        _check(
            len(set(names)) == len(names),
            "features",
            "feature names must be unique and differ from the observation's names",
        )

    @property
    def size(self) -> int:
        """Number of observation dimensions."""
        return len(self.names)


@dataclass(frozen=True)
class ActionSpec:
    """The continuous action range A_c and its discretisation into q bins of width delta."""

    low: float = -2.0  # [m/s²]
    high: float = 2.0  # [m/s²]
    step: float = 0.2  # [m/s²], the paper's delta
    out_of_range: Literal["clip", "reject"] = "clip"

    def __post_init__(self) -> None:
        _check_range(self.low, self.high, "low")
        _check(math.isfinite(self.step) and self.step > 0, "step", "step must be positive")
        bins = (self.high - self.low) / self.step
        _check(bins <= MAX_BINS, "step", f"the range holds at most {MAX_BINS} steps")
        _check(
            abs(bins - round(bins)) < 1e-9 and round(bins) >= 2,
            "step",
            "the range must hold a whole number (>= 2) of steps",
        )

    @functools.cached_property
    def n_bins(self) -> int:
        """Number of discrete actions q (20 for [-2, 2] with delta = 0.2)."""
        return round((self.high - self.low) / self.step)


@dataclass(frozen=True)
class Bound:
    """Where a criterion's failures lie, when the user knows it: the observation named
    ``observation`` at or below ``below``, or at or above ``above`` (either may be left out).

    With a bound the reach (:mod:`app.core.reach`) asks whether the worst case of a path
    crosses it, at any speed, rather than only whether the path nears a failure seen."""

    observation: str
    below: float | None = None
    above: float | None = None

    def __post_init__(self) -> None:
        _check(bool(self.observation), "observation", "a bound names an observation")
        _check(
            self.below is not None or self.above is not None,
            "below",
            "a bound needs below, above or both",
        )
        for name, value in (("below", self.below), ("above", self.above)):
            _check(
                value is None or abs(value) <= MAX_PHYSICAL,
                name,  # (NaN fails it too)
                f"must be finite and within +-{MAX_PHYSICAL:g}",
            )
        _check(
            self.below is None or self.above is None or self.below < self.above,
            "above",
            "above must exceed below",
        )


@dataclass(frozen=True)
class Criterion:
    """An unfavourable-state criterion: its name, the direction of the action that moves away
    from it where the user knows one, and where its failures lie, if known (:class:`Bound`).

    A direction is a prior (:func:`app.core.risk.monotone`): ``decrease`` when a smaller
    action never raises the risk (braking against a collision), ``increase`` when a larger one
    never does, None when it depends on the state (an unstable system, where the action that
    saves it from a fall depends on which way it leans): the risk reviser then learns each
    action's risk as it is. The paper's reviser needs a direction."""

    name: str
    direction: Direction = None
    bound: Bound | None = None

    def __post_init__(self) -> None:
        _check_name(self.name, "name")
        _check(self.name != "ok", "name", "'ok' is reserved for the favourable verdict")
        _check(
            self.direction in ("decrease", "increase", None),
            "direction",
            "direction is 'decrease', 'increase' or null (none known)",
        )


PAPER_CRITERIA = (
    # l_s: slow down against a crash, at a headway of 0
    Criterion("collision", "decrease", Bound("headway", below=0.0)),
    # l_ld: speed up against falling behind (beyond 200 m; bounded, every path's worst case
    # would fall behind within the reach's horizon, and braking would read as risky)
    Criterion("large_distance", "increase"),
)


@dataclass(frozen=True)
class ClusteringConfig:
    """Online evolving clustering (docs/algorithm.md).

    ``rho`` (0.7) and ``epsilon`` are the paper's eTS coefficients. rho is the radius
    learning constant, epsilon the zone-of-influence radius in normalised units and the initial
    spread of a new state. The default halves the paper's epsilon of 0.3: at 0.3 the
    model kept 5-12 states, a few runs were caught braking in a coarse state flagged for
    collision, and 0.15 (12-17 states) succeeded more on three tuning seeds when both ran on
    one machine; on a fourth tuning seed (four runs each) and on the evaluation seeds the two
    were level (results/README.md, "The clustering radius"; tuned on seeds 0-3).
    """

    rho: float = 0.7
    epsilon: float = 0.15
    creation_rule: Literal["ets_plus", "ets2004"] = "ets_plus"  # A2
    spread: Literal["radius", "member_variance", "ets2004"] = "radius"  # A9
    min_variance: float = 1e-4

    def __post_init__(self) -> None:
        # the clustering space spans about [0, 1] a dimension (a knee: [0, 2])
        _check(0.0 <= self.rho <= 1.0, "rho", "rho lies in [0, 1]")  # (NaN fails it too)
        _check(0.0 < self.epsilon <= 10.0, "epsilon", "epsilon lies in (0, 10]")
        _check(
            1e-12 <= self.min_variance <= 100.0, "min_variance", "min_variance lies in [1e-12, 100]"
        )


@dataclass(frozen=True)
class TransitionConfig:
    """Online transition identification, Eqs. 3-4 (docs/algorithm.md)."""

    learning_rate: float = 0.01  # phi
    prior: float = 1e-3  # F(0) = F_o(0) = epsilon-bar, must be > 0
    on_new_state: Literal["skip", "pad"] = "skip"  # A3
    expansion: Literal["prior", "zero_uniform", "zero_identity"] = "prior"  # A10
    action_source: Literal["executed", "proposed"] = "executed"  # A8
    across_episodes: bool = False  # A13
    on_replace: Literal["keep", "reset"] = "keep"  # A16

    def __post_init__(self) -> None:
        _check(0.0 < self.learning_rate < 1.0, "learning_rate", "phi lies in (0, 1)")
        _check(1e-12 <= self.prior <= 1e6, "prior", "prior lies in [1e-12, 1e6]")


@dataclass(frozen=True)
class ReviserConfig:
    """The action reviser and its activation.

    ``method`` ``risk`` (the default) revises by the failure risk of each action over a
    horizon (:class:`RiskConfig`, :mod:`app.core.risk`); ``paper`` by the paper's flags on
    predicted states (Algs. 1-3, with every switch below; :meth:`ShieldConfig.paper`). Either
    revises only after ``activate_after_episodes`` episodes, learning from the controller's
    own actions until then: from the first episode by default (the risk reviser reads a risk
    only once a failure was learned; docs/lab/risk-reviser.md), after the paper's xi = 50 in
    :meth:`ShieldConfig.paper` and :meth:`ShieldConfig.paper_literal`. ``seed`` drives the
    paper reviser's noise.
    """

    method: Literal["paper", "risk"] = "risk"
    activate_after_episodes: int = 0  # xi
    noise_k: float = 0.001  # K
    noise: Literal["variance", "std"] = "variance"  # A7: V = a_max / max(1, K * episode)
    horizon: int = 1  # k, prediction steps
    transpose: bool = True  # A1: Prob_pred = P^T Prob(S_t)
    inspect: Literal["any", "first_index"] = "any"  # A5
    search: Literal["fixed", "literal"] = "fixed"  # A6
    multi_step: Literal["iterate", "single"] = "iterate"  # A11
    # A4: "overwrite" re-flags the recognised state on every step (the literal reading);
    # "rate" flags a state by the criterion whose failures make up at least flag_min_rate of
    # the entries into it (docs/algorithm.md)
    flags: Literal["overwrite", "rate"] = "rate"
    flag_min_rate: float = 0.05
    # Not in the paper: a revision never goes past the proposal the wrong way (Alg. 2's bin
    # midpoint plus noise can brake less than the controller asked)
    one_sided: bool = True
    seed: int = 0

    def __post_init__(self) -> None:
        _check(
            0 <= self.activate_after_episodes < 2**63,
            "activate_after_episodes",
            "lies in [0, 2**63)",
        )
        _check(0.0 <= self.noise_k <= 1e6, "noise_k", "noise_k lies in [0, 1e6]")
        _check(1 <= self.horizon <= 16, "horizon", "horizon lies in [1, 16]")
        _check(0.0 < self.flag_min_rate <= 1.0, "flag_min_rate", "lies in (0, 1]")
        _check(0 <= self.seed < 2**63, "seed", "seed lies in [0, 2**63)")


@dataclass(frozen=True)
class RiskConfig:
    """The failure-aware reviser (:mod:`app.core.local_risk`, :mod:`app.core.risk`).

    Each action's total risk is the probability that any failure follows within ``horizon``
    steps: per criterion the mean of a linear model per state in the observation and the
    action, and of the reach. The proposal is kept when its total risk is at most ``threshold``
    or within ``margin`` of the least; otherwise the nearest action within that limit replaces
    it. The defaults act on any measurable difference (docs/lab/risk-reviser.md).

    The reach (:mod:`app.core.reach`) asks whether a failure can still be avoided:
    ``reach_horizon`` steps of the learned dynamics under the safest action after the one
    judged, a path counting as failing by its closeness to a failure seen, within
    ``reach_radius`` in the clustering space. The shield's own record (:mod:`app.core.record`)
    counts failures within the farther of the two horizons.
    """

    horizon: int = 24
    threshold: float = 0.0
    margin: float = 0.001
    reach_horizon: int = 40  # steps rolled out under the safest continuation (0: no reach)
    reach_radius: float = 0.05  # normalised distance within which a path meets a failure

    def __post_init__(self) -> None:
        _check(1 <= self.horizon <= 256, "horizon", "horizon lies in [1, 256]")
        _check(0.0 <= self.threshold <= 1.0, "threshold", "threshold lies in [0, 1]")
        _check(0.0 <= self.margin <= 1.0, "margin", "margin lies in [0, 1]")
        _check(0 <= self.reach_horizon <= 1024, "reach_horizon", "reach_horizon lies in [0, 1024]")
        _check(
            0.0 < self.reach_radius <= 10.0,
            "reach_radius",  # (NaN fails it too)
            "reach_radius lies in (0, 10]",
        )


@dataclass(frozen=True)
class LimitsConfig:
    """Bounds that keep the cost of a step flat as the model grows.

    When ``max_states`` is reached no state is created any more: an observation that would
    have made one joins its nearest state instead (counted as ``capacity_hits``). A new stream
    beyond ``max_streams`` makes the model forget the least recently used stream's previous
    step (counted as ``streams_expired``), so that stream names cannot exhaust memory.
    ``belief_top_k`` truncates beliefs and propagated predictions to their k most likely
    states (exact when k >= the number of states).
    """

    max_states: int = 10_000
    max_streams: int = 10_000
    belief_top_k: int = 16
    tpm_backend: Literal["lazy", "dense"] = "lazy"

    def __post_init__(self) -> None:
        _check(1 <= self.max_states <= 1_000_000, "max_states", "lies in [1, 1000000]")
        _check(1 <= self.max_streams <= 1_000_000, "max_streams", "lies in [1, 1000000]")
        _check(1 <= self.belief_top_k <= MAX_TOP_K, "belief_top_k", f"lies in [1, {MAX_TOP_K}]")


@dataclass(frozen=True)
class ShieldConfig:
    """Everything one e-FSM model needs; the defaults are the paper's car-following values."""

    observation: ObservationSpec = field(default_factory=ObservationSpec)
    action: ActionSpec = field(default_factory=ActionSpec)
    criteria: tuple[Criterion, ...] = PAPER_CRITERIA
    clustering: ClusteringConfig = field(default_factory=ClusteringConfig)
    transitions: TransitionConfig = field(default_factory=TransitionConfig)
    reviser: ReviserConfig = field(default_factory=ReviserConfig)
    risk: RiskConfig = field(default_factory=RiskConfig)
    limits: LimitsConfig = field(default_factory=LimitsConfig)

    def __post_init__(self) -> None:
        names = [c.name for c in self.criteria]
        # without a criterion no failure is learned and no proposal is ever revised
        _check(1 <= len(names) <= MAX_CRITERIA, "criteria", f"1 to {MAX_CRITERIA} criteria")
        _check(len(set(names)) == len(names), "criteria", "criterion names must be unique")
        observed = self.observation.names
        for i, criterion in enumerate(self.criteria):
            _check(
                criterion.direction is not None or self.reviser.method == "risk",
                f"criteria.{i}.direction",
                "the paper's reviser searches along a "
                "direction: declare one, or use the risk reviser",
            )
            if criterion.bound is None:
                continue
            _check(
                criterion.bound.observation in observed,
                f"criteria.{i}.bound.observation",
                f"{criterion.bound.observation!r} is not an observation name "
                f"({', '.join(observed)}); a custom observation declares its own criteria",
            )
            _check(
                self.observation.cluster_raw,
                f"criteria.{i}.bound",
                "a bound needs the observation clustered (observation.cluster_raw); "
                "declare the criteria without bounds",
            )

    @classmethod
    def paper(cls, **overrides: Any) -> ShieldConfig:
        """The paper's reviser (flags on predicted states, activated after 50 episodes) with
        this project's readings of its gaps: the default before the risk reviser."""
        return dataclasses.replace(
            cls(reviser=ReviserConfig(method="paper", activate_after_episodes=50)), **overrides
        )

    @classmethod
    def paper_literal(cls, **overrides: Any) -> ShieldConfig:
        """The paper's reviser with the literal reading of every ambiguity (A1-A16)."""
        literal = cls(
            clustering=ClusteringConfig(epsilon=0.3, creation_rule="ets2004"),
            transitions=TransitionConfig(action_source="proposed", across_episodes=True),
            reviser=ReviserConfig(
                method="paper",
                activate_after_episodes=50,
                transpose=False,
                inspect="first_index",
                search="literal",
                multi_step="single",
                flags="overwrite",
                one_sided=False,
            ),
        )
        return dataclasses.replace(literal, **overrides)

    def criterion_index(self, name: str) -> int | None:
        """Priority index of a criterion (0 = highest), or None if it is not configured."""
        for i, criterion in enumerate(self.criteria):
            if criterion.name == name:
                return i
        return None

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able data with the stored format's ``version``; :meth:`from_dict` and
        :meth:`from_stored` invert it."""
        return {"version": CONFIG_VERSION, **_lists(dataclasses.asdict(self))}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ShieldConfig:
        """Build a configuration from nested plain data; missing fields take their defaults.
        ``version``, if given, must be this format's (older ones: :meth:`from_stored`)."""
        if not isinstance(data, Mapping):
            raise InvalidConfig("expected an object")
        if "version" in data:
            if data["version"] != CONFIG_VERSION:
                raise InvalidConfig(
                    f"expected version {CONFIG_VERSION}; a stored configuration "
                    "of an older version loads through from_stored",
                    field="version",
                )
            data = {key: value for key, value in data.items() if key != "version"}
        return _build(cls, data, "")

    @classmethod
    def from_stored(cls, data: Mapping[str, Any]) -> ShieldConfig:
        """A whole configuration that :meth:`to_dict` wrote, maybe by an older version of this
        package, migrated to this format so that it decides as it did when it was written
        (:mod:`app.core.migrations`, which refuses one it cannot reproduce, naming the
        field)."""
        from app.core import migrations  # (it builds on this module)

        return cls.from_dict(migrations.migrate(data))


CONFIG_VERSION = 5


def _lists(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _lists(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_lists(v) for v in value]
    return value


T = TypeVar("T")


def _build(cls: type[T], data: Any, path: str) -> T:
    if not isinstance(data, Mapping):
        raise InvalidConfig("expected an object", field=path or None)
    hints = get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - names)
    if unknown:
        raise InvalidConfig(f"unknown field {unknown[0]!r}", field=join_path(path, unknown[0]))
    kwargs = {k: _convert(hints[k], v, join_path(path, k)) for k, v in data.items()}
    try:
        return cls(**kwargs)
    except InvalidConfig as error:
        error.field = join_path(path, error.field or "")
        raise


def _convert(hint: Any, value: Any, path: str) -> Any:
    origin = get_origin(hint)
    if origin is UnionType and type(None) in get_args(hint):  # an optional field
        if value is None:
            return None
        (inner,) = (a for a in get_args(hint) if a is not type(None))
        return _convert(inner, value, path)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, path)  # type: ignore[arg-type]
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise InvalidConfig("expected a list", field=path)
        item = get_args(hint)[0]
        return tuple(_convert(item, v, f"{path}.{i}") for i, v in enumerate(value))
    if origin is Literal:
        if value not in get_args(hint):
            options = ", ".join(repr(a) for a in get_args(hint))
            raise InvalidConfig(f"expected one of {options}", field=path)
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise InvalidConfig("expected a boolean", field=path)
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise InvalidConfig("expected an integer", field=path)
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise InvalidConfig("expected a number", field=path)
        try:
            number = float(value)
        except OverflowError:  # an integer beyond any float
            number = math.inf
        if not math.isfinite(number):
            raise InvalidConfig("expected a finite number", field=path)
        return number
    if hint is str:
        if not isinstance(value, str):
            raise InvalidConfig("expected a string", field=path)
        return value
    raise InvalidConfig("unsupported field", field=path)


def join_path(path: str, name: str) -> str:
    return f"{path}.{name}" if path and name else path or name
