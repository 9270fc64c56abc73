"""Colour-histogram heat maps from RGB frames (Olufs et al., section 2, eq. 1-3).

For every pixel, the ball is supposed centred there: the histogram ``p_obj`` of a square *object
window* and the histogram ``p_bck`` of the square *background ring* around it (eq. 1, in the r'g'I space
of :mod:`heatpf_jax.colour.space`) are compared with the reference object histogram ``q`` by the
Bhattacharyya coefficient (eq. 2), background subtracted bin-wise (eq. 3) with the lower limit
``theta``::

    rho = sum_u sqrt(q_u) * max(0, sqrt(p_obj(u)) - sqrt(p_bck(u)))
    activation = max(0, rho - theta) / (1 - theta)          in [0, 1]

The paper writes eq. 3 with an absolute value around the difference and says the background "is
extracted bin-wise instead of subtracting the summed likelihood". The bin-wise difference is rectified
here: a bin counts only where the window holds *more* of the reference colour than its ring. The
absolute value would also light up every position whose ring, not its window, holds the ball: a halo
one ball radius around it. The normalisation is fixed (``1 - theta``): a per-frame maximum would turn
noise into full activation in a frame without the ball.

**An absolute scale.** ``rho`` of the object itself stays below 1 (by how much depends on the reference's
spread and on what its ring holds): ``rho`` is divided by :attr:`ColourParams.reference_score` before
``theta``, the reference object's own ``rho`` (:func:`heatpf_jax.colour.reference.reference_score`), so that
the object looking as it does in the reference maps to about 1 and the filters' own threshold applies;
``theta`` is then a share of that score. ``white`` brings every frame under the reference's light first
(:func:`~heatpf_jax.colour.space.balance`): a colour cast moves a white object across chromaticity bins.

The window follows the ball's expected image size: :func:`expected_radius_px` gives, for every pixel,
the radius in pixels of a ball resting on the ground whose centre projects there (from the camera pose
and intrinsics, like the heat-map projection of III-A); the object window's half-size is
``window_scale`` times it, the ring's ``ring_scale`` times that. Windowed histograms of every size come
from summed-area tables (integral images, ``uint16``, :func:`~heatpf_jax.colour.space.bin_table`) of one-hot
bin indicators, four corner gathers per box. Only
bins where the reference has mass contribute to eq. 2-3, so the tables are built for the ``top_bins``
bins of largest reference mass: exact whenever the reference has at most ``top_bins`` non-empty bins
(:func:`~heatpf_jax.colour.space.exact_top_bins` gives the smallest such power of two). The tables hold 64
bins each (a reference with more gets several, summed in a :func:`~jax.lax.scan`): one table of 128 bins
took 4-5 times as long per frame as one of 64, its boxes no longer gathered from the cache.

**The window at the blob, not at the pixel.** A window that follows each pixel's own expected size is
larger below a ball than above it (lower rows look at nearer ground), and the box score is not flat in the
window's size: the map's response is skewed towards the camera. On rendered ``standard`` frames (seeds
100-101, development seeds) the weighted centroid of the pixels above 0.1 sat 0.32 px below the ball's
projected centre, against 0.06 px with one window size for the whole frame; 0.3 px is about 2 cm on the
ground at 2 m. So by default (``blob_window=True``) the map is computed twice on the same tables: the
second pass gives every pixel the window of the first map's local weighted centroid
(:func:`blob_half_size`), so all pixels of one response share the window of the ball they respond to
(0.06 px on the same frames), and responses at different ranges keep their own sizes. Without a response
nearby a pixel keeps its own window.
"""

from __future__ import annotations

from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, UInt8

from heatpf_jax.colour.silhouette import silhouette_score, window_max
from heatpf_jax.colour.space import DEFAULT_BINS, MAX_BOX_HALF, balance, box_counts, rgi_bins

