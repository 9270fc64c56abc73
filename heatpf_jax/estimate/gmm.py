"""Gaussian-mixture EM for weighted 2-D points with fixed sizes, in log space.

:func:`gmm_em` runs :func:`responsibilities` (the E-step) and :func:`m_step` for a weighted mixture of
full-covariance Gaussians (:class:`Mixture`), from a start such as :func:`mixture_from_labels` (the mixture
of a hard clustering). Every operation is smooth, so ``jax.grad`` flows through it; all-zero weights count
as uniform. The shared helpers are in :mod:`heatpf_jax.estimate.clustering`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int

from heatpf_jax.estimate.clustering import _check_count, usable_weights, weighted_stats

__all__ = [
    "Mixture",
    "gmm_em",
    "m_step",
    "mixture_from_labels",
    "mixture_log_prob",
    "responsibilities",
]

_LOG_2PI = math.log(2.0 * math.pi)


class Mixture(NamedTuple):
    """A mixture of ``K`` Gaussians in the plane.

    Attributes:
        weight: ``float32 [K]`` mixing weights, summing to 1.
        mean: ``float32 [K, 2]``.
        cov: ``float32 [K, 2, 2]`` full covariances.
    """

    weight: Float[Array, " k"]
    mean: Float[Array, "k 2"]
    cov: Float[Array, "k 2 2"]


def _regularised(cov, reg_covar):
    return cov + reg_covar * jnp.eye(2, dtype=cov.dtype)[None, :, :]


def mixture_from_labels(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    labels: Int[ArrayLike, " n"],
    centres: Float[ArrayLike, "k 2"],
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """The mixture of hard clusters (EM's initialisation from k-means): weight shares, member means,
    member covariances plus ``reg_covar I``. A cluster without weight keeps its centre and gets
    ``reg_covar I`` and weight 0."""
    points = jnp.asarray(points)
    w = usable_weights(weights)
    k = jnp.asarray(centres).shape[0]
    member = jax.nn.one_hot(jnp.asarray(labels), k, dtype=w.dtype) * w[:, None]
    mass, mean, cov = weighted_stats(points, member, centres)
    return Mixture(weight=mass / jnp.sum(mass), mean=mean, cov=_regularised(cov, reg_covar))


def mixture_log_prob(points: Float[ArrayLike, "n 2"], mixture: Mixture) -> Float[Array, "n k"]:
    """``log(pi_k N(x_i | mu_k, Sigma_k))`` for every point and component (``-inf`` where ``pi_k = 0``).

    The 2 x 2 inverse and determinant are written out: ``Sigma = [[a, b], [b, c]]``,
    ``(x - mu)^T Sigma^{-1} (x - mu) = (c dx^2 - 2 b dx dy + a dy^2) / (a c - b^2)``.
    """
    points = jnp.asarray(points)
    a = mixture.cov[:, 0, 0]
    b = 0.5 * (mixture.cov[:, 0, 1] + mixture.cov[:, 1, 0])
    c = mixture.cov[:, 1, 1]
    det = a * c - b * b
    d = points[:, None, :] - mixture.mean[None, :, :]  # [N, K, 2]
    dx, dy = d[..., 0], d[..., 1]
    maha = (c[None, :] * dx * dx - 2.0 * b[None, :] * dx * dy + a[None, :] * dy * dy) / det[None, :]
    positive = mixture.weight > 0
    log_pi = jnp.where(positive, jnp.log(jnp.where(positive, mixture.weight, 1.0)), -jnp.inf)
    return (log_pi - 0.5 * jnp.log(det) - _LOG_2PI)[None, :] - 0.5 * maha


def responsibilities(points: Float[ArrayLike, "n 2"], mixture: Mixture) -> Float[Array, "n k"]:
    """E-step: ``r_ik = pi_k N(x_i | k) / sum_l pi_l N(x_i | l)``, normalised in log space."""
    log_p = mixture_log_prob(points, mixture)
    return jnp.exp(log_p - jax.nn.logsumexp(log_p, axis=1, keepdims=True))


def m_step(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    resp: Float[ArrayLike, "n k"],
    previous: Mixture,
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """M-step with point weights ``w_i`` (equivalent to repeating point i ``w_i`` times)::

        N_k = sum_i w_i r_ik,  pi_k = N_k / sum_k N_k,  mu_k = sum_i w_i r_ik x_i / N_k,
        Sigma_k = sum_i w_i r_ik (x_i - mu_k)(x_i - mu_k)^T / N_k + reg_covar I

    A component whose ``N_k`` is zero keeps ``previous``'s mean and covariance, with weight 0. All-zero
    weights count as uniform.
    """
    w = usable_weights(weights)
    mass, mean, cov = weighted_stats(points, jnp.asarray(resp) * w[:, None], previous.mean)
    cov = jnp.where((mass > 0)[:, None, None], _regularised(cov, reg_covar), previous.cov)
    return Mixture(weight=mass / jnp.sum(mass), mean=mean, cov=cov)


def gmm_em(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    init: Mixture,
    *,
    num_iters: int,
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """EM for a weighted mixture of full-covariance Gaussians: ``num_iters`` steps of
    :func:`responsibilities` (log space) then :func:`m_step`, from ``init``.

    Args:
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        init: the starting :class:`Mixture` (``K`` components).
        num_iters: EM steps, static.
        reg_covar: added to the diagonal of every covariance.

    Returns:
        The fitted :class:`Mixture`. Every operation is smooth, so ``jax.grad`` flows through all the
        steps (compiling that is costly: :class:`heatpf_jax.estimate.modes.GaussianMixtureModes` differentiates
        only the last M-step).
    """
    _check_count("num_iters", num_iters, 0)
    points = jnp.asarray(points)

    def step(_, mix: Mixture) -> Mixture:
        return m_step(points, weights, responsibilities(points, mix), mix, reg_covar)

    init = Mixture(*(jnp.asarray(x, points.dtype) for x in init))
    return lax.fori_loop(0, num_iters, step, init)
