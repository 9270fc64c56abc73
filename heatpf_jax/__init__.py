"""heatpf_jax: a particle filter on image-based heat maps in Cartesian space, in pure JAX.

Fiedler, Bestmann, Zhang, "Position Estimation on Image-Based Heat Map Input
using Particle Filters in Cartesian Space".
"""

from heatpf_jax.camera import camera_pose, pixel_ray, project_pixel, project_points
from heatpf_jax.estimate import Estimate, sorted_top_fraction_estimate, top_fraction_estimate, weighted_mean_cov
from heatpf_jax.explorers import explorer_count, explorer_mask, explorer_slots, spawn_gaussian, spawn_uniform
from heatpf_jax.filter import (
    FilterConfig,
    FilterParams,
    FilterState,
    RunResult,
    StepInfo,
    StepInputs,
    init,
    run,
    stack_params,
    step,
    validate_config,
    validate_params,
)
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
from heatpf_jax.motion import apply_odometry, diffuse, move_and_diffuse, move_particles
from heatpf_jax.observation import gaussian_particle_weights, k_nearest, particle_weights
from heatpf_jax.resampling import (
    RESAMPLERS,
    effective_sample_size,
    multinomial,
    residual,
    stratified,
    systematic,
)
from heatpf_jax.sequence import Sequence, SequenceError, load_sequence, save_sequence, validate_sequence

__version__ = "0.1.0"

__all__ = [
    "RESAMPLERS",
    "Estimate",
    "FilterConfig",
    "FilterParams",
    "FilterState",
    "Measurements",
    "RunResult",
    "Sequence",
    "SequenceError",
    "StepInfo",
    "StepInputs",
    "age_measurements",
    "apply_odometry",
    "camera_pose",
    "diffuse",
    "downscale_heatmap",
    "effective_sample_size",
    "empty_measurements",
    "explorer_count",
    "explorer_mask",
    "explorer_slots",
    "gaussian_particle_weights",
    "init",
    "k_nearest",
    "k_nearest_blocked",
    "load_sequence",
    "move_and_diffuse",
    "move_measurements",
    "move_particles",
    "multinomial",
    "particle_weights",
    "pixel_ray",
    "project_heatmap",
    "project_pixel",
    "project_points",
    "residual",
    "run",
    "save_sequence",
    "spawn_gaussian",
    "spawn_uniform",
    "stack_params",
    "step",
    "stratified",
    "systematic",
    "sorted_top_fraction_estimate",
    "top_fraction_estimate",
    "update_buffer",
    "validate_config",
    "validate_params",
    "validate_sequence",
    "weighted_mean_cov",
]