__all__ = [
    "MAP_SETTINGS",
    "ColourParams",
    "blob_half_size",
    "colour_heatmaps",
    "colour_likelihood",
    "expected_radius_px",
    "window_coefficient",
    "window_half_sizes",
]


MAP_SETTINGS = {"source": "pixels"}
"""What a filter of colour maps must follow (``Sequence.settings`` of :func:`heatpf_jax.cli.colour.colour_sequence`):
a colour map's blob is as large as the object window that made it, and that window is a ground ball's at its pixel
(:func:`expected_radius_px`), so the blob's size says nothing of the ball's height. A source that places blobs in
the air by their size (:class:`~heatpf_jax.sources.lofted.LoftedSource`, ``heatmap``'s own) reads its scatter as
flight; every pixel is measured where it projects instead (``source=pixels``, the paper's source)."""

_OUTLINE_BOUND = 32  # the outline's largest radius in pixels (window_max's table); beyond it, a square of 32
_CHUNK = 64  # bins per summed-area table (_chunk_tables): 64 bins were the fastest of 16-64 per bin


class ColourParams(NamedTuple):
    """Numbers of the colour likelihood.

    Attributes:
        theta: eq. 3's lower limit on the background-subtracted coefficient (0.2; 0.3 lost the ball in
            the darker frames of seed 101).
        window_scale: object window half-size over the expected ball radius (0.9, chosen on rendered
            ``standard`` seeds 100-102 among 0.5-1.0: smaller windows lose the ball among field lines).
        ring_scale: the ring's outer half-size over the object window's.
        min_half_size: smallest object window half-size, pixels.
        max_half_size: largest object window half-size, pixels.
        blob_reach: the neighbourhood of :func:`blob_half_size` (half-size over the pixel's expected
            radius); 2 and 3 gave the same centroids on seeds 100-101.
        reference_score: the coefficient ``rho`` that maps to activation 1: ``rho`` is divided by it before
            ``theta`` is applied. 1 (the default) keeps the coefficient's own scale; the reference's own
            score (:func:`heatpf_jax.colour.reference.reference_score`, what ``heatpf colour`` uses) puts the
            maps on an absolute scale, the object as it looks in the reference at about 1.
        window_waist: the object window's shape (:func:`window_coefficient`): the union of a wide and a tall
            rectangle, half-sizes ``a x b`` and ``b x a`` with ``a`` the window's half-size and ``b = round(waist
            a)``. 1 (the default, and ``heatpf colour``'s) is the square; 0.618 with ``window_scale`` 0.851 is the
            largest such cross inside a round ball's disc (``heatpf colour --window-scale 0.851 --window-waist
            0.618``; docs/results.md has what it changes).
        silhouette_score: the reference's own silhouette score ``S_ref``
            (:func:`heatpf_jax.colour.silhouette.reference_silhouette`), used only when the maps are given an
            ``object_probability``: the map is then ``H * (1 - c + c S+ / S_max)``, ``c = min(S_max / S_ref, 1)``,
            the histogram map ``H`` combined with the ball's outline (:mod:`heatpf_jax.colour.silhouette`).
            ``heatpf colour`` sets it (unless ``--no-silhouette``); at most 1e-6 counts as 1e-6.
        silhouette_outer: the silhouette's annulus, outer radius over the ball's
            (:func:`~heatpf_jax.colour.silhouette.silhouette_score`).
    """

    theta: float = 0.2
    window_scale: float = 0.9
    ring_scale: float = 2.0
    min_half_size: float = 1.0
    max_half_size: float = 25.0
    blob_reach: float = 2.0
    reference_score: float = 1.0
    window_waist: float = 1.0
    silhouette_score: float = 1.0
    silhouette_outer: float = 1.5


