"""The reference histogram from a user's box: the object inside it, the background around it weighted out.

A user takes a reference the quick way: a bounding box around the ball in one frame, or that box saved as an
image. The box holds the background in its corners (about a fifth of its area for a round ball in a tight
box, half of it in a box 40 % larger than the ball), and a histogram of the whole box learns grass as part of
the ball (with the previous release's reference, the filters at their default threshold were 265-590 times as
far off as on detector-like maps of the same frames, ``benchmarks/colour_user_box.py``). Three things keep it
out here:

* **A prior on where the object is in the box**: the pixels are weighted by the Epanechnikov profile
  ``k(d^2) = max(0, 1 - d^2)`` over the ellipse inscribed in the box (shrunk by ``shrink``), Comaniciu et al.'s
  kernel-weighted target model: the corners count nothing, the centre most.
* **The background-weighted histogram** (Comaniciu, Ramesh and Meer, "Kernel-based object tracking", IEEE
  PAMI 25(5), 2003, section 6.2): the background's histogram ``o_u`` is taken from the ring around the box
  (between the box and the box scaled ``ring`` times about its centre: three times the box's area for
  ``ring = 2``), and every bin is weighted by ::

      v_u = min(o* / o_u, 1)        (1 where o_u = 0),    o* = the smallest non-zero o_u

  so that the colours common in the background lose weight in the reference whatever the box holds. Ning,
  Zhang, Zhang and Wu ("Robust mean-shift tracking with corrected background-weighted histogram", IET
  Computer Vision 6(1), 2012) showed that weighting the target model *and* the candidates by ``v`` (as
  Comaniciu et al. wrote it) leaves the mean-shift iterations those of the plain histogram, and proposed
  the corrected form (CBWH) used here: only the target model is weighted, ``q'_u = C v_u q_u`` with ``C``
  normalising, and the candidates (:mod:`heatpf_jax.colour.likelihood`'s windows) are plain histograms.
  Where no ring is known (an image cropped to the object), the input's frames stand in for it
  (:func:`frames_histogram`, with ``floor``: see :func:`background_weights`).
* **The object's own box**: the model is matched against the box and the image around it
  (:func:`locate_object`), and a box larger than the object or off-centre is replaced by the box of the
  best window (its centre, its size) before the model is taken again, so that neither the prior nor the
  ring holds much of the other (a box off-centre by a quarter puts part of the ball in the ring).

The weighted model is then smoothed along the intensity and chromaticity bins (lighting changes,
:func:`~heatpf_jax.colour.space.smooth_intensity`, :func:`~heatpf_jax.colour.space.smooth_chromaticity`),
and its lightest bins (together at most ``1 - mass`` of it) are dropped: their share of the coefficient is
that small, and every bin kept costs a summed-area table in every frame.

**The reference's own score.** :func:`reference_score` is the largest background-subtracted coefficient
(:func:`~heatpf_jax.colour.likelihood.window_coefficient`) the reference object gets against its own
model: the object's box set into its background (every pixel outside it holding the background histogram),
every window position and size in it. Dividing the maps by it (:attr:`ColourParams.reference_score
<heatpf_jax.colour.likelihood.ColourParams>`) puts them on an absolute scale: the object looking as it does
in the reference scores about 1 in any frame, whatever the spread of the reference, and a frame without
it stays low (no per-frame normalisation).

Everything here runs once per reference, on the host (NumPy; only the bins come from
:func:`~heatpf_jax.colour.space.rgi_bins`, once per image): patches of every size would each compile
their own JAX programs, seconds of a command that takes the maps of 200 frames in a few.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import numpy as np
from jaxtyping import ArrayLike, Bool, Float, UInt8

from heatpf_jax.colour.likelihood import ColourParams, window_half_sizes
from heatpf_jax.colour.silhouette import chromaticity_probability, reference_silhouette, silhouette_prior
from heatpf_jax.colour.space import (
    DEFAULT_BINS,
    exact_top_bins,
    num_bins,
    rgi_bins,
    smooth_chromaticity,
    smooth_intensity,
)

__all__ = [
    "SCALED_PARAMS",
    "ObjectFit",
    "Reference",
    "ReferenceOptions",
    "background_weights",
    "box_reference",
    "corrected_background_weighted",
    "ellipse_prior",
    "frames_histogram",
    "heaviest_bins",
    "locate_object",
    "reference_score",
    "ring_histogram",
]

# One compiled program each (eager JAX compiles every operation for every new shape: seconds).
_bins = jax.jit(rgi_bins, static_argnums=1)
_half_sizes = jax.jit(window_half_sizes)
_smooth = jax.jit(lambda q, bins, wi, wc: smooth_chromaticity(smooth_intensity(q, bins, wi), bins, wc),
                  static_argnums=(1, 2, 3))

SCALED_PARAMS = ColourParams(theta=0.35, window_scale=0.8)
"""The colour maps' numbers on the reference's own scale (``heatpf colour``): ``theta`` 0.35 of the reference's
own score (chosen on development seeds 100-102 of both renderers of ``benchmarks/colour_user_box.py`` among
0.2-0.5: 0.2 let field lines and a goal post over the filter's threshold, 0.5 lost the ball in frames whose
light differed from the reference's), and an object window of 0.8 ball radii: a square that lies mostly inside
the ball (its corners at 1.13 radii; at 0.9 they reach 1.27, on the grass around it), so that the score falls
as soon as the window leaves the ball's centre. On the development seeds 100-101 of
``benchmarks/colour_user_box.py`` (both renderers, four reference frames, boxes 1.1 and 1.4 times the ball,
centred and off-centre) ``heatmap``'s colour/detector error ratio went from about 2.0 to 1.67 (the independent
renderer) and from about 1.5 to 1.46 (the package's). The cross inscribed in the ball (``window_scale`` 0.851,
``window_waist`` 0.618) did better on the development seeds and worse on the report's independent renderer
(docs/results.md), so it is not the default."""


class ReferenceOptions(NamedTuple):
    """How a reference is taken from a box.

    Attributes:
        shrink: the ellipse prior's semi-axes over the inscribed ellipse's (:func:`ellipse_prior`).
        ring: the background ring's outer box over the box (both centred), 2: three times the box's area
            (Comaniciu et al., section 6.2).
        intensity_smoothing: weight of :func:`~heatpf_jax.colour.space.smooth_intensity` (0: none).
        chroma_smoothing: weight of :func:`~heatpf_jax.colour.space.smooth_chromaticity` (0: none).
        mass: the share of the weighted, smoothed model that is kept (its heaviest bins,
            :func:`heaviest_bins`); 1 keeps every bin.
        max_bins: at most this many bins are kept (the maps' cost grows with them, in steps of 64).
        background: weight the model by the background (the CBWH); ``False`` keeps the prior-weighted
            histogram as it is.
        floor: the least ``o*`` of :func:`background_weights` (0: the paper's, the smallest non-zero bin).
        refine: how many times the box is replaced by the object's own box (:func:`box_reference`).
        min_fill: the object's radius is taken to be at least this share of the box's inscribed radius when it
            is looked for in the box (a box a user draws around a ball; a smaller fit was one dark patch of the
            ball, with the input's frames as the background).
    """

    shrink: float = 0.9
    ring: float = 2.0
    intensity_smoothing: float = 0.25
    chroma_smoothing: float = 0.25
    mass: float = 0.98
    max_bins: int = 64
    background: bool = True
    floor: float = 0.0
    refine: int = 1
    min_fill: float = 0.4


class Reference(NamedTuple):
    """A reference model and how it was made (:func:`box_reference`).

    Attributes:
        histogram: ``float32 [m]`` the model the maps compare with: background-weighted, smoothed, its
            lightest bins dropped, normalised.
        score: the reference's own score (:func:`reference_score`), for
            :attr:`~heatpf_jax.colour.likelihood.ColourParams.reference_score`.
        target: ``float32 [m]`` the object's prior-weighted histogram ``q`` (before the background).
        background: ``float32 [m]`` the background's histogram ``o``.
        weights: ``float32 [m]`` the background weights ``v`` (:func:`background_weights`; ones without).
        box: ``(x, y, width, height)`` the object's box the model was taken from (after refinement).
        silhouette: ``float32 [m]`` every bin's probability of showing the object, by its chromaticity
            (:func:`~heatpf_jax.colour.silhouette.chromaticity_probability` of ``histogram`` against ``background``,
            the prior :func:`~heatpf_jax.colour.silhouette.silhouette_prior` of the ring), for the maps'
            ``object_probability``; ``None`` where not taken.
        silhouette_score: the object's own silhouette score in its box
            (:func:`~heatpf_jax.colour.silhouette.reference_silhouette`), for
            :attr:`~heatpf_jax.colour.likelihood.ColourParams.silhouette_score`; 0 where not taken.
    """

    histogram: np.ndarray
    score: float
    target: np.ndarray
    background: np.ndarray
    weights: np.ndarray
    box: tuple[int, int, int, int]
    silhouette: np.ndarray | None = None
    silhouette_score: float = 0.0


def _normalised(counts: np.ndarray) -> np.ndarray:
    total = counts.sum()
    return (counts / total if total > 0 else np.zeros_like(counts)).astype(np.float32)


def _histogram(idx: np.ndarray, m: int, weights: np.ndarray | None = None) -> np.ndarray:
    """Eq. (1) on bin indices (:func:`~heatpf_jax.colour.space.histogram`'s, in NumPy)."""
    w = None if weights is None else np.asarray(weights, np.float64).ravel()
    return _normalised(np.bincount(np.asarray(idx).ravel(), weights=w, minlength=m).astype(np.float64))


def ellipse_prior(height: int, width: int, shrink: float = 0.9) -> Float[np.ndarray, "h w"]:
    """The Epanechnikov profile ``max(0, 1 - d^2)`` over the ellipse inscribed in a ``height x width`` box.

    ``d`` is a pixel centre's distance from the box's centre in units of the semi-axes ``shrink * height / 2``
    and ``shrink * width / 2`` (Comaniciu et al. 2003's kernel-weighted target model): the corners,
    where a round object's box holds background, get 0.

    Returns:
        ``float32 [height, width]``, at most 1 (the centre), never all 0 for a box of a pixel or more.
    """
    v = (np.arange(height) + 0.5 - height / 2.0) / max(shrink * height / 2.0, 0.5)
    u = (np.arange(width) + 0.5 - width / 2.0) / max(shrink * width / 2.0, 0.5)
    d2 = v[:, None] ** 2 + u[None, :] ** 2
    return np.maximum(1.0 - d2, 0.0).astype(np.float32)


def _ring_mask(shape: tuple[int, int], box, ring: float) -> np.ndarray:
    x, y, w, h = (int(v) for v in box)
    grow_x, grow_y = (ring - 1.0) * w / 2.0, (ring - 1.0) * h / 2.0
    x0, x1 = max(int(math.floor(x - grow_x)), 0), min(int(math.ceil(x + w + grow_x)), shape[1])
    y0, y1 = max(int(math.floor(y - grow_y)), 0), min(int(math.ceil(y + h + grow_y)), shape[0])
    mask = np.zeros(shape, bool)
    mask[y0:y1, x0:x1] = True
    mask[max(y, 0):y + h, max(x, 0):x + w] = False
    return mask


def ring_histogram(
    image: UInt8[ArrayLike, "h w 3"],
    box: tuple[int, int, int, int],
    ring: float = 2.0,
    bins: tuple[int, int, int] = DEFAULT_BINS,
) -> tuple[Float[np.ndarray, " m"], int]:
    """The histogram of the ring around ``box``: inside the box scaled ``ring`` times about its centre (clipped
    to the image), outside the box.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        box: ``(x, y, width, height)`` pixels.
        ring: the outer box over the box; 2 gives three times the box's area (Comaniciu et al., section 6.2).
        bins: the r'g'I bins.

    Returns:
        ``(o [m], pixels)``: the normalised histogram (zeros when the ring is empty) and the ring's pixel count.
    """
    idx = np.asarray(_bins(image, bins))
    mask = _ring_mask(idx.shape, box, ring)
    return _histogram(idx[mask], num_bins(bins)), int(mask.sum())


def frames_histogram(
    images: UInt8[ArrayLike, "t h w 3"], num: int = 8, bins: tuple[int, int, int] = DEFAULT_BINS
) -> Float[np.ndarray, " m"]:
    """The mean histogram of ``num`` frames spread evenly over ``images``: the scene's background where no
    ring around the object is known (a reference image cropped to the object)."""
    images = np.asarray(images)
    picks = np.unique(np.linspace(0, images.shape[0] - 1, max(min(int(num), images.shape[0]), 1)).round().astype(int))
    return _histogram(np.asarray(_bins(images[picks], bins)), num_bins(bins))


def background_weights(background: Float[ArrayLike, " m"], floor: float = 0.0) -> Float[np.ndarray, " m"]:
    """Comaniciu et al.'s background weights ``v_u = min(o* / o_u, 1)`` (2003, section 6.2).

    ``o*`` is the smallest non-zero ``o_u`` (the paper's choice, ``floor = 0``), or ``floor`` where that is
    larger: every bin holding at most ``floor`` of the background then keeps weight 1, and only the colours
    common in it lose weight. Bins the background lacks get 1; all ones for an empty background.

    The paper's ``o*`` suits a ring (a few hundred pixels: ``o*`` is one of them); on the development seeds a
    floor of 0.002-0.01 over a ring let more field lines into the maps. Over the input's frames (a hundred
    thousand pixels) it weighs every colour seen anywhere, a ball's white in the field lines, down to nothing
    beside colours never seen (one dark patch of the ball became the reference); ``heatpf colour`` then
    takes a ring's resolution as the floor (one pixel in a ring three times the box's area).
    """
    o = np.asarray(background, np.float64)
    present = o > 0
    if not present.any():
        return np.ones(o.shape, np.float32)
    o_star = max(float(o[present].min()), float(floor))
    return np.where(present, np.minimum(o_star / np.where(present, o, 1.0), 1.0), 1.0).astype(np.float32)


def corrected_background_weighted(
    target: Float[ArrayLike, " m"], background: Float[ArrayLike, " m"], floor: float = 0.0
) -> Float[np.ndarray, " m"]:
    """The corrected background-weighted target model (CBWH, Ning et al. 2012): ``q'_u = C v_u q_u`` with
    ``v`` from :func:`background_weights` and ``C`` normalising; the candidates are left unweighted.

    Returns:
        ``float32 [m]`` summing to 1 (``target`` itself where every one of its bins has weight 0).
    """
    q = np.asarray(target, np.float64)
    weighted = background_weights(background, floor) * q
    return _normalised(weighted) if weighted.sum() > 0 else q.astype(np.float32)


def heaviest_bins(
    histogram_: Float[ArrayLike, " m"], mass: float = 0.98, max_bins: int | None = None
) -> Float[np.ndarray, " m"]:
    """The histogram restricted to its heaviest bins that together hold at least ``mass`` of it (at most
    ``max_bins`` of them), renormalised.

    Ties at the cut are kept together, so the result does not depend on the order of equal bins (and may
    hold more than ``max_bins`` where the cut falls among equal bins).
    """
    q = np.asarray(histogram_, np.float64)
    if mass >= 1.0 and max_bins is None:
        return q.astype(np.float32)
    ordered = np.sort(q)[::-1]
    cut = int(np.searchsorted(np.cumsum(ordered), mass * q.sum()))  # the first bin reaching the mass
    if max_bins is not None:
        cut = min(cut, int(max_bins) - 1)
    kept = np.where(q >= ordered[min(cut, q.size - 1)], q, 0.0)
    return _normalised(kept) if kept.sum() > 0 else q.astype(np.float32)


class ObjectFit(NamedTuple):
    """Where a reference matches best in its own patch (:func:`locate_object`).

    Attributes:
        score: the largest coefficient ``rho`` (eq. 2-3, before ``theta``).
        row, col: the best window's centre, pixels of the patch.
        radius: the object's radius in pixels (the best object window's half-size over ``window_scale``).
    """

    score: float
    row: int
    col: int
    radius: float


def _coefficient(
    table: np.ndarray, q_top: np.ndarray, rows, cols, inner: int, outer: int, waist: float = 1.0
) -> np.ndarray:
    """:func:`~heatpf_jax.colour.likelihood.window_coefficient` with one window size, at the pixels
    ``rows x cols`` of the table's image (NumPy)."""
    h, w = table.shape[0] - 1, table.shape[1] - 1
    v, u = np.asarray(rows)[:, None], np.asarray(cols)[None, :]

    def box(rx, ry):
        y0, y1 = np.clip(v - ry, 0, h), np.clip(v + ry + 1, 0, h)
        x0, x1 = np.clip(u - rx, 0, w), np.clip(u + rx + 1, 0, w)
        sums = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        return sums, ((y1 - y0) * (x1 - x0)).astype(np.float64)

    b = int(min(max(np.round(np.float32(waist) * np.float32(inner)), 0), inner))  # as the maps round it
    (wide, n_wide), (tall, n_tall), (both, n_both) = box(inner, b), box(b, inner), box(b, b)
    in_sum, in_count = np.maximum(wide + tall - both, 0.0), n_wide + n_tall - n_both
    out_sum, out_count = box(outer, outer)
    out_sum = np.maximum(out_sum, 0.0)
    p_obj = in_sum / np.maximum(in_count, 1.0)[..., None]
    p_bck = np.maximum(out_sum - in_sum, 0.0) / np.maximum(out_count - in_count, 1.0)[..., None]
    return np.sum(np.sqrt(q_top) * np.maximum(np.sqrt(p_obj) - np.sqrt(p_bck), 0.0), axis=-1)


def _locate(q, idx, background, params: ColourParams, where=None, radius=None, smallest=0.2) -> ObjectFit:
    """:func:`locate_object` on a patch's bin indices ``idx [h, w]``."""
    q = np.asarray(q, np.float64)
    h, w = idx.shape
    k = exact_top_bins(q)
    top = np.argsort(-q, kind="stable")[:k]
    rank = np.full(q.shape[0], k)
    rank[top] = np.arange(k)
    onehot = (rank[idx][..., None] == np.arange(k)).astype(np.float64)
    radius = min(h, w) / 2.0 if radius is None else float(radius)
    tried = np.clip(np.round(np.linspace(smallest, 1.0, 17) * radius), params.min_half_size, params.max_half_size)
    _, outer = _half_sizes(tried.astype(np.float32), params._replace(window_scale=1.0))  # sizes as given
    outers = dict(zip(tried.astype(int).tolist(), np.asarray(outer).astype(int).tolist(), strict=True))
    sizes = sorted(outers)
    pad = max(outers.values())
    canvas = np.broadcast_to(np.asarray(background, np.float64)[top], (h + 2 * pad, w + 2 * pad, k)).copy()
    canvas[pad:pad + h, pad:pad + w] = onehot
    table = np.zeros((h + 2 * pad + 1, w + 2 * pad + 1, k))
    table[1:, 1:] = canvas.cumsum(axis=0).cumsum(axis=1)
    allowed = np.ones((h, w), bool) if where is None else np.asarray(where, bool)
    best = ObjectFit(0.0, h // 2, w // 2, radius)
    for s in sizes:
        rho = _coefficient(table, q[top], np.arange(pad, pad + h), np.arange(pad, pad + w), s, outers[s],
                           params.window_waist)
        rho = np.where(allowed, rho, 0.0)
        at = np.unravel_index(int(np.argmax(rho)), rho.shape)
        if rho[at] > best.score:
            best = ObjectFit(float(rho[at]), int(at[0]), int(at[1]), s / params.window_scale)
    return best


def locate_object(
    reference: Float[ArrayLike, " m"],
    patch: UInt8[ArrayLike, "h w 3"],
    background: Float[ArrayLike, " m"],
    params: ColourParams = ColourParams(),
    *,
    bins: tuple[int, int, int] = DEFAULT_BINS,
    where: Bool[ArrayLike, "h w"] | None = None,
    radius: float | None = None,
    smallest: float = 0.2,
) -> ObjectFit:
    """The window of the largest :func:`~heatpf_jax.colour.likelihood.window_coefficient` of ``reference`` in
    ``patch`` set into its background.

    The patch (a box's pixels) is placed in a canvas whose other pixels each hold the histogram ``background``
    (fractional bin counts: the ring as the maps see it on average), and the coefficient is taken at every
    pixel of the patch (where ``where`` holds), with object windows of half-sizes from ``smallest`` to the whole
    of ``radius`` (windows larger or smaller than the object score lower: the best one finds its size too). The
    canvas, and so the fit, is the same for a box in a frame and for that box saved as an image, given the
    same background. Only the reference's :func:`~heatpf_jax.colour.space.exact_top_bins` heaviest bins
    count, as in the maps' tables.

    Args:
        reference: ``float32 [m]`` the model.
        patch: ``uint8 [h, w, 3]`` the box's pixels.
        background: ``float32 [m]`` the background's histogram.
        params: the maps' :class:`~heatpf_jax.colour.likelihood.ColourParams` (window and ring sizes).
        bins: the r'g'I bins.
        where: ``bool [h, w]`` the window centres tried (default: every pixel of the patch).
        radius: the largest object window half-size tried, pixels (default: the patch's inscribed radius).
        smallest: the smallest object window half-size tried, a share of ``radius``.

    Returns:
        :class:`ObjectFit` (score 0 where the reference matches nothing).
    """
    return _locate(reference, np.asarray(_bins(patch, bins)), background, params, where, radius, smallest)


def reference_score(
    reference: Float[ArrayLike, " m"],
    patch: UInt8[ArrayLike, "h w 3"],
    background: Float[ArrayLike, " m"],
    params: ColourParams = ColourParams(),
    *,
    bins: tuple[int, int, int] = DEFAULT_BINS,
) -> float:
    """The reference object's own score: :func:`locate_object`'s coefficient (0 where the reference matches
    nothing in its patch: no colour of it stands out from the background)."""
    return locate_object(reference, patch, background, params, bins=bins).score


def _model(idx, background, options: ReferenceOptions, bins) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(model, target, weights)`` of the object in the patch of bin indices ``idx`` (see :func:`box_reference`)."""
    m = num_bins(bins)
    target = _histogram(idx, m, ellipse_prior(idx.shape[0], idx.shape[1], options.shrink))
    if options.background:
        weights = background_weights(background, options.floor)
        weighted = corrected_background_weighted(target, background, options.floor)
    else:
        weights = np.ones((m,), np.float32)
        weighted = target
    model = np.asarray(_smooth(weighted, bins, float(options.intensity_smoothing), float(options.chroma_smoothing)))
    return heaviest_bins(model, options.mass, options.max_bins), target, weights


def _clip_box(box, shape) -> tuple[int, int, int, int]:
    x0, y0 = max(box[0], 0), max(box[1], 0)
    x1, y1 = min(box[0] + box[2], shape[1]), min(box[1] + box[3], shape[0])
    return x0, y0, max(x1 - x0, 1), max(y1 - y0, 1)


def box_reference(
    image: UInt8[ArrayLike, "h w 3"],
    box: tuple[int, int, int, int],
    options: ReferenceOptions = ReferenceOptions(),
    params: ColourParams = ColourParams(),
    *,
    bins: tuple[int, int, int] = DEFAULT_BINS,
    background: Float[ArrayLike, " m"] | None = None,
) -> Reference:
    """The reference of the object in ``box`` ``(x, y, width, height)`` of ``image`` (a frame, or a reference
    image with the box the whole of it).

    1. The model of the box: its prior-weighted histogram (:func:`ellipse_prior`), weighted by the background
       (:func:`corrected_background_weighted`, unless ``options.background`` is off), smoothed along intensity
       and chromaticity, cut to its heaviest bins (:func:`heaviest_bins`).
    2. Where the object is in the box (:func:`locate_object` on the box and the image around it, the window's
       centre inside the box): a box that is larger than the object or off-centre is replaced by the object's
       own box (its best window's centre and radius, clipped to the image), and step 1 is repeated on it, so
       that neither the prior nor the ring holds much of the other.
    3. The model's own score (:func:`reference_score`, on the object's box).

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        box: ``(x, y, width, height)``, pixels, inside ``image``.
        options: :class:`ReferenceOptions`.
        params: the maps' :class:`~heatpf_jax.colour.likelihood.ColourParams` (window sizes, for steps 2-3).
        bins: the r'g'I bins.
        background: the background's histogram ``o``; default the ring around the box in ``image``
            (:func:`ring_histogram`, taken again around the object's box in step 2). Give it for an image that
            is cropped to the object (:func:`frames_histogram`).

    Returns:
        :class:`Reference`.
    """
    idx = np.asarray(_bins(image, bins))  # once: every patch below is cut from it
    m = num_bins(bins)

    def crop(b):
        return idx[b[1]:b[1] + b[3], b[0]:b[0] + b[2]]

    def ring(b):
        if background is not None:
            return np.asarray(background, np.float32)
        return _histogram(idx[_ring_mask(idx.shape, b, options.ring)], m)

    box = tuple(int(v) for v in box)
    o = ring(box)
    for _ in range(options.refine):
        model, _, _ = _model(crop(box), o, options, bins)
        # Around the box, so that an object the box cuts is seen whole; its centre inside the box.
        x, y, w, h = box
        around = _clip_box((x - w // 2, y - h // 2, 2 * w, 2 * h), idx.shape)
        inside = np.zeros((around[3], around[2]), bool)
        inside[y - around[1]:y - around[1] + h, x - around[0]:x - around[0] + w] = True
        fit = _locate(model, crop(around), o, params, where=inside, radius=min(w, h) / 2.0,
                      smallest=options.min_fill * params.window_scale)
        if fit.score <= 0.0:
            break
        r = max(int(round(fit.radius)), 1)
        box = _clip_box((around[0] + fit.col - r, around[1] + fit.row - r, 2 * r + 1, 2 * r + 1), idx.shape)
        o = ring(box)
    model, target, weights = _model(crop(box), o, options, bins)
    score = _locate(model, crop(box), o, params).score
    lut, own = _silhouette(model, o, crop(box), box, options, params, bins)
    return Reference(histogram=model, score=score, target=target, background=o, weights=weights, box=box,
                     silhouette=lut, silhouette_score=own)


def _silhouette(model, background, idx, box, options: ReferenceOptions, params: ColourParams, bins):
    """The object probability of every bin (by its chromaticity) and the object's own silhouette score in its box
    (:class:`Reference`): the ring's prior, one of its ``(ring^2 - 1) w h`` pixels as the least background mass,
    the box's inscribed radius as the object's, the pixels around the box at the background's mean probability."""
    w, h = box[2], box[3]
    lut = chromaticity_probability(model, background, silhouette_prior(options.ring), (options.ring**2 - 1.0) * w * h,
                                   bins)
    o = np.asarray(background, np.float64)
    mean = float(np.sum(o * lut) / o.sum()) if o.sum() > 0 else 0.0
    radius = max((min(w, h) - 1) / 2.0, 1.0)
    return lut, reference_silhouette(lut[idx], mean, radius, params.silhouette_outer)
