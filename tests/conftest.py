"""Shared test settings: strict JAX promotion, small shared sizes so compiled functions are reused."""

import os

import jax
import numpy as np
import pytest

# The tests never write JAX's persistent compilation cache into the user's cache directory.
os.environ.setdefault("HEATPF_NO_CACHE", "1")

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

import heatpf_jax as hp  # noqa: E402
from heatpf_jax.sim import simulate_standard  # noqa: E402

# One small filter shared by the filter-level tests, so `run` compiles once per shape.
SMALL_OPTIONS = hp.FilterOptions(num_particles=128, max_measurements=128, k_max=8)
SMALL_FILTER = hp.paper_filter(SMALL_OPTIONS)


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session):
    """Starts the notebooks in background kernels when their test is selected (tests/notebook_runs.py).

    At the start of the test loop, after ``-k``/``-m`` deselection and never for ``--collect-only``, so
    collecting or running other tests starts no kernel.
    """
    if session.config.option.collectonly:
        return
    if any("test_notebooks.py::test_notebook_executes" in item.nodeid for item in session.items):
        from tests.notebook_runs import start

        start()


@pytest.fixture(scope="session")
def small_filter() -> hp.Filter:
    return SMALL_FILTER


@pytest.fixture(scope="session")
def small_sequence() -> hp.Sequence:
    """20 steps of the standard scenario on a 50 x 37 heat map (shrink 4)."""
    return simulate_standard(3, num_steps=20, shrink=4)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def step_inputs(seq: hp.Sequence, t: int, *, odometry=(0.0, 0.0, 0.0), has_heatmap: bool | None = None):
    """Step t of ``seq`` as one step's ``StepInputs`` (the given odometry; the file's has_heatmap unless given)."""
    import jax.numpy as jnp

    return hp.StepInputs(
        heatmap=jnp.asarray(seq.heatmaps[t], jnp.float32),
        has_heatmap=jnp.asarray(seq.has_heatmap[t] if has_heatmap is None else has_heatmap),
        cam_to_base=jnp.asarray(seq.cam_to_base[t], jnp.float32),
        odometry=jnp.asarray(odometry, jnp.float32),
        intrinsics=jnp.asarray(seq.intrinsics, jnp.float32),
        plane_height=jnp.asarray(seq.ball_radius, jnp.float32),
        dt=jnp.asarray(seq.dt, jnp.float32),
    )
