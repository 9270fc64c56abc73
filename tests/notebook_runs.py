"""Executes the committed notebooks in background kernels while the rest of the suite runs.

Most of the suite compiles on one core; a notebook's kernel is a process of its own, so running the notebooks
beside the other tests uses the second core (``tests/conftest.py`` starts them when ``test_notebooks.py`` is
among the selected tests; ``test_notebooks.py`` waits for the results).

Under ``pytest -n`` every worker collects every test, so only one process executes the notebooks: the first worker
(``gw0``), or the only process without xdist. It publishes each executed notebook (or its error) in the run's shared
directory (``$HEATPF_TESTS_SHARED``, made by ``tests/conftest.py``), where a notebook test that another worker runs
reads it. Before, each worker started both kernels, and the notebooks ran twice.
"""

from __future__ import annotations

import os
import tempfile
import time
import traceback
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
SHARED_ENV = "HEATPF_TESTS_SHARED"
_RUNS: dict[str, Future] = {}
_POOL: ThreadPoolExecutor | None = None


def runs_here() -> bool:
    """Whether this process executes the notebooks: no xdist, or its first worker."""
    return os.environ.get("PYTEST_XDIST_WORKER", "gw0") == "gw0"


def _published(name: str) -> Path | None:
    shared = os.environ.get(SHARED_ENV)
    return Path(shared) / "notebooks" / name if shared else None


def _publish(name: str, text: str, suffix: str) -> None:
    target = _published(name)
    if target is None:
        return
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=".part-")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, target.with_name(target.name + suffix))


def _execute(path: Path):
    import nbformat
    from nbclient import NotebookClient

    try:
        nb = nbformat.read(path, as_version=4)
        stripped = all(not cell.get("outputs") for cell in nb.cells if cell.cell_type == "code")
        with tempfile.TemporaryDirectory() as cwd:
            NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": cwd}}).execute()
    except BaseException:
        _publish(path.name, traceback.format_exc(), ".error")
        raise
    _publish(path.name, ("stripped\n" if stripped else "outputs\n") + nbformat.writes(nb), ".done")
    return stripped, nb


def start() -> None:
    """Starts every notebook (once per session), each in its own kernel, in the process that runs them."""
    global _POOL
    if _POOL is None and runs_here():
        _POOL = ThreadPoolExecutor(max_workers=len(NOTEBOOKS) or 1, thread_name_prefix="notebook")
        for path in NOTEBOOKS:
            _RUNS[path.name] = _POOL.submit(_execute, path)


def wait() -> None:
    """Waits for the notebooks this process started (so that a worker does not exit before publishing them)."""
    for run in _RUNS.values():
        run.exception(timeout=600)


def result(path: Path, timeout: float = 600.0):
    """``(committed_stripped, executed_notebook)``; re-raises what the execution raised."""
    start()
    if path.name in _RUNS:
        return _RUNS[path.name].result(timeout=timeout)
    import nbformat

    target = _published(path.name)
    if target is None:
        raise RuntimeError(f"{path.name}: not executed in this worker and no {SHARED_ENV} to read it from")
    done, error = target.with_name(target.name + ".done"), target.with_name(target.name + ".error")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if error.exists():
            raise RuntimeError(f"{path.name} failed in worker gw0:\n{error.read_text()}")
        if done.exists():
            flag, _, text = done.read_text().partition("\n")
            return flag == "stripped", nbformat.reads(text, as_version=4)
        time.sleep(1.0)
    raise TimeoutError(f"{path.name}: no result from worker gw0 within {timeout:.0f} s")
