"""Image-space colour trackers, the contestants of Olufs et al.'s Table 1.

* :func:`mean_shift_window`: OpenCV's ``cv2.meanShift`` on a back-projection (a probability image): the
  window moves to the centroid of the probability inside it until the shift is below ``eps`` pixels or
  ``max_iter`` iterations, with OpenCV's rounding and clipping (checked against it in the tests).
* :class:`MeanShiftTracker` (Comaniciu, Ramesh, Meer 2003, "Kernel-based object tracking"): each frame
  the window climbs the Bhattacharyya coefficient from the previous position: pixel weights
  ``sqrt(q_u / p_u(y))`` for the candidate histogram ``p(y)`` under an Epanechnikov profile, the new
  centre their weighted mean (the profile's derivative is constant), until the shift is below ``eps``.
* :class:`KalmanMeanShiftTracker` ("Mean Shift + KL"): a constant-velocity Kalman filter in pixels whose
  prediction starts the mean-shift search and whose update takes its result.
* :class:`ColourParticleTracker` (Perez, Hue, Vermaak, Gangnet 2002; Nummiaro et al. 2003): particles
  ``(u, v, du, dv)`` with constant-velocity motion and Gaussian noise, likelihood
  ``exp(-lam * (1 - rho))`` with ``rho`` the Bhattacharyya coefficient of the window's histogram (summed-
  area tables over the reference's ``top_bins`` bins, as :mod:`heatpf_jax.colour_likelihood`),
  systematic resampling every step, output the weighted mean.

All are pure JAX with ``init``/``step``; :func:`track` scans one over a sequence of frames. None re-detects
a lost object, as in the paper's comparison; positions are kept inside the image (a window that finds
none of the reference's colours gives the Kalman variant no measurement). Positions are ``(u, v)`` =
(column, row) in pixels.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray, UInt8

from heatpf_jax.colour_space import DEFAULT_BINS, num_bins, rgi_bins
from heatpf_jax.resampling import systematic

__all__ = [
    "ColourParticleParams",
    "ColourParticleTracker",
    "KalmanMeanShiftParams",
    "KalmanMeanShiftTracker",
    "MeanShiftParams",
    "MeanShiftTracker",
    "backprojection",
    "mean_shift_window",
    "track",
]


def backprojection(image: UInt8[ArrayLike, "h w 3"], q: Float[ArrayLike, " m"], bins=DEFAULT_BINS):
    """``q`` at every pixel's bin, scaled so that its largest value is 1: the probability image of
    ``cv2.calcBackProject``."""
    q = jnp.asarray(q, jnp.float32)
    return q[rgi_bins(image, bins)] / jnp.maximum(jnp.max(q), 1e-12)


def mean_shift_window(prob: Float[ArrayLike, "h w"], window, max_iter: int = 10, eps: float = 1.0):
    """``cv2.meanShift(prob, window, (EPS | COUNT, max_iter, eps))``: the final window ``(x, y, w, h)``.

    As OpenCV: the window is clipped to the image; the shift is the rounded centroid of ``prob`` inside it
    minus half the window size, the new corner clipped so the window stays inside; the loop stops when
    the window's mass is 0 or the squared shift is below ``round(eps^2)``.
    """
    prob = jnp.asarray(prob, jnp.float32)
    h, w = prob.shape
    x, y, ww, wh = (jnp.asarray(v, jnp.int32) for v in window)
    # The window clipped to the image (cv::Rect intersection), at least 1 x 1.
    x0, y0 = jnp.clip(x, 0, w), jnp.clip(y, 0, h)
    x1, y1 = jnp.clip(x + ww, 0, w), jnp.clip(y + wh, 0, h)
    cw, ch = jnp.maximum(x1 - x0, 1), jnp.maximum(y1 - y0, 1)
    eps2 = jnp.round(jnp.float32(eps) ** 2)
    vv, uu = jnp.meshgrid(jnp.arange(h), jnp.arange(w), indexing="ij")

    def body(carry):
        cx, cy, i, _ = carry
        inside = (uu >= cx) & (uu < cx + cw) & (vv >= cy) & (vv < cy + ch)
        p = jnp.where(inside, prob, 0.0)
        m00 = jnp.sum(p)
        m10 = jnp.sum(p * (uu - cx).astype(jnp.float32))
        m01 = jnp.sum(p * (vv - cy).astype(jnp.float32))
        empty = m00 < 1e-12
        safe = jnp.where(empty, 1.0, m00)
        dx = jnp.round(m10 / safe - ww.astype(jnp.float32) * 0.5).astype(jnp.int32)
        dy = jnp.round(m01 / safe - wh.astype(jnp.float32) * 0.5).astype(jnp.int32)
        nx = jnp.clip(cx + dx, 0, w - cw)
        ny = jnp.clip(cy + dy, 0, h - ch)
        moved = (nx - cx) ** 2 + (ny - cy) ** 2
        nx, ny = jnp.where(empty, cx, nx), jnp.where(empty, cy, ny)
        done = empty | (moved.astype(jnp.float32) < eps2)
        return nx, ny, i + 1, done

    cx, cy, _, _ = lax.while_loop(lambda c: (c[2] < max_iter) & ~c[3], body, (x0, y0, jnp.int32(0), jnp.bool_(False)))
    return cx, cy, cw, ch


# --- Comaniciu mean shift --------------------------------------------------------------------------------------


class MeanShiftParams(NamedTuple):
    """Numbers of :class:`MeanShiftTracker`.

    Attributes:
        max_iter: mean-shift iterations per frame.
        eps: stop below this shift, pixels.
    """

    max_iter: int = 20
    eps: float = 0.5


def _epanechnikov_histogram(idx, centre, half, num, valid):
    h, w = idx.shape
    vv, uu = jnp.meshgrid(jnp.arange(h, dtype=jnp.float32), jnp.arange(w, dtype=jnp.float32), indexing="ij")
    r2 = ((uu - centre[0]) / half) ** 2 + ((vv - centre[1]) / half) ** 2
    k = jnp.where((r2 < 1.0) & valid, 1.0 - r2, 0.0)
    counts = jnp.zeros((num,), jnp.float32).at[idx.reshape(-1)].add(k.reshape(-1))
    total = jnp.sum(counts)
    return counts / jnp.where(total > 0, total, 1.0), r2, uu, vv


def _mean_shift(idx, q, start, half, params: MeanShiftParams, num: int):
    """Comaniciu's iterations from ``start`` (clipped to the image) on one frame's bin image:
    ``(centre, found)``, ``found`` False where the window holds none of the reference's colours."""
    valid = jnp.ones(idx.shape, bool)
    h, w = idx.shape
    start = jnp.clip(jnp.asarray(start, jnp.float32), jnp.zeros((2,), jnp.float32),
                     jnp.array([w - 1, h - 1], jnp.float32))

    def body(carry):
        centre, i, _ = carry
        p, r2, uu, vv = _epanechnikov_histogram(idx, centre, half, num, valid)
        ratio = jnp.where(p > 0, q / jnp.where(p > 0, p, 1.0), 0.0)
        wgt = jnp.where(r2 < 1.0, jnp.sqrt(ratio[idx]), 0.0)
        total = jnp.sum(wgt)
        new = jnp.where(total > 0, jnp.stack([jnp.sum(wgt * uu), jnp.sum(wgt * vv)]) / jnp.where(total > 0, total, 1.0),
                        centre)
        done = jnp.sum((new - centre) ** 2) < params.eps**2
        return new, i + 1, done

    centre, _, _ = lax.while_loop(lambda c: (c[1] < params.max_iter) & ~c[2], body,
                                  (start, jnp.int32(0), jnp.bool_(False)))
    p, r2, _, _ = _epanechnikov_histogram(idx, centre, half, num, valid)
    found = jnp.sum(jnp.sqrt(p * q)) > 0.0
    return centre, found


