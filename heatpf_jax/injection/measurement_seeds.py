"""Explorers at this step's measurements, drawn before the weighting when the cloud has lost the ball.

:class:`~heatpf_jax.injection.measurement_explorers.MeasurementExplorers` refills its slots after the resampling,
at the measurements of the step that has just been weighted; those particles are predicted and weighted one step
later, so a ball that reappears (after a long occlusion, out of view, beyond the detector's range) is in the
estimate one heat map after it is first seen at the earliest, and only as far as its first particles' weight
allows. Lenser and Veloso's sensor resetting draws the new hypotheses from the reading being incorporated.

:class:`ReacquisitionSeeds` keeps the fixed share after the resampling and adds, on a step whose measurements hold
nothing within ``seed_gate`` of the predicted cloud's mean (the cloud has no support in this heat map: the ball it
followed is not where it predicts, or it never had one), the same share drawn at this step's measurements after the
prediction and before the weighting, so that the step that first shows the ball weighs particles on it. While the
cloud has support nothing is seeded before the weighting, so a ball that is followed is filtered as with
``MeasurementExplorers``, and a false blob elsewhere is seeded no sooner. Before the weighting no particle's support
is known: the slots taken are drawn at random.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, refill
from heatpf_jax.injection.measurement_explorers import MeasurementExplorers, sample_measurements
from heatpf_jax.injection.support_drop import support_at
from heatpf_jax.params import nonnegative, positive, unit_interval

__all__ = ["ReacquisitionParams", "ReacquisitionSeeds", "cloud_mean"]


class ReacquisitionParams(NamedTuple):
    """Numbers of :class:`ReacquisitionSeeds`.

    Attributes:
        measurement_fraction: share of the particles drawn at measurements after each resampling, and before the
            weighting on a step where the cloud has no support.
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
        seed_gate: the cloud has support when a valid measurement lies within this distance of its mean, metres.
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05
    seed_gate: float = 0.5


def cloud_mean(xy: Float[Array, "n 2"], log_weights: Float[Array, " n"]) -> Float[Array, "2"]:
    """The weighted mean of the particles (weights ``softmax(log_weights)``)."""
    w = jax.nn.softmax(log_weights)
    return jnp.sum(w[:, None] * xy, axis=0)


@dataclass(frozen=True)
class ReacquisitionSeeds(MeasurementExplorers):
    """The fixed share of :class:`MeasurementExplorers` after each resampling, and as much again before the weighting
    on a step where the predicted cloud has no support (see the module)."""

    def default_params(self) -> ReacquisitionParams:
        return ReacquisitionParams()

    def properties(self) -> ReacquisitionParams:
        return ReacquisitionParams(
            measurement_fraction=unit_interval(high_closed=False, trainable=False),
            measurement_jitter=nonnegative(),
            seed_gate=positive(),
        )

    def seed(self, key: PRNGKeyArray, context: InjectionContext, params: ReacquisitionParams) -> InjectionContext:
        """Before the weighting: the share at this step's measurements where the cloud's mean has none near it."""
        buffer = context.measurements
        mean = cloud_mean(context.particles.xy, context.log_weights)
        lost = support_at(buffer, jax.lax.stop_gradient(mean), params.seed_gate) <= 0.0
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        fraction = jnp.where(has & lost, params.measurement_fraction, 0.0)
        k_slots, k_draw = jax.random.split(key)
        n = context.log_weights.shape[0]
        context = context._replace(rank=jax.random.permutation(k_slots, n).astype(context.rank.dtype))
        jitter = params.measurement_jitter
        return refill(k_draw, context, fraction, lambda k, m: sample_measurements(k, buffer, m, jitter))
