"""The simulated world: ball paths, robot poses and odometry, visibility, and random on/off events.

Frames: the world frame is the robot's base frame at step 0 (x forward, y left, z up, ground z = 0).
A robot pose is ``(x, y, theta)`` in the world. A world point ``p`` has base coordinates
``R(theta)^T (p - (x, y))``. Odometry from step t-1 to t is ``(dx, dy, dtheta)`` in the base frame
of t-1, so a world-fixed point with base coordinates ``q`` at t-1 has ``R(dtheta)^T (q - (dx, dy))`` at t
(the sequence-file convention). NumPy only.
"""

from __future__ import annotations

import numpy as np

from heatpf_jax.sim.render import project_centre

__all__ = [
    "ball_path",
    "bursty_mask",
    "compose_pose",
    "fits_in_view",
    "integrate_odometry",
    "lateral_limit",
    "odometry_from_poses",
    "random_windows",
    "slow_down",
    "smooth_signal",
    "view_path",
    "walk_poses",
    "world_to_base",
]


# --- Paths ---------------------------------------------------------------------------------------------------------


def ball_path(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    *,
    centre=(2.2, 0.0),
    extent=(1.2, 1.2),
    max_speed: float = 3.0,
) -> np.ndarray:
    """A smooth random path: a sum of three sinusoids per axis, slowed to ``max_speed``.

    Returns:
        ``float64 [num_steps, 2]`` ball positions in a fixed (world = base) frame.
    """
    t = np.arange(num_steps) * dt
    path = np.zeros((num_steps, 2))
    for axis in range(2):
        amps = rng.uniform(0.2, 1.0, 3)
        amps = amps / amps.sum() * extent[axis]
        freqs = rng.uniform(0.05, 0.35, 3)
        phases = rng.uniform(0, 2 * np.pi, 3)
        path[:, axis] = centre[axis] + (amps[:, None] * np.sin(2 * np.pi * freqs[:, None] * t + phases[:, None])).sum(0)
    return slow_down(path, dt, max_speed)


def slow_down(path: np.ndarray, dt: float, max_speed: float) -> np.ndarray:
    """The same curve replayed slower (linear interpolation) so that no step is faster than ``max_speed``."""
    speed = np.linalg.norm(np.diff(path, axis=0), axis=1).max(initial=0.0) / dt
    if speed <= max_speed:
        return path
    factor = speed / max_speed
    n = path.shape[0]
    s = np.arange(n) / factor
    return np.stack([np.interp(s, np.arange(n), path[:, i]) for i in range(path.shape[1])], axis=-1)


def smooth_signal(
    rng: np.random.Generator, num_steps: int, dt: float, *, freqs=(0.05, 0.35), terms: int = 3
) -> np.ndarray:
    """A smooth random signal in ``[-1, 1]``: ``terms`` sinusoids with weights summing to 1.

    Returns:
        ``float64 [num_steps]``.
    """
    t = np.arange(num_steps) * dt
    amps = rng.uniform(0.2, 1.0, terms)
    amps = amps / amps.sum()
    f = rng.uniform(freqs[0], freqs[1], terms)
    phases = rng.uniform(0, 2 * np.pi, terms)
    return (amps[:, None] * np.sin(2 * np.pi * f[:, None] * t + phases[:, None])).sum(0)


def fits_in_view(
    xy: np.ndarray,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    *,
    radius: float,
    margin_px: float = 2.0,
) -> bool:
    """Whether the projected disc of an object of ``radius`` lying at base ``xy`` is wholly inside the image."""
    u, v, depth = project_centre(np.array([xy[0], xy[1], radius]), intrinsics, cam_to_base)
    if depth <= 0.05:
        return False
    r_px = intrinsics[0] * radius / depth + margin_px
    return r_px <= u <= shape[1] - 1 - r_px and r_px <= v <= shape[0] - 1 - r_px


