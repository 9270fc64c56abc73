"""The long-term memory (Olufs et al. 3.4): a small fixed-capacity track table fed by the particle filter.

The particle filter is the short-term memory: it loses an occluded ball within a few steps. The
long-term memory keeps *tracks* of what it sees, a hypothesis for every object, not only the ball (a
multiple-hypothesis tracker in the small): ``capacity`` slots, each a Kalman filter over ``(x, y, vx, vy)``
that rolls with friction. One step:

1. **predict** every track by ``dt``: constant velocity slowed by the rolling friction ``memory_friction``
   (m/s^2, the speed falls to 0 and stays; a ball rolls, it does not keep its speed), white-noise
   acceleration ``memory_accel_std`` (``memory_lost_accel_std`` while unobserved: an unseen ball rolls on), and
   the robot's motion (the ego-motion's ``tracks`` part, :mod:`heatpf_jax.ego`);
2. **candidates**: the filter's modes (``Filter.modes``; the estimate when there are none) that are
   *observed*, i.e. have at least ``memory_min_support`` of buffered measurement weight within
   ``memory_support_radius``: a mode of particles with nothing under it is the filter guessing, not seeing.
   The memory observes the centroid of that weight, the blob under the candidate (:func:`observed_blob`), not the
   particles' mean, which passes between two blobs when the filter moves from one to the other;
3. **associate** candidates to tracks within each track's **gate**: at most ``memory_gate`` metres *and*
   ``memory_redetect_sigmas`` Mahalanobis sigmas (``P_xy + memory_obs_std^2 I``) from its *prediction*, most
   likely pairs first (:func:`gate_costs`), and update those tracks (measurement std ``memory_obs_std``); their
   age returns to 0. A track is never moved by anything outside its gate;
4. **re-detect**: the memory finds the blobs of the buffer itself (:func:`find_blobs`, up to ``max_blobs``: a
   pixel's footprint stretches a ball's pixels along the ray) and pairs them with its tracks, most likely pairs
   first, each blob's centroid inside the track's gate; a track no candidate took is re-detected at its blob when
   the blob weighs ``memory_min_support`` and ``memory_redetect_share`` of the track's usual blob (the paper: the
   memory "allows to re-detect vanished objects"). A blob another track explains better (a static distractor's)
   is not the ball's;
5. **birth**: an observed candidate outside every gate opens a track (in a free slot, else in the slot of
   the least useful track, never the ball's), and so does a blob of ``memory_birth_support`` outside every gate
   (at most ``max_births`` a step, only into free slots or the slots of memory-only tracks): a distractor that
   appears where no track predicts anything gets a track of its own at once;
6. **roles**: the **ball** (``TrackTable.ball``) is the track that carried the filter's estimate; it keeps
   the flag through an occlusion (the identity is kept by prediction, not by the nearest blob) and hands
   it over only when it is forgotten, or to a moving track carrying the estimate that the filter has found
   on more steps, or when the filter has not found it for ``memory_forget``. A confirmed track other than
   the ball whose speed stays below ``memory_static_speed`` is **static clutter** (``TrackTable.static``);
7. **forget**: a track unobserved for more than ``memory_forget`` seconds (2 s in the paper) is dropped.

Before the particles are weighted, :meth:`TrackMemory.recall` looks at this step's buffer for the tracks
the filter had lost (predicted to now, re-detected as in step 4): the paper's memory re-detects
vanished objects "using their new position as a new initial position for object tracking", and
:class:`~heatpf_jax.injection_memory.RedetectionSeeds` seeds particles there in the same step, so the
frame on which the ball is seen again already weighs particles on it.

A track is *lost* by the filter when it is confirmed (observed on ``memory_confirm`` steps or more), no
candidate of the filter's was associated to it this step (re-detected or not), and it is the ball or a
track the filter carried that is not static clutter (:func:`lost_tracks`);
:class:`~heatpf_jax.injection_memory.MemoryHints` then injects b hint particles around its position, the
ball's first, spread by the track's own covariance, which grows with its age (the paper: "an older age
will result in a larger spread") and shrinks again when the memory re-detects it.

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
from heatpf_jax.params import integer, nonnegative, positive, unit_interval

__all__ = [
    "MemoryParams",
    "NoMemory",
    "Recall",
    "TrackMemory",
    "TrackTable",
    "candidates_from",
    "Blobs",
    "find_blobs",
    "complete_tracks",
    "empty_tracks",
    "gate_costs",
    "lost_tracks",
    "observed_blob",
    "observed_support",
]


class TrackTable(NamedTuple):
    """The memory's tracks, ``M = capacity`` slots (the state of :class:`TrackMemory`, ``StepInfo.tracks``).

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
        blob: ``float32 [M]`` the weight of the track's blob (:func:`find_blobs`) as usually seen (a running mean
            over the steps it was observed; 0: not known yet): what the object looks like in the heat map.

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


