"""``heatpf_jax.estimate.clustering``: the helpers the clusterings share, against NumPy.

The clusterings themselves are checked against independent references in tests/estimate/test_mean_shift.py,
test_kmeans.py and test_gmm.py.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from heatpf_jax.estimate.clustering import squared_distances, usable_weights, weighted_stats


def test_shared_helpers_match_numpy(rng):
    points = rng.normal(size=(9, 2)).astype(np.float32)
    # Squared distances from the coordinate differences: exact zero from a point to itself.
    d2 = np.asarray(squared_distances(jnp.asarray(points[:4]), jnp.asarray(points)))
    np.testing.assert_allclose(d2, np.sum((points[:4, None] - points[None]) ** 2, axis=-1), rtol=1e-6)
    np.testing.assert_array_equal(np.diag(d2[:, :4]), 0.0)
    # All-zero weights count as uniform; others are kept.
    np.testing.assert_array_equal(np.asarray(usable_weights(jnp.zeros(3))), 1.0)
    np.testing.assert_array_equal(np.asarray(usable_weights(jnp.array([0.0, 2.0, 0.5]))), [0.0, 2.0, 0.5])
    # Hard groups: mass, weighted mean, biased covariance; a group without mass keeps its fallback mean.
    w = rng.uniform(0.5, 2.0, size=9).astype(np.float32)
    labels = np.arange(9) % 2  # groups 0 and 1; group 2 is empty
    member = np.eye(3, dtype=np.float32)[labels] * w[:, None]
    fallback = np.array([[0.0, 0.0], [0.0, 0.0], [7.0, -7.0]], np.float32)
    mass, mean, cov = (np.asarray(x) for x in weighted_stats(jnp.asarray(points), jnp.asarray(member), fallback))
    for k in range(2):
        wk, pk = w[labels == k], points[labels == k]
        mk = wk @ pk / wk.sum()
        np.testing.assert_allclose(mass[k], wk.sum(), rtol=1e-6)
        np.testing.assert_allclose(mean[k], mk, atol=1e-6)
        np.testing.assert_allclose(cov[k], (wk[:, None] * (pk - mk)).T @ (pk - mk) / wk.sum(), atol=1e-6)
    assert mass[2] == 0.0
    np.testing.assert_array_equal(mean[2], fallback[2])
    np.testing.assert_array_equal(cov[2], 0.0)
