"""The options several subcommands share: the error statistics after ``--burn-in``."""

import numpy as np
import pytest

from heatpf_jax.cli.options import error_stats


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


def test_error_stats_against_hand_values():
    est = np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 0.0]])
    truth = np.zeros((3, 2))
    stats = error_stats(est, truth)
    assert stats["mean"] == pytest.approx(2.0) and stats["max"] == pytest.approx(5.0)
    assert stats["std"] == pytest.approx(np.std([0.0, 5.0, 1.0]))
    stats = error_stats(est, truth, burn_in=1)
    assert stats["mean"] == pytest.approx(3.0) and stats["std"] == pytest.approx(2.0)
