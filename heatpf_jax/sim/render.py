"""Heat-map rendering: FCNN-like activations over the projected discs of ball-sized objects.

A rendered object is a soft (Gaussian) blob centred on the projection of the object's centre whose
size follows perspective (apparent radius ``fx * r / depth``), plus Gaussian activation noise, clipped
to ``[0, 1]`` and stored as float32. Several objects in one frame combine by their maximum (a detector's
activation saturates, it does not add up). NumPy only.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BALL_RADIUS",
    "DEFAULT_INTRINSICS",
    "HEATMAP_SHAPE",
    "blob",
    "compose_frame",
    "project_centre",
    "render_heatmap",
    "scaled_camera",
    "stripe_mask",
]

# 200 x 150 heat map (the paper's FCNN input size) with a ~70 degree horizontal field of view.
DEFAULT_INTRINSICS = np.array([143.0, 143.0, 99.5, 74.5])
HEATMAP_SHAPE = (150, 200)
BALL_RADIUS = 0.075

# Closer than this (optical depth, metres) an object is not rendered.
_MIN_DEPTH = 0.05


def scaled_camera(shrink: int = 1) -> tuple[np.ndarray, tuple[int, int]]:
    """Intrinsics and heat-map shape for the 200 x 150 camera divided by ``shrink`` (same field of view).

    Pixel centres stay at integer coordinates: the new pixel ``u'`` covers old pixels
    ``shrink * u' ... shrink * u' + shrink - 1``.
    """
    shrink = int(shrink)
    offset = (shrink - 1) / 2.0
    intrinsics = np.array([DEFAULT_INTRINSICS[0] / shrink, DEFAULT_INTRINSICS[1] / shrink,
                           (DEFAULT_INTRINSICS[2] - offset) / shrink, (DEFAULT_INTRINSICS[3] - offset) / shrink])
    shape = (HEATMAP_SHAPE[0] // shrink, HEATMAP_SHAPE[1] // shrink)
    return intrinsics, shape


def project_centre(centre: np.ndarray, intrinsics: np.ndarray, cam_to_base: np.ndarray) -> tuple[float, float, float]:
    """Pixel ``(u, v)`` and optical depth of one base-frame point ``[3]``."""
    fx, fy, cx, cy = intrinsics
    rot, trans = cam_to_base[:3, :3], cam_to_base[:3, 3]
    p_cam = rot.T @ (np.asarray(centre, np.float64) - trans)
    depth = float(p_cam[2])
    safe = depth if abs(depth) > 1e-12 else 1e-12
    return float(fx * p_cam[0] / safe + cx), float(fy * p_cam[1] / safe + cy), depth


def blob(
    centre: np.ndarray,
    radius: float,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    peak: float,
) -> np.ndarray:
    """The noise-free activation of one object: a Gaussian of std ``max(0.6 * radius_px, 0.7)`` pixels.

    Args:
        centre: ``[3]`` object centre in the base frame (a ball lies at height ``radius``).
        radius: object radius, metres.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose used for rendering (the true one).
        shape: ``(H, W)``.
        peak: activation at the blob centre.

    Returns:
        ``float64 [H, W]``, zeros when the object is behind (or almost at) the camera.
    """
    h, w = shape
    u0, v0, depth = project_centre(centre, intrinsics, cam_to_base)
    if depth <= _MIN_DEPTH:
        return np.zeros(shape)
    radius_px = intrinsics[0] * radius / depth
    sigma = max(0.6 * radius_px, 0.7)
    vv, uu = np.mgrid[0:h, 0:w]
    return peak * np.exp(-0.5 * ((uu - u0) ** 2 + (vv - v0) ** 2) / sigma**2)


def stripe_mask(
    shape: tuple[int, int], u0: float, v0: float, angle: float, offset: float, width: float
) -> np.ndarray:
    """A multiplicative mask that zeroes a straight band (an occluder in front of the object).

    The band's centre line passes ``offset`` pixels (signed, perpendicular) from ``(u0, v0)``;
    ``angle`` is its tilt from the image vertical in radians; ``width`` its full width in pixels.

    Returns:
        ``float64 [H, W]`` with 0 inside the band and 1 elsewhere.
    """
    h, w = shape
    vv, uu = np.mgrid[0:h, 0:w]
    # Signed distance from the band's centre line along its normal (cos a, -sin a) in (u, v).
    dist = (uu - u0) * np.cos(angle) - (vv - v0) * np.sin(angle) - offset
    return (np.abs(dist) > 0.5 * width).astype(np.float64)


def compose_frame(rng: np.random.Generator, activation: np.ndarray, noise: float) -> np.ndarray:
    """Adds Gaussian activation noise (std ``noise``) and clips to a ``float32`` heat map in ``[0, 1]``."""
    heat = activation + noise * rng.standard_normal(activation.shape)
    return np.clip(heat, 0.0, 1.0).astype(np.float32)


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

    Args:
        rng: source of the activation noise.
        ball_xy: ``[2]`` ball centre on the ground in the base frame (the centre is at height ``ball_radius``).
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose.
        ball_radius: metres.
        shape: ``(H, W)``.
        peak: activation at the blob centre.
        noise: std of the additive activation noise.

    Returns:
        ``float32 [H, W]`` activations in ``[0, 1]``.
    """
    centre = np.array([ball_xy[0], ball_xy[1], ball_radius])
    return compose_frame(rng, blob(centre, ball_radius, intrinsics, cam_to_base, shape, peak), noise)
