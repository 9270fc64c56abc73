"""The long-term memory (Olufs et al. 3.4): a small fixed-capacity track table fed by the particle filter.

The particle filter is the short-term memory: it loses an occluded ball within a few steps. The
long-term memory keeps *tracks* of what the filter has seen: a multiple-hypothesis tracker in the
small, with ``capacity`` slots, each a constant-velocity Kalman filter over ``(x, y, vx, vy)``:

1. **predict** every track by ``dt`` (white-noise acceleration ``memory_accel_std``) and move it with the
   robot (the ego-motion's ``tracks`` part, rotation and translation, :mod:`heatpf_jax.ego`);
2. **candidates**: the filter's modes (``Filter.modes``; the estimate when there are none) that are
   *observed*, i.e. have at least ``memory_min_support`` of buffered measurement weight within
   ``memory_support_radius``: a mode of particles with nothing under it is the filter guessing, not seeing;
3. **associate** candidates to tracks greedily by distance within the gate ``memory_gate`` (metres) and
   update those tracks (measurement std ``memory_obs_std``); their age returns to 0;
4. **re-detect**: a confirmed track no candidate took looks for buffered measurements near its prediction
   itself (:func:`redetect`; the paper: the memory "allows to re-detect vanished objects");
5. **birth**: an observed candidate far (beyond the gate) from every track opens a track in a free slot
   (or in the oldest one's);
6. **forget**: a track unobserved for more than ``memory_forget`` seconds (2 s in the paper) is dropped.

Before the particles are weighted, :meth:`TrackMemory.recall` looks at this step's buffer for the tracks
the filter had lost (predicted to now, re-detected as in step 4): the paper's memory re-detects
vanished objects "using their new position as a new initial position for object tracking", and
:class:`~heatpf_jax.injection_memory.RedetectionSeeds` seeds particles there in the same step, so the
frame on which the ball is seen again already weighs particles on it.

A track is *lost* by the filter when it is confirmed (observed on ``memory_confirm`` steps or more) and
no candidate of the filter's was associated to it this step (re-detected or not);
:class:`~heatpf_jax.injection_memory.MemoryHints` then injects b hint particles around its position,
spread by the track's own covariance, which grows with its age (the paper: "an older age will result in
a larger spread") and shrinks again when the memory re-detects it.

Everything has fixed sizes (``capacity`` tracks, ``K`` candidates) and is jittable and vmappable.
:class:`NoMemory` is the default: a table of capacity 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.buffers import NoParams
from heatpf_jax.measurements import Measurements
from heatpf_jax.motion import apply_odometry
from heatpf_jax.params import integer, positive

__all__ = [
    "MemoryParams",
    "NoMemory",
    "Recall",
    "TrackMemory",
    "TrackTable",
    "candidates_from",
    "empty_tracks",
    "lost_tracks",
    "observed_support",
]


class TrackTable(NamedTuple):
    """The memory's tracks, ``M = capacity`` slots (the state of :class:`TrackMemory`, ``StepInfo.tracks``).

    Attributes:
        id: ``int32 [M]`` track identifiers (1, 2, ...; 0 in empty slots).
        valid: ``bool [M]`` slots holding a track.
        mean: ``float32 [M, 4]`` ``(x, y, vx, vy)`` in the current base frame (metres, m/s).
        cov: ``float32 [M, 4, 4]`` its covariance.
        age: ``float32 [M]`` seconds since the track was last observed (0: observed this step).
        hits: ``int32 [M]`` steps on which it was observed.
        found: ``bool [M]`` observed this step by the filter (a candidate was associated to it); a track
            the memory re-detected on its own is not found.
        next_id: ``int32 []`` the next identifier to hand out.
    """

    id: Int[Array, " m"]
    valid: Bool[Array, " m"]
    mean: Float[Array, "m 4"]
    cov: Float[Array, "m 4 4"]
    age: Float[Array, " m"]
    hits: Int[Array, " m"]
    found: Bool[Array, " m"]
    next_id: Int[Array, ""]


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
    )


def lost_tracks(tracks: TrackTable, confirm: Int[Array, ""] | int) -> Bool[Array, " m"]:
    """Tracks the filter has lost: confirmed (``hits >= confirm``) and not found by the filter this step."""
    return tracks.valid & (tracks.hits >= confirm) & ~tracks.found


def observed_support(
    xy: Float[Array, "k 2"], buffer: Measurements, radius: Float[Array, ""]
) -> Float[Array, " k"]:
    """Buffered measurement weight within ``radius`` of each point: how much the filter *sees* there."""
    d2 = jnp.sum((xy[:, None, :] - buffer.xy[None, :, :]) ** 2, axis=-1)
    near = (d2 <= radius**2) & buffer.valid[None, :]
    return jnp.sum(jnp.where(near, buffer.weight[None, :], 0.0), axis=1)


def candidates_from(modes, estimate_mean: Float[Array, "2"]) -> tuple[Float[Array, "k 2"], Bool[Array, " k"]]:
    """The memory's candidate positions: the valid modes, or the estimate alone when there are no modes."""
    if modes.mean.shape[0] == 0:
        return jnp.asarray(estimate_mean, jnp.float32)[None, :], jnp.ones((1,), bool)
    return modes.mean, modes.valid


