"""Stored configurations of older versions, migrated to this one (CHANGELOG.md lists them).

A configuration that :meth:`~app.core.config.ShieldConfig.to_dict` wrote, maybe by an older
version of this package, becomes this version's plain data so that it decides as it did when
it was written (:func:`migrate`). One that used a switch since removed is refused
(:class:`InvalidConfig` names the field), and so is one that lacks a field its version wrote:
a stored configuration is whole, and a missing field would silently take a default.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from types import UnionType
from typing import Any, get_args, get_origin, get_type_hints

from app.core.config import CONFIG_VERSION, PAPER_CRITERIA, ShieldConfig, join_path
from app.core.errors import InvalidConfig


def migrate(data: Mapping[str, Any]) -> Mapping[str, Any]:
    """``data``, a whole stored configuration of any version, as this version's."""
    if not isinstance(data, Mapping):
        raise InvalidConfig("expected an object")
    version = data.get("version", 1)
    if isinstance(version, bool) or version not in range(1, CONFIG_VERSION + 1):
        raise InvalidConfig(f"unknown configuration version {version!r}", field="version")
    _check_written(data, version)
    if version == 1:
        data = _from_version_1(data)
    if version in (1, 2):
        data = _from_version_2(data)
    if version in (1, 2, 3):
        data = _from_version_3(data)
    if version in (1, 2, 3, 4):
        data = _from_version_4(data)
    return data


# The fields a stored version wrote that this version does not have ("section.field", and
# "section.*.field" for each item of a list), with the version that dropped them; and this
# version's fields with the version that added them (fields of every version: not listed).
# risk.model and limits.outcome_log came within version 2's life: not every version 2 has them.
_WENT = {"risk.prior_safe": 3, "risk.refresh_steps": 3}
_CAME = {"risk.reach_horizon": 4, "risk.reach_radius": 4, "criteria.*.bound": 5}


def _written(cls: type[Any], path: str) -> list[str]:
    """Every field path of a configuration dataclass (lists' items as ``*``)."""
    paths = []
    for name, hint in get_type_hints(cls).items():
        here = join_path(path, name)
        paths.append(here)
        if get_origin(hint) is UnionType:
            hint = next(a for a in get_args(hint) if a is not type(None))
        if get_origin(hint) is tuple and dataclasses.is_dataclass(get_args(hint)[0]):
            paths += _written(get_args(hint)[0], f"{here}.*")
        elif dataclasses.is_dataclass(hint):
            paths += _written(hint, here)  # type: ignore[arg-type]
    return paths


def _check_written(data: Mapping[str, Any], version: int) -> None:
    """Refuse a stored configuration of ``version`` (2 on) that lacks a field its version
    wrote, naming it. Version 1 gained fields over its life and its migration says what a
    missing one meant."""
    if version < 2:
        return
    required = [p for p in _written(ShieldConfig, "") if _came(p) <= version]
    required += [p for p, gone in _WENT.items() if version < gone]
    for path in required:
        _require(data, path.split("."), "")


def _came(path: str) -> int:
    """The version that added a field or the field it lies in (1: every version has it)."""
    keys = path.split(".")
    return max(_CAME.get(".".join(keys[:i]), 1) for i in range(1, len(keys) + 1))


def _require(part: Any, keys: list[str], at: str) -> None:
    """Follow ``keys`` through ``part`` (``*``: every item of a list); refuse a missing key.
    A part of another type, or a null optional section, is left to the build to judge."""
    if not keys:
        return
    key, rest = keys[0], keys[1:]
    if key == "*":
        if isinstance(part, list | tuple):
            for i, item in enumerate(part):
                _require(item, rest, join_path(at, str(i)))
        return
    if not isinstance(part, Mapping):
        return
    if key not in part:
        raise InvalidConfig(
            f"the stored configuration lacks {join_path(at, key)!r}", field=join_path(at, key)
        )
    _require(part[key], rest, join_path(at, key))


