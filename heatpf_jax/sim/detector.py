"""A randomised detector: heat maps whose blob shape, background and artefacts are drawn per world.

:func:`render_frame` draws one heat map of a list of :class:`SceneObject` (spheres in the base frame) with
the factors of a :class:`DetectorFactors`; :func:`draw_detector` draws those factors from the documented
ranges (:data:`DETECTOR_RANGES`). ``DetectorFactors()`` (the defaults) is the fixed renderer of
:mod:`heatpf_jax.sim.render`: a Gaussian blob of std 0.6 times the apparent radius, peak 0.9, noise 0.03.

The blob follows the sphere's true outline in perspective. The rays that touch a sphere of radius ``r``
and optical-frame centre ``C`` form the cone ``(d . C)^2 = |d|^2 (|C|^2 - r^2)``; through the intrinsics
``K`` it is the image conic ``p^T K^-T (C C^T - (|C|^2 - r^2) I) K^-1 p = 0``, an ellipse elongated
radially away from the principal point (by ``1 / cos`` of the angle off the optical axis) whose centre
lies slightly outside the projection of ``C``. :func:`sphere_outline` returns its centre and shape
matrix; the blob's shape value at pixel ``p`` depends on ``s^2 = (p - c)^T S (p - c)`` (``s = 1`` on the
outline).

| factor              | range                | meaning                                                            |
|---------------------|----------------------|--------------------------------------------------------------------|
| blob_shape          | gaussian, disc       | a Gaussian over the outline, or the filled outline (anti-aliased)  |
| softness            | 0.35-0.9             | Gaussian std per axis as a fraction of the outline's semi-axis      |
| size_scale          | 0.8-1.3              | blob size over the sphere's true outline                           |
| saturation          | 0-4                  | gain ``g`` of ``tanh(g f) / tanh(g)`` on the shape value (0: linear) |
| blur_px             | 0-1.5                | std of a Gaussian blur of the objects, px of the 200 x 150 map     |
| peak                | 0.4-1                | the ball blob's peak activation                                     |
| peak_jitter         | 0-0.1                | std of the per-frame change of the peak (applied by the caller)     |
| occlusion_rate      | 0-0.3                | share of frames with a partly occluded ball (applied by the caller) |
| dropout             | 0-0.2                | share of the objects' pixels dropped (set to 0) per frame          |
| noise               | 0.01-0.06            | std of the additive Gaussian activation noise                       |
| clutter_strength    | 0-0.3                | the clutter field's level at 2 sigma (its positive part, capped)    |
| clutter_length_px   | 2-20                 | the clutter's correlation length (Gaussian std), px of 200 x 150    |
| clutter_persistence | 0-0.95               | AR(1) coefficient of the clutter from frame to frame (the caller's) |
| speckle_density     | 0-0.002              | share of pixels lit by speckle per frame                            |
| speckle_peak        | 0.3-1                | the brightest speckle (each lit pixel ``U(0.5, 1)`` times it)       |
| line_rate           | 0-0.03               | share of rows and of columns raised per frame                       |
| line_strength       | 0-0.15               | how much a raised row or column is raised (``U(0.5, 1)`` times it)  |

Pixel-sized factors are given in pixels of the 200 x 150 heat map and scaled to the frame's width. The
frame is ``clip(max(objects) + clutter + lines + noise, 0, 1)`` with speckle combined by the maximum;
objects combine by their maximum (a detector saturates, it does not add up). NumPy only.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from heatpf_jax.sim.render import HEATMAP_SHAPE

__all__ = [
    "DETECTOR_RANGES",
    "DetectorFactors",
    "Occluder",
    "SceneObject",
    "clutter_field",
    "draw_detector",
    "object_blob",
    "render_frame",
    "smooth",
    "sphere_outline",
]

# Closer than this (optical depth over radius) a sphere is not rendered: the outline is no ellipse.
_MIN_DEPTH_RADII = 1.2
_MIN_SIGMA_PX = 0.7  # the thinnest Gaussian blob, as in heatpf_jax.sim.render.blob


class DetectorFactors(NamedTuple):
    """The drawn factors of a detector (ranges in :data:`DETECTOR_RANGES`; defaults: the fixed renderer)."""

    blob_shape: str = "gaussian"  # "gaussian" or "disc"
    softness: float = 0.6  # Gaussian std / outline semi-axis
    size_scale: float = 1.0  # blob size / true outline
    saturation: float = 0.0  # tanh gain, 0 = linear
    blur_px: float = 0.0  # Gaussian blur std, px of the 200 x 150 map
    peak: float = 0.9  # the ball's peak activation
    peak_jitter: float = 0.0  # per-frame std of the peak
    occlusion_rate: float = 0.0  # share of frames with a partly occluded ball
    dropout: float = 0.0  # share of object pixels dropped
    noise: float = 0.03  # activation noise std
    clutter_strength: float = 0.0  # clutter level at 2 sigma
    clutter_length_px: float = 8.0  # clutter correlation length, px of the 200 x 150 map
    clutter_persistence: float = 0.0  # AR(1) coefficient of the clutter over frames
    speckle_density: float = 0.0  # share of pixels lit by speckle
    speckle_peak: float = 0.5  # brightest speckle
    line_rate: float = 0.0  # share of rows / columns raised
    line_strength: float = 0.0  # how much they are raised


# name -> (low, high) for a uniform draw, or a tuple of strings for a uniform choice.
DETECTOR_RANGES: dict[str, tuple] = {
    "blob_shape": ("gaussian", "disc"),
    "softness": (0.35, 0.9),
    "size_scale": (0.8, 1.3),
    "saturation": (0.0, 4.0),
    "blur_px": (0.0, 1.5),
    "peak": (0.4, 1.0),
    "peak_jitter": (0.0, 0.1),
    "occlusion_rate": (0.0, 0.3),
    "dropout": (0.0, 0.2),
    "noise": (0.01, 0.06),
    "clutter_strength": (0.0, 0.3),
    "clutter_length_px": (2.0, 20.0),
    "clutter_persistence": (0.0, 0.95),
    "speckle_density": (0.0, 0.002),
    "speckle_peak": (0.3, 1.0),
    "line_rate": (0.0, 0.03),
    "line_strength": (0.0, 0.15),
}


class Occluder(NamedTuple):
    """Something in front of an object that hides part of its blob.

    Distances are in the blob's mean outline radius, measured along the normal ``(cos a, -sin a)`` (in
    ``(u, v)``) of a line tilted ``angle`` radians from the image vertical. With a finite ``width`` the
    band ``|dist - offset| < width / 2`` is hidden (a leg, a post: the blob is cut in two); with
    ``width = inf`` the half plane ``dist > offset`` is hidden (the object is partly behind an edge).
    """

    angle: float
    offset: float
    width: float


class SceneObject(NamedTuple):
    """A sphere the detector responds to.

    Attributes:
        centre: ``[3]`` centre in the base frame (a ball on the ground lies at height ``radius``).
        radius: metres.
        peak: activation at the blob's centre (after saturation), in ``[0, 1]``.
        kind: what it is (``"ball"``, ``"false_positive"``, ``"distractor"``): for the record only.
        occluder: an optional :class:`Occluder` of its blob.
    """

    centre: np.ndarray
    radius: float
    peak: float
    kind: str = "ball"
    occluder: Occluder | None = None


def draw_detector(rng: np.random.Generator, ranges: dict[str, tuple] | None = None) -> DetectorFactors:
    """Draws every factor uniformly from its range, in the order of :class:`DetectorFactors`.

    Args:
        rng: the source of the draws (one draw per factor, so a changed range keeps the other draws).
        ranges: ``name -> (low, high)`` or ``name -> (choice, ...)`` replacing some of
            :data:`DETECTOR_RANGES`; a range with ``low == high`` pins the factor.

    Returns:
        The drawn factors.
    """
    merged = {**DETECTOR_RANGES, **(ranges or {})}
    unknown = set(merged) - set(DetectorFactors._fields)
    if unknown:
        raise ValueError(f"ranges: unknown detector factors {sorted(unknown)}")
    values = {}
    for name in DetectorFactors._fields:
        spec = merged[name]
        if isinstance(spec[0], str):
            values[name] = str(spec[int(rng.integers(len(spec)))])
        else:
            values[name] = float(rng.uniform(spec[0], spec[1]))
    return DetectorFactors(**values)


# --- Geometry -----------------------------------------------------------------------------------------------------


def sphere_outline(
    centre: np.ndarray, radius: float, intrinsics: np.ndarray, cam_to_base: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """The image ellipse of a sphere (its exact perspective outline).

    Args:
        centre: ``[3]`` sphere centre in the base frame.
        radius: metres.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose.

    Returns:
        ``(c, S)``: the ellipse's centre ``[2]`` (pixels ``(u, v)``) and its ``[2, 2]`` shape matrix, with
        ``(p - c)^T S (p - c) = 1`` on the outline; ``None`` when the sphere is not wholly in front of the
        camera (optical depth below 1.2 radii).
    """
    fx, fy, cx, cy = (float(v) for v in intrinsics)
    rot, trans = cam_to_base[:3, :3], cam_to_base[:3, 3]
    c_cam = rot.T @ (np.asarray(centre, np.float64) - trans)
    if c_cam[2] <= _MIN_DEPTH_RADII * radius:
        return None
    cone = np.outer(c_cam, c_cam) - (c_cam @ c_cam - radius**2) * np.eye(3)
    k_inv = np.array([[1.0 / fx, 0.0, -cx / fx], [0.0, 1.0 / fy, -cy / fy], [0.0, 0.0, 1.0]])
    conic = -(k_inv.T @ cone @ k_inv)  # negative inside the outline
    a, b, c = conic[:2, :2], conic[:2, 2], conic[2, 2]
    centre_px = -np.linalg.solve(a, b)
    level = b @ np.linalg.solve(a, b) - c
    return centre_px, a / level


def _grid(shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    vv, uu = np.mgrid[0 : shape[0], 0 : shape[1]]
    return uu.astype(np.float64), vv.astype(np.float64)


def object_blob(
    obj: SceneObject,
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    factors: DetectorFactors,
) -> np.ndarray:
    """The noise-free activation of one object, before blur and dropout.

    The shape value ``f`` is ``exp(-0.5 d^T Sigma^-1 d)`` (``gaussian``: ``Sigma`` shares the outline's
    axes, with std ``softness * size_scale`` times each semi-axis, at least 0.7 px) or the outline's
    inside, anti-aliased over one pixel (``disc``: ``size_scale`` times the outline); then
    ``tanh(g f) / tanh(g)`` with ``g = saturation``, the occluder's mask, and times ``peak``.

    Returns:
        ``float64 [H, W]`` in ``[0, peak]``; zeros when the object is not wholly in front of the camera.
    """
    outline = sphere_outline(obj.centre, obj.radius, intrinsics, cam_to_base)
    if outline is None:
        return np.zeros(shape)
    centre_px, s_mat = outline
    eig, vec = np.linalg.eigh(s_mat)
    semi = factors.size_scale / np.sqrt(np.maximum(eig, 1e-12))  # the blob outline's semi-axes, px
    uu, vv = _grid(shape)
    du, dv = uu - centre_px[0], vv - centre_px[1]
    # Coordinates along the ellipse's axes.
    a1 = du * vec[0, 0] + dv * vec[1, 0]
    a2 = du * vec[0, 1] + dv * vec[1, 1]
    if factors.blob_shape == "gaussian":
        sig = np.maximum(factors.softness * semi, _MIN_SIGMA_PX)
        f = np.exp(-0.5 * ((a1 / sig[0]) ** 2 + (a2 / sig[1]) ** 2))
    elif factors.blob_shape == "disc":
        rho = np.sqrt((a1 / semi[0]) ** 2 + (a2 / semi[1]) ** 2)  # 1 on the outline
        dist = np.hypot(a1, a2) * (1.0 - 1.0 / np.maximum(rho, 1e-12))  # signed px to the outline along the ray
        f = np.clip(0.5 - dist, 0.0, 1.0)
    else:
        raise ValueError(f"blob_shape: must be 'gaussian' or 'disc', got {factors.blob_shape!r}")
    if factors.saturation > 1e-6:
        f = np.tanh(factors.saturation * f) / np.tanh(factors.saturation)
    if obj.occluder is not None:
        angle, offset, width = obj.occluder
        mean_r = float(np.sqrt(semi[0] * semi[1]))
        dist = (du * np.cos(angle) - dv * np.sin(angle)) / max(mean_r, 1e-9) - offset
        hidden = dist > 0.0 if np.isinf(width) else np.abs(dist) < 0.5 * width
        f = np.where(hidden, 0.0, f)
    return obj.peak * f


# --- Smoothing and background -------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=64)
def _smoothing_matrix(n: int, sigma_key: float) -> np.ndarray:
    """``[n, n]`` Gaussian smoothing (std ``sigma_key`` px, kernel to 3 std) with reflecting edges."""
    sigma = float(sigma_key)
    half = int(3.0 * sigma + 0.5)  # scipy.ndimage's radius for truncate=3
    offsets = np.arange(-half, half + 1)
    kernel = np.exp(-0.5 * (offsets / sigma) ** 2)
    kernel /= kernel.sum()
    mat = np.zeros((n, n))
    rows = np.arange(n)
    for off, weight in zip(offsets, kernel, strict=True):
        cols = rows + off
        # Reflect about the edge pixels' outer sides (scipy's "reflect" mode): -1 -> 0, n -> n - 1.
        for _ in range(4):
            cols = np.where(cols < 0, -cols - 1, cols)
            cols = np.where(cols > n - 1, 2 * n - 1 - cols, cols)
        np.add.at(mat, (rows, cols), weight)
    mat.setflags(write=False)
    return mat


def smooth(image: np.ndarray, sigma: float) -> np.ndarray:
    """Separable Gaussian smoothing of ``[H, W]`` with std ``sigma`` px (reflecting edges; ``sigma <= 0``: a copy).

    Equal to ``scipy.ndimage.gaussian_filter(image, sigma, mode="reflect", truncate=3.0)``.
    """
    if sigma <= 1e-3:
        return np.array(image, np.float64)
    key = round(float(sigma), 4)
    rows = _smoothing_matrix(image.shape[0], key)
    cols = _smoothing_matrix(image.shape[1], key)
    return rows @ np.asarray(image, np.float64) @ cols.T


def clutter_field(rng: np.random.Generator, shape: tuple[int, int], length_px: float) -> np.ndarray:
    """Smooth Gaussian noise of unit std at every pixel and correlation length ``length_px`` (frame pixels).

    White noise smoothed by :func:`smooth` and divided by each pixel's exact std (the product of the
    smoothing rows' norms), so the edges are not weaker than the middle.

    Returns:
        ``float64 [H, W]``.
    """
    white = rng.standard_normal(shape)
    if length_px <= 1e-3:
        return white
    key = round(float(length_px), 4)
    rows, cols = _smoothing_matrix(shape[0], key), _smoothing_matrix(shape[1], key)
    norm = np.outer(np.linalg.norm(rows, axis=1), np.linalg.norm(cols, axis=1))
    return (rows @ white @ cols.T) / norm


def _px_scale(shape: tuple[int, int]) -> float:
    return shape[1] / HEATMAP_SHAPE[1]


def render_frame(
    rng: np.random.Generator,
    objects: Sequence[SceneObject],
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    factors: DetectorFactors,
    *,
    clutter: np.ndarray | None = None,
) -> np.ndarray:
    """One heat map of ``objects`` seen from ``cam_to_base`` by a detector with ``factors``.

    Args:
        rng: the source of this frame's dropout, artefacts, speckle and noise (and clutter, when not given).
        objects: the spheres in view (their blobs combine by the maximum).
        intrinsics: ``(fx, fy, cx, cy)`` of the frame.
        cam_to_base: ``[4, 4]`` the camera pose the frame is seen from (the true one).
        shape: ``(H, W)``.
        factors: the detector's factors (``peak_jitter``, ``occlusion_rate`` and ``clutter_persistence`` are
            the caller's: they act across frames).
        clutter: an optional unit-std clutter field ``[H, W]`` (for clutter that persists over frames);
            drawn fresh (:func:`clutter_field`) when ``None`` and ``clutter_strength > 0``.

    Returns:
        ``float32 [H, W]`` in ``[0, 1]``.
    """
    scale = _px_scale(shape)
    act = np.zeros(shape)
    for obj in objects:
        act = np.maximum(act, object_blob(obj, intrinsics, cam_to_base, shape, factors))
    act = smooth(act, factors.blur_px * scale)
    if factors.dropout > 0.0:
        act = act * (rng.uniform(size=shape) >= factors.dropout)
    heat = act
    if factors.clutter_strength > 0.0:
        field = clutter_field(rng, shape, factors.clutter_length_px * scale) if clutter is None else clutter
        heat = heat + factors.clutter_strength * np.clip(0.5 * field, 0.0, 1.0)
    if factors.line_rate > 0.0 and factors.line_strength > 0.0:
        rows = (rng.uniform(size=shape[0]) < factors.line_rate) * rng.uniform(0.5, 1.0, shape[0])
        cols = (rng.uniform(size=shape[1]) < factors.line_rate) * rng.uniform(0.5, 1.0, shape[1])
        heat = heat + factors.line_strength * (rows[:, None] + cols[None, :])
    heat = heat + factors.noise * rng.standard_normal(shape)
    if factors.speckle_density > 0.0:
        lit = rng.uniform(size=shape) < factors.speckle_density
        heat = np.where(lit, np.maximum(heat, factors.speckle_peak * rng.uniform(0.5, 1.0, shape)), heat)
    return np.clip(heat, 0.0, 1.0).astype(np.float32)
