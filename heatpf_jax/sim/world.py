"""The simulated world: ball paths, robot poses and odometry, visibility, and random on/off events.

Frames: the world frame is the robot's base frame at step 0 (x forward, y left, z up, ground z = 0).
A robot pose is ``(x, y, theta)`` in the world. A world point ``p`` has base coordinates
``R(theta)^T (p - (x, y))``. Odometry from step t-1 to t is ``(dx, dy, dtheta)`` in the base frame
of t-1, so a world-fixed point with base coordinates ``q`` at t-1 has ``R(dtheta)^T (q - (dx, dy))`` at t
(the sequence-file convention). NumPy only.

Ball paths live in :mod:`heatpf_jax.sim.world_paths` and random signals and events in
:mod:`heatpf_jax.sim.world_events`; this module re-exports them.
"""

from __future__ import annotations

import numpy as np

from heatpf_jax.sim.world_events import bursty_mask, random_windows, smooth_signal
from heatpf_jax.sim.world_paths import (
    ball_path,
    fits_in_view,
    lateral_limit,
    meet_apart_path,
    meet_path,
    shot_path,
    slow_down,
    view_path,
)

__all__ = [
    "ball_path",
    "bursty_mask",
    "compose_pose",
    "fits_in_view",
    "integrate_odometry",
    "lateral_limit",
    "meet_apart_path",
    "meet_path",
    "odometry_from_poses",
    "random_windows",
    "shot_path",
    "slow_down",
    "smooth_signal",
    "turn_poses",
    "view_path",
    "walk_poses",
    "world_to_base",
]



# --- Robot poses and odometry -------------------------------------------------------------------------------------


def _rot(theta) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def world_to_base(pose: np.ndarray, points: np.ndarray) -> np.ndarray:
    """World points ``[..., 2]`` in the base frame of ``pose = (x, y, theta)``: ``R(theta)^T (p - (x, y))``."""
    return (np.asarray(points) - pose[:2]) @ _rot(pose[2])


def compose_pose(pose: np.ndarray, odometry: np.ndarray) -> np.ndarray:
    """The pose after a motion ``(dx, dy, dtheta)`` expressed in the base frame of ``pose``."""
    xy = pose[:2] + _rot(pose[2]) @ odometry[:2]
    return np.array([xy[0], xy[1], pose[2] + odometry[2]])


def odometry_from_poses(poses: np.ndarray) -> np.ndarray:
    """Per-step odometry ``[T, 3]`` between consecutive poses ``[T, 3]`` (row 0 zeros)."""
    odom = np.zeros_like(poses)
    for t in range(1, poses.shape[0]):
        d = world_to_base(poses[t - 1], poses[t, :2])
        dth = np.arctan2(np.sin(poses[t, 2] - poses[t - 1, 2]), np.cos(poses[t, 2] - poses[t - 1, 2]))
        odom[t] = (d[0], d[1], dth)
    return odom


