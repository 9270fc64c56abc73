"""Measurements from a heat map, and the fixed-size buffer that ages them.

Section III-A: every heat-map pixel with activation ``>= threshold`` is projected
onto the plane ``z = ball radius`` and becomes a measurement ``m = (r, w)`` with
``w`` the activation. Section III-C, eq. (2): when a filter step brings no new
measurements, the buffered ones age: ``w <- w - v``; measurements with
``w < l`` are removed. Section III-D: odometry moves buffered measurements too.

Each measurement also carries its pixel's ground *footprint* (the projection's Jacobian, metres per
pixel), which range-aware observation models (:mod:`heatpf_jax.observation.range_aware`) read.

Buffers have a fixed size with a ``valid`` mask so that every function here is
jittable and vmappable; invalid slots hold ``xy = 0, weight = 0, footprint = 0``.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

from heatpf_jax.camera import ground_jacobian, project_pixel
from heatpf_jax.frames import apply_odometry

__all__ = [
    "Measurements",
    "measurements_at",
    "strongest_pixels",
    "age_measurements",
    "downscale_heatmap",
    "empty_measurements",
    "move_measurements",
    "project_heatmap",
    "update_buffer",
]


class _MeasurementFields(NamedTuple):
    xy: Float[Array, "m 2"]
    weight: Float[Array, " m"]
    valid: Bool[Array, " m"]
    footprint: Float[Array, "m 2 2"] | None = None


class Measurements(_MeasurementFields):
    """A fixed-size, padded set of ground-plane measurements.

    ``Measurements(xy, weight, valid)`` (three fields, as before the footprint existed) builds measurements
    without a pixel footprint: ``footprint`` is then zeros, as for sources without pixels.

    Attributes:
        xy: ``float32 [M, 2]`` positions in the base frame, metres.
        weight: ``float32 [M]`` weights (heat-map activations, aged).
        valid: ``bool [M]`` which slots hold a measurement.
        footprint: ``float32 [M, 2, 2]`` the ground spacing of each measurement's pixel: the Jacobian
            ``d (x, y) / d (u, v)`` of its projection (:func:`~heatpf_jax.camera.ground_jacobian`), metres
            per pixel; column 0 is the ground step of one pixel to the right (lateral), column 1 of one
            row down (radial, several times longer far away). Zeros in invalid slots and for sources
            without pixels (the default). Odometry turns it with the base frame; aging leaves it unchanged.
    """

    __slots__ = ()

    def __new__(cls, xy, weight, valid, footprint=None):
        if footprint is None and getattr(xy, "ndim", 0) >= 1:  # not when JAX rebuilds a tree of other leaves
            footprint = jnp.zeros((*xy.shape[:-1], 2, 2), getattr(xy, "dtype", jnp.float32))
        return super().__new__(cls, xy, weight, valid, footprint)


def empty_measurements(size: int) -> Measurements:
    """A buffer of ``size`` invalid slots."""
    return Measurements(
        xy=jnp.zeros((size, 2), jnp.float32),
        weight=jnp.zeros((size,), jnp.float32),
        valid=jnp.zeros((size,), bool),
        footprint=jnp.zeros((size, 2, 2), jnp.float32),
    )


def downscale_heatmap(
    heatmap: Float[ArrayLike, "h w"], intrinsics: Float[ArrayLike, "4"], factor: int
) -> tuple[Float[Array, "h2 w2"], Float[Array, "4"]]:
    """Averages ``factor x factor`` blocks (the paper's second way to cut |M|).

    Rows and columns that do not fill a whole block are dropped. The intrinsics
    are rescaled so that the new pixel ``(u', v')`` has its centre at the centre
    of its block: ``u = factor * u' + (factor - 1) / 2``.

    Args:
        heatmap: ``[H, W]`` activations.
        intrinsics: ``(fx, fy, cx, cy)`` of ``heatmap``.
        factor: static positive integer.

    Returns:
        ``(heatmap [H // factor, W // factor], intrinsics [4])``.
    """
    factor = int(factor)
    if factor < 1:
        raise ValueError(f"downscale: must be a positive integer, got {factor}")
    heatmap = jnp.asarray(heatmap)
    intrinsics = jnp.asarray(intrinsics)
    if factor == 1:
        return heatmap, intrinsics
    h, w = heatmap.shape
    h2, w2 = h // factor, w // factor
    if h2 == 0 or w2 == 0:
        raise ValueError(f"downscale: factor {factor} exceeds heat map shape {heatmap.shape}")
    blocks = heatmap[: h2 * factor, : w2 * factor].reshape(h2, factor, w2, factor)
    small = blocks.mean(axis=(1, 3))
    offset = (factor - 1) / 2.0
    fx, fy, cx, cy = intrinsics[0], intrinsics[1], intrinsics[2], intrinsics[3]
    new = jnp.stack([fx / factor, fy / factor, (cx - offset) / factor, (cy - offset) / factor])
    return small, new


def project_heatmap(
    heatmap: Float[ArrayLike, "h w"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    threshold: Float[ArrayLike, ""],
    plane_height: Float[ArrayLike, ""],
    max_measurements: int,
    max_distance: Float[ArrayLike, ""] = jnp.inf,
    downscale: int = 1,
) -> Measurements:
    """Projects every heat-map pixel at or above ``threshold`` onto the ground (III-A).

    Each pixel centre defines a ray from the camera; its intersection with the
    plane ``z = plane_height`` is the measurement's position, the pixel's
    activation its weight and the projection's Jacobian there its footprint.
    Rays that miss the plane, meet it behind the camera or farther than
    ``max_distance`` from the base origin are invalid. When more
    than ``max_measurements`` pixels pass, the highest activations are kept.
    Kept measurements are in raster order (row-major), valid ones first
    whenever all passing pixels fit.

    Args:
        heatmap: ``[H, W]`` activations in ``[0, 1]``.
        intrinsics: ``(fx, fy, cx, cy)`` in heat-map pixels.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        threshold: minimum activation (may be traced).
        plane_height: height of the projection plane (the ball radius), metres.
        max_measurements: static size of the returned buffer.
        max_distance: maximum horizontal distance from the base origin, metres.
        downscale: static integer block-averaging factor applied first.

    Returns:
        :class:`Measurements` of size ``max_measurements``.
    """
    heatmap, intrinsics = downscale_heatmap(heatmap, intrinsics, downscale)
    uv, passes, weight = strongest_pixels(heatmap, intrinsics, cam_to_base, threshold=threshold,
                                          plane_height=plane_height, max_measurements=max_measurements,
                                          max_distance=max_distance)
    return measurements_at(uv, passes, weight, intrinsics, cam_to_base, plane_height=plane_height,
                           max_measurements=max_measurements, max_distance=max_distance)


def strongest_pixels(
    heatmap: Float[ArrayLike, "h w"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    threshold: Float[ArrayLike, ""],
    plane_height: Float[ArrayLike, ""],
    max_measurements: int,
    max_distance: Float[ArrayLike, ""] = jnp.inf,
) -> tuple[Float[Array, "k 2"], Bool[Array, " k"], Float[Array, " k"]]:
    """The pixels :func:`project_heatmap` projects: at or above ``threshold`` with a ray that meets the plane.

    Returns:
        ``(uv, passes, activation)`` each of ``k = min(max_measurements, H W)`` entries: the strongest passing
        pixels (all of them when they fit) in raster order, passing ones first.
    """
    h, w = heatmap.shape
    n_pix = h * w
    act = jnp.asarray(heatmap, jnp.float32).ravel()
    passes = _rays_hit(h, w, intrinsics, cam_to_base, plane_height, max_distance).ravel() & (act >= threshold)

    # The strongest passing pixels (all of them when they fit), back in raster order. top_k over the
    # H*W scores is cheaper on XLA:CPU than a cumsum-based compaction.
    k = min(int(max_measurements), n_pix)
    _, idx = lax.top_k(jnp.where(passes, act, -1.0), k)
    # One sort puts the passing pixels first, in raster order, then the rest.
    idx = jnp.sort(jnp.where(passes[idx], idx, idx + n_pix)) % n_pix
    uv = jnp.stack([(idx % w).astype(jnp.float32), (idx // w).astype(jnp.float32)], axis=-1)
    return uv, passes[idx], act[idx]


def measurements_at(
    uv: Float[ArrayLike, "k 2"],
    passes: Bool[ArrayLike, " k"],
    weight: Float[ArrayLike, " k"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    plane_height: Float[ArrayLike, ""],
    max_measurements: int,
    max_distance: Float[ArrayLike, ""] = jnp.inf,
) -> Measurements:
    """Measurements at image points ``uv`` (any real pixel coordinates): their rays' hits on the plane, the
    given weights and the projection's Jacobian there, padded to ``max_measurements`` slots."""
    xy, ray_ok = jax.vmap(project_pixel, in_axes=(0, None, None, None, None))(
        uv, intrinsics, cam_to_base, plane_height, max_distance
    )
    valid = passes & ray_ok
    footprint = jax.vmap(ground_jacobian, in_axes=(0, None, None, None))(uv, intrinsics, cam_to_base, plane_height)
    pad = int(max_measurements) - uv.shape[0]
    return Measurements(
        xy=jnp.pad(jnp.where(valid[:, None], xy, 0.0), ((0, pad), (0, 0))),
        weight=jnp.pad(jnp.where(valid, weight, 0.0), (0, pad)),
        valid=jnp.pad(valid, (0, pad)),
        footprint=jnp.pad(jnp.where(valid[:, None, None], footprint, 0.0), ((0, pad), (0, 0), (0, 0))),
    )


def _rays_hit(h: int, w: int, intrinsics, cam_to_base, plane_height, max_distance) -> Bool[Array, "h w"]:
    """Which pixel rays meet the plane in front of the camera within ``max_distance`` (all pixels at once).

    The same test as :func:`~heatpf_jax.camera.project_pixel`, written as outer sums over rows and
    columns so the whole image costs a few fused element-wise passes.
    """
    intrinsics = jnp.asarray(intrinsics, jnp.float32)
    pose = jnp.asarray(cam_to_base, jnp.float32)
    a = (jnp.arange(w, dtype=jnp.float32) - intrinsics[2]) / intrinsics[0]
    b = (jnp.arange(h, dtype=jnp.float32) - intrinsics[3]) / intrinsics[1]
    rot, origin = pose[:3, :3], pose[:3, 3]

    def component(i):
        return rot[i, 0] * a[None, :] + (rot[i, 1] * b + rot[i, 2])[:, None]

    dx, dy, dz = component(0), component(1), component(2)
    hits = jnp.abs(dz) > 1e-9
    scale = (plane_height - origin[2]) / jnp.where(hits, dz, 1.0)
    x = origin[0] + scale * dx
    y = origin[1] + scale * dy
    return hits & (scale > 0.0) & (x * x + y * y <= jnp.square(max_distance)) & jnp.isfinite(x) & jnp.isfinite(y)


def age_measurements(
    measurements: Measurements, aging: Float[ArrayLike, ""], min_weight: Float[ArrayLike, ""]
) -> Measurements:
    """Eq. (2): subtracts ``aging`` (v) from every weight, drops weights below ``min_weight`` (l)."""
    weight = measurements.weight - aging
    valid = measurements.valid & (weight >= min_weight)
    return measurements._replace(weight=jnp.where(valid, weight, 0.0), valid=valid)


def move_measurements(measurements: Measurements, odometry: Float[ArrayLike, "3"]) -> Measurements:
    """Moves buffered measurements into the base frame after ``odometry`` (III-C, III-D).

    Measurements are data, not hypotheses: they move with the odometry as given,
    without the particles' motion noise. Their footprints (ground vectors) turn with
    the frame, ``R(dtheta)^T F``, and are not translated.
    """
    odometry = jnp.asarray(odometry)
    xy = apply_odometry(measurements.xy, odometry)
    valid = measurements.valid
    # Each footprint column is a ground vector: apply_odometry's rotation R(dtheta)^T, without the shift.
    c, s = jnp.cos(odometry[2]), jnp.sin(odometry[2])
    fx, fy = measurements.footprint[:, 0, :], measurements.footprint[:, 1, :]
    footprint = jnp.stack([c * fx + s * fy, -s * fx + c * fy], axis=1)
    return measurements._replace(
        xy=jnp.where(valid[:, None], xy, 0.0), footprint=jnp.where(valid[:, None, None], footprint, 0.0)
    )


def update_buffer(
    buffer: Measurements,
    new: Measurements,
    has_new: Bool[ArrayLike, ""],
    aging: Float[ArrayLike, ""],
    min_weight: Float[ArrayLike, ""],
) -> Measurements:
    """Eq. (2): a non-empty new measurement set replaces the buffer, otherwise it ages.

    Following eq. (2), a heat map that yields no valid measurement (nothing above
    the threshold) counts as no new input, so the old measurements age instead
    of being wiped. New measurements below ``min_weight`` (l) are dropped, as
    the paper removes every measurement with ``w < l``.

    Args:
        buffer: the current buffer (already moved by this step's odometry).
        new: this step's projected heat map (ignored unless ``has_new``).
        has_new: whether this step brought a heat map.
        aging: v, subtracted per filter step.
        min_weight: l.

    Returns:
        The buffer for this step.
    """
    new_valid = new.valid & (new.weight >= min_weight)
    new = new._replace(weight=jnp.where(new_valid, new.weight, 0.0), valid=new_valid)
    use_new = jnp.asarray(has_new) & jnp.any(new_valid)
    aged = age_measurements(buffer, aging, min_weight)
    return jax.tree.map(lambda a, b: jnp.where(use_new, a, b), new, aged)
