"""Replay worlds: a real ball track, scaled down to a KidSize field, watched by a humanoid's head camera.

:func:`replay_world` turns a piece of a real track (:mod:`heatpf_jax.sim.tracks`) into a version-1
:class:`~heatpf_jax.Sequence` with ground truth, like :func:`~heatpf_jax.sim.simulate_with_info`:

* **Scale.** Pitch positions are scaled by ``scale`` (1/8 by default: professional speeds of 5-25 m/s
  become 0.6-3 m/s, a 105 x 68 m pitch 13 x 8.5 m) about the median of the piece's ball positions, and
  resampled to the filter period ``dt`` (:func:`~heatpf_jax.sim.tracks_pieces.resample_track`: linear
  interpolation, not across gaps longer than ``max_gap_s``; across such gaps the ball is hidden while
  the ground truth interpolates). Time is not scaled.
* **Placement.** The robot stands where the ball stays in front of it: among 12 headings (a random
  rotation) and distances 1-6 m back from the median, the pose that keeps the most steps between 0.5 m
  and the farthest distance the camera sees on the ground (at most 6 m; about 3 m for a low camera pitched
  35 degrees) within the head's reach (bearing within the yaw limit plus most of half the field of view),
  ties broken towards a drawn distance of 2-3.5 m. The world frame is the robot's base frame at step 0.
* **Robot.** ``"static"``: the robot stands still. ``"walking"``: it walks after the ball from there,
  at up to 0.25-0.35 m/s (accelerating at up to 0.5 m/s^2, slower when the ball is off its heading), turns
  at up to 0.5-0.7 rad/s, and stops 0.45-0.55 m from the ball, stepping back at up to 0.1 m/s from a ball
  that comes closer (the replayed ball does not bounce off the robot: it may roll through its feet); its
  odometry is the true motion with 5-10 % multiplicative and a small additive noise, as in the
  ``walking`` scenario.
* **Head.** The camera (0.45-0.7 m high, pitched down 25-35 degrees) turns about the vertical to follow
  the ball's bearing with a first-order lag of time constant ``tau`` (0.3-0.6 s):
  ``yaw[t] = target[t] + exp(-dt / tau) (yaw[t-1] - target[t])``, ``target`` the bearing clipped to
  +-1.2 rad (held while the track has no ball); ``yaw[0] = target[0]``. After a jump of the target at
  step s, the error at step s + k is ``exp(-(k + 1) dt / tau)`` times the jump. ``cam_to_base`` is the
  true pose at each step.
* **Heights.** ``"kept"``: the provider's height (clipped at 0) is scaled; the ball is rendered at its
  3D centre (height + ball radius), while ``ground_truth`` is the ground point under it (base x, y).
  ``"flat"``: the ball rolls on the ground (height 0). A ball whose centre is at or above the camera's
  height (above the horizon) or behind the camera renders nothing.
* **Render.** By default a Gaussian blob of peak 0.9 plus activation noise 0.03
  (:func:`~heatpf_jax.sim.render.blob`, :func:`~heatpf_jax.sim.render.compose_frame`, as the scenarios
  do); any ``render(rng, centres_base [K, 3], radius, intrinsics, cam_to_base, shape) -> float32 [H, W]``
  may replace it (K is 0 or 1).

Every output is a deterministic function of ``(track, seed, options)``. NumPy only.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.io.sequence import Sequence, validate_sequence
from heatpf_jax.sim.render import BALL_RADIUS, blob, compose_frame, project_centre, scaled_camera
from heatpf_jax.sim.tracks import (
    BallTrack,
    fetch_kloppy_files,
    load_pff,
    load_skillcorner,
    resample_track,
    segments,
)
from heatpf_jax.sim.world import compose_pose, odometry_from_poses, world_to_base

__all__ = [
    "HEAD_YAW_LIMIT",
    "HEIGHTS",
    "IN_AIR_HEIGHT",
    "REPLAY_SOURCES",
    "ROBOTS",
    "blob_render",
    "replay_segments",
    "replay_world",
]

ROBOTS = ("static", "walking")
HEIGHTS = ("kept", "flat")
REPLAY_SOURCES = ("skillcorner", "pff")
HEAD_YAW_LIMIT = 1.2  # rad
IN_AIR_HEIGHT = 0.1  # m (scaled): a ball whose bottom is higher than this is in the air
BALL_PEAK = 0.9
NOISE = 0.03
_STREAM = 8101  # this module's tag in the seeds of its random streams
_MIN_DEPTH = 0.05
_NEAR, _FAR = 0.5, 6.0  # where the placement wants the ball, metres from the robot
_ACCEL = 0.5  # m/s^2, the walking robot's acceleration limit
_BACK_SPEED = 0.1  # m/s, how fast it steps back from a ball closer than its stop distance

Render = Callable[[np.random.Generator, np.ndarray, float, np.ndarray, np.ndarray, tuple[int, int]], np.ndarray]


def blob_render(
    rng: np.random.Generator,
    centres_base: np.ndarray,
    radius: float,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
) -> np.ndarray:
    """The default renderer: the maximum of Gaussian blobs (peak 0.9) plus activation noise 0.03.

    Args:
        rng: source of the activation noise.
        centres_base: ``[K, 3]`` ball centres in the base frame (K may be 0: noise only).
        radius: ball radius, metres.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose.
        shape: ``(H, W)``.

    Returns:
        ``float32 [H, W]`` activations in ``[0, 1]``.
    """
    act = np.zeros(shape)
    for centre in np.asarray(centres_base, np.float64).reshape(-1, 3):
        act = np.maximum(act, blob(centre, radius, intrinsics, cam_to_base, shape, BALL_PEAK))
    return compose_frame(rng, act, NOISE)


# --- The robot ----------------------------------------------------------------------------------------------------


def _place(rng_draw: tuple[float, float], ball_xy: np.ndarray, reach: float, far: float) -> np.ndarray:
    """The standing pose ``(x, y, theta)`` that keeps most ball positions ``[N, 2]`` 0.5-``far`` m within ``reach``."""
    phi0, d0 = rng_draw
    centre = np.median(ball_xy, axis=0)
    headings = phi0 + 2.0 * np.pi * np.arange(12) / 12.0
    distances = np.arange(1.0, 6.0 + 1e-9, 0.25)
    hh, dd = (a.ravel() for a in np.meshgrid(headings, distances, indexing="ij"))
    pos = centre[None] - dd[:, None] * np.stack([np.cos(hh), np.sin(hh)], axis=-1)  # [C, 2]
    rel = ball_xy[None] - pos[:, None]  # [C, N, 2]
    dist = np.linalg.norm(rel, axis=-1)
    bearing = np.arctan2(rel[..., 1], rel[..., 0]) - hh[:, None]
    bearing = np.arctan2(np.sin(bearing), np.cos(bearing))
    good = (dist >= _NEAR) & (dist <= far) & (np.abs(bearing) <= reach)
    score = good.mean(axis=1) - 1e-3 * np.abs(dd - d0)
    best = int(np.argmax(score))
    return np.array([pos[best, 0], pos[best, 1], hh[best]])


def _walk(start: np.ndarray, ball_xy: np.ndarray, dt: float, v_max: float, w_max: float, stop: float) -> np.ndarray:
    """Poses ``[T, 3]`` of a robot walking after the ball from ``start`` (motion t-1 -> t uses the ball at t-1)."""
    poses = np.zeros((ball_xy.shape[0], 3))
    poses[0] = start
    speed = 0.0
    for t in range(1, ball_xy.shape[0]):
        rel = world_to_base(poses[t - 1], ball_xy[t - 1])
        dist, bearing = float(np.hypot(*rel)), float(np.arctan2(rel[1], rel[0]))
        turn = float(np.clip(2.0 * bearing, -w_max, w_max))
        wanted = float(np.clip(1.0 * (dist - stop), -_BACK_SPEED, v_max)) * max(np.cos(bearing), 0.0)
        speed = float(np.clip(wanted, speed - _ACCEL * dt, speed + _ACCEL * dt))
        poses[t] = compose_pose(poses[t - 1], np.array([speed * dt, 0.0, turn * dt]))
    return poses


def _head_yaw(bearing: np.ndarray, known: np.ndarray, dt: float, tau: float) -> np.ndarray:
    """The lagging head yaw ``[T]`` for the ball's bearing ``[T]`` (held where the ball is not known)."""
    target = np.clip(bearing, -HEAD_YAW_LIMIT, HEAD_YAW_LIMIT)
    keep = np.exp(-dt / tau)
    yaw = np.zeros_like(target)
    yaw[0] = target[0]
    for t in range(1, target.shape[0]):
        yaw[t] = target[t] + keep * (yaw[t - 1] - target[t]) if known[t] else yaw[t - 1]
    return yaw