class PixelState(NamedTuple):
    """A tracker's state: its position (and velocity, for the Kalman variant) in pixels."""

    mean: Float[Array, " d"]
    cov: Float[Array, "d d"]


@dataclass(frozen=True)
class MeanShiftTracker:
    """Comaniciu et al.'s mean-shift tracker with a fixed round window of radius ``half`` pixels."""

    bins: tuple[int, int, int] = DEFAULT_BINS

    def default_params(self) -> MeanShiftParams:
        return MeanShiftParams()

    def init(self, key: PRNGKeyArray, start, params) -> PixelState:
        del key, params
        return PixelState(mean=jnp.asarray(start, jnp.float32), cov=jnp.zeros((2, 2), jnp.float32))

    def step(self, key, state: PixelState, frame, q, half, params: MeanShiftParams):
        del key
        idx = rgi_bins(frame, self.bins)
        centre, _ = _mean_shift(idx, q, state.mean, half, params, num_bins(self.bins))
        return PixelState(mean=centre, cov=state.cov), centre


class KalmanMeanShiftParams(NamedTuple):
    """Numbers of :class:`KalmanMeanShiftTracker`.

    Attributes:
        mean_shift: the mean-shift search's.
        accel_std: white-noise acceleration, pixels / frame^2.
        meas_std: std of a mean-shift result, pixels.
    """

    mean_shift: MeanShiftParams = MeanShiftParams()
    accel_std: float = 2.0
    meas_std: float = 2.0


