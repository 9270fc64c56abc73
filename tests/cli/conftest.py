"""Fixtures of the command-line tests: a small sequence file with the shapes of ``tests.conftest``'s."""

import pytest

import heatpf_jax as hp
from heatpf_jax.sim import simulate_standard


@pytest.fixture(scope="module")
def seq_file(tmp_path_factory):
    """``(path, sequence)``: 20 steps of the standard scenario, seed 3, shrink 4, saved once per module."""
    seq = simulate_standard(3, num_steps=20, shrink=4)  # same shapes as conftest's small_sequence
    path = tmp_path_factory.mktemp("cli") / "seq.npz"
    hp.save_sequence(path, seq)
    return path, seq
