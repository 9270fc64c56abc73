"""Image-space colour trackers: the contestants of Olufs et al.'s Table 1 (section 4).

Olufs et al. compare their tracker with "Mean Shift" [5], "Mean Shift + KL" (mean shift with a Kalman
filter) and the "MC Tracker", the colour-based particle filter [7, 13]; all track a colour histogram
(eq. 1, here the r'g'I bins of :mod:`heatpf_jax.colour_space`) with the Bhattacharyya coefficient
``rho[p, q] = sum_u sqrt(p_u q_u)`` (eq. 2) directly in the image, and none re-detects a lost object.

* :class:`MeanShiftTracker` (Comaniciu, Ramesh, Meer 2003, "Kernel-based object tracking"): each frame
  the elliptical window climbs ``rho`` from the previous centre. The candidate histogram ``p(y)`` is
  weighted by the Epanechnikov profile ``k(r^2) = 1 - r^2``; each pixel gets ``w_i = sqrt(q_u / p_u(y))``
  for its bin ``u``, and the new centre is their weighted mean over the window (the profile's
  derivative is constant, so the mean-shift kernel ``g`` is flat) until the shift is below ``eps`` or
  after ``max_iter`` iterations. Optionally Comaniciu's scale adaptation: search with ``h``, ``0.9 h``
  and ``1.1 h``, keep the best ``rho``, ``h <- gamma h_best + (1 - gamma) h``.
* :func:`mean_shift_backprojection`: OpenCV's ``cv2.meanShift`` on a back-projection (the window moves
  to the rounded centroid of the probability inside it), with OpenCV's clipping, rounding and stopping.
* :class:`KalmanMeanShiftTracker` ("Mean Shift + KL"): a constant-velocity Kalman filter in pixels
  (:func:`heatpf_jax.baselines.kalman_predict` / ``kalman_update`` with ``dt = 1`` frame) whose
  prediction seeds the mean-shift search and whose update takes the search's result.
* :class:`ColourParticleTracker` (Perez, Hue, Vermaak, Gangnet 2002; Nummiaro et al. 2003): particles
  ``(u, v, du, dv)`` with constant-velocity motion and Gaussian noise, likelihood
  ``exp(-lam d^2)`` with ``d^2 = 1 - rho``, systematic resampling every frame, the weighted mean as
  output. Window histograms come from summed-area tables over the reference's ``top_bins`` largest bins
  (exact when ``q`` has at most ``top_bins`` non-zero bins): 4 corner gathers per particle.

Every tracker is a frozen (hashable) dataclass of static choices with a params ``NamedTuple`` of numbers,
``init(key, first_window, params)`` and ``step(key, state, image, params) -> (state, info)``; :func:`run`
scans ``step`` over the frames (jitted with the tracker static) and :func:`track` returns its positions.
Positions are ``(u, v)`` = (column, row) in pixels, pixel centres at integers. Windows are clipped to
the image, centres kept inside it; a window without any of the reference's colours leaves the mean shift
where it is (and gives the Kalman filter no measurement), and an empty window has an all-zero histogram.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, UInt8

from heatpf_jax.baselines.kalman import KalmanState, kalman_predict, kalman_update
from heatpf_jax.colour_space import DEFAULT_BINS, MAX_BOX_HALF, bin_table, box_counts, num_bins, rgi_bins
from heatpf_jax.params import make_params, nonnegative, positive, unit_interval
from heatpf_jax.resampling import effective_sample_size, systematic

__all__ = [
    "ColourParticleInfo",
    "ColourParticleParams",
    "ColourParticleState",
    "ColourParticleTracker",
    "KalmanMeanShiftInfo",
    "KalmanMeanShiftParams",
    "KalmanMeanShiftState",
    "KalmanMeanShiftTracker",
    "MeanShiftInfo",
    "MeanShiftParams",
    "MeanShiftState",
    "MeanShiftTracker",
    "Window",
    "backprojection",
    "mean_shift_backprojection",
    "run",
    "track",
    "window_histograms",
]

_F32 = jnp.float32
_DBL_EPSILON = 2.220446049250313e-16


class Window(NamedTuple):
    """The object in the first frame: where, how large, and what colours.

    Attributes:
        centre: ``(u, v)`` in pixels, shape ``[2]``.
        half_size: half width and half height in pixels, shape ``[2]`` (the ellipse's semi-axes for mean
            shift, the rectangle's half sides for the particle filter).
        reference: the reference histogram ``q``, shape ``[m]``.
    """

    centre: Float[Array, "2"]
    half_size: Float[Array, "2"]
    reference: Float[Array, " m"]


def _window(start_uv: Float[ArrayLike, "2"], half_size: Float[ArrayLike, "*2"], q: Float[ArrayLike, " m"]) -> Window:
    half = jnp.broadcast_to(jnp.asarray(half_size, _F32), (2,))
    return Window(centre=jnp.asarray(start_uv, _F32), half_size=half, reference=jnp.asarray(q, _F32))


def _clip_to_image(uv: Float[Array, "*n 2"], shape: tuple[int, ...]) -> Float[Array, "*n 2"]:
    h, w = shape[0], shape[1]
    upper = jnp.array([w - 1, h - 1], _F32).reshape((1,) * (uv.ndim - 1) + (2,))
    return jnp.clip(uv, jnp.zeros_like(upper), upper)


def _safe_div(num: Array, den: Array) -> Array:
    """``num / den`` where ``den > 0``, else 0 (the double-where idiom: no NaN, no NaN gradient)."""
    ok = den > 0
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


# --- OpenCV's meanShift on a back-projection ---------------------------------------------------------------------


def backprojection(
    image: UInt8[ArrayLike, "h w 3"], q: Float[ArrayLike, " m"], bins: tuple[int, int, int] = DEFAULT_BINS
) -> UInt8[Array, "h w"]:
    """``q`` at every pixel's bin scaled to ``0..255``: ``cv2.calcBackProject`` of ``q * 255 / max(q)``.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        q: the reference histogram ``[m]``.
        bins: as :func:`heatpf_jax.colour_space.rgi_bins`.

    Returns:
        ``uint8 [H, W]``, ``round(255 q_u / max(q))`` for each pixel's bin ``u`` (all 0 for an all-zero ``q``).
    """
    q = jnp.asarray(q, _F32)
    scaled = _safe_div(q * 255.0, jnp.max(q))
    return jnp.round(scaled[rgi_bins(image, bins)]).astype(jnp.uint8)


def _round_half_even_ratio(num: Int[Array, ""], den: Int[Array, ""]) -> Int[Array, ""]:
    """``round(num / den)``, ties to even, in exact integer arithmetic (``den > 0``; no product overflows)."""
    quo = jnp.floor_divide(num, den)
    rem = num - quo * den  # [0, den)
    up = (rem > den - rem) | ((rem == den - rem) & (quo % 2 == 1))
    return quo + up.astype(jnp.int32)


@jax.jit
def mean_shift_backprojection(
    prob: Float[ArrayLike, "h w"] | UInt8[ArrayLike, "h w"],
    window: Int[ArrayLike, "4"],
    max_iter: Int[ArrayLike, ""] = 10,
    eps: Float[ArrayLike, ""] = 1.0,
) -> Int[Array, "4"]:
    """``cv2.meanShift(prob, window, (TERM_CRITERIA_EPS | TERM_CRITERIA_COUNT, max_iter, eps))``'s window.

    OpenCV's semantics (``modules/video/src/camshift.cpp``): the window ``(x, y, w, h)`` is intersected with
    the image (a window entirely outside becomes the ``1 x 1`` one at ``(W // 2, H // 2)``); each iteration
    takes the moments ``m00, m10, m01`` of ``prob`` inside it (coordinates relative to its corner), stops if
    ``m00`` is 0, moves the corner by ``round(m10 / m00 - w0 / 2)`` (``w0`` the clipped starting width;
    likewise in ``y``; ties to even, as ``cvRound``) clipped so that the window stays inside the image, and
    stops when the squared move is below ``round(eps^2)`` or after ``max(max_iter, 1)`` iterations.

    Integer images (``uint8``, the usual back-projection) are done in exact integer arithmetic while the
    window's first moments stay below ``10^9`` (any ``100 x 100`` window of ``uint8``), so the result is
    OpenCV's to the pixel; float images and larger windows use ``float32`` moments, where a centroid
    within about ``1e-6`` of a half pixel may round the other way.

    Args:
        prob: the back-projection ``[H, W]`` (non-negative), e.g. :func:`backprojection`.
        window: ``(x, y, width, height)`` of the starting window (positive sizes).
        max_iter: ``criteria.maxCount``.
        eps: ``criteria.epsilon``, pixels.

    Returns:
        ``int32 [4]``: the final ``(x, y, width, height)``.
    """
    prob = jnp.asarray(prob)
    exact = jnp.issubdtype(prob.dtype, jnp.integer)
    prob_f = prob.astype(_F32)
    prob_i = prob.astype(jnp.int32)
    h, w = prob.shape
    x, y, ww, wh = (jnp.asarray(v, jnp.int32) for v in (window[0], window[1], window[2], window[3]))
    # window & Rect(0, 0, W, H); an empty intersection is Rect() (all zeros).
    x0, y0 = jnp.maximum(x, 0), jnp.maximum(y, 0)
    cw, ch = jnp.minimum(x + ww, w) - x0, jnp.minimum(y + wh, h) - y0
    empty = (cw <= 0) | (ch <= 0)
    w0 = jnp.where(empty, 0, cw)  # the clipped window's size, used for the shift
    h0 = jnp.where(empty, 0, ch)
    cx, cy = jnp.where(empty, w // 2, x0), jnp.where(empty, h // 2, y0)
    cw, ch = jnp.where(empty, 1, cw), jnp.where(empty, 1, ch)
    eps = jnp.maximum(jnp.asarray(eps, _F32), 0.0)
    eps2 = jnp.round(eps * eps).astype(jnp.int32)
    niters = jnp.maximum(jnp.asarray(max_iter, jnp.int32), 1)
    vv = jnp.arange(h, dtype=jnp.int32)[:, None]
    uu = jnp.arange(w, dtype=jnp.int32)[None, :]

    def shift(m00_f, m1_f, m00_i, m1_i, size0):
        approx = jnp.round(_safe_div(m1_f, m00_f) - size0.astype(_F32) * 0.5).astype(jnp.int32)
        if not exact:
            return approx
        den = 2 * m00_i
        fits = (m1_f < 1e9) & (m00_f * size0.astype(_F32) < 1e9) & (m00_i > 0)
        num = 2 * m1_i - size0 * m00_i
        exact_shift = _round_half_even_ratio(jnp.where(fits, num, 0), jnp.where(fits, den, 1))
        return jnp.where(fits, exact_shift, approx)

    def body(carry):
        cx, cy, i, _ = carry
        du, dv = uu - cx, vv - cy
        inside = (du >= 0) & (du < cw) & (dv >= 0) & (dv < ch)
        p_f = jnp.where(inside, prob_f, 0.0)
        m00_f = jnp.sum(p_f)
        m10_f = jnp.sum(p_f * du.astype(_F32))
        m01_f = jnp.sum(p_f * dv.astype(_F32))
        p_i = jnp.where(inside, prob_i, 0)
        m00_i = jnp.sum(p_i)
        m10_i = jnp.sum(p_i * du)
        m01_i = jnp.sum(p_i * dv)
        no_mass = (m00_i <= 0) if exact else (jnp.abs(m00_f) < _DBL_EPSILON)
        dx = shift(m00_f, m10_f, m00_i, m10_i, w0)
        dy = shift(m00_f, m01_f, m00_i, m01_i, h0)
        nx = jnp.clip(cx + dx, 0, w - cw)
        ny = jnp.clip(cy + dy, 0, h - ch)
        moved = (nx - cx) ** 2 + (ny - cy) ** 2
        nx, ny = jnp.where(no_mass, cx, nx), jnp.where(no_mass, cy, ny)
        return nx, ny, i + 1, no_mass | (moved < eps2)

    cx, cy, _, _ = lax.while_loop(lambda c: (c[2] < niters) & ~c[3], body, (cx, cy, jnp.int32(0), jnp.bool_(False)))
    return jnp.stack([cx, cy, cw, ch])


# --- Comaniciu's mean shift ------------------------------------------------------------------------------------


class MeanShiftParams(NamedTuple):
    """Numbers of :class:`MeanShiftTracker`.

    Attributes:
        eps: stop when the window moves less than this, pixels.
        scale_gamma: Comaniciu's ``gamma``, the weight of the best probed scale (``adapt_scale`` only).
    """

    eps: float = 0.5
    scale_gamma: float = 0.1


class MeanShiftState(NamedTuple):
    """The window: centre ``[2]`` (u, v), half-size ``[2]`` and the reference histogram ``[m]``."""

    centre: Float[Array, "2"]
    half_size: Float[Array, "2"]
    reference: Float[Array, " m"]


class MeanShiftInfo(NamedTuple):
    """One frame's result.

    Attributes:
        position: the window's centre ``(u, v)``, shape ``[2]``.
        rho: Bhattacharyya coefficient of the final window's histogram and ``q``.
        iterations: mean-shift iterations done (of the chosen scale).
        found: whether the final window holds any of the reference's colours (``rho > 0``).
    """

    position: Float[Array, "2"]
    rho: Float[Array, ""]
    iterations: Int[Array, ""]
    found: Bool[Array, ""]


@dataclass(frozen=True)
class MeanShiftTracker:
    """Comaniciu et al.'s mean-shift tracker with an elliptical Epanechnikov window.

    Attributes:
        bins: the r'g'I bins (:func:`heatpf_jax.colour_space.rgi_bins`).
        max_iter: mean-shift iterations per frame at most (static).
        max_half_size: the largest half-size in pixels: each iteration works on a
            ``(2 max_half_size + 3)^2`` patch around the window, and half-sizes are clipped to
            ``[1, max_half_size]``.
        adapt_scale: Comaniciu's scale adaptation (three searches per frame, at ``h``, ``0.9 h``, ``1.1 h``).
    """

    bins: tuple[int, int, int] = DEFAULT_BINS
    max_iter: int = 20
    max_half_size: int = 24
    adapt_scale: bool = False

    def default_params(self) -> MeanShiftParams:
        return MeanShiftParams()

    def properties(self) -> MeanShiftParams:
        return MeanShiftParams(eps=positive(), scale_gamma=unit_interval())

    def make_params(self, updates: dict | None = None, /, **names) -> MeanShiftParams:
        """Default params with some replaced by name."""
        return make_params(self, updates, **names)

    def init(self, key: PRNGKeyArray, first_window: Window, params: MeanShiftParams) -> MeanShiftState:
        """The window in the first frame (the key and params are unused)."""
        del key, params
        return MeanShiftState(
            centre=jnp.asarray(first_window.centre, _F32),
            half_size=self._clip_half(jnp.asarray(first_window.half_size, _F32)),
            reference=jnp.asarray(first_window.reference, _F32),
        )

    def step(
        self, key: PRNGKeyArray, state: MeanShiftState, image: UInt8[ArrayLike, "h w 3"], params: MeanShiftParams
    ) -> tuple[MeanShiftState, MeanShiftInfo]:
        """Mean shift on ``image`` from the previous centre."""
        del key
        padded = self.padded_bins(image)
        centre, half, rho, iterations = self.search(padded, state.centre, state.half_size, state.reference, params)
        info = MeanShiftInfo(position=centre, rho=rho, iterations=iterations, found=rho > 0.0)
        return MeanShiftState(centre=centre, half_size=half, reference=state.reference), info

    def track(
        self,
        key: PRNGKeyArray,
        images: UInt8[ArrayLike, "t h w 3"],
        q: Float[ArrayLike, " m"],
        start_uv: Float[ArrayLike, "2"],
        half_size: Float[ArrayLike, "*2"],
        params: MeanShiftParams,
    ) -> Float[Array, "t 2"]:
        """:func:`track` with this tracker."""
        return track(key, images, q, start_uv, half_size, params, tracker=self)

    # -- the search, shared with the Kalman variant --

    def _clip_half(self, half: Float[Array, "2"]) -> Float[Array, "2"]:
        return jnp.clip(half, 1.0, float(self.max_half_size))

    def padded_bins(self, image: UInt8[ArrayLike, "h w 3"]) -> Int[Array, "hp wp"]:
        """The bin image padded by ``max_half_size + 1`` pixels of the out-of-image bin ``m``."""
        pad = self.max_half_size + 1
        return jnp.pad(rgi_bins(image, self.bins), pad, constant_values=num_bins(self.bins))

    def _patch(self, padded: Int[Array, "hp wp"], centre: Float[Array, "2"]):
        """The bins around ``centre`` (inside the image) and their pixel coordinates ``u [1, s]``, ``v [s, 1]``."""
        r = self.max_half_size + 1
        size = 2 * r + 1
        ci = jnp.round(centre).astype(jnp.int32)
        patch = lax.dynamic_slice(padded, (ci[1], ci[0]), (size, size))  # image rows ci_v - r .. ci_v + r
        offsets = jnp.arange(size, dtype=jnp.int32) - r
        uu = (ci[0] + offsets).astype(_F32)[None, :]
        vv = (ci[1] + offsets).astype(_F32)[:, None]
        return patch, uu, vv

    def _kernel(self, padded, centre, half, q_ext):
        """The Epanechnikov-weighted candidate histogram at ``centre``; ``(p [m+1], patch, r^2, inside, u, v)``."""
        m = q_ext.shape[0] - 1
        patch, uu, vv = self._patch(padded, centre)
        r2 = ((uu - centre[0]) / half[0]) ** 2 + ((vv - centre[1]) / half[1]) ** 2
        inside = (r2 < 1.0) & (patch < m)
        counts = jnp.zeros((m + 1,), _F32).at[patch.reshape(-1)].add(jnp.where(inside, 1.0 - r2, 0.0).reshape(-1))
        return _safe_div(counts, jnp.sum(counts)), patch, inside, uu, vv

    def _search_one(self, padded, start, half, q_ext, params: MeanShiftParams):
        shape = (padded.shape[0] - 2 * (self.max_half_size + 1), padded.shape[1] - 2 * (self.max_half_size + 1))

        def body(carry):
            centre, i, _ = carry
            p, patch, inside, uu, vv = self._kernel(padded, centre, half, q_ext)
            ratio = _safe_div(q_ext, p)  # q_u / p_u(y), 0 where p_u = 0
            wgt = jnp.where(inside, jnp.sqrt(ratio[patch]), 0.0)
            total = jnp.sum(wgt)
            mean = jnp.stack([_safe_div(jnp.sum(wgt * uu), total), _safe_div(jnp.sum(wgt * vv), total)])
            new = _clip_to_image(jnp.where(total > 0, mean, centre), shape)
            done = (total <= 0) | (jnp.sum((new - centre) ** 2) < params.eps**2)
            return new, i + 1, done

        start = _clip_to_image(start, shape)
        centre, iterations, _ = lax.while_loop(
            lambda c: (c[1] < self.max_iter) & ~c[2], body, (start, jnp.int32(0), jnp.bool_(False))
        )
        p = self._kernel(padded, centre, half, q_ext)[0]
        rho = jnp.sum(jnp.sqrt(p * q_ext))
        return centre, rho, iterations

    def search(
        self,
        padded: Int[Array, "hp wp"],
        start: Float[ArrayLike, "2"],
        half_size: Float[ArrayLike, "2"],
        q: Float[ArrayLike, " m"],
        params: MeanShiftParams,
    ) -> tuple[Float[Array, "2"], Float[Array, "2"], Float[Array, ""], Int[Array, ""]]:
        """Comaniciu's iterations on one frame from ``start`` (clipped to the image).

        Args:
            padded: the frame's :meth:`padded_bins`.
            start: the first centre ``(u, v)``.
            half_size: the ellipse's semi-axes ``[2]``.
            q: the reference histogram ``[m]``.
            params: :class:`MeanShiftParams`.

        Returns:
            ``(centre [2], half_size [2], rho, iterations)``: the converged centre, the (adapted) half-size,
            the Bhattacharyya coefficient there and the number of iterations.
        """
        q_ext = jnp.concatenate([jnp.asarray(q, _F32), jnp.zeros((1,), _F32)])  # bin m: outside the image
        start = jnp.asarray(start, _F32)
        half = self._clip_half(jnp.asarray(half_size, _F32))
        if not self.adapt_scale:
            centre, rho, iterations = self._search_one(padded, start, half, q_ext, params)
            return centre, half, rho, iterations
        scales = jnp.array([1.0, 0.9, 1.1], _F32)
        halves = self._clip_half(scales[:, None] * half[None, :])
        centres, rhos, iters = jax.vmap(lambda hh: self._search_one(padded, start, hh, q_ext, params))(halves)
        best = jnp.argmax(rhos)
        new_half = self._clip_half(params.scale_gamma * halves[best] + (1.0 - params.scale_gamma) * half)
        return centres[best], new_half, rhos[best], iters[best]


# --- Mean shift + Kalman ---------------------------------------------------------------------------------------


class KalmanMeanShiftParams(NamedTuple):
    """Numbers of :class:`KalmanMeanShiftTracker`.

    Attributes:
        mean_shift: the search's :class:`MeanShiftParams`.
        accel_std: white-noise acceleration, pixels / frame^2.
        meas_std: std of the mean-shift result, pixels.
        init_position_std: prior std of the first position, pixels.
        init_velocity_std: prior std of the first velocity, pixels / frame.
    """

    mean_shift: MeanShiftParams = MeanShiftParams()
    accel_std: float = 1.0
    meas_std: float = 2.0
    init_position_std: float = 2.0
    init_velocity_std: float = 3.0


class KalmanMeanShiftState(NamedTuple):
    """The Kalman state ``(u, v, du, dv)`` (mean ``[4]``, covariance ``[4, 4]``), half-size ``[2]``, ``q [m]``."""

    kalman: KalmanState
    half_size: Float[Array, "2"]
    reference: Float[Array, " m"]


class KalmanMeanShiftInfo(NamedTuple):
    """One frame's result.

    Attributes:
        position: the filtered ``(u, v)``, shape ``[2]``.
        measurement: the mean-shift result ``(u, v)`` the update took, shape ``[2]``.
        rho: Bhattacharyya coefficient at the measurement.
        iterations: mean-shift iterations done.
        found: whether the window held any reference colour (else the filter only predicted).
    """

    position: Float[Array, "2"]
    measurement: Float[Array, "2"]
    rho: Float[Array, ""]
    iterations: Int[Array, ""]
    found: Bool[Array, ""]


@dataclass(frozen=True)
class KalmanMeanShiftTracker:
    """The paper's "Mean Shift + KL": mean shift seeded by a constant-velocity Kalman filter, which takes its result.

    Per frame: predict (``F`` = constant velocity over one frame, white-noise acceleration ``accel_std``);
    mean shift from the predicted position (clipped to the image); update with the converged centre as the
    measurement (noise ``meas_std``), skipped when the window holds none of the reference's colours. The
    filtered position is kept in the image, the velocity along a bound it hits set to 0 (no-ops while the
    object is inside).

    Attributes:
        mean_shift: the search (its bins, iterations, window bound, scale adaptation).
    """

    mean_shift: MeanShiftTracker = MeanShiftTracker()

    def default_params(self) -> KalmanMeanShiftParams:
        return KalmanMeanShiftParams(mean_shift=self.mean_shift.default_params())

    def properties(self) -> KalmanMeanShiftParams:
        return KalmanMeanShiftParams(
            mean_shift=self.mean_shift.properties(),
            accel_std=nonnegative(),
            meas_std=positive(),
            init_position_std=positive(),
            init_velocity_std=positive(),
        )

    def make_params(self, updates: dict | None = None, /, **names) -> KalmanMeanShiftParams:
        """Default params with some replaced by (dotted or unambiguous short) name."""
        return make_params(self, updates, **names)

    def init(self, key: PRNGKeyArray, first_window: Window, params: KalmanMeanShiftParams) -> KalmanMeanShiftState:
        """Prior ``N((u, v, 0, 0), diag(s_p^2, s_p^2, s_v^2, s_v^2))`` at the first window (key unused)."""
        del key
        pos_var = jnp.square(jnp.asarray(params.init_position_std, _F32))
        vel_var = jnp.square(jnp.asarray(params.init_velocity_std, _F32))
        mean = jnp.concatenate([jnp.asarray(first_window.centre, _F32), jnp.zeros((2,), _F32)])
        cov = jnp.diag(jnp.stack([pos_var, pos_var, vel_var, vel_var]))
        return KalmanMeanShiftState(
            kalman=KalmanState(mean=mean, cov=cov),
            half_size=self.mean_shift._clip_half(jnp.asarray(first_window.half_size, _F32)),
            reference=jnp.asarray(first_window.reference, _F32),
        )

    def step(
        self,
        key: PRNGKeyArray,
        state: KalmanMeanShiftState,
        image: UInt8[ArrayLike, "h w 3"],
        params: KalmanMeanShiftParams,
    ) -> tuple[KalmanMeanShiftState, KalmanMeanShiftInfo]:
        """Predict, search from the prediction, update with the search's result."""
        del key
        image = jnp.asarray(image)
        predicted = kalman_predict(state.kalman, jnp.float32(1.0), jnp.asarray(params.accel_std, _F32))
        padded = self.mean_shift.padded_bins(image)
        z, half, rho, iterations = self.mean_shift.search(
            padded, predicted.mean[:2], state.half_size, state.reference, params.mean_shift
        )
        found = rho > 0.0
        updated = kalman_update(predicted, z, found, jnp.asarray(params.meas_std, _F32))
        pos = _clip_to_image(updated.mean[:2], image.shape)
        vel = jnp.where(pos != updated.mean[:2], 0.0, updated.mean[2:])
        kalman = KalmanState(mean=jnp.concatenate([pos, vel]), cov=updated.cov)
        info = KalmanMeanShiftInfo(position=pos, measurement=z, rho=rho, iterations=iterations, found=found)
        return KalmanMeanShiftState(kalman=kalman, half_size=half, reference=state.reference), info

    def track(
        self,
        key: PRNGKeyArray,
        images: UInt8[ArrayLike, "t h w 3"],
        q: Float[ArrayLike, " m"],
        start_uv: Float[ArrayLike, "2"],
        half_size: Float[ArrayLike, "*2"],
        params: KalmanMeanShiftParams,
    ) -> Float[Array, "t 2"]:
        """:func:`track` with this tracker."""
        return track(key, images, q, start_uv, half_size, params, tracker=self)


# --- Colour particle filter ------------------------------------------------------------------------------------


@partial(jax.jit, static_argnames=("bins", "top_bins"))
def window_histograms(
    image: UInt8[ArrayLike, "h w 3"],
    q: Float[ArrayLike, " m"],
    centres: Float[ArrayLike, "n 2"],
    half_size: Float[ArrayLike, "*2"],
    bins: tuple[int, int, int] = DEFAULT_BINS,
    top_bins: int = 64,
) -> tuple[Float[Array, "n k"], Float[Array, " k"], Int[Array, " k"]]:
    """The histograms of rectangular windows, over the reference's ``top_bins`` largest bins.

    Window ``i`` covers rows ``round(v_i) - round(h_v) .. round(v_i) + round(h_v)`` and the like columns
    (inclusive), clipped to the image; its histogram is normalised by its pixel count (every bin), so
    ``sum_k sqrt(p_ik q_top_k)`` is the exact Bhattacharyya coefficient when ``q`` has at most ``top_bins``
    non-zero bins. Summed-area tables (a ``uint16`` cumulative sum of the ``[H, W, K]`` one-hot bins, exact for
    windows below ``2^16`` pixels: half-sizes are clipped to 127) give each window's counts from 4 corner
    gathers. An empty window (entirely outside) has an all-zero histogram.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        q: the reference histogram ``[m]``.
        centres: window centres ``(u, v)`` ``[N, 2]``.
        half_size: half width and height (scalar or ``[2]``), pixels.
        bins: the r'g'I bins.
        top_bins: ``K`` (static), at most ``m``.

    Returns:
        ``(p [N, K], q_top [K], top_index [K])``: the windows' histograms on the ``K`` bins, the reference's
        values there and the bins' indices (``lax.top_k`` order).
    """
    image = jnp.asarray(image)
    h, w = image.shape[:2]
    tables = bin_table(image, q, top_bins, bins)
    centres = jnp.asarray(centres, _F32)
    half = jnp.round(jnp.broadcast_to(jnp.asarray(half_size, _F32), (2,)))
    half = jnp.clip(half, 0.0, float(MAX_BOX_HALF)).astype(jnp.int32)
    cu = jnp.round(centres[:, 0]).astype(jnp.int32)
    cv = jnp.round(centres[:, 1]).astype(jnp.int32)
    x0, x1 = jnp.clip(cu - half[0], 0, w), jnp.clip(cu + half[0] + 1, 0, w)
    y0, y1 = jnp.clip(cv - half[1], 0, h), jnp.clip(cv + half[1] + 1, 0, h)
    sums = box_counts(tables.table, y0, y1, x0, x1)
    count = ((y1 - y0) * (x1 - x0)).astype(_F32)
    return _safe_div(sums, count[:, None]), tables.q_top, tables.top_index


class ColourParticleParams(NamedTuple):
    """Numbers of :class:`ColourParticleTracker`.

    Attributes:
        position_std: position noise per frame, pixels.
        velocity_std: velocity noise per frame, pixels / frame.
        lam: the likelihood's ``lambda`` in ``exp(-lambda (1 - rho))`` (20 in Perez et al.).
        init_position_std: spread of the first particles about the first window's centre, pixels.
    """

    position_std: float = 2.0
    velocity_std: float = 1.0
    lam: float = 20.0
    init_position_std: float = 2.0


class ColourParticleState(NamedTuple):
    """Particles ``(u, v, du, dv)`` ``[N, 4]`` (equally weighted after resampling), half-size ``[2]``, ``q [m]``."""

    particles: Float[Array, "n 4"]
    half_size: Float[Array, "2"]
    reference: Float[Array, " m"]


class ColourParticleInfo(NamedTuple):
    """One frame's result.

    Attributes:
        position: the weighted mean ``(u, v)`` of the moved particles, shape ``[2]``.
        ess: effective sample size of the weights before resampling.
        max_rho: the best particle's Bhattacharyya coefficient.
        ancestors: the resampled indices ``[N]``.
    """

    position: Float[Array, "2"]
    ess: Float[Array, ""]
    max_rho: Float[Array, ""]
    ancestors: Int[Array, " n"]


@dataclass(frozen=True)
class ColourParticleTracker:
    """Perez et al.'s colour particle filter in the image with rectangular windows.

    Attributes:
        num_particles: ``N`` (150 in the paper's Table 2).
        bins: the r'g'I bins.
        top_bins: ``K``, the reference's bins the window histograms are taken over (see :func:`window_histograms`).
    """

    num_particles: int = 150
    bins: tuple[int, int, int] = DEFAULT_BINS
    top_bins: int = 64

    def default_params(self) -> ColourParticleParams:
        return ColourParticleParams()

    def properties(self) -> ColourParticleParams:
        return ColourParticleParams(
            position_std=nonnegative(), velocity_std=nonnegative(), lam=positive(), init_position_std=nonnegative()
        )

    def make_params(self, updates: dict | None = None, /, **names) -> ColourParticleParams:
        """Default params with some replaced by name."""
        return make_params(self, updates, **names)

    def init(self, key: PRNGKeyArray, first_window: Window, params: ColourParticleParams) -> ColourParticleState:
        """``N`` particles about the first centre (Gaussian, ``init_position_std``), velocity 0."""
        n = self.num_particles
        noise = jax.random.normal(key, (n, 2), _F32) * jnp.asarray(params.init_position_std, _F32)
        xy = jnp.asarray(first_window.centre, _F32)[None, :] + noise
        return ColourParticleState(
            particles=jnp.concatenate([xy, jnp.zeros((n, 2), _F32)], axis=1),
            half_size=jnp.maximum(jnp.asarray(first_window.half_size, _F32), 0.0),
            reference=jnp.asarray(first_window.reference, _F32),
        )

    def step(
        self,
        key: PRNGKeyArray,
        state: ColourParticleState,
        image: UInt8[ArrayLike, "h w 3"],
        params: ColourParticleParams,
    ) -> tuple[ColourParticleState, ColourParticleInfo]:
        """Move (constant velocity + noise, positions kept in the image), weigh, estimate, resample."""
        k_motion, k_resample = jax.random.split(key)
        image = jnp.asarray(image)
        n = self.num_particles
        p = state.particles
        std = jnp.stack([params.position_std, params.position_std, params.velocity_std, params.velocity_std])
        noise = jax.random.normal(k_motion, (n, 4), _F32) * jnp.asarray(std, _F32)[None, :]
        pos = _clip_to_image(p[:, :2] + p[:, 2:] + noise[:, :2], image.shape)
        vel = p[:, 2:] + noise[:, 2:]
        hist, q_top, _ = window_histograms(image, state.reference, pos, state.half_size, self.bins, self.top_bins)
        rho = jnp.sum(jnp.sqrt(hist * q_top[None, :]), axis=1)
        weights = jax.nn.softmax(-jnp.asarray(params.lam, _F32) * (1.0 - rho))
        estimate = weights @ pos
        ancestors = systematic(k_resample, weights, n)
        particles = jnp.concatenate([pos, vel], axis=1)[ancestors]
        info = ColourParticleInfo(
            position=estimate, ess=effective_sample_size(weights), max_rho=jnp.max(rho), ancestors=ancestors
        )
        return ColourParticleState(particles=particles, half_size=state.half_size, reference=state.reference), info

    def window_histograms(self, image, q, centres, half_size):
        """:func:`window_histograms` with this tracker's bins and ``top_bins``."""
        return window_histograms(image, q, centres, half_size, self.bins, self.top_bins)

    def track(
        self,
        key: PRNGKeyArray,
        images: UInt8[ArrayLike, "t h w 3"],
        q: Float[ArrayLike, " m"],
        start_uv: Float[ArrayLike, "2"],
        half_size: Float[ArrayLike, "*2"],
        params: ColourParticleParams,
    ) -> Float[Array, "t 2"]:
        """:func:`track` with this tracker."""
        return track(key, images, q, start_uv, half_size, params, tracker=self)


# --- Sequences -------------------------------------------------------------------------------------------------


@partial(jax.jit, static_argnames=("tracker",))
def run(
    key: PRNGKeyArray,
    images: UInt8[ArrayLike, "t h w 3"],
    q: Float[ArrayLike, " m"],
    start_uv: Float[ArrayLike, "2"],
    half_size: Float[ArrayLike, "*2"],
    params: Any,
    *,
    tracker: Any,
) -> tuple[Any, Any]:
    """Runs ``tracker`` over the frames with ``lax.scan``: ``(final state, per-frame info)``.

    Args:
        key: PRNG key (split into the init's and one per frame).
        images: ``uint8 [T, H, W, 3]`` RGB frames.
        q: the reference histogram ``[m]``.
        start_uv: the object's centre ``(u, v)`` in the first frame, pixels.
        half_size: the window's half-size, scalar or ``[2]`` (half width, half height), pixels.
        params: the tracker's params.
        tracker: :class:`MeanShiftTracker`, :class:`KalmanMeanShiftTracker` or :class:`ColourParticleTracker`
            (static).

    Returns:
        The final state and the tracker's info ``NamedTuple`` with a leading ``T`` axis.
    """
    images = jnp.asarray(images)
    k_init, k_steps = jax.random.split(key)
    state = tracker.init(k_init, _window(start_uv, half_size, q), params)

    def body(state, inputs):
        k, image = inputs
        return tracker.step(k, state, image, params)

    return lax.scan(body, state, (jax.random.split(k_steps, images.shape[0]), images))


def track(
    key: PRNGKeyArray,
    images: UInt8[ArrayLike, "t h w 3"],
    q: Float[ArrayLike, " m"],
    start_uv: Float[ArrayLike, "2"],
    half_size: Float[ArrayLike, "*2"],
    params: Any,
    *,
    tracker: Any,
) -> Float[Array, "t 2"]:
    """The ``(u, v)`` that ``tracker`` reports for each frame, ``float32 [T, 2]`` (the jitted :func:`run`'s)."""
    return run(key, images, q, start_uv, half_size, params, tracker=tracker)[1].position
