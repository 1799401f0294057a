"""Put the notebooks (``notebooks/*.ipynb``) into the site, rendered by mkdocs-jupyter.

Run by mkdocs-gen-files at build time: each notebook is copied to ``notebooks/`` of the
docs (not executed: ``tests/test_notebooks.py`` runs them; they are stored without
outputs, so the pages show the code and text only) with ``notebooks/SUMMARY.md``.
"""

from __future__ import annotations

import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def notebooks() -> list[tuple[Path, str]]:
    """Each notebook and its title (its first heading)."""
    out = []
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
        title = path.stem
        for cell in cells:
            if cell["cell_type"] == "markdown":
                first = "".join(cell["source"]).strip().splitlines()[0]
                title = first.lstrip("#").strip()
                break
        out.append((path, title))
    return out


def main() -> None:
    """Copy the notebooks in, with an index page and their navigation."""
    import mkdocs_gen_files

    nav = ["* [About the notebooks](index.md)"]
    index = [
        "# Notebooks",
        "",
        "Worked examples in `notebooks/`, shown here as stored: without outputs (the test "
        "suite runs each top to bottom, `tests/test_notebooks.py`). Run one headless with "
        "`.venv/bin/jupyter execute notebooks/NAME.ipynb`, or open them in a Jupyter client "
        "started on the project's virtualenv (JupyterLab is not among its packages).",
        "",
    ]
    for path, title in notebooks():
        with mkdocs_gen_files.open(f"notebooks/{path.name}", "wb") as fh:
            fh.write(path.read_bytes())
        nav.append(f"* [{title}]({path.name})")
        index.append(f"- [{title}]({path.name})")
    with mkdocs_gen_files.open("notebooks/index.md", "w") as fh:
        fh.write("\n".join(index) + "\n")
    with mkdocs_gen_files.open("notebooks/SUMMARY.md", "w") as fh:
        fh.write("\n".join(nav) + "\n")


if __name__ == "<run_path>":  # mkdocs-gen-files runs this file with runpy.run_path
    main()
