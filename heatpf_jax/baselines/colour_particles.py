"""The "MC Tracker": Perez et al.'s colour particle filter in the image, on rectangular window histograms.

:class:`ColourParticleTracker` (Perez, Hue, Vermaak, Gangnet 2002; Nummiaro et al. 2003): particles
``(u, v, du, dv)`` with constant-velocity motion and Gaussian noise, likelihood
``exp(-lam d^2)`` with ``d^2 = 1 - rho``, systematic resampling every frame, the weighted mean as
output. Window histograms (:func:`window_histograms`) come from summed-area tables over the reference's
``top_bins`` largest bins (exact when ``q`` has at most ``top_bins`` non-zero bins): 4 corner gathers per
particle.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, Int, PRNGKeyArray, UInt8

from heatpf_jax.baselines.image_sequences import SequenceTracker
from heatpf_jax.baselines.image_window import _F32, Window, _clip_to_image, _safe_div
from heatpf_jax.colour.space import DEFAULT_BINS, MAX_BOX_HALF, bin_table, box_counts
from heatpf_jax.params import make_params, nonnegative, positive
from heatpf_jax.resampling.resamplers import effective_sample_size, systematic

__all__ = [
    "ColourParticleInfo",
    "ColourParticleParams",
    "ColourParticleState",
    "ColourParticleTracker",
    "window_histograms",
]


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
class ColourParticleTracker(SequenceTracker):
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

