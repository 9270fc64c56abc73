"""Explorer particles (III-E): the lowest-support particles respawn from a spawn distribution.

A configurable fraction of the particles with the lowest support is drawn anew,
so that a second region of high activation (a true positive next to a false
one, Fig. 5) can still attract particles after the cloud has converged.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray

__all__ = ["explorer_count", "explorer_mask", "explorer_slots", "spawn_gaussian", "spawn_uniform"]


def spawn_uniform(key: PRNGKeyArray, num: int, box: tuple[float, float, float, float]) -> Float[Array, "num 2"]:
    """``num`` points uniform over ``box = (x_min, x_max, y_min, y_max)`` in the base frame."""
    x_min, x_max, y_min, y_max = box
    low = jnp.array([x_min, y_min], jnp.float32)
    high = jnp.array([x_max, y_max], jnp.float32)
    return jax.random.uniform(key, (num, 2), jnp.float32, low, high)


def spawn_gaussian(
    key: PRNGKeyArray, num: int, mean: Float[ArrayLike, "2"], std: Float[ArrayLike, ""]
) -> Float[Array, "num 2"]:
    """``num`` points from ``N(mean, std^2 I)``."""
    return jnp.asarray(mean, jnp.float32)[None, :] + std * jax.random.normal(key, (num, 2), jnp.float32)


def explorer_mask(support: Float[ArrayLike, " n"], fraction: Float[ArrayLike, ""]) -> Bool[Array, " n"]:
    """Marks the ``round(fraction * n)`` particles with the lowest support (ties by index).

    ``fraction`` may be traced: the count is a traced integer and the mask is
    built from ranks, so shapes stay static.
    """
    support = jnp.asarray(support)
    n = support.shape[0]
    count = explorer_count(fraction, n)
    order = jnp.argsort(support, stable=True)
    rank = jnp.zeros((n,), jnp.int32).at[order].set(jnp.arange(n, dtype=jnp.int32))
    return rank < count


def explorer_count(fraction: Float[ArrayLike, ""], num: int) -> Array:
    """``round(fraction * num)`` as a (possibly traced) ``int32``: how many particles respawn."""
    return jnp.round(fraction * num).astype(jnp.int32)


def explorer_slots(num: int, fraction: Float[ArrayLike, ""]) -> Bool[Array, " num"]:
    """Marks the last ``round(fraction * num)`` of ``num`` slots.

    After resampling particles sorted by decreasing weight (every resampler returns
    non-decreasing indices), the last slots hold the copies with the lowest support:
    this is :func:`explorer_mask` of their support (ties broken by the sort) without a
    second sort.
    """
    return jnp.arange(num, dtype=jnp.int32) >= num - explorer_count(fraction, num)
