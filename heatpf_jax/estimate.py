"""Output generation (III-F): mean and covariance of the best particles.

The paper uses "the mean of 95 % of the highest rated particles": the
``ceil(top_fraction * N)`` particles with the largest weights are kept and their
weighted mean and covariance (weights renormalised over the kept set) are
returned, which drops the explorer particles that found no support. The plain
weighted mean over all particles is returned too.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Estimate", "top_fraction_estimate", "weighted_mean_cov"]


class Estimate(NamedTuple):
    """A point estimate of the filter.

    Attributes:
        mean: ``[2]`` weighted mean of the best ``top_fraction`` of particles.
        cov: ``[2, 2]`` their weighted covariance.
        weighted_mean: ``[2]`` weighted mean of all particles.
    """

    mean: Float[Array, "2"]
    cov: Float[Array, "2 2"]
    weighted_mean: Float[Array, "2"]


def weighted_mean_cov(
    points: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"]
) -> tuple[Float[Array, "2"], Float[Array, "2 2"]]:
    """Weighted mean and (biased, population) covariance; weights need not be normalised."""
    points = jnp.asarray(points)
    weights = jnp.asarray(weights)
    weights = weights / jnp.sum(weights)
    mean = weights @ points
    centred = points - mean[None, :]
    cov = (centred * weights[:, None]).T @ centred
    return mean, cov


def top_fraction_estimate(
    particles: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], top_fraction: Float[ArrayLike, ""]
) -> Estimate:
    """Mean and covariance of the ``ceil(top_fraction * N)`` highest-weight particles.

    Args:
        particles: ``[N, 2]``.
        weights: ``[N]`` non-negative weights, not all zero.
        top_fraction: share of particles kept, in ``(0, 1]`` (may be traced).

    Returns:
        :class:`Estimate`.
    """
    particles = jnp.asarray(particles)
    weights = jnp.asarray(weights)
    n = weights.shape[0]
    count = jnp.clip(jnp.ceil(top_fraction * n - 1e-4), 1, n).astype(jnp.int32)
    order = jnp.argsort(-weights, stable=True)
    rank = jnp.zeros((n,), jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))
    kept = jnp.where(rank < count, weights, 0.0)
    # If every kept weight is zero the best particles are tied at zero: use them equally.
    kept = jnp.where(jnp.sum(kept) > 0, kept, (rank < count).astype(weights.dtype))
    mean, cov = weighted_mean_cov(particles, kept)
    weighted_mean, _ = weighted_mean_cov(particles, weights)
    return Estimate(mean=mean, cov=cov, weighted_mean=weighted_mean)
