"""Clustering of weighted 2-D particles with fixed sizes: the helpers the algorithms share.

The multi-modal output (III-F; Olufs et al. 2006, sec. 3.2, the "extended particle filter") needs
the modes of the particle set every filter step, so every clustering is jittable with static sizes,
works under ``vmap`` and costs O(S N) or O(K N) per iteration:

* :func:`~heatpf_jax.estimate.mean_shift.mean_shift` (Comaniciu & Meer 2002): ``S`` seeds, not all N
  particles, climb the weighted kernel density; converged modes closer than a merge radius are merged
  greedily in order of density (sklearn's rule); at most ``M`` modes are kept (the heaviest) behind a
  ``valid`` mask (:mod:`heatpf_jax.estimate.mean_shift`).
* :func:`~heatpf_jax.estimate.kmeans.kmeans_plus_plus` and :func:`~heatpf_jax.estimate.kmeans.kmeans`:
  weighted k-means++ seeding and Lloyd iterations (:mod:`heatpf_jax.estimate.kmeans`).
* :func:`~heatpf_jax.estimate.gmm.gmm_em`: EM (:func:`~heatpf_jax.estimate.gmm.responsibilities`,
  :func:`~heatpf_jax.estimate.gmm.m_step`) for a weighted mixture of full-covariance Gaussians, in log
  space (:mod:`heatpf_jax.estimate.gmm`).

Mean shift and k-means are discrete decisions: their centres, labels and the choices inside are
computed on ``stop_gradient`` inputs, so ``jax.grad`` through them is finite (zero). Sums over the
members (:attr:`~heatpf_jax.estimate.mean_shift.Clusters.weights`,
:attr:`~heatpf_jax.estimate.kmeans.KMeans.weights`, :func:`weighted_stats`) keep the gradient
of the inputs, and EM is smooth throughout. All-zero weights are treated as uniform; nothing returns
NaN. The pieces that turn these into the filter's modes are in :mod:`heatpf_jax.estimate.modes`.

This module holds what they share: :func:`usable_weights` (all-zero weights as uniform),
:func:`squared_distances`, :func:`weighted_stats` (mass, mean and covariance of groups of points)
and the nearest-centre assignment.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

__all__ = [
    "squared_distances",
    "usable_weights",
    "weighted_stats",
]


def _check_count(name: str, value, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name}: must be an integer >= {low}, got {value!r}")


def usable_weights(weights: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
    """``weights``, or all ones when they sum to zero (no information: treat the points alike)."""
    weights = jnp.asarray(weights)
    return jnp.where(jnp.sum(weights) > 0, weights, jnp.ones_like(weights))


def squared_distances(a: Float[ArrayLike, "m 2"], b: Float[ArrayLike, "n 2"]) -> Float[Array, "m n"]:
    """``|a_i - b_j|^2`` from the coordinate differences (exact at zero, unlike the dot-product form).

    Written per coordinate: XLA's CPU backend vectorises ``[m, n]`` planes far better than a reduction
    over a trailing axis of size 2.
    """
    a = jnp.asarray(a)
    b = jnp.asarray(b)
    dx = a[:, 0][:, None] - b[:, 0][None, :]
    dy = a[:, 1][:, None] - b[:, 1][None, :]
    return dx * dx + dy * dy


def weighted_stats(
    points: Float[ArrayLike, "n 2"], member_weights: Float[ArrayLike, "n k"], fallback: Float[ArrayLike, "k 2"]
) -> tuple[Float[Array, " k"], Float[Array, "k 2"], Float[Array, "k 2 2"]]:
    """Mass, weighted mean and biased weighted covariance of ``K`` (soft or hard) groups of points.

    Args:
        points: ``[N, 2]``.
        member_weights: ``[N, K]`` weight of point i in group k (``w_i r_ik``, or ``w_i`` one-hot).
        fallback: ``[K, 2]`` the mean of a group without mass (its covariance is then zero).

    Returns:
        ``(mass [K], mean [K, 2], cov [K, 2, 2])``.
    """
    points = jnp.asarray(points)
    member_weights = jnp.asarray(member_weights)
    mass = jnp.sum(member_weights, axis=0)
    has_mass = mass > 0
    safe_mass = jnp.where(has_mass, mass, 1.0)
    # Elementwise products and sums, no dot: K and 2 are tiny, and XLA compiles these much faster.
    px, py = points[:, 0][:, None], points[:, 1][:, None]
    mean_x = jnp.sum(member_weights * px, axis=0) / safe_mass
    mean_y = jnp.sum(member_weights * py, axis=0) / safe_mass
    mean = jnp.where(has_mass[:, None], jnp.stack([mean_x, mean_y], axis=1), jnp.asarray(fallback))
    dx = px - mean[:, 0][None, :]
    dy = py - mean[:, 1][None, :]
    cxx = jnp.sum(member_weights * dx * dx, axis=0) / safe_mass
    cxy = jnp.sum(member_weights * dx * dy, axis=0) / safe_mass
    cyy = jnp.sum(member_weights * dy * dy, axis=0) / safe_mass
    cov = jnp.stack([jnp.stack([cxx, cxy], axis=1), jnp.stack([cxy, cyy], axis=1)], axis=1)
    return mass, mean, cov


def _nearest(points, centres, allowed) -> Int[Array, " n"]:
    """Index of the nearest allowed centre (the first of equals), as two plain ``min`` reductions:
    XLA's CPU backend runs those far faster than ``argmin``'s value-index reduction."""
    k = centres.shape[0]
    d2 = jnp.where(allowed[None, :], squared_distances(points, centres), jnp.inf)
    best = jnp.min(d2, axis=1, keepdims=True)
    return jnp.min(jnp.where(d2 == best, jnp.arange(k, dtype=jnp.int32)[None, :], k), axis=1)
