"""Explorers at the measurements with their importance weight: a new hypothesis weighs as much as its prior allows.

:class:`~heatpf_jax.injection.measurement_explorers.MeasurementExplorers` gives every particle it draws at the
measurements the weight ``1 / N`` of the resampled ones, as if the ball were as likely to be at any bright blob as
where the motion model predicts it; a false blob brighter than the ball then wins within a step. Drawn from the
measurements, a new particle at ``x`` is a draw from the proposal

    q(x) = sum_j (w_j / W) N(x; m_j, jitter^2 I)        (the buffer's weights w_j, their sum W),

and the particles together are a draw from the mixture ``(1 - f) p_cloud(x) + f q(x)``, ``f`` the share drawn so.
The prior of where the ball is, after the motion model, is the cloud's own density plus a small chance ``birth_rate``
that the ball is anywhere in an area ``area`` (a ball the filter lost, or never had):

    p(x) = (1 - birth_rate) p_cloud(x) + birth_rate / area,

so a particle drawn at the measurements takes the importance weight ``p(x) / ((1 - f) p_cloud(x) + f q(x))``
(relative to the resampled particles' ``1 / N``). :class:`BirthWeightedExplorers` draws as
``MeasurementExplorers`` does and gives each new particle that weight, with ``p_cloud`` the Gaussian of the
estimate's mean and covariance (widened by the jitter). A seed on the ball, inside the cloud, weighs about as much
as the others; a seed at a blob far from the cloud starts ``birth_rate / (area f q(x))`` as heavy and must win
that back through the heat map over steps, unless the cloud has nothing, where any evidence outweighs it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, explorer_count, replace_slots, take_slots
from heatpf_jax.injection.measurement_explorers import sample_measurements
from heatpf_jax.measurements import Measurements
from heatpf_jax.params import nonnegative, positive, unit_interval

__all__ = ["BirthParams", "BirthWeightedExplorers", "birth_log_weight"]


class BirthParams(NamedTuple):
    """Numbers of :class:`BirthWeightedExplorers`.

    Attributes:
        measurement_fraction: share of the particles drawn at measurements each step (``f``).
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
        birth_rate: the prior probability per step that the ball is anywhere in ``area`` rather than where the cloud
            predicts it.
        area: the area the ball may be anywhere in, square metres (the spawn box's 7 m x 8 m by default).
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05
    birth_rate: float = 0.01
    area: float = 56.0


def _gaussian_log_density(xy: Float[Array, "n 2"], mean: Float[Array, "2"], cov: Float[Array, "2 2"]):
    d = xy - mean[None, :]
    det = cov[0, 0] * cov[1, 1] - cov[0, 1] * cov[1, 0]
    q = (cov[1, 1] * d[:, 0] ** 2 - 2.0 * cov[0, 1] * d[:, 0] * d[:, 1] + cov[0, 0] * d[:, 1] ** 2) / det
    return -0.5 * q - 0.5 * jnp.log(det) - math.log(2.0 * math.pi)


def birth_log_weight(
    xy: Float[Array, "n 2"],
    measurements: Measurements,
    mean: Float[Array, "2"],
    cov: Float[Array, "2 2"],
    params: BirthParams,
) -> Float[Array, " n"]:
    """``log p(x) - log((1 - f) p_cloud(x) + f q(x))`` at each of ``xy`` (see the module), ``p_cloud`` the Gaussian
    ``N(mean, cov + jitter^2 I)``."""
    jitter2 = jnp.square(jnp.maximum(params.measurement_jitter, 1e-3))
    log_cloud = _gaussian_log_density(xy, mean, cov + jitter2 * jnp.eye(2, dtype=cov.dtype))
    w = jnp.where(measurements.valid, jnp.maximum(measurements.weight, 0.0), 0.0)
    log_share = jnp.log(w) - jnp.log(jnp.maximum(jnp.sum(w), 1e-30))
    d2 = jnp.sum(jnp.square(xy[:, None, :] - measurements.xy[None, :, :]), axis=-1)
    log_q = jax.nn.logsumexp(log_share[None, :] - 0.5 * d2 / jitter2, axis=1) - jnp.log(2.0 * math.pi * jitter2)
    f = params.measurement_fraction
    log_prior = jnp.logaddexp(jnp.log1p(-params.birth_rate) + log_cloud, jnp.log(params.birth_rate / params.area))
    log_mixture = jnp.logaddexp(jnp.log1p(-f) + log_cloud, jnp.log(f) + log_q)
    return log_prior - log_mixture


@dataclass(frozen=True)
class BirthWeightedExplorers:
    """Draws the next ``measurement_fraction`` of lowest-support slots at measurements with their importance weight
    (see the module)."""

    name: str = "measurement"

    def default_params(self) -> BirthParams:
        return BirthParams()

    def properties(self) -> BirthParams:
        return BirthParams(
            measurement_fraction=unit_interval(high_closed=False, trainable=False),
            measurement_jitter=nonnegative(),
            birth_rate=unit_interval(trainable=False),
            area=positive(),
        )

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: BirthParams) -> InjectionContext:
        buffer = context.measurements
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        n = context.log_weights.shape[0]
        count = explorer_count(jnp.where(has, params.measurement_fraction, 0.0), n)
        mask = take_slots(context.rank, context.used, count)
        xy = sample_measurements(key, buffer, n, params.measurement_jitter)
        log_w = birth_log_weight(xy, buffer, context.estimate.mean, context.estimate.cov, params)
        context = replace_slots(jax.random.fold_in(key, 1), context, mask, xy)
        context = context._replace(log_weights=jnp.where(mask, context.log_weights + log_w, context.log_weights))
        return context._replace(used=context.used + count)
