"""Gradients of a run's loss with respect to every trainable parameter of the heatmap method (velocity,
the range-aware observation, measurement explorers) and of the extended method (mass inertia, cluster-wise
resampling, random particles) are finite, and nonzero for the new continuous ones.

The heatmap method is checked through one step of ``tune`` (score-form and stop-gradient estimators, every
trainable parameter), on tests/test_tuning.py's sequences, so it reuses that compiled gradient; the extended
method through ``jax.grad`` of a plain run (pathwise)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.sim import simulate_standard
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


def test_heatmap_tune_step_moves_every_new_parameter(small_sequence):
    model, params = hp.build("heatmap", SMALL_OPTIONS)
    sequences = [small_sequence, simulate_standard(4, num_steps=20, shrink=4)]  # test_tuning's
    result = hp.tune(jax.random.key(0), sequences, params, model, steps=1, burn_in=10)
    assert np.all(np.isfinite(result.history))
    start = dict(zip(P.leaf_names(model.properties()), jax.tree.leaves(P.as_arrays(params, model.properties())),
                     strict=True))
    end = dict(zip(P.leaf_names(model.properties()), jax.tree.leaves(result.params), strict=True))
    assert not any(np.any(np.isnan(v)) for v in end.values())  # inf is a default of some (e.g. source.max_ratio)
    assert all(np.all(np.isfinite(end[name])) for name in result.names)
    for name in NEW["heatmap"]:
        # Adam's first step moves a parameter by lr in log coordinates unless its gradient is zero.
        assert abs(np.log(float(end[name]) / float(start[name]))) > 0.01, (name, start[name], end[name])


@pytest.mark.parametrize("method", ["extended"])
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
