"""Write docs/configuration.md, the configuration reference, from the dataclasses of
``app.core.config``: every section's fields with their types, defaults, the ranges their
``__post_init__`` checks and the docstrings, so that the reference says what the code does.

    .venv/bin/python scripts/config_reference.py          # rewrite docs/configuration.md
    .venv/bin/python scripts/config_reference.py --check  # exit 1 when the file differs

``tests/test_config_reference.py`` fails when the committed file differs from what this
prints, so the reference cannot drift from the code.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import inspect
import io
import sys
import textwrap
import tokenize
import typing
from pathlib import Path
from typing import Any

from app.core import config

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "docs" / "configuration.md"

# The sections of ShieldConfig in their order, then the dataclasses its fields hold.
SECTIONS: tuple[tuple[str, type[Any]], ...] = (
    ("observation", config.ObservationSpec),
    ("observation.features[]", config.Feature),
    ("action", config.ActionSpec),
    ("criteria[]", config.Criterion),
    ("criteria[].bound", config.Bound),
    ("clustering", config.ClusteringConfig),
    ("transitions", config.TransitionConfig),
    ("reviser", config.ReviserConfig),
    ("risk", config.RiskConfig),
    ("limits", config.LimitsConfig),
)


def _type_name(hint: Any) -> str:
    """A type as a reader writes it: ``float``, ``"clip" | "reject"``, ``tuple[float, ...]``."""
    origin = typing.get_origin(hint)
    args = typing.get_args(hint)
    if origin is typing.Literal:
        return " \\| ".join("`null`" if a is None else f'`"{a}"`' for a in args)
    if origin is tuple:
        inner = ", ".join("..." if a is Ellipsis else _type_name(a).strip("`") for a in args)
        return f"`tuple[{inner}]`"
    if args:  # a union: X | None
        return " \\| ".join(_type_name(a) for a in args)
    name = "None" if hint is type(None) else getattr(hint, "__name__", str(hint))
    return f"`{name}`"


def _default(f: dataclasses.Field[Any]) -> str:
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
    else:
        return "required"
    if isinstance(value, tuple) and value and dataclasses.is_dataclass(value[0]):
        return "the paper's two (below)"
    if dataclasses.is_dataclass(value):
        return "its section's defaults"
    return f"`{value!r}`".replace("|", "\\|")


def _comments(cls: type[Any]) -> dict[str, str]:
    """The comment on each field: the comment lines just above it, then the one ending its line
    (units, the paper's name of the value, the reading of the paper's gap: A1-A16)."""
    source = textwrap.dedent(inspect.getsource(cls))
    inline = {
        token.start[0]: token.string.lstrip("# ").strip()
        for token in tokenize.generate_tokens(io.StringIO(source).readline)
        if token.type == tokenize.COMMENT
    }
    found: dict[str, str] = {}
    above: list[str] = []
    for number, line in enumerate(source.splitlines(), start=1):
        text = line.strip()
        if text.startswith("#"):
            above.append(text.lstrip("# "))
            continue
        name = text.split(":", 1)[0]
        if name.isidentifier() and ":" in text and not text.startswith("def "):
            found[name] = " ".join(above + [inline[number]] if number in inline else above)
        above = []
    return found


def _text(node: ast.expr) -> str:
    """A message as the user reads it: module constants filled in, other placeholders named."""
    if isinstance(node, ast.Constant):
        return str(node.value)
    if isinstance(node, ast.JoinedStr):
        parts = []
        for value in node.values:
            if isinstance(value, ast.Constant):
                parts.append(str(value.value))
            elif isinstance(value, ast.FormattedValue):
                inner = ast.unparse(value.value)
                if inner in vars(config) and not callable(vars(config)[inner]):
                    spec = ast.unparse(value.format_spec).strip("f'\"") if value.format_spec else ""
                    parts.append(format(vars(config)[inner], spec))
                elif isinstance(value.value, ast.Name | ast.Attribute):
                    parts.append("`" + inner.rsplit(".", 1)[-1] + "`")
                else:
                    parts.append("...")
        return "".join(parts)
    return ast.unparse(node)


def _field_of(node: ast.expr) -> str:
    """The top field a check names: ``low`` of ``"low.{i}"``, ``features`` of ``features.0.x``."""
    text = _text(node)
    return text.split(".", 1)[0].strip("{}")


def _checks(cls: type[Any]) -> dict[str, list[str]]:
    """What ``__post_init__`` refuses, per field, read from its ``_check*`` calls."""
    if "__post_init__" not in vars(cls):
        return {}
    tree = ast.parse(textwrap.dedent(inspect.getsource(vars(cls)["__post_init__"])))
    # `for name, values in (("weights", ...), ("divide_by", ...)):` checks each named field
    looped: dict[str, list[str]] = {}
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.For)
            and isinstance(node.target, ast.Tuple)
            and isinstance(node.target.elts[0], ast.Name)
            and isinstance(node.iter, ast.Tuple)
        ):
            looped[node.target.elts[0].id] = [
                str(item.elts[0].value)
                for item in node.iter.elts
                if isinstance(item, ast.Tuple) and isinstance(item.elts[0], ast.Constant)
            ]
    rules: dict[str, list[str]] = {}
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)):
            continue
        name, args = node.func.id, node.args
        if name == "_check" and len(args) == 3:
            field, rule = _field_of(args[1]), _text(args[2])
        elif name == "_check_range" and len(args) == 3:
            field = _field_of(args[2])
            rule = (
                f"low and high finite within +-{config.MAX_PHYSICAL:g}, high - low at least "
                f"{config.MIN_SPAN:g}"
            )
        elif name == "_check_name" and len(args) == 2:
            field, rule = _field_of(args[1]), f"1 to {config.MAX_NAME} characters"
        else:
            continue
        for name in looped.get(field, [field]) if isinstance(args[1], ast.Name) else [field]:
            rules.setdefault(name, []).append(rule.replace("|", "\\|"))
    return rules


def _section(path: str, cls: type[Any]) -> list[str]:
    hints = typing.get_type_hints(cls)
    comments = _comments(cls)
    checks = _checks(cls)
    doc = inspect.getdoc(cls) or ""
    lines = [f"## `{path}` ({cls.__name__})", "", doc, ""]
    lines += [
        "| field | type | default | notes | checked on construction |",
        "|---|---|---|---|---|",
    ]
    for f in dataclasses.fields(cls):
        rules = "; ".join(checks.pop(f.name, [])) or ""
        note = comments.get(f.name, "").replace("|", "\\|")
        lines.append(
            f"| `{f.name}` | {_type_name(hints[f.name])} | {_default(f)} | {note} | {rules} |"
        )
    if checks:  # checks across fields (their first field's name is not a field of its own)
        lines += ["", "Also checked: " + "; ".join(r for rs in checks.values() for r in rs) + "."]
    return lines + [""]


def render() -> str:
    """The whole reference, as docs/configuration.md holds it."""
    whole = config.ShieldConfig
    lines = [
        "# Configuration reference",
        "",
        "<!-- Generated by scripts/config_reference.py from app/core/config.py; do not edit:",
        "     run `.venv/bin/python scripts/config_reference.py` after changing them. -->",
        "",
        f"A model's configuration is one `ShieldConfig` (`app/core/config.py`), stored as JSON "
        f'with `"version": {config.CONFIG_VERSION}`; over HTTP it is the body\'s `config` '
        "(`docs/api.md`). Every field may be left out and takes the default below; a value "
        "outside its range is refused with the dotted field at fault (`InvalidConfig`, over "
        "HTTP 422 `invalid_config`). `ShieldConfig.paper()` and `ShieldConfig.paper_literal()` "
        "give the paper's reviser (`docs/algorithm.md`). A stored configuration of an older "
        "version loads through `ShieldConfig.from_stored` (`CHANGELOG.md` lists the versions).",
        "",
        inspect.getdoc(whole) or "",
        "",
    ]
    checks = _checks(whole)
    lines += ["| section | type | default | checked on construction |", "|---|---|---|---|"]
    hints = typing.get_type_hints(whole)
    for f in dataclasses.fields(whole):
        rules = "; ".join(checks.pop(f.name, []))
        lines.append(f"| `{f.name}` | {_type_name(hints[f.name])} | {_default(f)} | {rules} |")
    lines += [
        "",
        "The default criteria: "
        + ", ".join(
            f"`{c.name}` ({c.direction}"
            + (
                f", bound {c.bound.observation} below {c.bound.below:g}"
                if c.bound and c.bound.below is not None
                else ""
            )
            + ")"
            for c in config.PAPER_CRITERIA
        )
        + ".",
        "",
    ]
    for path, cls in SECTIONS:
        lines += _section(path, cls)
    return "\n".join(lines).rstrip("\n") + "\n"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--check",
        action="store_true",
        help="exit 1 when docs/configuration.md differs instead of writing it",
    )
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        if not OUT.exists() or OUT.read_text() != text:
            print(f"{OUT.relative_to(ROOT)} is out of date: run scripts/config_reference.py")
            return 1
        return 0
    OUT.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
