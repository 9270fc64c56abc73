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