def lateral_limit(
    x: np.ndarray,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    *,
    radius: float,
    margin_px: float = 2.0,
) -> np.ndarray:
    """The largest ``|y|`` at which an object of ``radius`` at forward distance ``x`` is wholly in view.

    For a camera that looks forward (no yaw; small roll): bisection on ``y`` for each ``x``, on both
    sides, keeping the smaller. Zero where the object does not fit at ``y = 0`` (too close or too far).

    Returns:
        ``float64`` array shaped like ``x``.
    """
    x = np.atleast_1d(np.asarray(x, np.float64))

    def fits(xi: float, yi: float) -> bool:
        return fits_in_view(np.array([xi, yi]), intrinsics, cam_to_base, shape, radius=radius, margin_px=margin_px)

    out = np.zeros_like(x)
    for i, xi in enumerate(x):
        if not fits(xi, 0.0):
            continue
        limits = []
        for sign in (1.0, -1.0):
            lo, hi = 0.0, 2.0 * xi + 5.0
            for _ in range(40):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if fits(xi, sign * mid) else (lo, mid)
            limits.append(lo)
        out[i] = min(limits)
    return out


def view_path(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    *,
    x_range: tuple[float, float],
    max_distance: float = np.inf,
    fill: float = 0.8,
    radius: float,
    max_speed: float = 3.0,
    freqs=(0.05, 0.35),
) -> np.ndarray:
    """A smooth random path that keeps a ball wholly inside a forward-looking camera's view.

    Forward distance ``x`` sweeps ``x_range`` with one smooth signal; the lateral position is another
    smooth signal times ``fill`` times the visible half-width at that ``x`` (and at most what keeps
    ``|(x, y)| <= max_distance``). The curve is then slowed to ``max_speed``.

    Returns:
        ``float64 [num_steps, 2]`` positions in the camera's base frame.
    """
    a = smooth_signal(rng, num_steps, dt, freqs=freqs)
    b = smooth_signal(rng, num_steps, dt, freqs=freqs)
    x = x_range[0] + 0.5 * (a + 1.0) * (x_range[1] - x_range[0])
    # The half-width is smooth in x: tabulate it once and interpolate.
    grid = np.linspace(x_range[0], x_range[1], 25)
    half = fill * lateral_limit(grid, intrinsics, cam_to_base, shape, radius=radius)
    half = np.minimum(half, np.sqrt(np.maximum(max_distance**2 - grid**2, 0.0)))
    y = b * np.interp(x, grid, half)
    return slow_down(np.stack([x, y], axis=-1), dt, max_speed)


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


# --- Random events ------------------------------------------------------------------------------------------------


def bursty_mask(rng: np.random.Generator, num_steps: int, on_fraction: float, mean_on_steps: float) -> np.ndarray:
    """A two-state Markov chain: on for bursts of mean length ``mean_on_steps``, on ``on_fraction`` of the time.

    The chain starts from its stationary distribution.

    Returns:
        ``bool [num_steps]``.
    """
    on_fraction = float(np.clip(on_fraction, 1e-3, 1 - 1e-3))
    p_off = 1.0 / max(mean_on_steps, 1.0)  # on -> off
    p_on = min(p_off * on_fraction / (1.0 - on_fraction), 1.0)  # off -> on
    u = rng.uniform(size=num_steps)
    out = np.zeros(num_steps, bool)
    state = u[0] < on_fraction
    for t in range(num_steps):
        if t > 0:
            state = (u[t] >= p_off) if state else (u[t] < p_on)
        out[t] = state
    return out


def random_windows(
    rng: np.random.Generator,
    num_steps: int,
    count: int,
    length_range: tuple[int, int],
    *,
    min_gap: int,
    start_after: int,
) -> list[tuple[int, int]]:
    """Non-overlapping windows ``[start, stop)`` of random integer lengths in ``length_range`` (inclusive).

    Windows start at or after ``start_after``, are separated by at least ``min_gap`` steps and end by
    ``num_steps``; windows that do not fit are dropped (the last ones first).
    """
    lengths = list(rng.integers(length_range[0], length_range[1] + 1, size=count))
    while lengths and start_after + sum(lengths) + min_gap * (len(lengths) - 1) > num_steps:
        lengths.pop()
    if not lengths:
        return []
    slack = num_steps - start_after - sum(lengths) - min_gap * (len(lengths) - 1)
    # Spread the slack at random over the len + 1 gaps (before, between, after).
    cuts = np.sort(rng.integers(0, slack + 1, size=len(lengths)))
    windows, pos, used = [], start_after, 0
    for i, (length, cut) in enumerate(zip(lengths, cuts, strict=True)):
        pos += int(cut) - used + (min_gap if i else 0)
        used = int(cut)
        windows.append((pos, pos + int(length)))
        pos += int(length)
    return windows
