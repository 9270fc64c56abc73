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


def meet_path(
    path_a: np.ndarray,
    path_b: np.ndarray,
    dt: float,
    steps: np.ndarray,
    offsets: np.ndarray,
    *,
    max_added_speed: float = 1.3,
    min_width: float = 0.5,
) -> np.ndarray:
    """Path ``b`` bent so that it passes ``path_a[steps[k]] + offsets[k]`` at step ``steps[k]``.

    Each meeting adds a Gaussian bump in time, ``w_k(t) * shift_k``, to ``b``: at the meeting ``b`` keeps its
    own velocity (the bump is flat there), so the balls cross rather than follow each other. The bump's
    width (std, seconds) is ``max(min_width, 0.61 |shift_k| / max_added_speed)``, so one bump adds at most
    ``max_added_speed`` to ``b``'s speed (the Gaussian's steepest slope is ``0.61 / std``). The shifts
    solve the small linear system of all bumps, so the meetings are exact when bumps overlap.

    Args:
        path_a: ``[T, 2]`` the path met.
        path_b: ``[T, 2]`` the path bent.
        dt: step, seconds.
        steps: ``int [K]`` meeting steps.
        offsets: ``[K, 2]`` ``b - a`` at the meetings.

    Returns:
        ``float64 [T, 2]`` the bent path ``b``.
    """
    steps = np.asarray(steps, np.int64)
    if steps.size == 0:
        return path_b.copy()
    t = np.arange(path_b.shape[0]) * dt
    target = path_a[steps] + offsets
    shift = target - path_b[steps]
    width = np.maximum(min_width, 0.61 * np.linalg.norm(shift, axis=1) / max_added_speed)
    for _ in range(3):  # the widths depend on the shifts: settle both
        bumps = np.exp(-0.5 * ((t[:, None] - t[steps][None]) / width[None]) ** 2)  # [T, K]
        shift = np.linalg.solve(bumps[steps], target - path_b[steps])
        width = np.maximum(min_width, 0.61 * np.linalg.norm(shift, axis=1) / max_added_speed)
    bumps = np.exp(-0.5 * ((t[:, None] - t[steps][None]) / width[None]) ** 2)
    shift = np.linalg.solve(bumps[steps], target - path_b[steps])
    return path_b + bumps @ shift