def expected_radius_px(
    intrinsics: Float[ArrayLike, "4"], cam_to_base: Float[ArrayLike, "4 4"], ball_radius, shape: tuple[int, int]
) -> Float[Array, "h w"]:
    """The image radius (pixels) of a ball on the ground whose centre projects onto each pixel.

    The pixel's ray meets the plane ``z = ball_radius`` at the ball's centre ``c``; the radius is the mean
    image distance between ``c`` and ``c +- ball_radius * s`` with ``s`` the horizontal unit vector across
    the ray (the silhouette's half-width across the line of sight, off-axis magnification included). Pixels whose
    ray does not meet the plane in front of the camera (above the horizon) get 0.
    """
    h, w = shape
    intr = jnp.asarray(intrinsics, jnp.float32)
    pose = jnp.asarray(cam_to_base, jnp.float32)
    rot, origin = pose[:3, :3], pose[:3, 3]
    v, u = jnp.meshgrid(jnp.arange(h, dtype=jnp.float32), jnp.arange(w, dtype=jnp.float32), indexing="ij")
    ray = jnp.stack([(u - intr[2]) / intr[0], (v - intr[3]) / intr[1], jnp.ones_like(u)], axis=-1)
    direction = jnp.einsum("ij,hwj->hwi", rot, ray)  # base frame, per unit optical depth
    radius = jnp.asarray(ball_radius, jnp.float32)
    dz = direction[..., 2]
    ok = dz < -1e-6
    depth = (radius - origin[2]) / jnp.where(ok, dz, -1.0)
    ok = ok & (depth > 0)
    side = jnp.stack([-direction[..., 1], direction[..., 0], jnp.zeros_like(dz)], axis=-1)  # ray x z, horizontal
    norm = jnp.sqrt(jnp.maximum(jnp.sum(side**2, axis=-1, keepdims=True), 1e-12))
    centre = origin[None, None, :] + depth[..., None] * direction
    offset = radius * side / norm

    def pixel_distance(point):
        cam = jnp.einsum("ji,hwj->hwi", rot, point - origin[None, None, :])  # optical frame
        front = cam[..., 2] > 1e-6
        z = jnp.where(front, cam[..., 2], 1.0)
        du = intr[0] * cam[..., 0] / z + intr[2] - u
        dv = intr[1] * cam[..., 1] / z + intr[3] - v
        return jnp.sqrt(du * du + dv * dv), front

    left, front_l = pixel_distance(centre + offset)
    right, front_r = pixel_distance(centre - offset)
    return jnp.where(ok & front_l & front_r, 0.5 * (left + right), 0.0)


def _boxes(radius, shape, rows=None):
    """Per pixel, the rows ``[y0, y1)`` and columns ``[x0, x1)`` of the box of half-sizes ``radius`` (columns) and
    ``rows`` (rows; default ``radius``: a square) around it, clipped to the image."""
    h, w = shape
    v, u = jnp.meshgrid(jnp.arange(h), jnp.arange(w), indexing="ij")
    r = radius.astype(jnp.int32)
    q = r if rows is None else rows.astype(jnp.int32)
    return jnp.clip(v - q, 0, h), jnp.clip(v + q + 1, 0, h), jnp.clip(u - r, 0, w), jnp.clip(u + r + 1, 0, w)


def _box_sums(table, radius, shape, rows=None):
    """Per pixel, the bin counts and pixel count of the box of half-sizes ``radius`` by ``rows`` (default: the
    square) around it."""
    y0, y1, x0, x1 = _boxes(radius, shape, rows)
    return box_counts(table, y0, y1, x0, x1), ((y1 - y0) * (x1 - x0)).astype(jnp.float32)


