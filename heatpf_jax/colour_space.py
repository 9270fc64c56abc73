"""The r'g'I colour space and its histograms (Olufs et al., section 2, eq. 1).

Olufs et al. bin colours in an illumination-invariant space, ``(r', g', I) = (r / g, g / b, (r + g + b) / 3)``,
with ``12 x 12 x 4`` bins: 12 x 12 for the two chromaticity ratios and only 4 for the intensity, which keeps
black and white apart while staying insensitive to lighting changes. The ratios are unbounded (and undefined
at 0), so each is binned by its angle: ``atan2(r + 1, g + 1)`` maps ``r / g`` in ``(0, inf)`` onto
``(0, pi / 2)`` symmetrically about 1 (grey), and a gain on all three channels leaves it (nearly) unchanged.

Every function here is pure JAX on ``uint8`` images; :mod:`heatpf_jax.colour` builds the likelihood maps on
them and :mod:`heatpf_jax.baselines.image_trackers` the image-space trackers.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int, UInt8

__all__ = ["DEFAULT_BINS", "histogram", "num_bins", "patch_histogram", "rgi_bins", "smooth_intensity"]

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
        image: ``uint8 [H, W, 3]`` RGB (any leading axes are kept).
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


def smooth_intensity(
    histogram_: Float[ArrayLike, " m"], bins: tuple[int, int, int] = DEFAULT_BINS, weight: float = 0.25
) -> Float[Array, " m"]:
    """The histogram smoothed along the intensity bins with the kernel ``(weight, 1 - 2 weight, weight)``.

    A kernel density estimate in intensity: a gain on the light (a cloud, a lamp) moves a white ball's
    pixels by up to a bin of ``I`` while ``r'`` and ``g'`` stay; a reference smoothed this way still
    matches it. Mass that would leave the first or last bin is dropped, then the result is
    renormalised.
    """
    n_r, n_g, n_i = bins
    h = jnp.asarray(histogram_, jnp.float32).reshape(n_r, n_g, n_i)
    padded = jnp.pad(h, ((0, 0), (0, 0), (1, 1)))
    out = (1.0 - 2.0 * weight) * h + weight * (padded[..., :-2] + padded[..., 2:])
    total = jnp.sum(out)
    return (out / jnp.where(total > 0, total, 1.0)).reshape(-1)
