"""Each pixel's blob centre in the image: a mean shift with a window as large as a ball would be there.

Eq. (1) weights a particle by the k measurements nearest to it on the ground. A blob of several rows far
away projects to points a third of a metre apart along the line of sight, spread unevenly (the ground
spacing of a row grows with range), so the weights do not see where the blob's mass lies along the ray:
the centroid that a Kalman filter is fed does. This module moves every above-threshold pixel to the
activation-weighted centroid of the blob it belongs to, *in the image*, before it is projected:

    (u, v) <- sum_{q in W(u, v)} h_q q / sum_{q in W(u, v)} h_q,   h_q = activation where >= threshold,

iterated (a mean shift with a flat kernel, Comaniciu and Meer 2002; Olufs et al. 3.2 use it on the ground),
with ``W`` a square of half-size ``reach * r(u, v)`` and ``r(u, v)`` the radius in pixels of a ball lying
on the ground at the point the pixel sees (``f R / depth``). So:

* every pixel of a ball's blob ends at the blob's centroid, which projects to the ball (the blob of a
  sphere is centred on the projection of its centre; projecting the image centroid, not averaging
  projected pixels, avoids the bias of the projection's curvature);
* a false positive or a second ball farther away than the window keeps its own centre (eq. 1's
  robustness to false positives is kept), and the two halves of a blob split by an occluder, each within
  a ball's size of the other, join at the whole blob's centroid;
* near the robot the window is large (a near ball is large), far away small.

The window's share of above-threshold pixels (its *fill*) at the end tells whether the blob is larger than
a ground ball there would be: a ball in the air projects onto the ground behind itself, where a ground ball
would look smaller (:class:`~heatpf_jax.sources.pixels.CentroidSource` can refuse such measurements).

Sums over windows come from summed-area tables, so each iteration costs a few gathers per pixel.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float

__all__ = ["BlobCentres", "ball_radius_px", "blob_centres", "box_sums", "summed_area", "summed_areas"]


class BlobCentres(NamedTuple):
    """Where each start pixel's mean shift ended.

    Attributes:
        uv: ``[M, 2]`` (column, row) of the window's final centroid.
        mass: ``[M]`` summed above-threshold activation in the final window.
        fill: ``[M]`` share of the final window's pixels at or above the threshold.
        spill: ``[M]`` above-threshold pixels in a window twice as large, over those in the final window: about
            1 for a blob no larger than the window (a ball on the ground, a split ball), more for a blob larger
            than a ground ball there (a ball in the air, a large false positive); 1 for an empty window.
        radius_px: ``[M]`` the ground ball's radius in pixels at the final centre (0 above the horizon).
    """

    uv: Float[Array, "m 2"]
    mass: Float[Array, " m"]
    fill: Float[Array, " m"]
    spill: Float[Array, " m"]
    radius_px: Float[Array, " m"]


def summed_area(table: Float[ArrayLike, "h w"]) -> Float[Array, "h+1 w+1"]:
    """Summed-area table with a zero first row and column: ``S[i, j] = sum(table[:i, :j])``."""
    s = jnp.cumsum(jnp.cumsum(jnp.asarray(table, jnp.float32), axis=0), axis=1)
    return jnp.pad(s, ((1, 0), (1, 0)))


def _blocked_cumsum(x: Float[Array, "..."], axis: int, block: int) -> Float[Array, "..."]:
    """Inclusive cumulative sum along ``axis``: sums within blocks of ``block`` entries and the blocks' running
    totals, each a small triangular matrix product (XLA:CPU's ``cumsum`` is a windowed reduction, slower)."""
    x = jnp.moveaxis(x, axis, -1)
    n = x.shape[-1]
    nb = -(-n // block)
    padded = jnp.pad(x, [(0, 0)] * (x.ndim - 1) + [(0, nb * block - n)]).reshape(*x.shape[:-1], nb, block)
    within = jnp.matmul(padded, jnp.triu(jnp.ones((block, block), x.dtype)), precision=lax.Precision.HIGHEST)
    before = jnp.matmul(within[..., -1], jnp.triu(jnp.ones((nb, nb), x.dtype), 1), precision=lax.Precision.HIGHEST)
    out = (within + before[..., None]).reshape(*x.shape[:-1], nb * block)[..., :n]
    return jnp.moveaxis(out, -1, axis)


def summed_areas(tables: Float[ArrayLike, "c h w"], block: int = 8) -> Float[Array, "c h+1 w+1"]:
    """:func:`summed_area` of each of ``c`` stacked tables at once, the same up to float rounding (the sums are
    taken in another order): cumulative sums by blocks of ``block`` entries as matrix products, about half the
    cost of ``jnp.cumsum`` on XLA:CPU for three 200 x 150 tables."""
    s = jnp.asarray(tables, jnp.float32)
    s = _blocked_cumsum(_blocked_cumsum(s, -1, block), -2, block)
    return jnp.pad(s, ((0, 0), (1, 0), (1, 0)))


def box_sums(s: Float[Array, "h1 w1"], u0, u1, v0, v1) -> Float[Array, "..."]:
    """Sums of the inclusive integer boxes ``[u0, u1] x [v0, v1]`` (already clipped to the image) from a
    :func:`summed_area` table."""
    return s[v1 + 1, u1 + 1] - s[v0, u1 + 1] - s[v1 + 1, u0] + s[v0, u0]


def ball_radius_px(
    uv: Float[ArrayLike, "m 2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    plane_height: Float[ArrayLike, ""],
) -> Float[Array, " m"]:
    """The radius in pixels, ``fx R / depth``, of a ball of radius ``R = plane_height`` on the ground where each
    pixel's ray meets the plane ``z = R``; 0 where the ray misses the plane in front of the camera."""
    uv = jnp.asarray(uv, jnp.float32)
    intrinsics = jnp.asarray(intrinsics, jnp.float32)
    pose = jnp.asarray(cam_to_base, jnp.float32)
    ray = jnp.stack([(uv[:, 0] - intrinsics[2]) / intrinsics[0], (uv[:, 1] - intrinsics[3]) / intrinsics[1],
                     jnp.ones_like(uv[:, 0])], axis=-1)
    dz = ray @ pose[2, :3]
    hits = jnp.abs(dz) > 1e-9
    depth = (plane_height - pose[2, 3]) / jnp.where(hits, dz, 1.0)  # optical depth: the ray has z = 1
    ok = hits & (depth > 0.0)
    return jnp.where(ok, intrinsics[0] * plane_height / jnp.where(ok, depth, 1.0), 0.0)


def blob_centres(
    heatmap: Float[ArrayLike, "h w"],
    start: Float[ArrayLike, "m 2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    threshold: Float[ArrayLike, ""],
    plane_height: Float[ArrayLike, ""],
    reach: Float[ArrayLike, ""] = 1.5,
    iterations: int = 3,
) -> BlobCentres:
    """Mean shift of each start pixel over the above-threshold activations, the window a ball's size there.

    Args:
        heatmap: ``[H, W]`` activations.
        start: ``[M, 2]`` start pixels (column, row), usually the above-threshold pixels themselves.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        threshold: activations below it are not part of any blob.
        plane_height: the ball radius, metres.
        reach: the window's half-size in ground-ball radii at its centre (at least one pixel).
        iterations: static number of mean-shift steps.

    Returns:
        :class:`BlobCentres`; a window without mass keeps its centre.
    """
    heat = jnp.asarray(heatmap, jnp.float32)
    h, w = heat.shape
    mass_map = jnp.where(heat >= threshold, heat, 0.0)
    cols = jnp.arange(w, dtype=jnp.float32)[None, :]
    rows = jnp.arange(h, dtype=jnp.float32)[:, None]
    s_mass = summed_area(mass_map)
    s_u = summed_area(mass_map * cols)
    s_v = summed_area(mass_map * rows)
    s_count = summed_area((heat >= threshold).astype(jnp.float32))

    def window(uv, scale=1.0):
        radius = ball_radius_px(uv, intrinsics, cam_to_base, plane_height)
        half = scale * jnp.maximum(jnp.round(reach * radius), 1.0)
        u0 = jnp.clip(jnp.round(uv[:, 0] - half), 0, w - 1).astype(jnp.int32)
        u1 = jnp.clip(jnp.round(uv[:, 0] + half), 0, w - 1).astype(jnp.int32)
        v0 = jnp.clip(jnp.round(uv[:, 1] - half), 0, h - 1).astype(jnp.int32)
        v1 = jnp.clip(jnp.round(uv[:, 1] + half), 0, h - 1).astype(jnp.int32)
        return (u0, u1, v0, v1), radius

    uv = jnp.asarray(start, jnp.float32)
    for _ in range(int(iterations)):
        box, _ = window(uv)
        m = box_sums(s_mass, *box)
        has = m > 0.0
        safe = jnp.where(has, m, 1.0)
        moved = jnp.stack([box_sums(s_u, *box) / safe, box_sums(s_v, *box) / safe], axis=-1)
        uv = jnp.where(has[:, None], moved, uv)
    box, radius = window(uv)
    u0, u1, v0, v1 = box
    area = ((u1 - u0 + 1) * (v1 - v0 + 1)).astype(jnp.float32)
    count = box_sums(s_count, *box)
    count_around = box_sums(s_count, *window(uv, 2.0)[0])
    spill = jnp.where(count > 0.0, count_around / jnp.maximum(count, 1.0), 1.0)
    return BlobCentres(uv=uv, mass=box_sums(s_mass, *box), fill=count / area, spill=spill, radius_px=radius)
