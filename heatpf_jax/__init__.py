"""heatpf_jax: a particle filter on image-based heat maps in Cartesian space, in pure JAX.

Fiedler, Bestmann, Zhang, "Position Estimation on Image-Based Heat Map Input
using Particle Filters in Cartesian Space".
"""

from heatpf_jax.baselines import KalmanFilter, KalmanParams, KalmanState
from heatpf_jax.buffers import AgingBuffer, AgingParams, LatestOnly
from heatpf_jax.camera import camera_pose, ground_jacobian, pixel_ray, project_pixel, project_points
from heatpf_jax.clustering import Clusters, mean_shift
from heatpf_jax.ego import EgoMotion, LocalisationEgo, NoEgo, OdometryEgo, pose_confidences, pose_deltas
from heatpf_jax.estimate import (
    Estimate,
    TopFraction,
    TopFractionParams,
    sorted_top_fraction_estimate,
    top_fraction_estimate,
    weighted_mean_cov,
)
from heatpf_jax.estimate_modes import DominantMode
from heatpf_jax.filter import Filter, FilterParams, FilterState, StepInfo
from heatpf_jax.injection import (
    ExplorerParams,
    GaussianExplorerParams,
    GaussianExplorers,
    InjectionContext,
    RandomParticles,
    UniformBox,
    UniformExplorers,
    explorer_count,
    explorer_mask,
    explorer_slots,
    spawn_gaussian,
    spawn_uniform,
    take_slots,
)
from heatpf_jax.injection_memory import HintParams, MemoryHints, RedetectionSeeds, SeedParams
from heatpf_jax.injection_sensor import MeasurementExplorers, MeasurementParams, sample_measurements
from heatpf_jax.knn import k_nearest_blocked
from heatpf_jax.measurements import (
    Measurements,
    age_measurements,
    downscale_heatmap,
    empty_measurements,
    move_measurements,
    project_heatmap,
    update_buffer,
)
from heatpf_jax.memory import MemoryParams, NoMemory, TrackMemory, TrackTable
from heatpf_jax.modes import (
    GaussianMixtureModes,
    KMeansModes,
    MeanShiftModes,
    Modes,
    NoModes,
)
from heatpf_jax.motion import (
    DiffusionOnly,
    Particles,
    RandomWalk,
    RandomWalkParams,
    apply_odometry,
    diffuse,
    move_and_diffuse,
    move_particles,
)
from heatpf_jax.motion_inertia import InertiaParticles, MassInertia, MassInertiaParams
from heatpf_jax.motion_score import ScoredParticles, ScoreMotion
from heatpf_jax.motion_velocity import ConstantVelocity, ConstantVelocityParams, VelocityParticles
from heatpf_jax.observation import (
    Floored,
    GaussianDensity,
    GaussianKernel,
    InverseDistance,
    InverseDistanceParams,
    gaussian_particle_weights,
    k_nearest,
    particle_weights,
)
from heatpf_jax.observation_range import FootprintTemplate, FootprintTemplateParams
from heatpf_jax.pieces import StepInputs
from heatpf_jax.presets import (
    FilterOptions,
    Method,
    bitbots2018,
    build,
    conventional_filter,
    extended_filter,
    heatmap_filter,
    heatmap_params,
    paper_filter,
)
from heatpf_jax.resampling import (
    RESAMPLERS,
    ESSParams,
    ESSResampling,
    Resampled,
    effective_sample_size,
    multinomial,
    residual,
    stratified,
    systematic,
)
from heatpf_jax.resampling_clustered import ClusterParams, ClusterResampling
from heatpf_jax.resampling_gradients import DetachResampling, SoftResampling, StopGradientResampling
from heatpf_jax.rollout import RunResult, run, stack_params, validate_params
from heatpf_jax.sequence import Sequence, SequenceError, load_sequence, save_sequence, validate_sequence
from heatpf_jax.sources import CentroidParams, CentroidSource, ClusterCentreSource, PixelSource, SourceParams
from heatpf_jax.tracker import Tracker
from heatpf_jax.tuning import Checkpointed, TuneResult, differentiable, mse_loss, nll_loss, trainable_names, tune


