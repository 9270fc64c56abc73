"""The long-term memory's gates (Olufs et al. 3.4): where a track may be moved, and the most likely pairs.

:func:`gate_costs` is the cost of explaining each point by each track, infinite outside the track's gate; points
(the filter's candidates, the memory's blobs) and tracks are paired most likely first by a greedy assignment.
A lost track that rolls takes only a point its roll can reach (:func:`motion_consistent`).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.table import TrackTable

__all__ = ["gate_costs", "motion_consistent"]


def motion_consistent(
    tracks: TrackTable, xy: Float[Array, "p 2"], params: "MemoryParams", dt
) -> Bool[Array, "p m"]:
    """Whether each point is a position each track's roll can have reached (``True`` where the test does not apply).

    A lost ball rolls on in a straight line and only slows down: it does not roll back, nor turn. The Gaussian
    gate of :func:`gate_costs` cannot say so: the white-noise acceleration of an unobserved track
    (``memory_lost_accel_std``) grows its position covariance alike in every direction, so after a second or two
    its gate reaches blobs behind the place where the ball vanished (a distractor, the occluder's side) and beside
    its path. This test applies to the tracks that are *lost and moving*: unobserved since before this step
    (``age > 0``), confirmed (``hits >= memory_confirm``), not static clutter, and predicted to roll faster than
    ``memory_static_speed``. Such a track was last observed ``T = age + dt`` seconds ago at (the rolling model of
    :mod:`~heatpf_jax.memory.predict` run backwards along its unit velocity ``u``)

        ``p0 = p - u (s T + memory_friction T^2 / 2)``,

    ``p`` and ``s`` its predicted position and speed. A point ``z`` with ``z - p0 = a u + b u_perp`` is
    consistent with the roll when it lies in the cone of half-angle ``memory_lost_turn`` around ``u`` from ``p0``,
    widened by ``m = memory_redetect_sigmas sqrt(2) memory_obs_std`` (``p0`` and ``z`` are both observations of std
    ``memory_obs_std``):

    * not behind ``p0``: ``a >= -m``, and
    * near the line of the roll: ``|b| <= m + tan(memory_lost_turn) max(a, 0)`` (``memory_lost_turn >= pi / 2``:
      any direction ahead; the ball only cannot have rolled back).

    How far along its line the ball got (it may roll slower or faster than predicted) is left to the Gaussian gate.

    Args:
        tracks: the tracks, predicted to now (``age`` not yet advanced by this step).
        xy: ``[P, 2]`` points (candidates or blobs).
        params: :class:`~heatpf_jax.memory.params.MemoryParams`.
        dt: the step's length, seconds (``T = age + dt``).

    Returns:
        ``bool [P, M]``.
    """
    vel = tracks.mean[:, 2:]
    speed = jnp.sqrt(jnp.sum(vel**2, axis=1))
    unit = vel / jnp.maximum(speed, 1e-12)[:, None]
    static = jnp.zeros_like(tracks.valid) if tracks.static is None else tracks.static
    lost = (tracks.valid & (tracks.age > 0) & (tracks.hits >= params.memory_confirm) & ~static
            & (speed > params.memory_static_speed))
    t = tracks.age + dt
    p0 = tracks.mean[:, :2] - unit * (speed * t + 0.5 * params.memory_friction * t * t)[:, None]
    w = xy[:, None, :] - p0[None]
    a = jnp.sum(w * unit[None], axis=-1)
    b = jnp.abs(w[..., 0] * unit[None, :, 1] - w[..., 1] * unit[None, :, 0])
    m = params.memory_redetect_sigmas * jnp.sqrt(2.0 * params.memory_obs_std**2)
    # |b| <= m + tan(turn) max(a, 0), as cos(turn) (|b| - m) <= sin(turn) max(a, 0) (no tan at pi / 2).
    cos, sin = jnp.maximum(jnp.cos(params.memory_lost_turn), 0.0), jnp.sin(params.memory_lost_turn)
    on_line = (b <= m) | (cos * (b - m) <= sin * jnp.maximum(a, 0.0))
    return ~lost[None, :] | ((a >= -m) & on_line)


def gate_costs(
    tracks: TrackTable, xy: Float[Array, "p 2"], params: "MemoryParams", dt=None
) -> Float[Array, "p m"]:
    """The cost of explaining each point by each track: its negative log-likelihood under the track's predicted
    position, ``d^2 / 2 + log det(S) / 2`` with ``d`` the Mahalanobis distance for ``S = P_xy + memory_obs_std^2 I``;
    ``inf`` outside the track's **gate** (farther than ``memory_redetect_sigmas`` sigmas or ``memory_gate`` metres,
    or, given the step's length ``dt``, a point a lost rolling track cannot have reached: :func:`motion_consistent`)
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
    if dt is not None:
        inside = inside & motion_consistent(tracks, xy, params, dt)
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
