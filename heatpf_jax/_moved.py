"""Names and modules that moved when the package was grouped by pipeline stage (0.2), for one release.

``hp.ConstantVelocity`` is now ``hp.motion.ConstantVelocity``, and ``heatpf_jax.motion_velocity`` is now
``heatpf_jax.motion.constant_velocity``. The old names and module paths keep working through 0.2 (they go in 0.3), and
each use warns with a ``DeprecationWarning`` that names the new place.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["MOVED_MODULES", "MOVED_NAMES", "install", "moved_module", "moved_name"]

MOVED_NAMES: dict[str, str] = {  # name -> the module that holds it now
    # heatpf_jax.baselines
    "KalmanFilter": "heatpf_jax.baselines",
    "KalmanParams": "heatpf_jax.baselines",
    "KalmanState": "heatpf_jax.baselines",
    # heatpf_jax.buffers
    "AgingBuffer": "heatpf_jax.buffers",
    "AgingParams": "heatpf_jax.buffers",
    "LatestOnly": "heatpf_jax.buffers",
    # heatpf_jax.camera
    "camera_pose": "heatpf_jax.camera",
    "ground_jacobian": "heatpf_jax.camera",
    "pixel_ray": "heatpf_jax.camera",
    "project_pixel": "heatpf_jax.camera",
    "project_points": "heatpf_jax.camera",
    # heatpf_jax.estimate
    "Clusters": "heatpf_jax.estimate",
    "DominantMode": "heatpf_jax.estimate",
    "GaussianMixtureModes": "heatpf_jax.estimate",
    "KMeansModes": "heatpf_jax.estimate",
    "MeanShiftModes": "heatpf_jax.estimate",
    "Modes": "heatpf_jax.estimate",
    "NoModes": "heatpf_jax.estimate",
    "TopFraction": "heatpf_jax.estimate",
    "TopFractionParams": "heatpf_jax.estimate",
    "mean_shift": "heatpf_jax.estimate",
    "sorted_top_fraction_estimate": "heatpf_jax.estimate",
    "top_fraction_estimate": "heatpf_jax.estimate",
    "weighted_mean_cov": "heatpf_jax.estimate",
    # heatpf_jax.injection
    "ExplorerParams": "heatpf_jax.injection",
    "GaussianExplorerParams": "heatpf_jax.injection",
    "GaussianExplorers": "heatpf_jax.injection",
    "HintParams": "heatpf_jax.injection",
    "InjectionContext": "heatpf_jax.injection",
    "MeasurementExplorers": "heatpf_jax.injection",
    "MeasurementParams": "heatpf_jax.injection",
    "MemoryHints": "heatpf_jax.injection",
    "RandomParticles": "heatpf_jax.injection",
    "RedetectionSeeds": "heatpf_jax.injection",
    "SeedParams": "heatpf_jax.injection",
    "UniformBox": "heatpf_jax.injection",
    "UniformExplorers": "heatpf_jax.injection",
    "explorer_count": "heatpf_jax.injection",
    "explorer_mask": "heatpf_jax.injection",
    "explorer_slots": "heatpf_jax.injection",
    "sample_measurements": "heatpf_jax.injection",
    "spawn_gaussian": "heatpf_jax.injection",
    "spawn_uniform": "heatpf_jax.injection",
    "take_slots": "heatpf_jax.injection",
    # heatpf_jax.measurements
    "age_measurements": "heatpf_jax.measurements",
    "downscale_heatmap": "heatpf_jax.measurements",
    "empty_measurements": "heatpf_jax.measurements",
    "move_measurements": "heatpf_jax.measurements",
    "project_heatmap": "heatpf_jax.measurements",
    "update_buffer": "heatpf_jax.measurements",
    # heatpf_jax.memory
    "MemoryParams": "heatpf_jax.memory",
    "NoMemory": "heatpf_jax.memory",
    "TrackMemory": "heatpf_jax.memory",
    "TrackTable": "heatpf_jax.memory",
    # heatpf_jax.motion
    "ConstantVelocity": "heatpf_jax.motion",
    "ConstantVelocityParams": "heatpf_jax.motion",
    "DiffusionOnly": "heatpf_jax.motion",
    "EgoMotion": "heatpf_jax.motion",
    "InertiaParticles": "heatpf_jax.motion",
    "LocalisationEgo": "heatpf_jax.motion",
    "MassInertia": "heatpf_jax.motion",
    "MassInertiaParams": "heatpf_jax.motion",
    "NoEgo": "heatpf_jax.motion",
    "OdometryEgo": "heatpf_jax.motion",
    "Particles": "heatpf_jax.motion",
    "RandomWalk": "heatpf_jax.motion",
    "RandomWalkParams": "heatpf_jax.motion",
    "ScoreMotion": "heatpf_jax.motion",
    "ScoredParticles": "heatpf_jax.motion",
    "VelocityParticles": "heatpf_jax.motion",
    "apply_odometry": "heatpf_jax.motion",
    "diffuse": "heatpf_jax.motion",
    "move_and_diffuse": "heatpf_jax.motion",
    "move_particles": "heatpf_jax.motion",
    "pose_confidences": "heatpf_jax.motion",
    "pose_deltas": "heatpf_jax.motion",
    # heatpf_jax.observation
    "Floored": "heatpf_jax.observation",
    "FootprintTemplate": "heatpf_jax.observation",
    "FootprintTemplateParams": "heatpf_jax.observation",
    "GaussianDensity": "heatpf_jax.observation",
    "GaussianKernel": "heatpf_jax.observation",
    "InverseDistance": "heatpf_jax.observation",
    "InverseDistanceParams": "heatpf_jax.observation",
    "gaussian_particle_weights": "heatpf_jax.observation",
    "k_nearest": "heatpf_jax.observation",
    "k_nearest_blocked": "heatpf_jax.observation",
    "particle_weights": "heatpf_jax.observation",
    # heatpf_jax.resampling
    "ClusterParams": "heatpf_jax.resampling",
    "ClusterResampling": "heatpf_jax.resampling",
    "DetachResampling": "heatpf_jax.resampling",
    "ESSParams": "heatpf_jax.resampling",
    "ESSResampling": "heatpf_jax.resampling",
    "RESAMPLERS": "heatpf_jax.resampling",
    "Resampled": "heatpf_jax.resampling",
    "SoftResampling": "heatpf_jax.resampling",
    "StopGradientResampling": "heatpf_jax.resampling",
    "effective_sample_size": "heatpf_jax.resampling",
    "multinomial": "heatpf_jax.resampling",
    "residual": "heatpf_jax.resampling",
    "stratified": "heatpf_jax.resampling",
    "systematic": "heatpf_jax.resampling",
    # heatpf_jax.sources
    "CentroidParams": "heatpf_jax.sources",
    "CentroidSource": "heatpf_jax.sources",
    "ClusterCentreSource": "heatpf_jax.sources",
    "PixelSource": "heatpf_jax.sources",
    "SourceParams": "heatpf_jax.sources",
}

MOVED_MODULES: dict[str, tuple[str, ...]] = {  # old module path -> the modules that hold its names now
    "heatpf_jax.baselines.image_trackers": (
        "heatpf_jax.baselines.image_window",
        "heatpf_jax.baselines.image_sequences",
        "heatpf_jax.baselines.opencv_mean_shift",
        "heatpf_jax.baselines.mean_shift",
        "heatpf_jax.baselines.kalman_mean_shift",
        "heatpf_jax.baselines.colour_particles",
    ),
    "heatpf_jax.cache": ("heatpf_jax.io.cache",),
    "heatpf_jax.cli_rgb": ("heatpf_jax.cli.colour",),
    "heatpf_jax.cli_simulate": ("heatpf_jax.cli.simulate",),
    "heatpf_jax.cli_tune": ("heatpf_jax.cli.tune",),
    "heatpf_jax.clustering": (
        "heatpf_jax.estimate.clustering",
        "heatpf_jax.estimate.mean_shift",
        "heatpf_jax.estimate.kmeans",
        "heatpf_jax.estimate.gmm",
    ),
    "heatpf_jax.colour_likelihood": ("heatpf_jax.colour.likelihood",),
    "heatpf_jax.colour_reference": ("heatpf_jax.colour.reference",),
    "heatpf_jax.colour_space": ("heatpf_jax.colour.space",),
    "heatpf_jax.ego": ("heatpf_jax.motion.ego",),
    "heatpf_jax.estimate_modes": ("heatpf_jax.estimate.dominant_mode",),
    "heatpf_jax.files": ("heatpf_jax.io.files",),
    "heatpf_jax.image_centroids": ("heatpf_jax.sources.image_centroids",),
    "heatpf_jax.image_components": ("heatpf_jax.sources.image_components",),
    "heatpf_jax.injection_memory": ("heatpf_jax.injection.memory_hints",),
    "heatpf_jax.injection_sensor": ("heatpf_jax.injection.measurement_explorers",),
    "heatpf_jax.knn": ("heatpf_jax.observation.knn",),
    "heatpf_jax.modes": ("heatpf_jax.estimate.modes",),
    "heatpf_jax.motion_inertia": ("heatpf_jax.motion.mass_inertia",),
    "heatpf_jax.motion_rolling": ("heatpf_jax.motion.rolling_ball",),
    "heatpf_jax.motion_score": ("heatpf_jax.motion.score",),
    "heatpf_jax.motion_velocity": ("heatpf_jax.motion.constant_velocity",),
    "heatpf_jax.observation_range": ("heatpf_jax.observation.range_aware",),
    "heatpf_jax.params_file": ("heatpf_jax.io.params_file",),
    "heatpf_jax.resampling_clustered": ("heatpf_jax.resampling.clustered",),
    "heatpf_jax.resampling_gradients": ("heatpf_jax.resampling.gradients",),
    "heatpf_jax.ros_messages": ("heatpf_jax.io.ros_messages",),
    "heatpf_jax.rosbag_export": ("heatpf_jax.io.rosbag_export",),
    "heatpf_jax.rosbag_import": ("heatpf_jax.io.rosbag_import", "heatpf_jax.cli.import_rosbag"),
    "heatpf_jax.run_plot": ("heatpf_jax.cli.run_plot",),
    "heatpf_jax.sequence": ("heatpf_jax.io.sequence",),
    "heatpf_jax.settings": ("heatpf_jax.cli.settings",),
    "heatpf_jax.sources_lofted": ("heatpf_jax.sources.lofted",),
    "heatpf_jax.sweep_record": ("heatpf_jax.cli.sweep_record",),
}


def _warn(old: str, new: str) -> None:
    warnings.warn(f"{old} moved to {new}; the old name goes in 0.3", DeprecationWarning, stacklevel=3)


def moved_name(name: str):
    """The object a moved top-level name (``heatpf_jax.X``) or old module (``heatpf_jax.motion_velocity``) is now.

    Raises:
        AttributeError: ``name`` is not one that moved.
    """
    if name in MOVED_NAMES:
        _warn(f"heatpf_jax.{name}", f"{MOVED_NAMES[name]}.{name}")
        return getattr(importlib.import_module(MOVED_NAMES[name]), name)
    if f"heatpf_jax.{name}" in MOVED_MODULES:
        return moved_module(f"heatpf_jax.{name}")
    raise AttributeError(f"module 'heatpf_jax' has no attribute {name!r}")


def moved_module(old: str) -> types.ModuleType:
    """The stand-in of an old module path reached as an attribute (``hp.motion_velocity``), with a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        module = importlib.import_module(old)
    _warn(old, ", ".join(MOVED_MODULES[old]))
    return module


class _MovedModule(types.ModuleType):
    """An old module path: each name is looked up in the modules that hold it now, with a warning."""

    def __init__(self, name: str, targets: tuple[str, ...]):
        super().__init__(name, f"Moved to {', '.join(targets)}.")
        self._targets = targets

    def __getattr__(self, attr: str):
        if attr.startswith("__"):
            raise AttributeError(attr)
        for target in self._targets:
            module = importlib.import_module(target)
            if hasattr(module, attr):
                _warn(f"{self.__name__}.{attr}", f"{target}.{attr}")
                return getattr(module, attr)
        moved = ", ".join(self._targets)
        raise AttributeError(f"module {self.__name__!r} (moved to {moved}) has no attribute {attr!r}")


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Finds the old module paths (``import heatpf_jax.motion_velocity``) and gives their stand-ins."""

    def find_spec(self, fullname, path, target=None):
        if fullname in MOVED_MODULES:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        return _MovedModule(spec.name, MOVED_MODULES[spec.name])

    def exec_module(self, module) -> None:
        _warn(module.__name__, ", ".join(module._targets))


def install() -> None:
    """Lets the old module paths import (once per process)."""
    if not any(isinstance(finder, _MovedFinder) for finder in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
