"""``heatpf_jax.estimate.kmeans`` against sklearn's ``KMeans`` from our initial centres with ``sample_weight``
(skips where scikit-learn is not installed). The fit is compiled once with the Gaussian-mixture tests'
(tests/estimate/clustering_data.py).
"""

from __future__ import annotations

import jax
import numpy as np
import pytest

from tests.estimate.clustering_data import N, blobs, kmeans_fit


def test_kmeans_matches_sklearn(rng):
    sklearn_cluster = pytest.importorskip("sklearn.cluster")
    points, _ = blobs(rng, std=0.6)
    weights = rng.gamma(1.0, size=N).astype(np.float32)
    init, ours = kmeans_fit(jax.random.key(3), points, weights)
    init = np.asarray(init)
    # k-means++ picks points of the set.
    assert all(np.any(np.all(points == c, axis=1)) for c in init)
    ref = sklearn_cluster.KMeans(3, init=init.astype(np.float64), n_init=1, algorithm="lloyd", tol=0.0, max_iter=300)
    ref.fit(points.astype(np.float64), sample_weight=weights.astype(np.float64))
    np.testing.assert_allclose(np.asarray(ours.centres), ref.cluster_centers_, atol=1e-4)
    np.testing.assert_array_equal(np.asarray(ours.labels), ref.labels_)
    np.testing.assert_allclose(np.asarray(ours.weights), np.bincount(ref.labels_, weights=weights), rtol=1e-5)


def test_kmeans_plus_plus_skips_zero_weights_and_spreads(rng):
    points, which = blobs(rng, std=0.2)
    weights = np.ones(N, np.float32)
    weights[which == 2] = 0.0
    for seed in range(4):
        init, _ = kmeans_fit(jax.random.key(seed), points, weights)
        picked = [int(np.flatnonzero(np.all(points == c, axis=1))[0]) for c in np.asarray(init)]
        assert np.all(weights[picked] > 0)
        # D^2 sampling puts the first two centres in different blobs.
        assert which[picked[0]] != which[picked[1]]
