"""The long-term memory's track table (Olufs et al. 3.4): its slots, and which tracks the filter has lost.

:class:`TrackTable` is the memory's state (``StepInfo.tracks``); :func:`complete_tracks` fills the role fields of
a table built without them, and :func:`lost_tracks` names the tracks that get hint particles. The memory's
step is described in :mod:`heatpf_jax.memory`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

__all__ = [
    "TrackTable",
    "complete_tracks",
    "empty_tracks",
    "lost_tracks",
]


class TrackTable(NamedTuple):
    """The memory's tracks, ``M = capacity`` slots (the state of
    :class:`~heatpf_jax.memory.track_memory.TrackMemory`, ``StepInfo.tracks``).

    Attributes:
        id: ``int32 [M]`` track identifiers (1, 2, ...; 0 in empty slots).
        valid: ``bool [M]`` slots holding a track.
        mean: ``float32 [M, 4]`` ``(x, y, vx, vy)`` in the current base frame (metres, m/s).
        cov: ``float32 [M, 4, 4]`` its covariance.
        age: ``float32 [M]`` seconds since the track was last observed, by the filter or by the memory's
            own re-detection (0: observed this step).
        hits: ``int32 [M]`` steps on which it was observed.
        found: ``bool [M]`` observed this step by the filter (a candidate was associated to it); a track
            the memory re-detected on its own is not found.
        next_id: ``int32 []`` the next identifier to hand out.
        ball: ``bool [M]`` the ball's track: the one that carried the filter's estimate (at most one).
        static: ``bool [M]`` static clutter: confirmed, not the ball, slower than ``memory_static_speed``.
        carried: ``int32 [M]`` steps on which the filter found the track (0: only the memory saw it).
        missed: ``float32 [M]`` seconds since the filter last found the track (since its birth if never).
        blob: ``float32 [M]`` the weight of the track's blob (:func:`~heatpf_jax.memory.blobs.find_blobs`) as usually
            seen (a running mean over the steps it was observed; 0: not known yet): what the object looks like in the
            heat map.

    The last five fields were added later: a table built without them (``None``) is completed by
    :func:`complete_tracks` (no ball, no clutter, every observation the filter's, ``missed = age``, no blob).
    """

    id: Int[Array, " m"]
    valid: Bool[Array, " m"]
    mean: Float[Array, "m 4"]
    cov: Float[Array, "m 4 4"]
    age: Float[Array, " m"]
    hits: Int[Array, " m"]
    found: Bool[Array, " m"]
    next_id: Int[Array, ""]
    ball: Bool[Array, " m"] | None = None
    static: Bool[Array, " m"] | None = None
    carried: Int[Array, " m"] | None = None
    missed: Float[Array, " m"] | None = None
    blob: Float[Array, " m"] | None = None


def empty_tracks(capacity: int) -> TrackTable:
    """A table of ``capacity`` empty slots."""
    return TrackTable(
        id=jnp.zeros((capacity,), jnp.int32),
        valid=jnp.zeros((capacity,), bool),
        mean=jnp.zeros((capacity, 4), jnp.float32),
        cov=jnp.tile(jnp.eye(4, dtype=jnp.float32), (capacity, 1, 1)),
        age=jnp.zeros((capacity,), jnp.float32),
        hits=jnp.zeros((capacity,), jnp.int32),
        found=jnp.zeros((capacity,), bool),
        next_id=jnp.ones((), jnp.int32),
        ball=jnp.zeros((capacity,), bool),
        static=jnp.zeros((capacity,), bool),
        carried=jnp.zeros((capacity,), jnp.int32),
        missed=jnp.zeros((capacity,), jnp.float32),
        blob=jnp.zeros((capacity,), jnp.float32),
    )


def complete_tracks(tracks: TrackTable) -> TrackTable:
    """``tracks`` with its role fields filled where they are ``None`` (a table built by hand, or before they
    existed): no ball, no static clutter, every observation of a track the filter's (``carried = hits``),
    ``missed = age``."""
    valid = jnp.asarray(tracks.valid)
    return tracks._replace(
        ball=jnp.zeros_like(valid) if tracks.ball is None else tracks.ball,
        static=jnp.zeros_like(valid) if tracks.static is None else tracks.static,
        carried=jnp.where(valid, tracks.hits, 0).astype(jnp.int32) if tracks.carried is None else tracks.carried,
        missed=jnp.asarray(tracks.age, jnp.float32) if tracks.missed is None else tracks.missed,
        blob=jnp.zeros(valid.shape, jnp.float32) if tracks.blob is None else tracks.blob,
    )


def lost_tracks(tracks: TrackTable, confirm: Int[Array, ""] | int) -> Bool[Array, " m"]:
    """Tracks the filter has lost: confirmed (``hits >= confirm``), not found by the filter this step, and the
    ball or a track the filter carried that is not static clutter (a blob only the memory saw, or a static
    distractor, was never the filter's to lose)."""
    t = complete_tracks(tracks)
    return t.valid & (t.hits >= confirm) & ~t.found & (t.ball | ((t.carried > 0) & ~t.static))
