"""Output generation (III-F): mean and covariance of the best particles.

The paper uses "the mean of 95 % of the highest rated particles": the
``ceil(top_fraction * N)`` particles with the largest weights are kept and their
weighted mean and covariance (weights renormalised over the kept set) are
returned, which drops the explorer particles that found no support. The plain
weighted mean over all particles is returned too.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int

from heatpf_jax.params import unit_interval

__all__ = [
    "Estimate",
    "TopFraction",
    "TopFractionParams",
    "sorted_top_fraction_estimate",
    "top_fraction_estimate",
    "weighted_mean_cov",
]


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


def _top_count(top_fraction, n: int):
    """``ceil(top_fraction * n)`` clipped to ``[1, n]`` (tolerant of float32 products like 0.95 * 500)."""
    return jnp.clip(jnp.ceil(top_fraction * n - 1e-4), 1, n).astype(jnp.int32)


def sorted_top_fraction_estimate(
    particles: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], top_fraction: Float[ArrayLike, ""]
) -> Estimate:
    """:func:`top_fraction_estimate` for particles already sorted by non-increasing weight.

    The kept particles are then the first ``ceil(top_fraction * N)``: no sort, no ranks.
    The filter step sorts once and shares the order with resampling and the explorers.
    """
    particles = jnp.asarray(particles)
    weights = jnp.asarray(weights)
    n = weights.shape[0]
    head = jnp.arange(n, dtype=jnp.int32) < _top_count(top_fraction, n)
    kept = jnp.where(head, weights, 0.0)
    # If every kept weight is zero the best particles are tied at zero: use them equally.
    kept = jnp.where(jnp.sum(kept) > 0, kept, head.astype(weights.dtype))
    mean, cov = weighted_mean_cov(particles, kept)
    weighted_mean, _ = weighted_mean_cov(particles, weights)
    return Estimate(mean=mean, cov=cov, weighted_mean=weighted_mean)


def top_fraction_estimate(
    particles: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], top_fraction: Float[ArrayLike, ""]
) -> Estimate:
    """Mean and covariance of the ``ceil(top_fraction * N)`` highest-weight particles.

    Ties in weight are broken by index (a stable sort).

    Args:
        particles: ``[N, 2]``.
        weights: ``[N]`` non-negative weights, not all zero.
        top_fraction: share of particles kept, in ``(0, 1]`` (may be traced).

    Returns:
        :class:`Estimate`.
    """
    particles = jnp.asarray(particles)
    weights = jnp.asarray(weights)
    order = jnp.argsort(-weights, stable=True)
    return sorted_top_fraction_estimate(particles[order], weights[order], top_fraction)


class TopFractionParams(NamedTuple):
    """Numbers of :class:`TopFraction`.

    Attributes:
        top_fraction: share of best particles averaged for the output (III-F); 95 % in the paper.
    """

    top_fraction: float = 0.95


@dataclass(frozen=True)
class TopFraction:
    """The paper's output (III-F): weighted mean and covariance of the best ``top_fraction`` of the particles.

    Uses the step's one sort of the particles by decreasing weight (``order``).
    """

    def default_params(self) -> TopFractionParams:
        return TopFractionParams()

    def properties(self) -> TopFractionParams:
        # A count of particles: frozen.
        return TopFractionParams(top_fraction=unit_interval(low_closed=False, trainable=False))

    def estimate(self, particles, weights: Float[Array, " n"], order: Int[Array, " n"], params) -> Estimate:
        return sorted_top_fraction_estimate(particles.xy[order], weights[order], params.top_fraction)
