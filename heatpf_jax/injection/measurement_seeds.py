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

Nothing is seeded while the predicted cloud lies mostly (half its weight or more) outside what the camera sees
(behind it or beyond the heat map's edges, :func:`in_view`) and knows where the ball is (its robust spread,
:func:`robust_spread`, within ``seed_spread``): a ball the cloud places out of view is not expected on the heat map,
its absence says nothing, and a blob elsewhere is no more likely the ball than before (a goal post, a line, a false
positive while the ball has rolled out of the image). A cloud that knows little (the uniform start, a ball lost for
long) lies mostly out of view too, only because the camera sees a small part of the field: it is seeded. The fixed
share after the resampling is drawn as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from heatpf_jax.camera import project_points
from heatpf_jax.injection.explorers import InjectionContext, refill
from heatpf_jax.injection.measurement_explorers import MeasurementExplorers, sample_measurements
from heatpf_jax.measurements import Measurements
from heatpf_jax.observation.range_aware import _footprint_quadratic
from heatpf_jax.params import nonnegative, positive, unit_interval
from heatpf_jax.pieces import StepInputs

__all__ = ["ReacquisitionParams", "ReacquisitionSeeds", "cloud_mean", "has_support", "in_view", "robust_spread"]


class ReacquisitionParams(NamedTuple):
    """Numbers of :class:`ReacquisitionSeeds`.

    Attributes:
        measurement_fraction: share of the particles drawn at measurements after each resampling, and before the
            weighting on a step where the cloud has no support.
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
        seed_gate: the gate's smallest radius on the ground, metres.
        seed_gate_px: the gate's radius in the measurement's own pixels (its footprint): far away, where a pixel
            covers a long strip of ground along the ray, the gate is that long.
        seed_spread: a cloud whose robust spread (:func:`robust_spread`) is wider than this, metres, knows too little
            of where the ball is for its place out of view to matter: it is seeded wherever it lies.
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05
    seed_gate: float = 0.5
    seed_gate_px: float = 3.0
    seed_spread: float = 1.0


def cloud_mean(xy: Float[Array, "n 2"], log_weights: Float[Array, " n"]) -> Float[Array, "2"]:
    """The weighted mean of the particles (weights ``softmax(log_weights)``)."""
    w = jax.nn.softmax(log_weights)
    return jnp.sum(w[:, None] * xy, axis=0)


def robust_spread(xy: Float[Array, "n 2"]) -> Float[Array, ""]:
    """The particles' spread, robust to the few explorers among them: the root of the sum over both axes of the
    squared median absolute deviation from the median, scaled by 1.4826 (a Gaussian's std)."""
    mad = jnp.median(jnp.abs(xy - jnp.median(xy, axis=0, keepdims=True)), axis=0)
    return 1.4826 * jnp.sqrt(jnp.sum(mad * mad))


def has_support(
    measurements: Measurements, mean: Float[Array, "2"], gate: Float[Array, ""], gate_px: Float[Array, ""]
) -> Bool[Array, ""]:
    """Whether a valid measurement of positive weight lies within the gate of ``mean``: ``d_j^T G_j^{-1} d_j <= 1``
    with ``d_j = mean - m_j`` and ``G_j = gate_px^2 F_j F_j^T + gate^2 I`` (``F_j`` the measurement's footprint: the
    gate is ``gate_px`` of its pixels, at least ``gate`` metres; a measurement without a footprint gets ``gate``)."""
    every = jnp.arange(measurements.xy.shape[0])[None, :]
    q = _footprint_quadratic(mean[None, :], measurements, every, gate_px, gate)[0]  # the template's own quadratic
    return jnp.any(measurements.valid & (measurements.weight > 0) & (q <= 1.0))


def in_view(xy: Float[Array, "n 2"], inputs: StepInputs) -> Bool[Array, " n"]:
    """Whether a ball at each ``xy`` (its centre on the plane ``z = inputs.plane_height``) is in front of the camera and
    projects onto the heat map: ``depth > 0`` and pixel coordinates within ``[-0.5, W - 0.5] x [-0.5, H - 0.5]``
    (pixel centres at integer coordinates, as :func:`~heatpf_jax.camera.project_pixel` reads them)."""
    height = jnp.broadcast_to(jnp.asarray(inputs.plane_height, xy.dtype), xy.shape[:1])
    uv, depth = project_points(jnp.concatenate([xy, height[:, None]], axis=1), inputs.intrinsics, inputs.cam_to_base)
    h, w = inputs.heatmap.shape[-2:]
    u, v = uv[:, 0], uv[:, 1]
    return (depth > 0.0) & (u >= -0.5) & (u <= w - 0.5) & (v >= -0.5) & (v <= h - 0.5)


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
            seed_spread=positive(),
        )

    def seed(self, key: PRNGKeyArray, context: InjectionContext, params: ReacquisitionParams) -> InjectionContext:
        """Before the weighting: the share at this step's measurements where the cloud's mean has none near it, now and
        on the previous heat map (``context.previous_measurements``, where known), and the camera sees at least half of
        the cloud's weight (:func:`in_view` of ``context.inputs``, where known)."""
        buffer = context.measurements
        mean = cloud_mean(context.particles.xy, context.log_weights)
        mean = jax.lax.stop_gradient(mean)
        lost = ~has_support(buffer, mean, params.seed_gate, params.seed_gate_px)
        if context.previous_measurements is not None:  # lost on the previous heat map too: not a frame's dropout
            lost = lost & ~has_support(context.previous_measurements, mean, params.seed_gate, params.seed_gate_px)
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        if context.inputs is not None:
            # Only where the camera sees at least half of the cloud the ball is expected, or where the cloud is too
            # wide to predict anything; tested only on a step without support (the medians cost a sort).
            inputs, xy, log_weights = context.inputs, context.particles.xy, context.log_weights

            def expected(_):
                seen = jnp.sum(jnp.where(in_view(xy, inputs), jax.nn.softmax(log_weights), 0.0))
                return jax.lax.stop_gradient((seen >= 0.5) | (robust_spread(xy) > params.seed_spread))

            lost = jax.lax.cond(has & lost, expected, lambda _: jnp.zeros((), bool), None)
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