def _version() -> str:
    """The installed distribution's version (``pyproject.toml``); ``0+unknown`` from a source tree not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("heatpf-jax")
    except PackageNotFoundError:
        return "0+unknown"


__version__ = _version()

__all__ = [
    "AgingBuffer",
    "AgingParams",
    "CentroidParams",
    "CentroidSource",
    "Checkpointed",
    "ClusterCentreSource",
    "ClusterParams",
    "ClusterResampling",
    "Clusters",
    "ConstantVelocity",
    "ConstantVelocityParams",
    "DetachResampling",
    "DiffusionOnly",
    "DominantMode",
    "ESSParams",
    "ESSResampling",
    "Estimate",
    "ExplorerParams",
    "Filter",
    "FilterOptions",
    "FilterParams",
    "FilterState",
    "Floored",
    "FootprintTemplate",
    "FootprintTemplateParams",
    "GaussianDensity",
    "GaussianExplorerParams",
    "GaussianExplorers",
    "GaussianKernel",
    "GaussianMixtureModes",
    "InertiaParticles",
    "InjectionContext",
    "InverseDistance",
    "InverseDistanceParams",
    "KMeansModes",
    "KalmanFilter",
    "KalmanParams",
    "KalmanState",
    "LatestOnly",
    "MassInertia",
    "MassInertiaParams",
    "MeanShiftModes",
    "MeasurementExplorers",
    "HintParams",
    "MemoryHints",
    "RedetectionSeeds",
    "SeedParams",
    "MemoryParams",
    "NoMemory",
    "TrackMemory",
    "TrackTable",
    "EgoMotion",
    "LocalisationEgo",
    "NoEgo",
    "OdometryEgo",
    "pose_confidences",
    "pose_deltas",
    "MeasurementParams",
    "Measurements",
    "Method",
    "Modes",
    "NoModes",
    "Particles",
    "PixelSource",
    "RESAMPLERS",
    "RandomParticles",
    "RandomWalk",
    "RandomWalkParams",
    "Resampled",
    "RunResult",
    "ScoreMotion",
    "ScoredParticles",
    "Sequence",
    "SequenceError",
    "SoftResampling",
    "SourceParams",
    "StepInfo",
    "StepInputs",
    "StopGradientResampling",
    "TopFraction",
    "TopFractionParams",
    "Tracker",
    "TuneResult",
    "UniformBox",
    "UniformExplorers",
    "VelocityParticles",
    "age_measurements",
    "apply_odometry",
    "bitbots2018",
    "build",
    "camera_pose",
    "conventional_filter",
    "differentiable",
    "diffuse",
    "downscale_heatmap",
    "effective_sample_size",
    "empty_measurements",
    "explorer_count",
    "explorer_mask",
    "explorer_slots",
    "extended_filter",
    "gaussian_particle_weights",
    "ground_jacobian",
    "heatmap_filter",
    "heatmap_params",
    "k_nearest",
    "k_nearest_blocked",
    "load_sequence",
    "mean_shift",
    "move_and_diffuse",
    "move_measurements",
    "move_particles",
    "mse_loss",
    "multinomial",
    "nll_loss",
    "paper_filter",
    "particle_weights",
    "pixel_ray",
    "project_heatmap",
    "project_pixel",
    "project_points",
    "residual",
    "run",
    "sample_measurements",
    "save_sequence",
    "sorted_top_fraction_estimate",
    "spawn_gaussian",
    "spawn_uniform",
    "stack_params",
    "stratified",
    "systematic",
    "take_slots",
    "top_fraction_estimate",
    "trainable_names",
    "tune",
    "update_buffer",
    "validate_params",
    "validate_sequence",
    "weighted_mean_cov",
]
