"""A motion model for a real ball: it rolls with friction and stops, and is kicked now and then.

A ball on grass does not keep its velocity (constant velocity) nor wander (a random walk): it rolls,
decelerating by the rolling friction until it stops, and its velocity jumps when it is kicked or bounces
off a robot or a post. Particles carry ``(x, y, vx, vy)`` 
(:class:`~heatpf_jax.motion.constant_velocity.VelocityParticles`,
as :class:`~heatpf_jax.motion.constant_velocity.ConstantVelocity`). One step of length ``dt``:

* odometry moves every particle and turns its velocity, each with its own noisy copy of the motion
  (:func:`~heatpf_jax.motion.constant_velocity.move_with_odometry`, III-D);
* **rolling friction**: the speed ``s`` falls by ``friction * dt`` and stops at zero; the position advances
  by the exact distance of that deceleration, ``s dt - friction dt^2 / 2`` while it rolls, ``s^2 / (2 friction)``
  when it stops within the step (a constant deceleration ``friction``, m/s^2, along the velocity);
* **kicks**: a share ``1 - exp(-kick_rate dt)`` of the particles (a Poisson process of rate ``kick_rate`` per
  second, drawn per particle) receives a velocity impulse ``N(0, kick_speed_std^2 I)``: a jump process in the
  prior, so some particles are always ready for a kick, a bounce or a stop by a robot's foot;
* small white-noise acceleration ``accel_std`` (a ball is not a point on a plane) and the paper's position
  diffusion ``diffusion_std``.

All Gaussian noise is reparameterised, so gradients with respect to the stds and the friction flow; which
particles are kicked is a Bernoulli draw (``kick_rate`` is frozen: sweep it). New particles (initial,
explorers) get a velocity ``N(0, spawn_speed_std^2 I)``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.motion.constant_velocity import VelocityParticles, move_with_odometry
from heatpf_jax.numerics import safe_sqrt
from heatpf_jax.params import nonnegative

__all__ = ["RollingBall", "RollingBallParams", "roll"]


class RollingBallParams(NamedTuple):
    """Numbers of :class:`RollingBall`.

    Attributes:
        friction: rolling deceleration, m/s^2 (a size-1 ball on artificial turf: about 0.3-1.2).
        kick_rate: kicks per second per particle (the jump process's rate).
        kick_speed_std: std of each component of a kick's velocity impulse, m/s.
        accel_std: white-noise acceleration, m/s^2.
        diffusion_std: extra Gaussian position noise per step, metres.
        odom_trans_noise: odometry translation noise, a fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, a fraction of the angle turned.
        spawn_speed_std: std of each velocity component of new particles, m/s.
    """

    friction: float = 0.6
    kick_rate: float = 0.5
    kick_speed_std: float = 1.5
    accel_std: float = 1.0
    diffusion_std: float = 0.02
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1
    spawn_speed_std: float = 1.0


def roll(
    xy: Float[Array, "n 2"], v: Float[Array, "n 2"], friction: Float[Array, ""], dt: Float[Array, ""]
) -> tuple[Float[Array, "n 2"], Float[Array, "n 2"]]:
    """Rolls each ball for ``dt`` seconds under a constant deceleration ``friction`` along its velocity.

    Returns:
        ``(xy, v)`` after the step: the speed ``max(s - friction dt, 0)`` in the same direction, the position
        moved by ``s t - friction t^2 / 2`` with ``t = min(dt, s / friction)`` (the time it still rolls).
    """
    speed = safe_sqrt(jnp.sum(v * v, axis=-1))
    moving = speed > 0.0
    direction = v / jnp.where(moving, speed, 1.0)[:, None]
    friction = jnp.maximum(friction, 0.0)
    # The time it keeps rolling within the step; a friction of 0 rolls the whole step.
    rolling = jnp.where(friction > 0.0, jnp.minimum(dt, speed / jnp.where(friction > 0.0, friction, 1.0)), dt)
    distance = speed * rolling - 0.5 * friction * rolling * rolling
    new_speed = jnp.maximum(speed - friction * dt, 0.0)
    return xy + direction * distance[:, None], direction * new_speed[:, None]


@dataclass(frozen=True)
class RollingBall:
    """A ball that rolls with friction, stops, and is kicked (see the module docstring)."""

    def default_params(self) -> RollingBallParams:
        return RollingBallParams()

    def properties(self) -> RollingBallParams:
        fields = {name: nonnegative() for name in RollingBallParams._fields}
        fields["kick_rate"] = nonnegative(trainable=False)  # acts through a Bernoulli draw: sweep it
        return RollingBallParams(**fields)

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: RollingBallParams) -> VelocityParticles:
        v = params.spawn_speed_std * jax.random.normal(key, xy.shape, xy.dtype)
        return VelocityParticles(xy=xy, v=v)

    def predict(
        self, key: PRNGKeyArray, particles: VelocityParticles, inputs, params: RollingBallParams
    ) -> VelocityParticles:
        xy, v = particles.xy, particles.v
        n = xy.shape[0]
        dt = jnp.asarray(inputs.dt, xy.dtype)
        k_noise, k_kick = jax.random.split(key)
        noise = jax.random.normal(k_noise, (n, 9), xy.dtype)
        xy, v = move_with_odometry(xy, v, inputs.odometry, noise[:, :3], params.odom_trans_noise, params.odom_rot_noise)
        xy, v = roll(xy, v, jnp.asarray(params.friction, xy.dtype), dt)
        kicked = jax.random.uniform(k_kick, (n,), xy.dtype) < -jnp.expm1(-params.kick_rate * dt)
        v = v + jnp.where(kicked[:, None], params.kick_speed_std * noise[:, 3:5], 0.0)
        accel = params.accel_std * noise[:, 5:7]
        xy = xy + 0.5 * accel * dt * dt + params.diffusion_std * noise[:, 7:9]
        return VelocityParticles(xy=xy, v=v + accel * dt)

    def remember(self, particles: VelocityParticles, weights: Float[Array, " n"]) -> VelocityParticles:
        del weights
        return particles
