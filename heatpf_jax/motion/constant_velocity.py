"""A velocity state for the particles: the constant-velocity (white-noise acceleration) motion model.

Particles carry ``(x, y, vx, vy)`` (:class:`VelocityParticles`). One step of length ``dt``:

* odometry moves every particle into the new base frame like a position-only particle (III-D:
  ``R(theta_i)^T (p - d)``, each particle with its own noisy copy of the motion), and turns its
  velocity with the same rotation, ``R(theta_i)^T v`` (a world-fixed velocity seen from a turned base);
* the ball moves: ``p += v dt + a dt^2 / 2``, ``v += a dt`` with ``a ~ N(0, accel_std^2 I)``, the
  discretised white-noise acceleration of the Kalman baseline, so both share one process model;
* positions diffuse by ``diffusion_std`` as in the paper (model mismatch, detector jitter).

All noise is reparameterised (``std * standard normal``), so gradients with respect to every std flow.
New particles (initial, explorers) get a velocity drawn from ``N(0, spawn_speed_std^2 I)``: a ball may
already be rolling when an explorer lands on it, and a spread of velocities lets resampling pick the
right one within a few steps; ``spawn_speed_std = 0`` starts them at rest.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.motion.random_walk import apply_odometry
from heatpf_jax.numerics import safe_sqrt
from heatpf_jax.params import nonnegative

__all__ = ["ConstantVelocity", "ConstantVelocityParams", "VelocityParticles", "move_with_odometry"]


class VelocityParticles(NamedTuple):
    """Particles with a velocity.

    Attributes:
        xy: ``float32 [N, 2]`` positions in the current base frame, metres.
        v: ``float32 [N, 2]`` velocities in the current base frame, m/s.
    """

    xy: Float[Array, "n 2"]
    v: Float[Array, "n 2"]


class ConstantVelocityParams(NamedTuple):
    """Numbers of :class:`ConstantVelocity`.

    Attributes:
        accel_std: white-noise acceleration, m/s^2 (the Kalman baseline's default, 3).
        diffusion_std: extra Gaussian position noise per step, metres.
        odom_trans_noise: odometry translation noise, a fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, a fraction of the angle turned.
        spawn_speed_std: std of each velocity component of new particles, m/s.
    """

    accel_std: float = 3.0
    diffusion_std: float = 0.05
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1
    spawn_speed_std: float = 1.0


@dataclass(frozen=True)
class ConstantVelocity:
    """Constant-velocity motion with white-noise acceleration (see the module docstring)."""

    def default_params(self) -> ConstantVelocityParams:
        return ConstantVelocityParams()

    def properties(self) -> ConstantVelocityParams:
        return ConstantVelocityParams(*(nonnegative() for _ in ConstantVelocityParams._fields))

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: ConstantVelocityParams) -> VelocityParticles:
        v = params.spawn_speed_std * jax.random.normal(key, xy.shape, xy.dtype)
        return VelocityParticles(xy=xy, v=v)

    def predict(
        self, key: PRNGKeyArray, particles: VelocityParticles, inputs, params: ConstantVelocityParams
    ) -> VelocityParticles:
        xy, v = particles.xy, particles.v
        n = xy.shape[0]
        dt = jnp.asarray(inputs.dt, xy.dtype)
        noise = jax.random.normal(key, (n, 7), xy.dtype)
        xy, v = move_with_odometry(xy, v, inputs.odometry, noise[:, :3], params.odom_trans_noise, params.odom_rot_noise)
        # The ball's own motion over dt, and the position diffusion.
        accel = params.accel_std * noise[:, 3:5]
        xy = xy + v * dt + 0.5 * accel * dt * dt + params.diffusion_std * noise[:, 5:7]
        v = v + accel * dt
        return VelocityParticles(xy=xy, v=v)

    def remember(self, particles: VelocityParticles, weights: Float[Array, " n"]) -> VelocityParticles:
        del weights
        return particles

    # The Gaussian form of ``predict`` (:class:`heatpf_jax.motion.score.ScoreMotion`): ``predict`` draws
    # ``noise_std * N(0, I)`` and applies ``transition``; the two methods below are that split.

    def noise_std(self, particles: VelocityParticles, inputs, params: ConstantVelocityParams) -> Float[Array, "1 7"]:
        """Std of each noise component: odometry translation x, y and rotation, acceleration x, y, diffusion x, y."""
        odometry = jnp.asarray(inputs.odometry, particles.xy.dtype)
        dist = safe_sqrt(odometry[0] ** 2 + odometry[1] ** 2)
        trans = params.odom_trans_noise * dist
        accel = jnp.asarray(params.accel_std, particles.xy.dtype)
        diff = jnp.asarray(params.diffusion_std, particles.xy.dtype)
        rot = params.odom_rot_noise * jnp.abs(odometry[2])
        return jnp.stack([trans, trans, rot, accel, accel, diff, diff])[None, :]

    def transition(
        self, particles: VelocityParticles, noise: Float[Array, "n 7"], inputs, params
    ) -> VelocityParticles:
        """``predict`` for scaled noise ``e`` (``e = noise_std * N(0, I)``)."""
        del params
        xy, v = particles.xy, particles.v
        dt = jnp.asarray(inputs.dt, xy.dtype)
        odometry = jnp.asarray(inputs.odometry, xy.dtype)
        shift = odometry[None, :2] + noise[:, :2]
        theta = odometry[2] + noise[:, 2]
        xy = apply_odometry(xy, jnp.concatenate([shift, theta[:, None]], axis=1))
        c, s = jnp.cos(theta), jnp.sin(theta)
        v = jnp.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=-1)
        accel = noise[:, 3:5]
        xy = xy + v * dt + 0.5 * accel * dt * dt + noise[:, 5:7]
        return VelocityParticles(xy=xy, v=v + accel * dt)


def move_with_odometry(
    xy: Float[Array, "n 2"],
    v: Float[Array, "n 2"],
    odometry: Float[Array, "3"],
    noise: Float[Array, "n 3"],
    trans_noise: Float[Array, ""],
    rot_noise: Float[Array, ""],
) -> tuple[Float[Array, "n 2"], Float[Array, "n 2"]]:
    """Moves positions and velocities into the new base frame, each particle with its own noisy odometry.

    Positions: ``R(theta_i)^T (p - d_i)`` (III-D); velocities: ``R(theta_i)^T v`` (a world-fixed velocity
    seen from the turned base). Translation noise scales with the distance moved, rotation noise with
    the angle turned (as :func:`heatpf_jax.motion.random_walk.move_particles`).

    Args:
        xy: positions. v: velocities. odometry: ``(dx, dy, dtheta)``.
        noise: standard normal draws, one row per particle (translation x, y; rotation).
        trans_noise: fraction of the distance moved.
        rot_noise: fraction of the angle turned.
    """
    odometry = jnp.asarray(odometry, xy.dtype)
    dist = safe_sqrt(odometry[0] ** 2 + odometry[1] ** 2)
    shift = odometry[None, :2] + trans_noise * dist * noise[:, :2]
    theta = odometry[2] + rot_noise * jnp.abs(odometry[2]) * noise[:, 2]
    xy = apply_odometry(xy, jnp.concatenate([shift, theta[:, None]], axis=1))
    c, s = jnp.cos(theta), jnp.sin(theta)
    v = jnp.stack([c * v[:, 0] + s * v[:, 1], -s * v[:, 0] + c * v[:, 1]], axis=-1)
    return xy, v
