"""What the generated doc pages read from the code: commands, options, settings, terrain fields.

Shared by the mkdocs-gen-files scripts beside it (``cli_pages.py``, ``settings_page.py``) and
by ``tests/test_docs.py``. Everything here reads the code itself (the argparse parser, the
settings dataclasses and their docstrings, the terrain kinds' field reads), so the pages
cannot drift from it; where the code has no help for an option, ``MISSING_HELP`` supplies it
and the build fails once the code has its own (or the option is gone).
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import dataclasses
import inspect
import io
import os
import re
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
HELP_COLUMNS = "100"

# Options whose parser gives no help text: their effect, until the code has one. Keyed by
# (command path, option); the build fails if an entry's option is gone or has help now.
MISSING_HELP = {
    ("plan", "--robot"): "littledog, an example-robot-data name, or a URDF path",
    ("plan", "--out"): "the plan file to write (stratawalk.plan/1 JSON)",
    ("demo", "--terrain"): "terrain of the demo walk (a name or a YAML path)",
    ("demo", "--out"): "folder for plan.json, replay.html and figures/",
    ("bench theta", "--seed"): "seed of the random instances (same seed, same instances)",
}

# Units by name suffix, for settings and fields whose help has no [unit].
_SUFFIX_UNITS = (
    ("_nm_s_per_rad", "N m s/rad"),
    ("_nm_per_rad", "N m/rad"),
    ("_kg_m2", "kg m²"),
    ("_pct", "%"),
    ("_m_s2", "m/s²"),
    ("_m_s", "m/s"),
    ("_mg_per_l", "m g / L"),
    ("_nm", "N m"),
    ("_n", "N"),
    ("_kg", "kg"),
    ("_hz", "Hz"),
    ("_deg", "deg"),
    ("_rad", "rad"),
    ("_mm", "mm"),
    ("_m", "m"),
    ("_s", "s"),
)


def unit_of(name: str, text: str = "") -> str:
    """The unit of a setting: a ``[unit]`` in its help text, else its name's suffix, else ''."""
    m = re.search(r"\[([^\]]*?(?:m|s|Hz|deg|rad|N|kg|mm|m/s\^2|%)[^\]]*)\]", text or "")
    if m and len(m.group(1)) <= 12 and not re.search(r"[,;]", m.group(1)):
        return m.group(1).replace("^2", "²")
    low = name.lower().lstrip("-").replace("-", "_")
    for suffix, unit in _SUFFIX_UNITS:
        if low.endswith(suffix):
            return unit
    return ""


# ---------------------------------------------------------------------------------------
# The command line.


def build_parser() -> argparse.ArgumentParser:
    """The ``stratawalk`` parser, its help formatted at ``HELP_COLUMNS`` columns."""
    os.environ["COLUMNS"] = HELP_COLUMNS
    from planner.cli.main import build_parser as build

    return build()


def _subparsers(parser: argparse.ArgumentParser):
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return action
    return None


def commands(parser: argparse.ArgumentParser | None = None) -> list[tuple[tuple[str, ...], Any]]:
    """Every command and sub-command as ((name, ...), parser, one-line help), parser order."""
    parser = parser or build_parser()
    out = []

    def walk(p, path):
        sub = _subparsers(p)
        if sub is None:
            return
        helps = {a.dest: a.help or "" for a in sub._choices_actions}
        for name, sp in sub.choices.items():
            out.append(((*path, name), sp, helps.get(name, "")))
            walk(sp, (*path, name))

    walk(parser, ())
    return out


def help_text(parser: argparse.ArgumentParser) -> str:
    """``--help`` of a (sub)parser, as the command prints it."""
    os.environ["COLUMNS"] = HELP_COLUMNS
    return parser.format_help()


def _default(action: argparse.Action) -> str:
    if isinstance(action, (argparse._StoreTrueAction, argparse._StoreFalseAction)):
        return "off" if action.default in (False, None) else "on"
    if action.required:
        return "required"
    if action.default is None or action.default is argparse.SUPPRESS:
        return ""
    return str(action.default)


