"""The ball's outline in a colour map: a matched filter of each pixel's object probability.

A histogram window inside the ball (:mod:`heatpf_jax.colour.likelihood`) holds the same colours wherever it lies
within the ball, so its response is nearly flat over the ball's middle and its peak follows the patches that turn
into and out of it. Where the ball *is* is told by its outline: the disc where the object's colours are, against
the grass around it. This module scores that outline.

Every pixel first gets the probability that it shows the object, from the reference's model ``q`` and its
background's histogram ``o`` (Bayes' rule with the prior ``pi``; ``1 / N`` keeps a colour the background did not
show, one pixel of its ``N``, from counting as certain)::

    P(u) = pi q_u / (pi q_u + (1 - pi) (o_u + 1 / N))

taken on the chromaticity alone (:func:`chromaticity_probability`: ``q`` and ``o`` summed over the intensity bins),
since the ball's lit top and shaded bottom lie in different intensity bins and would weigh its two halves
differently; then the *silhouette score* of a ball of radius ``r`` centred at each pixel is the mean of ``P`` over
the disc of radius ``r`` less its mean over the annulus from ``r`` to ``outer * r``::

    S(x) = mean_{|y - x| <= r} P(y) - mean_{r < |y - x| <= outer r} P(y)

the matched filter of a disc on a plain background: as the disc moves off the ball by ``d`` it loses object pixels
along its rim and its annulus gains them, so ``S`` falls from its peak in proportion to ``d`` (a cone; a window
inside the ball stays flat until it reaches the rim). Only pixels inside the image count (a disc the border cuts is
scored on what is seen). Disc sums are exact: the row prefix sums of ``P`` summed over the disc's rows.

:func:`heatpf_jax.colour.likelihood.colour_heatmaps` combines it with the histogram map ``H`` as ::

    H(x) * (1 - c + c S+(x) / S_max(x)),        c = min(S_max(x) / S_ref, 1)

``S+`` the score clipped at 0, ``S_max`` its largest value within the ball's radius of ``x`` (:func:`window_max`)
and ``S_ref`` the reference's own score (:func:`reference_silhouette`): the histogram's map tells *whether* the
object's colours are there (with its ring test; a white goal post as wide as the ball fills a disc too), the outline
*where*, in proportion to how clearly it is seen. Where it is as clear as in the reference the map is the histogram's
value times the outline's cone, its peak where the outline's is; where little outline is seen (a ball in front of a
white post or on a line) the histogram's map stays as it is. The outline's best point keeps the histogram's value,
and nothing raises it (a geometric mean did, and a far post's weak histogram response became the brightest thing in
view). Two forms measured worse: ``S / S_ref`` clipped at 1 cuts the cone to a plateau, whose centroid is no better
than a pixel mask's; and ``S+ / max(S_max, S_ref)`` takes a ball in front of a white post below the threshold.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

__all__ = [
    "chromaticity_probability",
    "disc_means",
    "object_probability",
    "reference_silhouette",
    "silhouette_prior",
    "silhouette_score",
    "window_max",
]


def silhouette_prior(ring: float = 2.0) -> float:
    """``pi``, the share of a box's ring (a square ``ring`` times the ball's diameter on a side) that a ball of
    the box's size covers: ``pi r^2 / (2 ring r)^2 = pi / (4 ring^2)`` (0.196 for the reference's ring of 2)."""
    return math.pi / (4.0 * float(ring) ** 2)


def object_probability(
    model: Float[ArrayLike, " m"], background: Float[ArrayLike, " m"], prior: float, pixels: float
) -> Float[np.ndarray, " m"]:
    """Every bin's probability of showing the object: ``pi q_u / (pi q_u + (1 - pi)(o_u + 1 / N))``.

    Args:
        model: ``[m]`` the object's histogram ``q`` (normalised here).
        background: ``[m]`` the background's histogram ``o`` (normalised here; all zeros: no background known).
        prior: ``pi`` in ``(0, 1)``, the object's share of what is looked at (:func:`silhouette_prior`).
        pixels: ``N > 0``, the number of background pixels ``o`` was taken from: a colour it did not show has
            background mass ``1 / N``, not 0.

    Returns:
        ``float32 [m]`` in ``[0, 1)``; 0 where ``q`` is 0.
    """
    q = np.asarray(model, np.float64)
    o = np.asarray(background, np.float64)
    q = q / max(q.sum(), 1e-300)
    o = o / o.sum() if o.sum() > 0 else o
    if not 0.0 < prior < 1.0:
        raise ValueError(f"prior: must lie in (0, 1), got {prior}")
    if not pixels > 0:
        raise ValueError(f"pixels: must be positive, got {pixels}")
    obj = prior * q
    return (obj / (obj + (1.0 - prior) * (o + 1.0 / pixels))).astype(np.float32)


def _disc_sums(values, radii, reach):
    """Per pixel and per radius in ``radii`` (a tuple of ``[H, W]`` arrays), the sum of ``values`` and the count
    of image pixels over the disc (``|dy|`` rows up to ``reach``, a traced bound)."""
    h, w = values.shape
    prefix = jnp.pad(jnp.cumsum(values, axis=1), ((0, 0), (1, 0)))  # [H, W + 1]
    v, u = jnp.meshgrid(jnp.arange(h, dtype=jnp.int32), jnp.arange(w, dtype=jnp.int32), indexing="ij")
    zeros = tuple((jnp.zeros((h, w), jnp.float32), jnp.zeros((h, w), jnp.float32)) for _ in radii)

    def body(i, acc):
        dy = i - reach
        row = v + dy
        in_rows = (row >= 0) & (row < h)
        r_safe = jnp.clip(row, 0, h - 1)
        out = []
        for radius, (total, count) in zip(radii, acc, strict=True):
            half = jnp.floor(jnp.sqrt(jnp.maximum(radius * radius - (dy * dy).astype(jnp.float32), 0.0)))
            ok = in_rows & (jnp.abs(dy).astype(jnp.float32) <= radius)
            x0 = jnp.clip(u - half.astype(jnp.int32), 0, w)
            x1 = jnp.clip(u + half.astype(jnp.int32) + 1, 0, w)
            seg = prefix[r_safe, x1] - prefix[r_safe, x0]
            out.append((total + jnp.where(ok, seg, 0.0), count + jnp.where(ok, (x1 - x0).astype(jnp.float32), 0.0)))
        return tuple(out)

    return lax.fori_loop(0, 2 * reach + 1, body, zeros)


def disc_means(
    values: Float[ArrayLike, "h w"],
    radius: Float[ArrayLike, "h w"],
    outer: Float[ArrayLike, "h w"],
    where: Bool[ArrayLike, "h w"] | None = None,
) -> tuple[Float[Array, "h w"], Float[Array, "h w"]]:
    """The mean of ``values`` over the disc of ``radius`` around every pixel, and over the annulus from
    ``radius`` to ``outer`` (pixels ``y`` with ``|y - x|^2 <= radius^2`` and ``radius^2 < |y - x|^2 <=
    outer^2``), each over the image's pixels only (0 where the region holds none).

    Args:
        values: ``[H, W]``.
        radius: ``[H, W]`` the disc's radius per pixel, pixels (``>= 0``).
        outer: ``[H, W]`` the annulus's outer radius per pixel (``>= radius``).
        where: ``bool [H, W]`` the pixels whose means are wanted (default: all); the others' are computed over
            the rows that those need only (a cost that follows the largest wanted radius), and are not exact.

    Returns:
        ``(disc, annulus)``, each ``float32 [H, W]``.
    """
    values = jnp.asarray(values, jnp.float32)
    radius = jnp.asarray(radius, jnp.float32)
    outer = jnp.maximum(jnp.asarray(outer, jnp.float32), radius)
    wanted = outer if where is None else jnp.where(jnp.asarray(where, bool), outer, 0.0)
    reach = jnp.ceil(jnp.max(wanted)).astype(jnp.int32)
    (s_in, n_in), (s_out, n_out) = _disc_sums(values, (radius, outer), reach)
    disc = s_in / jnp.maximum(n_in, 1.0)
    annulus = jnp.maximum(s_out - s_in, 0.0) / jnp.maximum(n_out - n_in, 1.0)
    return disc, jnp.where(n_out > n_in, annulus, 0.0)


def silhouette_score(
    probability: Float[ArrayLike, "h w"],
    radius: Float[ArrayLike, "h w"],
    outer: float = 1.5,
    where: Bool[ArrayLike, "h w"] | None = None,
) -> Float[Array, "h w"]:
    """``S(x)``: the mean object probability over the disc of ``radius`` around each pixel less its mean over
    the annulus out to ``outer`` times that radius (see the module docstring); 0 where ``radius`` is 0.

    Args:
        probability: ``[H, W]`` each pixel's object probability (:func:`object_probability` of its bin).
        radius: ``[H, W]`` the ball's radius in pixels, were it centred there.
        outer: the annulus's outer radius over ``radius`` (``> 1``).
        where: the pixels whose score is wanted (:func:`disc_means`; default all): the others' are not exact.

    Returns:
        ``float32 [H, W]`` in ``[-1, 1]``.
    """
    radius = jnp.asarray(radius, jnp.float32)
    disc, annulus = disc_means(probability, radius, outer * radius, where)
    return jnp.where(radius > 0, disc - annulus, 0.0)


def reference_silhouette(
    probability: Float[ArrayLike, "h w"], background: float, radius: float, outer: float = 1.5
) -> float:
    """The reference object's own silhouette score: the largest :func:`silhouette_score` of its box's pixels
    ``probability`` set into a canvas whose other pixels hold ``background`` (the background's mean object
    probability, ``sum_u o_u P(u)``), at the object's ``radius``.

    The canvas is the same for a box in a frame and for that box saved as an image, as for the histogram's
    own score (:func:`heatpf_jax.colour.reference.locate_object`). NumPy; exact disc sums.

    Args:
        probability: ``[h, w]`` the object box's pixels' object probabilities.
        background: the probability that stands for every pixel around the box.
        radius: the object's radius, pixels.
        outer: as in :func:`silhouette_score`.

    Returns:
        The largest score over the box's pixels (at least 0).
    """
    p = np.asarray(probability, np.float64)
    h, w = p.shape
    pad = int(math.ceil(outer * radius)) + 1
    canvas = np.full((h + 2 * pad, w + 2 * pad), float(background))
    canvas[pad:pad + h, pad:pad + w] = p
    dy, dx = np.mgrid[-pad:pad + 1, -pad:pad + 1]
    d2 = dy * dy + dx * dx
    disc = d2 <= radius * radius
    ring = (d2 > radius * radius) & (d2 <= (outer * radius) ** 2)
    best = 0.0
    for row in range(h):
        for col in range(w):
            patch = canvas[row:row + 2 * pad + 1, col:col + 2 * pad + 1]
            best = max(best, float(patch[disc].mean() - patch[ring].mean()))
    return best


def chromaticity_probability(
    model: Float[ArrayLike, " m"],
    background: Float[ArrayLike, " m"],
    prior: float,
    pixels: float,
    bins: tuple[int, int, int],
) -> Float[np.ndarray, " m"]:
    """:func:`object_probability` of the chromaticity alone: ``q`` and ``o`` summed over the intensity bins, the
    probability of each ``(r', g')`` given to every intensity bin of it.

    A ball is lit from above: its top is brighter than its shaded bottom, and a reference taken in another light
    holds the two in other intensity bins than a frame does. On the independent renderer of
    ``benchmarks/colour_user_box.py`` (development seed 106, the ``light`` reference) the full model's probability
    was 0.54-0.57 over the ball's upper rows and 0.84 over its lower ones, and the outline's centre lay 2.6 cm
    towards the camera on average; by chromaticity the rows were even and the centre 0.3-0.5 cm off, as the
    detector-like maps' (docs/results.md).

    Args:
        model: ``[m]`` the object's histogram ``q`` over the r'g'I bins ``bins``.
        background: ``[m]`` the background's histogram ``o`` over the same bins.
        prior: ``pi`` in ``(0, 1)`` (:func:`object_probability`).
        pixels: ``N > 0`` (:func:`object_probability`).
        bins: ``(n_r, n_g, n_I)`` (:func:`~heatpf_jax.colour.space.rgi_bins`; the intensity varies fastest).

    Returns:
        ``float32 [m]`` in ``[0, 1)``.
    """
    n_r, n_g, n_i = (int(b) for b in bins)
    q = np.asarray(model, np.float64).reshape(n_r, n_g, n_i).sum(axis=-1)
    o = np.asarray(background, np.float64).reshape(n_r, n_g, n_i).sum(axis=-1)
    chroma = object_probability(q.ravel(), o.ravel(), prior, pixels).reshape(n_r, n_g, 1)
    return np.repeat(chroma, n_i, axis=-1).ravel()


def window_max(
    values: Float[ArrayLike, "h w"], half_size: Float[ArrayLike, "h w"], bound: int = 32
) -> Float[Array, "h w"]:
    """The largest of the non-negative ``values`` over the square of half-size ``round(half_size)`` around every
    pixel (the image's pixels in it), from a sparse table of maxima.

    Level ``k`` of the table holds the maximum over the ``2^k x 2^k`` square from each pixel; a square of side
    ``s = 2 r + 1`` is covered by four such squares with ``2^k <= s`` (they overlap, as a maximum allows). The image
    is padded by ``bound`` zeros, so squares cut by the border need no clipping: values must be at least 0.

    Args:
        values: ``[H, W]``, at least 0.
        half_size: ``[H, W]`` the square's half-size per pixel, clipped to ``[0, bound]``.
        bound: the largest half-size (static).

    Returns:
        ``float32 [H, W]``.
    """
    values = jnp.asarray(values, jnp.float32)
    h, w = values.shape
    bound = int(bound)
    levels = max((2 * bound + 1).bit_length(), 1)  # 2^(levels - 1) <= 2 bound + 1
    padded = jnp.pad(values, bound)  # a level's squares past the padding are filled with 0 as they are built
    tables = [padded]
    for k in range(levels - 1):
        t, d = tables[-1], 2**k
        shifted_rows = jnp.pad(t[d:], ((0, d), (0, 0)))
        t = jnp.maximum(t, shifted_rows)
        tables.append(jnp.maximum(t, jnp.pad(t[:, d:], ((0, 0), (0, d)))))
    table = jnp.stack(tables)  # [levels, H', W']
    r = jnp.clip(jnp.round(jnp.asarray(half_size, jnp.float32)), 0, bound).astype(jnp.int32)
    side = 2 * r + 1
    k = 31 - lax.clz(side)  # floor(log2(side)), exact in integers
    step = jnp.left_shift(1, k)
    v, u = jnp.meshgrid(jnp.arange(h, dtype=jnp.int32), jnp.arange(w, dtype=jnp.int32), indexing="ij")
    y0, x0 = v - r + bound, u - r + bound
    y1, x1 = v + r - step + 1 + bound, u + r - step + 1 + bound
    return jnp.maximum(jnp.maximum(table[k, y0, x0], table[k, y0, x1]), jnp.maximum(table[k, y1, x0], table[k, y1, x1]))
