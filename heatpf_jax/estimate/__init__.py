"""Estimates: what the filter reports (III-F; Olufs 3.2).

* :mod:`~heatpf_jax.estimate.top_fraction`: the mean and covariance of the best 95 %;
* :mod:`~heatpf_jax.estimate.dominant_mode`: the strongest mode as the estimate;
* :mod:`~heatpf_jax.estimate.modes`: several modes (mean shift, k-means, a Gaussian mixture);
* the clustering they use: :mod:`~heatpf_jax.estimate.mean_shift`, :mod:`~heatpf_jax.estimate.kmeans`,
  :mod:`~heatpf_jax.estimate.gmm` (Gaussian-mixture EM) and the helpers they share,
  :mod:`~heatpf_jax.estimate.clustering`.
"""

from heatpf_jax.estimate.clustering import (
    squared_distances,
    usable_weights,
    weighted_stats,
)
from heatpf_jax.estimate.dominant_mode import (
    DominantMode,
)
from heatpf_jax.estimate.gmm import (
    Mixture,
    gmm_em,
    m_step,
    mixture_from_labels,
    mixture_log_prob,
    responsibilities,
)
from heatpf_jax.estimate.kmeans import (
    KMeans,
    kmeans,
    kmeans_plus_plus,
)
from heatpf_jax.estimate.mean_shift import (
    KERNELS,
    Clusters,
    grid_cells,
    mean_shift,
    seed_points,
)
from heatpf_jax.estimate.modes import (
    GaussianMixtureModes,
    GaussianMixtureParams,
    KMeansModes,
    KMeansParams,
    MeanShiftModes,
    MeanShiftParams,
    Modes,
    NoModes,
    empty_modes,
)
from heatpf_jax.estimate.top_fraction import (
    Estimate,
    TopFraction,
    TopFractionParams,
    sorted_top_fraction_estimate,
    top_fraction_estimate,
    weighted_mean_cov,
)

__all__ = [
    "Clusters",
    "DominantMode",
    "Estimate",
    "GaussianMixtureModes",
    "GaussianMixtureParams",
    "KERNELS",
    "KMeans",
    "KMeansModes",
    "KMeansParams",
    "MeanShiftModes",
    "MeanShiftParams",
    "Mixture",
    "Modes",
    "NoModes",
    "TopFraction",
    "TopFractionParams",
    "empty_modes",
    "gmm_em",
    "grid_cells",
    "kmeans",
    "kmeans_plus_plus",
    "m_step",
    "mean_shift",
    "mixture_from_labels",
    "mixture_log_prob",
    "responsibilities",
    "seed_points",
    "sorted_top_fraction_estimate",
    "squared_distances",
    "top_fraction_estimate",
    "usable_weights",
    "weighted_mean_cov",
    "weighted_stats",
]
