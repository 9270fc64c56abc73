"""Named methods and named static choices: the registries the command line and validation use.

The filter itself knows no names: a :class:`~heatpf_jax.filter.Filter` holds pieces. Here names are
turned into pieces:

* ``METHODS``: ``heatmap`` (the paper's filter), ``conventional`` (the same particle filter fed the
  cluster centre, IV-B), ``kalman`` (the constant-velocity Kalman baseline) and ``bitbots2018``
  (the original team's 2018 node, :func:`bitbots2018`);
* :class:`FilterOptions`: the static choices by name (``--set resampler=residual``,
  ``--set num_particles=1000``), with ``RESAMPLERS``, ``SPAWNS``, ``OBSERVATIONS`` and ``KNN_METHODS``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any, NamedTuple

from heatpf_jax.baselines.kalman import KalmanFilter
from heatpf_jax.buffers import AgingBuffer, LatestOnly
from heatpf_jax.estimate import TopFraction, TopFractionParams
from heatpf_jax.filter import Filter, FilterParams
from heatpf_jax.injection import ExplorerParams, GaussianExplorers, UniformBox, UniformExplorers
from heatpf_jax.motion import DiffusionOnly, DiffusionParams, RandomWalk
from heatpf_jax.observation import (
    KNN_METHODS,
    Floored,
    FloorParams,
    GaussianKernel,
    InverseDistance,
    InverseDistanceParams,
)
from heatpf_jax.resampling import RESAMPLERS, ESSParams, ESSResampling
from heatpf_jax.sources import ClusterCentreSource, PixelSource, SourceParams

__all__ = [
    "BITBOTS_BOX",
    "METHODS",
    "Method",
    "OBSERVATIONS",
    "SPAWNS",
    "FilterOptions",
    "bitbots2018",
    "bitbots2018_params",
    "build",
    "conventional_filter",
    "heatmap_filter",
    "kalman_baseline",
    "validate_options",
]

SPAWNS = ("uniform", "gaussian")
OBSERVATIONS = {"inverse_distance": InverseDistance, "gaussian": GaussianKernel}


class FilterOptions(NamedTuple):
    """The static choices by name, as the command line sets them (changing one recompiles).

    Attributes:
        num_particles: N. 500, as the original team ran the filter.
        max_measurements: measurement buffer size; the strongest pixels are kept (IV-E).
        k_max: static upper bound on the traced ``k`` (the search's arrays are sized for it: keep it
            near the largest k you use).
        resampler: a name in ``RESAMPLERS`` (default ``"systematic"``).
        spawn: explorers drawn ``"uniform"`` over ``spawn_box`` (default) or ``"gaussian"`` around
            the estimate (with ``explorer_std``).
        spawn_box: ``(x_min, x_max, y_min, y_max)`` in the base frame, metres: initial particles and
            uniform explorers. The default covers what a humanoid's head camera sees in front of it.
        downscale: integer block-averaging of the heat map before projection (III-A).
        observation: ``"inverse_distance"`` (eq. 1, default) or ``"gaussian"`` (kernel std ``obs_std``).
        knn: k-nearest search, ``"auto"`` (default), ``"blocked"`` or ``"dense"``: all exact.
    """

    num_particles: int = 500
    max_measurements: int = 1024
    k_max: int = 10
    resampler: str = "systematic"
    spawn: str = "uniform"
    spawn_box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)
    downscale: int = 1
    observation: str = "inverse_distance"
    knn: str = "auto"


def validate_options(options: FilterOptions) -> None:
    """Raises ``ValueError`` naming the option if it is unusable."""
    if not isinstance(options, FilterOptions):
        raise TypeError(f"options: expected FilterOptions, got {type(options).__name__}")
    for name in ("num_particles", "max_measurements", "k_max", "downscale"):
        value = getattr(options, name)
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    if options.resampler not in RESAMPLERS:
        raise ValueError(f"resampler: must be one of {sorted(RESAMPLERS)}, got {options.resampler!r}")
    if options.spawn not in SPAWNS:
        raise ValueError(f"spawn: must be one of {list(SPAWNS)}, got {options.spawn!r}")
    if options.observation not in OBSERVATIONS:
        raise ValueError(f"observation: must be one of {list(OBSERVATIONS)}, got {options.observation!r}")
    if options.knn not in KNN_METHODS:
        raise ValueError(f"knn: must be one of {list(KNN_METHODS)}, got {options.knn!r}")
    box = tuple(options.spawn_box)
    if len(box) != 4 or not all(math.isfinite(b) for b in box) or box[0] >= box[1] or box[2] >= box[3]:
        raise ValueError(f"spawn_box: must be finite (x_min, x_max, y_min, y_max) with min < max, got {box!r}")


def _particle_filter(options: FilterOptions, source) -> Filter:
    validate_options(options)
    box = tuple(float(b) for b in options.spawn_box)
    explorers = UniformExplorers(box=box) if options.spawn == "uniform" else GaussianExplorers()
    return Filter(
        motion=RandomWalk(),
        source=source,
        buffer=AgingBuffer(),
        observation=OBSERVATIONS[options.observation](k_max=options.k_max, knn=options.knn),
        estimator=TopFraction(),
        resampling=ESSResampling(resampler=RESAMPLERS[options.resampler]),
        injectors=(explorers,),
        initial=UniformBox(box=box),
        num_particles=options.num_particles,
    )


def heatmap_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """The paper's filter: every pixel above the threshold is a measurement (III-A)."""
    source = PixelSource(max_measurements=options.max_measurements, downscale=options.downscale)
    return _particle_filter(options, source)


