"""Observation models: a particle's weight from the buffered measurements (III-B, eq. 1).

* :mod:`~heatpf_jax.observation.kernels`: eq. 1 (inverse distance), Gaussian kernels, a floor;
* :mod:`~heatpf_jax.observation.range_aware`: each pixel's kernel follows its ground footprint;
* :mod:`~heatpf_jax.observation.knn`: the exact k-nearest search.
"""

from heatpf_jax.observation.kernels import (
    AUTO_BLOCKED_MIN_SIZE,
    DEFAULT_MIN_DISTANCE,
    KNN_METHODS,
    Floored,
    FloorParams,
    GaussianDensity,
    GaussianKernel,
    GaussianKernelParams,
    InverseDistance,
    InverseDistanceParams,
    gaussian_particle_weights,
    k_nearest,
    particle_weights,
)
from heatpf_jax.observation.knn import (
    DEFAULT_BLOCK_SIZE,
    DEFAULT_CHUNK_SIZE,
    BlockPlan,
    k_nearest_blocked,
    plan_blocks,
)
from heatpf_jax.observation.range_aware import (
    FootprintKernel,
    FootprintKernelParams,
    FootprintTemplate,
    FootprintTemplateParams,
    footprint_template_log_likelihood,
    nearest_slots,
)

__all__ = [
    "AUTO_BLOCKED_MIN_SIZE",
    "BlockPlan",
    "DEFAULT_BLOCK_SIZE",
    "DEFAULT_CHUNK_SIZE",
    "DEFAULT_MIN_DISTANCE",
    "FloorParams",
    "Floored",
    "FootprintKernel",
    "FootprintKernelParams",
    "FootprintTemplate",
    "FootprintTemplateParams",
    "GaussianDensity",
    "GaussianKernel",
    "GaussianKernelParams",
    "InverseDistance",
    "InverseDistanceParams",
    "KNN_METHODS",
    "footprint_template_log_likelihood",
    "gaussian_particle_weights",
    "k_nearest",
    "k_nearest_blocked",
    "nearest_slots",
    "particle_weights",
    "plan_blocks",
]
