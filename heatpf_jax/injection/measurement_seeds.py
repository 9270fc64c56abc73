"""Explorers at this step's measurements, drawn before the weighting when the cloud has lost the ball.

:class:`~heatpf_jax.injection.measurement_explorers.MeasurementExplorers` refills its slots after the resampling,
at the measurements of the step that has just been weighted; those particles are predicted and weighted one step
later, so a ball that reappears (after a long occlusion, out of view, beyond the detector's range) is in the
estimate one heat map after it is first seen at the earliest, and only as far as its first particles' weight
allows. Lenser and Veloso's sensor resetting draws the new hypotheses from the reading being incorporated.

:class:`ReacquisitionSeeds` keeps the fixed share after the resampling and adds, on a step where nothing lies within
the gate of the predicted cloud's mean on this heat map's measurements nor on the previous step's (``seed_gate_px``
of a measurement's pixels, at least ``seed_gate`` metres), the same share drawn at this step's measurements after the
prediction and before the weighting: the step that first shows a ball the cloud had lost weighs particles on it.
While the cloud has support nothing is seeded before the weighting, so a ball that is followed is filtered as with
``MeasurementExplorers`` and a false blob elsewhere is seeded no sooner. The previous heat map counts because a
single frame in which the detector misses the ball is common (a far, patchy blob): seeded then, the estimate would
jump to whatever else the frame shows and back on the next. The gate is in pixels because far away one pixel covers
a long strip of ground along the ray. Before the weighting no particle's support is known: the slots taken are drawn
at random.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, refill
from heatpf_jax.injection.measurement_explorers import MeasurementExplorers, sample_measurements
from heatpf_jax.measurements import Measurements
from heatpf_jax.observation.range_aware import _footprint_quadratic
from heatpf_jax.params import nonnegative, positive, unit_interval

__all__ = ["ReacquisitionParams", "ReacquisitionSeeds", "cloud_mean", "has_support"]


class ReacquisitionParams(NamedTuple):
    """Numbers of :class:`ReacquisitionSeeds`.

    Attributes:
        measurement_fraction: share of the particles drawn at measurements after each resampling, and before the
            weighting on a step where the cloud has no support.
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
        seed_gate: the gate's smallest radius on the ground, metres.
        seed_gate_px: the gate's radius in the measurement's own pixels (its footprint): far away, where a pixel
            covers a long strip of ground along the ray, the gate is that long.
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05
    seed_gate: float = 0.5
    seed_gate_px: float = 3.0


def cloud_mean(xy: Float[Array, "n 2"], log_weights: Float[Array, " n"]) -> Float[Array, "2"]:
    """The weighted mean of the particles (weights ``softmax(log_weights)``)."""
    w = jax.nn.softmax(log_weights)
    return jnp.sum(w[:, None] * xy, axis=0)


def has_support(
    measurements: Measurements, mean: Float[Array, "2"], gate: Float[Array, ""], gate_px: Float[Array, ""]
) -> Bool[Array, ""]:
    """Whether a valid measurement of positive weight lies within the gate of ``mean``: ``d_j^T G_j^{-1} d_j <= 1``
    with ``d_j = mean - m_j`` and ``G_j = gate_px^2 F_j F_j^T + gate^2 I`` (``F_j`` the measurement's footprint: the
    gate is ``gate_px`` of its pixels, at least ``gate`` metres; a measurement without a footprint gets ``gate``)."""
    every = jnp.arange(measurements.xy.shape[0])[None, :]
    q = _footprint_quadratic(mean[None, :], measurements, every, gate_px, gate)[0]  # the template's own quadratic
    return jnp.any(measurements.valid & (measurements.weight > 0) & (q <= 1.0))


@dataclass(frozen=True)
class ReacquisitionSeeds(MeasurementExplorers):
    """The fixed share of :class:`MeasurementExplorers` after each resampling, and as much again before the weighting
    on a step where the predicted cloud has no support on this heat map nor on the previous one (see the module)."""

    def default_params(self) -> ReacquisitionParams:
        return ReacquisitionParams()

    def properties(self) -> ReacquisitionParams:
        return ReacquisitionParams(
            measurement_fraction=unit_interval(high_closed=False, trainable=False),
            measurement_jitter=nonnegative(),
            seed_gate=positive(),
            seed_gate_px=nonnegative(),
        )

    def seed(self, key: PRNGKeyArray, context: InjectionContext, params: ReacquisitionParams) -> InjectionContext:
        """Before the weighting: the share at this step's measurements where the cloud's mean has none near it, now and
        on the previous heat map (``context.previous_measurements``, where known)."""
        buffer = context.measurements
        mean = cloud_mean(context.particles.xy, context.log_weights)
        mean = jax.lax.stop_gradient(mean)
        lost = ~has_support(buffer, mean, params.seed_gate, params.seed_gate_px)
        if context.previous_measurements is not None:  # lost on the previous heat map too: not a frame's dropout
            lost = lost & ~has_support(context.previous_measurements, mean, params.seed_gate, params.seed_gate_px)
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        k_slots, k_draw = jax.random.split(key)
        n = context.log_weights.shape[0]
        jitter = params.measurement_jitter

        def draw(carry):  # only on a step that seeds: the permutation and the draws cost a tenth of a step
            particles, log_weights, rank, used = carry
            ctx = context._replace(particles=particles, log_weights=log_weights, used=used,
                                   rank=jax.random.permutation(k_slots, n).astype(rank.dtype))
            out = refill(k_draw, ctx, params.measurement_fraction,
                         lambda k, m: sample_measurements(k, buffer, m, jitter))
            return out.particles, out.log_weights, out.rank, out.used

        carry = (context.particles, context.log_weights, context.rank, context.used)
        particles, log_weights, rank, used = jax.lax.cond(has & lost, draw, lambda c: c, carry)
        return context._replace(particles=particles, log_weights=log_weights, rank=rank, used=used)