def conventional_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """The paper's conventional filter (IV-B): the same particle filter fed one measurement per heat map,
    the centre of the strongest image-space component."""
    return _particle_filter(options, ClusterCentreSource())


def kalman_baseline(options: FilterOptions = FilterOptions()) -> KalmanFilter:
    """The constant-velocity Kalman filter on the cluster centre; only ``spawn_box`` (its prior) applies."""
    validate_options(options)
    box = tuple(float(b) for b in options.spawn_box)
    return KalmanFilter(source=ClusterCentreSource(), initial=UniformBox(box=box))


BITBOTS_BOX = (-18.0, 18.0, -18.0, 18.0)


def bitbots2018(options: FilterOptions = FilterOptions()) -> Filter:
    """The original team's 2018 node (Hamburg Bit-Bots, ``bitbots_world_model``), composed from pieces.

    As its ``config/world_model_config.yaml`` and ``src/ObservationModels.cpp`` set it (commit
    b98d9cf, 2018): every projected pixel a measurement, k = 1 (hard-coded), no aging (the buffer
    holds this step's measurements only: a step without a heat map weights all particles equally),
    no odometry (neither particles nor measurements move with the robot), 2000 particles, systematic
    resampling every step, 20 % explorers drawn uniformly over [-18, 18] x [-18, 18] m (also the
    initial distribution), diffusion 0.1 m per step, each particle's weight floored at 0.001, output
    the weighted mean of the best 50 %. The numbers are :func:`bitbots2018_params`. Of ``options``
    only the measurement search applies (``max_measurements``, ``downscale``, ``k_max``, ``knn``);
    the rest is the node's.
    """
    validate_options(options)
    return Filter(
        motion=DiffusionOnly(),
        source=PixelSource(max_measurements=options.max_measurements, downscale=options.downscale),
        buffer=LatestOnly(),
        observation=Floored(InverseDistance(k_max=options.k_max, knn=options.knn)),
        estimator=TopFraction(),
        resampling=ESSResampling(resampler=RESAMPLERS["systematic"]),
        injectors=(UniformExplorers(box=BITBOTS_BOX),),
        initial=UniformBox(box=BITBOTS_BOX),
        num_particles=2000,
    )


def bitbots2018_params() -> FilterParams:
    """The 2018 node's numbers for :func:`bitbots2018` (the threshold and distance limit are ours)."""
    return FilterParams(
        motion=DiffusionParams(diffusion_std=0.1),
        source=SourceParams(),
        buffer=LatestOnly().default_params(),
        observation=FloorParams(base=InverseDistanceParams(k=1), weight_floor=0.001),
        estimator=TopFractionParams(top_fraction=0.5),
        resampling=ESSParams(resample_threshold=1.0),
        injectors={"explorers": ExplorerParams(explorer_fraction=0.2)},
    )


class Method(NamedTuple):
    """A named method: its model (static) and its default params."""

    model: Any
    params: Any


def _with_defaults(make: Callable[[FilterOptions], Any]) -> Callable[[FilterOptions], Method]:
    def method(options: FilterOptions) -> Method:
        model = make(options)
        return Method(model, model.default_params())

    return method


METHODS: dict[str, Callable[[FilterOptions], Method]] = {
    "heatmap": _with_defaults(heatmap_filter),
    "conventional": _with_defaults(conventional_filter),
    "kalman": _with_defaults(kalman_baseline),
    "bitbots2018": lambda options: Method(bitbots2018(options), bitbots2018_params()),
}


def build(method: str, options: FilterOptions = FilterOptions()) -> Method:
    """The model and default params of a named method with the given static options.

    Raises:
        ValueError: naming ``method`` or the option that is unusable.
    """
    if method not in METHODS:
        raise ValueError(f"method: must be one of {list(METHODS)}, got {method!r}")
    return METHODS[method](options)
