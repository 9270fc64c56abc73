"""The Kalman baseline: a constant-velocity Kalman filter on the conventional measurement.

What the original team ships today: one point per heat map (the centre of the
strongest image-space cluster, :mod:`heatpf_jax.clusters`) filtered by a
constant-velocity Kalman filter in the robot's base frame. Configured like the
heat-map filter (the same threshold, odometry noise and projection) and
differing only where the method does:

* state ``(x, y, vx, vy)`` with white-noise acceleration ``kalman_accel_std``
  (m/s^2) over the sequence's ``dt``;
* odometry moves the state into the new base frame (position ``R^T (p - d)``,
  velocity ``R^T v``) and adds the odometry noise of the particle filter to
  the position covariance, to first order;
* a measurement (when the heat map yields one) updates with isotropic noise
  ``kalman_meas_std`` (m); without one the filter only predicts.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

__all__ = ["KalmanState", "kalman_init", "kalman_odometry", "kalman_predict", "kalman_update"]

_H = jnp.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]], jnp.float32)


class KalmanState(NamedTuple):
    """Mean ``[4]`` = (x, y, vx, vy) and covariance ``[4, 4]``."""

    mean: Float[Array, "4"]
    cov: Float[Array, "4 4"]


def kalman_init(
    centre: Float[ArrayLike, "2"], position_std: Float[ArrayLike, ""], speed_std: float = 3.0
) -> KalmanState:
    """A broad prior: position ``N(centre, position_std^2 I)``, velocity ``N(0, speed_std^2 I)``."""
    centre = jnp.asarray(centre, jnp.float32)
    var = jnp.stack([position_std**2, position_std**2, jnp.float32(speed_std**2), jnp.float32(speed_std**2)])
    return KalmanState(mean=jnp.concatenate([centre, jnp.zeros((2,), jnp.float32)]), cov=jnp.diag(var))


def kalman_odometry(
    state: KalmanState,
    odometry: Float[ArrayLike, "3"],
    trans_noise: Float[ArrayLike, ""],
    rot_noise: Float[ArrayLike, ""],
) -> KalmanState:
    """Expresses the state in the base frame after ``odometry`` (dx, dy, dtheta), adding odometry noise."""
    odometry = jnp.asarray(odometry, jnp.float32)
    c, s = jnp.cos(odometry[2]), jnp.sin(odometry[2])
    rt = jnp.stack([jnp.stack([c, s]), jnp.stack([-s, c])])  # R(dtheta)^T
    zero = jnp.zeros((2, 2), jnp.float32)
    big = jnp.block([[rt, zero], [zero, rt]])
    pos = rt @ (state.mean[:2] - odometry[:2])
    vel = rt @ state.mean[2:]
    cov = big @ state.cov @ big.T
    sq = odometry[0] ** 2 + odometry[1] ** 2
    dist = jnp.where(sq > 0.0, jnp.sqrt(jnp.where(sq > 0.0, sq, 1.0)), 0.0)
    perp = jnp.stack([-pos[1], pos[0]])  # d position / d dtheta, to first order
    pos_noise = (trans_noise * dist) ** 2 * jnp.eye(2, dtype=jnp.float32) + (rot_noise * jnp.abs(odometry[2])) ** 2 * (
        perp[:, None] * perp[None, :]
    )
    cov = cov.at[:2, :2].add(pos_noise)
    return KalmanState(mean=jnp.concatenate([pos, vel]), cov=cov)


def kalman_predict(state: KalmanState, dt: Float[ArrayLike, ""], accel_std: Float[ArrayLike, ""]) -> KalmanState:
    """Constant-velocity prediction with white-noise acceleration."""
    eye = jnp.eye(2, dtype=jnp.float32)
    zero = jnp.zeros((2, 2), jnp.float32)
    f = jnp.block([[eye, dt * eye], [zero, eye]])
    q = accel_std**2 * jnp.block([[dt**4 / 4 * eye, dt**3 / 2 * eye], [dt**3 / 2 * eye, dt**2 * eye]])
    return KalmanState(mean=f @ state.mean, cov=f @ state.cov @ f.T + q)


def kalman_update(
    state: KalmanState, z: Float[ArrayLike, "2"], has_z: Bool[ArrayLike, ""], meas_std: Float[ArrayLike, ""]
) -> KalmanState:
    """Standard update with ``z = (x, y) + N(0, meas_std^2 I)``; a no-op when ``has_z`` is False.

    Uses the Joseph form so the covariance stays symmetric positive definite in float32.
    """
    z = jnp.asarray(z, jnp.float32)
    r = meas_std**2 * jnp.eye(2, dtype=jnp.float32)
    s = _H @ state.cov @ _H.T + r
    gain = jnp.linalg.solve(s, _H @ state.cov).T  # P H^T S^-1 (S symmetric)
    mean = state.mean + gain @ (z - _H @ state.mean)
    a = jnp.eye(4, dtype=jnp.float32) - gain @ _H
    cov = a @ state.cov @ a.T + gain @ r @ gain.T
    cov = 0.5 * (cov + cov.T)
    has_z = jnp.asarray(has_z)
    return KalmanState(mean=jnp.where(has_z, mean, state.mean), cov=jnp.where(has_z, cov, state.cov))
