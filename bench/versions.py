"""A package of this repository as it was at another commit, beside this checkout's, and the
paired medians of the two: the ``*_versions.py`` benchmarks time both in one process."""

from __future__ import annotations

import importlib
import statistics
import subprocess
import sys
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def load_package(commit: str, path: str, directory: Path) -> ModuleType:
    """The package at ``path`` (for example ``client/agents``) as it was at ``commit``, as a
    package of its own in ``directory`` whose modules import each other, not this
    checkout's; every module imported."""

    def git(*args: str) -> str:
        return subprocess.run(
            ["git", *args], cwd=ROOT, check=True, capture_output=True, text=True
        ).stdout

    dotted = path.replace("/", ".")
    name = f"{path.rsplit('/', 1)[-1]}_{commit}"
    package = directory / name
    package.mkdir()
    modules = []
    for file in git("ls-tree", "--name-only", f"{commit}:{path}").split():
        if file.endswith(".py"):
            source = git("show", f"{commit}:{path}/{file}")
            (package / file).write_text(
                source.replace(f"{dotted}.", f"{name}.").replace(
                    f"from {dotted} import", f"from {name} import"
                )
            )
            modules.append(file.removesuffix(".py"))
    sys.path.insert(0, str(directory))
    loaded = importlib.import_module(name)
    for module in modules:
        if module != "__init__":
            importlib.import_module(f"{name}.{module}")
    return loaded


def paired(other: list[float], this: list[float], unit: float = 1.0) -> dict[str, Any]:
    """Each commit's median over rounds (times ``unit``) and the median of the rounds'
    ratios, other over this: the speed-up of this checkout."""
    return {
        "other_ms": statistics.median(other) * unit,
        "this_ms": statistics.median(this) * unit,
        "speed_up": statistics.median(o / t for o, t in zip(other, this, strict=True)),
        "rounds": {"other": other, "this": this},
    }


def table_row(label: str, row: dict[str, Any], same: bool) -> str:
    """A Markdown row of :func:`paired`'s result and whether both commits gave the same."""
    return (
        f"| {label} | {row['other_ms']:.2f} | {row['this_ms']:.2f} | "
        f"{row['speed_up']:.2f}x | {'yes' if same else 'no'} |"
    )