class Recall(NamedTuple):
    """The lost tracks the memory re-detects in this step's buffer, before the filter weighs its particles.

    Attributes:
        redetected: ``bool [M]`` tracks that nothing observed last step (lost by the filter and not
            re-detected by the memory either) and that this step's measurements re-detect: a reappearance.
        xy: ``float32 [M, 2]`` where: the re-detecting measurements' weighted centroid.
        hits: ``int32 [M]`` the tracks' observation counts (how established each is).
        ball: ``bool [M]`` the ball's track (``TrackTable.ball``; ``None``: none known).
    """

    redetected: Bool[Array, " m"]
    xy: Float[Array, "m 2"]
    hits: Int[Array, " m"]
    ball: Bool[Array, " m"] | None = None


class MemoryParams(NamedTuple):
    """Numbers of :class:`TrackMemory`.

    Attributes:
        memory_forget: seconds a track survives unobserved (Olufs et al.: 2 s).
        memory_gate: the gate's largest radius, metres: nothing farther from a track's prediction moves it.
        memory_accel_std: the tracks' white-noise acceleration while they are seen, m/s^2 (kicks the filter
            follows).
        memory_lost_accel_std: the same for a track unobserved since the last step, m/s^2: an unseen ball rolls
            on, so its gate grows slowly and does not reach over the distractors beside its path.
        memory_obs_std: std of a candidate's position, metres.
        memory_spawn_speed_std: prior std of a new track's velocity, m/s.
        memory_min_support: buffered weight near a mode for it to count as observed (and to re-detect a track).
        memory_support_radius: radius of that neighbourhood, metres.
        memory_confirm: observations before a track can be lost (and get hints) or count as static.
        memory_redetect_sigmas: the gate in Mahalanobis sigmas of a track's predicted position
            (``P_xy + memory_obs_std^2 I``), for candidates and re-detection alike.
        memory_friction: the tracks' rolling deceleration, m/s^2 (0: constant velocity).
        memory_static_speed: a confirmed track slower than this (m/s) that is not the ball is static clutter.
        memory_birth_support: buffered weight of a blob outside every gate for the memory to open a track on it.
        memory_blob_radius: radius of a ball-sized blob on the ground, metres: the pixels of one blob spread along
            the ray by its footprint (:func:`find_blobs`).
        memory_redetect_share: the memory re-detects a track on its own only on a blob of at least this share of
            the track's usual blob weight (``TrackTable.blob``).
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
    memory_friction: float = 0.3
    memory_static_speed: float = 0.15
    memory_birth_support: float = 3.0
    memory_blob_radius: float = 0.1
    memory_lost_accel_std: float = 0.5
    memory_redetect_share: float = 0.3


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


def _roll(mean: Float[Array, "m 4"], dt, friction) -> Float[Array, "m 4"]:
    """Rolls every track by ``dt`` with a constant deceleration ``friction`` along its velocity until it stops:
    the speed ``s`` becomes ``max(s - friction dt, 0)`` and the position advances ``s tau - friction tau^2 / 2``
    along the velocity, ``tau = min(dt, s / friction)`` (``friction = 0``: constant velocity)."""
    vel = mean[:, 2:]
    speed = jnp.sqrt(jnp.sum(vel**2, axis=1) + 1e-20)
    unit = vel / speed[:, None]
    tau = jnp.where(friction > 0, jnp.minimum(dt, speed / jnp.maximum(friction, 1e-12)), dt)
    step = speed * tau - 0.5 * friction * tau**2
    new_speed = jnp.maximum(speed - friction * dt, 0.0)
    return jnp.concatenate([mean[:, :2] + unit * step[:, None], unit * new_speed[:, None]], axis=1)


def predict_tracks(
    tracks: TrackTable, dt, ego: Float[Array, "3"], accel_std, friction=0.0, lost_accel_std=None
) -> TrackTable:
    """Rolling prediction by ``dt`` (:func:`_roll`; constant velocity without ``friction``), the covariance
    by the constant-velocity Jacobian plus white-noise acceleration (``accel_std``; ``lost_accel_std`` for the
    tracks unobserved last step, ``age > 0``, where given), then the ego-motion (positions moved, vectors turned).
    """
    f, q = _cv_matrices(dt, accel_std)
    mean = _roll(tracks.mean, dt, friction)
    if lost_accel_std is not None:
        unseen = (tracks.age > 0)[:, None, None]
        q = jnp.where(unseen, (lost_accel_std / accel_std) ** 2 * q[None], q[None])
    else:
        q = q[None]
    cov = jnp.einsum("ij,mjk,lk->mil", f, tracks.cov, f) + q
    r = _rotation(ego[2])
    j = jnp.zeros((4, 4), jnp.float32).at[:2, :2].set(r).at[2:, 2:].set(r)
    xy = apply_odometry(mean[:, :2], ego)
    vel = mean[:, 2:] @ r.T
    cov = jnp.einsum("ij,mjk,lk->mil", j, cov, j)
    return tracks._replace(mean=jnp.concatenate([xy, vel], axis=1), cov=cov)


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


def gate_costs(tracks: TrackTable, xy: Float[Array, "p 2"], params: "MemoryParams") -> Float[Array, "p m"]:
    """The cost of explaining each point by each track: its negative log-likelihood under the track's predicted
    position, ``d^2 / 2 + log det(S) / 2`` with ``d`` the Mahalanobis distance for ``S = P_xy + memory_obs_std^2 I``;
    ``inf`` outside the track's **gate** (farther than ``memory_redetect_sigmas`` sigmas or ``memory_gate`` metres)
    and for empty slots. The gate is where a track may be moved; the cost picks the most likely track among those
    whose gates overlap (a tight static track explains its own blob better than a wide lost one).
    """
    cov = tracks.cov[:, :2, :2] + params.memory_obs_std**2 * jnp.eye(2, dtype=jnp.float32)[None]
    a, b, c = cov[None, :, 0, 0], cov[None, :, 0, 1], cov[None, :, 1, 1]
    det = jnp.maximum(a * c - b * b, 1e-12)
    dx = xy[:, None, 0] - tracks.mean[None, :, 0]
    dy = xy[:, None, 1] - tracks.mean[None, :, 1]
    d2 = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
    inside = (
        tracks.valid[None, :]
        & (d2 <= params.memory_redetect_sigmas**2)
        & (dx * dx + dy * dy <= params.memory_gate**2)
    )
    return jnp.where(inside, 0.5 * d2 + 0.5 * jnp.log(det), jnp.inf)


def _associate(costs: Float[Array, "k m"], cand_ok: Bool[Array, " k"]) -> Int[Array, " k"]:
    """Greedy assignment by increasing cost (finite: inside the gate): ``track_of[k]`` (-1: none) per candidate."""
    d = jnp.where(cand_ok[:, None], costs, jnp.inf)
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


def _kalman_update(mean, cov, z, obs_std):
    h = jnp.zeros((2, 4), jnp.float32).at[0, 0].set(1.0).at[1, 1].set(1.0)
    s = h @ cov @ h.T + obs_std**2 * jnp.eye(2, dtype=jnp.float32)
    gain = jnp.linalg.solve(s, h @ cov).T  # cov h^T s^-1 (s symmetric)
    mean = mean + gain @ (z - h @ mean)
    i_kh = jnp.eye(4, dtype=jnp.float32) - gain @ h
    cov = i_kh @ cov @ i_kh.T + obs_std**2 * gain @ gain.T  # Joseph form: stays symmetric positive
    return mean, cov


def _blob_of_track(tracks: TrackTable, blobs: Blobs, params: "MemoryParams") -> Int[Array, " m"]:
    """Each track's blob (-1: none): blobs and tracks paired most likely first, each blob's centroid inside the
    track's gate (:func:`gate_costs`), each blob and each track at most once."""
    track_of_blob = _associate(gate_costs(tracks, blobs.xy, params), blobs.valid)
    m = tracks.valid.shape[0]
    hits = track_of_blob[:, None] == jnp.arange(m, dtype=jnp.int32)[None, :]
    return jnp.where(jnp.any(hits, axis=0), jnp.argmax(hits, axis=0).astype(jnp.int32), -1)