def _across(path_a: np.ndarray, path_b: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Unit vectors across the relative motion of ``b`` and ``a`` at ``steps``, on the side where ``b`` is."""
    rel = np.gradient(path_b, axis=0)[steps] - np.gradient(path_a, axis=0)[steps] if len(path_a) > 1 else None
    if rel is None:
        return np.tile([0.0, 1.0], (len(steps), 1))
    across = np.stack([-rel[:, 1], rel[:, 0]], axis=-1)
    across /= np.maximum(np.linalg.norm(across, axis=1), 1e-12)[:, None]
    side = np.sign(np.einsum("kd,kd->k", path_b[steps] - path_a[steps], across))
    return across * np.where(side == 0.0, 1.0, side)[:, None]


def meet_apart_path(
    path_a: np.ndarray,
    path_b: np.ndarray,
    dt: float,
    steps: np.ndarray,
    distances: np.ndarray,
    *,
    min_distance: float,
    max_rounds: int = 20,
) -> tuple[np.ndarray, np.ndarray]:
    """Path ``b`` bent (:func:`meet_path`) to pass ``distances[k]`` from ``a`` near ``steps[k]``, never closer
    than ``min_distance`` (two balls cannot overlap).

    The offsets lie across the relative motion (so a meeting is about the closest approach), on the side
    where ``b`` already is. Then, round by round, each stretch where the bent paths come closer than
    ``min_distance`` gets a constraint of its own at its closest step (``min_distance + 0.05`` apart); a
    constraint within 0.3 s of an earlier one replaces it (a meeting keeps its distance). Stops when the
    paths keep apart or after ``max_rounds``.

    Returns:
        ``(b, steps)``: ``float64 [T, 2]`` the bent path and ``int64 [K']`` the steps of the meetings as
        finally placed (each meeting moved at most by the rounds that replaced it).
    """
    steps = np.asarray(steps, np.int64).copy()
    dist = np.asarray(distances, np.float64).copy()
    is_meeting = np.ones(len(steps), bool)
    window = int(round(0.3 / dt))
    b = meet_path(path_a, path_b, dt, steps, _across(path_a, path_b, steps) * dist[:, None])
    for _ in range(max_rounds):
        gap = np.linalg.norm(b - path_a, axis=1)
        close = gap < min_distance
        if not close.any():
            break
        edges = np.diff(np.r_[0, close.astype(int), 0])
        for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
            worst = start + int(np.argmin(gap[start:stop]))
            near = np.flatnonzero(np.abs(steps - worst) <= window)
            if near.size:
                steps[near[0]] = worst
                dist[near[0]] = max(dist[near[0]], min_distance + 0.05)
            else:
                steps, dist = np.r_[steps, worst], np.r_[dist, min_distance + 0.05]
                is_meeting = np.r_[is_meeting, False]
        keep = np.unique(steps, return_index=True)[1]
        steps, dist, is_meeting = steps[keep], dist[keep], is_meeting[keep]
        # Offsets from the current bent path: its relative motion is what the new bumps must cross.
        b = meet_path(path_a, path_b, dt, steps, _across(path_a, b, steps) * dist[:, None])
    return b, steps[is_meeting]


def shot_path(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    *,
    start: tuple[float, float],
    goal_x: float,
    num_shots: int,
    shot_speed=(5.0, 8.0),
    friction=(0.5, 1.0),
    restitution=(0.4, 0.7),
    angle=(np.deg2rad(3.0), np.deg2rad(10.0)),
    dribble_speed=(0.8, 1.2),
    substeps: int = 50,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ball shot at a wall (a goal) again and again: kick, roll, bounce, roll back, trap, dribble back.

    The ball is first dribbled to a start spot near ``start``; it waits there 0.5-1.5 s and is kicked at
    ``shot_speed`` (m/s, drawn per shot) in a direction ``angle`` (radians, drawn per shot, either side)
    off the x axis. It rolls with a constant deceleration ``friction`` (m/s^2, drawn once), bounces off
    the goal line ``x = goal_x`` (the x component of its velocity reversed and scaled by ``restitution``,
    drawn per shot; the y component kept) and rolls back. A player traps it once it has rolled back to
    1-2 m short of the start spot: a constant extra deceleration (at least 4 m/s^2) that stops it before it
    passes the spot. After 0.3-0.8 s the player dribbles it to the next start spot at ``dribble_speed``
    (m/s, accelerating and braking at 2 m/s^2), where it waits for the next kick. Kick ``k`` comes at
    ``(k + 0.3) / num_shots`` of the run (+- 0.5 s) or, if the ball is not back by then, 0.5-1.5 s after
    it is. The start spots lie on the side opposite to the kick's angle, so the bounce brings the ball back
    across the middle. The motion is integrated with ``substeps`` per step (exact for a constant
    deceleration).

    Returns:
        ``(positions, speeds, kick_steps)``: ``float64 [T, 2]`` ball centres, ``float64 [T]`` speeds (m/s,
        just after a kick at a kick step) and ``int64 [K]`` the steps of the kicks within the run.
    """
    n = int(num_shots)
    decel = rng.uniform(*friction)
    speeds0 = rng.uniform(*shot_speed, n)
    sides = rng.choice([-1.0, 1.0], n + 1)
    angles = sides[:n] * rng.uniform(*angle, n)
    bounce = rng.uniform(*restitution, n)
    spots = np.stack(
        [start[0] + rng.uniform(-0.15, 0.15, n + 1), start[1] - sides * rng.uniform(0.1, 0.4, n + 1)], axis=-1
    )
    trap_x = spots[:n, 0] + rng.uniform(1.0, 2.0, n)
    waits = rng.uniform(0.5, 1.5, n)
    pauses = rng.uniform(0.3, 0.8, n)
    dribble = rng.uniform(*dribble_speed, n + 1)
    jitter = rng.uniform(-0.5, 0.5, n)
    first = spots[0] + np.array([-rng.uniform(0.5, 1.0), rng.uniform(-0.4, 0.4)])
    scheduled = np.round(((np.arange(n) + 0.3) * num_steps * dt / n + jitter) / dt).astype(np.int64)

    h = dt / substeps
    accel = 2.0  # m/s^2, the dribbling player's
    pos, vel = first.astype(np.float64), np.zeros(2)
    phase, shot, target, kick_step, resume = "dribble", 0, spots[0], -1, 0.0
    trap_decel = 0.0
    positions, speeds, kicks = np.zeros((num_steps, 2)), np.zeros(num_steps), []
    for i in range(num_steps):
        if phase == "wait" and i == kick_step:
            vel = speeds0[shot] * np.array([np.cos(angles[shot]), np.sin(angles[shot])])
            phase, bounced = "roll", False
            kicks.append(i)
        positions[i], speeds[i] = pos, np.linalg.norm(vel)
        for j in range(substeps):
            now = (i * substeps + j) * h
            if phase in ("roll", "trap"):
                speed = np.linalg.norm(vel)
                slow = decel + (trap_decel if phase == "trap" else 0.0)
                new = max(speed - slow * h, 0.0)
                # Exact for a constant deceleration, also when the ball stops inside the substep.
                travel = (speed**2 - new**2) / (2.0 * slow)
                pos = pos + vel / max(speed, 1e-12) * travel
                vel = vel * (new / max(speed, 1e-12))
                if not bounced and pos[0] > goal_x:
                    pos[0] = 2.0 * goal_x - pos[0]
                    vel[0] = -bounce[shot] * vel[0]
                    bounced = True
                elif phase == "roll" and bounced and pos[0] < trap_x[shot] and vel[0] < 0.0:
                    speed = np.linalg.norm(vel)
                    room = (pos[0] - spots[shot, 0]) * speed / -vel[0]
                    trap_decel = max(4.0, speed**2 / (2.0 * max(room, 1e-3)) - decel)
                    phase = "trap"
                if new == 0.0:
                    vel = np.zeros(2)
                    shot += 1
                    phase, resume, target = "pause", now + h + pauses[shot - 1], spots[shot]
            elif phase == "pause" and now >= resume:
                phase = "dribble"
            if phase == "dribble":
                gap = target - pos
                dist = np.linalg.norm(gap)
                want = gap / max(dist, 1e-12) * min(dribble[shot], np.sqrt(2.0 * accel * dist))
                change = want - vel
                size = np.linalg.norm(change)
                vel = vel + change * min(1.0, accel * h / max(size, 1e-12))
                pos = pos + vel * h
                if dist < 0.005 and np.linalg.norm(vel) < 0.05:
                    pos, vel, phase = target.copy(), np.zeros(2), "wait"
                    if shot < n:
                        ready = int(np.ceil((now + h + waits[shot]) / dt))
                        kick_step = max(ready, int(scheduled[shot]))
    return positions, speeds, np.array(kicks, np.int64)


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
