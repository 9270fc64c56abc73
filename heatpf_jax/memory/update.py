"""One step of the long-term memory (Olufs et al. 3.4): associate, update, re-detect, give birth, roles, forget.

:func:`update_tracks` runs the steps of :mod:`heatpf_jax.memory` on a :class:`~heatpf_jax.memory.table.TrackTable`:
a Kalman update of each track the filter's candidates or the memory's blobs observe, new tracks for what no track
explains, the ball's flag and static clutter, and forgetting.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from heatpf_jax.measurements import Measurements
from heatpf_jax.memory.blobs import _redetect, find_blobs
from heatpf_jax.memory.candidates import observed_support
from heatpf_jax.memory.gates import _associate, gate_costs
from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.predict import predict_tracks
from heatpf_jax.memory.table import TrackTable, complete_tracks

__all__ = ["update_tracks"]


def _kalman_update(mean, cov, z, obs_std):
    h = jnp.zeros((2, 4), jnp.float32).at[0, 0].set(1.0).at[1, 1].set(1.0)
    s = h @ cov @ h.T + obs_std**2 * jnp.eye(2, dtype=jnp.float32)
    gain = jnp.linalg.solve(s, h @ cov).T  # cov h^T s^-1 (s symmetric)
    mean = mean + gain @ (z - h @ mean)
    i_kh = jnp.eye(4, dtype=jnp.float32) - gain @ h
    cov = i_kh @ cov @ i_kh.T + obs_std**2 * gain @ gain.T  # Joseph form: stays symmetric positive
    return mean, cov


_BLOB_RATE = 0.3  # the running mean's weight of a new observation of a track's blob weight


def _spawn_cov(params: MemoryParams):
    return jnp.diag(
        jnp.stack([params.memory_obs_std**2, params.memory_obs_std**2,
                   params.memory_spawn_speed_std**2, params.memory_spawn_speed_std**2])
    ).astype(jnp.float32)


def _birth(tracks: TrackTable, slot, xy, born, spawn_cov, carried: bool, blob=0.0) -> TrackTable:
    """``tracks`` with a new track at ``xy`` (at rest) in ``slot`` where ``born``."""
    new = tracks._replace(
        id=tracks.id.at[slot].set(tracks.next_id),
        valid=tracks.valid.at[slot].set(True),
        mean=tracks.mean.at[slot].set(jnp.concatenate([xy, jnp.zeros((2,), jnp.float32)])),
        cov=tracks.cov.at[slot].set(spawn_cov),
        age=tracks.age.at[slot].set(0.0),
        hits=tracks.hits.at[slot].set(1),
        found=tracks.found.at[slot].set(carried),
        next_id=tracks.next_id + 1,
        ball=tracks.ball.at[slot].set(False),
        static=tracks.static.at[slot].set(False),
        carried=tracks.carried.at[slot].set(int(carried)),
        missed=tracks.missed.at[slot].set(0.0),
        blob=tracks.blob.at[slot].set(blob),
    )
    return jax.tree.map(lambda a, b: jnp.where(born, a, b), new, tracks)


def update_tracks(
    tracks: TrackTable,
    cand_xy: Float[Array, "k 2"],
    observed: Bool[Array, " k"],
    dt,
    ego: Float[Array, "3"],
    params: MemoryParams,
    buffer: Measurements | None = None,
    estimate: Float[Array, "2"] | None = None,
    max_births: int = 1,
    max_blobs: int = 8,
) -> TrackTable:
    """One memory step: predict, associate, update, re-detect, give birth, roles, forget (:mod:`heatpf_jax.memory`).

    Args:
        tracks: the previous table.
        cand_xy: ``[K, 2]`` the filter's candidates (modes, or its estimate).
        observed: ``bool [K]`` those with buffered support (:func:`~heatpf_jax.memory.candidates.observed_support`).
        dt: the step's length, seconds.
        ego: the robot's motion ``(dx, dy, dtheta)`` since the last step.
        params: :class:`~heatpf_jax.memory.params.MemoryParams`.
        buffer: this step's measurements; without it nothing is re-detected and no blob opens a track.
        estimate: ``[2]`` the filter's estimate, which names the ball's track; without it (or where it has
            less than ``memory_min_support`` of buffered weight near it) the flag stays where it is.
        max_births: at most this many blobs no track explains open a track this step.
        max_blobs: blobs looked for in the buffer (:func:`~heatpf_jax.memory.blobs.find_blobs`).

    Returns:
        The new :class:`~heatpf_jax.memory.table.TrackTable` (every field filled).
    """
    tracks = predict_tracks(complete_tracks(tracks), dt, ego, params.memory_accel_std, params.memory_friction,
                            params.memory_lost_accel_std)
    m = tracks.valid.shape[0]
    # Candidates -> tracks, inside the gates only; each track takes at most one candidate.
    track_of = _associate(gate_costs(tracks, cand_xy, params, dt), observed)
    hit = jnp.zeros((m,), bool)
    z_of = jnp.zeros((m, 2), jnp.float32)
    for k in range(cand_xy.shape[0]):
        j = track_of[k]
        take = j >= 0
        jj = jnp.maximum(j, 0)
        hit = jnp.where(take, hit.at[jj].set(True), hit)
        z_of = jnp.where(take, z_of.at[jj].set(cand_xy[k]), z_of)
    found = hit
    blob = tracks.blob
    blobs = None
    if buffer is not None:  # the memory's own detections: a track's blob re-detects it
        blobs = find_blobs(buffer, params, max_blobs)
        again, centroid, weight, j = _redetect(tracks, ~hit, blobs, params, dt)
        z_of = jnp.where(again[:, None], centroid, z_of)
        hit = hit | again
        seen = hit & (j >= 0)
        blob = jnp.where(seen, jnp.where(blob > 0, (1.0 - _BLOB_RATE) * blob + _BLOB_RATE * weight, weight), blob)
    new_mean, new_cov = jax.vmap(_kalman_update, in_axes=(0, 0, 0, None))(
        tracks.mean, tracks.cov, z_of, params.memory_obs_std
    )
    tracks = tracks._replace(
        mean=jnp.where(hit[:, None], new_mean, tracks.mean),
        cov=jnp.where(hit[:, None, None], new_cov, tracks.cov),
        age=jnp.where(hit, 0.0, tracks.age + dt),
        hits=tracks.hits + hit.astype(jnp.int32),
        found=found,
        carried=tracks.carried + found.astype(jnp.int32),
        missed=jnp.where(found, 0.0, tracks.missed + dt),
        blob=blob,
    )
    spawn_cov = _spawn_cov(params)
    # The ages are advanced now: the gates below take T = age for the time since a track was last observed
    # (gate_costs with dt = 0), so a point a lost rolling track cannot have reached is clear of its gate.
    # Births from the filter's candidates outside every gate. A free slot first, else the least useful track
    # (memory-only, static, then unobserved longest); never the ball's, never one observed this step.
    for k in range(cand_xy.shape[0]):
        clear = ~jnp.any(jnp.isfinite(gate_costs(tracks, cand_xy[k][None], params, 0.0)))
        usefulness = tracks.age + params.memory_forget * ((tracks.carried == 0).astype(jnp.float32)
                                                          + tracks.static.astype(jnp.float32))
        priority = jnp.where(tracks.valid, jnp.where(hit | tracks.ball, -jnp.inf, usefulness), jnp.inf)
        slot = jnp.argmax(priority)
        born = observed[k] & (track_of[k] < 0) & clear & (priority[slot] > -jnp.inf)
        hit = hit.at[slot].set(hit[slot] | born)
        tracks = _birth(tracks, slot, cand_xy[k], born, spawn_cov, carried=True)
    # Births from blobs no track explains (a distractor where no track predicts anything), strongest first: into
    # free slots or those of memory-only tracks not observed this step.
    if blobs is not None and max_births > 0:
        unexplained = blobs.valid & (blobs.weight >= params.memory_birth_support) & ~jnp.any(
            jnp.isfinite(gate_costs(tracks, blobs.xy, params, 0.0)), axis=1)
        order = jnp.argsort(-jnp.where(unexplained, blobs.weight, -1.0), stable=True)
        for b in range(min(max_births, max_blobs)):
            i = order[b]
            priority = jnp.where(tracks.valid, jnp.where((tracks.carried > 0) | tracks.ball | hit, -jnp.inf,
                                                         tracks.age), jnp.inf)
            slot = jnp.argmax(priority)
            born = unexplained[i] & (priority[slot] > -jnp.inf)
            hit = hit.at[slot].set(hit[slot] | born)
            tracks = _birth(tracks, slot, blobs.xy[i], born, spawn_cov, carried=False, blob=blobs.weight[i])
    tracks = _roles(tracks, estimate, buffer, params)
    # Forget. The age is a float32 sum of step lengths: twenty steps of 0.1 s make 2.0000002 s, which would drop
    # a track unobserved for exactly memory_forget. A relative tolerance of 1e-4 (0.2 ms at 2 s) absorbs that
    # rounding and is far below any step length.
    keep = tracks.valid & (tracks.age <= params.memory_forget * (1.0 + 1e-4))
    return tracks._replace(
        valid=keep,
        id=jnp.where(keep, tracks.id, 0),
        hits=jnp.where(keep, tracks.hits, 0),
        found=tracks.found & keep,
        ball=tracks.ball & keep,
        static=tracks.static & keep,
        carried=jnp.where(keep, tracks.carried, 0),
    )


def _roles(tracks: TrackTable, estimate, buffer, params: MemoryParams) -> TrackTable:
    """The ball flag and static clutter (step 6 of :mod:`heatpf_jax.memory`)."""
    speed = jnp.sqrt(jnp.sum(tracks.mean[:, 2:] ** 2, axis=1))
    # Static once slower than memory_static_speed, and until faster than twice that (a blob's jitter does not
    # make it move).
    limit = jnp.where(tracks.static, 2.0 * params.memory_static_speed, params.memory_static_speed)
    slow = tracks.valid & (tracks.hits >= params.memory_confirm) & (speed <= limit)
    ball = tracks.ball & tracks.valid
    if estimate is not None:
        estimate = jnp.asarray(estimate, jnp.float32)
        seen = True if buffer is None else (
            observed_support(estimate[None], buffer, params.memory_support_radius)[0] >= params.memory_min_support)
        # The track that carries the estimate: found by the filter this step, the nearest within memory_gate.
        d2 = jnp.sum((tracks.mean[:, :2] - estimate[None]) ** 2, axis=1)
        d2 = jnp.where(tracks.valid & tracks.found & (d2 <= params.memory_gate**2), d2, jnp.inf)
        k = jnp.argmin(d2)
        carrier = seen & jnp.isfinite(d2[k])
        has_ball = jnp.any(ball)
        b = jnp.argmax(ball)
        # The flag moves to a moving track that carries the estimate when the filter has found it on more steps
        # than the ball's, or has not found the ball's for memory_forget (kept alive by the memory's
        # re-detection alone); a static track never takes it from another.
        overtaken = (tracks.carried[k] > tracks.carried[b]) | (tracks.missed[b] > params.memory_forget * (1.0 + 1e-4))
        take = carrier & (~has_ball | ((k != b) & ~slow[k] & overtaken))
        ball = jnp.where(take, jnp.arange(ball.shape[0]) == k, ball)
    return tracks._replace(ball=ball, static=slow & ~ball)