def redetect(
    tracks: TrackTable,
    lost: Bool[Array, " m"],
    buffer: Measurements,
    params: "MemoryParams",
    max_blobs: int = 8,
) -> tuple[Bool[Array, " m"], Float[Array, "m 2"]]:
    """The memory re-detects lost tracks on its own (Olufs et al.: "the long-term memory allows to re-detect
    vanished objects"): the blobs in ``buffer`` (:func:`find_blobs`) are paired with every track, most likely pairs
    first, each blob's centroid inside the track's gate around its *prediction*; a lost track is re-detected at
    its blob when that blob weighs ``memory_min_support`` and ``memory_redetect_share`` of the track's usual blob
    (``TrackTable.blob``: a speck of clutter is not the ball that was there). A blob outside the gate, or one
    a static distractor's track explains better, never re-detects it, however uncertain the track has grown.

    Returns:
        ``(redetected [M], centroid [M, 2])``.
    """
    again, centroid, _, _ = _redetect(complete_tracks(tracks), lost, find_blobs(buffer, params, max_blobs), params)
    return again, centroid


def _redetect(tracks: TrackTable, lost, blobs: Blobs, params: "MemoryParams"):
    """:func:`redetect` on found blobs; also every track's blob weight ``[M]`` and blob index ``[M]``."""
    j = _blob_of_track(tracks, blobs, params)
    jj = jnp.maximum(j, 0)
    weight = jnp.where(j >= 0, blobs.weight[jj], 0.0)
    centroid = jnp.where((j >= 0)[:, None], blobs.xy[jj], tracks.mean[:, :2])
    enough = weight >= jnp.maximum(params.memory_min_support, params.memory_redetect_share * tracks.blob)
    return lost & tracks.valid & (j >= 0) & enough, centroid, weight, j


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
    """One memory step: predict, associate, update, re-detect, give birth, roles, forget (the module docstring).

    Args:
        tracks: the previous table.
        cand_xy: ``[K, 2]`` the filter's candidates (modes, or its estimate).
        observed: ``bool [K]`` those with buffered support (:func:`observed_support`).
        dt: the step's length, seconds.
        ego: the robot's motion ``(dx, dy, dtheta)`` since the last step.
        params: :class:`MemoryParams`.
        buffer: this step's measurements; without it nothing is re-detected and no blob opens a track.
        estimate: ``[2]`` the filter's estimate, which names the ball's track; without it (or where it has
            less than ``memory_min_support`` of buffered weight near it) the flag stays where it is.
        max_births: at most this many blobs no track explains open a track this step.
        max_blobs: blobs looked for in the buffer (:func:`find_blobs`).

    Returns:
        The new :class:`TrackTable` (every field filled).
    """
    tracks = predict_tracks(complete_tracks(tracks), dt, ego, params.memory_accel_std, params.memory_friction,
                            params.memory_lost_accel_std)
    m = tracks.valid.shape[0]
    # Candidates -> tracks, inside the gates only; each track takes at most one candidate.
    track_of = _associate(gate_costs(tracks, cand_xy, params), observed)
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
        again, centroid, weight, j = _redetect(tracks, ~hit, blobs, params)
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
    # Births from the filter's candidates outside every gate. A free slot first, else the least useful track
    # (memory-only, static, then unobserved longest); never the ball's, never one observed this step.
    for k in range(cand_xy.shape[0]):
        clear = ~jnp.any(jnp.isfinite(gate_costs(tracks, cand_xy[k][None], params)))
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
            jnp.isfinite(gate_costs(tracks, blobs.xy, params)), axis=1)
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
    """The ball flag and static clutter (step 6 of the module docstring)."""
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
        return Recall(jnp.zeros((0,), bool), jnp.zeros((0, 2), jnp.float32), jnp.zeros((0,), jnp.int32),
                      jnp.zeros((0,), bool))


