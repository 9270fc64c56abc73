"""Explorers at the measurements with their importance weight: the weight against a SciPy computation of
``p(x) / ((1 - f) p_cloud(x) + f q(x))``, its limits (a seed inside the cloud about 1, one far from it about
``birth_rate / (area f q)``), and the slots refilled with it."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

import heatpf_jax as hp
from heatpf_jax.injection.birth_weight import BirthParams, BirthWeightedExplorers, birth_log_weight
from heatpf_jax.measurements import Measurements
from heatpf_jax.motion.random_walk import Particles

# Through `jit`, the params (Python floats) static as they are eagerly: each eager operation compiles on its own.
_birth_log_weight = jax.jit(birth_log_weight, static_argnames="params")


@partial(jax.jit, static_argnames="params")
def _inject(key, xy, log_w, rank, estimate, buffer, params):
    """:meth:`BirthWeightedExplorers.inject` on a context with two slots used: one program."""
    ctx = hp.injection.InjectionContext(
        particles=Particles(xy), log_weights=log_w, rank=rank, used=jnp.int32(2), estimate=estimate,
        motion=hp.motion.RandomWalk(), motion_params=hp.motion.RandomWalkParams(), measurements=buffer)
    return BirthWeightedExplorers().inject(key, ctx, params)._replace(motion=None)  # not an array: not returned


def _buffer(rng, m=48):
    half = (m // 2, 2)
    xy = np.concatenate([rng.normal([2.0, 0.0], 0.05, size=half), rng.normal([4.0, 1.5], 0.05, size=half)])
    weight = rng.uniform(0.3, 1.0, size=m)
    valid = rng.uniform(size=m) < 0.8
    # NumPy, with the zero footprint of `empty_measurements` (in `jnp`, a program compiled per field and shape).
    return Measurements(np.asarray(xy, np.float32), np.asarray(weight, np.float32), valid,
                        np.zeros((m, 2, 2), np.float32))


def _reference(xy, buffer, mean, cov, p: BirthParams):
    j2 = p.measurement_jitter**2
    cloud = stats.multivariate_normal(mean, cov + j2 * np.eye(2)).pdf(xy)
    bxy, w, valid = (np.asarray(a, np.float64) for a in (buffer.xy, buffer.weight, buffer.valid))
    w = np.where(valid > 0, w, 0.0)
    q = sum(wi / w.sum() * stats.multivariate_normal(m, j2 * np.eye(2)).pdf(xy) for m, wi in zip(bxy, w, strict=True)
            if wi > 0)
    prior = (1 - p.birth_rate) * cloud + p.birth_rate / p.area
    return np.log(prior) - np.log((1 - p.measurement_fraction) * cloud + p.measurement_fraction * q)


def test_weight_against_scipy(rng):
    buffer = _buffer(rng)
    params = BirthParams(measurement_fraction=0.1, measurement_jitter=0.08, birth_rate=0.02, area=40.0)
    mean, cov = np.array([2.05, 0.02]), np.array([[0.02, 0.005], [0.005, 0.01]])
    xy = np.concatenate([rng.normal([2.0, 0.0], 0.1, size=(10, 2)), rng.normal([4.0, 1.5], 0.1, size=(10, 2))])
    got = _birth_log_weight(np.asarray(xy, np.float32), buffer, np.asarray(mean, np.float32),
                            np.asarray(cov, np.float32), params)
    np.testing.assert_allclose(np.asarray(got), _reference(xy, buffer, mean, cov, params), rtol=1e-4, atol=1e-3)
    # Inside the cloud about the resampled particles' weight; at the far blob far below it.
    assert np.all(np.abs(np.asarray(got)[:3]) < 1.5) and np.all(np.asarray(got)[10:] < -5.0)


def test_seeds_take_their_weight_in_the_lowest_support_slots(rng):
    n = 40
    buffer = _buffer(rng)
    # NumPy inputs, the context built in the jitted call: in `jnp` each is a program compiled on its own.
    rank = rng.permutation(n).astype(np.int32)
    log_w = np.full((n,), -np.log(n), np.float32)
    estimate = hp.Estimate(np.asarray([2.0, 0.0], np.float32), np.float32(0.01) * np.eye(2, dtype=np.float32),
                           np.asarray([2.0, 0.0], np.float32))
    xy = np.asarray(rng.normal(size=(n, 2)) - 20.0, np.float32)
    params = BirthParams(measurement_fraction=0.25)
    out = jax.tree.map(np.asarray, _inject(jax.random.key(0), xy, log_w, rank, estimate, buffer, params))
    r = np.asarray(rank)
    taken = (r >= n - 2 - 10) & (r < n - 2)
    moved = np.any(np.asarray(out.particles.xy) != xy, axis=1)
    np.testing.assert_array_equal(moved, taken)
    assert int(out.used) == 12
    new_xy = np.asarray(out.particles.xy)[taken]
    want = -np.log(n) + _reference(new_xy, buffer, np.array([2.0, 0.0]), 0.01 * np.eye(2), params)
    np.testing.assert_allclose(np.asarray(out.log_weights)[taken], want, rtol=1e-4, atol=1e-3)
    np.testing.assert_array_equal(np.asarray(out.log_weights)[~taken], np.asarray(log_w)[~taken])
