"""Resampling (III-E): index resamplers and the resampling strategy of the filter step.

Resamplers share one signature ``(key, weights, num_samples) -> indices``.

All are built on a normalised cumulative sum and ``searchsorted``; the cumulative
sum is divided by its last element and the indices clipped, so float32 rounding
(a total that stays just below 1) never yields an out-of-range index.

Every resampler returns **non-decreasing** indices: the copies of one particle are
contiguous. The filter step relies on it: it resamples particles sorted by
decreasing weight, so the last slots hold the copies with the lowest support and
become the explorers (III-E) without a second sort.

:class:`ESSResampling` is the filter's resampling piece: it resamples when the effective sample
size falls below a share of N and returns a :class:`Resampled`: the ancestors of every slot and
each slot's support rank, from which the injectors take the slots they refill.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from heatpf_jax.params import unit_interval

__all__ = [
    "check_resampler",
    "RESAMPLERS",
    "ESSParams",
    "ESSResampling",
    "Resampled",
    "effective_sample_size",
    "ess_trigger",
    "multinomial",
    "residual",
    "sorted_resampled",
    "stratified",
    "systematic",
]


def effective_sample_size(weights: Float[ArrayLike, " n"]) -> Float[Array, ""]:
    """``1 / sum(w^2)`` of normalised weights: N for uniform weights, 1 for a single survivor."""
    weights = jnp.asarray(weights)
    weights = weights / jnp.sum(weights)
    return 1.0 / jnp.sum(weights * weights)


def ess_trigger(
    weights: Float[Array, " n"], threshold: Float[ArrayLike, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """The resampling trigger (III-E): ``(ess, ess < threshold * N)`` of normalised weights."""
    ess = effective_sample_size(weights)
    return ess, ess < threshold * weights.shape[0]


def _search(weights: Float[Array, " n"], positions: Float[Array, " m"]) -> Int[Array, " m"]:
    n = weights.shape[0]
    # XLA's blocked cumsum is not exactly monotone; the running maximum makes it so, which
    # keeps the indices of sorted positions non-decreasing.
    cdf = lax.cummax(jnp.cumsum(weights), axis=0)
    cdf = cdf / cdf[-1]
    idx = jnp.clip(jnp.searchsorted(cdf, positions, side="right"), 0, n - 1)
    # float32 rounding (a position that rounds to 1, or XLA's blocked cumsum not being exactly
    # monotone) can land on a zero-weight particle: move to the next positive-weight index,
    # or back to the last one. Integer work, so exact.
    slots = jnp.arange(n, dtype=jnp.int32)
    positive = weights > 0
    next_positive = lax.cummin(jnp.where(positive, slots, n), axis=0, reverse=True)
    last_positive = jnp.max(jnp.where(positive, slots, -1))
    moved = next_positive[idx]
    return jnp.where(moved < n, moved, last_positive).astype(jnp.int32)


def systematic(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """One uniform offset shared by ``num_samples`` evenly spaced positions ``(i + u) / m``."""
    weights = jnp.asarray(weights)
    u = jax.random.uniform(key, (), weights.dtype)
    positions = (jnp.arange(num_samples, dtype=weights.dtype) + u) / num_samples
    return _search(weights, positions)


def stratified(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """One independent uniform per stratum: positions ``(i + u_i) / m``."""
    weights = jnp.asarray(weights)
    u = jax.random.uniform(key, (num_samples,), weights.dtype)
    positions = (jnp.arange(num_samples, dtype=weights.dtype) + u) / num_samples
    return _search(weights, positions)


def _sorted_uniforms(key: PRNGKeyArray, num: int, dtype) -> Float[Array, " num"]:
    """The order statistics of ``num`` iid uniforms on [0, 1), drawn in O(num) without a sort.

    Normalised partial sums of ``num + 1`` standard exponentials ``E_i = -log(1 - U_i)``
    are distributed as sorted uniforms (the exponential-spacings representation).
    """
    u = jax.random.uniform(key, (num + 1,), dtype)
    sums = lax.cummax(jnp.cumsum(-jnp.log1p(-u)), axis=0)
    return jnp.minimum(sums[:num] / sums[num], jnp.asarray(1.0, dtype))


def multinomial(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """Independent draws from the categorical distribution of ``weights`` (returned sorted)."""
    weights = jnp.asarray(weights)
    return _search(weights, _sorted_uniforms(key, num_samples, weights.dtype))


def residual(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """``floor(m w_i)`` deterministic copies of each particle, the rest multinomial on the residuals."""
    weights = jnp.asarray(weights)
    weights = weights / jnp.sum(weights)
    scaled = num_samples * weights
    counts = jnp.floor(scaled).astype(jnp.int32)
    n_det = jnp.sum(counts)
    rest = scaled - counts.astype(scaled.dtype)
    # If rounding left no residual mass, fall back to the weights themselves.
    rest = jnp.where(jnp.sum(rest) > 0, rest, weights)
    # m iid draws on the residuals (unsorted, so any m - n_det of them are iid); their counts
    # join the deterministic copies and one repeat returns everything in sorted order.
    extra = _search(rest, jax.random.uniform(key, (num_samples,), weights.dtype))
    slots = jnp.arange(num_samples, dtype=jnp.int32)
    counts = counts.at[extra].add((slots >= n_det).astype(jnp.int32))
    return jnp.repeat(jnp.arange(weights.shape[0], dtype=jnp.int32), counts, total_repeat_length=num_samples)


RESAMPLERS: dict[str, Callable[[PRNGKeyArray, Array, int], Array]] = {
    "systematic": systematic,
    "stratified": stratified,
    "multinomial": multinomial,
    "residual": residual,
}


def check_resampler(resampler) -> None:
    """Raises ``ValueError`` naming ``resampler`` unless it is an index resampler (a function)."""
    if not callable(resampler):
        raise ValueError(f"resampler: must be a function (key, weights, num) -> indices, got {resampler!r}")


class Resampled(NamedTuple):
    """What a resampling strategy returns.

    Attributes:
        ancestors: ``int32 [N]``: slot i now holds a copy of particle ``ancestors[i]``.
        log_weights: ``float32 [N]`` normalised log weights after resampling.
        rank: ``int32 [N]`` each slot's support rank (0: the most support). Injectors refill the
            slots of highest rank (lowest support) first.
        resampled: ``bool []`` whether this step resampled.
        ess: ``float32 []`` effective sample size before resampling.
    """

    ancestors: Int[Array, " n"]
    log_weights: Float[Array, " n"]
    rank: Int[Array, " n"]
    resampled: Bool[Array, ""]
    ess: Float[Array, ""]


class ESSParams(NamedTuple):
    """Numbers of :class:`ESSResampling`.

    Attributes:
        resample_threshold: resample when ESS < resample_threshold * N (1.0: every step, as SIR,
            unless the weights are uniform).
    """

    resample_threshold: float = 1.0


@dataclass(frozen=True)
class ESSResampling:
    """Resamples with ``resampler`` when the effective sample size falls below ``resample_threshold * N``.

    The particles are resampled in the step's order of decreasing weight; since every resampler
    returns non-decreasing indices, slot i of the result has support rank i. A step that does not
    resample keeps every particle in its slot, ranked by its weight.

    Attributes:
        resampler: an index resampler ``(key, weights, num_samples) -> indices`` (see ``RESAMPLERS``).
    """

    resampler: Callable[[PRNGKeyArray, Array, int], Array] = systematic

    def default_params(self) -> ESSParams:
        return ESSParams()

    def properties(self) -> ESSParams:
        return ESSParams(resample_threshold=unit_interval(trainable=False))

    def validate(self) -> None:
        check_resampler(self.resampler)

    def resample(
        self,
        key: PRNGKeyArray,
        xy: Float[Array, "n 2"],
        log_weights: Float[Array, " n"],
        order: Int[Array, " n"],
        params: ESSParams,
    ) -> Resampled:
        del xy
        n = log_weights.shape[0]
        weights = jnp.exp(log_weights)
        ess, resampled = ess_trigger(weights, params.resample_threshold)
        idx = self.resampler(key, weights[order], n)
        return sorted_resampled(resampled, order[idx], jnp.full_like(log_weights, -math.log(n)), log_weights, order,
                                ess)


def sorted_resampled(
    resampled: Bool[Array, ""],
    ancestors: Int[Array, " n"],
    new_log_weights: Float[Array, " n"],
    log_weights: Float[Array, " n"],
    order: Int[Array, " n"],
    ess: Float[Array, ""],
) -> Resampled:
    """The :class:`Resampled` of a draw made in the order of decreasing weight (slot i has support rank i), or,
    where ``resampled`` is false, every particle kept in its slot with its weight, ranked by ``order``."""
    n = log_weights.shape[0]
    slots = jnp.arange(n, dtype=jnp.int32)
    inverse = jnp.zeros((n,), jnp.int32).at[order].set(slots, unique_indices=True)
    return Resampled(
        ancestors=jnp.where(resampled, ancestors, slots),
        log_weights=jnp.where(resampled, new_log_weights, log_weights),
        rank=jnp.where(resampled, slots, inverse),
        resampled=resampled,
        ess=ess,
    )
