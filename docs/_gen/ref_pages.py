"""Generate the API reference: one page per module of the ``planner`` package.

Run by mkdocs-gen-files at build time. The module list comes from walking ``planner/`` on
disk (:func:`reference_modules`), so a new module gets its page without editing the docs;
``tests/test_docs.py`` checks the walk covers every module and that every public name is
rendered. Each page is one mkdocstrings directive (``::: planner.x.y``); the members shown
are griffe's public ones (``filters: public`` in mkdocs.yml: ``__all__`` where the module
has one, else the names not starting with ``_`` defined in it).
"""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "planner"


def reference_modules(package: Path = PACKAGE) -> list[str]:
    """Dotted names of every module and package under ``package``, packages first."""
    names = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package.parent).with_suffix("")
        parts = rel.parts
        if any(p.startswith("_") and p != "__init__" for p in parts):
            continue  # private modules (none today)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        names.append(".".join(parts))
    return sorted(names, key=lambda n: n.split("."))


def page_path(module: str) -> str:
    """The reference page of ``module``: ``reference/planner/body/robot.md``.

    A package's page is its folder's ``index.md``.
    """
    parts = module.split(".")
    if (PACKAGE.parent.joinpath(*parts) / "__init__.py").exists():
        return "/".join(["reference", *parts, "index.md"])
    return "/".join(["reference", *parts]) + ".md"


def main() -> None:
    """Write the pages and the reference's navigation (``reference/SUMMARY.md``)."""
    import mkdocs_gen_files

    nav = mkdocs_gen_files.Nav()
    for module in reference_modules():
        parts = tuple(module.split("."))
        path = page_path(module)
        nav[parts] = path.removeprefix("reference/")
        with mkdocs_gen_files.open(path, "w") as fh:
            fh.write(f"::: {module}\n")
        mkdocs_gen_files.set_edit_path(path, Path(*parts[:-1], parts[-1] + ".py"))
    with mkdocs_gen_files.open("reference/SUMMARY.md", "w") as fh:
        fh.writelines(nav.build_literate_nav())


if __name__ == "<run_path>":  # mkdocs-gen-files runs this file with runpy.run_path
    main()
