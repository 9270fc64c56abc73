"""Movement model (III-D): odometry with motion-scaled noise, and Gaussian diffusion.

Odometry ``(dx, dy, dtheta)`` is the robot's motion from step t-1 to t in the base
frame of t-1. A world-fixed point with base coordinates ``p`` at t-1 has
coordinates ``R(dtheta)^T (p - (dx, dy))`` at t. Noise is reparameterised
(``std * standard normal``) so gradients with respect to the noise parameters exist.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from heatpf_jax.frames import apply_odometry
from heatpf_jax.numerics import safe_sqrt
from heatpf_jax.params import nonnegative

__all__ = [
    "DiffusionOnly",
    "DiffusionParams",
    "Particles",
    "RandomWalk",
    "RandomWalkParams",
    "apply_odometry",
    "diffuse",
    "move_and_diffuse",
    "move_particles",
]


def move_particles(
    key: PRNGKeyArray,
    particles: Float[ArrayLike, "n 2"],
    odometry: Float[ArrayLike, "3"],
    trans_noise: Float[ArrayLike, ""],
    rot_noise: Float[ArrayLike, ""],
) -> Float[Array, "n 2"]:
    """Applies odometry to particles, each with its own noisy copy of the motion.

    Each particle sees ``dx + trans_noise * |d| * n1``, ``dy + trans_noise * |d| * n2``
    and ``dtheta + rot_noise * |dtheta| * n3`` with ``|d| = hypot(dx, dy)`` and
    ``n ~ N(0, 1)``: the noise scales with the motion, so a standing robot adds none.

    Args:
        key: PRNG key.
        particles: ``[n, 2]``.
        odometry: ``[3]`` ``(dx, dy, dtheta)``.
        trans_noise: translational noise, a fraction of the distance travelled.
        rot_noise: rotational noise, a fraction of the angle turned.

    Returns:
        ``[n, 2]`` moved particles.
    """
    particles = jnp.asarray(particles)
    odometry = jnp.asarray(odometry, particles.dtype)
    dist = safe_sqrt(odometry[0] ** 2 + odometry[1] ** 2)
    scale = jnp.stack([trans_noise * dist, trans_noise * dist, rot_noise * jnp.abs(odometry[2])])
    noise = jax.random.normal(key, (particles.shape[0], 3), particles.dtype)
    return apply_odometry(particles, odometry[None, :] + noise * scale[None, :])


def diffuse(key: PRNGKeyArray, particles: Float[ArrayLike, "n 2"], std: Float[ArrayLike, ""]) -> Float[Array, "n 2"]:
    """Adds isotropic Gaussian noise ``std * N(0, I)`` to every particle (III-D)."""
    particles = jnp.asarray(particles)
    return particles + std * jax.random.normal(key, particles.shape, particles.dtype)


def move_and_diffuse(
    key: PRNGKeyArray,
    particles: Float[ArrayLike, "n 2"],
    odometry: Float[ArrayLike, "3"],
    trans_noise: Float[ArrayLike, ""],
    rot_noise: Float[ArrayLike, ""],
    diffusion_std: Float[ArrayLike, ""],
) -> Float[Array, "n 2"]:
    """:func:`move_particles` followed by :func:`diffuse`, drawn with 3 normals per particle instead of 5.

    Both translational noises are isotropic Gaussians independent of the noisy angle
    ``theta' = dtheta + rot_noise * |dtheta| * n3``: rotating the odometry noise by
    ``R(theta')^T`` leaves it ``N(0, (trans_noise |d|)^2 I)``, so

        p' = R(theta')^T (p - (dx, dy)) + sqrt((trans_noise |d|)^2 + diffusion_std^2) * (n1, n2)

    has exactly the distribution of the two steps in sequence (III-D). The filter step
    uses this form: the noise draw is a large part of a step's cost on a CPU.

    Args:
        key: PRNG key.
        particles: ``[n, 2]``.
        odometry: ``[3]`` ``(dx, dy, dtheta)``.
        trans_noise: translational noise, a fraction of the distance travelled.
        rot_noise: rotational noise, a fraction of the angle turned.
        diffusion_std: Gaussian diffusion, metres.

    Returns:
        ``[n, 2]`` moved and diffused particles.
    """
    particles = jnp.asarray(particles)
    odometry = jnp.asarray(odometry, particles.dtype)
    sq = odometry[0] ** 2 + odometry[1] ** 2
    std = safe_sqrt(trans_noise * trans_noise * sq + diffusion_std * diffusion_std)
    noise = jax.random.normal(key, (particles.shape[0], 3), particles.dtype)
    theta = odometry[2] + rot_noise * jnp.abs(odometry[2]) * noise[:, 2]
    shift = jnp.broadcast_to(odometry[None, :2], (particles.shape[0], 2))
    moved = apply_odometry(particles, jnp.concatenate([shift, theta[:, None]], axis=1))
    return moved + std * noise[:, :2]


class Particles(NamedTuple):
    """Particles of a position-only motion model.

    Attributes:
        xy: ``float32 [N, 2]`` positions in the current base frame.
    """

    xy: Float[Array, "n 2"]


class RandomWalkParams(NamedTuple):
    """Numbers of :class:`RandomWalk`.

    Attributes:
        diffusion_std: Gaussian diffusion per filter step, metres (III-D).
        odom_trans_noise: odometry translation noise, a fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, a fraction of the angle turned.
    """

    diffusion_std: float = 0.2
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1


@dataclass(frozen=True)
class RandomWalk:
    """The paper's movement model (III-D): odometry with motion-scaled noise, then Gaussian diffusion.

    The particles carry positions only (:class:`Particles`); both noises come from one draw
    (:func:`move_and_diffuse`).
    """

    def default_params(self) -> RandomWalkParams:
        return RandomWalkParams()

    def properties(self) -> RandomWalkParams:
        return RandomWalkParams(nonnegative(), nonnegative(), nonnegative())

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: RandomWalkParams) -> Particles:
        del key, params
        return Particles(xy=xy)

    def predict(self, key: PRNGKeyArray, particles: Particles, inputs, params: RandomWalkParams) -> Particles:
        xy = move_and_diffuse(
            key, particles.xy, inputs.odometry, params.odom_trans_noise, params.odom_rot_noise, params.diffusion_std
        )
        return particles._replace(xy=xy)

    def remember(self, particles: Particles, weights: Float[Array, " n"]) -> Particles:
        del weights
        return particles

    # The Gaussian form of ``predict`` (:class:`heatpf_jax.motion.score.ScoreMotion`): ``predict`` draws
    # ``noise_std * N(0, I)`` and applies ``transition``; the two methods below are that split.

    def noise_std(self, particles: Particles, inputs, params: RandomWalkParams) -> Float[Array, "1 3"]:
        """Std of each noise component: translation x, y (odometry and diffusion together), rotation."""
        odometry = jnp.asarray(inputs.odometry, particles.xy.dtype)
        sq = odometry[0] ** 2 + odometry[1] ** 2
        std = safe_sqrt(params.odom_trans_noise * params.odom_trans_noise * sq + params.diffusion_std**2)
        return jnp.stack([std, std, params.odom_rot_noise * jnp.abs(odometry[2])])[None, :]

    def transition(self, particles: Particles, noise: Float[Array, "n 3"], inputs, params) -> Particles:
        """``R(dtheta + e_3)^T (p - d) + (e_1, e_2)`` for scaled noise ``e`` (:func:`move_and_diffuse`)."""
        del params
        odometry = jnp.asarray(inputs.odometry, particles.xy.dtype)
        n = particles.xy.shape[0]
        theta = odometry[2] + noise[:, 2]
        shift = jnp.broadcast_to(odometry[None, :2], (n, 2))
        moved = apply_odometry(particles.xy, jnp.concatenate([shift, theta[:, None]], axis=1))
        return particles._replace(xy=moved + noise[:, :2])


class DiffusionParams(NamedTuple):
    """Numbers of :class:`DiffusionOnly`.

    Attributes:
        diffusion_std: Gaussian diffusion per filter step, metres.
    """

    diffusion_std: float = 0.1


@dataclass(frozen=True)
class DiffusionOnly:
    """Gaussian diffusion without odometry: the particles stay where they were in the robot's frame.

    The original team's 2018 node moved nothing by odometry (:func:`heatpf_jax.presets.bitbots2018`).
    """

    def default_params(self) -> DiffusionParams:
        return DiffusionParams()

    def properties(self) -> DiffusionParams:
        return DiffusionParams(nonnegative())

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: DiffusionParams) -> Particles:
        del key, params
        return Particles(xy=xy)

    def predict(self, key: PRNGKeyArray, particles: Particles, inputs, params: DiffusionParams) -> Particles:
        del inputs
        return particles._replace(xy=diffuse(key, particles.xy, params.diffusion_std))

    def remember(self, particles: Particles, weights: Float[Array, " n"]) -> Particles:
        del weights
        return particles

    def noise_std(self, particles: Particles, inputs, params: DiffusionParams) -> Float[Array, "1 2"]:
        del inputs
        return jnp.broadcast_to(jnp.asarray(params.diffusion_std, particles.xy.dtype), (1, 2))

    def transition(self, particles: Particles, noise: Float[Array, "n 2"], inputs, params) -> Particles:
        del inputs, params
        return particles._replace(xy=particles.xy + noise)
