"""A small simulated world: a head camera watching a ball roll, rendered as FCNN-like heat maps.

NumPy only (it makes data; it is not part of the filter). Conventions follow the
sequence-file contract, so ``project_heatmap`` of a rendered frame lands on the ball.
"""

from __future__ import annotations

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.sequence import Sequence

__all__ = ["DEFAULT_INTRINSICS", "ball_path", "render_heatmap", "simulate_standard"]

# 200 x 150 heat map (the paper's FCNN input size) with a ~70 degree horizontal field of view.
DEFAULT_INTRINSICS = np.array([143.0, 143.0, 99.5, 74.5])
HEATMAP_SHAPE = (150, 200)
BALL_RADIUS = 0.075


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
    speed = np.linalg.norm(np.diff(path, axis=0), axis=1).max(initial=0.0) / dt
    if speed > max_speed:  # a slower replay of the same curve
        return _resample(path, speed / max_speed)
    return path


def _resample(path: np.ndarray, factor: float) -> np.ndarray:
    n = path.shape[0]
    s = np.arange(n) / factor
    return np.stack([np.interp(s, np.arange(n), path[:, i]) for i in range(2)], axis=-1)


def render_heatmap(
    rng: np.random.Generator,
    ball_xy: np.ndarray,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    *,
    ball_radius: float = BALL_RADIUS,
    shape: tuple[int, int] = HEATMAP_SHAPE,
    peak: float = 0.9,
    noise: float = 0.03,
) -> np.ndarray:
    """A soft blob over the ball's projected disc (size follows perspective), plus activation noise.

    Returns:
        ``float32 [H, W]`` activations in ``[0, 1]``.
    """
    h, w = shape
    fx, fy, cx, cy = intrinsics
    centre = np.array([ball_xy[0], ball_xy[1], ball_radius])
    rot, trans = cam_to_base[:3, :3], cam_to_base[:3, 3]
    p_cam = rot.T @ (centre - trans)
    heat = np.zeros(shape)
    if p_cam[2] > 0.05:
        u0 = fx * p_cam[0] / p_cam[2] + cx
        v0 = fy * p_cam[1] / p_cam[2] + cy
        radius_px = fx * ball_radius / p_cam[2]
        sigma = max(0.6 * radius_px, 0.7)
        vv, uu = np.mgrid[0:h, 0:w]
        heat = peak * np.exp(-0.5 * ((uu - u0) ** 2 + (vv - v0) ** 2) / sigma**2)
    heat = heat + noise * rng.standard_normal(shape)
    return np.clip(heat, 0.0, 1.0).astype(np.float32)


def simulate_standard(seed: int, num_steps: int = 300, dt: float = 0.1, *, shrink: int = 1) -> Sequence:
    """The paper's Table I setting: a static robot, a heat map every filter step.

    Camera 0.6 m high, pitched down 30 degrees; a ball rolling on a smooth
    random path in front of it at up to 3 m/s.

    Args:
        seed: seed of the path and the activation noise.
        num_steps: T.
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view),
            for quick tests.
    """
    rng = np.random.default_rng(seed)
    pose = camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    path = ball_path(rng, num_steps, dt)
    offset = (shrink - 1) / 2.0
    intrinsics = np.array([DEFAULT_INTRINSICS[0] / shrink, DEFAULT_INTRINSICS[1] / shrink,
                           (DEFAULT_INTRINSICS[2] - offset) / shrink, (DEFAULT_INTRINSICS[3] - offset) / shrink])
    shape = (HEATMAP_SHAPE[0] // shrink, HEATMAP_SHAPE[1] // shrink)
    heatmaps = np.stack([render_heatmap(rng, p, intrinsics, pose, shape=shape) for p in path])
    return Sequence(
        heatmaps=heatmaps,
        has_heatmap=np.ones(num_steps, bool),
        intrinsics=intrinsics,
        cam_to_base=np.repeat(pose[None], num_steps, axis=0),
        odometry=np.zeros((num_steps, 3)),
        ball_radius=np.asarray(BALL_RADIUS),
        dt=np.asarray(dt),
        ground_truth=path,
    )