@dataclass(frozen=True)
class TrackMemory:
    """The long-term memory of Olufs et al. (3.4) with ``capacity`` track slots (see the module docstring).

    Attributes:
        capacity: track slots.
        max_births: blobs no track explains that may open a track each step (0: tracks come from the filter's
            candidates only).
        max_blobs: blobs the memory looks for in each buffer (:func:`find_blobs`), strongest first.
    """

    capacity: int = 4
    max_births: int = 1
    max_blobs: int = 8

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
            memory_friction=nonnegative(),
            memory_static_speed=positive(trainable=False),
            memory_birth_support=positive(trainable=False),
            memory_blob_radius=positive(trainable=False),
            memory_lost_accel_std=positive(),
            memory_redetect_share=unit_interval(trainable=False),
        )

    def validate(self) -> None:
        c = self.capacity
        if not isinstance(c, int) or isinstance(c, bool) or c < 1:
            raise ValueError(f"max_tracks: must be a positive integer, got {c!r}")
        for name in ("max_births", "max_blobs"):
            b = getattr(self, name)
            if not isinstance(b, int) or isinstance(b, bool) or b < 0:
                raise ValueError(f"{name}: must be a non-negative integer, got {b!r}")

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
        support, centre = observed_blob(cand_xy, buffer, params.memory_support_radius)
        observed = cand_valid & (support >= params.memory_min_support)
        # What the memory observes is the blob under a candidate, not the particles' mean: a cloud on its way
        # from a vanished ball to a distractor is on the distractor's blob, or on none.
        cand_xy = jnp.where(observed[:, None], centre, cand_xy)
        return update_tracks(tracks, cand_xy, observed, jnp.asarray(dt, jnp.float32), ego, params, buffer,
                             estimate=estimate_mean, max_births=self.max_births, max_blobs=self.max_blobs)

    def lost(self, tracks: TrackTable, params: MemoryParams) -> Bool[Array, " m"]:
        """The tracks the filter has lost this step (they get hints)."""
        return lost_tracks(tracks, params.memory_confirm)

    def recall(
        self, tracks: TrackTable, buffer: Measurements, ego: Float[Array, "3"], dt, params: MemoryParams
    ) -> Recall:
        """The tracks lost at the end of the previous step (``tracks``), predicted by ``dt`` and ``ego``, that
        :func:`redetect` finds in this step's ``buffer`` (the state is not changed: :meth:`update` does that)."""
        tracks = complete_tracks(tracks)
        lost = lost_tracks(tracks, params.memory_confirm) & (tracks.age > 0)  # unseen last step, by anyone
        predicted = predict_tracks(tracks, jnp.asarray(dt, jnp.float32), ego, params.memory_accel_std,
                                   params.memory_friction, params.memory_lost_accel_std)
        again, centroid = redetect(predicted, lost, buffer, params, self.max_blobs)
        return Recall(redetected=again, xy=centroid, hits=tracks.hits, ball=tracks.ball)
