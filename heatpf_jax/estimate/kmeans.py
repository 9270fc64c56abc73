"""Weighted k-means with fixed sizes: k-means++ seeding (Arthur & Vassilvitskii 2007) and Lloyd iterations.

Centres and labels are discrete decisions, computed on ``stop_gradient`` inputs (``jax.grad`` through them is
zero); the member weight sums (:attr:`KMeans.weights`) keep the gradient of the input weights. All-zero weights
count as uniform. The shared helpers are in :mod:`heatpf_jax.estimate.clustering`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

from heatpf_jax.estimate.clustering import _check_count, _nearest, squared_distances, usable_weights

__all__ = [
    "KMeans",
    "kmeans",
    "kmeans_plus_plus",
]


class KMeans(NamedTuple):
    """What :func:`kmeans` returns.

    Attributes:
        centres: ``float32 [K, 2]`` the centres after the last Lloyd update.
        labels: ``int32 [N]`` each point's nearest centre.
        weights: ``float32 [K]`` the sum of the member weights.
    """

    centres: Float[Array, "k 2"]
    labels: Int[Array, " n"]
    weights: Float[Array, " k"]


def kmeans_plus_plus(
    key: PRNGKeyArray, points: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], num_clusters: int
) -> Float[Array, "k 2"]:
    """Weighted greedy k-means++ seeding (Arthur & Vassilvitskii 2007; sklearn's variant).

    The first centre is drawn with probability proportional to ``w_i``. For each next one,
    ``2 + floor(ln K)`` candidates are drawn proportional to ``w_i D_i^2`` (``D_i``: distance to the
    nearest centre so far) and the one that leaves the smallest potential ``sum_i w_i D_i^2`` is kept;
    if every point with weight already coincides with a centre, candidates are drawn proportional to
    ``w_i``. No gradient.

    Args:
        key: PRNG key.
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        num_clusters: ``K``, static.

    Returns:
        ``[K, 2]`` initial centres (points of the set).
    """
    _check_count("num_clusters", num_clusters, 1)
    pts = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    n = w.shape[0]
    trials = 2 + int(math.log(num_clusters))
    # Uniforms turned into indices by inverse-CDF search: cheaper to run and to compile than
    # categorical draws over all N points.
    u = jax.random.uniform(key, (num_clusters, trials), w.dtype)

    def draw(p, u_k):
        cdf = jnp.cumsum(p)
        return jnp.clip(jnp.searchsorted(cdf, u_k * cdf[-1], side="right", method="compare_all"), 0, n - 1)

    first = draw(w, u[0, :1])[0]
    centres = jnp.zeros((num_clusters, 2), pts.dtype).at[0].set(pts[first])
    d2 = squared_distances(pts[first][None, :], pts)[0]

    def add_centre(k, state):
        centres, d2 = state
        p = w * d2
        candidates = draw(jnp.where(jnp.sum(p) > 0, p, w), u[k])
        d2_new = jnp.minimum(d2[None, :], squared_distances(pts[candidates], pts))  # [trials, N]
        best = jnp.argmin(jnp.sum(d2_new * w[None, :], axis=1))
        return centres.at[k].set(pts[candidates[best]]), d2_new[best]

    centres, _ = lax.fori_loop(1, num_clusters, add_centre, (centres, d2))
    return centres


def kmeans(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    centres: Float[ArrayLike, "k 2"],
    *,
    num_iters: int,
) -> KMeans:
    """Weighted Lloyd iterations from ``centres``: assign to the nearest centre, move centres to the
    weighted means of their members. A centre without member weight stays where it is.

    Args:
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        centres: ``[K, 2]`` initial centres (e.g. :func:`kmeans_plus_plus`).
        num_iters: Lloyd iterations, static.

    Returns:
        :class:`KMeans`: the centres after the last update, the labels of those centres (as sklearn's
        ``KMeans``) and the member weight sums (of ``weights``, which keep their gradient).
    """
    _check_count("num_iters", num_iters, 0)
    weights = jnp.asarray(weights)
    pts = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    centres = lax.stop_gradient(jnp.asarray(centres, pts.dtype))
    k = centres.shape[0]
    everyone = jnp.ones((k,), bool)

    def update(_, c):
        member = jax.nn.one_hot(_nearest(pts, c, everyone), k, dtype=w.dtype) * w[:, None]
        mass = jnp.sum(member, axis=0)
        moved = (member.T @ pts) / jnp.where(mass > 0, mass, 1.0)[:, None]
        return jnp.where((mass > 0)[:, None], moved, c)

    centres = lax.fori_loop(0, num_iters, update, centres)
    labels = _nearest(pts, centres, everyone)
    return KMeans(centres=centres, labels=labels, weights=weights @ jax.nn.one_hot(labels, k, dtype=weights.dtype))
