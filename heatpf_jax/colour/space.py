"""The r'g'I colour space and its histograms (Olufs et al., section 2, eq. 1).

Olufs et al. bin colours in an illumination-invariant space, ``(r', g', I) = (r / g, g / b, (r + g + b) / 3)``,
with ``12 x 12 x 4`` bins: 12 x 12 for the two chromaticity ratios and only 4 for the intensity, which keeps
black and white apart while staying insensitive to lighting changes. The ratios are unbounded (and undefined
at 0), so each is binned by its angle: ``atan2(r + 1, g + 1)`` maps ``r / g`` in ``(0, inf)`` onto
``(0, pi / 2)`` symmetrically about 1 (grey), and a gain on all three channels leaves it (nearly) unchanged.

Every function here is pure JAX on ``uint8`` images; :mod:`heatpf_jax.colour.likelihood` builds the likelihood maps on
them and :mod:`heatpf_jax.baselines` the image-space trackers.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int, UInt8, UInt16

__all__ = [
    "DEFAULT_BINS",
    "MAX_BOX_HALF",
    "MAX_BOX_PIXELS",
    "BinTable",
    "balance",
    "bin_table",
    "box_counts",
    "channel_means",
    "exact_top_bins",
    "histogram",
    "num_bins",
    "patch_histogram",
    "rgi_bins",
    "smooth_chromaticity",
    "smooth_intensity",
]

DEFAULT_BINS = (12, 12, 4)  # r', g', I: the paper's experimental setup


def num_bins(bins: tuple[int, int, int] = DEFAULT_BINS) -> int:
    """``m``, the number of histogram bins."""
    return int(bins[0] * bins[1] * bins[2])


# Grey (r = g = b) maps to angle 0.5 exactly, a bin edge for an even number of bins; the nearest other
# integer ratio (256 / 255) is 1.2e-3 away. A nudge far below that and far above float32 rounding puts
# grey, white and black (the ball) inside one bin whichever way atan2 rounds (XLA's fused atan2 and
# NumPy's differ in the last bit).
_GREY_NUDGE = 1e-4


def _angle_bin(num: Array, den: Array, count: int) -> Array:
    angle = jnp.arctan2(num + 1.0, den + 1.0) * (2.0 / math.pi) + _GREY_NUDGE  # (0, 1)
    return jnp.clip(jnp.floor(angle * count), 0, count - 1).astype(jnp.int32)


def rgi_bins(image: UInt8[ArrayLike, "h w 3"], bins: tuple[int, int, int] = DEFAULT_BINS) -> Int[Array, "h w"]:
    """The r'g'I histogram bin ``h(x_i)`` of every pixel (eq. 1's bin function).

    Args:
        image: ``uint8 [H, W, 3]`` RGB (any leading axes are kept), or integral values in ``[0, 255]`` of
            another dtype (:func:`balance`).
        bins: ``(n_r, n_g, n_I)`` bins of ``r / g``, ``g / b`` and the intensity.

    Returns:
        ``int32 [H, W]`` bin indices in ``[0, n_r * n_g * n_I)``, ``((i_r * n_g) + i_g) * n_I + i_I``.
    """
    rgb = jnp.asarray(image).astype(jnp.float32)
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    n_r, n_g, n_i = bins
    i_r = _angle_bin(r, g, n_r)
    i_g = _angle_bin(g, b, n_g)
    i_i = jnp.clip(jnp.floor((r + g + b) / 3.0 * (n_i / 256.0)), 0, n_i - 1).astype(jnp.int32)
    return (i_r * n_g + i_g) * n_i + i_i


def channel_means(images: UInt8[ArrayLike, "*t h w 3"]) -> Float[Array, "3"]:
    """The mean R, G and B of ``images`` (all frames and pixels together): the light they were taken in, for
    :func:`balance` (the grey-world assumption)."""
    return jnp.mean(jnp.asarray(images).astype(jnp.float32).reshape(-1, 3), axis=0)


def balance(image: UInt8[ArrayLike, "h w 3"], white: Float[ArrayLike, "3"]) -> Float[Array, "h w 3"]:
    """``image`` under the light ``white``: each channel scaled by ``white / channel mean`` (von Kries's
    diagonal adaptation with the grey-world estimate of the light), rounded and clipped to ``[0, 255]``.

    A change of the light's level or colour (a cloud, a warmer lamp, the camera's white balance) multiplies
    each channel of the whole frame by its own factor; the r'g'I bins of a white object move with it (a
    cast of 10 % in ``g / b`` is most of a chromaticity bin). Scaling every frame's channel means to those
    of the reference's frame undoes it, whatever moves in the frame (a small object shifts the means little).

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        white: ``[3]`` the channel means to scale to (:func:`channel_means` of the reference's frame).

    Returns:
        ``float32 [H, W, 3]`` integral values in ``[0, 255]`` (the input for :func:`rgi_bins`).
    """
    rgb = jnp.asarray(image).astype(jnp.float32)
    mean = jnp.mean(rgb.reshape(-1, 3), axis=0)
    gain = jnp.asarray(white, jnp.float32) / jnp.maximum(mean, 1.0)
    return jnp.clip(jnp.round(rgb * gain[None, None, :]), 0.0, 255.0)


MAX_BOX_PIXELS = 2**16 - 1  # box counts from a uint16 table are exact below this many pixels
MAX_BOX_HALF = (math.isqrt(MAX_BOX_PIXELS) - 1) // 2  # 127: the largest square half-size below that (255 x 255)


class BinTable(NamedTuple):
    """Summed-area tables of the one-hot indicators of a reference's heaviest bins (:func:`bin_table`).

    Attributes:
        table: ``uint16 [H + 1, W + 1, K]``, ``table[y, x, k]`` = pixels of bin ``top_index[k]`` in rows ``< y``
            and columns ``< x``, modulo ``2^16``.
        q_top: ``float32 [K]`` the reference's values on those bins (largest first).
        top_index: ``int32 [K]`` the bins.
    """

    table: UInt16[Array, "h1 w1 k"]
    q_top: Float[Array, " k"]
    top_index: Int[Array, " k"]


def bin_table(
    image: UInt8[ArrayLike, "h w 3"],
    reference: Float[ArrayLike, " m"],
    top_bins: int = 64,
    bins: tuple[int, int, int] = DEFAULT_BINS,
) -> BinTable:
    """Summed-area tables (integral images) of the ``top_bins`` bins of largest ``reference`` mass.

    Eq. (2) only sums over bins where the reference has mass, so windowed histograms restricted to the
    reference's ``K`` heaviest bins give the exact Bhattacharyya coefficient whenever the reference has at
    most ``K`` non-empty bins (:func:`exact_top_bins`). The tables are ``uint16``: the running sums wrap
    modulo ``2^16``, but a box's four-corner sum (:func:`box_counts`) is exact modulo ``2^16`` and so exact
    for boxes below :data:`MAX_BOX_PIXELS` pixels; XLA's associative scan on 16 bits is several times
    faster than a 32-bit cumulative sum.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        reference: ``float32 [m]`` the reference histogram.
        top_bins: ``K`` (static), at most ``m``.
        bins: the r'g'I bins.

    Returns:
        :class:`BinTable`, zero-padded in front so that ``table[0, :]`` and ``table[:, 0]`` are 0.
    """
    q = jnp.asarray(reference, jnp.float32)
    m = q.shape[0]
    k = min(int(top_bins), m)
    q_top, top_index = lax.top_k(q, k)
    rank = jnp.full((m,), k, jnp.int32).at[top_index].set(jnp.arange(k, dtype=jnp.int32))
    ranked = rank[rgi_bins(image, bins)]  # [H, W]: each pixel's place among the K bins (K: none of them)
    onehot = (ranked[..., None] == jnp.arange(k, dtype=jnp.int32)[None, None, :]).astype(jnp.uint16)
    table = lax.associative_scan(jnp.add, lax.associative_scan(jnp.add, onehot, axis=0), axis=1)
    return BinTable(table=jnp.pad(table, ((1, 0), (1, 0), (0, 0))), q_top=q_top, top_index=top_index)


def box_counts(
    table: UInt16[Array, "h1 w1 k"],
    y0: Int[Array, "*n"],
    y1: Int[Array, "*n"],
    x0: Int[Array, "*n"],
    x1: Int[Array, "*n"],
) -> Float[Array, "*n k"]:
    """Pixels of each bin in the boxes of rows ``[y0, y1)`` and columns ``[x0, x1)`` (already clipped to the
    image, fewer than :data:`MAX_BOX_PIXELS` pixels each), from :class:`BinTable` ``.table``: 4 corner gathers."""
    sums = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]  # modulo 2^16: exact below it
    return sums.astype(jnp.float32)


def exact_top_bins(reference: Float[ArrayLike, " m"], smallest: int = 8) -> int:
    """The smallest power of two (at least ``smallest``, at most ``m``) not below the reference's non-empty
    bins: the ``top_bins`` that keeps :func:`bin_table` exact at the least cost (host-side, concrete input)."""
    q = np.asarray(reference)
    m = int(q.shape[0])
    nonzero = int(np.count_nonzero(q > 0))
    k = smallest
    while k < nonzero:
        k *= 2
    return min(k, m)


def histogram(
    bin_index: Int[ArrayLike, "..."], num: int, weights: Float[ArrayLike, "..."] | None = None
) -> Float[Array, " m"]:
    """Eq. (1): the normalised (weighted) histogram ``p^(u) = f sum_i w_i delta[h(x_i) - u]``.

    Args:
        bin_index: bin of each pixel (any shape).
        num: ``m``, the number of bins.
        weights: optional per-pixel weights of the same shape (a mask, or a kernel profile).

    Returns:
        ``float32 [m]`` summing to 1 (all zeros where the weights sum to 0).
    """
    idx = jnp.asarray(bin_index).reshape(-1)
    w = jnp.ones(idx.shape, jnp.float32) if weights is None else jnp.asarray(weights, jnp.float32).reshape(-1)
    counts = jnp.zeros((num,), jnp.float32).at[idx].add(w)
    total = jnp.sum(counts)
    return jnp.where(total > 0, counts / jnp.where(total > 0, total, 1.0), 0.0)


def patch_histogram(
    image: UInt8[ArrayLike, "h w 3"],
    box: tuple[int, int, int, int] | None = None,
    bins: tuple[int, int, int] = DEFAULT_BINS,
) -> Float[Array, " m"]:
    """The reference histogram ``q`` of an object patch: the whole image, or the box ``(x, y, w, h)`` of it.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        box: optional ``(x, y, width, height)`` in pixels (column, row of the top-left corner).
        bins: as :func:`rgi_bins`.

    Returns:
        ``float32 [m]``, normalised.
    """
    image = jnp.asarray(image)
    if box is not None:
        x, y, w, h = (int(v) for v in box)
        image = image[y : y + h, x : x + w]
    return histogram(rgi_bins(image, bins), num_bins(bins))


def _smooth_along(h: Float[Array, "r g i"], axis: int, weight: float) -> Float[Array, "r g i"]:
    """``h`` convolved with ``(weight, 1 - 2 weight, weight)`` along one axis; mass leaving the ends is dropped."""
    pad = [(0, 0)] * 3
    pad[axis] = (1, 1)
    padded = jnp.pad(h, pad)
    n = h.shape[axis]
    before = lax.slice_in_dim(padded, 0, n, axis=axis)
    after = lax.slice_in_dim(padded, 2, n + 2, axis=axis)
    return (1.0 - 2.0 * weight) * h + weight * (before + after)


def _smoothed(histogram_, bins, weights) -> Float[Array, " m"]:
    h = jnp.asarray(histogram_, jnp.float32).reshape(bins)
    for axis, weight in enumerate(weights):
        if weight:
            h = _smooth_along(h, axis, weight)
    total = jnp.sum(h)
    return (h / jnp.where(total > 0, total, 1.0)).reshape(-1)


def smooth_intensity(
    histogram_: Float[ArrayLike, " m"], bins: tuple[int, int, int] = DEFAULT_BINS, weight: float = 0.25
) -> Float[Array, " m"]:
    """The histogram smoothed along the intensity bins with the kernel ``(weight, 1 - 2 weight, weight)``.

    A kernel density estimate in intensity: a gain on the light (a cloud, a lamp) moves a white ball's
    pixels by up to a bin of ``I`` while ``r'`` and ``g'`` stay; a reference smoothed this way still
    matches it. Mass that would leave the first or last bin is dropped, then the result is
    renormalised.
    """
    return _smoothed(histogram_, bins, (0.0, 0.0, weight))


def smooth_chromaticity(
    histogram_: Float[ArrayLike, " m"], bins: tuple[int, int, int] = DEFAULT_BINS, weight: float = 0.25
) -> Float[Array, " m"]:
    """The histogram smoothed along both chromaticity axes (``r'`` then ``g'``) with ``(weight, 1 - 2 weight,
    weight)``, renormalised.

    White and grey lie where the chromaticity bins meet (``r = g = b``): a slight colour cast of the light
    (warmer or colder) moves a white ball's pixels into the neighbouring bins, which a reference taken under
    another light has no mass in, and the ball drops out of the map. On rendered ``standard`` seed 4 the ball
    went from bins (5, 5) at frame 0 to (6, 6) at frames 89-92 and the map's maximum fell to 0.0-0.12.
    """
    return _smoothed(histogram_, bins, (weight, weight, 0.0))