def options(path: tuple[str, ...], parser: argparse.ArgumentParser) -> list[dict]:
    """The options and arguments of one command: name, value, default, unit, effect."""
    rows = []
    for action in parser._actions:
        if isinstance(action, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        name = ", ".join(action.option_strings) if action.option_strings else action.dest
        key = (" ".join(path), action.option_strings[0] if action.option_strings else name)
        text = action.help or ""
        if key in MISSING_HELP:
            if text:
                raise RuntimeError(f"docs/_gen/docinfo.py: {key} has help now; drop MISSING_HELP")
            text = MISSING_HELP[key]
        if action.choices:
            value = "{" + ",".join(map(str, action.choices)) + "}"
        elif action.nargs == 0:
            value = ""
        else:
            value = action.metavar or (action.dest.upper() if action.option_strings else "")
        rows.append(
            {
                "name": name,
                "value": value if action.option_strings else "(argument)",
                "default": _default(action),
                "unit": unit_of(action.dest, text),
                "effect": text,
            }
        )
    return rows


def check_missing_help(parser: argparse.ArgumentParser | None = None) -> None:
    """Fail when an entry of ``MISSING_HELP`` names an option that is gone."""
    known = set()
    for path, p, _ in commands(parser):
        for a in p._actions:
            if a.option_strings:
                known.add((" ".join(path), a.option_strings[0]))
    gone = sorted(set(MISSING_HELP) - known)
    if gone:
        raise RuntimeError(
            f"docs/_gen/docinfo.py: MISSING_HELP names options that are gone: {gone}"
        )


def run_cli(argv: list[str]) -> str:
    """What ``stratawalk ARGV`` prints on stdout."""
    from planner.cli.main import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        rc = main(argv)
    if rc != 0:
        raise RuntimeError(f"stratawalk {' '.join(argv)}: exit {rc}")
    return out.getvalue()


# ---------------------------------------------------------------------------------------
# Settings dataclasses and their docstrings.


def field_docs(cls: type) -> dict[str, str]:
    """Field descriptions of a class: its docstring's ``name : text`` items, then comments.

    ``a, b : text`` describes both; a field's trailing ``# comment`` counts where the
    docstring has no item for it.
    """
    doc = inspect.getdoc(cls) or ""
    out: dict[str, str] = {}
    current: list[str] = []
    text: list[str] = []

    def flush():
        for n in current:
            out.setdefault(n, " ".join(text).strip())

    for line in doc.splitlines():
        m = re.match(r"^([A-Za-z_][\w.]*(?:, [A-Za-z_][\w.]*)*) : (.*)$", line)
        if m:
            flush()
            current, text = [n.strip() for n in m.group(1).split(",")], [m.group(2)]
        elif current and line.startswith("    "):
            text.append(line.strip())
        else:
            flush()
            current, text = [], []
    flush()
    for name, comment in field_comments(cls).items():
        out.setdefault(name, comment)
    return out


def field_comments(cls: type) -> dict[str, str]:
    """The trailing ``# comment`` of each field line of a dataclass body."""
    try:
        lines, _ = inspect.getsourcelines(cls)
    except (OSError, TypeError):
        return {}
    out = {}
    for line in lines:
        m = re.match(r"^\s+([A-Za-z_]\w*)\s*:[^#]*#\s*(.*)$", line)
        if m:
            out[m.group(1)] = m.group(2).strip()
    return out


def dataclass_rows(cls: type) -> list[dict]:
    """One row per field: name, type, default, unit, effect."""
    docs = field_docs(cls)
    rows = []
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            made = f.default_factory()
            default = type(made).__name__ + "()" if dataclasses.is_dataclass(made) else repr(made)
        else:
            default = "required"
        typ = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", str(f.type))
        effect = docs.get(f.name, "")
        rows.append(
            {
                "name": f.name,
                "type": typ,
                "default": default,
                "unit": unit_of(f.name, effect),
                "effect": effect,
            }
        )
    return rows


# ---------------------------------------------------------------------------------------
# Terrain fields, read from the kinds' code.

_FIELD_METHODS = {"number", "integer", "string", "pair", "raw", "has"}
_DEFAULT_WORDS = {
    "ctx.u0": "the segment's start (x_min)",
    "ctx.u1": "the segment's end (x_min + length)",
    "ctx.y0": "y_min",
    "ctx.y1": "y_max",
    "_REQUIRED": "required",
}


def _kw(call: ast.Call, name: str):
    for k in call.keywords:
        if k.arg == name:
            return k.value
    return None


def _show(node, namespace: dict | None = None) -> str:
    """A default or bound as the code writes it, module constants by their value."""
    if node is None:
        return ""
    ns = namespace or {}
    sign, inner = "", node
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        sign, inner = "-", node.operand
    value = ns.get(inner.id) if isinstance(inner, ast.Name) else None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return f"{sign}{value!r}"
    if isinstance(value, str) and not sign:
        return repr(value)
    text = ast.unparse(node)
    for code, words in _DEFAULT_WORDS.items():
        text = text if text != code else words
        text = re.sub(rf"\b{re.escape(code)}\b", words, text) if code == "_REQUIRED" else text
    return text


def _field_calls(fn_nodes, helpers: dict, seen: set[str], ns: dict | None = None) -> list[dict]:
    """The ``f.<method>("key", ...)`` reads in these nodes (the fields a kind reads).

    Module helpers called with ``f`` are followed; ``ns``, the module's namespace, shows
    constants by their value.
    """
    out = []
    for node in fn_nodes:
        for call in ast.walk(node):
            if not isinstance(call, ast.Call):
                continue
            func = call.func
            if (
                isinstance(func, ast.Attribute)
                and func.attr in _FIELD_METHODS
                and isinstance(func.value, ast.Name)
                and func.value.id in ("f", "top", "sf")
                and call.args
                and isinstance(call.args[0], ast.Constant)
                and isinstance(call.args[0].value, str)
            ):
                default = call.args[1] if len(call.args) > 1 else _kw(call, "default")
                method = func.attr
                if method == "has":
                    out.append({"name": call.args[0].value, "method": "has"})
                    continue
                lo, hi = _kw(call, "lo"), _kw(call, "hi")
                lo_open = _kw(call, "lo_open")
                bounds = []
                if lo is not None:
                    op = ">" if isinstance(lo_open, ast.Constant) and lo_open.value else ">="
                    bounds.append(f"{op} {_show(lo, ns)}")
                if hi is not None:
                    bounds.append(f"<= {_show(hi, ns)}")
                if _kw(call, "nonzero") is not None:
                    bounds.append("!= 0")
                hint = _kw(call, "hint")
                out.append(
                    {
                        "name": call.args[0].value,
                        "method": method,
                        "default": "required" if default is None else _show(default, ns),
                        "range": ", ".join(bounds),
                        "hint": hint.value if isinstance(hint, ast.Constant) else "",
                    }
                )
            elif (
                isinstance(func, ast.Name)
                and func.id in helpers
                and func.id not in seen
                and any(isinstance(a, ast.Name) and a.id == "f" for a in call.args)
            ):
                out += _field_calls([helpers[func.id]], helpers, seen | {func.id}, ns)
    return out


def _merge(calls: list[dict]) -> list[dict]:
    """One row per field name, in reading order (a ``has`` alone: an optional field)."""
    rows: dict[str, dict] = {}
    for c in calls:
        row = rows.setdefault(
            c["name"],
            {"name": c["name"], "method": "", "default": "", "range": "", "hint": "", "if": 0},
        )
        if c["method"] == "has":
            row["if"] = 1
            continue
        for k in ("method", "default", "range", "hint"):
            row[k] = row[k] or c.get(k, "")
    for row in rows.values():
        if row.pop("if") and row["default"] in ("", "required"):
            row["default"] = "optional"
    return list(rows.values())


def terrain_kind_fields() -> dict[str, list[dict]]:
    """Per terrain kind (``KINDS``), the fields its code reads: name, default, range, hint."""
    from planner.world.terrain import KINDS

    out = {}
    for kind, cls in KINDS.items():
        module = inspect.getmodule(cls)
        tree = ast.parse(inspect.getsource(module))
        helpers = {n.name: n for n in tree.body if isinstance(n, ast.FunctionDef)}
        cls_node = next(
            n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == cls.__name__
        )
        out[kind] = _merge(_field_calls([cls_node], helpers, set(), vars(module)))
    return out


def terrain_top_fields() -> tuple[list[dict], list[dict]]:
    """The fields of a terrain file's top level and of a ``course`` segment."""
    from planner.world import terrain

    tree = ast.parse(inspect.getsource(terrain))
    cls = next(n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "Terrain")
    init = next(n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "__init__")
    course = next(
        n for n in cls.body if isinstance(n, ast.FunctionDef) and n.name == "_read_course"
    )
    ns = vars(terrain)
    top = _field_calls([init], {}, set(), ns) + [
        c for c in _field_calls([course], {}, set(), ns) if c["name"] == "segments"
    ]
    seg = [c for c in _field_calls([course], {}, set(), ns) if c["name"] != "segments"]
    return _merge([c for c in top if c["method"] != "has"]), _merge(seg)


def kind_descriptions() -> dict[str, str]:
    """Each kind's paragraph of :mod:`planner.world.terrain`'s docstring (``kind`` heading)."""
    from planner.world import terrain

    doc = inspect.getdoc(terrain) or ""
    out, current, text = {}, None, []
    for line in doc.splitlines():
        m = re.match(r"^``(\w+)``\s*$", line)
        if m or (line and not line.startswith(" ")):
            if current:
                out[current] = " ".join(text).strip()
            current, text = (m.group(1), []) if m else (None, [])
        elif current:
            text.append(line.strip())
    if current:
        out[current] = " ".join(text).strip()
    return out


_ROLE = re.compile(r":(?:py:)?[a-z]+:`~?([^`]+)`")


def md_escape(text: str) -> str:
    """Docstring text for a markdown table cell: one line, no pipes, reST markup as code."""
    text = _ROLE.sub(lambda m: f"`{m.group(1)}`", " ".join(str(text).split()))
    return text.replace("``", "`").replace("|", "\\|")