@dataclass(frozen=True)
class KalmanMeanShiftTracker:
    """Mean shift seeded by a constant-velocity Kalman filter in pixels, which takes its result."""

    bins: tuple[int, int, int] = DEFAULT_BINS

    def default_params(self) -> KalmanMeanShiftParams:
        return KalmanMeanShiftParams()

    def init(self, key: PRNGKeyArray, start, params) -> PixelState:
        del key, params
        mean = jnp.concatenate([jnp.asarray(start, jnp.float32), jnp.zeros((2,), jnp.float32)])
        return PixelState(mean=mean, cov=jnp.diag(jnp.array([4.0, 4.0, 25.0, 25.0], jnp.float32)))

    def step(self, key, state: PixelState, frame, q, half, params: KalmanMeanShiftParams):
        del key
        f = jnp.eye(4, dtype=jnp.float32).at[0, 2].set(1.0).at[1, 3].set(1.0)
        g = jnp.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]], jnp.float32)
        mean = f @ state.mean
        cov = f @ state.cov @ f.T + params.accel_std**2 * (g @ g.T)
        idx = rgi_bins(frame, self.bins)
        z, found = _mean_shift(idx, q, mean[:2], half, params.mean_shift, num_bins(self.bins))
        h = jnp.eye(2, 4, dtype=jnp.float32)
        s = h @ cov @ h.T + params.meas_std**2 * jnp.eye(2, dtype=jnp.float32)
        gain = jnp.linalg.solve(s, h @ cov).T
        # No reference colour in the window: no measurement (prediction only).
        mean = jnp.where(found, mean + gain @ (z - h @ mean), mean)
        cov = jnp.where(found, (jnp.eye(4, dtype=jnp.float32) - gain @ h) @ cov, cov)
        # The position stays in the image; a bound stops the velocity along it.
        rows, cols = idx.shape
        bound = jnp.array([cols - 1, rows - 1], jnp.float32)
        clipped = jnp.clip(mean[:2], jnp.zeros((2,), jnp.float32), bound)
        vel = jnp.where(clipped != mean[:2], 0.0, mean[2:])
        mean = jnp.concatenate([clipped, vel])
        return PixelState(mean=mean, cov=cov), mean[:2]


# --- Colour particle filter ------------------------------------------------------------------------------------


class ColourParticleParams(NamedTuple):
    """Numbers of :class:`ColourParticleTracker`.

    Attributes:
        position_std: position noise per frame, pixels.
        velocity_std: velocity noise per frame, pixels / frame.
        lam: the likelihood's sharpness, ``exp(-lam (1 - rho))`` (20 in Perez et al.).
    """

    position_std: float = 2.0
    velocity_std: float = 1.0
    lam: float = 20.0


class ParticleState(NamedTuple):
    """Particles ``(u, v, du, dv)`` ``[N, 4]``."""

    particles: Float[Array, "n 4"]


