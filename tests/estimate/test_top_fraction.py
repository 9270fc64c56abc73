"""``top_fraction_estimate`` and ``weighted_mean_cov`` against NumPy references.

Reference: sort by weight (stable, ties by index), keep ``ceil(f N)``, renormalise,
weighted mean and biased (population) weighted covariance; the plain weighted mean
over all particles via ``np.average``.
"""

from __future__ import annotations

import math
from fractions import Fraction

import jax
import numpy as np
import pytest

import heatpf_jax as hp

# One compilation per particle count: the fraction is traced (as inside the filter).
_estimate = jax.jit(hp.estimate.top_fraction_estimate)
# The fraction a Python float (concrete), the array operations in one program: run eagerly, each compiles its own.
_concrete = jax.jit(hp.estimate.top_fraction_estimate, static_argnums=2)


def _est(particles: np.ndarray, weights: np.ndarray, fraction: float) -> hp.Estimate:
    return _estimate(particles, weights, np.float32(fraction))  # NumPy: an eager `jnp.asarray` compiles per shape


def _reference(particles: np.ndarray, weights: np.ndarray, fraction: float):
    p = particles.astype(np.float64)
    w = weights.astype(np.float64)
    n = w.shape[0]
    # Exact ceil(f N) of the decimal fraction (no float rounding in the reference).
    count = min(max(math.ceil(Fraction(str(fraction)) * n), 1), n)
    keep = np.argsort(-w, kind="stable")[:count]
    wk = w[keep] / w[keep].sum()
    mean = wk @ p[keep]
    centred = p[keep] - mean
    cov = (wk[:, None] * centred).T @ centred
    return mean, cov, np.average(p, axis=0, weights=w), keep


def _cloud(rng: np.random.Generator, n: int):
    particles = rng.normal([1.0, -2.0], [0.7, 0.3], size=(n, 2)).astype(np.float32)
    weights = rng.gamma(0.5, size=n).astype(np.float32)
    return particles, weights


