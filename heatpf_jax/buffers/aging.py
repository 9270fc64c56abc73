"""Measurement buffers: what the filter keeps between heat maps (III-C, III-D).

* :class:`AgingBuffer`: the paper's buffer. Odometry moves the buffered measurements; a heat map
  that yields measurements replaces them, otherwise they age (eq. 2).
* :class:`LatestOnly`: no memory. Each step holds only this step's measurements; a step without a
  heat map holds none, so every particle is weighted equally (the original team's 2018 node).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp

from heatpf_jax.measurements import Measurements, move_measurements, update_buffer
from heatpf_jax.params import NoParams, nonnegative
from heatpf_jax.pieces import StepInputs

__all__ = ["AgingBuffer", "AgingParams", "LatestOnly", "NoParams"]


class AgingParams(NamedTuple):
    """Numbers of :class:`AgingBuffer`.

    Attributes:
        aging: v, weight subtracted from buffered measurements per step without input (eq. 2).
        min_weight: l, measurements with a weight below it are removed (III-C).
    """

    aging: float = 0.3
    min_weight: float = 0.1


@dataclass(frozen=True)
class AgingBuffer:
    """Moves buffered measurements by odometry (III-D) and replaces or ages them (III-C, eq. 2)."""

    def default_params(self) -> AgingParams:
        return AgingParams()

    def properties(self) -> AgingParams:
        # min_weight only decides which measurements count (a mask): frozen.
        return AgingParams(aging=nonnegative(), min_weight=nonnegative(trainable=False))

    def update(self, buffer: Measurements, new: Measurements, inputs: StepInputs, params: AgingParams) -> Measurements:
        moved = move_measurements(buffer, inputs.odometry)
        return update_buffer(moved, new, inputs.has_heatmap, params.aging, params.min_weight)


@dataclass(frozen=True)
class LatestOnly:
    """This step's measurements only: nothing is kept, moved or aged."""

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def update(self, buffer: Measurements, new: Measurements, inputs: StepInputs, params: NoParams) -> Measurements:
        del buffer, params
        valid = new.valid & inputs.has_heatmap
        return new._replace(weight=jnp.where(valid, new.weight, 0.0), valid=valid)
