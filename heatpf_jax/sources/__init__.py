"""Measurement sources: what a heat map's pixels become (III-A).

* :mod:`~heatpf_jax.sources.pixels`: the paper's pixels, the conventional cluster centre, blob centroids;
* :mod:`~heatpf_jax.sources.lofted`: balls in the air placed by their blob's size;
* :mod:`~heatpf_jax.sources.blob_scale`: the detector's blob size, learned from the heat maps;
* :mod:`~heatpf_jax.sources.hover`: a ball does not hover (a blob read as flying that stays put lies on the ground);
* :mod:`~heatpf_jax.sources.image_centroids`, :mod:`~heatpf_jax.sources.image_components`: blobs in the image.
"""

from heatpf_jax.sources.blob_scale import (
    BlobScaleState,
    blob_scale_estimate,
    blob_scale_spread,
    frame_log_ratio,
    init_blob_scale,
    update_blob_scale,
)
from heatpf_jax.sources.image_centroids import (
    BlobCentres,
    ball_radius_px,
    blob_centres,
    box_sums,
    summed_area,
)
from heatpf_jax.sources.image_components import (
    cluster_measurement,
    connected_components,
    strongest_cluster_centre,
)
from heatpf_jax.sources.lofted import (
    BlobSizes,
    LoftedParams,
    LoftedSource,
    LoftedState,
    air_points,
    blob_elongation,
    blob_sizes,
    bright_pixels,
)
from heatpf_jax.sources.pixels import (
    CentroidParams,
    CentroidSource,
    ClusterCentreSource,
    PixelSource,
    SourceParams,
)

__all__ = [
    "BlobCentres",
    "BlobScaleState",
    "BlobSizes",
    "CentroidParams",
    "CentroidSource",
    "ClusterCentreSource",
    "LoftedParams",
    "LoftedSource",
    "LoftedState",
    "PixelSource",
    "SourceParams",
    "air_points",
    "ball_radius_px",
    "blob_centres",
    "blob_elongation",
    "blob_scale_estimate",
    "blob_scale_spread",
    "blob_sizes",
    "box_sums",
    "bright_pixels",
    "cluster_measurement",
    "connected_components",
    "frame_log_ratio",
    "init_blob_scale",
    "strongest_cluster_centre",
    "summed_area",
    "update_blob_scale",
]
