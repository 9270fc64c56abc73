"""Gradients of a run's loss with respect to every trainable parameter of the extended method (mass
inertia, the range-aware observation, cluster-wise resampling, measurement explorers) are finite, and
nonzero for the new continuous ones."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import heatpf_jax as hp
from heatpf_jax import params as P
from tests.conftest import SMALL_OPTIONS


def test_extended_run_gradients_are_finite(small_sequence):
    model, params = hp.build("extended", SMALL_OPTIONS)
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
    for name in ("motion.rho_move", "motion.rho_position", "motion.noise", "observation.gain", "observation.min_std",
                 "injectors.measurement.measurement_jitter"):
        assert g[name] != 0.0, (name, g)
