"""Executes the committed notebooks in background kernels while the rest of the suite runs.

Most of the suite compiles on one core; a notebook's kernel is a process of its own, so running the notebooks
beside the other tests uses the second core (``tests/conftest.py`` starts them when ``test_notebooks.py`` is
among the selected tests; ``test_notebooks.py`` waits for the results).
"""

from __future__ import annotations

import tempfile
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
_RUNS: dict[str, Future] = {}
_POOL: ThreadPoolExecutor | None = None


def _execute(path: Path):
    import nbformat
    from nbclient import NotebookClient

    nb = nbformat.read(path, as_version=4)
    stripped = all(not cell.get("outputs") for cell in nb.cells if cell.cell_type == "code")
    with tempfile.TemporaryDirectory() as cwd:
        NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": cwd}}).execute()
    return stripped, nb


def start() -> None:
    """Starts every notebook (once per session), each in its own kernel."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=len(NOTEBOOKS) or 1, thread_name_prefix="notebook")
        for path in NOTEBOOKS:
            _RUNS[path.name] = _POOL.submit(_execute, path)


def result(path: Path):
    """``(committed_stripped, executed_notebook)``; re-raises what the execution raised."""
    start()
    return _RUNS[path.name].result(timeout=600)
