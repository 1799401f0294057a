"""The notebooks in notebooks/ run top to bottom without error (headless, nbclient).

They run two at a time (one kernel each, the machine has two cores); each test then checks
one notebook's run.
"""

import os
import time
import traceback
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
BOOKS = sorted(NOTEBOOKS.glob("*.ipynb"))


def _run(path: Path) -> tuple:
    """Execute one notebook; (notebook, error text or None, seconds)."""
    nb = nbformat.read(path, as_version=4)
    t0 = time.perf_counter()
    try:
        client = NotebookClient(
            nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(NOTEBOOKS)}}
        )
        client.execute()  # raises CellExecutionError, naming the cell, on any error
        error = None
    except Exception:  # reported by the test of that notebook
        error = traceback.format_exc()
    return nb, error, time.perf_counter() - t0


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    out = tmp_path_factory.mktemp("notebooks")
    env = {
        "STRATAWALK_NOTEBOOK_OUT": str(out),  # where the notebooks write their files
        "MPLBACKEND": "module://matplotlib_inline.backend_inline",
        "PYDEVD_DISABLE_FILE_VALIDATION": "1",
    }
    saved = {k: os.environ.get(k) for k in env}
    os.environ.update(env)  # the kernels inherit this environment
    try:
        with ThreadPoolExecutor(max_workers=2) as pool:
            results = dict(zip(BOOKS, pool.map(_run, BOOKS), strict=True))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return out, results


def _outputs(nb, kind):
    return [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
            if kind in o.get("data", {})]  # fmt: skip


def test_there_are_notebooks():
    assert len(BOOKS) >= 4
    for path in BOOKS:
        nb = nbformat.read(path, as_version=4)
        nbformat.validate(nb)
        assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), (
            f"{path.name}: commit notebooks without outputs"
        )


@pytest.mark.parametrize("path", BOOKS, ids=[p.stem for p in BOOKS])
def test_notebook_runs(path, runs):
    out, results = runs
    nb, error, seconds = results[path]
    assert error is None, f"{path.name} failed:\n{error}"
    # how long it ran is printed, not asserted: speed is the benchmarks' (make bench) to
    # judge, and a busy machine must not fail a notebook that runs
    print(f"{path.name}: {seconds:.0f} s")
    assert _outputs(nb, "image/png"), f"{path.name}: no figure was drawn"
    if path.stem.startswith(("03", "04")):  # the walks: replay inline, plan written
        (replay,) = _outputs(nb, "text/html")
        assert "<iframe srcdoc=" in replay["data"]["text/html"]
        folder = "03_walk" if path.stem.startswith("03") else "04_byo"
        assert (out / folder / "plan.json").is_file()
