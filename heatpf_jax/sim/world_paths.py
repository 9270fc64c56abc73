"""Ball paths in the simulated world: smooth random paths, paths kept in a camera's view, meetings, shots.

Frames as in :mod:`heatpf_jax.sim.world` (which re-exports every name here). A path is ``float64 [T, 2]``
ground positions; :func:`fits_in_view` and :func:`lateral_limit` say where a ball is wholly in view of a
forward-looking camera. NumPy only.
"""

from __future__ import annotations

import numpy as np

from heatpf_jax.sim.render import project_centre
from heatpf_jax.sim.world_events import smooth_signal

__all__ = [
    "ball_path",
    "fits_in_view",
    "lateral_limit",
    "meet_apart_path",
    "meet_path",
    "shot_path",
    "slow_down",
    "view_path",
]


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