def _to_frame(pose0: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """Poses ``[T, 3]`` expressed in the frame of ``pose0`` (angles wrapped to (-pi, pi])."""
    xy = world_to_base(pose0, poses[:, :2])
    theta = poses[:, 2] - pose0[2]
    return np.concatenate([xy, np.arctan2(np.sin(theta), np.cos(theta))[:, None]], axis=-1)


# --- Public entry points ------------------------------------------------------------------------------------------


def _check(seed, scale, dt, robot, heights, num_steps, shrink, render, max_gap_s) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    for name, value in (("scale", scale), ("dt", dt), ("max_gap_s", max_gap_s)):
        if isinstance(value, bool) or not isinstance(value, int | float | np.number) or not (
                np.isfinite(value) and value > 0):
            raise ValueError(f"{name}: must be a positive number, got {value!r}")
    if robot not in ROBOTS:
        raise ValueError(f"robot: must be one of {', '.join(ROBOTS)}, got {robot!r}")
    if heights not in HEIGHTS:
        raise ValueError(f"heights: must be one of {', '.join(HEIGHTS)}, got {heights!r}")
    if num_steps is not None and (isinstance(num_steps, bool) or not isinstance(num_steps, int | np.integer)
                                  or num_steps < 1):
        raise ValueError(f"num_steps: must be a positive integer or None, got {num_steps!r}")
    if isinstance(shrink, bool) or not isinstance(shrink, int | np.integer) or not 1 <= shrink <= 50:
        raise ValueError(f"shrink: must be an integer in [1, 50], got {shrink!r}")
    if render is not None and not callable(render):
        raise ValueError(f"render: must be a callable or None, got {type(render).__name__}")


def replay_world(
    track_segment: BallTrack,
    seed: int,
    *,
    scale: float = 1 / 8,
    dt: float = 0.1,
    robot: str = "static",
    heights: str = "kept",
    num_steps: int | None = None,
    shrink: int = 1,
    render: Render | None = None,
    max_gap_s: float = 0.5,
) -> tuple[Sequence, dict[str, Any]]:
    """A replay world: a real ball track, scaled, resampled and rendered for a humanoid's head camera.

    See the module docstring for the world's construction.

    Args:
        track_segment: a piece of a real track (:func:`~heatpf_jax.sim.tracks_pieces.segments`), pitch metres.
        seed: non-negative integer; draws the camera, the head's lag, the placement, the walking
            limits and all noise.
        scale: factor applied to positions and heights (1/8: a pitch to a KidSize field).
        dt: filter period, seconds; the track is resampled to it.
        robot: ``"static"`` or ``"walking"``.
        heights: ``"kept"`` (scaled provider heights) or ``"flat"`` (the ball on the ground).
        num_steps: the first T steps (default: the whole piece).
        shrink: integer divisor of the 200 x 150 heat map (same field of view).
        render: ``(rng, centres_base [K, 3], radius, intrinsics, cam_to_base, shape) -> float32 [H, W]``
            (default :func:`blob_render`).
        max_gap_s: gaps in the track up to this long (seconds) are bridged by interpolation; across
            longer ones the ball is hidden.

    Returns:
        ``(sequence, info)``: a validated version-1 sequence with ground truth (``robot_pose`` is not
        set: there is no self-localisation), and a dict of

        * ``robot_pose`` ``[T, 3]``: the base pose in the world (the base frame of step 0);
        * ``ball_world`` ``[T, 2]``: the ground point under the ball in the world;
        * ``ball_height`` ``[T]``: the ball's bottom above the ground, metres (0 with ``"flat"``);
        * ``ball_centre_base`` ``[T, 3]``: the ball's 3D centre in the base frame of step t;
        * ``in_air`` ``bool [T]``: ``ball_height > IN_AIR_HEIGHT`` (0.1 m);
        * ``track_known`` ``bool [T]``: the track knows the ball (no long gap);
        * ``above_horizon`` ``bool [T]``: the ball's centre is at or above the camera;
        * ``in_view`` ``bool [T]``: the ball is rendered and its centre projects inside the image;
        * ``visible`` ``bool [T]``: the ball is rendered in ``heatmaps[t]`` (known, in front of the camera,
          below the horizon; its blob may be cut by the image border);
        * ``ball_bearing`` ``[T]``, ``head_yaw`` ``[T]``: the ball's bearing in the base frame and the camera's yaw;
        * ``true_odometry`` ``[T, 3]``, ``true_cam_to_base`` ``[T, 4, 4]``;
        * ``ball_speed`` ``[T]``: the scaled 3D speed, m/s (0 at step 0);
        * ``time`` ``[T]``: the steps' times on the source's clock; ``start_time``: its first;
        * ``ball_pitch`` ``[T, 3]``: the resampled unscaled pitch position; ``scale_centre`` ``[2]``: the
          pitch point the scaling is about;
        * ``camera_height``, ``camera_pitch`` (rad), ``head_tau`` (s), and for ``"walking"``
          ``walk_speed_limit`` (m/s), ``turn_rate_limit`` (rad/s), ``stop_distance`` (m);
        * ``source``, ``seed``, ``scale``, ``robot``, ``heights``.

    Raises:
        ValueError: a bad argument (named), a track that never knows the ball, or ``num_steps``
            longer than the resampled piece.
    """
    _check(seed, scale, dt, robot, heights, num_steps, shrink, render, max_gap_s)
    dt, scale = float(dt), float(scale)
    res = resample_track(track_segment, dt, max_gap_s=float(max_gap_s))
    if num_steps is not None:
        if num_steps > res.num_frames:
            raise ValueError(f"num_steps: {num_steps} steps asked, the piece gives {res.num_frames} at dt = {dt} s "
                             f"({track_segment.source}, {res.t[-1] - res.t[0]:.1f} s)")
        res = res.slice(0, int(num_steps))
    steps = res.num_frames
    known = res.visible.copy()
    world, noise_rng, odom_rng = (np.random.default_rng([int(seed), _STREAM, j]) for j in range(3))
    cam_height = world.uniform(0.45, 0.7)
    cam_pitch = np.deg2rad(world.uniform(25.0, 35.0))
    tau = world.uniform(0.3, 0.6)
    v_max, w_max, stop = world.uniform(0.25, 0.35), world.uniform(0.5, 0.7), world.uniform(0.45, 0.55)
    placement = (world.uniform(0.0, 2.0 * np.pi), world.uniform(2.0, 3.5))

    intrinsics, shape = scaled_camera(int(shrink))
    half_fov = float(np.arctan2(shape[1] / 2.0, intrinsics[0]))
    # The farthest ground ball the camera sees (its image's top row), at most 6 m.
    top = cam_pitch - float(np.arctan2(shape[0] / 2.0, intrinsics[1]))
    far = _FAR if top <= 0.0 else min(_FAR, 0.95 * (cam_height - BALL_RADIUS) / np.tan(top))
    # Scaled pitch frame: the median ball position at the origin.
    centre = np.median(res.xyz[known, :2] if known.any() else res.xyz[:, :2], axis=0)
    ball_xy = (res.xyz[:, :2] - centre) * scale
    height = np.zeros(steps) if heights == "flat" else np.maximum(res.xyz[:, 2], 0.0) * scale
    start = _place(placement, ball_xy[known] if known.any() else ball_xy, HEAD_YAW_LIMIT + 0.8 * half_fov, far)
    if robot == "walking":
        poses_pitch = _walk(start, ball_xy, dt, v_max, w_max, stop)
    else:
        poses_pitch = np.repeat(start[None], steps, axis=0)
    robot_pose = _to_frame(start, poses_pitch)
    ball_world = world_to_base(start, ball_xy)
    ground = np.stack([world_to_base(robot_pose[t], ball_world[t]) for t in range(steps)])
    bearing = np.arctan2(ground[:, 1], ground[:, 0])
    yaw = _head_yaw(bearing, known, dt, tau)
    cams = np.stack([camera_pose(height=cam_height, pitch=cam_pitch, yaw=y) for y in yaw])
    centres = np.concatenate([ground, (height + BALL_RADIUS)[:, None]], axis=-1)

    draw = blob_render if render is None else render
    h, w = shape
    heatmaps = np.zeros((steps, h, w), np.float32)
    above = centres[:, 2] >= cam_height
    rendered = np.zeros(steps, bool)
    in_view = np.zeros(steps, bool)
    for t in range(steps):
        u, v, depth = project_centre(centres[t], intrinsics, cams[t])
        rendered[t] = known[t] and not above[t] and depth > _MIN_DEPTH
        in_view[t] = rendered[t] and 0.0 <= u <= w - 1 and 0.0 <= v <= h - 1
        frame = np.asarray(draw(noise_rng, centres[t:t + 1] if rendered[t] else np.zeros((0, 3)), BALL_RADIUS,
                                intrinsics.copy(), cams[t].copy(), shape), np.float32)
        if frame.shape != shape:
            raise ValueError(f"render: returned shape {frame.shape}, expected {shape}")
        heatmaps[t] = frame

    true_odom = odometry_from_poses(robot_pose)
    odom = true_odom.copy()
    noise_scale = odom_rng.uniform(0.05, 0.1)
    mult = odom_rng.standard_normal(true_odom.shape)
    add = odom_rng.standard_normal(true_odom.shape)
    if robot == "walking":  # legged odometry, as in the walking scenario
        odom = true_odom * (1.0 + noise_scale * mult) + np.array([0.001, 0.001, 0.002]) * add
        odom[0] = 0.0
    seq = Sequence(
        heatmaps=heatmaps,
        has_heatmap=np.ones(steps, bool),
        intrinsics=intrinsics.copy(),
        cam_to_base=cams.copy(),
        odometry=odom,
        ball_radius=np.asarray(BALL_RADIUS),
        dt=np.asarray(dt),
        ground_truth=ground.copy(),
    )
    world3 = np.concatenate([ball_world, height[:, None]], axis=-1)
    speed = np.zeros(steps)
    speed[1:] = np.linalg.norm(np.diff(world3, axis=0), axis=1) / dt
    info: dict[str, Any] = {
        "source": track_segment.source,
        "seed": int(seed),
        "scale": scale,
        "robot": robot,
        "heights": heights,
        "robot_pose": robot_pose,
        "ball_world": ball_world,
        "ball_height": height,
        "ball_centre_base": centres,
        "in_air": height > IN_AIR_HEIGHT,
        "track_known": known,
        "above_horizon": above,
        "in_view": in_view,
        "visible": rendered,
        "ball_bearing": bearing,
        "head_yaw": yaw,
        "true_odometry": true_odom,
        "true_cam_to_base": cams.copy(),
        "ball_speed": speed,
        "time": res.t.copy(),
        "start_time": float(res.t[0]),
        "ball_pitch": res.xyz.copy(),
        "scale_centre": centre,
        "camera_height": float(cam_height),
        "camera_pitch": float(cam_pitch),
        "head_tau": float(tau),
    }
    if robot == "walking":
        info.update(walk_speed_limit=float(v_max), turn_rate_limit=float(w_max), stop_distance=float(stop))
    return validate_sequence(seq), info


def replay_segments(
    source: str = "skillcorner",
    *,
    min_length_s: float = 30.0,
    max_gap_s: float = 0.5,
    max_speed: float | None = 45.0,
    cache_dir: str | os.PathLike | None = None,
) -> list[BallTrack]:
    """The pieces of a real source's ball tracks, fetched (once) and split where the ball is lost.

    Args:
        source: ``"skillcorner"`` (one 10 Hz match, about 51 minutes with the ball known: 6 pieces of
            at least 30 s, 233 s in all, at the defaults; 116 pieces of at least 10 s, 2030 s in all) or
            ``"pff"`` (two World Cup samples with heights: pieces of 0.8 s at most, so pass a small
            ``min_length_s``).
        min_length_s: pieces shorter than this are left out.
        max_gap_s: the longest gap bridged inside a piece (:func:`~heatpf_jax.sim.tracks_pieces.segments`).
        max_speed: a faster jump (m/s, unscaled: a tracking glitch) starts a new piece; ``None``: no limit.
        cache_dir: see :func:`~heatpf_jax.sim.tracks.fetch_kloppy_files`.

    Returns:
        The pieces, in time order (PFF: game 10517, then 3812).

    Raises:
        ValueError: an unknown source; RuntimeError: the download failed (see ``fetch_kloppy_files``).
    """
    if source not in REPLAY_SOURCES:
        raise ValueError(f"source: must be one of {', '.join(REPLAY_SOURCES)}, got {source!r}")
    folder = fetch_kloppy_files(cache_dir)
    if source == "skillcorner":
        tracks = [load_skillcorner(folder / "skillcorner_structured_data.json")]
    else:
        tracks = [load_pff(folder / "pff_10517.jsonl"), load_pff(folder / "pff_3812.jsonl")]
    return [piece for track in tracks
            for piece in segments(track, max_gap_s, min_length_s=min_length_s, max_speed=max_speed)]
