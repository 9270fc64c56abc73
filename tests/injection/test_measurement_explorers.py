"""Explorers drawn from the measurements (sensor resetting): draws in proportion to the weights of the
valid measurements (chi-square against the exact shares), jitter, slots, and nothing without measurements."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from scipy import stats

import heatpf_jax as hp
from heatpf_jax.motion.random_walk import Particles


def _buffer():
    xy = jnp.asarray([[1.0, 0.0], [2.0, 1.0], [3.0, -1.0], [9.0, 9.0], [5.0, 5.0]], jnp.float32)
    weight = jnp.asarray([0.2, 0.5, 0.3, 0.9, 0.0], jnp.float32)
    valid = jnp.asarray([True, True, True, False, True])  # slot 3 invalid, slot 4 weightless
    return hp.measurements.empty_measurements(5)._replace(xy=xy, weight=weight, valid=valid)


def test_draws_follow_the_weights_of_valid_measurements():
    n = 20_000
    out = np.asarray(hp.injection.sample_measurements(jax.random.key(0), _buffer(), n, jnp.float32(0.0)))
    counts = np.array([np.sum(np.all(out == p, axis=1)) for p in ([1, 0], [2, 1], [3, -1])])
    assert counts.sum() == n  # never the invalid or the weightless slot
    assert stats.chisquare(counts, n * np.array([0.2, 0.5, 0.3])).pvalue > 1e-3
    jittered = np.asarray(
        hp.injection.sample_measurements(
            jax.random.key(1), _buffer()._replace(weight=jnp.asarray([1.0, 0.0, 0.0, 0.0, 0.0])), n, jnp.float32(0.1)
        )
    )
    np.testing.assert_allclose(jittered.mean(axis=0), [1.0, 0.0], atol=0.005)
    np.testing.assert_allclose(jittered.std(axis=0), [0.1, 0.1], rtol=0.03)


def test_refills_the_next_lowest_support_slots_only_with_measurements(rng):
    n = 40
    xy = jnp.asarray(rng.normal(size=(n, 2)) - 20.0, jnp.float32)
    rank = jnp.asarray(rng.permutation(n), jnp.int32)
    ctx = hp.injection.InjectionContext(
        particles=Particles(xy),
        log_weights=jnp.full((n,), -np.log(n), jnp.float32),
        rank=rank,
        used=jnp.int32(4),
        estimate=hp.Estimate(jnp.zeros(2), jnp.eye(2), jnp.zeros(2)),
        motion=hp.motion.RandomWalk(),
        motion_params=hp.motion.RandomWalkParams(),
        measurements=_buffer(),
    )
    piece = hp.injection.MeasurementExplorers()
    out = piece.inject(jax.random.key(0), ctx, hp.injection.MeasurementParams(0.25, 0.01))
    r = np.asarray(rank)
    taken = (r >= n - 4 - 10) & (r < n - 4)
    moved = np.any(np.asarray(out.particles.xy) != np.asarray(xy), axis=1)
    np.testing.assert_array_equal(moved, taken)
    assert int(out.used) == 14
    near = np.min(
        np.linalg.norm(np.asarray(out.particles.xy)[taken][:, None] - np.asarray(_buffer().xy)[:3], axis=-1), axis=1
    )
    assert np.all(near < 0.06)
    empty = piece.inject(jax.random.key(0), ctx._replace(measurements=hp.measurements.empty_measurements(5)),
                         piece.default_params())
    np.testing.assert_array_equal(np.asarray(empty.particles.xy), np.asarray(xy))
    assert int(empty.used) == 4
    assert not piece.properties().measurement_fraction.trainable and piece.properties().measurement_jitter.trainable
