"""Multi-modal output (III-F, V; Olufs et al. 2006, sec. 3.2): the modes of a weighted particle set.

A single mean hides a second hypothesis (a true and a false positive, Fig. 5); a mode piece returns
up to ``num_modes`` weighted Gaussians instead, as :class:`Modes` with a ``valid`` mask, the valid
modes first by decreasing weight. The pieces share one signature
``modes(key, xy, weights, params) -> Modes`` (the key first, even where unused), with ``xy`` the
particles' ``[N, 2]`` positions and ``weights`` their ``[N]`` non-negative weights, not necessarily
normalised (all zero counts as uniform). Each piece holds only static sizes (``num_modes``, iteration
counts) and has ``default_params()``, ``properties()`` and ``validate()``:

* :class:`NoModes`: zero modes (``K = 0``), the default when no modes are asked for.
* :class:`KMeansModes`: weighted k-means++ seeding (the key) and Lloyd iterations.
* :class:`GaussianMixtureModes`: EM for a weighted Gaussian mixture, initialised by k-means.
* :class:`MeanShiftModes`: weighted mean shift (:func:`heatpf_jax.estimate.mean_shift.mean_shift`).

For the hard clusterings (k-means, mean shift) a mode is its members' weighted mean and covariance,
for the mixture the last M-step's soft-weighted mean and covariance. The assignment (labels, or the
last responsibilities) is a decision without gradient; the weights, means and covariances keep the
gradient of the particles and weights through those statistics. A mode is valid when its share of
the total weight is at least ``min_weight``; the weights of the valid modes sum to 1. Entries of
invalid modes are finite but meaningless.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from heatpf_jax.estimate.clustering import _check_count, usable_weights, weighted_stats
from heatpf_jax.estimate.gmm import gmm_em, m_step, mixture_from_labels, responsibilities
from heatpf_jax.estimate.kmeans import kmeans, kmeans_plus_plus
from heatpf_jax.estimate.mean_shift import KERNELS, mean_shift
from heatpf_jax.params import NoParams, positive, unit_interval

__all__ = [
    "GaussianMixtureModes",
    "GaussianMixtureParams",
    "KMeansModes",
    "KMeansParams",
    "MeanShiftModes",
    "MeanShiftParams",
    "Modes",
    "NoModes",
    "empty_modes",
]


class Modes(NamedTuple):
    """Up to ``K`` modes of a particle set, the valid ones first by decreasing weight.

    Attributes:
        weight: ``float32 [K]`` share of the particle weight; sums to 1 over the valid modes, 0 elsewhere.
        mean: ``float32 [K, 2]``.
        cov: ``float32 [K, 2, 2]``.
        valid: ``bool [K]``.
    """

    weight: Float[Array, " k"]
    mean: Float[Array, "k 2"]
    cov: Float[Array, "k 2 2"]
    valid: Bool[Array, " k"]


def empty_modes() -> Modes:
    """Zero modes (``K = 0``)."""
    return Modes(
        weight=jnp.zeros((0,), jnp.float32),
        mean=jnp.zeros((0, 2), jnp.float32),
        cov=jnp.zeros((0, 2, 2), jnp.float32),
        valid=jnp.zeros((0,), bool),
    )


def _finish(mass, mean, cov, valid, min_weight) -> Modes:
    """Marks modes below ``min_weight`` of the total invalid, normalises the valid weights, sorts."""
    total = jnp.sum(mass)
    share = mass / jnp.where(total > 0, total, 1.0)
    valid = valid & (mass > 0) & (share >= min_weight)
    kept = jnp.where(valid, mass, 0.0)
    kept_total = jnp.sum(kept)
    weight = kept / jnp.where(kept_total > 0, kept_total, 1.0)
    order = jnp.argsort(-jnp.where(valid, lax.stop_gradient(weight), -1.0), stable=True)
    return Modes(weight=weight[order], mean=mean[order], cov=cov[order], valid=valid[order])


def _hard_modes(xy, weights, labels, centres, valid, min_weight) -> Modes:
    """Modes of hard clusters: member weighted mean and covariance, member weight."""
    w = usable_weights(weights)
    k = centres.shape[0]
    member = jax.nn.one_hot(labels, k, dtype=w.dtype) * w[:, None]
    mass, mean, cov = weighted_stats(xy, member, centres)
    return _finish(mass, mean, cov, valid, min_weight)


@dataclass(frozen=True)
class NoModes:
    """No multi-modal output: :class:`Modes` with ``K = 0``."""

    @property
    def num_modes(self) -> int:
        return 0

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def validate(self) -> None:
        pass

    def modes(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], weights: Float[Array, " n"], params) -> Modes:
        return empty_modes()


class KMeansParams(NamedTuple):
    """Numbers of :class:`KMeansModes`.

    Attributes:
        min_weight: a mode holding less than this share of the weight is invalid.
    """

    min_weight: float = 1e-3


@dataclass(frozen=True)
class KMeansModes:
    """``num_modes`` weighted k-means clusters as modes.

    Initialisation: weighted greedy k-means++ with the key (a draw proportional to ``w``, then each
    time the best of a few draws proportional to ``w D^2``; :func:`heatpf_jax.estimate.kmeans.kmeans_plus_plus`),
    then ``num_iters`` Lloyd iterations.
    k-means always splits the particles into ``num_modes`` clusters, even a single blob; only clusters
    with less than ``min_weight`` of the weight (e.g. around explorers) are invalid.

    Attributes:
        num_modes: ``K``.
        num_iters: Lloyd iterations.
    """

    num_modes: int = 3
    num_iters: int = 10

    def default_params(self) -> KMeansParams:
        return KMeansParams()

    def properties(self) -> KMeansParams:
        # A threshold on a mask: frozen.
        return KMeansParams(min_weight=unit_interval(trainable=False))

    def validate(self) -> None:
        _check_count("num_modes", self.num_modes, 1)
        _check_count("num_iters", self.num_iters, 0)

    def modes(
        self, key: PRNGKeyArray, xy: Float[Array, "n 2"], weights: Float[Array, " n"], params: KMeansParams
    ) -> Modes:
        init = kmeans_plus_plus(key, xy, weights, self.num_modes)
        fit = kmeans(xy, weights, init, num_iters=self.num_iters)
        valid = jnp.ones((self.num_modes,), bool)
        return _hard_modes(xy, weights, fit.labels, fit.centres, valid, params.min_weight)


class GaussianMixtureParams(NamedTuple):
    """Numbers of :class:`GaussianMixtureModes`.

    Attributes:
        reg_covar: added to the diagonal of every covariance, m^2 (keeps a component on duplicated
            particles, as after resampling, non-singular in float32).
        min_weight: a component with a smaller mixing weight is invalid.
    """

    reg_covar: float = 1e-4
    min_weight: float = 1e-3


@dataclass(frozen=True)
class GaussianMixtureModes:
    """The components of a ``num_modes`` Gaussian mixture fitted by weighted EM.

    Initialisation: k-means (k-means++ with the key, ``kmeans_iters`` Lloyd iterations), each cluster
    giving a component (its weight share, mean, covariance + ``reg_covar I``); then ``num_iters``
    EM steps (:func:`heatpf_jax.estimate.gmm.gmm_em`, full covariances, log-space responsibilities).
    Gradients flow through the last M-step only, with its responsibilities held fixed (as the labels
    of a hard clustering): differentiating all the EM steps would cost far more to compile for a
    gradient that matters little at convergence.

    Attributes:
        num_modes: ``K`` components.
        num_iters: EM steps, at least 1.
        kmeans_iters: Lloyd iterations of the initialisation.
    """

    num_modes: int = 3
    num_iters: int = 20
    kmeans_iters: int = 5

    def default_params(self) -> GaussianMixtureParams:
        return GaussianMixtureParams()

    def properties(self) -> GaussianMixtureParams:
        return GaussianMixtureParams(
            reg_covar=positive(),
            min_weight=unit_interval(trainable=False),
        )

    def validate(self) -> None:
        _check_count("num_modes", self.num_modes, 1)
        _check_count("num_iters", self.num_iters, 1)
        _check_count("kmeans_iters", self.kmeans_iters, 0)

    def modes(
        self, key: PRNGKeyArray, xy: Float[Array, "n 2"], weights: Float[Array, " n"], params: GaussianMixtureParams
    ) -> Modes:
        fixed_xy, fixed_w = lax.stop_gradient(xy), lax.stop_gradient(weights)
        reg = jnp.asarray(params.reg_covar, jnp.float32)
        init = kmeans_plus_plus(key, fixed_xy, fixed_w, self.num_modes)
        fit = kmeans(fixed_xy, fixed_w, init, num_iters=self.kmeans_iters)
        start = mixture_from_labels(fixed_xy, fixed_w, fit.labels, fit.centres, lax.stop_gradient(reg))
        mix = gmm_em(fixed_xy, fixed_w, start, num_iters=self.num_iters - 1, reg_covar=lax.stop_gradient(reg))
        # The last EM step: responsibilities fixed (the decision), the M-step differentiable.
        mix = m_step(xy, weights, responsibilities(fixed_xy, mix), mix, reg)
        valid = jnp.ones((self.num_modes,), bool)
        return _finish(mix.weight, mix.mean, mix.cov, valid, params.min_weight)


class MeanShiftParams(NamedTuple):
    """Numbers of :class:`MeanShiftModes`.

    Attributes:
        bandwidth: kernel scale ``h``, metres.
        merge_factor: modes closer than ``merge_factor * bandwidth`` are merged.
        min_weight: a cluster holding less than this share of the weight is invalid.
    """

    bandwidth: float = 0.3
    merge_factor: float = 1.0
    min_weight: float = 1e-3


@dataclass(frozen=True)
class MeanShiftModes:
    """Up to ``max_modes`` mean-shift clusters (Olufs sec. 3.2) as modes.

    :func:`heatpf_jax.estimate.mean_shift.mean_shift` with ``num_seeds`` seeds spread over the weight mass and
    the plane (no key needed: deterministic); a mode is its cluster's member weighted mean and
    covariance and its member weight. Unlike k-means, the number of valid modes follows the data: one
    blob gives one mode.

    Attributes:
        max_modes: ``K``, at most ``num_seeds``.
        num_seeds: mean-shift seeds.
        num_iters: mean-shift steps.
        kernel: ``"gaussian"`` or ``"flat"``.
    """

    max_modes: int = 3
    num_seeds: int = 32
    num_iters: int = 10
    kernel: str = "gaussian"

    @property
    def num_modes(self) -> int:
        return self.max_modes

    def default_params(self) -> MeanShiftParams:
        return MeanShiftParams()

    def properties(self) -> MeanShiftParams:
        # Each acts through a discrete clustering (no gradient): frozen.
        return MeanShiftParams(
            bandwidth=positive(trainable=False),
            merge_factor=positive(trainable=False),
            min_weight=unit_interval(trainable=False),
        )

    def validate(self) -> None:
        _check_count("max_modes", self.max_modes, 1)
        _check_count("num_seeds", self.num_seeds, 1)
        _check_count("num_iters", self.num_iters, 0)
        if self.max_modes > self.num_seeds:
            raise ValueError(f"max_modes: must be at most num_seeds ({self.num_seeds}), got {self.max_modes}")
        if self.kernel not in KERNELS:
            raise ValueError(f"kernel: must be one of {', '.join(KERNELS)}, got {self.kernel!r}")

    def modes(
        self, key: PRNGKeyArray, xy: Float[Array, "n 2"], weights: Float[Array, " n"], params: MeanShiftParams
    ) -> Modes:
        clusters = mean_shift(
            xy,
            weights,
            bandwidth=params.bandwidth,
            num_seeds=self.num_seeds,
            max_clusters=self.max_modes,
            num_iters=self.num_iters,
            merge_radius=params.merge_factor * params.bandwidth,
            kernel=self.kernel,
        )
        return _hard_modes(xy, weights, clusters.labels, clusters.centres, clusters.valid, params.min_weight)
