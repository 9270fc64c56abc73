"""Numerical helpers shared by the pieces: safe log and sqrt, log-weight normalisation, one fast sort."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, Int

__all__ = ["normalise_log", "order_by_weight", "ranks_of", "safe_log", "safe_sqrt"]


def safe_log(x: Float[Array, "..."]) -> Float[Array, "..."]:
    """log with log(0) = -inf and finite gradients elsewhere (the double-``where`` idiom)."""
    positive = x > 0
    return jnp.where(positive, jnp.log(jnp.where(positive, x, 1.0)), -jnp.inf)


def safe_sqrt(x: Float[Array, "..."]) -> Float[Array, "..."]:
    """sqrt with a zero (not infinite) gradient at 0, so reparameterised noise stays differentiable."""
    return jnp.where(x > 0.0, jnp.sqrt(jnp.where(x > 0.0, x, 1.0)), 0.0)


def normalise_log(log_w: Float[Array, " n"], total: Float[Array, ""] | None = None) -> Float[Array, " n"]:
    """Log weights minus their log-sum-exp; uniform when every weight is zero (or the sum is not finite).

    ``total`` is ``logsumexp(log_w)`` when the caller has it already.
    """
    total = jax.nn.logsumexp(log_w) if total is None else total
    n = log_w.shape[0]
    return jnp.where(jnp.isfinite(total), log_w - total, jnp.full_like(log_w, -math.log(n)))


def ranks_of(order: Int[Array, " n"]) -> Int[Array, " n"]:
    """The inverse permutation: ``rank[order[i]] = i`` (each slot's place in ``order``)."""
    n = order.shape[0]
    return jnp.zeros((n,), jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))


def order_by_weight(weights: Float[Array, " n"]) -> Int[Array, " n"]:
    """Particle indices by decreasing weight, from one sort of ``int32`` keys.

    A single-operand integer sort is about three times faster on XLA:CPU than an argsort
    (which sorts a key and an index payload with a compiled comparator). The key is the
    weight's bit pattern (monotone for non-negative floats) with its ``ceil(log2 n)`` low
    bits replaced by the index, so weights that agree to within ``2**(ceil(log2 n) - 24)``
    relative (6e-5 for 500 particles) are ordered by index, as exact ties are. Resampling
    is valid in any order; the top-fraction estimate and the injected slots only move
    between such near-equal weights.
    """
    n = weights.shape[0]
    bits = max(1, (n - 1).bit_length())
    if bits > 16:  # the key would lose more than half of the mantissa: sort exactly
        return jnp.argsort(-weights, stable=True).astype(jnp.int32)
    low = (1 << bits) - 1
    # Equal weight bits: the larger (low - index), i.e. the smaller index, comes first. ~key sorts
    # ascending exactly as key sorts descending.
    key = (lax.bitcast_convert_type(weights, jnp.int32) & ~low) | (low - lax.iota(jnp.int32, n))
    return low - (~jnp.sort(~key) & low)