def window_half_sizes(radius: Float[ArrayLike, "*n"], params: ColourParams) -> tuple[Array, Array]:
    """The object window's and the ring's outer half-sizes (pixels, integral ``float32``) for an expected ball
    radius: ``window_scale * radius`` rounded and clipped to ``[min_half_size, max_half_size]``, and
    ``ring_scale`` times that (at least one pixel more, at most :data:`~heatpf_jax.colour.space.MAX_BOX_HALF`)."""
    radius = jnp.asarray(radius, jnp.float32)
    inner = jnp.clip(jnp.round(params.window_scale * radius), params.min_half_size, params.max_half_size)
    outer = jnp.maximum(jnp.round(params.ring_scale * inner), inner + 1.0)
    outer = jnp.minimum(outer, float(MAX_BOX_HALF))  # the uint16 tables count boxes below 2^16 pixels exactly
    return inner, outer


def _cross_sums(table, inner, waist, shape):
    """Per pixel, the bin counts and pixel count of the cross of half-sizes ``inner x b`` and ``b x inner`` around
    it (``b = round(waist * inner)``, clipped to ``[0, inner]``): the wide box plus the tall one less their
    overlap, each clipped to the image. ``waist`` 1 gives the square."""
    a = inner
    b = jnp.clip(jnp.round(waist * inner), 0.0, inner)

    def cross():
        (wide, n_wide), (tall, n_tall), (both, n_both) = (
            _box_sums(table, a, shape, b), _box_sums(table, b, shape, a), _box_sums(table, b, shape))
        return wide + tall - both, n_wide + n_tall - n_both

    # The square (waist 1, the default) with one box's gathers instead of three: 20 % of a map's time.
    return lax.cond(jnp.all(b >= a), lambda: _box_sums(table, a, shape), cross)


def window_coefficient(
    table: Float[Array, "h1 w1 k"],
    q_top: Float[Array, " k"],
    inner: Float[Array, "h w"],
    outer: Float[Array, "h w"],
    waist: Float[ArrayLike, ""] = 1.0,
) -> Float[Array, "h w"]:
    """Eq. 2-3's background-subtracted Bhattacharyya coefficient ``rho`` at every pixel (before ``theta``).

    The object window is the cross of half-sizes ``inner x b`` and ``b x inner`` (``b = round(waist * inner)``;
    ``waist`` 1, the default: the square of half-size ``inner``), the ring the square of half-size ``outer`` less
    the window. A ball is round: a square window inside it leaves its rim out, one over it takes in the grass at its
    corners. The cross with ``b / a = tan(atan(2) / 2) = 0.618`` and ``a = 0.851`` radii has its corners on the
    disc's rim and is the largest cross inside it (its area ``4 (2 a b - b^2)`` is largest at ``tan 2 theta = 2``
    for ``a = r cos theta``, ``b = r sin theta``): 2.47 squared radii, against 2.0 for the largest square inside.

    Args:
        table: a summed-area table of bin counts (:class:`~heatpf_jax.colour.space.BinTable` ``.table``, or
            any float table of per-pixel bin masses over the same ``K`` bins).
        q_top: the reference's values on those bins.
        inner: per pixel, the object window's half-size (:func:`window_half_sizes`).
        outer: per pixel, the ring's outer half-size (:func:`window_half_sizes`).
        waist: the cross's arm width over its length (:attr:`ColourParams.window_waist`).

    Returns:
        ``float32 [H, W]``, ``sum_u sqrt(q_u) max(0, sqrt(p_obj(u)) - sqrt(p_bck(u)))``.
    """
    shape = inner.shape
    in_sum, in_count = _cross_sums(table, inner, jnp.asarray(waist, jnp.float32), shape)
    out_sum, out_count = _box_sums(table, outer, shape)
    # Clipped at 0: a float table's box sums can come out a rounding error below it (uint16 ones are exact).
    p_obj = jnp.maximum(in_sum, 0.0) / jnp.maximum(in_count, 1.0)[..., None]
    ring = jnp.maximum(out_count - in_count, 1.0)[..., None]
    p_bck = jnp.maximum(out_sum - in_sum, 0.0) / ring
    # sqrt of a count ratio: exact zeros stay zero (no NaN gradient needed here: counts are data).
    return jnp.sum(jnp.sqrt(q_top)[None, None, :] * jnp.maximum(jnp.sqrt(p_obj) - jnp.sqrt(p_bck), 0.0), axis=-1)


