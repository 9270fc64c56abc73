"""Explorers drawn from the measurements: sensor resetting (Lenser and Veloso, 2000).

The paper's explorers (III-E) land uniformly over the spawn area, so a ball that appears where no
particle is (a second ball, a ball after a long occlusion, a kick that outruns the cloud) is found
only when an explorer happens to land within the observation kernel of it: with 25 explorers over
56 m^2 and a 5 cm kernel, that takes tens of steps. Here the lowest-support slots are refilled at
measurements of the current buffer instead, each drawn with probability proportional to its weight
(the heat-map activation, aged) and jittered by a Gaussian of std ``measurement_jitter``: new
hypotheses start where the detector sees something. A step with an empty buffer refills nothing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, refill
from heatpf_jax.measurements import Measurements
from heatpf_jax.params import nonnegative, unit_interval

__all__ = ["MeasurementExplorers", "MeasurementParams", "sample_measurements"]


class MeasurementParams(NamedTuple):
    """Numbers of :class:`MeasurementExplorers`.

    Attributes:
        measurement_fraction: share of the particles refilled at measurements each step.
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05


def sample_measurements(
    key: PRNGKeyArray, measurements: Measurements, num: int, jitter: Float[Array, ""]
) -> Float[Array, "num 2"]:
    """``num`` positions drawn from the valid measurements in proportion to their weight, plus jitter.

    Inverse-CDF sampling (one ``cumsum`` and a ``searchsorted``); with no valid measurement the
    positions are those of slot 0 (callers refill nothing then).
    """
    k_pick, k_jitter = jax.random.split(key)
    w = jnp.where(measurements.valid, jnp.maximum(measurements.weight, 0.0), 0.0)
    cdf = jnp.cumsum(w)
    u = jax.random.uniform(k_pick, (num,), w.dtype) * cdf[-1]
    idx = jnp.clip(jnp.searchsorted(cdf, u, side="right"), 0, w.shape[0] - 1)
    xy = measurements.xy[idx]
    return xy + jitter * jax.random.normal(k_jitter, xy.shape, xy.dtype)


@dataclass(frozen=True)
class MeasurementExplorers:
    """Refills the next ``measurement_fraction`` of lowest-support slots at measurements (see the module)."""

    name: str = "measurement"

    def default_params(self) -> MeasurementParams:
        return MeasurementParams()

    def properties(self) -> MeasurementParams:
        return MeasurementParams(
            measurement_fraction=unit_interval(high_closed=False, trainable=False),
            measurement_jitter=nonnegative(),
        )

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: MeasurementParams) -> InjectionContext:
        buffer = context.measurements
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        fraction = jnp.where(has, params.measurement_fraction, 0.0)
        return refill(key, context, fraction, lambda k, n: sample_measurements(k, buffer, n, params.measurement_jitter))
