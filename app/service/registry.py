"""Many e-FSM models in one process: creation, lookup, serialised steps, durability.

Each model has its own lock: steps to one model are applied one at a time, in the order the
lock is taken, while other models proceed in parallel. Every accepted learning request is
journaled before it is applied (see :mod:`app.service.storage`), so a crash loses nothing that
was acknowledged under ``fsync=always``. A bad request is validated in full first and changes
nothing. A step sent with an idempotency key is applied once: sent again, it is answered with
its first decision (:mod:`app.service.idempotency`).

At start-up each model is read back from its files. A journal whose last record is torn or
damaged, with nothing readable after it, is repaired: cut after its last good record (the cut
bytes kept beside it) and a snapshot taken, said in an error line. Any other damage (a snapshot
that cannot be read, a journal damaged before readable records or missing beside its snapshot,
a bad ``config.json``) sets the model aside with its files untouched. Every model has a
snapshot from its creation on, so a missing journal is always told apart from an empty one.
"""

from __future__ import annotations

import logging
import re
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.core import Decision, Shield, ShieldConfig, ShieldError
from app.core.stream import StepInput
from app.service import codec
from app.service.idempotency import Entry, KeyReused, KeyWindow, fingerprint
from app.service.limits import ModelLimits
from app.service.storage import Fsync, ModelStore

log = logging.getLogger("app.registry")

NAME = re.compile(r"[a-z0-9][a-z0-9_-]{0,63}")
DEFAULT_MODEL = "default"
IDEMPOTENCY_WINDOW = 1024  # keyed steps a model remembers, by default


class UnknownModel(ShieldError):
    """No model has this name."""

    code = "unknown_model"


class ModelExists(ShieldError):
    """A model with this name exists already."""

    code = "model_exists"


class ModelQuarantined(ShieldError):
    """The model's files were damaged at start-up: it is set aside, the others serve."""

    code = "model_quarantined"


class TooManyModels(ShieldError):
    """The server holds as many models as it may."""

    code = "too_many_models"


class DamagedModel(Exception):
    """A model's files cannot be read back into the model they recorded."""


class InvalidName(ShieldError):
    """A model name must match ``[a-z0-9][a-z0-9_-]{0,63}``."""

    code = "invalid_name"


@dataclass
class Model:
    """One model with its lock and its files."""

    name: str
    shield: Shield
    store: ModelStore | None
    lock: threading.Lock = field(default_factory=threading.Lock)
    snapshotting: threading.Lock = field(default_factory=threading.Lock)  # one write at a time
    since_snapshot: int = 0
    watchers: list[Watcher] = field(default_factory=list)
    decisions: dict[str, int] = field(default_factory=dict)  # served here, by reason
    keys: KeyWindow = field(default_factory=lambda: KeyWindow(IDEMPOTENCY_WINDOW))


Watcher = Callable[[dict[str, Any]], None]
"""Called with each step's event, from the thread that applied the step; must not block."""


@dataclass(frozen=True)
class Step:
    """One step as the API hands it over: keyword arguments of :meth:`Shield.step`."""

    observation: Sequence[float]
    action: float | None
    stream: str = "0"
    event: str | None = None
    done: bool = False
    applied_action: float | None = None
    learn: bool = True
    shadow: bool = False
    key: str | None = None  # the idempotency key: sent again, answered, not applied again

    def journal(self) -> dict[str, Any]:
        """The record that replays this step (and remembers its key)."""
        record = {
            "o": list(self.observation),
            "a": self.action,
            "s": self.stream,
            "e": self.event,
            "d": self.done,
            "p": self.applied_action,
            "h": self.shadow,
        }
        if self.key is not None:
            record["k"] = self.key
        return record

    @classmethod
    def from_journal(cls, r: dict[str, Any]) -> Step:
        return cls(r["o"], r["a"], r["s"], r["e"], r["d"], r["p"], True, r["h"], r.get("k"))

    def fingerprint(self) -> str:
        """What a step sent again under the same key must match."""
        return fingerprint(
            self.observation,
            self.action,
            self.stream,
            self.event,
            self.done,
            self.applied_action,
            self.learn,
            self.shadow,
        )


