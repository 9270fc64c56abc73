"""heatpf_jax: a particle filter on image-based heat maps in Cartesian space, in pure JAX.

Fiedler, Bestmann, Zhang, "Position Estimation on Image-Based Heat Map Input
using Particle Filters in Cartesian Space".

The top level runs, builds and tunes a filter; the pieces are reached through their stage of the
pipeline, as ``hp.motion.ConstantVelocity`` or ``hp.resampling.systematic``:

* :mod:`heatpf_jax.motion`: motion models and the robot's ego-motion (III-D; Olufs 3.3, 3.5);
* :mod:`heatpf_jax.sources`: what a heat map's pixels become (III-A);
* :mod:`heatpf_jax.buffers`: the measurement buffer and its aging (III-C);
* :mod:`heatpf_jax.observation`: a particle's weight (III-B, eq. 1);
* :mod:`heatpf_jax.estimate`: the reported estimate and modes (III-F);
* :mod:`heatpf_jax.resampling`: resamplers, the ESS trigger, cluster-wise resampling (III-E);
* :mod:`heatpf_jax.injection`: explorers, random particles, hints from the memory (III-E; Olufs 3.4);
* :mod:`heatpf_jax.memory`: the long-term memory's tracks (Olufs 3.4);
* :mod:`heatpf_jax.colour`: colour heat maps from RGB frames (Olufs 2);
* :mod:`heatpf_jax.baselines`: the Kalman filter and the image-space trackers;
* :mod:`heatpf_jax.io`: files, the compilation cache, ROS 2 bags; :mod:`heatpf_jax.cli`: the ``heatpf`` command;
* :mod:`heatpf_jax.camera`, :mod:`heatpf_jax.measurements`: the projection and the measurement type.
"""

from heatpf_jax import (
    baselines,
    buffers,
    camera,
    colour,
    estimate,
    injection,
    io,
    measurements,
    memory,
    motion,
    observation,
    resampling,
    sources,
)
from heatpf_jax._moved import install as _install_moved_modules
from heatpf_jax._moved import moved_name as _moved_name
from heatpf_jax.estimate.top_fraction import Estimate
from heatpf_jax.filter import Filter, FilterParams, FilterState, StepInfo
from heatpf_jax.io.sequence import Sequence, SequenceError, load_sequence, save_sequence, validate_sequence
from heatpf_jax.measurements import Measurements
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
from heatpf_jax.rollout import RunResult, run, stack_params, validate_params
from heatpf_jax.tracker import Tracker
from heatpf_jax.tuning import Checkpointed, TuneResult, differentiable, mse_loss, nll_loss, trainable_names, tune

_install_moved_modules()


def __getattr__(name: str):
    """A name that moved to its stage (``hp.ConstantVelocity`` is ``hp.motion.ConstantVelocity``), with a warning."""
    return _moved_name(name)


def _version() -> str:
    """The installed distribution's version (``pyproject.toml``); ``0+unknown`` from a source tree not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("heatpf-jax")
    except PackageNotFoundError:
        return "0+unknown"


__version__ = _version()

__all__ = [
    "Checkpointed",
    "Estimate",
    "Filter",
    "FilterOptions",
    "FilterParams",
    "FilterState",
    "Measurements",
    "Method",
    "RunResult",
    "Sequence",
    "SequenceError",
    "StepInfo",
    "StepInputs",
    "Tracker",
    "TuneResult",
    "baselines",
    "bitbots2018",
    "buffers",
    "build",
    "camera",
    "colour",
    "conventional_filter",
    "differentiable",
    "estimate",
    "extended_filter",
    "heatmap_filter",
    "heatmap_params",
    "injection",
    "io",
    "load_sequence",
    "measurements",
    "memory",
    "motion",
    "mse_loss",
    "nll_loss",
    "observation",
    "paper_filter",
    "resampling",
    "run",
    "save_sequence",
    "sources",
    "stack_params",
    "trainable_names",
    "tune",
    "validate_params",
    "validate_sequence",
]
