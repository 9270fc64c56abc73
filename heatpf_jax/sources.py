"""Measurement sources: a heat map becomes a fixed-size :class:`Measurements` (III-A, IV-B).

* :class:`PixelSource`: the paper's source, every pixel at or above the threshold is a measurement
  (:func:`heatpf_jax.measurements.project_heatmap`).
* :class:`ClusterCentreSource`: the conventional source, one measurement per heat map, the centre of
  the strongest image-space component (:mod:`heatpf_jax.image_components`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from heatpf_jax.image_components import cluster_measurement
from heatpf_jax.measurements import Measurements, project_heatmap
from heatpf_jax.params import positive, unit_interval
from heatpf_jax.pieces import StepInputs

__all__ = ["ClusterCentreSource", "PixelSource", "SourceParams"]


class SourceParams(NamedTuple):
    """Numbers of a measurement source.

    Attributes:
        threshold: minimum heat-map activation projected (III-A).
        max_distance: projected pixels farther from the robot are dropped, metres.
    """

    threshold: float = 0.3
    max_distance: float = 12.0


def _properties() -> SourceParams:
    # Both act through a mask (which pixels count): frozen, swept rather than tuned.
    return SourceParams(
        threshold=unit_interval(trainable=False), max_distance=positive(trainable=False, allow_inf=True)
    )


@dataclass(frozen=True)
class PixelSource:
    """Every heat-map pixel at or above ``threshold`` projected onto the ball plane (III-A).

    Attributes:
        max_measurements: slots; the strongest pixels are kept (IV-E).
        downscale: integer block-averaging of the heat map before projection (III-A).
    """

    max_measurements: int = 1024
    downscale: int = 1

    @property
    def size(self) -> int:
        return self.max_measurements

    def default_params(self) -> SourceParams:
        return SourceParams()

    def properties(self) -> SourceParams:
        return _properties()

    def validate(self) -> None:
        for name in ("max_measurements", "downscale"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer, got {value!r}")

    def measure(self, inputs: StepInputs, params: SourceParams) -> Measurements:
        return project_heatmap(
            inputs.heatmap,
            inputs.intrinsics,
            inputs.cam_to_base,
            threshold=params.threshold,
            plane_height=inputs.plane_height,
            max_measurements=self.max_measurements,
            max_distance=params.max_distance,
            downscale=self.downscale,
        )


@dataclass(frozen=True)
class ClusterCentreSource:
    """One measurement per heat map: the centre of the strongest 8-connected component (IV-B)."""

    @property
    def size(self) -> int:
        return 1

    def default_params(self) -> SourceParams:
        return SourceParams()

    def properties(self) -> SourceParams:
        return _properties()

    def measure(self, inputs: StepInputs, params: SourceParams) -> Measurements:
        return cluster_measurement(
            inputs.heatmap,
            inputs.intrinsics,
            inputs.cam_to_base,
            threshold=params.threshold,
            plane_height=inputs.plane_height,
            size=1,
            max_distance=params.max_distance,
        )