class ModelRegistry:
    """The models of one server."""

    def __init__(
        self,
        data_dir: Path | None = None,
        fsync: Fsync = "interval",
        snapshot_every: int = 50_000,
        default_config: ShieldConfig | None = None,
        *,
        max_models: int = 1000,
        limits: ModelLimits | None = None,
        create_default: bool = True,
        idempotency_window: int = IDEMPOTENCY_WINDOW,
    ) -> None:
        self.data_dir = data_dir
        self.idempotency_window = idempotency_window
        self.max_models = max_models
        self.limits = limits or ModelLimits()
        self.fsync = fsync
        self.snapshot_every = snapshot_every
        self.default_config = default_config or ShieldConfig()
        self.create_default = create_default  # a shard of a cluster leaves it to its owner
        self._models: dict[str, Model] = {}
        self.quarantined: dict[str, str] = {}  # name -> why its files could not be loaded
        self._lock = threading.Lock()  # the name -> model map
        self._stop = threading.Event()
        self._syncer: threading.Thread | None = None
        self.ready = False

    # --- life cycle -----------------------------------------------------------------------

    def open(self) -> None:
        """Load every stored model (snapshot + journal replay) and make sure 'default' exists
        (unless ``create_default`` is off).

        A model whose files are damaged is set aside (:attr:`quarantined`, logged as an
        error): it answers :class:`ModelQuarantined` while every other model serves, and no
        fresh model takes its place or its files.
        """
        if self.data_dir is not None:
            root = self.data_dir / "models"
            root.mkdir(parents=True, exist_ok=True)
            for directory in sorted(p for p in root.iterdir() if p.is_dir()):
                try:
                    model = self._load(directory)
                except Exception as error:  # any damage to any file: set this model aside
                    reason = f"{type(error).__name__}: {error}"
                    log.error(
                        "model %r is quarantined, its files in %s are kept as they are: %s",
                        directory.name,
                        directory,
                        reason,
                    )
                    self.quarantined[directory.name] = reason
                    continue
                if model is not None:
                    self._models[directory.name] = model
            if self.fsync == "interval":
                self._syncer = threading.Thread(
                    target=self._sync_loop, name="journal-sync", daemon=True
                )
                self._syncer.start()
        if self.create_default:
            self.ensure_default()
        self.ready = True

    def close(self) -> None:
        """Snapshot every model and close its files."""
        self.ready = False
        self._stop.set()
        if self._syncer is not None:
            self._syncer.join()
        for model in list(self._models.values()):
            with model.lock, model.snapshotting:
                if model.store is not None:
                    if model.since_snapshot:
                        self._snapshot(model)
                    model.store.close()

    def ensure_default(self) -> None:
        """Create the 'default' model with the default configuration if it is missing."""
        with self._lock:
            missing = DEFAULT_MODEL not in self._models and DEFAULT_MODEL not in self.quarantined
        if missing:
            try:
                self.create(DEFAULT_MODEL, self.default_config)
            except ModelExists:
                pass  # created meanwhile

    def _sync_loop(self) -> None:
        while not self._stop.wait(1.0):  # fsync=interval: at most one second at risk
            for model in list(self._models.values()):
                if model.store is not None:
                    model.store.sync()

    def _load(self, directory: Path) -> Model | None:
        """The model stored in ``directory`` (None for a directory that holds no model), a
        damaged tail of its journal repaired; :class:`DamagedModel` for any other damage,
        before any file is changed."""
        store = ModelStore(directory, self.fsync)
        if not store.config_path.exists():
            if store.snapshot_path.exists() or store.journal_path.exists():
                raise DamagedModel("config.json is missing beside the model's other files")
            return None
        try:
            config = ShieldConfig.from_stored(store.read_config())
        except Exception as error:
            raise DamagedModel(
                f"config.json cannot be read ({type(error).__name__}: {error})"
            ) from error
        blob = store.read_snapshot()
        if blob is None:  # a model that never learned, or one stored before snapshots at birth
            shield = Shield(config)
        else:
            shield = Shield.from_snapshot(codec.from_npz(blob))
            if not store.journal_path.exists():
                raise DamagedModel(
                    "journal.log is missing: the steps learned after the "
                    f"snapshot (version {shield.counters.model_version}) are "
                    "not known"
                )
        records, damage = store.scan()
        if damage is not None and not damage.at_tail:
            raise DamagedModel(
                f"{damage.describe()}, and readable records follow it: the "
                "damage is not at the end of the journal"
            )
        model = Model(directory.name, shield, store, keys=KeyWindow(self.idempotency_window))
        replayed = self._replay(model, records)
        if damage is not None:
            kept = store.cut(damage)
            log.error(
                "model %r repaired: %s; the journal now ends at its last good record "
                "(version %d, %d steps replayed), the cut bytes are kept in %s, and a "
                "snapshot was taken",
                directory.name,
                damage.describe(),
                shield.counters.model_version,
                replayed,
                ", ".join(p.name for p in kept) or "no file (nothing was cut)",
            )
        if damage is not None or blob is None:  # the repair, or the snapshot of its birth
            self._snapshot(model)
        log.info(
            "model %r: %d states, version %d (%d journaled steps replayed)",
            directory.name,
            shield.n_states,
            shield.counters.model_version,
            replayed,
        )
        return model

    @staticmethod
    def _replay(model: Model, records: Sequence[dict[str, Any]]) -> int:
        """Apply the journal's records the model's snapshot does not hold, and remember their
        keys; the steps replayed."""
        shield = model.shield
        replayed = 0
        for record in records:
            if "w" in record:  # the keys remembered when a snapshot was taken
                model.keys.load(record["w"])
                continue
            if record["v"] <= shield.counters.model_version:
                continue  # already in the snapshot
            start = record["v"] - len(record["steps"])
            if start != shield.counters.model_version:
                raise DamagedModel(
                    f"the journal goes on from version {start}, the model is "
                    f"at version {shield.counters.model_version} (a snapshot "
                    "missing or older than the journal)"
                )
            for data in record["steps"]:
                step = Step.from_journal(data)
                decision = shield.step(
                    step.observation,
                    step.action,
                    stream=step.stream,
                    event=step.event,
                    done=step.done,
                    applied_action=step.applied_action,
                    shadow=step.shadow,
                )
                if step.key is not None:
                    model.keys.remember(step.key, step.fingerprint(), decision)
                replayed += 1
        model.since_snapshot = replayed
        return replayed

    # --- models ---------------------------------------------------------------------------

    def names(self) -> list[str]:
        return sorted(self._models)

    def get(self, name: str) -> Model:
        try:
            return self._models[name]
        except KeyError:
            self._refuse_quarantined(name)
            raise UnknownModel(f"no model named {name!r}", field="name") from None

    def _refuse_quarantined(self, name: str) -> None:
        if name in self.quarantined:
            raise ModelQuarantined(
                f"model {name!r} was set aside at start-up, its files damaged "
                f"({self.quarantined[name]}); repair or move its directory and restart",
                field="name",
            )

    def create(self, name: str, config: ShieldConfig) -> Model:
        """A new, empty model (its configuration is stored at once)."""
        check_name(name)
        self._refuse_quarantined(name)
        self._check_limits(config)
        with self._lock:
            if name in self._models:
                raise ModelExists(f"a model named {name!r} exists", field="name")
            self._check_room(name)
            model = self._new_model(name, Shield(config))
            if model.store is not None:
                model.store.create(config.to_dict())
                self._snapshot(model)  # from its birth: a missing journal is then damage
            self._models[name] = model
            return model

    def _new_model(self, name: str, shield: Shield) -> Model:
        return Model(name, shield, self._store(name), keys=KeyWindow(self.idempotency_window))

    def restore(self, name: str, snapshot: dict[str, Any], keys: Sequence[Entry] = ()) -> Model:
        """Create or replace a model from a snapshot (the snapshot is stored at once), with
        the idempotency keys it remembers (a model moved from another shard)."""
        check_name(name)
        self._refuse_quarantined(name)
        shield = Shield.from_snapshot(snapshot, self.limits.check)  # bounds before arrays
        with self._lock:
            self._check_room(name)
            old = self._models.get(name)
            if old is not None:
                with old.lock, old.snapshotting:
                    if old.store is not None:
                        old.store.close()
            model = self._new_model(name, shield)
            model.keys.load(keys)
            if model.store is not None:
                model.store.create(shield.config.to_dict())
                self._snapshot(model)
            self._models[name] = model
            return model

    def _check_limits(self, config: ShieldConfig) -> None:
        self.limits.check(config)

    def _check_room(self, name: str) -> None:
        if name not in self._models and len(self._models) >= self.max_models:
            raise TooManyModels(f"this server holds at most {self.max_models} models", field="name")

    def delete(self, name: str) -> None:
        """Remove a model and its files."""
        with self._lock:
            model = self.get(name)
            with model.lock, model.snapshotting:
                del self._models[name]
                if model.store is not None:
                    model.store.remove()

    def reset(self, name: str) -> Model:
        """Empty a model: no states, counters at zero, its seed's generator."""
        model = self.get(name)
        with model.lock, model.snapshotting:
            model.shield.reset()
            if model.store is not None:
                self._snapshot(model)
        return model

    def _store(self, name: str) -> ModelStore | None:
        if self.data_dir is None:
            return None
        return ModelStore(self.data_dir / "models" / name, self.fsync)

    def _snapshot(self, model: Model) -> None:
        """Snapshot now (the caller holds the model's locks)."""
        model.store.write_snapshot(codec.to_npz(self._take(model)))  # type: ignore[union-attr]

    @staticmethod
    def _take(model: Model) -> dict[str, Any]:
        """The model's state and a rotated journal: what a snapshot write then stores, with
        the model's lock released or not. The new journal starts with the keys the model
        remembers, which the snapshot does not hold."""
        assert model.store is not None
        data = model.shield.snapshot()
        model.store.rotate()
        if len(model.keys):
            model.store.append(
                {"v": model.shield.counters.model_version, "w": model.keys.entries()}
            )
        model.since_snapshot = 0
        return data

    # --- steps ----------------------------------------------------------------------------

    @property
    def steps_are_quick(self) -> bool:
        """False when every step waits for the disk (fsync=always): keep it off the loop."""
        return self.data_dir is None or self.fsync != "always"

    def step(self, name: str, step: Step) -> Decision:
        """One step of one model."""
        decision = self._step_one(name, step, blocking=True)
        assert decision is not None
        return decision

    def try_step(self, name: str, step: Step) -> Decision | None:
        """One step if the model's lock is free right now, else None (nothing done)."""
        return self._step_one(name, step, blocking=False)

    def step_batch(self, name: str, steps: Sequence[Step]) -> list[Decision]:
        """Steps of one model, in order; one bad step rejects them all."""
        decisions = self.step_many([(name, s) for s in steps])
        assert decisions is not None
        return decisions

    def _step_one(self, name: str, step: Step, blocking: bool) -> Decision | None:
        """:meth:`step_many` of one step, without a batch's bookkeeping: the path of every
        single request."""
        model = self.get(name)
        if not model.lock.acquire(blocking=blocking):
            return None
        taking = False
        try:
            try:
                self._check_current(name, model)
                if step.key is not None:
                    print_ = step.fingerprint()
                    remembered = model.keys.recall(step.key, print_, "idempotency_key")
                    if remembered is not None:
                        return remembered  # applied before: its first decision
                checked = _validate(model.shield, step, None)
                if step.learn:
                    self._journal(model, [step])
                decision = self._apply(model, step, checked)
                if step.key is not None and step.learn:
                    model.keys.remember(step.key, print_, decision)
                taking = self._snapshot_due(model)
                data = self._take(model) if taking else None
            finally:
                model.lock.release()
            if data is not None:  # with the model's lock released
                model.store.write_snapshot(codec.to_npz(data))  # type: ignore[union-attr]
        finally:
            if taking:
                model.snapshotting.release()
        return decision

    def step_many(
        self, steps: Sequence[tuple[str, Step]], blocking: bool = True
    ) -> list[Decision] | None:
        """Steps across models, in order; one bad step (or unknown model) rejects them all.
        A step whose key a model remembers is answered with its first decision, not applied.

        With ``blocking=False`` nothing is done (None) if a model's lock is taken.
        """
        models = {name: self.get(name) for name in dict.fromkeys(n for n, _ in steps)}
        due: list[Model] = []  # models whose snapshot this call takes, their write lock held
        held: list[Model] = []
        try:
            try:
                for name in sorted(models):  # a fixed order: no deadlock between batches
                    if not models[name].lock.acquire(blocking=blocking):
                        return None
                    held.append(models[name])
                    self._check_current(name, models[name])
                prints = [None if step.key is None else step.fingerprint() for _, step in steps]
                remembered = self._recall(models, steps, prints)
                inputs = [
                    None if known is not None else _validate(models[name].shield, step, i)
                    for i, ((name, step), known) in enumerate(zip(steps, remembered, strict=True))
                ]
                learned: dict[str, list[Step]] = {}
                for (name, step), known in zip(steps, remembered, strict=True):
                    if step.learn and known is None:
                        learned.setdefault(name, []).append(step)
                for name, group in learned.items():
                    self._journal(models[name], group)
                decisions = []
                for (name, step), known, checked, print_ in zip(
                    steps, remembered, inputs, prints, strict=True
                ):
                    if checked is None:
                        assert known is not None
                        decisions.append(known)
                        continue
                    decision = self._apply(models[name], step, checked)
                    if step.key is not None and print_ is not None and step.learn:
                        models[name].keys.remember(step.key, print_, decision)
                    decisions.append(decision)
                taken = []
                for model in models.values():
                    if self._snapshot_due(model):
                        due.append(model)
                        taken.append(self._take(model))
            finally:
                for model in held:
                    model.lock.release()
            for model, data in zip(due, taken, strict=True):  # with the models' locks released
                model.store.write_snapshot(codec.to_npz(data))  # type: ignore[union-attr]
        finally:
            for model in due:
                model.snapshotting.release()
        return decisions

    @staticmethod
    def _recall(
        models: dict[str, Model], steps: Sequence[tuple[str, Step]], prints: Sequence[str | None]
    ) -> list[Decision | None]:
        """Each step's first decision if its model remembers its key, else None; a key named
        twice in one request for one model, or more keys for a model than it remembers, is
        refused."""
        seen: dict[tuple[str, str], int] = {}
        keyed: dict[str, int] = {}
        remembered: list[Decision | None] = []
        for i, ((name, step), print_) in enumerate(zip(steps, prints, strict=True)):
            if step.key is None or print_ is None:
                remembered.append(None)
                continue
            field = f"steps.{i}.idempotency_key"
            if (name, step.key) in seen:
                raise KeyReused(
                    f"idempotency key {step.key!r} names step {seen[name, step.key]} "
                    "of this request already; a key names one step",
                    field=field,
                )
            seen[name, step.key] = i
            keyed[name] = keyed.get(name, 0) + 1
            remembered.append(models[name].keys.recall(step.key, print_, field))
        for name, count in keyed.items():
            models[name].keys.check_room(count, "steps")
        return remembered

    def _check_current(self, name: str, model: Model) -> None:
        """Refuse a model that was replaced or deleted while its lock was awaited."""
        if self._models.get(name) is not model:
            raise UnknownModel(f"model {name!r} was replaced or deleted; send again", field="name")

    def _apply(self, model: Model, step: Step, checked: StepInput) -> Decision:
        """Apply a validated step (the model's lock held): tally its decision, show it to
        the model's watchers."""
        decision = model.shield.apply(checked)
        tally = model.decisions
        tally[decision.reason] = tally.get(decision.reason, 0) + 1
        if model.watchers:  # nobody watching: this check is all it costs
            self._publish(model, step, decision)
        return decision

    def _snapshot_due(self, model: Model) -> bool:
        """Whether the model's snapshot is due now; if so, its write lock is taken (else it
        waits for a later step)."""
        return (
            model.store is not None
            and model.since_snapshot >= self.snapshot_every
            and model.snapshotting.acquire(blocking=False)
        )

    def watch(self, name: str, watcher: Watcher) -> Callable[[], None]:
        """Call ``watcher`` with every step of a model from now on; returns the unsubscribe."""
        model = self.get(name)
        model.watchers.append(watcher)
        return lambda: model.watchers.remove(watcher)

    @staticmethod
    def _publish(model: Model, step: Step, decision: Decision) -> None:
        event: dict[str, Any] = {
            "type": "step",
            "decision": decision.to_dict(),
            "observation": list(step.observation),
            "event": step.event,
            "learn": step.learn,
        }
        if decision.new_state or (step.event and decision.state is not None):
            event["state"] = model.shield.state_view(decision.state)  # type: ignore[arg-type]
        for watcher in list(model.watchers):
            watcher(event)

    @staticmethod
    def _journal(model: Model, learned: Sequence[Step]) -> None:
        """Append a model's learning steps to its journal (if it has a store) and count them
        towards its next snapshot."""
        if model.store is not None:
            version = model.shield.counters.model_version + len(learned)
            model.store.append({"v": version, "steps": [s.journal() for s in learned]})
        model.since_snapshot += len(learned)


def _validate(shield: Shield, step: Step, index: int | None) -> StepInput:
    """The step checked by its model; a refusal names the step's ``index`` in a batch."""
    try:
        return shield.validate(
            step.observation,
            step.action,
            stream=step.stream,
            event=step.event,
            done=step.done,
            applied_action=step.applied_action,
            learn=step.learn,
            shadow=step.shadow,
        )
    except ShieldError as error:
        if index is not None:
            error.field = f"steps.{index}.{error.field}" if error.field else f"steps.{index}"
        raise


def check_name(name: str) -> None:
    """Refuse names outside ``[a-z0-9][a-z0-9_-]{0,63}``."""
    if not NAME.fullmatch(name):
        raise InvalidName("a model name matches [a-z0-9][a-z0-9_-]{0,63}", field="name")
