"""Explorers at the measurements when the tracked object's support drops (Augmented MCL; sensor resetting).

:class:`~heatpf_jax.injection.measurement_explorers.MeasurementExplorers` refills a fixed share of the particles at
the measurements every step. While the filter follows the ball, that share keeps seeding every other blob of the
heat map, and where one is brighter than the ball (a false positive near the robot, a saturated reflection) the
seeds outweigh the ball's particles within a step: the world family's ``false_positives``, development seeds
100-102, 1.40 m with the fixed share against 1.09 m without any (docs/results.md, "Explorers when the ball's support
drops"). Whether something else is brighter says nothing of whether the ball is still where the filter believes;
what does is the evidence at the estimate itself, against its own recent level. (It is an option: once the ball is
lost, seeds that land on clutter keep a steady support, so the ball is not looked for when it returns, and the same
page measures the fixed share lower on the family's ``walking``, ``sparse_rate`` and after a landing.)

:class:`SupportDropExplorers` follows Thrun, Burgard and Fox's Augmented MCL (Probabilistic Robotics, Table 8.3): the
support ``s_t`` of a step with a new heat map is the strongest measurement within ``gate`` of the estimate (0 while
the particles are spread over the field and their mean lies where nothing is), smoothed by a slow and a fast
exponential average,

    slow_t = slow_{t-1} + slow_rate (s_t - slow_{t-1}),   fast_t = fast_{t-1} + fast_rate (s_t - fast_{t-1}),

and the share refilled at the measurements is ``measurement_fraction * max(0, 1 - fast_t / slow_t)`` (the whole
``measurement_fraction`` while ``slow_t`` is 0: before the first track, or long after losing it). A ball that
leaves the view, is hidden or is kicked out of the cloud takes its support with it and the explorers return within
a few steps; a ball that stays seen keeps them off, whatever else the heat map holds. A step without a new heat
map keeps the averages (an aged buffer is no new evidence). The support is an activation, so the ratio is the
same for any observation model.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, refill
from heatpf_jax.injection.measurement_explorers import sample_measurements
from heatpf_jax.measurements import Measurements
from heatpf_jax.params import nonnegative, positive, unit_interval

__all__ = ["SupportDropExplorers", "SupportDropParams", "SupportState", "support_at", "support_update"]


class SupportDropParams(NamedTuple):
    """Numbers of :class:`SupportDropExplorers`.

    Attributes:
        measurement_fraction: share of the particles refilled at measurements when the support is gone.
        measurement_jitter: std of the Gaussian jitter around the drawn measurement, metres.
        slow_rate: the slow average's rate per heat map, ``0 < slow_rate < fast_rate``.
        fast_rate: the fast average's rate per heat map, ``<= 1``.
        gate: the radius around the estimate, metres, where a measurement counts as its support.
    """

    measurement_fraction: float = 0.05
    measurement_jitter: float = 0.05
    slow_rate: float = 0.05
    fast_rate: float = 0.5
    gate: float = 0.5


class SupportState(NamedTuple):
    """The carried averages of the support.

    Attributes:
        slow: ``float32 []`` the slow average.
        fast: ``float32 []`` the fast average.
    """

    slow: Float[Array, ""]
    fast: Float[Array, ""]


def support_at(measurements: Measurements, mean: Float[Array, "2"], gate: Float[Array, ""]) -> Float[Array, ""]:
    """The strongest valid measurement's weight within ``gate`` of ``mean`` (0 if none)."""
    d2 = jnp.sum(jnp.square(measurements.xy - mean[None, :]), axis=-1)
    near = measurements.valid & (d2 <= jnp.square(gate))
    return jnp.max(jnp.where(near, jnp.maximum(measurements.weight, 0.0), 0.0), initial=0.0)


def support_update(
    state: SupportState, support: Float[Array, ""], has_heatmap, params: SupportDropParams
) -> tuple[SupportState, Float[Array, ""]]:
    """The averages after this step's support (unchanged without a new heat map) and the share to refill."""
    slow = state.slow + params.slow_rate * (support - state.slow)
    fast = state.fast + params.fast_rate * (support - state.fast)
    new = SupportState(slow=jnp.where(has_heatmap, slow, state.slow), fast=jnp.where(has_heatmap, fast, state.fast))
    lost = jnp.where(new.slow > 0.0, jnp.clip(1.0 - new.fast / jnp.maximum(new.slow, 1e-30), 0.0, 1.0), 1.0)
    return new, params.measurement_fraction * lost


@dataclass(frozen=True)
class SupportDropExplorers:
    """Refills up to ``measurement_fraction`` of the lowest-support slots at measurements, as far as the support at
    the estimate has dropped below its slow average (see the module)."""

    name: str = "measurement"

    def default_params(self) -> SupportDropParams:
        return SupportDropParams()

    def properties(self) -> SupportDropParams:
        return SupportDropParams(
            measurement_fraction=unit_interval(high_closed=False, trainable=False),
            measurement_jitter=nonnegative(),
            slow_rate=unit_interval(trainable=False),
            fast_rate=unit_interval(trainable=False),
            gate=positive(),
        )

    def init_state(self) -> SupportState:
        return SupportState(slow=jnp.zeros((), jnp.float32), fast=jnp.zeros((), jnp.float32))

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: SupportDropParams) -> InjectionContext:
        """As :meth:`inject_state` from empty averages (a filter that carries none refills the whole share)."""
        return self.inject_state(key, context, params, self.init_state())[0]

    def inject_state(
        self, key: PRNGKeyArray, context: InjectionContext, params: SupportDropParams, state: SupportState
    ) -> tuple[InjectionContext, SupportState]:
        buffer = context.measurements
        has_heatmap = jnp.asarray(True) if context.has_heatmap is None else context.has_heatmap
        support = support_at(buffer, context.estimate.mean, params.gate)
        state, fraction = support_update(state, support, has_heatmap, params)
        has = jnp.any(buffer.valid & (buffer.weight > 0))
        fraction = jnp.where(has, fraction, 0.0)
        context = refill(key, context, fraction,
                         lambda k, n: sample_measurements(k, buffer, n, params.measurement_jitter))
        return context, state
