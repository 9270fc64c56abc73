"""Olufs et al.'s mass-inertia motion model (sec. 3.3, eq. 4-6): a velocity whose spread follows the weight.

Particles carry ``(x, y, vx, vy)`` and ``score``, their normalised weight ``pi'`` in ``[0, 1]`` from the
last update (the weight divided by the largest weight; it travels with the particle through resampling,
see :meth:`MassInertia.remember`). One step of length ``dt``, after the odometry (as
:class:`~heatpf_jax.motion.constant_velocity.ConstantVelocity`: positions and velocities turned into the new base
frame)::

    p <- p + v dt + (1.1 - pi') rho_position U2 + noise U2                  (eq. 5, 6)
    v <- v + (1.1 - pi') (rho_move / dt) U2                                 (eq. 6)

with ``U2`` independent uniform draws on ``[-1, 1]^2`` (the paper's ``RND()``). ``rho_move`` is the
expected maximum change of the motion per step in metres, so a particle with a poor weight tries
velocities up to ``rho_move / dt`` away from its own while the best particles keep theirs ("a 'good'
proposal will generate more but concentrated particles, while a 'bad' proposal will generate fewer but
highly varied particles"); ``1.1`` instead of ``1`` keeps a little spread even for the best particle.
The paper's eq. 6 spreads only the velocity (its position rows advance by the velocity alone); the
issue's reading adds a position spread, here ``rho_position`` (0 gives the paper's row exactly).

All noise is reparameterised (``scale * U``), so gradients with respect to every ``rho`` flow. New
particles (initial, explorers, random particles) start at rest with ``score = 0`` as the paper sets
"initially all parameters to zero": their first prediction has the widest velocity spread, so the
weight picks the right velocity within a few steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.motion.constant_velocity import move_with_odometry
from heatpf_jax.params import nonnegative, positive

__all__ = ["InertiaParticles", "MassInertia", "MassInertiaParams", "normalised_score"]

HEADROOM = 1.1  # the paper's "1.1 instead of 1.0" (eq. 6)


class InertiaParticles(NamedTuple):
    """Particles of the mass-inertia model.

    Attributes:
        xy: ``float32 [N, 2]`` positions in the current base frame, metres.
        v: ``float32 [N, 2]`` velocities in the current base frame, m/s.
        score: ``float32 [N]`` normalised weight ``pi'`` in ``[0, 1]`` from the last update.
    """

    xy: Float[Array, "n 2"]
    v: Float[Array, "n 2"]
    score: Float[Array, " n"]


class MassInertiaParams(NamedTuple):
    """Numbers of :class:`MassInertia`.

    Attributes:
        rho_move: expected maximum change of the motion per step, metres (velocity spread
            ``rho_move / dt`` m/s at ``pi' = 0.1``... ``1.1 rho_move / dt`` at ``pi' = 0``).
        rho_position: position spread per step at ``pi' = 0.1`` (times ``1.1 - pi'``), metres.
        noise: half-width of the uniform position noise ``Delta_Noise``, metres.
        odom_trans_noise: odometry translation noise, a fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, a fraction of the angle turned.

    The defaults were chosen on simulated seeds 100-103 (standard, shot, sparse_rate, occlusion; with a
    Gaussian observation kernel), disjoint from the seeds ``heatpf eval`` reports.
    """

    rho_move: float = 0.3
    rho_position: float = 0.05
    noise: float = 0.05
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1


def normalised_score(weights: Float[Array, " n"]) -> Float[Array, " n"]:
    """``pi' = w / max w`` in ``[0, 1]`` (uniform weights give 1; all-zero weights give 0)."""
    top = jnp.max(weights)
    return jnp.where(top > 0, weights / jnp.where(top > 0, top, 1.0), 0.0)


@dataclass(frozen=True)
class MassInertia:
    """Olufs et al.'s mass-inertia motion with weight-dependent spread (see the module docstring)."""

    def default_params(self) -> MassInertiaParams:
        return MassInertiaParams()

    def properties(self) -> MassInertiaParams:
        return MassInertiaParams(positive(), nonnegative(), nonnegative(), nonnegative(), nonnegative())

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: MassInertiaParams) -> InertiaParticles:
        del key, params
        return InertiaParticles(xy=xy, v=jnp.zeros_like(xy), score=jnp.zeros(xy.shape[:1], xy.dtype))

    def predict(
        self, key: PRNGKeyArray, particles: InertiaParticles, inputs, params: MassInertiaParams
    ) -> InertiaParticles:
        xy, v, score = particles
        n = xy.shape[0]
        dt = jnp.asarray(inputs.dt, xy.dtype)
        k_odom, k_spread = jax.random.split(key)
        odom_noise = jax.random.normal(k_odom, (n, 3), xy.dtype)
        xy, v = move_with_odometry(xy, v, inputs.odometry, odom_noise, params.odom_trans_noise, params.odom_rot_noise)
        u = jax.random.uniform(k_spread, (n, 6), xy.dtype, minval=-1.0, maxval=1.0)
        spread = (HEADROOM - jnp.clip(score, 0.0, 1.0))[:, None]
        xy = xy + v * dt + spread * params.rho_position * u[:, 0:2] + params.noise * u[:, 2:4]
        v = v + spread * (params.rho_move / dt) * u[:, 4:6]
        return InertiaParticles(xy=xy, v=v, score=score)

    def remember(self, particles: InertiaParticles, weights: Float[Array, " n"]) -> InertiaParticles:
        """Stores each particle's ``pi'`` before resampling, so that its copies inherit it."""
        return particles._replace(score=normalised_score(weights).astype(particles.score.dtype))