@dataclass(frozen=True)
class ColourParticleTracker:
    """Perez et al.'s colour particle filter in the image, ``num_particles`` particles (150 in Table 2)."""

    num_particles: int = 150
    bins: tuple[int, int, int] = DEFAULT_BINS
    top_bins: int = 64

    def default_params(self) -> ColourParticleParams:
        return ColourParticleParams()

    def init(self, key: PRNGKeyArray, start, params: ColourParticleParams) -> ParticleState:
        n = self.num_particles
        noise = jax.random.normal(key, (n, 2), jnp.float32) * params.position_std
        xy = jnp.asarray(start, jnp.float32)[None, :] + noise
        return ParticleState(particles=jnp.concatenate([xy, jnp.zeros((n, 2), jnp.float32)], axis=1))

    def window_histograms(self, frame, q, centres, half):
        """The normalised histograms of the square windows of half-size ``half`` at ``centres`` ``[N, 2]``
        over the reference's ``top_bins`` bins: ``([N, K] histograms, [K] reference masses)``."""
        h, w = frame.shape[:2]
        q = jnp.asarray(q, jnp.float32)
        q_top, u_top = lax.top_k(q, min(self.top_bins, q.shape[0]))
        idx = rgi_bins(frame, self.bins)
        onehot = (idx[..., None] == u_top[None, None, :]).astype(jnp.float32)
        table = jnp.pad(jnp.cumsum(jnp.cumsum(onehot, axis=0), axis=1), ((1, 0), (1, 0), (0, 0)))
        r = jnp.round(jnp.asarray(half, jnp.float32)).astype(jnp.int32)
        cu = jnp.round(centres[:, 0]).astype(jnp.int32)
        cv = jnp.round(centres[:, 1]).astype(jnp.int32)
        y0, y1 = jnp.clip(cv - r, 0, h), jnp.clip(cv + r + 1, 0, h)
        x0, x1 = jnp.clip(cu - r, 0, w), jnp.clip(cu + r + 1, 0, w)
        sums = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
        count = ((y1 - y0) * (x1 - x0)).astype(jnp.float32)
        return sums / jnp.maximum(count, 1.0)[:, None], q_top

    def step(self, key, state: ParticleState, frame, q, half, params: ColourParticleParams):
        k_noise, k_res = jax.random.split(key)
        n = self.num_particles
        p = state.particles
        noise = jax.random.normal(k_noise, (n, 4), jnp.float32) * jnp.array(
            [params.position_std, params.position_std, params.velocity_std, params.velocity_std], jnp.float32)[None, :]
        p = jnp.concatenate([p[:, :2] + p[:, 2:], p[:, 2:]], axis=1) + noise
        rows, cols = frame.shape[:2]
        p = p.at[:, :2].set(jnp.clip(p[:, :2], jnp.zeros((1, 2), jnp.float32),
                                     jnp.array([[cols - 1, rows - 1]], jnp.float32)))  # particles stay in the image
        hist, q_top = self.window_histograms(frame, q, p[:, :2], half)
        rho = jnp.sum(jnp.sqrt(hist * q_top[None, :]), axis=1)
        log_w = -params.lam * (1.0 - rho)
        w = jax.nn.softmax(log_w)
        estimate = w @ p[:, :2]
        ancestors = systematic(k_res, w, n)
        return ParticleState(particles=p[ancestors]), estimate


@partial(jax.jit, static_argnames="tracker")
def track(
    key: PRNGKeyArray,
    images: UInt8[ArrayLike, "t h w 3"],
    q: Float[ArrayLike, " m"],
    start: Float[ArrayLike, "2"],
    half: Float[ArrayLike, ""],
    params: Any,
    tracker: Any,
) -> Float[Array, "t 2"]:
    """Runs ``tracker`` over the frames (``lax.scan``): the ``(u, v)`` it reports for each frame."""
    k_init, k_steps = jax.random.split(key)
    q = jnp.asarray(q, jnp.float32)
    half = jnp.asarray(half, jnp.float32)
    images = jnp.asarray(images)

    def body(state, x):
        k, frame = x
        return tracker.step(k, state, frame, q, half, params)

    keys = jax.random.split(k_steps, images.shape[0])
    _, out = lax.scan(body, tracker.init(k_init, start, params), (keys, images))
    return out
