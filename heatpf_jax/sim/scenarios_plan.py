"""The named scenarios' worlds: what each scenario puts in front of the camera, before any rendering.

:data:`SCENARIOS` names the scenarios, in the order that seeds their random streams; a builder per
scenario (``_BUILDERS``) makes a ``_Plan``: the ball's path, the robot's poses, the true and given
cameras and odometry, the heat-map timing, hidings, false positives, the split stripe, more balls, a
self-localisation. :mod:`heatpf_jax.sim.scenarios_render` renders a plan and :mod:`heatpf_jax.sim.scenarios`
(which re-exports :data:`SCENARIOS`) runs both. NumPy only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.sim.render import BALL_RADIUS, scaled_camera
from heatpf_jax.sim.world import localisation_poses, odometry_from_poses, turn_poses, walk_poses
from heatpf_jax.sim.world_events import bursty_mask, random_windows, smooth_signal
from heatpf_jax.sim.world_paths import (
    ball_path,
    fits_in_view,
    lateral_limit,
    meet_apart_path,
    shot_path,
    slow_down,
    view_path,
)

__all__ = ["BALL_PEAK", "MAX_BALL_SPEED", "NOISE", "SCENARIOS"]

# New scenarios go at the end: each scenario's random streams are seeded with its index here.
SCENARIOS = (
    "standard",
    "false_positives",
    "split",
    "far",
    "occlusion",
    "walking",
    "sparse_rate",
    "two_balls",
    "shot",
    "turning",
)

MAX_BALL_SPEED = 3.0  # m/s, in the world frame
BALL_PEAK = 0.9
NOISE = 0.03


@dataclass
class _Plan:
    """Everything needed to render a scenario; per-step arrays have a leading axis T."""

    ball_world: np.ndarray  # [T, 2]
    robot_pose: np.ndarray  # [T, 3]
    true_cam: np.ndarray  # [T, 4, 4], used for rendering
    noise_rng: np.random.Generator
    effects_rng: np.random.Generator
    given_cam: np.ndarray | None = None  # [T, 4, 4], written to the sequence (default: true_cam)
    given_odometry: np.ndarray | None = None  # [T, 3] (default: the true odometry)
    has_heatmap: np.ndarray | None = None  # [T] bool (default: all)
    ball_on: np.ndarray | None = None  # [T] bool, False where the ball is occluded (default: all)
    ball_peak: np.ndarray | None = None  # [T] (default: BALL_PEAK)
    fp_world: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # [K, 2]
    fp_radius: np.ndarray = field(default_factory=lambda: np.zeros(0))  # [K]
    fp_peak: np.ndarray | None = None  # [T, K], 0 where off
    stripe: np.ndarray | None = None  # [T, 3]: angle from vertical (rad), offset and width in ball radii
    split_on: np.ndarray | None = None  # [T] bool, where the stripe is drawn
    dropout: float = 0.0  # share of the ball blob's pixels dropped (far scenario)
    noise: float = NOISE
    extra_balls_world: np.ndarray | None = None  # [T, K, 2]: more balls like the tracked one, never occluded
    extra_info: dict[str, Any] = field(default_factory=dict)  # scenario-specific entries of the info dict
    localisation: np.ndarray | None = None  # [T, 3]: the self-localisation's poses, written as robot_pose
    pose_confidence: np.ndarray | None = None  # [T]: its confidence


# --- Helpers ------------------------------------------------------------------------------------------------------


def _scenario_rngs(seed: int, scenario: str, count: int) -> list[np.random.Generator]:
    index = SCENARIOS.index(scenario)
    return [np.random.default_rng([seed, index, j]) for j in range(count)]


def _static(cam: np.ndarray, num_steps: int) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros((num_steps, 3)), np.repeat(cam[None], num_steps, axis=0)


def _min_visible_x(intrinsics, cam, shape, *, radius: float, start: float = 0.2) -> float:
    """The smallest forward distance (0.01 m grid) at which a ball straight ahead is wholly in view."""
    for x in np.arange(start, 3.0, 0.01):
        if fits_in_view(np.array([x, 0.0]), intrinsics, cam, shape, radius=radius):
            return float(x)
    return 3.0


def _standard_plan(seed: int, num_steps: int, dt: float, effects_rng: np.random.Generator) -> _Plan:
    """The standard world of a seed: camera 0.6 m high, pitched 30 degrees; the original ball path and noise."""
    rng = np.random.default_rng(seed)
    cam = camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    path = ball_path(rng, num_steps, dt, max_speed=MAX_BALL_SPEED)
    pose, cams = _static(cam, num_steps)
    return _Plan(ball_world=path, robot_pose=pose, true_cam=cams, noise_rng=rng, effects_rng=effects_rng)


# --- Scenarios ----------------------------------------------------------------------------------------------------


def _standard(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    return _standard_plan(seed, num_steps, dt, _scenario_rngs(seed, "standard", 1)[0])


def _false_positives(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    (fx,) = _scenario_rngs(seed, "false_positives", 1)
    plan = _standard_plan(seed, num_steps, dt, fx)
    cam = plan.true_cam[0]

    def inside(x, y, radius):  # pull a place towards the centre line until it is wholly in view
        limit = 0.9 * lateral_limit(np.array([x]), intrinsics, cam, shape, radius=radius)[0]
        return x, float(np.clip(y, -limit, limit))

    places, radii = [], []
    # Goal-post feet: two posts 1.5-2.6 m apart, 4-5.5 m ahead.
    x_goal, width, y_goal = fx.uniform(4.0, 5.5), fx.uniform(1.5, 2.6), fx.uniform(-0.6, 0.6)
    for side in (-0.5, 0.5):
        r = fx.uniform(0.06, 0.09)
        places.append(inside(x_goal, y_goal + side * width, r))
        radii.append(r)
    # The penalty mark, in the ball's area.
    r = fx.uniform(0.05, 0.08)
    places.append(inside(fx.uniform(1.6, 3.0), fx.uniform(-0.4, 0.4), r))
    radii.append(r)
    # 0-2 white objects near the field border (the edges of the view).
    for _ in range(int(fx.integers(0, 3))):
        r = fx.uniform(0.06, 0.12)
        x = fx.uniform(2.5, 5.0)
        limit = lateral_limit(np.array([x]), intrinsics, cam, shape, radius=r)[0]
        places.append((x, float(fx.choice([-1.0, 1.0]) * fx.uniform(0.75, 0.9) * limit)))
        radii.append(r)
    k = len(places)
    base_peak = fx.uniform(0.55, 0.95, k)
    base_peak[fx.integers(0, k)] = fx.uniform(0.95, 1.0)  # at least one place outshines the ball (0.9)
    on = np.stack([
        bursty_mask(fx, num_steps, fx.uniform(0.3, 0.6), fx.uniform(0.5, 2.0) / dt) for _ in range(k)
    ], axis=-1)
    peak = np.clip(base_peak + 0.03 * fx.standard_normal((num_steps, k)), 0.3, 1.0)
    plan.fp_world = np.array(places)
    plan.fp_radius = np.array(radii)
    plan.fp_peak = np.where(on, peak, 0.0)
    return plan


def _split(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, noise, fx = _scenario_rngs(seed, "split", 3)
    # A camera that looks down a little more, as a robot does at a close ball.
    cam = camera_pose(height=world.uniform(0.45, 0.65), pitch=np.deg2rad(world.uniform(30.0, 35.0)))
    x_lo = max(0.45, _min_visible_x(intrinsics, cam, shape, radius=BALL_RADIUS) + 0.03)
    path = view_path(world, num_steps, dt, intrinsics, cam, shape, x_range=(x_lo, 1.15), max_distance=1.2,
                     fill=0.7, radius=BALL_RADIUS, max_speed=1.5, freqs=(0.05, 0.25))
    pose, cams = _static(cam, num_steps)
    # An occluder (a robot's leg, a post) drifts through the blob on most frames.
    split_on = bursty_mask(fx, num_steps, 0.8, 2.0 / dt)
    angle = np.deg2rad(35.0) * smooth_signal(fx, num_steps, dt, freqs=(0.05, 0.2))
    offset = 0.2 * smooth_signal(fx, num_steps, dt, freqs=(0.1, 0.4))
    width = 0.35 + 0.08 * smooth_signal(fx, num_steps, dt, freqs=(0.1, 0.4))
    return _Plan(ball_world=path, robot_pose=pose, true_cam=cams, noise_rng=noise, effects_rng=fx,
                 stripe=np.stack([angle, offset, width], axis=-1), split_on=split_on)


def _far(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, noise, fx = _scenario_rngs(seed, "far", 3)
    # Pitched up enough to see 7 m.
    cam = camera_pose(height=world.uniform(0.5, 0.7), pitch=np.deg2rad(world.uniform(25.0, 29.0)))
    path = view_path(world, num_steps, dt, intrinsics, cam, shape, x_range=(4.2, 6.6), max_distance=6.9,
                     fill=0.8, radius=BALL_RADIUS, max_speed=MAX_BALL_SPEED)
    pose, cams = _static(cam, num_steps)
    peak = np.clip(0.55 + 0.12 * smooth_signal(fx, num_steps, dt) + 0.04 * fx.standard_normal(num_steps), 0.35, 0.75)
    return _Plan(ball_world=path, robot_pose=pose, true_cam=cams, noise_rng=noise, effects_rng=fx,
                 ball_peak=peak, dropout=0.2)


def _occlusion(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    (fx,) = _scenario_rngs(seed, "occlusion", 1)
    plan = _standard_plan(seed, num_steps, dt, fx)
    count = max(1, int(round(fx.uniform(2.0, 3.0) * num_steps * dt / 30.0)))
    lengths = (max(1, int(round(0.5 / dt))), max(1, int(round(2.0 / dt))))
    windows = random_windows(fx, num_steps, count, lengths, min_gap=max(1, int(round(1.0 / dt))),
                             start_after=max(1, int(round(1.5 / dt))))
    ball_on = np.ones(num_steps, bool)
    for start, stop in windows:
        ball_on[start:stop] = False
    plan.ball_on = ball_on
    return plan


def _walking(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, noise, fx = _scenario_rngs(seed, "walking", 3)
    height, pitch = world.uniform(0.5, 0.65), np.deg2rad(world.uniform(27.0, 33.0))
    nominal = camera_pose(height=height, pitch=pitch)
    poses = walk_poses(world, num_steps, dt)
    # Ball: a path in the robot's view, carried into the world; slowed until its world speed is <= 3 m/s.
    rel = view_path(world, num_steps, dt, intrinsics, nominal, shape, x_range=(0.9, 3.5), fill=0.7,
                    radius=BALL_RADIUS, max_speed=1.2)
    c, s = np.cos(poses[:, 2]), np.sin(poses[:, 2])
    for _ in range(20):
        ball_world = poses[:, :2] + np.stack([c * rel[:, 0] - s * rel[:, 1], s * rel[:, 0] + c * rel[:, 1]], -1)
        speed = np.linalg.norm(np.diff(ball_world, axis=0), axis=1).max(initial=0.0) / dt
        if speed <= MAX_BALL_SPEED:
            break
        rel_speed = np.linalg.norm(np.diff(rel, axis=0), axis=1).max(initial=0.0) / dt
        rel = slow_down(rel, dt, 0.8 * rel_speed)
    # Head sway of a walking humanoid: roll and sideways at the stride frequency, pitch and height at the
    # step frequency (twice the stride frequency).
    t = np.arange(num_steps) * dt
    stride = 2 * np.pi * world.uniform(0.8, 1.0) * t + world.uniform(0, 2 * np.pi)
    roll = np.deg2rad(world.uniform(0.5, 1.5)) * np.sin(stride)
    sideways = world.uniform(0.01, 0.02) * np.sin(stride)
    bob_pitch = np.deg2rad(world.uniform(0.3, 0.8)) * np.sin(2 * stride)
    bob_height = world.uniform(0.005, 0.015) * np.sin(2 * stride + 0.5)
    # Forward kinematics while walking: a slowly varying pitch error of 1-2 degrees.
    error = np.deg2rad(fx.choice([-1.0, 1.0]) * (1.5 + 0.5 * smooth_signal(fx, num_steps, dt, freqs=(0.01, 0.05))))
    true_cam = np.stack([camera_pose(height=height + bob_height[i], pitch=pitch + bob_pitch[i], roll=roll[i],
                                     y=sideways[i]) for i in range(num_steps)])
    given_cam = np.stack([camera_pose(height=height + bob_height[i], pitch=pitch + bob_pitch[i] + error[i],
                                      roll=roll[i], y=sideways[i]) for i in range(num_steps)])
    # Legged odometry: 5-10 % multiplicative noise per component and step, plus a small additive part.
    true_odom = odometry_from_poses(poses)
    scale = fx.uniform(0.05, 0.1)
    given_odom = true_odom * (1.0 + scale * fx.standard_normal(true_odom.shape))
    given_odom += np.array([0.001, 0.001, 0.002]) * fx.standard_normal(true_odom.shape)
    given_odom[0] = 0.0
    return _Plan(ball_world=ball_world, robot_pose=poses, true_cam=true_cam, noise_rng=noise, effects_rng=fx,
                 given_cam=given_cam, given_odometry=given_odom)


def _sparse_rate(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    (fx,) = _scenario_rngs(seed, "sparse_rate", 1)
    plan = _standard_plan(seed, num_steps, dt, fx)
    has = np.zeros(num_steps, bool)
    t = 0
    while t < num_steps:  # gaps of 1-6 steps, mean 3.15: about a third of the steps bring a heat map
        has[t] = True
        t += int(fx.choice(np.arange(1, 7), p=[0.2, 0.2, 0.2, 0.15, 0.15, 0.1]))
    plan.has_heatmap = has
    return plan


def _meeting_steps(a, b, dt, count, intrinsics, cam, shape) -> np.ndarray:
    """One step in the middle 60 % of each of ``count`` equal parts of the run for paths ``a`` and ``b`` to meet.

    Where ``a`` is well in view and the balls pass each other at 0.8 m/s or more, the step where they are
    closest already (the least bending: a quick crossing, not one ball following the other).
    """
    num_steps = a.shape[0]
    bounds = np.linspace(0.0, num_steps, count + 1)
    rel_speed = np.linalg.norm(np.gradient(b - a, axis=0), axis=1) / dt if num_steps > 1 else np.zeros(1)
    gap = np.linalg.norm(b - a, axis=1)
    steps = []
    for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
        cand = np.arange(int(np.ceil(lo + 0.2 * (hi - lo))), int(np.floor(lo + 0.8 * (hi - lo))) + 1)
        cand = cand[cand < num_steps]
        good = [
            t
            for t in cand
            if rel_speed[t] >= 0.8 and fits_in_view(a[t], intrinsics, cam, shape, radius=BALL_RADIUS, margin_px=10.0)
        ]
        pool = np.array(good or list(cand) or [min(int(lo), num_steps - 1)])
        steps.append(int(pool[np.argmin(gap[pool])]))
    return np.unique(steps)


def _two_balls(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, fx = _scenario_rngs(seed, "two_balls", 2)
    plan = _standard_plan(seed, num_steps, dt, fx)  # ball A: the standard world of the seed
    cam = plan.true_cam[0]
    full, full_shape = scaled_camera(1)  # planned in the full-size view: the same world at every shrink
    a = plan.ball_world
    b = view_path(
        world, num_steps, dt, full, cam, full_shape, x_range=(1.0, 3.4), fill=0.8, radius=BALL_RADIUS, max_speed=1.6
    )
    # The balls meet (centres 0.18-0.26 m apart) about every 10 s: b is bent towards a around chosen steps, and
    # away from a wherever they would overlap (centres closer than 0.16 m).
    steps = _meeting_steps(a, b, dt, max(1, int(round(num_steps * dt / 10.0))), full, cam, full_shape)
    b, steps = meet_apart_path(a, b, dt, steps, world.uniform(0.18, 0.26, len(steps)), min_distance=0.16)
    plan.extra_balls_world = b[:, None, :]
    plan.extra_info = {"meeting_steps": steps}
    return plan


def _shot(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, noise, fx = _scenario_rngs(seed, "shot", 3)
    cam = camera_pose(height=world.uniform(0.55, 0.65), pitch=np.deg2rad(world.uniform(27.0, 30.0)))
    start, goal_x = (world.uniform(1.6, 2.4), 0.0), world.uniform(5.0, 6.0)
    num_shots = max(1, int(round(num_steps * dt / 10.0)))
    path, speed, kicks = shot_path(world, num_steps, dt, start=start, goal_x=goal_x, num_shots=num_shots)
    pose, cams = _static(cam, num_steps)
    return _Plan(
        ball_world=path,
        robot_pose=pose,
        true_cam=cams,
        noise_rng=noise,
        effects_rng=fx,
        extra_info={"ball_speed": speed, "shot_steps": kicks, "goal_x": goal_x},
    )


def _turning(seed, num_steps, dt, intrinsics, shape) -> _Plan:
    world, noise, fx, loc = _scenario_rngs(seed, "turning", 4)
    cam = camera_pose(height=world.uniform(0.55, 0.65), pitch=np.deg2rad(world.uniform(27.0, 33.0)))
    poses, centre = turn_poses(world, num_steps, dt)
    # A path like the standard one, ahead of the middle of the robot's swing.
    path = ball_path(world, num_steps, dt, max_speed=MAX_BALL_SPEED)
    c, s = np.cos(centre), np.sin(centre)
    ball_world = path @ np.array([[c, s], [-s, c]])
    # Odometry as in walking: 5-10 % multiplicative noise per component and step, plus a small additive part.
    true_odom = odometry_from_poses(poses)
    scale = fx.uniform(0.05, 0.1)
    given_odom = true_odom * (1.0 + scale * fx.standard_normal(true_odom.shape))
    given_odom += np.array([0.001, 0.001, 0.002]) * fx.standard_normal(true_odom.shape)
    given_odom[0] = 0.0
    # Self-localisation (Olufs et al. 3.5) from a stream of its own: the other arrays stay as they were.
    localisation, confidence, lost = localisation_poses(loc, poses, dt)
    return _Plan(
        ball_world=ball_world,
        robot_pose=poses,
        true_cam=np.repeat(cam[None], num_steps, axis=0),
        noise_rng=noise,
        effects_rng=fx,
        given_odometry=given_odom,
        localisation=localisation,
        pose_confidence=confidence,
        extra_info={"localisation_lost": lost},
    )


_BUILDERS = {
    "standard": _standard,
    "false_positives": _false_positives,
    "split": _split,
    "far": _far,
    "occlusion": _occlusion,
    "walking": _walking,
    "sparse_rate": _sparse_rate,
    "two_balls": _two_balls,
    "shot": _shot,
    "turning": _turning,
}
