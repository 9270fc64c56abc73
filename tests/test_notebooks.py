"""Every committed notebook executes top to bottom (so it cannot rot)."""

import pytest

from tests.notebook_runs import NOTEBOOKS, result

# What each notebook must print: its result was produced.
PRINTS = {
    "quickstart.ipynb": "mean/conventional",  # the comparison table
    "tuning.ipynb": "NLL and MSE on the training sequences",  # start against tuned parameters
}


def test_every_notebook_is_checked():
    assert sorted(p.name for p in NOTEBOOKS) == sorted(PRINTS)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_executes(path):
    """Executed in a background kernel since the session started (tests/notebook_runs.py)."""
    stripped, nb = result(path)
    assert stripped, "commit notebooks stripped"
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    printed = "".join(o.get("text", "") for c in nb.cells if c.cell_type == "code" for o in c.outputs)
    assert PRINTS[path.name] in printed


def test_kernels_start_only_for_a_run_that_selected_the_notebooks(monkeypatch):
    """Not while collecting (``pytest --co``) and not when ``-k`` deselected the notebooks (the hook runs on
    the final selection, ``session.items``); before, ``pytest --co -k cli`` started both kernels."""
    from types import SimpleNamespace

    import tests.conftest as conftest
    import tests.notebook_runs as runs

    started = []
    monkeypatch.setattr(runs, "start", lambda: started.append(True))
    notebook = SimpleNamespace(nodeid="tests/test_notebooks.py::test_notebook_executes[quickstart.ipynb]")
    other = SimpleNamespace(nodeid="tests/cli/test_main.py::test_run_writes_csv_and_prints_errors")

    def session(items, collectonly=False):
        return SimpleNamespace(items=items, config=SimpleNamespace(option=SimpleNamespace(collectonly=collectonly)))

    conftest.pytest_runtestloop(session([other]))
    conftest.pytest_runtestloop(session([notebook, other], collectonly=True))
    assert started == []
    conftest.pytest_runtestloop(session([other, notebook]))
    assert started == [True]