class Recall(NamedTuple):
    """The lost tracks the memory re-detects in this step's buffer, before the filter weighs its particles.

    Attributes:
        redetected: ``bool [M]`` tracks that nothing observed last step (lost by the filter and not
            re-detected by the memory either) and that this step's measurements re-detect: a reappearance.
        xy: ``float32 [M, 2]`` where: the re-detecting measurements' weighted centroid.
        hits: ``int32 [M]`` the tracks' observation counts (how established each is).
    """

    redetected: Bool[Array, " m"]
    xy: Float[Array, "m 2"]
    hits: Int[Array, " m"]


class MemoryParams(NamedTuple):
    """Numbers of :class:`TrackMemory`.

    Attributes:
        memory_forget: seconds a track survives unobserved (Olufs et al.: 2 s).
        memory_gate: association gate, metres.
        memory_accel_std: the tracks' white-noise acceleration, m/s^2.
        memory_obs_std: std of a candidate's position, metres.
        memory_spawn_speed_std: prior std of a new track's velocity, m/s.
        memory_min_support: buffered weight near a mode for it to count as observed.
        memory_support_radius: radius of that neighbourhood, metres.
        memory_confirm: observations before a track can be lost (and get hints).
        memory_redetect_sigmas: Mahalanobis radius in which the memory re-detects a lost track itself.
    """

    memory_forget: float = 2.0
    memory_gate: float = 0.75
    memory_accel_std: float = 2.0
    memory_obs_std: float = 0.1
    memory_spawn_speed_std: float = 1.0
    memory_min_support: float = 1.0
    memory_support_radius: float = 0.3
    memory_confirm: int = 3
    memory_redetect_sigmas: float = 3.0


def _cv_matrices(dt, accel_std):
    f = jnp.eye(4, dtype=jnp.float32).at[0, 2].set(dt).at[1, 3].set(dt)
    g = jnp.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]], jnp.float32) * jnp.array(
        [[dt * dt], [dt * dt], [dt], [dt]], jnp.float32
    )
    q = accel_std**2 * (g @ g.T)
    return f, q


def _rotation(theta):
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, s], [-s, c]], jnp.float32)  # R(theta)^T: the previous frame's vectors in the new one


def predict_tracks(tracks: TrackTable, dt, ego: Float[Array, "3"], accel_std) -> TrackTable:
    """Constant-velocity prediction by ``dt``, then the ego-motion (positions moved, vectors turned)."""
    f, q = _cv_matrices(dt, accel_std)
    mean = tracks.mean @ f.T
    cov = jnp.einsum("ij,mjk,lk->mil", f, tracks.cov, f) + q[None]
    r = _rotation(ego[2])
    j = jnp.zeros((4, 4), jnp.float32).at[:2, :2].set(r).at[2:, 2:].set(r)
    xy = apply_odometry(mean[:, :2], ego)
    vel = mean[:, 2:] @ r.T
    cov = jnp.einsum("ij,mjk,lk->mil", j, cov, j)
    return tracks._replace(mean=jnp.concatenate([xy, vel], axis=1), cov=cov)


def _associate(track_xy, track_valid, cand_xy, cand_ok, gate):
    """Greedy nearest-pair assignment within ``gate``: ``track_of[k]`` (-1: none) for every candidate."""
    d = jnp.sqrt(jnp.sum((cand_xy[:, None, :] - track_xy[None, :, :]) ** 2, axis=-1) + 1e-12)
    d = jnp.where(cand_ok[:, None] & track_valid[None, :] & (d <= gate), d, jnp.inf)
    k_count, m = d.shape
    track_of = jnp.full((k_count,), -1, jnp.int32)
    for _ in range(min(k_count, m)):  # static and small
        flat = jnp.argmin(d)
        best = d.reshape(-1)[flat]
        i, j = flat // m, flat % m
        ok = jnp.isfinite(best)
        track_of = jnp.where(ok, track_of.at[i].set(j.astype(jnp.int32)), track_of)
        d = jnp.where(ok, d.at[i, :].set(jnp.inf).at[:, j].set(jnp.inf), d)
    return track_of


