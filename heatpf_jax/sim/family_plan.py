"""The planning of a world family member: its world in the full-size camera, before any rendering.

``_plan`` turns drawn factors (:func:`heatpf_jax.sim.family_factors.draw_factors`) into a ``_World``: the
true and given cameras (gait sway, calibration error), the heat-map timing, the ball's motion, the robot's
poses and odometry, the hidings and partial occluders, and the false positives and distractors, from
the member's streams 1 (the world) and 3 (the effects). :mod:`heatpf_jax.sim.family_render` renders it.
Private to the family (no public names). NumPy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.sim.ball_motion import MOTION_KINDS, compose_motion, kicked_hidden_motion, wander_path
from heatpf_jax.sim.ball_physics import BallMotion
from heatpf_jax.sim.ball_region import view_region
from heatpf_jax.sim.detector import Occluder
from heatpf_jax.sim.family_factors import _rng
from heatpf_jax.sim.render import BALL_RADIUS, DEFAULT_INTRINSICS, HEATMAP_SHAPE
from heatpf_jax.sim.world import compose_pose, odometry_from_poses, world_to_base
from heatpf_jax.sim.world_events import bursty_mask, random_windows, smooth_signal

__all__: list[str] = []

# --- The world ----------------------------------------------------------------------------------------------------


class _World(NamedTuple):
    """A planned world; per-step arrays have a leading axis T."""

    motion: BallMotion
    robot_pose: np.ndarray  # [T, 3]
    true_cam: np.ndarray  # [T, 4, 4] the camera at step t
    given_cam: np.ndarray  # [T, 4, 4] what the sequence says
    given_odometry: np.ndarray  # [T, 3]
    has_heatmap: np.ndarray  # [T] bool
    ball_on: np.ndarray  # [T] bool: not hidden (world steps)
    occluder: list  # [T] Occluder or None (world steps)
    split: np.ndarray  # [T] bool: the occluder is the split stripe
    ball_peak: np.ndarray  # [T]
    fp_path: np.ndarray  # [T, K, 2] world
    fp_radius: np.ndarray  # [K]
    fp_peak: np.ndarray  # [T, K], 0 where off (world steps)
    extra_info: dict


def _full_camera(f: Mapping[str, Any]) -> np.ndarray:
    """The intrinsics of the 200 x 150 heat map for the drawn camera."""
    fx = DEFAULT_INTRINSICS[0] * f["fx_scale"]
    return np.array([fx, fx, DEFAULT_INTRINSICS[2] + f["cx_offset_px"], DEFAULT_INTRINSICS[3] + f["cy_offset_px"]])


def _shrunk(intrinsics: np.ndarray, shrink: int) -> tuple[np.ndarray, tuple[int, int]]:
    """As :func:`heatpf_jax.sim.render.scaled_camera`, for any full-size intrinsics."""
    offset = (shrink - 1) / 2.0
    fx, fy, cx, cy = intrinsics
    return (np.array([fx / shrink, fy / shrink, (cx - offset) / shrink, (cy - offset) / shrink]),
            (HEATMAP_SHAPE[0] // shrink, HEATMAP_SHAPE[1] // shrink))


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def _calibration_rotation(f: Mapping[str, Any]) -> np.ndarray:
    """The calibration error as a rotation of the optical frame: ``R_given = R_true @ E``."""
    phi = np.deg2rad(f["calibration_axis_deg"])
    return _axis_rotation(np.array([np.cos(phi), 0.0, np.sin(phi)]), np.deg2rad(f["calibration_error_deg"]))


def _cameras(f: Mapping[str, Any], num_steps: int, dt: float, rng: np.random.Generator):
    """True and given camera poses ``[T, 4, 4]``: gait sway (walking) and the calibration error."""
    t = np.arange(num_steps) * dt
    height, pitch = f["camera_height_m"], np.deg2rad(f["camera_pitch_deg"])
    stride = np.pi * f["gait_frequency_hz"] * t + rng.uniform(0.0, 2.0 * np.pi)  # half the step frequency
    roll = np.deg2rad(f["gait_roll_deg"]) * np.sin(stride)
    sway = f["gait_sway_m"] * np.sin(stride)
    bob_pitch = np.deg2rad(f["gait_pitch_deg"]) * np.sin(2.0 * stride)
    bob_height = f["gait_height_m"] * np.sin(2.0 * stride + 0.5)
    true = np.stack([camera_pose(height=height + bob_height[i], pitch=pitch + bob_pitch[i], roll=roll[i], y=sway[i])
                     for i in range(num_steps)])
    given = true.copy()
    given[:, :3, :3] = true[:, :3, :3] @ _calibration_rotation(f)
    return true, given


def _has_heatmap(f: Mapping[str, Any], num_steps: int, rng: np.random.Generator) -> np.ndarray:
    drop = float(f["drop_rate"])
    if f["rate_pattern"] == "regular":
        has = rng.uniform(size=num_steps) >= drop
    elif f["rate_pattern"] == "jittered":  # gaps of 1-3 steps: 1 + Binomial(2, p), a share `drop` of steps dropped
        p = drop / (2.0 * (1.0 - drop))
        has, t = np.zeros(num_steps, bool), int(rng.integers(0, 2))
        while t < num_steps:
            has[t] = True
            t += 1 + int(rng.binomial(2, p))
    else:
        has = ~bursty_mask(rng, num_steps, drop, f["drop_burst_steps"]) if drop > 0 else np.ones(num_steps, bool)
    if not has.any():
        has[0] = True
    return has


def _follow_poses(rng, ball: np.ndarray, dt: float, f: Mapping[str, Any]) -> np.ndarray:
    """A robot walking after the ball: it turns towards where it saw the ball 0.3 s ago and walks up to it."""
    num_steps = ball.shape[0]
    lag = max(1, int(round(0.3 / dt)))
    sideways = 0.03 * smooth_signal(rng, num_steps, dt, freqs=(0.02, 0.1))
    poses = np.zeros((num_steps, 3))
    for t in range(1, num_steps):
        rel = world_to_base(poses[t - 1], ball[max(t - 1 - lag, 0)])
        bearing, dist = float(np.arctan2(rel[1], rel[0])), float(np.hypot(*rel))
        turn = np.clip(1.5 * bearing, -f["turn_rate_max"], f["turn_rate_max"])
        speed = np.clip(0.6 * (dist - f["keep_distance_m"]), 0.0, f["walk_speed_max"]) * max(np.cos(bearing), 0.0)
        poses[t] = compose_pose(poses[t - 1], np.array([speed * dt, sideways[t] * dt, turn * dt]))
    return poses


def _occluders(rng, num_steps: int, dt: float, rate: float) -> list:
    """Partial occlusion: on a share ``rate`` of the steps (1 s bursts) a band or half plane, one per burst."""
    out = [None] * num_steps
    if rate <= 0.0:
        return out
    on = bursty_mask(rng, num_steps, rate, 1.0 / dt)
    edges = np.diff(np.r_[0, on.astype(int), 0])
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        if rng.uniform() < 0.5:
            occ = Occluder(rng.uniform(0.0, 2.0 * np.pi), rng.uniform(-0.3, 0.6), np.inf)
        else:
            occ = Occluder(rng.uniform(-0.5, 0.5) * np.pi, rng.uniform(-0.5, 0.5), rng.uniform(0.3, 0.8))
        out[start:stop] = [occ] * (stop - start)
    return out


def _plan(member: str, seed: int, f: Mapping[str, Any], num_steps: int, dt: float) -> _World:
    world, fx = _rng(seed, member, 1), _rng(seed, member, 3)
    full = _full_camera(f)
    true_cam, given_cam = _cameras(f, num_steps, dt, fx)
    nominal = camera_pose(height=f["camera_height_m"], pitch=np.deg2rad(f["camera_pitch_deg"]))
    region = view_region(full, nominal, HEATMAP_SHAPE, x_range=(f["region_near_m"], f["region_far_m"]),
                         radius=BALL_RADIUS, max_distance=f["region_far_m"] if member == "far" else np.inf)
    # False positives may be anywhere a ball could be seen (not only where this member keeps its ball).
    fp_region = view_region(full, nominal, HEATMAP_SHAPE, x_range=(0.4, 6.5), radius=BALL_RADIUS)
    extra: dict[str, Any] = {}
    ball_on = np.ones(num_steps, bool)
    if f["ball_motion"] == "kicked_hidden":
        motion, windows = kicked_hidden_motion(world, num_steps, dt, region)
        for w in windows:
            ball_on[w.start : w.stop] = False
        extra["hidden"] = np.array([(w.start, w.stop) for w in windows], np.int64).reshape(-1, 2)
        extra["hidden_kicks"] = windows
    else:
        motion = compose_motion(
            world, num_steps, dt, region, weights=MOTION_KINDS[f["ball_motion"]], decel=f["friction_decel"],
            kick_speed=(0.5, f["kick_speed_max"]), push_speed=f["push_speed"], stop_s=f["stop_s"],
            restitution=f["bounce_restitution"], loft_restitution=f["loft_restitution"])
    if f["robot_motion"] == "follow":
        poses = _follow_poses(world, motion.positions, dt, f)
        true_odom = odometry_from_poses(poses)
        noisy = true_odom * (1.0 + f["odometry_noise"] * fx.standard_normal(true_odom.shape))
        noisy += np.array([0.001, 0.001, 0.002]) * fx.standard_normal(true_odom.shape)
        noisy[0] = 0.0
    else:
        poses = np.zeros((num_steps, 3))
        noisy = np.zeros((num_steps, 3))
    if f["hide_count"] > 0:
        count = max(1, int(round(f["hide_count"] * num_steps * dt / 30.0)))
        lengths = (max(1, int(round(0.5 / dt))), max(1, int(round(f["hide_seconds_max"] / dt))))
        windows = random_windows(fx, num_steps, count, lengths, min_gap=max(1, int(round(1.0 / dt))),
                                 start_after=max(1, int(round(1.5 / dt))))
        for start, stop in windows:
            ball_on[start:stop] = False
        extra["hidden"] = np.array(windows, np.int64).reshape(-1, 2)
    occluder = _occluders(fx, num_steps, dt, f["occlusion_rate"])
    split = np.zeros(num_steps, bool)
    if f["split_rate"] > 0.0:
        split = bursty_mask(fx, num_steps, f["split_rate"], 2.0 / dt)
        tilt = np.deg2rad(f["stripe_tilt_deg"]) * smooth_signal(fx, num_steps, dt, freqs=(0.05, 0.2))
        offset = 0.2 * smooth_signal(fx, num_steps, dt, freqs=(0.1, 0.4))
        for t in np.flatnonzero(split):
            occluder[t] = Occluder(float(tilt[t]), float(offset[t]), float(f["stripe_width"]))
    peak = np.clip(f["peak"] + f["peak_jitter"] * fx.standard_normal(num_steps), 0.2, 1.0)
    # False positives: static places or smooth paths in the region, flickering in bursts.
    count = int(f["fp_count"])
    paths, radii, peaks = [], [], []
    for k in range(count):
        if f["fp_moving"][k]:
            paths.append(wander_path(world, num_steps, dt, fp_region, max_speed=f["fp_speed"][k]))
        else:
            paths.append(np.repeat(fp_region.sample(world)[None], num_steps, axis=0))
        radii.append(f["fp_radius_m"][k])
        on = bursty_mask(fx, num_steps, f["fp_on_fraction"][k], f["fp_burst_s"][k] / dt)
        level = np.clip(f["fp_brightness"][k] * f["peak"] + 0.03 * fx.standard_normal(num_steps), 0.2, 1.0)
        peaks.append(np.where(on, level, 0.0))
    # kicked_hidden's distractors: ball-like blobs near where the ball vanished and where it comes back.
    distractors, distractor_on = [], []
    for w in extra.get("hidden_kicks", []) if f["distractors"] > 0 else []:
        for j in range(int(f["distractors"])):
            anchor = motion.positions[min(w.start if j == 0 else w.stop, num_steps - 1)]
            place = anchor
            for _ in range(100):
                angle, dist = world.uniform(0.0, 2.0 * np.pi), world.uniform(0.3, 0.9)
                place = anchor + dist * np.array([np.cos(angle), np.sin(angle)])
                if region.contains(place):
                    break
            on = (np.arange(num_steps) >= w.start) & (np.arange(num_steps) < w.after)
            level = np.clip(f["distractor_brightness"] * f["peak"] + 0.03 * fx.standard_normal(num_steps), 0.2, 1.0)
            paths.append(np.repeat(place[None], num_steps, axis=0))
            radii.append(BALL_RADIUS)
            peaks.append(np.where(on, level, 0.0))
            distractors.append(place)
            distractor_on.append(on)
    if f["ball_motion"] == "kicked_hidden":
        extra["distractor_world"] = np.array(distractors, np.float64).reshape(-1, 2)
        extra["distractor_on"] = np.array(distractor_on, bool).reshape(-1, num_steps).T
    k_all = len(paths)
    return _World(
        motion=motion,
        robot_pose=poses,
        true_cam=true_cam,
        given_cam=given_cam,
        given_odometry=noisy,
        has_heatmap=_has_heatmap(f, num_steps, fx),
        ball_on=ball_on,
        occluder=occluder,
        split=split,
        ball_peak=peak,
        fp_path=np.stack(paths, axis=1) if k_all else np.zeros((num_steps, 0, 2)),
        fp_radius=np.array(radii, np.float64),
        fp_peak=np.stack(peaks, axis=1) if k_all else np.zeros((num_steps, 0)),
        extra_info=extra,
    )
