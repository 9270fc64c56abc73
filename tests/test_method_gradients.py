"""Gradients of a run's loss with respect to every trainable parameter of the heatmap method (velocity,
the range-aware observation, measurement explorers) and of the extended method (mass inertia, cluster-wise
resampling, random particles) are finite, and nonzero for the new continuous ones."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from tests.conftest import SMALL_OPTIONS

NEW = {
    "heatmap": (
        "motion.accel_std",
        "motion.spawn_speed_std",
        "observation.gain",
        "observation.template_px",
        "observation.min_std",
        "injectors.measurement.measurement_jitter",
    ),
    "extended": (
        "motion.rho_move",
        "motion.rho_position",
        "motion.noise",
        "observation.obs_std",
        "injectors.measurement.measurement_jitter",
    ),
}


@pytest.mark.parametrize("method", sorted(NEW))
def test_run_gradients_are_finite(small_sequence, method):
    model, params = hp.build(method, SMALL_OPTIONS)
    props = model.properties()
    trainable, frozen = P.partition(P.as_arrays(params, props), props)
    truth = jnp.asarray(small_sequence.ground_truth, jnp.float32)

    def loss(u):
        p = P.combine(P.from_unconstrained(u, props), frozen)
        mean = hp.run(jax.random.key(0), small_sequence, p, model).info.mean
        return jnp.mean(jnp.sum((mean - truth) ** 2, axis=-1))

    value, grads = jax.value_and_grad(loss)(P.to_unconstrained(trainable, props))
    g = dict(zip(P.leaf_names(grads), (float(x) for x in jax.tree.leaves(grads)), strict=True))
    assert np.isfinite(float(value)) and all(np.isfinite(x) for x in g.values()), g
    for name in NEW[method]:
        assert g[name] != 0.0, (name, g)
