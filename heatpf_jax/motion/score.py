"""Score-form gradients of the motion noise: the transition density in the weights, not the positions.

A particle filter's motion noise parameters ``theta`` (diffusion, odometry noise, acceleration) reach a
loss in two ways. *Pathwise*: positions are ``x' = F(x, sigma(theta) * n)`` and ``d/dtheta`` flows
through every later position (the reparameterisation trick; what the plain motion models give). *Score
form*: positions are drawn with ``stop_gradient(sigma)``, and each particle's log weight gains

    log f(e | theta) - stop_gradient(log f(e | theta)),    log f = sum_j log N(e_j; 0, sigma_j(theta)^2)

for its scaled noise ``e = stop_gradient(sigma) * n``: zero in value (the forward pass is unchanged), the
score ``sum_j (n_j^2 - 1) d log sigma_j`` in gradient. With stop-gradient resampling
(:class:`heatpf_jax.resampling.gradients.StopGradientResampling`) the weights carry these scores along
each particle's ancestry, which is Fisher's identity, ``d log p(y) = E[sum_t d log f_t | y]``, estimated on
the particles' genealogy (Scibior and Wood 2021; Poyiadjis, Doucet and Singh 2011). The noise ``e`` is the
latent variable: the map ``F`` from noise to state does not depend on ``theta``, so the identity holds
for every Gaussian motion model written as ``transition(particles, e)``.
Gradients of other parameters (a spawn speed or a jitter that reach positions through injected
particles) stay pathwise.

Pathwise gradients of a long run multiply Jacobians over every step and pass through resampling's
discrete copies; the score form's variance grows only with the genealogy (see ``benchmarks/gradients.py``).

:class:`ScoreMotion` wraps any motion model with ``noise_std`` and ``transition`` methods
(:class:`~heatpf_jax.motion.random_walk.RandomWalk`, :class:`~heatpf_jax.motion.random_walk.DiffusionOnly`,
:class:`~heatpf_jax.motion.constant_velocity.ConstantVelocity`); models with non-Gaussian noise
(:class:`~heatpf_jax.motion.mass_inertia.MassInertia`) keep pathwise gradients.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, PRNGKeyArray

__all__ = ["ScoreMotion", "ScoredParticles", "gaussian_log_score", "transition_log_weight"]


class ScoredParticles(NamedTuple):
    """Particles of a :class:`ScoreMotion`: the wrapped model's particles and the score term of the last move.

    Attributes:
        state: the wrapped motion model's particles (``state.xy``: ``[N, 2]`` positions).
        log_transition: ``[N]`` ``log f - stop_gradient(log f)`` of each particle's last move: zero in
            value, the transition's score in gradient; the filter step adds it to the log weights.
    """

    state: Any
    log_transition: Float[Array, " n"]

    @property
    def xy(self) -> Float[Array, "n 2"]:
        return self.state.xy


def transition_log_weight(particles) -> Float[Array, " n"] | None:
    """The log-weight term a motion model left in its particles (``None`` for ordinary models)."""
    return getattr(particles, "log_transition", None)


def gaussian_log_score(noise: Float[Array, "n d"], std: Float[Array, "1 d"]) -> Float[Array, " n"]:
    """``sum_j log N(e_j; 0, std_j^2) - stop_gradient(...)`` per row (constants dropped).

    Components with ``std_j = 0`` (no odometry noise while standing) add nothing and have a zero,
    not a NaN, gradient (the double-``where`` idiom).

    Args:
        noise: ``[N, D]`` scaled noise ``e`` (no gradient).
        std: ``[1, D]`` or ``[N, D]`` standard deviations (differentiable).
    """
    positive = std > 0
    safe = jnp.where(positive, std, 1.0)
    log_f = jnp.where(positive, -0.5 * jnp.square(noise / safe) - jnp.log(safe), 0.0)
    log_f = jnp.sum(log_f, axis=-1)
    return log_f - lax.stop_gradient(log_f)


@dataclass(frozen=True)
class ScoreMotion:
    """A Gaussian motion model whose parameters get score-form gradients (see the module docstring).

    The positions are the wrapped model's ``predict`` itself (the same values for the same key, bit for
    bit); params and properties are the wrapped model's.

    Attributes:
        motion: a motion model with ``noise_std(particles, inputs, params) -> [1 or N, D]`` and
            ``transition(particles, noise, inputs, params)``, whose ``predict(key, ...)`` equals
            ``transition(particles, noise_std * jax.random.normal(key, (N, D)), ...)``.
    """

    motion: Any

    def validate(self) -> None:
        if not (hasattr(self.motion, "noise_std") and hasattr(self.motion, "transition")):
            raise ValueError(
                f"motion: the score form needs Gaussian motion noise (noise_std, transition); "
                f"{type(self.motion).__name__} has none, use pathwise gradients for it"
            )
        if hasattr(self.motion, "validate"):
            self.motion.validate()

    def default_params(self):
        return self.motion.default_params()

    def properties(self):
        return self.motion.properties()

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params) -> ScoredParticles:
        state = self.motion.spawn(key, xy, params)
        return ScoredParticles(state=state, log_transition=jnp.zeros(xy.shape[:1], xy.dtype))

    def predict(self, key: PRNGKeyArray, particles: ScoredParticles, inputs, params) -> ScoredParticles:
        state = particles.state
        # The positions are the wrapped model's own predict (bit for bit), with no gradient from the motion
        # noise parameters (other gradients, e.g. of a spawn speed through injected particles, stay pathwise);
        # the score uses the same normals, which a Gaussian model draws as jax.random.normal(key, (N, D)).
        moved = self.motion.predict(key, state, inputs, lax.stop_gradient(params))
        std = self.motion.noise_std(lax.stop_gradient(state), inputs, params)
        normal = jax.random.normal(key, (state.xy.shape[0], std.shape[-1]), state.xy.dtype)
        noise = lax.stop_gradient(std) * normal
        return ScoredParticles(state=moved, log_transition=gaussian_log_score(noise, std))

    def remember(self, particles: ScoredParticles, weights: Float[Array, " n"]) -> ScoredParticles:
        return particles._replace(state=self.motion.remember(particles.state, weights))
