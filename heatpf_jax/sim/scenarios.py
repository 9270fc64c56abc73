"""Simulated evaluation scenarios: the paper's standard setting (Table I) and its edge cases (IV-D).

:func:`simulate` returns a version-1 :class:`~heatpf_jax.Sequence` with ground truth;
:func:`simulate_with_info` also returns per-step facts about what was rendered (for tests and
evaluation). Every scenario is a deterministic function of ``(scenario, seed, num_steps, dt, shrink)``.

The world frame is the robot's base frame at step 0. A humanoid's head camera (0.45-0.7 m high,
pitched down 25-35 degrees) sees a 200 x 150 heat map (``shrink`` divides it); the ball (radius
0.075 m) rolls on smooth random paths at up to 3 m/s (kicked at 5-8 m/s in ``shot``). ``standard``,
``false_positives``, ``occlusion``, ``sparse_rate`` and ``two_balls`` share the standard world of a seed
(camera 0.6 m, 30 degrees, the same ball path and activation noise), so their differences are the
scenario's effect alone.
``two_balls`` adds a second ball; ``shot`` and ``turning`` follow Olufs et al.'s test tours B (a ball
shot at a goal) and C (a robot turning in place).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.sequence import Sequence, validate_sequence
from heatpf_jax.sim.render import BALL_RADIUS, blob, compose_frame, project_centre, scaled_camera, stripe_mask
from heatpf_jax.sim.world import (
    ball_path,
    bursty_mask,
    fits_in_view,
    lateral_limit,
    localisation_poses,
    meet_apart_path,
    odometry_from_poses,
    random_windows,
    shot_path,
    slow_down,
    smooth_signal,
    turn_poses,
    view_path,
    walk_poses,
    world_to_base,
)

__all__ = ["SCENARIOS", "simulate", "simulate_standard", "simulate_with_info"]

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

DEFAULT_NUM_STEPS = 300
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


# --- Rendering ----------------------------------------------------------------------------------------------------


def _render(plan: _Plan, num_steps: int, dt: float, intrinsics: np.ndarray, shape: tuple[int, int]):
    has = np.ones(num_steps, bool) if plan.has_heatmap is None else plan.has_heatmap
    ball_on = np.ones(num_steps, bool) if plan.ball_on is None else plan.ball_on
    peaks = np.full(num_steps, BALL_PEAK) if plan.ball_peak is None else plan.ball_peak
    split_on = np.zeros(num_steps, bool) if plan.split_on is None else plan.split_on
    fp_peak = np.zeros((num_steps, 0)) if plan.fp_peak is None else plan.fp_peak
    truth = np.stack([world_to_base(plan.robot_pose[t], plan.ball_world[t]) for t in range(num_steps)])
    extra_world = np.zeros((num_steps, 0, 2)) if plan.extra_balls_world is None else plan.extra_balls_world
    extra = np.stack([world_to_base(plan.robot_pose[t], extra_world[t]) for t in range(num_steps)])
    extra_in_view = np.zeros(extra.shape[:2], bool)
    h, w = shape
    heatmaps = np.zeros((num_steps, h, w), np.float32)
    in_view = np.zeros(num_steps, bool)
    split = np.zeros(num_steps, bool)
    fp_rendered = np.zeros(fp_peak.shape, bool)
    for t in range(num_steps):
        cam = plan.true_cam[t]
        centre = np.array([truth[t, 0], truth[t, 1], BALL_RADIUS])
        u0, v0, depth = project_centre(centre, intrinsics, cam)
        in_view[t] = depth > 0.05 and 0.0 <= u0 <= w - 1 and 0.0 <= v0 <= h - 1
        act = blob(centre, BALL_RADIUS, intrinsics, cam, shape, peaks[t]) if ball_on[t] else np.zeros(shape)
        if ball_on[t] and split_on[t] and in_view[t]:
            radius_px = intrinsics[0] * BALL_RADIUS / depth
            angle, offset, width = plan.stripe[t]
            act = act * stripe_mask(shape, u0, v0, angle, offset * radius_px, max(width * radius_px, 1.5))
            split[t] = True
        for k in range(extra.shape[1]):
            other = np.array([extra[t, k, 0], extra[t, k, 1], BALL_RADIUS])
            u, v, d = project_centre(other, intrinsics, cam)
            extra_in_view[t, k] = d > 0.05 and 0.0 <= u <= w - 1 and 0.0 <= v <= h - 1
            act = np.maximum(act, blob(other, BALL_RADIUS, intrinsics, cam, shape, peaks[t]))
        if plan.dropout > 0.0:
            act = act * (plan.effects_rng.uniform(size=shape) >= plan.dropout)
        if fp_peak.shape[1]:
            base_fp = world_to_base(plan.robot_pose[t], plan.fp_world)
            for k in np.flatnonzero(fp_peak[t] > 0):
                r = plan.fp_radius[k]
                fp_centre = np.array([base_fp[k, 0], base_fp[k, 1], r])
                u, v, d = project_centre(fp_centre, intrinsics, cam)
                fp_rendered[t, k] = d > 0.05 and 0.0 <= u <= w - 1 and 0.0 <= v <= h - 1
                act = np.maximum(act, blob(fp_centre, r, intrinsics, cam, shape, fp_peak[t, k]))
        frame = compose_frame(plan.noise_rng, act, plan.noise)
        if has[t]:
            heatmaps[t] = frame
    true_odom = odometry_from_poses(plan.robot_pose)
    seq = Sequence(
        heatmaps=heatmaps,
        has_heatmap=has.copy(),
        intrinsics=intrinsics.copy(),
        cam_to_base=(plan.true_cam if plan.given_cam is None else plan.given_cam).copy(),
        odometry=true_odom.copy() if plan.given_odometry is None else plan.given_odometry.copy(),
        ball_radius=np.asarray(BALL_RADIUS),
        dt=np.asarray(float(dt)),
        ground_truth=truth,
        robot_pose=None if plan.localisation is None else plan.localisation.copy(),
        pose_confidence=None if plan.pose_confidence is None else plan.pose_confidence.copy(),
    )
    fp_rendered &= has[:, None]
    info = {
        "robot_pose": plan.robot_pose.copy(),
        "ball_world": plan.ball_world.copy(),
        "true_odometry": true_odom,
        "true_cam_to_base": plan.true_cam.copy(),
        "in_view": in_view,
        "occluded": ~ball_on,
        "visible": has & ball_on & in_view,
        "ball_peak": np.where(has & ball_on, peaks, 0.0),
        "split": split & has,
        "false_positive_world": plan.fp_world.copy(),
        "false_positive_radius": plan.fp_radius.copy(),
        "false_positive_on": fp_rendered,
        "false_positive_peak": np.where(fp_rendered, fp_peak, 0.0),
        "false_positive_count": fp_rendered.sum(axis=1).astype(np.int64),
        "balls_base": np.concatenate([truth[:, None], extra], axis=1),
        "balls_visible": np.concatenate([(has & ball_on & in_view)[:, None], has[:, None] & extra_in_view], axis=1),
        **{key: np.copy(value) for key, value in plan.extra_info.items()},
    }
    return validate_sequence(seq), info


# --- Public entry points ------------------------------------------------------------------------------------------


def _check_args(scenario, seed, num_steps, dt, shrink) -> int:
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario: unknown scenario {scenario!r}; valid names: {', '.join(SCENARIOS)}")
    return check_run_args(seed, num_steps, dt, shrink)


def check_run_args(seed, num_steps, dt, shrink) -> int:
    """Checks a simulation's seed, steps, period and shrink (one line naming the field); the number of steps."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    num_steps = DEFAULT_NUM_STEPS if num_steps is None else num_steps
    if isinstance(num_steps, bool) or not isinstance(num_steps, int | np.integer) or num_steps < 1:
        raise ValueError(f"num_steps: must be a positive integer, got {num_steps!r}")
    if not (isinstance(dt, int | float | np.floating) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
    if isinstance(shrink, bool) or not isinstance(shrink, int | np.integer) or not 1 <= shrink <= 50:
        raise ValueError(f"shrink: must be an integer in [1, 50], got {shrink!r}")
    return int(num_steps)


def simulate_with_info(
    scenario: str,
    seed: int,
    *,
    num_steps: int | None = None,
    dt: float = 0.1,
    shrink: int = 1,
    occlude: tuple[int, int] | None = None,
    rgb: bool = False,
) -> tuple[Sequence, dict[str, Any]]:
    """Simulates one scenario and reports what was rendered.

    Args:
        scenario: one of :data:`SCENARIOS`.
        seed: non-negative integer; the same arguments give identical arrays.
        num_steps: T (default 300: 30 s at 10 Hz).
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view), for quick tests.
        occlude: optional steps ``(start, stop)`` on which the ball is hidden as well (an occlusion of
            ``stop - start`` steps, e.g. for the long-term memory's re-acquisition test); the world is
            the scenario's own, unchanged.
        rgb: also render RGB frames of the same world into the sequence's ``images``
            (:func:`heatpf_jax.sim.render_rgb.render_rgb`; about 25 ms a 200 x 150 frame).

    Returns:
        ``(sequence, info)``: a validated version-1 sequence with ground truth, and a dict of

        * ``robot_pose`` ``[T, 3]``: (x, y, theta) in the world (the base frame of step 0);
        * ``ball_world`` ``[T, 2]``: ball centre in the world;
        * ``true_odometry`` ``[T, 3]``: the exact motion (the sequence's odometry is noisy in ``walking``);
        * ``true_cam_to_base`` ``[T, 4, 4]``: the pose the heat maps were rendered with (the sequence's
          ``cam_to_base`` is off by 1-2 degrees of pitch in ``walking``);
        * ``in_view`` ``bool [T]``: the ball centre projects inside the image;
        * ``occluded`` ``bool [T]``: the ball is hidden (``occlusion`` windows);
        * ``visible`` ``bool [T]``: the ball is rendered in ``heatmaps[t]`` (a heat map arrives, the ball
          is in view and not occluded);
        * ``ball_peak`` ``[T]``: the ball blob's peak activation (0 where not rendered);
        * ``split`` ``bool [T]``: an occluding stripe cuts the ball blob in two (``split``);
        * ``false_positive_world`` ``[K, 2]``, ``false_positive_radius`` ``[K]``: the spurious places;
        * ``false_positive_on`` ``bool [T, K]``, ``false_positive_peak`` ``[T, K]``: which are rendered, how
          bright; ``false_positive_count`` ``int [T]``: how many are rendered in ``heatmaps[t]``;
        * ``balls_base`` ``[T, B, 2]``: every ball's centre in the base frame of step t, the tracked one
          (``ground_truth``) first: ``B = 2`` in ``two_balls``, 1 elsewhere;
        * ``balls_visible`` ``bool [T, B]``: which balls are rendered in ``heatmaps[t]`` (column 0 is
          ``visible``; other balls are never occluded);

        and in ``two_balls``: ``meeting_steps`` ``int [M]``, the steps where the balls were made to meet
        (centres 0.18-0.26 m apart); in ``shot``: ``ball_speed`` ``[T]``, the ball's world speed
        (m/s, just after the kick at a kick step), ``shot_steps`` ``int [K]``, the steps of the kicks, and
        ``goal_x``, the x of the wall the ball bounces off; in ``turning``: ``localisation_lost`` ``bool [T]``,
        the steps on which the self-localisation (the sequence's ``robot_pose``) has jumped away.

    Raises:
        ValueError: an unknown ``scenario`` (the message lists the valid names) or a bad argument
            (the message names it).
    """
    num_steps = _check_args(scenario, seed, num_steps, dt, shrink)
    dt = float(dt)
    intrinsics, shape = scaled_camera(int(shrink))
    plan = _BUILDERS[scenario](int(seed), num_steps, dt, intrinsics, shape)
    if occlude is not None:
        start, stop = (int(v) for v in occlude)
        if not 0 <= start < stop <= num_steps:
            raise ValueError(f"occlude: must be (start, stop) with 0 <= start < stop <= {num_steps}, got {occlude}")
        hidden = (np.arange(num_steps) >= start) & (np.arange(num_steps) < stop)
        plan.ball_on = (np.ones(num_steps, bool) if plan.ball_on is None else plan.ball_on) & ~hidden
    seq, info = _render(plan, num_steps, dt, intrinsics, shape)
    if rgb:
        from heatpf_jax.sim.render_rgb import render_rgb

        seq = seq._replace(images=render_rgb(seq, info, seed=int(seed)))
    return seq, {"scenario": scenario, "seed": int(seed), **info}


def simulate(
    scenario: str, seed: int, *, num_steps: int | None = None, dt: float = 0.1, shrink: int = 1, rgb: bool = False
) -> Sequence:
    """Simulates one scenario as a validated version-1 sequence with ground truth.

    Scenarios (:data:`SCENARIOS`, 300 steps at 10 Hz by default):

    * ``standard``: static robot, a heat map every step (the paper's Table I setting).
    * ``false_positives``: standard plus 3-5 spurious blobs at fixed world places (goal-post feet, the
      penalty mark, white objects at the field border), each on 30-60 % of the frames in bursts, at least
      one brighter than the ball (Fig. 5).
    * ``split``: a close ball (0.45-1.2 m) whose blob an occluding stripe cuts into two clusters on about
      80 % of the frames (Fig. 7a).
    * ``far``: a distant ball (4.2-6.9 m): a few weak pixels with gaps (Fig. 7b).
    * ``occlusion``: standard, but the ball vanishes for 0.5-2 s windows (2-3 per 30 s) while it moves on.
    * ``walking``: the robot walks (0.1-0.3 m/s) and turns (up to 0.2-0.5 rad/s); noisy odometry, a
      camera pose off by 1-2 degrees of pitch, head sway; the heat maps use the true camera pose.
    * ``sparse_rate``: standard, but heat maps arrive on about a third of the steps, after gaps of 1-6 steps.
    * ``two_balls``: standard plus a second, identical ball (same size and activation) on its own smooth
      path in view, bent so that the balls pass each other (centres 0.18-0.26 m apart) about every 10 s
      and never overlap (centres at least 0.16 m apart). The ground truth is the standard ball.
    * ``shot``: static robot; a ball dribbled to a start spot 1.6-2.4 m ahead is shot at 5-8 m/s, 3-10
      degrees off straight ahead, towards a wall (a goal) 5-6 m ahead; it rolls with a deceleration of
      0.5-1 m/s^2, bounces back (restitution 0.4-0.7), is trapped by a player and dribbled back at about
      1 m/s; a shot about every 10 s (Olufs et al.'s tour B).
    * ``turning``: the robot turns in place, left and right: its yaw swings +-0.5-0.7 rad with a period of
      4-7 s, at up to 0.75-0.95 rad/s; the ball moves on a path like the standard one ahead of the
      middle of the swing and is in view about 80 % of the time. Noisy odometry as in ``walking``; the
      camera pose is exact (Olufs et al.'s tour C). The sequence also holds a self-localisation
      (``robot_pose``, ``pose_confidence``): off by about 2 cm and 0.5 degrees with confidence 0.85-0.98,
      except about 4 times a minute, when it jumps 0.3-1 m and 10-30 degrees away for 1-2.5 s with
      confidence 0.02-0.15 (:func:`~heatpf_jax.sim.world.localisation_poses`).

    ``two_balls``, ``shot`` and ``turning`` make the same world (paths, poses) at every ``shrink``.
    See :func:`simulate_with_info` for the arguments.
    """
    return simulate_with_info(scenario, seed, num_steps=num_steps, dt=dt, shrink=shrink, rgb=rgb)[0]


def simulate_standard(seed: int, num_steps: int = 300, dt: float = 0.1, *, shrink: int = 1) -> Sequence:
    """The paper's Table I setting: a static robot, a heat map every filter step.

    Camera 0.6 m high, pitched down 30 degrees; a ball rolling on a smooth random path in front of it
    at up to 3 m/s. Same as ``simulate("standard", seed, ...)``.

    Args:
        seed: seed of the path and the activation noise.
        num_steps: T.
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view), for quick tests.
    """
    return simulate("standard", seed, num_steps=num_steps, dt=dt, shrink=shrink)
