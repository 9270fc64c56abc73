"""The robot's base frame from one step to the next: where points of step t-1 lie in the base frame of step t (III-D).

Shared by everything odometry moves: particles (:mod:`heatpf_jax.motion`), buffered measurements
(:mod:`heatpf_jax.measurements`) and the memory's tracks.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["apply_odometry"]


def apply_odometry(points: Float[ArrayLike, "n 2"], odometry: Float[ArrayLike, "... 3"]) -> Float[Array, "n 2"]:
    """Expresses base-frame points of step t-1 in the base frame of step t.

    Args:
        points: ``[n, 2]`` points.
        odometry: ``[3]`` shared motion, or ``[n, 3]`` one motion per point.

    Returns:
        ``[n, 2]`` points ``R(dtheta)^T (p - (dx, dy))``.
    """
    points = jnp.asarray(points)
    odometry = jnp.asarray(odometry)
    dx, dy, dth = odometry[..., 0], odometry[..., 1], odometry[..., 2]
    c, s = jnp.cos(dth), jnp.sin(dth)
    if odometry.ndim == 1:
        dx, dy, c, s = (jnp.broadcast_to(a, points.shape[:1]) for a in (dx, dy, c, s))
    qx = points[:, 0] - dx
    qy = points[:, 1] - dy
    return jnp.stack([c * qx + s * qy, -s * qx + c * qy], axis=-1)
