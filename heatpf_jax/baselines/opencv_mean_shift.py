"""OpenCV's meanShift on a back-projection, to the pixel.

:func:`mean_shift_backprojection`: OpenCV's ``cv2.meanShift`` on a back-projection (the window moves
to the rounded centroid of the probability inside it), with OpenCV's clipping, rounding and stopping;
:func:`backprojection` is ``cv2.calcBackProject`` of the reference histogram (the r'g'I bins of
:mod:`heatpf_jax.colour.space`) scaled to ``0..255``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, Int, UInt8

from heatpf_jax.baselines.image_window import _F32, _safe_div
from heatpf_jax.colour.space import DEFAULT_BINS, rgi_bins

__all__ = ["backprojection", "mean_shift_backprojection"]

_DBL_EPSILON = 2.220446049250313e-16


def backprojection(
    image: UInt8[ArrayLike, "h w 3"], q: Float[ArrayLike, " m"], bins: tuple[int, int, int] = DEFAULT_BINS
) -> UInt8[Array, "h w"]:
    """``q`` at every pixel's bin scaled to ``0..255``: ``cv2.calcBackProject`` of ``q * 255 / max(q)``.

    Args:
        image: ``uint8 [H, W, 3]`` RGB.
        q: the reference histogram ``[m]``.
        bins: as :func:`heatpf_jax.colour.space.rgi_bins`.

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
