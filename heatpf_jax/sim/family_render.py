"""The rendering of a planned world family member into a version-1 sequence and its info dict.

``_render`` draws the heat maps of a ``_World`` (:mod:`heatpf_jax.sim.family_plan`) with the detector
model (:mod:`heatpf_jax.sim.detector`) at the requested ``shrink`` and latency, from the member's stream 2
(the detector's noise), and reports what each heat map shows. Private to the family (no public names).
NumPy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from heatpf_jax.io.sequence import Sequence, validate_sequence
from heatpf_jax.sim.detector import DetectorFactors, SceneObject, clutter_field, render_frame, sphere_outline
from heatpf_jax.sim.family_factors import _rng
from heatpf_jax.sim.family_plan import _full_camera, _shrunk, _World
from heatpf_jax.sim.render import BALL_RADIUS, HEATMAP_SHAPE
from heatpf_jax.sim.world import odometry_from_poses, world_to_base

__all__: list[str] = []

# --- Rendering ----------------------------------------------------------------------------------------------------


def _in_image(centre: np.ndarray, radius: float, intrinsics, cam, shape) -> bool:
    outline = sphere_outline(centre, radius, intrinsics, cam)
    if outline is None:
        return False
    u, v = outline[0]
    return 0.0 <= u <= shape[1] - 1 and 0.0 <= v <= shape[0] - 1


def _render(w: _World, f: Mapping[str, Any], seed: int, member: str, num_steps: int, dt: float, shrink: int):
    intrinsics, shape = _shrunk(_full_camera(f), shrink)
    det = DetectorFactors(**{name: f[name] for name in DetectorFactors._fields})
    noise = _rng(seed, member, 2)
    latency = int(f["latency_steps"])
    render_step = np.maximum(np.arange(num_steps) - latency, 0)
    pose = w.robot_pose
    truth = np.stack([world_to_base(pose[t], w.motion.positions[t]) for t in range(num_steps)])
    heatmaps = np.zeros((num_steps, *shape), np.float32)
    in_view = np.zeros(num_steps, bool)
    k_all = w.fp_radius.shape[0]
    fp_on = np.zeros((num_steps, k_all), bool)
    fp_peak = np.zeros((num_steps, k_all))
    length = det.clutter_length_px * shape[1] / HEATMAP_SHAPE[1]
    rho = det.clutter_persistence
    field = clutter_field(noise, shape, length) if det.clutter_strength > 0 else None
    for t in range(num_steps):
        if field is not None and t > 0:
            field = rho * field + np.sqrt(1.0 - rho**2) * clutter_field(noise, shape, length)
        s = render_step[t]
        cam = w.true_cam[s]
        ball = np.r_[truth[s], BALL_RADIUS + w.motion.heights[s]]
        in_view[t] = _in_image(ball, BALL_RADIUS, intrinsics, cam, shape)
        if not w.has_heatmap[t]:
            continue
        objects = []
        if w.ball_on[s]:
            objects.append(SceneObject(ball, BALL_RADIUS, float(w.ball_peak[s]), "ball", w.occluder[s]))
        if k_all:
            places = world_to_base(pose[s], w.fp_path[s])
            for k in np.flatnonzero(w.fp_peak[s] > 0):
                centre = np.r_[places[k], w.fp_radius[k]]
                objects.append(SceneObject(centre, float(w.fp_radius[k]), float(w.fp_peak[s, k]), "false_positive"))
                fp_on[t, k] = _in_image(centre, w.fp_radius[k], intrinsics, cam, shape)
                fp_peak[t, k] = w.fp_peak[s, k] if fp_on[t, k] else 0.0
        heatmaps[t] = render_frame(noise, objects, intrinsics, cam, shape, det, clutter=field)
    has = w.has_heatmap
    ball_on = w.ball_on[render_step]
    visible = has & ball_on & in_view
    true_odom = odometry_from_poses(pose)
    seq = Sequence(
        heatmaps=heatmaps,
        has_heatmap=has.copy(),
        intrinsics=intrinsics,
        cam_to_base=w.given_cam.copy(),
        odometry=w.given_odometry.copy(),
        ball_radius=np.asarray(BALL_RADIUS),
        dt=np.asarray(float(dt)),
        ground_truth=truth,
    )
    occluded_part = np.array([w.occluder[s] is not None for s in render_step]) & visible
    info = {
        "robot_pose": pose.copy(),
        "ball_world": w.motion.positions.copy(),
        "ball_height": w.motion.heights.copy(),
        "in_air": w.motion.in_air.copy(),
        "ball_speed": np.hypot(w.motion.velocities[:, 0], w.motion.velocities[:, 1]),
        "ball_events": w.motion.events,
        "obstacles": w.motion.obstacles.copy(),
        "obstacle_steps": w.motion.obstacle_steps.copy(),
        "true_odometry": true_odom,
        "true_cam_to_base": w.true_cam.copy(),
        "render_step": render_step,
        "in_view": in_view,
        "occluded": ~ball_on,
        "visible": visible,
        "ball_peak": np.where(visible, w.ball_peak[render_step], 0.0),
        "split": visible & w.split[render_step],
        "partly_occluded": occluded_part & ~w.split[render_step],
        "false_positive_world": w.fp_path[0].copy(),
        "false_positive_path": w.fp_path.copy(),
        "false_positive_radius": w.fp_radius.copy(),
        "false_positive_on": fp_on,
        "false_positive_peak": fp_peak,
        "false_positive_count": fp_on.sum(axis=1).astype(np.int64),
        "balls_base": truth[:, None].copy(),
        "balls_visible": visible[:, None].copy(),
        **w.extra_info,
    }
    return validate_sequence(seq), info
