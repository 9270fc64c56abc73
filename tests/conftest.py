"""Shared test settings: strict JAX promotion, small shared sizes so compiled functions are reused."""

import jax
import numpy as np
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

import heatpf_jax as hp  # noqa: E402
from heatpf_jax.sim import simulate_standard  # noqa: E402

# One small configuration shared by the filter-level tests, so `run` compiles once per shape.
SMALL_CONFIG = hp.FilterConfig(num_particles=128, max_measurements=128, k_max=8)


@pytest.fixture(scope="session")
def small_config() -> hp.FilterConfig:
    return SMALL_CONFIG


@pytest.fixture(scope="session")
def small_sequence() -> hp.Sequence:
    """20 steps of the standard scenario on a 50 x 37 heat map (shrink 4)."""
    return simulate_standard(3, num_steps=20, shrink=4)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)
