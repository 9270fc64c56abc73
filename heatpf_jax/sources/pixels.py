"""Measurement sources: a heat map becomes a fixed-size :class:`Measurements` (III-A, IV-B).

* :class:`PixelSource`: the paper's source, every pixel at or above the threshold is a measurement
  (:func:`heatpf_jax.measurements.project_heatmap`).
* :class:`ClusterCentreSource`: the conventional source, one measurement per heat map, the centre of
  the strongest image-space component (:mod:`heatpf_jax.sources.image_components`).
* :class:`CentroidSource`: every pixel at or above the threshold, moved to the centroid of its blob in the
  image before it is projected (:mod:`heatpf_jax.sources.image_centroids`): the centroid's precision along the
  line of sight with one measurement per pixel, so eq. (1)'s robustness to false positives and split
  blobs is kept.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp

from heatpf_jax.measurements import Measurements, downscale_heatmap, measurements_at, project_heatmap, strongest_pixels
from heatpf_jax.params import positive, unit_interval
from heatpf_jax.pieces import StepInputs
from heatpf_jax.sources.image_centroids import blob_centres
from heatpf_jax.sources.image_components import cluster_measurement

__all__ = ["CentroidParams", "CentroidSource", "ClusterCentreSource", "PixelSource", "SourceParams"]


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


class CentroidParams(NamedTuple):
    """Numbers of :class:`CentroidSource`.

    Attributes:
        threshold: minimum heat-map activation of a blob's pixel (III-A).
        max_distance: measurements farther from the robot are dropped, metres.
        reach: the centroid window's half-size in radii of a ground ball at its centre.
        max_spill: a measurement whose blob spills out of its window (above-threshold pixels in a window twice
            as large over those in the window, :attr:`~heatpf_jax.sources.image_centroids.BlobCentres.spill`) more than
            this is dropped: its blob is larger than a ball lying on the ground there would make, as a ball in
            the air is (its projection lies far behind it) or a large false positive; ``inf`` keeps all.
    """

    threshold: float = 0.3
    max_distance: float = 12.0
    reach: float = 1.5
    max_spill: float = float("inf")


@dataclass(frozen=True)
class CentroidSource:
    """Every pixel at or above ``threshold``, moved to its blob's centroid in the image, then projected.

    Each passing pixel runs ``iterations`` mean-shift steps over the above-threshold activations with a
    window of ``reach`` ground-ball radii (:func:`~heatpf_jax.sources.image_centroids.blob_centres`); the measurement
    is the projection of where it ends, with the pixel's own activation as its weight (eq. 1's ``w``) and
    the projection's Jacobian at the centroid as its footprint.

    Attributes:
        max_measurements: slots; the strongest pixels are kept (IV-E).
        downscale: integer block-averaging of the heat map first (III-A).
        iterations: mean-shift steps.
    """

    max_measurements: int = 1024
    downscale: int = 1
    iterations: int = 3

    @property
    def size(self) -> int:
        return self.max_measurements

    def default_params(self) -> CentroidParams:
        return CentroidParams()

    def properties(self) -> CentroidParams:
        # Each acts through which pixels count or where a window ends: frozen, swept rather than tuned.
        return CentroidParams(
            threshold=unit_interval(trainable=False),
            max_distance=positive(trainable=False, allow_inf=True),
            reach=positive(trainable=False),
            max_spill=positive(trainable=False, allow_inf=True),
        )

    def validate(self) -> None:
        for name in ("max_measurements", "downscale", "iterations"):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < 1:
                raise ValueError(f"{name}: must be a positive integer, got {value!r}")

    def measure(self, inputs: StepInputs, params: CentroidParams) -> Measurements:
        heatmap, intrinsics = downscale_heatmap(inputs.heatmap, inputs.intrinsics, self.downscale)
        uv, passes, weight = strongest_pixels(
            heatmap, intrinsics, inputs.cam_to_base, threshold=params.threshold,
            plane_height=inputs.plane_height, max_measurements=self.max_measurements,
            max_distance=params.max_distance,
        )
        centres = blob_centres(
            heatmap, uv, intrinsics, inputs.cam_to_base, threshold=params.threshold,
            plane_height=inputs.plane_height, reach=params.reach, iterations=self.iterations,
        )
        keep = passes & (centres.spill <= params.max_spill)
        return measurements_at(
            centres.uv, keep, jnp.where(keep, weight, 0.0), intrinsics, inputs.cam_to_base,
            plane_height=inputs.plane_height, max_measurements=self.max_measurements,
            max_distance=params.max_distance,
        )
