"""Resampling (III-E; Olufs 3.2).

* :mod:`~heatpf_jax.resampling.resamplers`: index resamplers and the ESS trigger;
* :mod:`~heatpf_jax.resampling.clustered`: cluster-wise resampling with mean shift;
* :mod:`~heatpf_jax.resampling.gradients`: gradient estimators around a resampler.
"""

from heatpf_jax.resampling.clustered import (
    ClusterParams,
    ClusterResampling,
    cluster_counts,
    resample_by_cluster,
)
from heatpf_jax.resampling.gradients import (
    DetachResampling,
    SoftResampling,
    StopGradientResampling,
)
from heatpf_jax.resampling.resamplers import (
    RESAMPLERS,
    ESSParams,
    ESSResampling,
    Resampled,
    check_resampler,
    effective_sample_size,
    ess_trigger,
    multinomial,
    residual,
    sorted_resampled,
    stratified,
    systematic,
)

__all__ = [
    "ClusterParams",
    "ClusterResampling",
    "DetachResampling",
    "ESSParams",
    "ESSResampling",
    "RESAMPLERS",
    "Resampled",
    "SoftResampling",
    "StopGradientResampling",
    "check_resampler",
    "cluster_counts",
    "effective_sample_size",
    "ess_trigger",
    "multinomial",
    "resample_by_cluster",
    "residual",
    "sorted_resampled",
    "stratified",
    "systematic",
]
