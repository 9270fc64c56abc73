"""The dominant-mode output against a NumPy reference: the weighted mean and covariance of the heavier
of two blobs, where the paper's top-fraction mean lands between them."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import heatpf_jax as hp
from heatpf_jax.estimate.modes import MeanShiftParams
from heatpf_jax.motion.random_walk import Particles


def test_dominant_mode_is_the_heavier_blob(rng):
    a = rng.normal([2.0, 0.0], 0.03, (60, 2))
    b = rng.normal([2.0, 1.0], 0.03, (40, 2))
    xy = np.concatenate([a, b])
    w = np.concatenate([np.full(60, 0.6 / 60), np.full(40, 0.4 / 40)]) * rng.uniform(0.5, 1.5, 100)
    w = w / w.sum()
    order = jnp.argsort(-jnp.asarray(w, jnp.float32))
    est = jax.jit(hp.estimate.DominantMode().estimate)(
        Particles(jnp.asarray(xy, jnp.float32)), jnp.asarray(w, jnp.float32), order, MeanShiftParams(bandwidth=0.1)
    )
    wa = w[:60] / w[:60].sum()
    mean = wa @ a
    cov = ((a - mean) * wa[:, None]).T @ (a - mean)
    np.testing.assert_allclose(np.asarray(est.mean), mean, atol=1e-5)
    np.testing.assert_allclose(np.asarray(est.cov), cov, atol=1e-6)
    np.testing.assert_allclose(np.asarray(est.weighted_mean), w @ xy, atol=1e-5)
    top = hp.estimate.TopFraction().estimate(
        Particles(jnp.asarray(xy, jnp.float32)), jnp.asarray(w, jnp.float32), order, hp.estimate.TopFractionParams()
    )
    assert 0.2 < float(top.mean[1]) < 0.8  # the paper's output lies between the two balls
