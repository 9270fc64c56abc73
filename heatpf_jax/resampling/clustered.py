"""Cluster-wise resampling: Olufs et al.'s extended particle filter (sec. 3.2, Fig. 3).

Plain resampling treats particles one by one, so a short dominant peak draws every offspring and a
second object's particles die out ("particle clinging", "loss of diversity"). The extended filter
treats clusters like particles: the particles are clustered by weighted mean shift
(:func:`heatpf_jax.estimate.mean_shift.mean_shift`), cluster ``j`` of weight ``varpi_j`` receives ``N_j``
offspring, and each cluster is resampled on its own with the same index resampler::

    share_j = s + (1 - m s) varpi_j,   s = min(min_share, 1 / m)    (m valid clusters)
    N_j = largest-remainder rounding of N share_j                     (sum_j N_j = N)

Implementation: the particles are laid out cluster by cluster (each in decreasing weight) and each
cluster's weights are rescaled to total ``N_j / N``; one call of the index resampler on the rescaled
weights then draws exactly ``N_j`` offspring per cluster for systematic and stratified resampling (a
cluster's interval is a whole number of the resampler's ``1 / N`` strata) and, within each cluster,
resamples its own normalised weights. (Multinomial and residual draw ``N_j`` in expectation.)

``min_share = 0`` gives ``N_j ~ N varpi_j``: the posterior is resampled as plain resampling does, with
each cluster's count rounded instead of random. ``min_share > 0`` keeps a weak cluster alive with at
least about ``min_share N`` particles; the offspring then carry (``correct=True``) the importance correction
``log varpi_j - log(N_j / N)``, so that the estimate and the next update still see the posterior
(a kept-alive weak cluster has many particles of small weight). Olufs et al. leave the weights
uniform; the correction is what makes the extra particles a proposal choice rather than a change of
the posterior.

Injectors refill the slots of lowest support first: here each cluster's tail, in proportion to its
size (the rank of a slot is its position within its cluster divided by ``N_j``), so explorers do not
eat a weak cluster first.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, Int, PRNGKeyArray

from heatpf_jax.estimate.mean_shift import mean_shift
from heatpf_jax.params import positive, unit_interval
from heatpf_jax.resampling.resamplers import Resampled, check_resampler, ess_trigger, systematic

__all__ = ["ClusterParams", "ClusterResampling", "cluster_counts", "resample_by_cluster"]


class ClusterParams(NamedTuple):
    """Numbers of :class:`ClusterResampling`.

    Attributes:
        bandwidth: mean-shift kernel bandwidth (Gaussian std), metres.
        min_share: least share of the offspring of every valid cluster (0: in proportion to weight).
        resample_threshold: resample when ESS < resample_threshold * N (as :class:`ESSResampling`).
    """

    bandwidth: float = 0.5
    min_share: float = 0.0
    resample_threshold: float = 1.0


def cluster_counts(
    cluster_weights: Float[Array, " m"], valid: Array, num: int, min_share: Float[Array, ""]
) -> Int[Array, " m"]:
    """Offspring per cluster, ``N_j`` (see the module docstring); sums to ``num``; 0 for invalid clusters.

    Args:
        cluster_weights: ``[M]`` total weight of each cluster (sums to 1 over the valid ones).
        valid: ``bool [M]`` which clusters exist (an empty cluster is treated as invalid).
        num: N.
        min_share: least share of each valid cluster.
    """
    valid = valid & (cluster_weights > 0)
    m = jnp.maximum(jnp.sum(valid), 1).astype(cluster_weights.dtype)
    s = jnp.minimum(min_share, 1.0 / m)
    total = jnp.sum(jnp.where(valid, cluster_weights, 0.0))
    norm = jnp.where(valid, cluster_weights, 0.0) / jnp.where(total > 0, total, 1.0)
    share = jnp.where(valid, s + (1.0 - m * s) * norm, 0.0)
    exact = share * num
    floor = jnp.floor(exact)
    base = floor.astype(jnp.int32)
    remainder = num - jnp.sum(base)
    # Largest remainder: the clusters with the largest fractional parts get one more.
    frac = jnp.where(valid, exact - floor, -1.0)
    place = jnp.argsort(jnp.argsort(-frac, stable=True), stable=True)
    return base + (place < remainder).astype(jnp.int32)


def resample_by_cluster(
    key: PRNGKeyArray,
    resampler: Callable[[PRNGKeyArray, Array, int], Array],
    log_weights: Float[Array, " n"],
    order: Int[Array, " n"],
    labels: Int[Array, " n"],
    cluster_valid: Array,
    min_share: Float[Array, ""],
    correct: bool = True,
) -> tuple[Int[Array, " n"], Float[Array, " n"], Int[Array, " n"]]:
    """Resamples every cluster on its own (Fig. 3); returns ``(ancestors, log_weights, rank)``.

    Args:
        key: PRNG key of the index resampler.
        resampler: index resampler ``(key, weights, num) -> non-decreasing indices``.
        log_weights: ``[N]`` normalised log weights.
        order: ``int32 [N]`` particle indices by decreasing weight.
        labels: ``int32 [N]`` each particle's cluster in ``[0, M)``.
        cluster_valid: ``bool [M]``.
        min_share: least share of each valid cluster.
        correct: give the offspring the importance correction (else uniform weights, as Olufs et al.).
    """
    n = log_weights.shape[0]
    m = cluster_valid.shape[0]
    weights = jnp.exp(log_weights)
    cluster_w = jax.ops.segment_sum(weights, labels, num_segments=m)
    counts = cluster_counts(cluster_w, cluster_valid, n, min_share)
    # Lay out the particles cluster by cluster, each cluster in decreasing weight.
    layout = order[jnp.argsort(labels[order], stable=True)]
    lab = labels[layout]
    safe_cw = jnp.where(cluster_w > 0, cluster_w, 1.0)
    scaled = weights[layout] / safe_cw[lab] * (counts[lab].astype(weights.dtype) / n)
    local = resampler(key, scaled / jnp.sum(scaled), n)
    ancestors = layout[local]
    # Importance correction: varpi_j / (N_j / N) per offspring of cluster j.
    slot_cluster = labels[ancestors]
    log_cw = jnp.log(jnp.where(cluster_w > 0, cluster_w, 1.0))
    log_share = jnp.log(jnp.maximum(counts, 1).astype(weights.dtype) / n)
    correction = (log_cw - log_share)[slot_cluster] if correct else jnp.zeros((n,), weights.dtype)
    new_log_w = correction - jax.nn.logsumexp(correction)
    # Support rank: each cluster's tail first, in proportion to its size.
    start = jnp.cumsum(counts) - counts
    slots = jnp.arange(n, dtype=jnp.int32)
    position = jnp.clip(slots - start[slot_cluster], 0, None).astype(weights.dtype)
    frac = position / jnp.maximum(counts[slot_cluster], 1).astype(weights.dtype)
    by_support = jnp.lexsort((-cluster_w[slot_cluster], frac))
    rank = jnp.zeros((n,), jnp.int32).at[by_support].set(slots, unique_indices=True)
    return ancestors, new_log_w, rank


@dataclass(frozen=True)
class ClusterResampling:
    """Olufs et al.'s cluster-wise resampling (see the module docstring), with an ESS trigger.

    Attributes:
        resampler: index resampler ``(key, weights, num) -> indices`` (see ``RESAMPLERS``).
        num_seeds: mean-shift seeds (the heaviest particles).
        max_clusters: static maximum number of clusters.
        num_iters: mean-shift iterations.
        correct: offspring carry the importance correction ``varpi_j / (N_j / N)`` (the posterior is
            kept: a kept-alive weak cluster has small weights), or uniform weights (``False``, Olufs et
            al.: every cluster is a hypothesis of its own, and a kept-alive one keeps its share).
    """

    resampler: Callable[[PRNGKeyArray, Array, int], Array] = systematic
    num_seeds: int = 32
    max_clusters: int = 4
    num_iters: int = 10
    correct: bool = True

    def default_params(self) -> ClusterParams:
        return ClusterParams()

    def properties(self) -> ClusterParams:
        return ClusterParams(
            bandwidth=positive(trainable=False),
            min_share=unit_interval(trainable=False),
            resample_threshold=unit_interval(trainable=False),
        )

    def validate(self) -> None:
        check_resampler(self.resampler)
        for name in ("num_seeds", "max_clusters", "num_iters"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer, got {value!r}")

    def resample(
        self,
        key: PRNGKeyArray,
        xy: Float[Array, "n 2"],
        log_weights: Float[Array, " n"],
        order: Int[Array, " n"],
        params: ClusterParams,
    ) -> Resampled:
        n = log_weights.shape[0]
        weights = jnp.exp(log_weights)
        ess, resampled = ess_trigger(weights, params.resample_threshold)
        slots = jnp.arange(n, dtype=jnp.int32)

        def by_cluster(_):
            clusters = mean_shift(
                lax.stop_gradient(xy),
                lax.stop_gradient(weights),
                bandwidth=params.bandwidth,
                num_seeds=min(self.num_seeds, n),
                max_clusters=self.max_clusters,
                num_iters=self.num_iters,
            )
            return resample_by_cluster(
                key,
                self.resampler,
                log_weights,
                order,
                clusters.labels,
                clusters.valid,
                params.min_share,
                self.correct,
            )

        def keep(_):
            inverse = jnp.zeros((n,), jnp.int32).at[order].set(slots, unique_indices=True)
            return slots, log_weights, inverse

        ancestors, new_log_w, rank = lax.cond(resampled, by_cluster, keep, None)
        return Resampled(ancestors=ancestors, log_weights=new_log_w, rank=rank, resampled=resampled, ess=ess)