def integrate_odometry(odometry: np.ndarray, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Poses ``[T, 3]`` from per-step odometry ``[T, 3]`` (row 0 ignored), starting at ``start``."""
    poses = np.zeros_like(odometry)
    poses[0] = start
    for t in range(1, odometry.shape[0]):
        poses[t] = compose_pose(poses[t - 1], odometry[t])
    return poses


def walk_poses(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    *,
    speed_range=(0.1, 0.3),
    max_sideways: float = 0.05,
    turn_rate_range=(0.2, 0.5),
) -> np.ndarray:
    """A legged robot's smooth walk from the world origin.

    Forward speed varies smoothly within ``speed_range`` (m/s), sideways speed within
    ``+-max_sideways``; the turn rate is a smooth signal (slow left and right turns) whose
    amplitude (its largest magnitude) is drawn from ``turn_rate_range`` (rad/s).

    Returns:
        ``float64 [num_steps, 3]`` poses ``(x, y, theta)`` in the world.
    """
    lo, hi = speed_range
    forward = lo + 0.5 * (smooth_signal(rng, num_steps, dt, freqs=(0.02, 0.1)) + 1.0) * (hi - lo)
    sideways = max_sideways * smooth_signal(rng, num_steps, dt, freqs=(0.02, 0.1))
    amplitude = rng.uniform(*turn_rate_range)
    # Saturated: turns last a while at about the amplitude, then the robot swings to the other side.
    turn = np.tanh(3.0 * smooth_signal(rng, num_steps, dt, freqs=(0.03, 0.1), terms=2))
    turn = amplitude * turn / max(np.abs(turn).max(initial=0.0), 1e-9)
    odom = np.stack([forward * dt, sideways * dt, turn * dt], axis=-1)
    odom[0] = 0.0
    return integrate_odometry(odom)


def turn_poses(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    *,
    max_rate_range=(0.75, 0.95),
    freq_range=(0.15, 0.25),
) -> tuple[np.ndarray, float]:
    """A robot turning in place, left and right: the yaw oscillates with a slowly varying frequency.

    The yaw is ``A (sin psi(t) - sin psi(0))``: it swings about ``-A sin psi(0)`` by ``+-A``; the phase
    ``psi`` advances at a frequency that varies smoothly within ``freq_range`` (Hz), so the turn rate
    changes smoothly and changes sign twice a period. ``A`` makes the largest turn rate between
    consecutive steps equal a draw from ``max_rate_range`` (rad/s), over the run or two periods at the
    lowest frequency, whichever is longer (a shorter run may turn more slowly; ``A`` stays bounded).

    Returns:
        ``(poses, centre)``: ``float64 [num_steps, 3]`` poses ``(0, 0, theta)`` (theta 0 at step 0) and the
        yaw the swing is centred on.
    """
    lo, hi = freq_range
    horizon = max(num_steps, int(np.ceil(2.0 / (lo * dt))))
    freq = lo + 0.5 * (smooth_signal(rng, horizon, dt, freqs=(0.02, 0.08), terms=2) + 1.0) * (hi - lo)
    phase0 = rng.uniform(0.0, 2.0 * np.pi)
    psi = phase0 + 2.0 * np.pi * np.concatenate([[0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1]) * dt)])
    shape = np.sin(psi) - np.sin(phase0)
    rate = np.abs(np.diff(shape)).max(initial=0.0) / dt
    amplitude = rng.uniform(*max_rate_range) / rate
    poses = np.zeros((num_steps, 3))
    poses[:, 2] = amplitude * shape[:num_steps]
    return poses, float(-amplitude * np.sin(phase0))


def localisation_poses(
    rng: np.random.Generator,
    poses: np.ndarray,
    dt: float,
    *,
    jumps_per_minute: float = 4.0,
    jump_seconds=(1.0, 2.5),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A self-localisation's view of ``poses``: a small smooth error, and jumps while its confidence dips.

    Normally the estimate is off by a slowly varying error (std about 2 cm and 0.5 degrees) and its
    confidence is 0.85-0.98. About ``jumps_per_minute`` times a minute it loses track for 1-2.5 s
    (Olufs et al. 3.5: "non explicit poses, like for example during the global localisation"): the
    estimate jumps 0.3-1.0 m and 10-30 degrees away, wanders (5 cm and 2 degrees per step) and jumps
    back at the end, while the confidence is 0.02-0.15.

    Returns:
        ``(estimate [T, 3], confidence [T], lost bool [T])``.
    """
    num_steps = poses.shape[0]
    err = np.stack(
        [0.02 * smooth_signal(rng, num_steps, dt, freqs=(0.05, 0.3)),
         0.02 * smooth_signal(rng, num_steps, dt, freqs=(0.05, 0.3)),
         np.deg2rad(0.5) * smooth_signal(rng, num_steps, dt, freqs=(0.05, 0.3))], axis=1)
    confidence = 0.915 + 0.065 * smooth_signal(rng, num_steps, dt, freqs=(0.05, 0.2))
    lost = np.zeros(num_steps, bool)
    count = max(1, int(round(jumps_per_minute * num_steps * dt / 60.0)))
    lo, hi = (max(1, int(round(s / dt))) for s in jump_seconds)
    for start, stop in random_windows(rng, num_steps, count, (lo, hi), min_gap=int(round(3.0 / dt)),
                                      start_after=int(round(3.0 / dt))):
        length = stop - start
        angle = rng.uniform(0.0, 2.0 * np.pi)
        offset = np.array([np.cos(angle), np.sin(angle)]) * rng.uniform(0.3, 1.0)
        turn = rng.choice([-1.0, 1.0]) * np.deg2rad(rng.uniform(10.0, 30.0))
        wander = np.cumsum(rng.standard_normal((length, 3)) * np.array([0.05, 0.05, np.deg2rad(2.0)]), axis=0)
        err[start:stop] += np.array([offset[0], offset[1], turn]) + wander
        confidence[start:stop] = rng.uniform(0.02, 0.15, length)
        lost[start:stop] = True
    estimate = poses + err
    estimate[:, 2] = np.angle(np.exp(1j * estimate[:, 2]))
    return estimate, np.clip(confidence, 0.0, 1.0), lost
