"""The documentation site (mkdocs.yml, docs/): its strict build catches a broken
cross-reference, and its generated pages cover the code.

The full site is built by ``make docs`` (``mkdocs build --strict``); these tests build only a
one-page project with the site's mkdocstrings configuration (a few seconds), and check the
generators in ``docs/_gen/`` without mkdocs. They need the ``docs`` extra (mkdocs,
mkdocstrings), which the ``dev`` extra (make test) installs.
"""

import ast
import importlib.util
import os
import pkgutil
import subprocess
import sys
from pathlib import Path

import yaml

import planner

ROOT = Path(__file__).resolve().parents[1]
GEN = ROOT / "docs" / "_gen"


def _module(name: str):
    spec = importlib.util.spec_from_file_location(f"docs_gen_{name}", GEN / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(GEN))
    try:
        spec.loader.exec_module(mod)
    finally:
        sys.path.remove(str(GEN))
    return mod


def _site_config() -> dict:
    return yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))


def _mkdocstrings_plugin() -> dict:
    """The site's mkdocstrings configuration, its paths made absolute."""
    for plugin in _site_config()["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            conf = plugin["mkdocstrings"]
            python = conf["handlers"]["python"]
            python["paths"] = [str(ROOT / p) for p in python["paths"]]
            python["options"]["extensions"] = [
                str(ROOT / e) for e in python["options"].get("extensions", [])
            ]
            return {"mkdocstrings": conf}
    raise AssertionError("mkdocs.yml: no mkdocstrings plugin")


def _build(tmp_path: Path, page: str):
    """``mkdocs build --strict`` of a one-page project with the site's mkdocstrings setup."""
    import mkdocs  # noqa: F401  (the docs extra, installed by the dev extra)
    import mkdocstrings  # noqa: F401

    docs = tmp_path / "docs"
    docs.mkdir()
    (docs / "index.md").write_text(page, encoding="utf-8")
    config = {
        "site_name": "test",
        "docs_dir": str(docs),
        "site_dir": str(tmp_path / "site"),
        "plugins": [_mkdocstrings_plugin()],
    }
    (tmp_path / "mkdocs.yml").write_text(yaml.safe_dump(config), encoding="utf-8")
    return subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(tmp_path / "mkdocs.yml")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1", "DISABLE_MKDOCS_2_WARNING": "true"},
    )


PAGE = "# Units\n\n::: planner.core.units\n\nGravity: [g][{target}].\n"


def test_a_broken_cross_reference_fails_the_strict_build(tmp_path):
    run = _build(tmp_path, PAGE.format(target="planner.no_such_thing"))
    assert run.returncode != 0, run.stdout + run.stderr
    assert "planner.no_such_thing" in run.stderr, run.stderr


def test_a_valid_cross_reference_builds(tmp_path):
    run = _build(tmp_path, PAGE.format(target="planner.core.units.GRAVITY_M_S2"))
    assert run.returncode == 0, run.stdout + run.stderr
    html = (tmp_path / "site" / "index.html").read_text(encoding="utf-8")
    assert 'href="#planner.core.units.GRAVITY_M_S2"' in html


def test_the_reference_has_a_page_for_every_module():
    ref = _module("ref_pages")
    walked = {"planner"} | {
        m.name for m in pkgutil.walk_packages(planner.__path__, "planner.", onerror=print)
    }
    listed = ref.reference_modules()
    assert set(listed) == walked
    pages = [ref.page_path(m) for m in listed]
    assert len(set(pages)) == len(pages)
    for layer in planner.LAYERS:
        assert f"planner.{layer}" in listed


def _public_names(path: Path) -> set[str]:
    """``__all__``, or else the public names a module defines at its top level."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return {ast.literal_eval(e) for e in node.value.elts}
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if not n.startswith("_")}


def test_every_public_name_is_in_the_reference():
    """What ``filters: public`` renders (griffe's public members) covers every public name."""
    import griffe

    options = _mkdocstrings_plugin()["mkdocstrings"]["handlers"]["python"]["options"]
    assert options["filters"] == "public" and options["show_if_no_docstring"] is True
    assert any(e.endswith("griffe_ext.py:LazyExports") for e in options["extensions"])
    sys.path.insert(0, str(GEN))
    try:
        import griffe_ext
    finally:
        sys.path.remove(str(GEN))
    extensions = griffe.load_extensions(griffe_ext.LazyExports)  # as mkdocs.yml has it
    pkg = griffe.load(
        "planner", search_paths=[str(ROOT)], extensions=extensions, resolve_aliases=True
    )
    ref = _module("ref_pages")
    missing = []
    for name in ref.reference_modules():
        module = pkg if name == "planner" else pkg[name.removeprefix("planner.")]
        for public in sorted(_public_names(Path(module.filepath))):
            member = module.members.get(public)
            if member is None or not member.is_public:
                missing.append(f"{name}.{public}")
    assert not missing, f"not rendered in the API reference: {missing}"


def test_every_command_has_its_page_and_example():
    cli = _module("cli_pages")
    info = _module("docinfo")
    info.check_missing_help()
    top = [path[0] for path, _, _ in info.commands() if len(path) == 1]
    assert sorted(top) == sorted(cli.EXAMPLES)
    for path, parser, _ in info.commands():
        for row in info.options(path, parser):
            assert row["effect"], f"stratawalk {' '.join(path)} {row['name']}: no help text"
