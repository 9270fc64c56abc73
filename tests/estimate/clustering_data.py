"""Shared data and compiled fits of the clustering tests (tests/estimate/test_mean_shift.py, test_kmeans.py,
test_gmm.py): points around three blob centres, and k-means++, k-means and Gaussian-mixture EM compiled once
for all of them (compiling is most of the cost of these tests).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.estimate.gmm import gmm_em, mixture_from_labels
from heatpf_jax.estimate.kmeans import kmeans, kmeans_plus_plus

N = 120
GMM_ITERS = 10
CENTRES = np.array([[0.0, 0.0], [3.0, 0.5], [0.5, 3.0]])


@jax.jit
def fit(key, points, weights, labels, reg_covar):
    """k-means++ centres, k-means from them, and the mixture of ``labels`` before and after EM."""
    init = kmeans_plus_plus(key, points, weights, 3)
    km = kmeans(points, weights, init, num_iters=30)
    start = mixture_from_labels(points, weights, labels, km.centres, reg_covar)
    return init, km, start, gmm_em(points, weights, start, num_iters=GMM_ITERS, reg_covar=reg_covar)


def kmeans_fit(key, points, weights):
    init, km, _, _ = fit(key, jnp.asarray(points), jnp.asarray(weights), jnp.zeros(N, jnp.int32), jnp.float32(1e-3))
    return init, km


def blobs(rng: np.random.Generator, n: int = N, std: float = 0.35, shares=(0.5, 0.3, 0.2)):
    """Points around ``CENTRES`` (float32) and which blob each came from."""
    which = rng.choice(len(shares), size=n, p=np.asarray(shares))
    points = CENTRES[which] + std * rng.normal(size=(n, 2))
    return points.astype(np.float32), which
