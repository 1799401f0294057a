"""The package's layers (planner/__init__.py): imports go down or sideways, never up, no cycle.

Every module's imports are read with ``ast`` (TYPE_CHECKING and function-level imports
included) and held against :data:`planner.LAYERS`, which lists the subpackages from the
bottom up.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import planner

ROOT = Path(planner.__file__).resolve().parent


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, name: str, modules: set[str]) -> set[str]:
    """The planner modules that the file imports (a package name counts as its package)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(up + ([node.module] if node.module else []))
            targets = [
                f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names
            ]
        else:
            continue
        for t in targets:
            while t and t not in modules:
                t = t.rpartition(".")[0]
            if t and t != name and t != "planner":
                out.add(t)
    return out


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Module name -> the planner modules it imports."""
    files = {_module_name(p, root): p for p in root.rglob("*.py")}
    modules = set(files)
    return {name: _imports(p, name, modules) for name, p in files.items()}


def layer_of(module: str) -> int:
    """Index of the module's layer in planner.LAYERS (the top-level package or module)."""
    top = module.split(".")[1]
    return planner.LAYERS.index(top)


def violations(graph: dict[str, set[str]]) -> list[str]:
    """Upward imports and import cycles, one line each."""
    out = []
    for mod, deps in sorted(graph.items()):
        if mod == "planner":
            continue
        for d in sorted(deps):
            if layer_of(d) > layer_of(mod):
                out.append(f"{mod} imports {d}: up from layer {planner.LAYERS[layer_of(mod)]}")
    # cycles: depth-first search with colours
    colour: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        colour[m] = 1
        stack.append(m)
        for d in sorted(graph.get(m, ())):
            if colour.get(d) == 1:
                out.append("cycle: " + " -> ".join(stack[stack.index(d) :] + [d]))
            elif d not in colour:
                visit(d)
        stack.pop()
        colour[m] = 2

    for m in sorted(graph):
        if m not in colour:
            visit(m)
    return out


def test_every_module_belongs_to_a_layer():
    for mod in import_graph():
        if mod != "planner":
            assert mod.split(".")[1] in planner.LAYERS, mod


def test_no_upward_import_and_no_cycle():
    assert violations(import_graph()) == []


def _copy_package(tmp_path: Path) -> Path:
    dst = tmp_path / "planner"
    for p in ROOT.rglob("*.py"):
        q = dst / p.relative_to(ROOT)
        q.parent.mkdir(parents=True, exist_ok=True)
        q.write_text(p.read_text())
    return dst


def test_a_constructed_upward_import_fails(tmp_path):
    dst = _copy_package(tmp_path)
    kin = dst / "body" / "kinematics.py"
    kin.write_text(
        kin.read_text() + "\n\ndef _up():\n    from planner.planning.walk import plan_walk\n"
    )
    assert any(
        "body.kinematics imports planner.planning.walk" in v for v in violations(import_graph(dst))
    )


def test_a_type_checking_import_counts(tmp_path):
    dst = _copy_package(tmp_path)
    lie = dst / "core" / "lie.py"
    lie.write_text(
        lie.read_text() + "\nfrom typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
        "    from planner.world.terrain import Terrain\n"
    )
    assert any("core.lie imports planner.world.terrain" in v for v in violations(import_graph(dst)))


def test_a_constructed_cycle_fails(tmp_path):
    dst = _copy_package(tmp_path)
    lie = dst / "core" / "errors.py"
    lie.write_text(lie.read_text() + "\n\ndef _c():\n    from planner.core import outputs\n")
    assert any(v.startswith("cycle:") for v in violations(import_graph(dst)))


@pytest.mark.parametrize("layer", planner.LAYERS)
def test_each_layer_is_a_package_or_module(layer):
    assert (ROOT / layer / "__init__.py").exists() or (ROOT / f"{layer}.py").exists()
