"""Observation model (III-B), eq. (1): inverse-distance weights over the k nearest measurements.

    w(p_i) = sum_{j=1..k} w(m_j) / delta_ij,   m_j in C_i (the k measurements nearest p_i)

``k`` may be a traced integer up to a static ``k_max`` so that it can be swept
under ``vmap``. Distances are floored at ``min_distance`` so that a particle on
top of a measurement gets a large but finite weight. The selection of the k
nearest is discrete; gradients flow through the selected distances and weights.

A Gaussian kernel variant (``w(m_j) * exp(-delta_ij^2 / (2 sigma^2))``) shares the
selection; with one measurement and k = 1 it is the exact Gaussian likelihood,
which lets the filter be checked against a Kalman posterior.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from heatpf_jax.measurements import Measurements
from heatpf_jax.numerics import safe_log
from heatpf_jax.observation.knn import _static_k_max, k_nearest_blocked
from heatpf_jax.params import integer, positive

__all__ = [
    "AUTO_BLOCKED_MIN_SIZE",
    "DEFAULT_MIN_DISTANCE",
    "KNN_METHODS",
    "FloorParams",
    "Floored",
    "GaussianDensity",
    "GaussianKernel",
    "GaussianKernelParams",
    "InverseDistance",
    "InverseDistanceParams",
    "gaussian_particle_weights",
    "k_nearest",
    "particle_weights",
]

DEFAULT_MIN_DISTANCE = 0.01  # metres: about the ground spacing of heat-map pixels at 1-2 m
KNN_METHODS = ("dense", "blocked", "auto")
AUTO_BLOCKED_MIN_SIZE = 256  # "auto": the blocked kernel from this buffer size on (measured crossover)


def k_nearest(
    particles: Float[ArrayLike, "n 2"],
    measurements: Measurements,
    k: Int[ArrayLike, ""],
    *,
    k_max: int | None = None,
    method: str = "auto",
) -> tuple[Float[Array, "n kmax"], Float[Array, "n kmax"], Bool[Array, "n kmax"]]:
    """Selects each particle's k nearest valid measurements (the set C_i of eq. 1).

    All three methods are exact. ``method="dense"`` is the plain formulation and the
    reference: a full particle x measurement squared-distance matrix followed by
    ``lax.top_k``. ``"blocked"`` is the block-minima kernel of :mod:`heatpf_jax.observation.knn`
    (same neighbour set up to distance ties, several times faster from a few hundred
    measurements on). ``"auto"``, the default, picks ``"blocked"`` for buffers of at
    least ``AUTO_BLOCKED_MIN_SIZE`` (256) slots and ``"dense"`` below, so the default
    is the fastest exact search; pass ``method="dense"`` for the reference.

    Args:
        particles: ``[N, 2]`` positions.
        measurements: a buffer of size ``M``.
        k: number of neighbours, ``1 <= k <= k_max`` (may be traced).
        k_max: static upper bound on ``k``; defaults to ``k`` (then ``k`` must be concrete).
        method: ``"auto"`` (default), ``"blocked"`` or ``"dense"`` (the reference); static.

    Returns:
        ``(sq_dist, weight, selected)`` each ``[N, min(k_max, M)]``: squared
        distances and weights of the nearest measurements in increasing
        distance, and whether each slot is among the k nearest *valid* ones.
    """
    particles = jnp.asarray(particles)
    size = measurements.xy.shape[0]
    kk = _static_k_max(k, k_max, size)
    if method not in KNN_METHODS:
        raise ValueError(f"method: must be one of {list(KNN_METHODS)}, got {method!r}")
    if method == "blocked" or (method == "auto" and size >= AUTO_BLOCKED_MIN_SIZE):
        return k_nearest_blocked(particles, measurements, k, k_max=kk)
    # Per coordinate: an [N, M, 2] difference summed over its last axis is several times
    # slower on XLA:CPU than two [N, M] planes.
    dx = particles[:, 0, None] - measurements.xy[None, :, 0]
    dy = particles[:, 1, None] - measurements.xy[None, :, 1]
    sq = dx * dx + dy * dy
    sq = jnp.where(measurements.valid[None, :], sq, jnp.inf)
    neg, idx = lax.top_k(-sq, kk)
    selected = measurements.valid[idx] & (jnp.arange(kk) < k)[None, :]
    sq_sel = jnp.where(selected, -neg, 1.0)
    w_sel = jnp.where(selected, measurements.weight[idx], 0.0)
    return sq_sel, w_sel, selected


def _sum_or_uniform(contrib, measurements: Measurements):
    weights = jnp.sum(contrib, axis=-1)
    return jnp.where(jnp.any(measurements.valid), weights, jnp.ones_like(weights))


def particle_weights(
    particles: Float[ArrayLike, "n 2"],
    measurements: Measurements,
    k: Int[ArrayLike, ""],
    *,
    k_max: int | None = None,
    min_distance: Float[ArrayLike, ""] = DEFAULT_MIN_DISTANCE,
    method: str = "auto",
) -> Float[Array, " n"]:
    """Eq. (1): for each particle, the sum over its k nearest valid measurements of weight / distance.

    Args:
        particles: ``[N, 2]`` positions.
        measurements: a buffer of size ``M`` (invalid slots are ignored).
        k: number of neighbours (may be traced if ``k_max`` is given).
        k_max: static upper bound on ``k``.
        min_distance: distance floor (epsilon), metres.
        method: exact neighbour search, ``"auto"`` (default: ``"blocked"`` from ``AUTO_BLOCKED_MIN_SIZE``
            slots on, ``"dense"`` below), ``"blocked"`` or ``"dense"`` (the reference); see :func:`k_nearest`.

    Returns:
        ``[N]`` unnormalised weights; all ones when no measurement is valid.
        With fewer than k valid measurements, all valid ones are summed.
    """
    sq, w, _ = k_nearest(particles, measurements, k, k_max=k_max, method=method)
    dist = jnp.sqrt(jnp.maximum(sq, jnp.square(min_distance)))
    return _sum_or_uniform(w / dist, measurements)


def gaussian_particle_weights(
    particles: Float[ArrayLike, "n 2"],
    measurements: Measurements,
    k: Int[ArrayLike, ""],
    *,
    std: Float[ArrayLike, ""],
    k_max: int | None = None,
    method: str = "auto",
) -> Float[Array, " n"]:
    """Gaussian-kernel variant: sum over the k nearest of ``w * exp(-delta^2 / (2 std^2))``.

    Args:
        particles: ``[N, 2]`` positions.
        measurements: a buffer of size ``M`` (invalid slots are ignored).
        k: number of neighbours (may be traced if ``k_max`` is given).
        std: kernel standard deviation, metres.
        k_max: static upper bound on ``k``.
        method: exact neighbour search, ``"auto"`` (default), ``"blocked"`` or ``"dense"`` (the reference);
            see :func:`k_nearest`.

    Returns:
        ``[N]`` unnormalised weights; all ones when no measurement is valid.
    """
    sq, w, _ = k_nearest(particles, measurements, k, k_max=k_max, method=method)
    return _sum_or_uniform(w * jnp.exp(-0.5 * sq / jnp.square(std)), measurements)


@dataclass(frozen=True)
class _KNearestModel:
    """What the k-nearest observation models share: the static search and the ``k`` constraint.

    Attributes:
        k_max: static upper bound on the traced ``k`` (the search's arrays are sized for it).
        knn: the exact k-nearest search, ``"auto"``, ``"blocked"`` or ``"dense"`` (see :func:`k_nearest`).
    """

    k_max: int = 10
    knn: str = "auto"

    def validate(self) -> None:
        if not isinstance(self.k_max, int) or isinstance(self.k_max, bool) or self.k_max < 1:
            raise ValueError(f"k_max: must be a positive integer, got {self.k_max!r}")
        if self.knn not in KNN_METHODS:
            raise ValueError(f"knn: must be one of {list(KNN_METHODS)}, got {self.knn!r}")

    def _k(self):
        return integer(1, self.k_max)


class InverseDistanceParams(NamedTuple):
    """Numbers of :class:`InverseDistance`.

    Attributes:
        k: neighbours per particle in eq. (1), ``1 <= k <= k_max``.
        min_distance: distance floor of eq. (1), metres.
    """

    k: int = 1
    min_distance: float = DEFAULT_MIN_DISTANCE


@dataclass(frozen=True)
class InverseDistance(_KNearestModel):
    """Eq. (1): ``log sum_{j in C_i} w(m_j) / max(delta_ij, min_distance)`` over the k nearest.

    Eq. (1) is a score, not a normalised density: it is the likelihood up to a factor shared by
    all particles, which resampling ignores, but its scale (and so the filter's log normalising
    constant) depends on the heat map's activations and pixel count.

    Attributes:
        k_max: static upper bound on the traced ``k`` (the search's arrays are sized for it).
        knn: the exact k-nearest search, ``"auto"``, ``"blocked"`` or ``"dense"`` (see :func:`k_nearest`).
    """

    def default_params(self) -> InverseDistanceParams:
        return InverseDistanceParams()

    def properties(self) -> InverseDistanceParams:
        return InverseDistanceParams(k=self._k(), min_distance=positive())

    def log_likelihood(
        self, xy: Float[Array, "n 2"], buffer: Measurements, params: InverseDistanceParams
    ) -> Float[Array, " n"]:
        w = particle_weights(xy, buffer, params.k, k_max=self.k_max, min_distance=params.min_distance, method=self.knn)
        return safe_log(w)


class GaussianKernelParams(NamedTuple):
    """Numbers of :class:`GaussianKernel`.

    Attributes:
        k: neighbours per particle, ``1 <= k <= k_max``.
        obs_std: kernel std, metres.
    """

    k: int = 1
    obs_std: float = 0.2


@dataclass(frozen=True)
class GaussianKernel(_KNearestModel):
    """``log sum_{j in C_i} w(m_j) exp(-delta_ij^2 / (2 obs_std^2))`` over the k nearest.

    With one measurement and k = 1 this is the exact Gaussian likelihood up to a constant, which
    lets the filter be checked against a Kalman posterior.
    """

    def default_params(self) -> GaussianKernelParams:
        return GaussianKernelParams()

    def properties(self) -> GaussianKernelParams:
        return GaussianKernelParams(k=self._k(), obs_std=positive())

    def log_likelihood(
        self, xy: Float[Array, "n 2"], buffer: Measurements, params: GaussianKernelParams
    ) -> Float[Array, " n"]:
        w = gaussian_particle_weights(xy, buffer, params.k, std=params.obs_std, k_max=self.k_max, method=self.knn)
        return safe_log(w)


@dataclass(frozen=True)
class GaussianDensity(GaussianKernel):
    """The normalised form of :class:`GaussianKernel`: ``log sum_{j in C_i} w(m_j) N(m_j; p_i, obs_std^2 I)``.

    The same weights up to the factor ``1 / (2 pi obs_std^2)``, which does not change the filter's
    estimates but makes ``StepInfo.log_likelihood`` the log-likelihood of the measurements as a function
    of ``obs_std``: with one measurement of activation 1 and k = 1 it is the exact Gaussian observation
    density, so maximum-likelihood tuning of ``obs_std`` (:mod:`heatpf_jax.tuning`) is well posed.
    """

    def log_likelihood(
        self, xy: Float[Array, "n 2"], buffer: Measurements, params: GaussianKernelParams
    ) -> Float[Array, " n"]:
        log_norm = -math.log(2.0 * math.pi) - 2.0 * jnp.log(params.obs_std)
        return super().log_likelihood(xy, buffer, params) + jnp.where(jnp.any(buffer.valid), log_norm, 0.0)


class FloorParams(NamedTuple):
    """Numbers of :class:`Floored`: the base model's params and the floor.

    Attributes:
        base: the wrapped model's params.
        weight_floor: lowest likelihood a particle gets.
    """

    base: NamedTuple
    weight_floor: float = 0.001


@dataclass(frozen=True)
class Floored:
    """Any observation model with each particle's likelihood floored: ``max(L_i, weight_floor)``.

    The original team's 2018 node floors every particle's weight at 0.001, so that one step with a
    false detection cannot wipe out the particles on the ball.
    """

    base: InverseDistance | GaussianKernel

    def default_params(self) -> FloorParams:
        return FloorParams(base=self.base.default_params())

    def properties(self) -> FloorParams:
        return FloorParams(base=self.base.properties(), weight_floor=positive(trainable=False))

    def validate(self) -> None:
        if hasattr(self.base, "validate"):
            self.base.validate()

    def log_likelihood(self, xy: Float[Array, "n 2"], buffer: Measurements, params: FloorParams) -> Float[Array, " n"]:
        return jnp.maximum(self.base.log_likelihood(xy, buffer, params.base), jnp.log(params.weight_floor))
