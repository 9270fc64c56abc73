"""The image-space trackers' common ground: the first frame's :class:`Window` and the pixel helpers they share.

Positions are ``(u, v)`` = (column, row) in pixels, pixel centres at integers. Windows are clipped to
the image, centres kept inside it; a window without any of the reference's colours leaves the mean shift
where it is (and gives the Kalman filter no measurement), and an empty window has an all-zero histogram.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Window"]

_F32 = jnp.float32


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
