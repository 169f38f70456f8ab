"""docs/configuration.md is what scripts/config_reference.py writes from app/core/config.py, so
the configuration reference cannot drift from the dataclasses."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

from app.core import config

ROOT = Path(__file__).resolve().parent.parent


def _script() -> ModuleType:
    spec = importlib.util.spec_from_file_location(
        "config_reference", ROOT / "scripts" / "config_reference.py"
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_committed_reference_is_what_the_script_writes() -> None:
    committed = (ROOT / "docs" / "configuration.md").read_text()
    assert committed == _script().render(), (
        "docs/configuration.md is out of date: run .venv/bin/python scripts/config_reference.py"
    )


def test_every_field_of_every_section_is_in_the_reference() -> None:
    text = _script().render()
    for section in (
        config.ObservationSpec,
        config.Feature,
        config.ActionSpec,
        config.Criterion,
        config.Bound,
        config.ClusteringConfig,
        config.TransitionConfig,
        config.ReviserConfig,
        config.RiskConfig,
        config.LimitsConfig,
        config.ShieldConfig,
    ):
        for f in dataclasses.fields(section):
            assert f"| `{f.name}` |" in text, f"{section.__name__}.{f.name}"


def test_a_checked_range_appears_beside_its_field() -> None:
    """The range __post_init__ enforces is read from its _check call, not written by hand."""
    rows = {
        line.split("|")[1].strip(): line
        for line in _script().render().splitlines()
        if line.startswith("| `")
    }
    assert "epsilon lies in (0, 10]" in rows["`epsilon`"]
    assert "reach_horizon lies in [0, 1024]" in rows["`reach_horizon`"]
    assert f"lies in [1, {config.MAX_TOP_K}]" in rows["`belief_top_k`"]


def test_check_reports_a_stale_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    script = _script()
    stale = tmp_path / "configuration.md"
    stale.write_text("# an old reference\n")
    monkeypatch.setattr(script, "OUT", stale)
    monkeypatch.setattr(script, "ROOT", tmp_path)
    assert script.main(["--check"]) == 1
    assert script.main([]) == 0
    assert script.main(["--check"]) == 0
    assert stale.read_text() == script.render()
