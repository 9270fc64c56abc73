"""Resamplers with one signature ``(key, weights, num_samples) -> indices`` (III-E).

All are built on a normalised cumulative sum and ``searchsorted``; the cumulative
sum is divided by its last element and the indices clipped, so float32 rounding
(a total that stays just below 1) never yields an out-of-range index.
"""

from __future__ import annotations

from collections.abc import Callable

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray

__all__ = [
    "RESAMPLERS",
    "effective_sample_size",
    "multinomial",
    "residual",
    "stratified",
    "systematic",
]


def effective_sample_size(weights: Float[ArrayLike, " n"]) -> Float[Array, ""]:
    """``1 / sum(w^2)`` of normalised weights: N for uniform weights, 1 for a single survivor."""
    weights = jnp.asarray(weights)
    weights = weights / jnp.sum(weights)
    return 1.0 / jnp.sum(weights * weights)


def _search(weights: Float[Array, " n"], positions: Float[Array, " m"]) -> Int[Array, " m"]:
    n = weights.shape[0]
    cdf = jnp.cumsum(weights)
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


def multinomial(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """Independent draws from the categorical distribution of ``weights``."""
    weights = jnp.asarray(weights)
    positions = jax.random.uniform(key, (num_samples,), weights.dtype)
    return _search(weights, positions)


def residual(key: PRNGKeyArray, weights: Float[ArrayLike, " n"], num_samples: int) -> Int[Array, " m"]:
    """``floor(m w_i)`` deterministic copies of each particle, the rest multinomial on the residuals."""
    weights = jnp.asarray(weights)
    weights = weights / jnp.sum(weights)
    scaled = num_samples * weights
    counts = jnp.floor(scaled).astype(jnp.int32)
    n_det = jnp.sum(counts)
    det = jnp.repeat(jnp.arange(weights.shape[0], dtype=jnp.int32), counts, total_repeat_length=num_samples)
    rest = scaled - counts.astype(scaled.dtype)
    # If rounding left no residual mass, fall back to the weights themselves.
    rest = jnp.where(jnp.sum(rest) > 0, rest, weights)
    extra = multinomial(key, rest, num_samples)
    return jnp.where(jnp.arange(num_samples) < n_det, det, extra)


RESAMPLERS: dict[str, Callable[[PRNGKeyArray, Array, int], Array]] = {
    "systematic": systematic,
    "stratified": stratified,
    "multinomial": multinomial,
    "residual": residual,
}