def _from_version_1(data: Mapping[str, Any]) -> dict[str, Any]:
    """Version 1 (no ``version`` field) to 2. A field that version 1 lacked takes the value it
    was added with, where the default has changed since; the switches removed in version 2 lost
    their trials (docs/lab/research-log.md) and must hold the value whose behaviour remains."""
    out = _copy(data)
    sections = {name: part for name, part in out.items() if isinstance(part, dict)}
    observation = sections.get("observation", {})
    reviser = sections.get("reviser", {})
    for name, value in (("method", "paper"), ("one_sided", False), ("flag_min_rate", 0.002)):
        reviser.setdefault(name, value)
    if "observation" in sections and "knee" not in observation:
        observation["knee"] = []
    curved = isinstance(observation.get("knee"), list | tuple) and any(observation["knee"])
    flags_rate = reviser.get("method") == "paper" and reviser.get("flags") == "rate"
    removed = (  # section, field, its value when missing, the value that remains, whether it counts
        ("observation", "knee_shape", "log", "double", curved),
        ("clustering", "failure_states", False, False, True),
        ("reviser", "failure_centres", False, False, True),
        ("reviser", "noise_side", "both", "both", True),
        ("reviser", "flag_rate_per", "recognition", "entry", flags_rate),
        ("risk", "precursor_steps", 0, 0, True),
        ("risk", "precursor_spacing", None, None, False),
    )
    _remove(sections, removed, 2)
    out["version"] = 2
    return out


def _from_version_2(data: Mapping[str, Any]) -> dict[str, Any]:
    """Version 2 to 3: the counted risk model (per state and action outcome counts and value
    iteration) lost to the local one everywhere (docs/lab/risk-reviser.md) and was removed with
    its settings. A risk reviser that used it (``risk.model`` missing means it: it came first)
    cannot be reproduced; its settings mean nothing to any other configuration."""
    out = _copy(data)
    sections = {name: part for name, part in out.items() if isinstance(part, dict)}
    risk_reviser = sections.get("reviser", {}).get("method") == "risk"
    removed = (
        ("risk", "model", "counts", "local", risk_reviser),
        ("risk", "prior_safe", 1.0, 1.0, False),
        ("risk", "refresh_steps", 500, 500, False),
        ("limits", "outcome_log", 0, 0, False),
    )
    _remove(sections, removed, 3)
    out["version"] = 3
    return out


def _from_version_3(data: Mapping[str, Any]) -> dict[str, Any]:
    """Version 3 to 4: the reach (``risk.reach_horizon``, ``risk.reach_radius``) came with
    version 4; a risk reviser written before it decided without it, and still does (the
    paper's reviser never reads the section)."""
    out = _copy(data)
    reviser = out.get("reviser", {})
    method = reviser.get("method", "risk") if isinstance(reviser, dict) else None
    risk_section = out.setdefault("risk", {})
    if method == "risk" and isinstance(risk_section, dict):
        risk_section.setdefault("reach_horizon", 0)
    out["version"] = 4
    return out


def _from_version_4(data: Mapping[str, Any]) -> dict[str, Any]:
    """Version 4 to 5: criteria may declare a bound (:class:`Bound`), and the default ones
    do. A configuration written before decided without bounds: one of version 1 that left its
    criteria out gets the paper's without them (one that lists them lacks bounds already;
    versions 2 to 4 always list them, :func:`_check_written`)."""
    out = _copy(data)
    out.setdefault("criteria", [{"name": c.name, "direction": c.direction} for c in PAPER_CRITERIA])
    out["version"] = CONFIG_VERSION
    return out


def _copy(data: Mapping[str, Any]) -> dict[str, Any]:
    return {
        key: dict(value) if isinstance(value, Mapping) else value for key, value in data.items()
    }


def _remove(
    sections: dict[str, dict[str, Any]],
    removed: tuple[tuple[str, str, Any, Any, bool], ...],
    version: int,
) -> None:
    """Drop removed fields; one whose value (or its value when missing) is not the behaviour
    that remains, where that matters, is refused."""
    for section, name, missing, remains, counts in removed:
        part = sections.get(section, {})
        value = part.pop(name, missing)
        if counts and value != remains:
            raise InvalidConfig(
                f"{section}.{name} = {value!r} was removed in configuration "
                f"version {version}; this version cannot reproduce it",
                field=f"{section}.{name}",
            )