def _kalman_update(mean, cov, z, obs_std):
    h = jnp.zeros((2, 4), jnp.float32).at[0, 0].set(1.0).at[1, 1].set(1.0)
    s = h @ cov @ h.T + obs_std**2 * jnp.eye(2, dtype=jnp.float32)
    gain = jnp.linalg.solve(s, h @ cov).T  # cov h^T s^-1 (s symmetric)
    mean = mean + gain @ (z - h @ mean)
    i_kh = jnp.eye(4, dtype=jnp.float32) - gain @ h
    cov = i_kh @ cov @ i_kh.T + obs_std**2 * gain @ gain.T  # Joseph form: stays symmetric positive
    return mean, cov


def redetect(
    tracks: TrackTable, lost: Bool[Array, " m"], buffer: Measurements, params: "MemoryParams"
) -> tuple[Bool[Array, " m"], Float[Array, "m 2"]]:
    """The memory re-detects lost tracks on its own (Olufs et al.: "the long-term memory allows to re-detect
    vanished objects"): buffered measurements within ``memory_redetect_sigmas`` Mahalanobis distance of a
    lost track's predicted position (covariance ``P_xy + memory_obs_std^2 I``) with a summed weight of
    at least ``memory_min_support`` re-detect it at their weighted centroid.

    Returns:
        ``(redetected [M], centroid [M, 2])``.
    """
    cov = tracks.cov[:, :2, :2] + params.memory_obs_std**2 * jnp.eye(2, dtype=jnp.float32)[None]
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = jnp.maximum(a * c - b * b, 1e-12)
    dx = buffer.xy[None, :, 0] - tracks.mean[:, None, 0]
    dy = buffer.xy[None, :, 1] - tracks.mean[:, None, 1]
    d2 = (c[:, None] * dx * dx - 2.0 * b[:, None] * dx * dy + a[:, None] * dy * dy) / det[:, None]
    near = (d2 <= params.memory_redetect_sigmas**2) & buffer.valid[None, :] & lost[:, None]
    w = jnp.where(near, buffer.weight[None, :], 0.0)
    support = jnp.sum(w, axis=1)
    centroid = (w @ buffer.xy) / jnp.where(support > 0, support, 1.0)[:, None]
    return lost & (support >= params.memory_min_support), centroid


def update_tracks(
    tracks: TrackTable,
    cand_xy: Float[Array, "k 2"],
    observed: Bool[Array, " k"],
    dt,
    ego: Float[Array, "3"],
    params: MemoryParams,
    buffer: Measurements | None = None,
) -> TrackTable:
    """One memory step: predict, associate, update, re-detect, give birth, forget (see the module docstring).

    Without a ``buffer`` nothing is re-detected.
    """
    tracks = predict_tracks(tracks, dt, ego, params.memory_accel_std)
    track_of = _associate(tracks.mean[:, :2], tracks.valid, cand_xy, observed, params.memory_gate)
    m = tracks.valid.shape[0]
    # Updates: each track takes at most one candidate.
    hit = jnp.zeros((m,), bool)
    z_of = jnp.zeros((m, 2), jnp.float32)
    for k in range(cand_xy.shape[0]):
        j = track_of[k]
        take = j >= 0
        jj = jnp.maximum(j, 0)
        hit = jnp.where(take, hit.at[jj].set(True), hit)
        z_of = jnp.where(take, z_of.at[jj].set(cand_xy[k]), z_of)
    found = hit
    if buffer is not None:
        again, centroid = redetect(tracks, tracks.valid & ~hit & (tracks.hits >= params.memory_confirm), buffer, params)
        z_of = jnp.where(again[:, None], centroid, z_of)
        hit = hit | again
    new_mean, new_cov = jax.vmap(_kalman_update, in_axes=(0, 0, 0, None))(
        tracks.mean, tracks.cov, z_of, params.memory_obs_std
    )
    mean = jnp.where(hit[:, None], new_mean, tracks.mean)
    cov = jnp.where(hit[:, None, None], new_cov, tracks.cov)
    age = jnp.where(hit, 0.0, tracks.age + dt)
    hits = tracks.hits + hit.astype(jnp.int32)
    tracks = tracks._replace(mean=mean, cov=cov, age=age, hits=hits, found=found)
    # Births: observed candidates that no track took and that lie outside every track's gate.
    spawn_cov = jnp.diag(
        jnp.stack([params.memory_obs_std**2, params.memory_obs_std**2,
                   params.memory_spawn_speed_std**2, params.memory_spawn_speed_std**2])
    ).astype(jnp.float32)
    for k in range(cand_xy.shape[0]):
        d = jnp.sqrt(jnp.sum((tracks.mean[:, :2] - cand_xy[k][None, :]) ** 2, axis=-1) + 1e-12)
        clear = ~jnp.any(tracks.valid & (d <= params.memory_gate))
        # A free slot first, else the one unobserved longest; never one observed this step.
        priority = jnp.where(tracks.valid, jnp.where(hit, -jnp.inf, tracks.age), jnp.inf)
        slot = jnp.argmax(priority)
        born = observed[k] & (track_of[k] < 0) & clear & (priority[slot] > -jnp.inf)
        hit = hit.at[slot].set(hit[slot] | born)
        new = TrackTable(
            id=tracks.id.at[slot].set(tracks.next_id),
            valid=tracks.valid.at[slot].set(True),
            mean=tracks.mean.at[slot].set(jnp.concatenate([cand_xy[k], jnp.zeros((2,), jnp.float32)])),
            cov=tracks.cov.at[slot].set(spawn_cov),
            age=tracks.age.at[slot].set(0.0),
            hits=tracks.hits.at[slot].set(1),
            found=tracks.found.at[slot].set(True),
            next_id=tracks.next_id + 1,
        )
        tracks = jax.tree.map(lambda a, b, born=born: jnp.where(born, a, b), new, tracks)
    # Forget. The age is a float32 sum of step lengths: twenty steps of 0.1 s make 2.0000002 s, which would drop
    # a track unobserved for exactly memory_forget. A relative tolerance of 1e-4 (0.2 ms at 2 s) absorbs that
    # rounding and is far below any step length.
    keep = tracks.valid & (tracks.age <= params.memory_forget * (1.0 + 1e-4))
    return tracks._replace(
        valid=keep,
        id=jnp.where(keep, tracks.id, 0),
        hits=jnp.where(keep, tracks.hits, 0),
        found=tracks.found & keep,
    )


