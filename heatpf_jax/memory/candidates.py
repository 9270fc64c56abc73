"""Step 2 of the long-term memory (Olufs et al. 3.4): the filter's candidates and what the buffer shows under them.

A candidate (a mode of the filter's, or its estimate) is *observed* when buffered measurement weight lies under it
(:func:`observed_support`); the memory then observes the memory's own blob that holds most of that weight
(:func:`blob_under`), or the centroid of that weight (:func:`observed_blob`).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.measurements import Measurements

__all__ = [
    "blob_under",
    "candidates_from",
    "observed_blob",
    "observed_support",
]


def observed_support(
    xy: Float[Array, "k 2"], buffer: Measurements, radius: Float[Array, ""]
) -> Float[Array, " k"]:
    """Buffered measurement weight within ``radius`` of each point: how much the filter *sees* there."""
    d2 = jnp.sum((xy[:, None, :] - buffer.xy[None, :, :]) ** 2, axis=-1)
    near = (d2 <= radius**2) & buffer.valid[None, :]
    return jnp.sum(jnp.where(near, buffer.weight[None, :], 0.0), axis=1)


def observed_blob(
    xy: Float[Array, "k 2"], buffer: Measurements, radius: Float[Array, ""]
) -> tuple[Float[Array, " k"], Float[Array, "k 2"]]:
    """:func:`observed_support` and the weighted centroid of those measurements (``xy`` where there are none)."""
    d2 = jnp.sum((xy[:, None, :] - buffer.xy[None, :, :]) ** 2, axis=-1)
    w = jnp.where((d2 <= radius**2) & buffer.valid[None, :], buffer.weight[None, :], 0.0)
    support = jnp.sum(w, axis=1)
    centre = (w @ buffer.xy) / jnp.where(support > 0, support, 1.0)[:, None]
    return support, jnp.where((support > 0)[:, None], centre, xy)


def candidates_from(modes, estimate_mean: Float[Array, "2"]) -> tuple[Float[Array, "k 2"], Bool[Array, " k"]]:
    """The memory's candidate positions: the valid modes, or the estimate alone when there are no modes."""
    if modes.mean.shape[0] == 0:
        return jnp.asarray(estimate_mean, jnp.float32)[None, :], jnp.ones((1,), bool)
    return modes.mean, modes.valid


def blob_under(
    xy: Float[Array, "k 2"], buffer: Measurements, member: Int[Array, " n"], blob_xy: Float[Array, "b 2"],
    radius: Float[Array, ""],
) -> Float[Array, "k 2"]:
    """Where the memory observes each candidate: the centroid of the blob holding the most buffered weight within
    ``radius`` of it (``member`` and ``blob_xy``: :func:`~heatpf_jax.memory.blobs.find_blobs`), one object, never the
    mean of two blobs that both lie near a candidate between them; the centroid of that weight
    (:func:`observed_blob`) where none of it lies in a blob, ``xy`` where there is none.

    When the ball vanishes beside a distractor the filter's mode passes from the one to the other; the centroid of
    everything near it lies between them and, a little farther each step, drags the ball's track (observed every
    step, its gate never widened) onto the distractor. The blob's centroid is the ball's last blob or the
    distractor's: the one the ball's track can take, the other its own track's.
    """
    d2 = jnp.sum((xy[:, None, :] - buffer.xy[None, :, :]) ** 2, axis=-1)
    w = jnp.where((d2 <= radius**2) & buffer.valid[None, :], buffer.weight[None, :], 0.0)
    support = jnp.sum(w, axis=1)
    centre = jnp.where((support > 0)[:, None], (w @ buffer.xy) / jnp.where(support > 0, support, 1.0)[:, None], xy)
    one_hot = (member[:, None] == jnp.arange(blob_xy.shape[0], dtype=member.dtype)[None, :]).astype(w.dtype)
    per_blob = w @ one_hot  # [k, b]: each candidate's weight in each blob
    on_blob = jnp.max(per_blob, axis=1, initial=0.0) > 0
    return jnp.where(on_blob[:, None], blob_xy[jnp.argmax(per_blob, axis=1)], centre)
