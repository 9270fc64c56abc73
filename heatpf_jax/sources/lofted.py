"""A measurement source for balls in the air: a blob larger than a ground ball there is placed by its size.

The paper's projection (III-A) puts every pixel on the plane ``z = R`` (the ball radius): right for a ball on
the ground, metres wrong for a chip or a lob. A ball of radius ``R`` seen with an apparent radius of ``rho``
pixels lies at the optical depth ``d = f R / rho`` along its pixel's ray; a ball lying on the ground where the
ray meets the plane (optical depth ``d_g``) would look ``rho_g = f R / d_g`` pixels large. A ball in the air
is nearer than the ground point its ray meets, so its blob is larger than a ground ball's there by the factor

    q = rho / rho_g = d_g / d  (> 1 in the air; about 1 on the ground),

and above the horizon, where the ray meets no ground, ``q`` is infinite. :class:`LoftedSource` measures each
blob's apparent size and:

* keeps every pixel of a blob with ``q <= min_ratio`` where it lies on the plane (the paper's source,
  :class:`~heatpf_jax.sources.pixels.PixelSource`: a ball on the ground, or a blob too small or too soft to tell);
* moves every pixel of a blob with ``q > min_ratio`` (a ball in the air, or above the horizon) to the ground
  point under the ball: the point at optical depth ``f R / rho`` along the ray through the blob's centroid,
  dropped to the ground, ``(x, y)``. The filter keeps tracking the ground point under the ball, as its
  estimate must; a flying ball's ground point moves on a straight line at the flight's horizontal speed.

The apparent size comes from the blob's activation mass: for a blob ``h(u) = p exp(-|u - c|^2 / 2 s^2)`` the
activation summed over the pixels at or above the threshold ``t`` is ``M = 2 pi s^2 (p - t)``, whatever the
peak ``p``, so ``s = sqrt(M / (2 pi (p - t)))`` and ``rho = s / blob_scale``, with ``blob_scale`` the
detector's blob std per apparent radius (0.6 for :func:`heatpf_jax.sim.render.blob`). ``M``, the centroid and
the peak come from an adaptive mean shift over summed-area tables
(:func:`~heatpf_jax.sources.image_centroids.summed_areas`): each above-threshold pixel's window starts as large as a
ground ball's blob at that pixel and grows with the blob's size estimate (``reach`` stds), up to
``max_half_px`` pixels.

The size is only as good as what is known of the detector's blob. ``blob_scale`` is a property of the detector (its
blob's softness, size, saturation and blur), so by default it is learned from the heat maps themselves
(:mod:`heatpf_jax.sources.blob_scale`): the filter carries the last ``calibration_frames`` frames' blob-size ratios
(``FilterState.source``) and takes the ground balls' own centre, the mode of their ratios
(:func:`~heatpf_jax.sources.blob_scale.ground_centre`), since a ball on the ground shows the detector's blob and a ball
in the air only ever a larger one; ``blob_scale`` is then only the prior before the first blob, and the recent frames'
median the reference until eight frames are in. The median lies above the mode by a share of the flights' sizes: on
the development replays with heights kept up to 2.6 % (0.6 % on average over the pieces; 0 on the flat ones), and
far more at the start of a run in a long flight, where most recent frames are in the air. A detector or camera whose
ground balls' sizes scatter widely (the world family's, :mod:`heatpf_jax.sim.family`: blob stds of 0.3-1.2 apparent
radii, saturated and occluded blobs, false blobs twice the ball's size, a calibration error of 1-3 degrees that makes
distant balls look too large for their projection) has no size that tells a flying ball from a ground one: a blob
counts as flying only when its ratio also lies ``calibration_sigmas`` robust stds of the ground balls' ratios
(:func:`~heatpf_jax.sources.blob_scale.ground_spread`) above their mode, and while the stds exceed
``calibration_max_spread``, or while the learned scale lies outside ``[min_blob_scale, max_blob_scale]`` (what the
frames show is speckle, clutter or large false blobs, not the ball), no blob is placed by its size: every pixel is
measured where it projects, as the paper's source does.
``LoftedSource(calibration_frames=0)`` keeps ``blob_scale`` fixed.

A sphere's blob is round, so a blob that its mass reads as flying is sized by its minor std,
``s / sqrt(e)`` with ``e`` its elongation (:func:`blob_elongation`, the square root of its second moments' eigenvalue
ratio): two ground blobs side by side that the window took as one (a ball beside a penalty mark, 0.45 m behind it
along the ray), or a blob blurred by motion, are stretched along one axis and keep a ground ball's minor std. And a
ball does not hover (:mod:`heatpf_jax.sources.hover`): a blob read as flying at the place, moved with the robot,
where one was read so 0.25-1 s before lies on the ground (a thing larger than the ball) and is measured where it
projects.

Below the hard test the size still says something: a ball 0.05-0.1 m up (the bounces of a landing) has a blob 5-20 %
larger than a ground ball's there, within the ground balls' scatter, and its projection on the plane overshoots by that
share of its range (0.5 m at 3-4 m). With calibration (and ``launch_rate > 0``) the source carries the probability
that the ball is in the air (``LoftedState.flight``, a two-state chain: launched at ``launch_rate``, landing after
``flight_time`` on average) and moves a blob that is more likely in the air than not, under that prior, along its ray
to the posterior mean of its size ratio (:mod:`heatpf_jax.sources.air_prior`: ground balls' log sizes scatter as a
Student t of the learned robust spread, :func:`~heatpf_jax.sources.blob_scale.ground_spread`, balls in the air as an
exponential of mean ``air_scale``). A flight starts only where a frame shows it beyond the hard test (a ground ball's
blob that reads a little large, once or frame after frame by a bias of its own, starts none), so a ground ball far
from any flight is measured as before, and a ball landing is followed down. A small blob's size is uncertain by its
pixel grid, ``1 / (24 s^2)`` in log units beyond the ground balls' spread, in both tests; and a blob's peak is taken
between pixel centres (:func:`subpixel_peaks`), where the largest pixel of a blob of 1-1.5 px std lies 4-8 % below
it and the size would read 2-4 % too large, rising and falling as the ball crosses the pixel grid. Every function
here is pure and jittable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

from heatpf_jax.camera import ground_jacobian, project_pixel, project_points
from heatpf_jax.measurements import Measurements, downscale_heatmap
from heatpf_jax.params import Param, interval, positive, unit_interval
from heatpf_jax.pieces import StepInputs
from heatpf_jax.sources.air_prior import air_posterior, predict_flight
from heatpf_jax.sources.blob_scale import (
    BlobScaleState,
    blob_scale_estimate,
    blob_scale_spread,
    frame_log_ratio,
    ground_centre,
    ground_spread,
    init_blob_scale,
    update_blob_scale,
)
from heatpf_jax.sources.hover import (
    HoverState,
    age_hover,
    air_places,
    hovering,
    init_hover,
    place_points,
    remember_hover,
)
from heatpf_jax.sources.image_centroids import ball_radius_px, box_sums, summed_areas

__all__ = [
    "BlobSizes",
    "LoftedParams",
    "LoftedSource",
    "LoftedState",
    "air_points",
    "blob_elongation",
    "blob_sizes",
    "bright_pixels",
    "subpixel_peaks",
]

_MIN_SPREAD = 0.02  # the smallest log-size spread of ground balls the posterior placement assumes
_CORE = 0.3  # subpixel_peaks refines a pixel whose neighbours are at least this share of it
_MIN_STD_PX = 0.7  # a blob is never thinner than this (pixel quantisation)
PEAK_RADIUS_PX = 3  # a blob's peak is the largest activation this close to its centroid


class LoftedParams(NamedTuple):
    """Numbers of :class:`LoftedSource`.

    Attributes:
        threshold: minimum heat-map activation of a measured pixel (III-A).
        max_distance: measurements farther from the robot (horizontal) are dropped, metres.
        blob_scale: the detector's blob std per apparent ball radius (0.6 for the simulator's Gaussian blob).
        min_ratio: a blob whose apparent radius exceeds a ground ball's at its ray's ground point by more than
            this factor is a ball in the air (``inf``: never; the source is then the paper's). 1.25 (a ball about
            0.1 m up at 3 m): chosen among 1.15, 1.25 and 1.5 by the worst case over development replays (16
            SkillCorner pieces of 10-30 s, seeds 1000-1015, static and walking robot, heights kept and flat);
            the simulator's ground balls give ratios 0.95-1.13 (5-95 %).
        max_ratio: a blob larger than this factor times a ground ball there (or above the horizon, where the
            factor is infinite) is refused: its pixels give no measurement. ``inf`` places every ball in the air
            by its size; ``max_ratio = min_ratio`` refuses every blob it would place (refusing to follow the
            inconsistent projection, for a detector whose blob size is not known).
        reach: the mean-shift window's half-size in blob stds.
        max_half_px: the largest window half-size, pixels.
        calibration_quantile: with ``LoftedSource.calibration_frames > 0``, the quantile of the recent frames'
            blob-size ratios taken as the detector's ``blob_scale`` (:mod:`heatpf_jax.sources.blob_scale`; 0.5:
            their median) until eight frames are stored, and for the mean-shift windows' first size; from the eighth
            frame on, the ground balls' mode (:func:`~heatpf_jax.sources.blob_scale.ground_centre`) is the
            reference of both size tests. ``blob_scale`` is only the prior before the first blob.
        calibration_sigmas: with calibration, a blob is in the air only if its ratio also lies this many robust
            stds of the ground balls' ratios (:func:`~heatpf_jax.sources.blob_scale.ground_spread`; before it has
            its frames, :func:`~heatpf_jax.sources.blob_scale.blob_scale_spread`) above their mode: a
            detector or camera whose ground balls' sizes scatter widely (soft, saturated or occluded blobs, a
            calibration error that grows with range) has no size that tells a flying ball.
        calibration_max_spread: with calibration, while the ground balls' robust std of ``log`` ratios (as for
            ``calibration_sigmas``) exceeds this, no blob is placed by its size (the size would place it to worse
            than about this share of its range): every pixel is measured where it projects, as the paper's source does.
        min_blob_scale: with calibration, a learned ``blob_scale`` below this is no detector's ball blob (the
            frames' ratios are those of speckle or clutter, which outnumber a distant ball's pixels): no blob is then
            placed by its size. 0.25: a blob std of a quarter of the ball's radius.
        max_blob_scale: the same above this (large false blobs outnumber the ball's). 2: a blob std of two radii.
        hover_px: with ``LoftedSource.hover_frames > 0``, a blob read as flying whose centroid lies within this many
            pixels of where a blob read as flying was seen ``hover_min_age`` to ``hover_max_age`` seconds ago (moved
            with the robot) has hovered: it lies on the ground, and is measured where it projects
            (:mod:`heatpf_jax.sources.hover`).
        hover_min_age: seconds; a ball in flight has crossed more than ``hover_px`` in this time.
        hover_max_age: seconds; places older than this are forgotten.
        launch_rate: with calibration, how often a ball on the ground is launched into the air, per second
            (:func:`~heatpf_jax.sources.air_prior.predict_flight`); 0 turns the flight state and the posterior
            placement off (a blob is then in the air only beyond the hard test, as before). 0.01: chosen among 0.005,
            0.01, 0.02 and 0.05 by the worst case over the development replays (16 pieces, static and walking robot,
            heights kept and flat) and the world family's development seeds 100-102.
        flight_time: with calibration, a flight's mean duration, seconds (bounces included).
        air_scale: the mean log size ratio ``log q`` of a ball in the air (the prior's exponential scale,
            :mod:`heatpf_jax.sources.air_prior`); 0.1 among 0.05, 0.1 and 0.2 on the development replays.
        false_alarm: the share of ground balls' blobs that the hard test (``min_ratio``, ``calibration_sigmas``)
            reads as flying: one such frame makes a flight that likely, and a few in a row certain.
    """

    threshold: float = 0.3
    max_distance: float = 12.0
    blob_scale: float = 0.6
    min_ratio: float = 1.25
    max_ratio: float = float("inf")
    reach: float = 3.0
    max_half_px: float = 24.0
    calibration_quantile: float = 0.5
    calibration_sigmas: float = 3.0
    calibration_max_spread: float = 0.3
    min_blob_scale: float = 0.25
    max_blob_scale: float = 2.0
    hover_px: float = 3.0
    hover_min_age: float = 0.25
    hover_max_age: float = 1.0
    launch_rate: float = 0.01
    flight_time: float = 1.5
    air_scale: float = 0.1
    false_alarm: float = 0.02


class LoftedState(NamedTuple):
    """What :class:`LoftedSource` carries from frame to frame (``FilterState.source``).

    Attributes:
        scale: the recent frames' blob-size ratios (:class:`~heatpf_jax.sources.blob_scale.BlobScaleState`),
            ``()`` without calibration.
        hover: the recent places of blobs read as flying (:class:`~heatpf_jax.sources.hover.HoverState`), ``()``
            without the test.
    """

    scale: BlobScaleState | tuple = ()
    hover: HoverState | tuple = ()
    flight: Float[Array, ""] | tuple = ()


class BlobSizes(NamedTuple):
    """Each start pixel's blob, as the adaptive mean shift found it.

    Attributes:
        uv: ``[M, 2]`` (column, row) of the blob's activation centroid.
        std_px: ``[M]`` the blob's std, pixels (``sqrt(M / (2 pi (p - t)))``).
        peak: ``[M]`` the largest activation within ``PEAK_RADIUS_PX`` pixels of the centroid.
        ground_radius_px: ``[M]`` a ground ball's radius at the centroid, pixels (0 above the horizon).
    """

    uv: Float[Array, "m 2"]
    std_px: Float[Array, " m"]
    peak: Float[Array, " m"]
    ground_radius_px: Float[Array, " m"]


def _box_max(x: Float[Array, "h w"], radius: int) -> Float[Array, "h w"]:
    """The largest value within ``radius`` pixels (a square, clipped at the border) of every pixel.

    The same numbers as a ``(2 r + 1)``-square ``lax.reduce_window`` max with ``"SAME"`` padding, as a row pass and a
    column pass of shifted maxima, which XLA:CPU fuses into two loops (its square ``reduce_window`` costs about
    twenty times more on a 200 x 150 map).
    """
    h, w = x.shape
    r = int(radius)
    padded = jnp.pad(x, ((0, 0), (r, r)), constant_values=-jnp.inf)
    rows = padded[:, :w]
    for k in range(1, 2 * r + 1):
        rows = jnp.maximum(rows, padded[:, k:k + w])
    padded = jnp.pad(rows, ((r, r), (0, 0)), constant_values=-jnp.inf)
    out = padded[:h]
    for k in range(1, 2 * r + 1):
        out = jnp.maximum(out, padded[k:k + h])
    return out


def subpixel_peaks(heatmap: Float[ArrayLike, "h w"]) -> Float[Array, "h w"]:
    """Each local maximum's activation refined to the height of the blob's true peak between pixel centres.

    A blob ``p exp(-|u - c|^2 / 2 s^2)`` whose centre ``c`` falls between pixels has its largest pixel below ``p``
    (by ``exp(-1 / 12 s^2)`` on average, 8 % for a distant ball's blob of 1 px std, up to ``exp(-1 / 4 s^2)``): its
    size ``sqrt(M / 2 pi (p - t))`` reads too large, by more the smaller and the farther off-centre it is (a ball
    rolling slowly across the pixel grid reads as rising and falling). The logarithm of a Gaussian is a parabola:
    through a pixel and its two neighbours along each axis it has its vertex at ``log p`` exactly,
    ``log h_0 + (a - c)^2 / (8 (2 b - a - c))`` per axis (``a, b, c`` the logarithms of the three activations).
    Only a pixel larger than its row and column neighbours (the vertex within half a pixel), each of them at least
    ``_CORE`` (0.3) of it, is refined: a flat (saturated) top or its rim, a speck, or any other pixel keeps its
    activation.

    Args:
        heatmap: ``[H, W]`` activations.

    Returns:
        ``[H, W]`` activations, the local maxima refined (never lowered).
    """
    heat = jnp.asarray(heatmap, jnp.float32)
    log_h = jnp.log(jnp.maximum(heat, 1e-6))
    padded = jnp.pad(log_h, 1, mode="edge")
    centre = padded[1:-1, 1:-1]

    def lift(before, after):
        curvature = 2.0 * centre - before - after
        # A Gaussian core: both neighbours within a factor _CORE of the pixel (a speck, a saturated plateau's edge
        # or a blob's rim is no parabola's vertex).
        ok = (curvature > 1e-6) & (centre > before) & (centre > after) & (jnp.minimum(before, after) >= centre
                                                                          + math.log(_CORE))
        return jnp.where(ok, jnp.square(before - after) / (8.0 * jnp.where(ok, curvature, 1.0)), 0.0), ok

    lift_u, ok_u = lift(padded[1:-1, :-2], padded[1:-1, 2:])
    lift_v, ok_v = lift(padded[:-2, 1:-1], padded[2:, 1:-1])
    ok = ok_u & ok_v & (heat > 0.0)
    return jnp.where(ok, heat * jnp.exp(lift_u + lift_v), heat)


def blob_sizes(
    heatmap: Float[ArrayLike, "h w"],
    start: Float[ArrayLike, "m 2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    threshold: Float[ArrayLike, ""],
    plane_height: Float[ArrayLike, ""],
    blob_scale: Float[ArrayLike, ""] = 0.6,
    reach: Float[ArrayLike, ""] = 3.0,
    max_half_px: Float[ArrayLike, ""] = 24.0,
    iterations: int = 4,
) -> BlobSizes:
    """Centroid and std of each start pixel's blob: a mean shift whose window grows with the blob.

    The window's half-size is ``reach`` times the larger of the blob std a ground ball would have at the window's
    centre (``blob_scale`` times its radius in pixels) and the std measured in the previous window, clipped to
    ``[1, max_half_px]``. In each window the centroid and the std ``sqrt(M / (2 pi (p - t)))`` are taken over the
    activations at or above ``threshold`` (``M`` their sum, ``p`` the largest activation within ``PEAK_RADIUS_PX``
    pixels of the centroid).

    Args:
        heatmap: ``[H, W]`` activations.
        start: ``[M, 2]`` start pixels (column, row).
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        threshold: activations below it are not part of a blob.
        plane_height: the ball radius, metres.
        blob_scale: the detector's blob std per apparent ball radius.
        reach: the window's half-size in blob stds.
        max_half_px: the largest window half-size, pixels.
        iterations: static number of mean-shift steps.

    Returns:
        :class:`BlobSizes`.
    """
    heat = jnp.asarray(heatmap, jnp.float32)
    h, w = heat.shape
    above = heat >= threshold
    mass_map = jnp.where(above, heat, 0.0)
    cols = jnp.arange(w, dtype=jnp.float32)[None, :]
    rows = jnp.arange(h, dtype=jnp.float32)[:, None]
    s_mass, s_u, s_v = summed_areas(jnp.stack([mass_map, mass_map * cols, mass_map * rows]))
    margin = jnp.maximum(jnp.max(heat) - threshold, 1e-3)
    # The blob's peak: the largest activation within PEAK_RADIUS_PX of its centroid (the centroid of a blob split by
    # an occluder lies in the gap; that of a small blob between pixel centres).
    local_peak = _box_max(subpixel_peaks(heat), PEAK_RADIUS_PX)

    def measure(uv, std):
        ground = blob_scale * ball_radius_px(uv, intrinsics, cam_to_base, plane_height)
        half = jnp.clip(jnp.round(reach * jnp.maximum(jnp.maximum(ground, std), _MIN_STD_PX)), 1.0, max_half_px)
        u0 = jnp.clip(jnp.round(uv[:, 0] - half), 0, w - 1).astype(jnp.int32)
        u1 = jnp.clip(jnp.round(uv[:, 0] + half), 0, w - 1).astype(jnp.int32)
        v0 = jnp.clip(jnp.round(uv[:, 1] - half), 0, h - 1).astype(jnp.int32)
        v1 = jnp.clip(jnp.round(uv[:, 1] + half), 0, h - 1).astype(jnp.int32)
        m = box_sums(s_mass, u0, u1, v0, v1)
        has = m > 0.0
        safe = jnp.where(has, m, 1.0)
        centre = jnp.where(has[:, None], jnp.stack([box_sums(s_u, u0, u1, v0, v1) / safe,
                                                   box_sums(s_v, u0, u1, v0, v1) / safe], axis=-1), uv)
        iu = jnp.clip(jnp.round(centre[:, 0]), 0, w - 1).astype(jnp.int32)
        iv = jnp.clip(jnp.round(centre[:, 1]), 0, h - 1).astype(jnp.int32)
        peak = local_peak[iv, iu]
        denom = jnp.clip(peak - threshold, 0.05 * margin, None)
        std = jnp.sqrt(m / (2.0 * math.pi * denom))
        return centre, jnp.where(has, std, 0.0), peak

    uv = jnp.asarray(start, jnp.float32)
    std = jnp.zeros(uv.shape[0], jnp.float32)
    peak = jnp.zeros(uv.shape[0], jnp.float32)
    # One loop body, not ``iterations`` copies of it: the same numbers, a smaller program to compile.
    uv, std, peak = lax.fori_loop(0, int(iterations), lambda _, carry: measure(carry[0], carry[1]), (uv, std, peak))
    ground = ball_radius_px(uv, intrinsics, cam_to_base, plane_height)
    return BlobSizes(uv=uv, std_px=std, peak=peak, ground_radius_px=ground)


def blob_elongation(
    heatmap: Float[ArrayLike, "h w"],
    uv: Float[ArrayLike, "m 2"],
    half: Float[ArrayLike, " m"],
    *,
    threshold: Float[ArrayLike, ""],
    samples: int = 7,
) -> Float[Array, " m"]:
    """The ratio of each blob's major to its minor std, from its second moments above the threshold.

    The heat map is sampled (bilinearly) on a ``samples x samples`` grid spanning ``half`` pixels each side of
    ``uv`` (2.5 mass-based stds in :class:`LoftedSource`); each sample weighs ``max(h - threshold, 0)``, which
    falls to zero at the blob's edge, so that a coarse grid still measures it. The weighted covariance of the
    samples' offsets has eigenvalues ``l1 >= l2``, and the elongation is ``sqrt(l1 / l2)``. For a Gaussian blob of
    stds ``a >= b`` the weight is a function of the blob's quadratic form alone, so the ratio is ``a / b`` whatever the
    threshold or the peak, and ``std_px / sqrt(elongation)``, with ``std_px`` the mass-based ``sqrt(a b)``, is its
    minor std.

    Args:
        heatmap: ``[H, W]`` activations.
        uv: ``[M, 2]`` blob centroids (column, row).
        half: ``[M]`` the grid's half-spans, pixels.
        threshold: activations below it are not part of a blob.
        samples: static grid points per axis.

    Returns:
        ``[M]`` elongations; 1 for a window with no activation above the threshold, or one that the image's border
        cuts.
    """
    heat = jnp.asarray(heatmap, jnp.float32)
    h, w = heat.shape
    uv = jnp.asarray(uv, jnp.float32)
    half = jnp.asarray(half, jnp.float32)
    n = int(samples)
    grid = jnp.linspace(-1.0, 1.0, n, dtype=jnp.float32)
    x = jnp.broadcast_to(grid[None, None, :] * half[:, None, None], (uv.shape[0], n, n))  # [M, S, S] column offsets
    y = jnp.broadcast_to(grid[None, :, None] * half[:, None, None], (uv.shape[0], n, n))
    fu = uv[:, 0, None, None] + x
    fv = uv[:, 1, None, None] + y
    # A blob that the image's border cuts is stretched along the border: its second moments say nothing of its shape.
    whole = jnp.all((fu >= 0.0) & (fu <= w - 1.0) & (fv >= 0.0) & (fv <= h - 1.0), axis=(1, 2))
    fu, fv = jnp.clip(fu, 0.0, w - 1.0), jnp.clip(fv, 0.0, h - 1.0)
    u0 = jnp.clip(jnp.floor(fu), 0, w - 2).astype(jnp.int32)
    v0 = jnp.clip(jnp.floor(fv), 0, h - 2).astype(jnp.int32)
    a, b = fu - u0.astype(jnp.float32), fv - v0.astype(jnp.float32)
    act = ((1.0 - a) * (1.0 - b) * heat[v0, u0] + a * (1.0 - b) * heat[v0, u0 + 1]
           + (1.0 - a) * b * heat[v0 + 1, u0] + a * b * heat[v0 + 1, u0 + 1])
    m = jnp.maximum(act - threshold, 0.0).reshape(uv.shape[0], -1)
    x = (fu - uv[:, 0, None, None]).reshape(uv.shape[0], -1)
    y = (fv - uv[:, 1, None, None]).reshape(uv.shape[0], -1)
    total = jnp.sum(m, axis=-1)
    safe = jnp.where(total > 0.0, total, 1.0)
    mx, my = jnp.sum(m * x, -1) / safe, jnp.sum(m * y, -1) / safe
    sxx = jnp.sum(m * x * x, -1) / safe - mx * mx
    syy = jnp.sum(m * y * y, -1) / safe - my * my
    sxy = jnp.sum(m * x * y, -1) / safe - mx * my
    mean = 0.5 * (sxx + syy)
    root = jnp.sqrt(jnp.square(0.5 * (sxx - syy)) + jnp.square(sxy))
    major, minor = mean + root, jnp.maximum(mean - root, 1e-6)
    return jnp.where(whole & (total > 0.0), jnp.sqrt(jnp.maximum(major / minor, 1.0)), 1.0)


def air_points(
    uv: Float[ArrayLike, "m 2"],
    radius_px: Float[ArrayLike, " m"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    ball_radius: Float[ArrayLike, ""],
) -> tuple[Float[Array, "m 3"], Bool[Array, " m"]]:
    """The centre of a ball of radius ``ball_radius`` seen at pixel ``uv`` with an apparent radius ``radius_px``.

    The centre lies along the pixel's ray at the optical depth ``fx R / rho``.

    Args:
        uv: ``[M, 2]`` blob centres (column, row).
        radius_px: ``[M]`` apparent radii, pixels.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` camera pose in the base frame.
        ball_radius: metres.

    Returns:
        ``(points [M, 3], ok [M])``: base-frame centres, and whether the radius is positive and finite.
    """
    uv = jnp.asarray(uv, jnp.float32)
    intrinsics = jnp.asarray(intrinsics, jnp.float32)
    pose = jnp.asarray(cam_to_base, jnp.float32)
    radius_px = jnp.asarray(radius_px, jnp.float32)
    ok = (radius_px > 0.0) & jnp.isfinite(radius_px)
    depth = intrinsics[0] * ball_radius / jnp.where(ok, radius_px, 1.0)
    ray = jnp.stack([(uv[:, 0] - intrinsics[2]) / intrinsics[0], (uv[:, 1] - intrinsics[3]) / intrinsics[1],
                     jnp.ones_like(uv[:, 0])], axis=-1)
    points = pose[:3, 3][None, :] + (depth[:, None] * ray) @ pose[:3, :3].T
    return jnp.where(ok[:, None], points, 0.0), ok


def bright_pixels(
    heatmap: Float[ArrayLike, "h w"], *, threshold: Float[ArrayLike, ""], max_measurements: int
) -> tuple[Float[Array, "k 2"], Bool[Array, " k"], Float[Array, " k"]]:
    """The strongest pixels at or above ``threshold``, wherever their rays go (above the horizon too).

    Returns:
        ``(uv, passes, activation)`` each of ``k = min(max_measurements, H W)`` entries, in raster order, passing
        ones first (as :func:`~heatpf_jax.measurements.strongest_pixels`, without its test of the ray).
    """
    heat = jnp.asarray(heatmap, jnp.float32)
    h, w = heat.shape
    n_pix = h * w
    act = heat.ravel()
    passes = act >= threshold
    k = min(int(max_measurements), n_pix)
    _, idx = lax.top_k(jnp.where(passes, act, -1.0), k)
    idx = jnp.sort(jnp.where(passes[idx], idx, idx + n_pix)) % n_pix
    uv = jnp.stack([(idx % w).astype(jnp.float32), (idx // w).astype(jnp.float32)], axis=-1)
    return uv, passes[idx], act[idx]


@dataclass(frozen=True)
class LoftedSource:
    """Every pixel at or above ``threshold``: on the ground plane, or under its ball when its blob is a ball in the air.

    See the module docstring. A blob no larger than ``min_ratio`` times a ground ball there gives exactly the
    paper's measurements (:class:`~heatpf_jax.sources.pixels.PixelSource`); a larger blob, or one above the horizon,
    gives the ground point under the ball its size places along the ray through its centroid, for each of its
    pixels, with the pixel's own activation as its weight and the footprint of a ground ball's pixel there.

    The detector's blob size is learned from the heat maps (:mod:`heatpf_jax.sources.blob_scale`): the filter
    carries the last ``calibration_frames`` frames' blob-size ratios (:meth:`init_state`, :meth:`measure_state`)
    and ``LoftedParams.blob_scale`` is only the prior before the first blob; ``calibration_frames=0`` keeps
    ``blob_scale`` fixed (the detector's size known).

    Attributes:
        max_measurements: slots; the strongest pixels are kept (IV-E).
        downscale: integer block-averaging of the heat map first (III-A).
        iterations: mean-shift steps of :func:`blob_sizes`.
        calibration_frames: frames whose blob-size ratios give the detector's blob scale (0: none, the
            fixed ``blob_scale``).
        hover_frames: frames whose blobs read as flying are remembered, to tell a ball in flight from a thing on the
            ground that looks larger than the ball (:mod:`heatpf_jax.sources.hover`; 0, the default: no such test).
            Off by default: on the replays of real tracks, scaled to a KidSize field, a low ball (0.1-0.2 m up)
            drifts slowly enough to read as hovering, and among the family's large false blobs it made no
            difference beyond the seeds' spread (docs/results.md); 16 with ``hover_blobs=4`` for a field with
            static clutter larger than the ball.
        hover_blobs: places remembered per frame.
    """

    max_measurements: int = 1024
    downscale: int = 1
    iterations: int = 4
    calibration_frames: int = 256
    hover_frames: int = 0
    hover_blobs: int = 4

    @property
    def size(self) -> int:
        return self.max_measurements

    def default_params(self) -> LoftedParams:
        return LoftedParams()

    def properties(self) -> LoftedParams:
        # Each acts through which pixels count or where a window ends: frozen, swept rather than tuned.
        return LoftedParams(
            threshold=unit_interval(trainable=False),
            max_distance=positive(trainable=False, allow_inf=True),
            blob_scale=positive(trainable=False),
            min_ratio=Param(low=1.0, trainable=False, allow_inf=True),
            max_ratio=Param(low=1.0, trainable=False, allow_inf=True),
            reach=positive(trainable=False),
            max_half_px=interval(1.0, math.inf, trainable=False),
            calibration_quantile=unit_interval(trainable=False),
            calibration_sigmas=Param(low=0.0, trainable=False, allow_inf=True),
            calibration_max_spread=Param(low=0.0, trainable=False, allow_inf=True),
            min_blob_scale=positive(trainable=False),
            max_blob_scale=positive(trainable=False, allow_inf=True),
            hover_px=Param(low=0.0, trainable=False),
            hover_min_age=Param(low=0.0, trainable=False, allow_inf=True),
            hover_max_age=Param(low=0.0, trainable=False, allow_inf=True),
            launch_rate=Param(low=0.0, trainable=False),
            flight_time=positive(trainable=False),
            air_scale=positive(trainable=False),
            false_alarm=interval(0.0, 1.0, trainable=False),
        )

    def validate(self) -> None:
        for name in ("max_measurements", "downscale", "iterations"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer, got {value!r}")
        for name in ("calibration_frames", "hover_frames"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 0:
                raise ValueError(f"{name}: must be a non-negative integer, got {value!r}")
        blobs = self.hover_blobs
        if not isinstance(blobs, int) or isinstance(blobs, bool) or blobs < 1:
            raise ValueError(f"hover_blobs: must be a positive integer, got {blobs!r}")

    def init_state(self) -> LoftedState | tuple:
        """The filter's carried state of this source (:class:`LoftedState`; ``()`` with neither calibration nor
        the hover test)."""
        if self.calibration_frames == 0 and self.hover_frames == 0:
            return ()
        return LoftedState(
            scale=init_blob_scale(self.calibration_frames) if self.calibration_frames > 0 else (),
            hover=init_hover(self.hover_frames, self.hover_blobs) if self.hover_frames > 0 else (),
            flight=jnp.zeros((), jnp.float32) if self.calibration_frames > 0 else (),
        )

    def measure(self, inputs: StepInputs, params: LoftedParams) -> Measurements:
        """The measurements with the fixed ``params.blob_scale`` and no memory of earlier frames."""
        return self._measure(inputs, params, LoftedState())[0]

    def measure_state(
        self, inputs: StepInputs, params: LoftedParams, state: LoftedState | tuple
    ) -> tuple[Measurements, LoftedState | tuple]:
        """The measurements with the blob scale learned so far (this frame included) and the places of recent
        flying blobs, and the updated state."""
        if not isinstance(state, LoftedState):  # neither calibration nor hover test: ()
            return self.measure(inputs, params), state
        return self._measure(inputs, params, state)

    def carry_state(
        self, inputs: StepInputs, params: LoftedParams, state: LoftedState | tuple
    ) -> LoftedState | tuple:
        """The state through a step without a heat map: the remembered places move with the robot and age."""
        if not isinstance(state, LoftedState):
            return state
        if isinstance(state.hover, HoverState):
            state = state._replace(hover=age_hover(state.hover, inputs.odometry, inputs.dt))
        if not isinstance(state.flight, tuple):
            state = state._replace(flight=predict_flight(state.flight, inputs.dt, params.launch_rate,
                                                         params.flight_time))
        return state

    def _measure(self, inputs: StepInputs, params: LoftedParams, state: LoftedState):
        heatmap, intrinsics = downscale_heatmap(inputs.heatmap, inputs.intrinsics, self.downscale)
        pose, radius = inputs.cam_to_base, inputs.plane_height
        uv, passes, weight = bright_pixels(heatmap, threshold=params.threshold, max_measurements=self.max_measurements)
        calib = state.scale if isinstance(state.scale, BlobScaleState) else None
        hover = state.hover if isinstance(state.hover, HoverState) else None
        scale = params.blob_scale
        if calib is not None:
            scale = blob_scale_estimate(calib, params.blob_scale, params.calibration_quantile)
        blobs = blob_sizes(heatmap, uv, intrinsics, pose, threshold=params.threshold, plane_height=radius,
                           blob_scale=scale, reach=params.reach, max_half_px=params.max_half_px,
                           iterations=self.iterations)
        # A blob's size is read against a ground ball's: ``scale`` becomes the detector's blob scale that a ball on
        # the ground shows, the ground balls' own centre (blob_scale.ground_centre, the mode of the recent frames'
        # ratios) once enough frames are in. A quantile of all recent frames lies above it by a share of the flights'
        # sizes, by far more where most recent frames are in flight (a run that starts in a long flight): it is only
        # the reference before the mode has its frames (and the mean-shift windows' first size above).
        if calib is not None:  # this frame's ratio joins the estimate before its blobs are judged
            calib = update_blob_scale(calib, *frame_log_ratio(blobs.std_px, blobs.ground_radius_px, weight, passes))
            centre, has_centre = ground_centre(calib)
            scale = jnp.where(has_centre, jnp.exp(centre),
                              blob_scale_estimate(calib, params.blob_scale, params.calibration_quantile))
        # A small blob's std is measured on a grid of unit pixels, whose variance (1/12 px^2) is of the order of its
        # own: its variance ``s^2`` is uncertain by about 1/12 px^2, its log size ``log s`` by ``1 / (24 s^2)`` beyond
        # the ground balls' spread (0.04 for a distant ball's blob of 1 px std, 0.01 at 2 px), and its size tells a
        # flight only beyond that.
        grid = 1.0 / (24.0 * jnp.square(jnp.maximum(blobs.std_px, _MIN_STD_PX)))
        min_ratio = jnp.broadcast_to(jnp.asarray(params.min_ratio, jnp.float32), grid.shape)
        soft = jnp.asarray(False)
        sigma = grid
        if calib is not None:
            # The ground balls' own spread about their mode (blob_scale.ground_spread; the robust spread of all
            # recent frames until it has its frames): flights only ever make a blob larger, and with their sizes in
            # it a run's first seconds in a flight read as a detector too erratic for any size to tell.
            ground = ground_spread(calib)  # 0 until enough frames are stored: no posterior placement before
            spread = jnp.where(ground > 0.0, ground, blob_scale_spread(calib))
            min_ratio = jnp.maximum(min_ratio, jnp.exp(params.calibration_sigmas * jnp.hypot(spread, grid)))
            # What the frames show is no detector's ball (speckle, clutter or large false blobs outnumber it), or its
            # sizes scatter too widely: no blob is placed by its size, every pixel is measured as the paper's.
            credible = (spread <= params.calibration_max_spread) & (scale >= params.min_blob_scale) & (
                scale <= params.max_blob_scale)
            min_ratio = jnp.where(credible, min_ratio, jnp.inf)
            sigma = jnp.hypot(jnp.maximum(ground, _MIN_SPREAD), grid)
            soft = credible & (params.launch_rate > 0.0) & (ground > 0.0)
        ground_px = blobs.ground_radius_px
        below = ground_px > 0.0
        # A sphere's blob is round: its size is its minor std. Two blobs side by side that the window took as one (a
        # ball beside a penalty mark), or a blurred blob, are stretched along one axis: by their mass they read as a
        # ball too large for the ground, by their minor std as what they are. The std by mass is at least the minor
        # one, so only a blob that its mass reads as flying needs the second moments (a frame without one skips them).
        flying = passes & (blobs.std_px / scale > min_ratio * ground_px)
        flying = flying | (soft & passes & below & (blobs.std_px / scale > jnp.exp(sigma) * ground_px))
        span = jnp.clip(2.5 * jnp.maximum(blobs.std_px, _MIN_STD_PX), 1.0, params.max_half_px)
        elongation = lax.cond(
            jnp.any(flying),
            lambda: jnp.where(flying, blob_elongation(heatmap, blobs.uv, span, threshold=params.threshold), 1.0),
            lambda: jnp.ones_like(blobs.std_px),
        )
        apparent = blobs.std_px / jnp.sqrt(elongation) / scale
        sized_up = flying & (apparent > min_ratio * ground_px)  # above the horizon: ground radius 0
        # Below the hard threshold, the posterior mean of the ball's size ratio (sources.air_prior): a low ball is not
        # left on the plane, a ground ball's size noise moves it little. How likely the ball flies now is carried from
        # frame to frame (LoftedState.flight).
        measured = jnp.log(jnp.maximum(apparent, 1e-6)) - jnp.log(jnp.where(below, ground_px, 1.0))
        flight = state.flight
        share = jnp.asarray(0.5, jnp.float32)
        if not isinstance(flight, tuple):
            flight = predict_flight(flight, inputs.dt, params.launch_rate, params.flight_time)
            share = jnp.clip(flight, 1e-6, 1.0 - 1e-6)
        p_air, posterior = air_posterior(jnp.where(below, measured, 0.0), sigma, share, params.air_scale)
        if not isinstance(flight, tuple):
            # The ball is the frame's strongest pixel's blob. A flight starts where a frame shows it clearly: the
            # ball's blob beyond the hard threshold (where the ground noise's polynomial tail outgrows the prior's
            # exponential one) or above the horizon. A blob within the size test's reach keeps a flight going or ends
            # it, but starts none: a ground ball whose blob reads a little large frame after frame (split by an
            # occluder, or distant, a few pixels wide) does not add up to a flight.
            ball = jnp.argmax(jnp.where(passes, weight, -1.0))
            # A blob beyond the test is a ball in the air, or a ground ball's blob that reads too large (a share
            # ``false_alarm`` of them): one such frame makes a flight likely, a few in a row certain.
            odds = share / (1.0 - share) / jnp.maximum(params.false_alarm, 1e-6)
            p_ball = jnp.where(below[ball] & ~sized_up[ball], jnp.minimum(p_air[ball], share), odds / (1.0 + odds))
            flight = jnp.where(jnp.any(passes) & soft, p_ball, flight)
        # Moved only where the ball is more likely in the air than not: near a flight (its landing and bounces), not a
        # ground ball whose blob reads large in a frame or, frame after frame, by a bias of its own.
        lifted = soft & passes & below & ~sized_up & (p_air > 0.5)
        apparent = jnp.where(lifted, ground_px * jnp.exp(posterior), apparent)
        in_air = sized_up | lifted
        if hover is not None:
            # A blob read as flying where one was read so a while ago (moved with the robot) hovers: it lies on the
            # ground. Its place is remembered all the same, so that a thing on the ground stays known as one.
            # Judged per place (the few distinct flying blobs), not per pixel: a pixel beyond the first places keeps
            # its reading.
            hover = age_hover(hover, inputs.odometry, inputs.dt)
            places, has, label = air_places(blobs.uv, weight, in_air, hover.valid.shape[1], params.hover_px)
            still = has & hovering(hover, places, intrinsics, pose, tolerance=params.hover_px,
                                   min_age=params.hover_min_age, max_age=params.hover_max_age)
            hover = remember_hover(hover, place_points(places, intrinsics, pose, radius), has)
            in_air = in_air & ~((label >= 0) & still[jnp.clip(label, 0, None)])
        state = LoftedState(scale=calib if calib is not None else state.scale,
                            hover=hover if hover is not None else state.hover, flight=flight)
        refused = apparent > params.max_ratio * blobs.ground_radius_px
        centres, sized = air_points(blobs.uv, apparent, intrinsics, pose, radius)
        air_xy = centres[:, :2]
        on_plane = jax.vmap(project_pixel, in_axes=(0, None, None, None, None))
        plane_xy, plane_ok = on_plane(uv, intrinsics, pose, radius, params.max_distance)
        air_dist = jnp.sqrt(jnp.sum(jnp.square(air_xy), axis=-1))
        air_ok = sized & (air_dist <= params.max_distance) & jnp.all(jnp.isfinite(air_xy), axis=-1)
        # The footprint of a ground ball's pixel under the ball (for range-aware observation models).
        ground_uv, depth = project_points(jnp.concatenate([air_xy, jnp.broadcast_to(radius, air_xy[:, :1].shape)],
                                                          axis=-1), intrinsics, pose)
        air_ok = air_ok & (depth > 0.0) & ~refused
        look_uv = jnp.where(in_air[:, None], ground_uv, uv)
        footprint = jax.vmap(ground_jacobian, in_axes=(0, None, None, None))(look_uv, intrinsics, pose, radius)
        # Each pixel of a flying ball's blob lies, about the point under the ball, where the same pixel of a ground
        # ball's blob there would put it: the blob is measured as that ground ball would be, not as one point that
        # all of its pixels (each a measurement) pile onto.
        shrink = ball_radius_px(ground_uv, intrinsics, pose, radius) / jnp.maximum(apparent, 1e-6)
        offset = (uv - blobs.uv) * shrink[:, None]
        air_xy = air_xy + jnp.einsum("mij,mj->mi", footprint, offset)
        xy = jnp.where(in_air[:, None], air_xy, plane_xy)
        valid = passes & jnp.where(in_air, air_ok, plane_ok)
        pad = int(self.max_measurements) - uv.shape[0]
        return Measurements(
            xy=jnp.pad(jnp.where(valid[:, None], xy, 0.0), ((0, pad), (0, 0))),
            weight=jnp.pad(jnp.where(valid, weight, 0.0), (0, pad)),
            valid=jnp.pad(valid, (0, pad)),
            footprint=jnp.pad(jnp.where(valid[:, None, None], footprint, 0.0), ((0, pad), (0, 0), (0, 0))),
        ), state
