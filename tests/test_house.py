"""The shape the code keeps: no function of the service or the core takes more than a dozen
parameters (a part hands the compiled step one tuple of its arrays, :mod:`app.core.step`), and
every reviser is one module of ``app/core/revisers/`` named by the configuration."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import get_args, get_type_hints

from app.core import ReviserConfig
from app.core.revisers import REVISERS, Reviser

APP = Path(__file__).resolve().parents[1] / "app"
MOST = 12


def parameters(node: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """A function's parameters, ``self`` or ``cls`` not counted, nor ``*args``/``**kwargs``."""
    a = node.args
    named = [*a.posonlyargs, *a.args, *a.kwonlyargs]
    return len(named) - (1 if named and named[0].arg in ("self", "cls") else 0)


def test_no_function_in_app_takes_more_than_a_dozen_parameters() -> None:
    wide = [
        f"{path.relative_to(APP.parent)}:{node.lineno} {node.name} ({parameters(node)})"
        for path in sorted(APP.rglob("*.py"))
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and parameters(node) > MOST
    ]
    assert not wide, wide


def test_each_reviser_the_configuration_names_is_one_module_of_the_revisers() -> None:
    methods = get_args(get_type_hints(ReviserConfig)["method"])
    assert set(methods) == set(REVISERS) == {"risk", "paper"}
    for name, reviser in REVISERS.items():
        assert issubclass(reviser, Reviser) and reviser is not Reviser
        assert reviser.__module__ == f"app.core.revisers.{name}"
