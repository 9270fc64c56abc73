"""``heatpf_jax.estimate.gmm``: Gaussian-mixture EM against sklearn's ``GaussianMixture`` from our initial mixture,
on points repeated by integer weights (it has no sample weights; skips where scikit-learn is not installed). The fit
is compiled once with the k-means tests' (tests/estimate/clustering_data.py).
"""

from __future__ import annotations

import warnings

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from tests.estimate.clustering_data import GMM_ITERS, N, blobs, fit, kmeans_fit


def test_gmm_em_matches_sklearn(rng):
    sklearn_mixture = pytest.importorskip("sklearn.mixture")
    points, _ = blobs(rng, std=0.7)  # overlapping blobs: the responsibilities matter
    counts = rng.integers(1, 4, size=N)
    weights = counts.astype(np.float32)
    reg = 1e-3
    _, km = kmeans_fit(jax.random.key(1), points, weights)
    _, _, init, ours = fit(jax.random.key(1), jnp.asarray(points), jnp.asarray(weights), km.labels, jnp.float32(reg))

    init64 = [np.asarray(x, np.float64) for x in init]
    ref = sklearn_mixture.GaussianMixture(
        3,
        covariance_type="full",
        weights_init=init64[0] / init64[0].sum(),
        means_init=init64[1],
        precisions_init=np.linalg.inv(init64[2]),
        reg_covar=reg,
        tol=0.0,
        max_iter=GMM_ITERS,
        n_init=1,
        init_params="random",
        random_state=0,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # not converged after max_iter: expected
        ref.fit(np.repeat(points.astype(np.float64), counts, axis=0))
    np.testing.assert_allclose(np.asarray(ours.weight), ref.weights_, atol=1e-3)
    np.testing.assert_allclose(np.asarray(ours.mean), ref.means_, atol=1e-3)
    np.testing.assert_allclose(np.asarray(ours.cov), ref.covariances_, atol=1e-3)
    # The init itself: hard-cluster shares, means and covariances + reg.
    labels = np.asarray(km.labels)
    for k in range(3):
        member = labels == k
        wk = weights[member] / weights[member].sum()
        mean = wk @ points[member]
        cov = (wk[:, None] * (points[member] - mean)).T @ (points[member] - mean) + reg * np.eye(2)
        np.testing.assert_allclose(init64[0][k], weights[member].sum() / weights.sum(), rtol=1e-5)
        np.testing.assert_allclose(init64[1][k], mean, atol=1e-5)
        np.testing.assert_allclose(init64[2][k], cov, atol=1e-5)


def test_gmm_em_dead_component_and_zero_weights_stay_finite(rng):
    points, which = blobs(rng)
    labels = jnp.asarray(np.maximum(which, 1), jnp.int32)  # cluster 0 gets no member: weight 0
    _, _, init, out = fit(jax.random.key(0), jnp.asarray(points), jnp.zeros(N, jnp.float32), labels, jnp.float32(1e-3))
    assert float(init.weight[0]) == 0.0
    np.testing.assert_allclose(np.asarray(init.cov[0]), 1e-3 * np.eye(2), rtol=1e-6)
    for leaf in out:
        assert np.all(np.isfinite(np.asarray(leaf)))
    assert float(out.weight[0]) == 0.0
    np.testing.assert_allclose(float(jnp.sum(out.weight)), 1.0, rtol=1e-6)