@dataclass(frozen=True)
class NoMemory:
    """No long-term memory (the default): a track table of capacity 0."""

    capacity: int = 0

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def validate(self) -> None:
        pass

    def init(self) -> TrackTable:
        return empty_tracks(0)

    def update(self, tracks, modes, estimate_mean, buffer, ego, dt, params) -> TrackTable:
        return tracks

    def lost(self, tracks: TrackTable, params) -> Bool[Array, " m"]:
        return tracks.valid

    def recall(self, tracks, buffer, ego, dt, params) -> Recall:
        return Recall(jnp.zeros((0,), bool), jnp.zeros((0, 2), jnp.float32), jnp.zeros((0,), jnp.int32))


@dataclass(frozen=True)
class TrackMemory:
    """The long-term memory of Olufs et al. (3.4) with ``capacity`` track slots (see the module docstring)."""

    capacity: int = 4

    def default_params(self) -> MemoryParams:
        return MemoryParams()

    def properties(self) -> MemoryParams:
        return MemoryParams(
            memory_forget=positive(),
            memory_gate=positive(),
            memory_accel_std=positive(),
            memory_obs_std=positive(),
            memory_spawn_speed_std=positive(),
            memory_min_support=positive(trainable=False),
            memory_support_radius=positive(trainable=False),
            memory_confirm=integer(1, 1000),
            memory_redetect_sigmas=positive(trainable=False),
        )

    def validate(self) -> None:
        c = self.capacity
        if not isinstance(c, int) or isinstance(c, bool) or c < 1:
            raise ValueError(f"max_tracks: must be a positive integer, got {c!r}")

    def init(self) -> TrackTable:
        return empty_tracks(self.capacity)

    def update(
        self,
        tracks: TrackTable,
        modes,
        estimate_mean: Float[Array, "2"],
        buffer: Measurements,
        ego: Float[Array, "3"],
        dt,
        params: MemoryParams,
    ) -> TrackTable:
        """One step of the memory from this step's modes (or estimate), buffer and ego-motion."""
        cand_xy, cand_valid = candidates_from(modes, estimate_mean)
        support = observed_support(cand_xy, buffer, params.memory_support_radius)
        observed = cand_valid & (support >= params.memory_min_support)
        return update_tracks(tracks, cand_xy, observed, jnp.asarray(dt, jnp.float32), ego, params, buffer)

    def lost(self, tracks: TrackTable, params: MemoryParams) -> Bool[Array, " m"]:
        """The tracks the filter has lost this step (they get hints)."""
        return lost_tracks(tracks, params.memory_confirm)

    def recall(
        self, tracks: TrackTable, buffer: Measurements, ego: Float[Array, "3"], dt, params: MemoryParams
    ) -> Recall:
        """The tracks lost at the end of the previous step (``tracks``), predicted by ``dt`` and ``ego``, that
        :func:`redetect` finds in this step's ``buffer`` (the state is not changed: :meth:`update` does that)."""
        lost = lost_tracks(tracks, params.memory_confirm) & (tracks.age > 0)  # unseen last step, by anyone
        predicted = predict_tracks(tracks, jnp.asarray(dt, jnp.float32), ego, params.memory_accel_std)
        again, centroid = redetect(predicted, lost, buffer, params)
        return Recall(redetected=again, xy=centroid, hits=tracks.hits)
