"""Step 4 of the long-term memory (Olufs et al. 3.4): the memory's own blobs, and re-detection on them.

:func:`find_blobs` groups the buffer's measurements into blobs (one object each, a ball's pixels stretched along
the ray by their footprint); :func:`redetect` pairs them with the tracks inside their gates and re-detects the
lost tracks whose blob is strong enough.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.measurements import Measurements
from heatpf_jax.memory.gates import _associate, gate_costs
from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.table import TrackTable, complete_tracks

__all__ = [
    "Blobs",
    "find_blobs",
    "redetect",
]


def _blob_cov(buffer: Measurements, radius) -> Float[Array, "n 2 2"]:
    """The ground covariance of a ball-sized blob (``radius`` metres) around each measurement, from its pixel's
    footprint ``J``: a disc of ``rho = radius / |J e_u|`` pixels (``|J e_u|``, the lateral ground step, is the
    distance over the focal length) has the pixel covariance ``rho^2 / 4 I``, so ``rho^2 / 4 J J^T`` on the ground:
    ``radius / 2`` across the ray and stretched along it as the ground is seen at a grazing angle (several times
    at a few metres). Zero for measurements without a footprint."""
    j = buffer.footprint
    lateral2 = jnp.sum(j[:, :, 0] ** 2, axis=1)
    scale = jnp.where(lateral2 > 0, radius**2 / (4.0 * jnp.maximum(lateral2, 1e-20)), 0.0)
    return scale[:, None, None] * jnp.einsum("nik,njk->nij", j, j)


class Blobs(NamedTuple):
    """The memory's own detections in a buffer (:func:`find_blobs`).

    Attributes:
        xy: ``float32 [B, 2]`` each blob's weighted centroid.
        weight: ``float32 [B]`` its summed measurement weight.
        valid: ``bool [B]`` blobs found (weight at least ``memory_min_support``).
        member: ``int32 [N]`` each measurement's blob (-1: none).
    """

    xy: Float[Array, "b 2"]
    weight: Float[Array, " b"]
    valid: Bool[Array, " b"]
    member: Int[Array, " n"]


def find_blobs(buffer: Measurements, params: "MemoryParams", count: int) -> Blobs:
    """Up to ``count`` blobs, strongest first: the strongest measurement not yet in a blob and every other one within
    ``memory_support_radius`` of it or within ``memory_redetect_sigmas`` sigmas of its ball-sized blob (a pixel's
    footprint stretches a ball's pixels along the ray, :func:`_blob_cov` with ``memory_blob_radius``). A blob is
    one object the heat map shows; the memory associates blobs, not pixels, to its tracks."""
    n = buffer.valid.shape[0]
    eye = jnp.eye(2, dtype=jnp.float32)[None]
    blob_cov = _blob_cov(buffer, params.memory_blob_radius) + params.memory_obs_std**2 * eye
    free = buffer.valid
    member = jnp.full((n,), -1, jnp.int32)
    xys, weights = [], []
    for b in range(count):
        w = jnp.where(free, buffer.weight, 0.0)
        i = jnp.argmax(w)
        d = buffer.xy - buffer.xy[i][None]
        d2 = jnp.einsum("ni,ij,nj->n", d, jnp.linalg.inv(blob_cov[i]), d)
        near = free & ((jnp.sum(d * d, axis=1) <= params.memory_support_radius**2)
                       | (d2 <= params.memory_redetect_sigmas**2))
        wn = jnp.where(near, buffer.weight, 0.0)
        support = jnp.sum(wn)
        xys.append((wn @ buffer.xy) / jnp.where(support > 0, support, 1.0))
        weights.append(support)
        member = jnp.where(near, b, member)
        free = free & ~near
    weight = jnp.stack(weights) if count else jnp.zeros((0,), jnp.float32)
    xy = jnp.stack(xys) if count else jnp.zeros((0, 2), jnp.float32)
    return Blobs(xy=xy, weight=weight, valid=weight >= params.memory_min_support, member=member)


def _blob_of_track(tracks: TrackTable, blobs: Blobs, params: "MemoryParams", dt=None) -> Int[Array, " m"]:
    """Each track's blob (-1: none): blobs and tracks paired most likely first, each blob's centroid inside the
    track's gate (:func:`~heatpf_jax.memory.gates.gate_costs`, with the step's length ``dt``), each blob and each
    track at most once."""
    track_of_blob = _associate(gate_costs(tracks, blobs.xy, params, dt), blobs.valid)
    m = tracks.valid.shape[0]
    hits = track_of_blob[:, None] == jnp.arange(m, dtype=jnp.int32)[None, :]
    return jnp.where(jnp.any(hits, axis=0), jnp.argmax(hits, axis=0).astype(jnp.int32), -1)


def redetect(
    tracks: TrackTable,
    lost: Bool[Array, " m"],
    buffer: Measurements,
    params: "MemoryParams",
    max_blobs: int = 8,
    dt=None,
) -> tuple[Bool[Array, " m"], Float[Array, "m 2"]]:
    """The memory re-detects lost tracks on its own (Olufs et al.: "the long-term memory allows to re-detect
    vanished objects"): the blobs in ``buffer`` (:func:`find_blobs`) are paired with every track, most likely pairs
    first, each blob's centroid inside the track's gate around its *prediction*; a lost track is re-detected at
    its blob when that blob weighs ``memory_min_support`` and ``memory_redetect_share`` of the track's usual blob
    (``TrackTable.blob``: a speck of clutter is not the ball that was there). A blob outside the gate, or one
    a static distractor's track explains better, never re-detects it, however uncertain the track has grown; given
    the step's length ``dt`` (the tracks predicted by it), neither does a blob a lost rolling track cannot have
    reached (:func:`~heatpf_jax.memory.gates.motion_consistent`).

    Returns:
        ``(redetected [M], centroid [M, 2])``.
    """
    again, centroid, _, _ = _redetect(complete_tracks(tracks), lost, find_blobs(buffer, params, max_blobs), params,
                                      dt)
    return again, centroid


def _redetect(tracks: TrackTable, lost, blobs: Blobs, params: "MemoryParams", dt=None):
    """:func:`redetect` on found blobs; also every track's blob weight ``[M]`` and blob index ``[M]``."""
    j = _blob_of_track(tracks, blobs, params, dt)
    jj = jnp.maximum(j, 0)
    weight = jnp.where(j >= 0, blobs.weight[jj], 0.0)
    centroid = jnp.where((j >= 0)[:, None], blobs.xy[jj], tracks.mean[:, :2])
    enough = weight >= jnp.maximum(params.memory_min_support, params.memory_redetect_share * tracks.blob)
    return lost & tracks.valid & (j >= 0) & enough, centroid, weight, j
