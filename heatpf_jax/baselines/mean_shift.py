"""Comaniciu's mean-shift tracker: an elliptical Epanechnikov window climbing the Bhattacharyya coefficient.

:class:`MeanShiftTracker` (Comaniciu, Ramesh, Meer 2003, "Kernel-based object tracking"): each frame
the elliptical window climbs ``rho`` from the previous centre. The candidate histogram ``p(y)`` is
weighted by the Epanechnikov profile ``k(r^2) = 1 - r^2``; each pixel gets ``w_i = sqrt(q_u / p_u(y))``
for its bin ``u``, and the new centre is their weighted mean over the window (the profile's
derivative is constant, so the mean-shift kernel ``g`` is flat) until the shift is below ``eps`` or
after ``max_iter`` iterations. Optionally Comaniciu's scale adaptation: search with ``h``, ``0.9 h``
and ``1.1 h``, keep the best ``rho``, ``h <- gamma h_best + (1 - gamma) h``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, UInt8

from heatpf_jax.baselines.image_sequences import SequenceTracker
from heatpf_jax.baselines.image_window import _F32, Window, _clip_to_image, _safe_div
from heatpf_jax.colour.space import DEFAULT_BINS, num_bins, rgi_bins
from heatpf_jax.params import make_params, positive, unit_interval

__all__ = [
    "MeanShiftInfo",
    "MeanShiftParams",
    "MeanShiftState",
    "MeanShiftTracker",
]


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
class MeanShiftTracker(SequenceTracker):
    """Comaniciu et al.'s mean-shift tracker with an elliptical Epanechnikov window.

    Attributes:
        bins: the r'g'I bins (:func:`heatpf_jax.colour.space.rgi_bins`).
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
