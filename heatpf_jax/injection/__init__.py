"""Injection: new particles among the resampled ones (III-E; Olufs 3.4).

* :mod:`~heatpf_jax.injection.explorers`: the paper's explorers and random particles;
* :mod:`~heatpf_jax.injection.measurement_explorers`: explorers drawn at measurements;
* :mod:`~heatpf_jax.injection.support_drop`: explorers at measurements when the estimate's support drops;
* :mod:`~heatpf_jax.injection.birth_weight`: explorers at measurements with their importance weight;
* :mod:`~heatpf_jax.injection.measurement_seeds`: explorers at this step's measurements before the weighting when the
  cloud has lost the ball;
* :mod:`~heatpf_jax.injection.memory_hints`: hint particles and re-detection seeds from the memory.
"""

from heatpf_jax.injection.birth_weight import BirthParams, BirthWeightedExplorers, birth_log_weight
from heatpf_jax.injection.explorers import (
    ExplorerParams,
    GaussianExplorerParams,
    GaussianExplorers,
    InjectionContext,
    RandomParams,
    RandomParticles,
    UniformBox,
    UniformExplorers,
    explorer_count,
    explorer_mask,
    explorer_slots,
    refill,
    replace_slots,
    spawn_gaussian,
    spawn_uniform,
    take_slots,
)
from heatpf_jax.injection.measurement_explorers import (
    MeasurementExplorers,
    MeasurementParams,
    sample_measurements,
)
from heatpf_jax.injection.measurement_seeds import (
    ReacquisitionParams,
    ReacquisitionSeeds,
    cloud_mean,
    has_support,
    in_view,
    robust_spread,
)
from heatpf_jax.injection.memory_hints import (
    HintParams,
    MemoryHints,
    RedetectionSeeds,
    SeedParams,
)
from heatpf_jax.injection.support_drop import (
    SupportDropExplorers,
    SupportDropParams,
    SupportState,
    support_at,
    support_update,
)

__all__ = [
    "BirthParams",
    "BirthWeightedExplorers",
    "ExplorerParams",
    "GaussianExplorerParams",
    "GaussianExplorers",
    "HintParams",
    "InjectionContext",
    "MeasurementExplorers",
    "MeasurementParams",
    "MemoryHints",
    "RandomParams",
    "RandomParticles",
    "ReacquisitionParams",
    "ReacquisitionSeeds",
    "RedetectionSeeds",
    "SeedParams",
    "SupportDropExplorers",
    "SupportDropParams",
    "SupportState",
    "UniformBox",
    "UniformExplorers",
    "explorer_count",
    "explorer_mask",
    "explorer_slots",
    "has_support",
    "in_view",
    "robust_spread",
    "birth_log_weight",
    "cloud_mean",
    "refill",
    "replace_slots",
    "sample_measurements",
    "spawn_gaussian",
    "spawn_uniform",
    "support_at",
    "support_update",
    "take_slots",
]