def _likelihood(tables, radius: Float[Array, "h w"], params: ColourParams) -> Float[Array, "h w"]:
    """Eq. 1-3 at every pixel from the summed-area tables, the window from ``radius`` (one pass)."""
    inner, outer = window_half_sizes(radius, params)
    rho = _chunked_coefficient(tables, inner, outer, params.window_waist)
    act = jnp.maximum(rho / params.reference_score - params.theta, 0.0) / (1.0 - params.theta)
    return jnp.where(radius > 0, jnp.clip(act, 0.0, 1.0), 0.0)


class _ChunkTables(NamedTuple):
    table: Array  # uint16 [n, H + 1, W + 1, C]: the summed-area tables of C bins each
    q_top: Array  # float32 [n, C]: the reference's values on those bins (0 for padding)


class _Ranks(NamedTuple):
    rank: Array  # int32 [m]: each bin's place among the reference's K heaviest (n * C: not among them)
    q_top: Array  # float32 [n, C]: the reference's values on those bins, C to a chunk (0 for padding)


def _reference_ranks(reference, top_bins: int, chunk: int) -> _Ranks:
    """The reference's ``top_bins`` heaviest bins in chunks of ``chunk`` (padded with empty ones): computed once
    for every frame."""
    q = jnp.asarray(reference, jnp.float32)
    m = q.shape[0]
    k = min(int(top_bins), m)
    q_top, top_index = lax.top_k(q, k)
    n = -(-k // chunk)
    rank = jnp.full((m,), n * chunk, jnp.int32).at[top_index].set(jnp.arange(k, dtype=jnp.int32))
    return _Ranks(rank, jnp.pad(q_top, (0, n * chunk - k)).reshape(n, chunk))


def _chunk_tables(image, ranks: _Ranks, bins) -> _ChunkTables:
    """:func:`~heatpf_jax.colour.space.bin_table`'s tables, a chunk of bins to a table: each table stays small
    enough for the cache while its boxes are gathered (at 128 bins in one table a frame took 4-5 times as long
    as at 64). A :func:`~jax.lax.scan` over the chunks keeps one compiled body whatever the number of bins."""
    n, chunk = ranks.q_top.shape
    ranked = ranks.rank[rgi_bins(image, bins)]  # [H, W]: each pixel's place among the K bins (n * chunk: none)

    def one(_, c):
        wanted = c * chunk + jnp.arange(chunk, dtype=jnp.int32)
        onehot = (ranked[..., None] == wanted[None, None, :]).astype(jnp.uint16)
        table = lax.associative_scan(jnp.add, lax.associative_scan(jnp.add, onehot, axis=0), axis=1)
        return None, jnp.pad(table, ((1, 0), (1, 0), (0, 0)))

    _, tables = lax.scan(one, None, jnp.arange(n, dtype=jnp.int32))
    return _ChunkTables(tables, ranks.q_top)


def _chunked_coefficient(tables: _ChunkTables, inner, outer, waist) -> Float[Array, "h w"]:
    """:func:`window_coefficient` summed over the chunks' tables."""

    def one(total, chunk):
        table, q_top = chunk
        return total + window_coefficient(table, q_top, inner, outer, waist), None

    total, _ = lax.scan(one, jnp.zeros(inner.shape, jnp.float32), (tables.table, tables.q_top))
    return total


def blob_half_size(
    first: Float[ArrayLike, "h w"], half_size: Float[ArrayLike, "h w"], reach: Float[ArrayLike, ""] = 2.0
) -> Float[Array, "h w"]:
    """Every pixel's expected ball radius taken at the weighted centroid of a first map around it.

    The centroid is that of ``first`` over the square of half-size ``round(reach * half_size)`` around the
    pixel (summed-area tables of ``first``, ``first * u`` and ``first * v``); the result is ``half_size`` at
    the centroid's nearest pixel. Pixels with no activation around them, or whose centroid lies where no ball
    can be (``half_size`` 0), keep their own ``half_size``; pixels with ``half_size`` 0 stay 0.

    Args:
        first: ``[H, W]`` a first likelihood map (non-negative).
        half_size: ``[H, W]`` the expected ball radius per pixel (:func:`expected_radius_px`).
        reach: the neighbourhood's half-size over ``half_size``.

    Returns:
        ``float32 [H, W]`` radii for a second pass of :func:`colour_likelihood`'s window.
    """
    first = jnp.asarray(first, jnp.float32)
    radius = jnp.asarray(half_size, jnp.float32)
    h, w = first.shape
    v, u = jnp.meshgrid(jnp.arange(h, dtype=jnp.float32), jnp.arange(w, dtype=jnp.float32), indexing="ij")
    # Sums relative to each pixel are taken from one table of (m, m*u, m*v); float32 sums of a 200 x 150
    # map stay exact to ~1e-5 relative in a window.
    stack = jnp.stack([first, first * u, first * v], axis=-1)
    table = jnp.pad(jnp.cumsum(jnp.cumsum(stack, axis=0), axis=1), ((1, 0), (1, 0), (0, 0)))
    sums = box_counts(table, *_boxes(jnp.maximum(jnp.round(reach * radius), 1.0), (h, w)))
    mass = sums[..., 0]
    found = mass > 1e-6
    safe = jnp.where(found, mass, 1.0)
    cu = jnp.clip(jnp.round(sums[..., 1] / safe), 0, w - 1).astype(jnp.int32)
    cv = jnp.clip(jnp.round(sums[..., 2] / safe), 0, h - 1).astype(jnp.int32)
    at_centroid = radius[cv, cu]
    return jnp.where(found & (radius > 0) & (at_centroid > 0), at_centroid, radius)


def colour_likelihood(
    image: UInt8[ArrayLike, "h w 3"],
    reference: Float[ArrayLike, " m"],
    half_size: Float[ArrayLike, "h w"],
    params: ColourParams = ColourParams(),
    *,
    bins: tuple[int, int, int] = DEFAULT_BINS,
    top_bins: int = 64,
    blob_window: bool = True,
    white: Float[ArrayLike, "3"] | None = None,
    object_probability: Float[ArrayLike, " m"] | None = None,
) -> Float[Array, "h w"]:
    """The colour likelihood map of one frame (eq. 1-3, see the module docstring).

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        reference: ``float32 [m]`` the object's normalised r'g'I histogram (e.g.
            :func:`~heatpf_jax.colour.space.patch_histogram`).
        half_size: ``[H, W]`` the expected ball radius per pixel (:func:`expected_radius_px`); 0 marks
            pixels where no ball can be (activation 0).
        params: :class:`ColourParams`.
        bins: the r'g'I bins of ``reference``.
        top_bins: bins used (those of largest reference mass); exact when the reference has at most this
            many non-empty bins.
        blob_window: a second pass with the window at each response's centroid (:func:`blob_half_size`,
            the default); ``False``: one pass, every pixel with its own window.
        white: ``[3]`` the channel means of the reference's light: the frame is first brought under it
            (:func:`~heatpf_jax.colour.space.balance`); ``None`` (the default) takes the frame as it is.
        object_probability: ``[m]`` every bin's probability of showing the object
            (:func:`heatpf_jax.colour.silhouette.chromaticity_probability`, :attr:`Reference.silhouette
            <heatpf_jax.colour.reference.Reference.silhouette>`): the map is then combined with the ball's
            outline, ``H * (1 - c + c S+ / S_max)`` (:mod:`heatpf_jax.colour.silhouette`,
            ``S`` at the radius of each response's centroid); ``None`` (the default) keeps the histogram map.

    Returns:
        ``float32 [H, W]`` activations in ``[0, 1]``.
    """
    ranks = _reference_ranks(reference, top_bins, min(int(top_bins), _CHUNK))
    return _frame_map(image, ranks, half_size, params, bins, blob_window, white, object_probability)


def _frame_map(image, ranks: _Ranks, half_size, params: ColourParams, bins, blob_window: bool, white,
               object_probability=None):
    """:func:`colour_likelihood` with the reference's bins already ranked."""
    image = jnp.asarray(image)
    if white is not None:
        image = balance(image, white)
    tables = _chunk_tables(image, ranks, bins)
    radius = jnp.asarray(half_size, jnp.float32)
    act = _likelihood(tables, radius, params)
    if blob_window:
        act = _likelihood(tables, blob_half_size(act, radius, params.blob_reach), params)
    if object_probability is not None:
        act = _with_silhouette(act, image, radius, jnp.asarray(object_probability, jnp.float32), params, bins)
    return act


def _with_silhouette(act, image, radius, object_probability, params: ColourParams, bins):
    """``act * (1 - c + c S+ / S_max)``, ``c = min(S_max / S_ref, 1)``, with ``S`` the silhouette score of each
    pixel's object probability at the expected radius of its response's centroid (:func:`blob_half_size`) and
    ``S_max`` the largest ``S`` within that radius (:func:`~heatpf_jax.colour.silhouette.window_max`)."""
    probability = object_probability[rgi_bins(image, bins)]
    at_blob = blob_half_size(act, radius, params.blob_reach)
    # Exact scores where the histogram map responds and two blob radii around (S_max looks one radius); elsewhere
    # the product is 0 whatever S is (the rows summed follow the largest responding radius, not the nearest ground).
    near = window_max(act, 2.0 * at_blob + 1.0, _OUTLINE_BOUND) > 0.0
    score = jnp.maximum(silhouette_score(probability, at_blob, params.silhouette_outer, where=near), 0.0)
    best = window_max(score, at_blob, _OUTLINE_BOUND)
    # The outline's shape, a cone whose peak keeps the histogram's value, weighed by how clearly the outline is seen
    # against the reference's: a ball in front of a white post or on a line shows little outline, which says
    # nothing of whether it is there (S+ / max(S_max, S_ref) took such a ball below the threshold).
    clear = jnp.clip(best / jnp.maximum(params.silhouette_score, 1e-6), 0.0, 1.0)
    shape = 1.0 - clear + clear * score / jnp.maximum(best, 1e-6)
    return jnp.where(radius > 0, act * shape, 0.0)


@partial(jax.jit, static_argnames=("bins", "top_bins", "blob_window"))
def colour_heatmaps(
    images: UInt8[ArrayLike, "t h w 3"],
    reference: Float[ArrayLike, " m"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "t 4 4"],
    ball_radius,
    params: ColourParams = ColourParams(),
    *,
    bins: tuple[int, int, int] = DEFAULT_BINS,
    top_bins: int = 64,
    blob_window: bool = True,
    white: Float[ArrayLike, "3"] | None = None,
    object_probability: Float[ArrayLike, " m"] | None = None,
) -> Float[Array, "t h w"]:
    """:func:`colour_likelihood` of every frame, the window from each frame's camera pose (``lax.map``:
    one frame's tables in memory at a time); ``white`` and ``object_probability`` as there."""
    images = jnp.asarray(images)
    shape = images.shape[1:3]
    ranks = _reference_ranks(reference, top_bins, min(int(top_bins), _CHUNK))  # once, not in every frame

    def one(frame):
        image, pose = frame
        radius = expected_radius_px(intrinsics, pose, ball_radius, shape)
        return _frame_map(image, ranks, radius, params, bins, blob_window, white, object_probability)

    return lax.map(one, (images, jnp.asarray(cam_to_base, jnp.float32)))