@pytest.mark.parametrize("n", [200, 201])
@pytest.mark.parametrize("fraction", [0.05, 0.3, 0.5, 0.95, 1.0])
def test_matches_numpy_reference(n, fraction, rng):
    particles, weights = _cloud(rng, n)
    est = _est(particles, weights, fraction)
    mean, cov, wmean, _ = _reference(particles, weights, fraction)
    np.testing.assert_allclose(est.mean, mean, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(est.cov, cov, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(est.weighted_mean, wmean, rtol=1e-5, atol=1e-5)
    assert est.mean.shape == (2,) and est.cov.shape == (2, 2) and est.weighted_mean.shape == (2,)


def test_only_the_kept_particles_matter(rng):
    """Moving the particles outside the top ceil(f N) leaves mean and cov unchanged, moving a kept one does not."""
    n, fraction = 200, 0.4
    particles, weights = _cloud(rng, n)
    *_, keep = _reference(particles, weights, fraction)
    assert keep.size == 80
    dropped = np.setdiff1d(np.arange(n), keep)
    moved = particles.copy()
    moved[dropped] += np.float32(100.0)
    a = _est(particles, weights, fraction)
    b = _est(moved, weights, fraction)
    np.testing.assert_allclose(a.mean, b.mean, rtol=1e-6)
    np.testing.assert_allclose(a.cov, b.cov, rtol=1e-6)
    # The all-particle weighted mean does see them.
    assert np.all(np.abs(np.asarray(b.weighted_mean) - np.asarray(a.weighted_mean)) > 1.0)
    moved = particles.copy()
    moved[keep[-1]] += np.float32(100.0)
    c = _est(moved, weights, fraction)
    assert np.all(np.abs(np.asarray(c.mean) - np.asarray(a.mean)) > 1e-3)


def test_full_fraction_equals_numpy_average_and_cov(rng):
    particles, weights = _cloud(rng, 200)
    est = _est(particles, weights, 1.0)
    p64, w64 = particles.astype(np.float64), weights.astype(np.float64)
    np.testing.assert_allclose(est.mean, np.average(p64, axis=0, weights=w64), rtol=1e-5)
    np.testing.assert_allclose(est.weighted_mean, np.average(p64, axis=0, weights=w64), rtol=1e-5)
    np.testing.assert_allclose(est.cov, np.cov(p64.T, aweights=w64, bias=True), rtol=1e-4, atol=1e-7)
    mean, cov = jax.jit(hp.estimate.weighted_mean_cov)(particles, weights)  # one program, not one per operation
    np.testing.assert_allclose(mean, np.average(p64, axis=0, weights=w64), rtol=1e-5)
    np.testing.assert_allclose(cov, np.cov(p64.T, aweights=w64, bias=True), rtol=1e-4, atol=1e-7)


def test_traced_fraction_under_jit_equals_concrete(rng):
    particles, weights = _cloud(rng, 200)
    for fraction in (0.05, 0.333, 0.95, 1.0):
        traced = _est(particles, weights, fraction)
        concrete = _concrete(particles, weights, fraction)
        for a, b in zip(traced, concrete, strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)
        mean, cov, _, _ = _reference(particles, weights, fraction)
        np.testing.assert_allclose(traced.mean, mean, rtol=1e-5, atol=1e-5)
    # Same under vmap over a batch of fractions.
    fractions = np.array([0.05, 0.5, 1.0], np.float32)
    batch = jax.jit(jax.vmap(hp.estimate.top_fraction_estimate, in_axes=(None, None, 0)))(  # one program
        particles, weights, fractions
    )
    batch = jax.tree.map(np.asarray, batch)  # indexed in NumPy: an eager index compiles a program
    for i, fraction in enumerate((0.05, 0.5, 1.0)):
        mean, cov, _, _ = _reference(particles, weights, fraction)
        np.testing.assert_allclose(batch.mean[i], mean, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(batch.cov[i], cov, rtol=1e-4, atol=1e-6)


def test_unnormalised_weights_and_ties(rng):
    """Scaling the weights changes nothing; equal weights are kept by index (stable)."""
    particles, weights = _cloud(rng, 200)
    a = _est(particles, weights, 0.5)
    b = _est(particles, weights * np.float32(1e-6), 0.5)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-7)
    equal = np.ones(200, np.float32)
    est = _est(particles, equal, 0.25)
    np.testing.assert_allclose(est.mean, particles[:50].astype(np.float64).mean(0), rtol=1e-5)
    np.testing.assert_allclose(est.cov, np.cov(particles[:50].T.astype(np.float64), bias=True), rtol=1e-4)


def test_tiny_fraction_keeps_the_single_best(rng):
    particles, weights = _cloud(rng, 200)
    est = _est(particles, weights, 1e-3)
    best = int(np.argmax(weights))
    np.testing.assert_allclose(est.mean, particles[best], rtol=1e-6)
    np.testing.assert_allclose(est.cov, np.zeros((2, 2)), atol=1e-12)


def test_sorted_top_fraction_estimate_matches_reference_on_sorted_input(rng):
    """Given particles sorted by decreasing weight it needs no sort and equals the NumPy reference."""
    sorted_est = jax.jit(hp.estimate.sorted_top_fraction_estimate)
    for n in (50, 333):
        particles = rng.normal(size=(n, 2)).astype(np.float32)
        weights = rng.gamma(0.5, size=n).astype(np.float32)
        weights[:5] = weights[5]  # ties
        order = np.argsort(-weights, kind="stable")
        for fraction in (0.05, 0.5, 0.95, 1.0):
            mean, cov, wmean, _ = _reference(particles, weights, fraction)
            got = sorted_est(particles[order], weights[order], np.float32(fraction))
            np.testing.assert_allclose(got.mean, mean, rtol=1e-4, atol=1e-6)
            np.testing.assert_allclose(got.cov, cov, rtol=1e-4, atol=1e-6)
            np.testing.assert_allclose(got.weighted_mean, wmean, rtol=1e-4, atol=1e-6)


def test_top_fraction_piece_uses_the_shared_order(rng):
    from heatpf_jax.motion.random_walk import Particles
    from heatpf_jax.numerics import order_by_weight

    xy = rng.normal(size=(60, 2)).astype(np.float32)
    w = rng.random(60).astype(np.float32)
    w /= w.sum()
    @jax.jit  # one program: run eagerly, each operation compiles its own
    def estimate(xy, w):
        return hp.estimate.TopFraction().estimate(Particles(xy), w, order_by_weight(w),
                                                  hp.estimate.TopFractionParams(0.5))

    est = estimate(xy, w)
    keep = np.argsort(-w, kind="stable")[:30]
    ref = np.average(xy[keep], axis=0, weights=w[keep])
    np.testing.assert_allclose(np.asarray(est.mean), ref, rtol=1e-5, atol=1e-6)
