"""Pinhole camera geometry: pixel rays, ray/plane intersection, back-projection.

Section III-A and Fig. 3 of Fiedler et al.: a ray from the camera pose through a
heat-map pixel meets the plane ``z = plane_height`` (the ball radius, to correct
the perspective error of a ball that is not flat on the floor).

Conventions (sequence file version 1):

* base frame: x forward, y left, z up, ground plane ``z = 0``;
* camera optical frame: x right, y down, z forward;
* ``cam_to_base`` is the 4x4 rigid transform with ``p_base = R @ p_cam + t``;
* ``intrinsics = (fx, fy, cx, cy)`` in pixels; pixel ``(u, v)`` is (column, row)
  and pixel centres sit at integer coordinates.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

__all__ = [
    "OPTICAL_TO_BODY",
    "camera_pose",
    "ground_jacobian",
    "pixel_ray",
    "project_pixel",
    "project_points",
]

# Columns: the optical x (right), y (down) and z (forward) axes expressed in a
# body frame with x forward, y left, z up.
OPTICAL_TO_BODY = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def camera_pose(
    *,
    height: float,
    pitch: float,
    yaw: float = 0.0,
    roll: float = 0.0,
    x: float = 0.0,
    y: float = 0.0,
) -> np.ndarray:
    """Builds a ``cam_to_base`` transform for a camera at a given height and attitude.

    Args:
        height: camera centre height above the ground, metres.
        pitch: downward tilt of the optical axis, radians (positive looks down).
        yaw: heading of the optical axis about base z, radians (positive turns left).
        roll: rotation about the optical axis, radians.
        x: camera centre x in the base frame, metres.
        y: camera centre y in the base frame, metres.

    Returns:
        ``float64 [4, 4]`` rigid transform from the optical frame to the base frame.
    """
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    # Positive pitch turns the forward axis x towards -z (looking down).
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    pose = np.eye(4)
    pose[:3, :3] = rz @ ry @ rx @ OPTICAL_TO_BODY
    pose[:3, 3] = (x, y, height)
    return pose


def pixel_ray(
    uv: Float[ArrayLike, "2"], intrinsics: Float[ArrayLike, "4"]
) -> Float[Array, "3"]:
    """Direction of the ray through pixel centre ``uv`` in the optical frame (z = 1)."""
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    return jnp.stack([(uv[0] - cx) / fx, (uv[1] - cy) / fy, jnp.ones_like(uv[0])])


def project_pixel(
    uv: Float[ArrayLike, "2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    plane_height: Float[ArrayLike, ""],
    max_distance: Float[ArrayLike, ""] = jnp.inf,
) -> tuple[Float[Array, "2"], Bool[Array, ""]]:
    """Intersects the ray through one pixel with the plane ``z = plane_height`` (Fig. 3).

    Written for a single pixel; ``jax.vmap`` it over pixels.

    Args:
        uv: pixel centre (column, row).
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        plane_height: height of the intersection plane, metres.
        max_distance: intersections farther than this from the base origin
            (horizontal distance) are invalid.

    Returns:
        ``(xy, valid)``: the intersection's base-frame ``(x, y)`` and whether the
        ray meets the plane in front of the camera within ``max_distance``.
        Invalid rays return ``xy = (0, 0)``.
    """
    cam_to_base = jnp.asarray(cam_to_base)
    direction = cam_to_base[:3, :3] @ pixel_ray(uv, intrinsics)
    origin = cam_to_base[:3, 3]
    dz = direction[2]
    hits = jnp.abs(dz) > 1e-9
    scale = (plane_height - origin[2]) / jnp.where(hits, dz, 1.0)
    xy = origin[:2] + scale * direction[:2]
    valid = hits & (scale > 0.0)
    # Guarded norm: its gradient stays finite at the origin.
    sq = jnp.sum(xy**2)
    dist = jnp.where(sq > 0.0, jnp.sqrt(jnp.where(sq > 0.0, sq, 1.0)), 0.0)
    valid = valid & (dist <= max_distance) & jnp.all(jnp.isfinite(xy))
    return jnp.where(valid, xy, 0.0), valid


def ground_jacobian(
    uv: Float[ArrayLike, "2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    plane_height: Float[ArrayLike, ""],
) -> Float[Array, "2 2"]:
    """Jacobian of :func:`project_pixel` at pixel ``uv``: ground metres per pixel, columns ``d xy / du``, ``d xy / dv``.

    With the base-frame ray ``d = R ((u - cx) / fx, (v - cy) / fy, 1)``, the scale ``s = (h - o_z) / d_z``
    and the hit ``xy = o_xy + s d_xy``, a change ``dd`` of the ray moves the hit by
    ``s (dd_xy - d_xy dd_z / d_z)``, with ``dd = R[:, 0] / fx`` per column ``u`` and ``R[:, 1] / fy`` per row
    ``v``. Its columns are the ground spacing of neighbouring pixels to first order: at a few metres
    the row step (``v``, radial) is many times the column step (``u``, lateral). Rays that miss the
    plane or meet it behind the camera give zeros. Written for a single pixel; ``jax.vmap`` it.

    Args:
        uv: pixel centre (column, row).
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        plane_height: height of the intersection plane, metres.

    Returns:
        ``[2, 2]`` Jacobian ``d (x, y) / d (u, v)``, metres per pixel.
    """
    cam_to_base = jnp.asarray(cam_to_base)
    rot = cam_to_base[:3, :3]
    direction = rot @ pixel_ray(uv, intrinsics)
    dz = direction[2]
    hits = jnp.abs(dz) > 1e-9
    safe_dz = jnp.where(hits, dz, 1.0)
    scale = (plane_height - cam_to_base[2, 3]) / safe_dz
    steps = rot[:, :2] / jnp.stack([intrinsics[0], intrinsics[1]])[None, :]  # [3, 2]: d direction / d (u, v)
    jac = scale * (steps[:2] - direction[:2, None] * steps[2][None, :] / safe_dz)
    ok = hits & (scale > 0.0) & jnp.all(jnp.isfinite(jac))
    return jnp.where(ok, jac, 0.0)


def project_points(
    points: Float[ArrayLike, "n 3"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
) -> tuple[Float[Array, "n 2"], Float[Array, " n"]]:
    """Projects base-frame points into the image (the inverse of :func:`project_pixel`).

    Args:
        points: ``[n, 3]`` points in the base frame.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose.

    Returns:
        ``(uv, depth)``: pixel coordinates ``[n, 2]`` and optical-frame depth
        ``[n]`` (points with ``depth <= 0`` are behind the camera).
    """
    points = jnp.asarray(points)
    cam_to_base = jnp.asarray(cam_to_base)
    rot, trans = cam_to_base[:3, :3], cam_to_base[:3, 3]
    p_cam = (points - trans[None, :]) @ rot  # R^T (p - t), row-wise
    depth = p_cam[:, 2]
    safe = jnp.where(jnp.abs(depth) > 1e-12, depth, 1e-12)
    u = intrinsics[0] * p_cam[:, 0] / safe + intrinsics[2]
    v = intrinsics[1] * p_cam[:, 1] / safe + intrinsics[3]
    return jnp.stack([u, v], axis=-1), depth
