"""Step 1 of the long-term memory (Olufs et al. 3.4): every track's rolling prediction.

Each track is a Kalman filter over ``(x, y, vx, vy)``: :func:`predict_tracks` rolls it by ``dt`` with friction,
grows its covariance by white-noise acceleration and applies the robot's motion (:mod:`heatpf_jax.motion.ego`).
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Float

from heatpf_jax.memory.table import TrackTable
from heatpf_jax.motion.random_walk import apply_odometry

__all__ = ["predict_tracks"]


def _cv_matrices(dt, accel_std):
    f = jnp.eye(4, dtype=jnp.float32).at[0, 2].set(dt).at[1, 3].set(dt)
    g = jnp.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]], jnp.float32) * jnp.array(
        [[dt * dt], [dt * dt], [dt], [dt]], jnp.float32
    )
    q = accel_std**2 * (g @ g.T)
    return f, q


def _rotation(theta):
    c, s = jnp.cos(theta), jnp.sin(theta)
    return jnp.array([[c, s], [-s, c]], jnp.float32)  # R(theta)^T: the previous frame's vectors in the new one


def _roll(mean: Float[Array, "m 4"], dt, friction) -> Float[Array, "m 4"]:
    """Rolls every track by ``dt`` with a constant deceleration ``friction`` along its velocity until it stops:
    the speed ``s`` becomes ``max(s - friction dt, 0)`` and the position advances ``s tau - friction tau^2 / 2``
    along the velocity, ``tau = min(dt, s / friction)`` (``friction = 0``: constant velocity)."""
    vel = mean[:, 2:]
    speed = jnp.sqrt(jnp.sum(vel**2, axis=1) + 1e-20)
    unit = vel / speed[:, None]
    tau = jnp.where(friction > 0, jnp.minimum(dt, speed / jnp.maximum(friction, 1e-12)), dt)
    step = speed * tau - 0.5 * friction * tau**2
    new_speed = jnp.maximum(speed - friction * dt, 0.0)
    return jnp.concatenate([mean[:, :2] + unit * step[:, None], unit * new_speed[:, None]], axis=1)


def predict_tracks(
    tracks: TrackTable, dt, ego: Float[Array, "3"], accel_std, friction=0.0, lost_accel_std=None
) -> TrackTable:
    """Rolling prediction by ``dt`` (:func:`_roll`; constant velocity without ``friction``), the covariance
    by the constant-velocity Jacobian plus white-noise acceleration (``accel_std``; ``lost_accel_std`` for the
    tracks unobserved last step, ``age > 0``, where given), then the ego-motion (positions moved, vectors turned).
    """
    f, q = _cv_matrices(dt, accel_std)
    mean = _roll(tracks.mean, dt, friction)
    if lost_accel_std is not None:
        unseen = (tracks.age > 0)[:, None, None]
        q = jnp.where(unseen, (lost_accel_std / accel_std) ** 2 * q[None], q[None])
    else:
        q = q[None]
    cov = jnp.einsum("ij,mjk,lk->mil", f, tracks.cov, f) + q
    r = _rotation(ego[2])
    j = jnp.zeros((4, 4), jnp.float32).at[:2, :2].set(r).at[2:, 2:].set(r)
    xy = apply_odometry(mean[:, :2], ego)
    vel = mean[:, 2:] @ r.T
    cov = jnp.einsum("ij,mjk,lk->mil", j, cov, j)
    return tracks._replace(mean=jnp.concatenate([xy, vel], axis=1), cov=cov)
