"""The rendering of a named scenario's plan into a version-1 sequence and its info dict.

``_render`` draws the heat maps of a ``_Plan`` (:mod:`heatpf_jax.sim.scenarios_plan`): the ball blob (cut
by the split stripe where drawn, with its dropout), more balls and false positives, and the activation
noise, and reports what each heat map shows. Private to the scenarios (no public names). NumPy only.
"""

from __future__ import annotations

import numpy as np

from heatpf_jax.io.sequence import Sequence, validate_sequence
from heatpf_jax.sim.render import BALL_RADIUS, blob, compose_frame, project_centre, stripe_mask
from heatpf_jax.sim.scenarios_plan import BALL_PEAK, _Plan
from heatpf_jax.sim.world import odometry_from_poses, world_to_base

__all__: list[str] = []

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
