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

from heatpf_jax import params as P
from heatpf_jax.baselines.kalman import KalmanFilter
from heatpf_jax.buffers.aging import AgingBuffer, LatestOnly
from heatpf_jax.estimate.dominant_mode import DominantMode
from heatpf_jax.estimate.modes import GaussianMixtureModes, KMeansModes, MeanShiftModes, NoModes
from heatpf_jax.estimate.top_fraction import TopFraction, TopFractionParams
from heatpf_jax.filter import Filter, FilterParams
from heatpf_jax.injection.birth_weight import BirthWeightedExplorers
from heatpf_jax.injection.explorers import (
    ExplorerParams,
    GaussianExplorers,
    RandomParticles,
    UniformBox,
    UniformExplorers,
)
from heatpf_jax.injection.measurement_explorers import MeasurementExplorers
from heatpf_jax.injection.measurement_seeds import ReacquisitionSeeds
from heatpf_jax.injection.memory_hints import MemoryHints, RedetectionSeeds
from heatpf_jax.injection.support_drop import SupportDropExplorers
from heatpf_jax.memory.track_memory import NoMemory, TrackMemory
from heatpf_jax.motion.constant_velocity import ConstantVelocity
from heatpf_jax.motion.ego import EGO_MOTIONS
from heatpf_jax.motion.mass_inertia import MassInertia
from heatpf_jax.motion.random_walk import DiffusionOnly, DiffusionParams, RandomWalk
from heatpf_jax.motion.rolling_ball import RollingBall
from heatpf_jax.observation.kernels import (
    KNN_METHODS,
    Floored,
    FloorParams,
    GaussianDensity,
    GaussianKernel,
    InverseDistance,
    InverseDistanceParams,
)
from heatpf_jax.observation.range_aware import FootprintTemplate
from heatpf_jax.resampling.clustered import ClusterResampling
from heatpf_jax.resampling.resamplers import RESAMPLERS, ESSParams, ESSResampling
from heatpf_jax.sources.lofted import LoftedSource
from heatpf_jax.sources.pixels import CentroidSource, ClusterCentreSource, PixelSource, SourceParams

__all__ = [
    "BITBOTS_BOX",
    "MEMORIES",
    "METHODS",
    "MODE_FINDERS",
    "MOTIONS",
    "Method",
    "OBSERVATIONS",
    "RESETTINGS",
    "SOURCES",
    "SPAWNS",
    "FilterOptions",
    "bitbots2018",
    "bitbots2018_params",
    "build",
    "conventional_filter",
    "extended_filter",
    "extended_params",
    "heatmap_filter",
    "heatmap_params",
    "paper_filter",
    "kalman_baseline",
    "validate_options",
]

SPAWNS = ("uniform", "gaussian")
SOURCES = ("pixels", "centroids", "lofted")
RESETTINGS = {  # explorers at the measurements (sensor resetting), by name
    "fixed": MeasurementExplorers,
    "support": SupportDropExplorers,
    "birth": BirthWeightedExplorers,
    "seeds": ReacquisitionSeeds,
}
MOTIONS = {  # what moves the particles between heat maps (III-D; Olufs 3.3), by name
    "random_walk": RandomWalk,
    "constant_velocity": ConstantVelocity,
    "mass_inertia": MassInertia,
    "rolling_ball": RollingBall,
}
MEMORIES = ("none", "tracks")
MODE_FINDERS = {
    "none": lambda k: NoModes(),
    "meanshift": lambda k: MeanShiftModes(max_modes=k),
    "kmeans": lambda k: KMeansModes(num_modes=k),
    "gmm": lambda k: GaussianMixtureModes(num_modes=k),
}
OBSERVATIONS = {
    "inverse_distance": InverseDistance,
    "gaussian": GaussianKernel,
    "gaussian_density": GaussianDensity,
    "range_aware": FootprintTemplate,
}
AUTO = "auto"  # a static option left to the method's own choice


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
        observation: ``"auto"`` (the method's own: eq. 1 for ``paper``, ``"range_aware"`` for
            ``heatmap``, ``"gaussian"`` for ``extended``), ``"inverse_distance"`` (eq. 1), ``"gaussian"`` (kernel std
            ``obs_std``) or ``"range_aware"`` (:class:`~heatpf_jax.observation.range_aware.FootprintTemplate`:
            each pixel's kernel follows its ground footprint).
        knn: k-nearest search, ``"auto"`` (default), ``"blocked"`` or ``"dense"``: all exact.
        modes: multi-modal output in ``StepInfo.modes`` (:mod:`heatpf_jax.estimate.modes`): ``"none"``
            (default), ``"meanshift"``, ``"kmeans"`` or ``"gmm"`` (a Gaussian mixture fitted by EM).
        max_modes: K, the number of mode slots.
        ego: what moves the particles, the buffer and the memory's tracks with the robot
            (:mod:`heatpf_jax.motion.ego`): ``"odometry"`` (default), ``"none"``, or the sequence's
            self-localisation ``robot_pose`` weighted by ``pose_confidence`` (Olufs 3.5): ``"pose"``
            (the particles only rotated, as the paper), ``"pose_full"`` (rotated and shifted), and
            ``"pose_unweighted"`` / ``"pose_full_unweighted"`` (the confidence ignored).
        memory: the long-term memory (:mod:`heatpf_jax.memory`, Olufs 3.4): ``"none"`` (default) or
            ``"tracks"`` (a track table of ``max_tracks`` slots fed by the modes, or the estimate when
            ``modes`` is ``"none"``, with hint particles for lost tracks).
        max_tracks: the memory's capacity (16: a track for the ball, the distractors near it and the clutter the
            filter visits; with fewer slots a lost ball's track lost its slot to a new blob among distractors).
        source: what the heat map's pixels become (III-A): ``"auto"`` (the method's own: ``"pixels"`` for
            ``paper`` and ``extended``, ``"lofted"`` for ``heatmap``), ``"pixels"`` (every pixel at or above the
            threshold, where it lies: the paper's source), ``"centroids"`` (every such pixel at its blob's centroid
            in the image, :class:`~heatpf_jax.sources.pixels.CentroidSource`; with ``heatmap`` its blobs that spill
            out of a ground ball's window by more than 1.5 are dropped) or ``"lofted"`` (every such pixel on the ground,
            except those of a blob larger than a ground ball there, which go to the ground point under the ball
            their blob's size places along the ray: :class:`~heatpf_jax.sources.lofted.LoftedSource`, for balls in
            the air; the detector's blob size learned from the heat maps). ``conventional``, ``kalman`` and
            ``bitbots2018`` keep their own.
        motion: what moves the particles between heat maps (III-D): ``"auto"`` (the method's own:
            ``"random_walk"`` for ``paper`` and ``conventional``, ``"constant_velocity"`` for ``heatmap``,
            ``"mass_inertia"`` for ``extended``), ``"random_walk"`` (the paper's: odometry and diffusion),
            ``"constant_velocity"`` (:class:`~heatpf_jax.motion.constant_velocity.ConstantVelocity`),
            ``"mass_inertia"`` (Olufs eq. 4-6) or ``"rolling_ball"``
            (:class:`~heatpf_jax.motion.rolling_ball.RollingBall`: rolling friction, kicks as a jump process).
            ``kalman`` and ``bitbots2018`` keep their own.
        hover_frames: with the ``"lofted"`` source, frames whose blobs read as flying are remembered
            (:mod:`heatpf_jax.sources.hover`: a blob read as flying at a place where one was read so 0.25-1 s before
            lies on the ground); 0 (default): no such test. 16 for a field with static clutter larger than the ball.
        resetting: how ``heatmap`` and ``extended`` draw explorers at the measurements (sensor resetting): ``"auto"``
            (the method's own: ``"seeds"`` for ``heatmap``, ``"fixed"`` for ``extended``), ``"fixed"`` (a fixed share
            every step,
            :class:`~heatpf_jax.injection.measurement_explorers.MeasurementExplorers`) or ``"support"`` (as far as
            the evidence at the estimate has dropped below its recent level, Augmented MCL:
            :class:`~heatpf_jax.injection.support_drop.SupportDropExplorers`) or ``"birth"`` (the fixed share, each
            with its importance weight against a prior that keeps a small chance of the ball being anywhere:
            :class:`~heatpf_jax.injection.birth_weight.BirthWeightedExplorers`) or ``"seeds"`` (the fixed share,
            and as much again at this step's measurements before the weighting on a step where nothing lies near the
            predicted cloud: a ball that reappears is weighed on the heat map that first shows it,
            :class:`~heatpf_jax.injection.measurement_seeds.ReacquisitionSeeds`). The other methods draw none.
    """

    num_particles: int = 500
    max_measurements: int = 1024
    k_max: int = 10
    resampler: str = "systematic"
    spawn: str = "uniform"
    spawn_box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)
    downscale: int = 1
    observation: str = AUTO
    knn: str = "auto"
    modes: str = "none"
    max_modes: int = 3
    ego: str = "odometry"
    memory: str = "none"
    max_tracks: int = 16
    source: str = AUTO
    motion: str = AUTO
    hover_frames: int = 0
    resetting: str = AUTO


def validate_options(options: FilterOptions) -> None:
    """Raises ``ValueError`` naming the option if it is unusable."""
    if not isinstance(options, FilterOptions):
        raise TypeError(f"options: expected FilterOptions, got {type(options).__name__}")
    for name in ("num_particles", "max_measurements", "k_max", "downscale", "max_modes", "max_tracks"):
        value = getattr(options, name)
        if not isinstance(value, int) or isinstance(value, bool) or value < 1:
            raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    hover = options.hover_frames
    if not isinstance(hover, int) or isinstance(hover, bool) or hover < 0:
        raise ValueError(f"hover_frames: must be a non-negative integer, got {hover!r}")
    if options.resampler not in RESAMPLERS:
        raise ValueError(f"resampler: must be one of {sorted(RESAMPLERS)}, got {options.resampler!r}")
    if options.spawn not in SPAWNS:
        raise ValueError(f"spawn: must be one of {list(SPAWNS)}, got {options.spawn!r}")
    if options.source not in (AUTO, *SOURCES):
        raise ValueError(f"source: must be one of {[AUTO, *SOURCES]}, got {options.source!r}")
    if options.motion not in (AUTO, *MOTIONS):
        raise ValueError(f"motion: must be one of {[AUTO, *MOTIONS]}, got {options.motion!r}")
    if options.resetting not in (AUTO, *RESETTINGS):
        raise ValueError(f"resetting: must be one of {[AUTO, *RESETTINGS]}, got {options.resetting!r}")
    if options.observation not in (AUTO, *OBSERVATIONS):
        raise ValueError(f"observation: must be one of {[AUTO, *OBSERVATIONS]}, got {options.observation!r}")
    if options.modes not in MODE_FINDERS:
        raise ValueError(f"modes: must be one of {list(MODE_FINDERS)}, got {options.modes!r}")
    if options.ego not in EGO_MOTIONS:
        raise ValueError(f"ego: must be one of {list(EGO_MOTIONS)}, got {options.ego!r}")
    if options.memory not in MEMORIES:
        raise ValueError(f"memory: must be one of {list(MEMORIES)}, got {options.memory!r}")
    if options.knn not in KNN_METHODS:
        raise ValueError(f"knn: must be one of {list(KNN_METHODS)}, got {options.knn!r}")
    box = tuple(options.spawn_box)
    if len(box) != 4 or not all(math.isfinite(b) for b in box) or box[0] >= box[1] or box[2] >= box[3]:
        raise ValueError(f"spawn_box: must be finite (x_min, x_max, y_min, y_max) with min < max, got {box!r}")


def _particle_filter(options: FilterOptions, source, observation: str = "inverse_distance") -> Filter:
    validate_options(options)
    box = tuple(float(b) for b in options.spawn_box)
    explorers = UniformExplorers(box=box) if options.spawn == "uniform" else GaussianExplorers()
    observation = observation if options.observation == AUTO else options.observation
    return Filter(
        motion=_motion(options, "random_walk"),
        source=source,
        buffer=AgingBuffer(),
        observation=OBSERVATIONS[observation](k_max=options.k_max, knn=options.knn),
        estimator=TopFraction(),
        resampling=ESSResampling(resampler=RESAMPLERS[options.resampler]),
        injectors=(explorers,),
        initial=UniformBox(box=box),
        num_particles=options.num_particles,
        modes=MODE_FINDERS[options.modes](options.max_modes),
        ego=EGO_MOTIONS[options.ego],
        memory=_memory(options),
    )


def _motion(options: FilterOptions, default: str):
    """The motion model named by ``options.motion``, the method's ``default`` when ``"auto"``."""
    return MOTIONS[default if options.motion == AUTO else options.motion]()


def _resetting(options: FilterOptions, default: str = "fixed"):
    """The explorers at the measurements named by ``options.resetting``, the method's ``default`` when ``"auto"``."""
    return RESETTINGS[default if options.resetting == AUTO else options.resetting]()


def _memory(options: FilterOptions):
    return TrackMemory(capacity=options.max_tracks) if options.memory == "tracks" else NoMemory()


def _with_hints(model: Filter) -> Filter:
    """``model`` with memory hints and re-detection seeds as its last injectors when it has a long-term
    memory (Olufs 3.4)."""
    if isinstance(model.memory, NoMemory):
        return model
    return model._replace(injectors=(*model.injectors, MemoryHints(), RedetectionSeeds()))


def _pixels(options: FilterOptions, default: str = "pixels") -> PixelSource | CentroidSource | LoftedSource:
    """The source of every above-threshold pixel: where it lies, at its blob's centroid, or under its ball when
    its blob is a ball in the air (``options.source``, the method's ``default`` when ``"auto"``)."""
    which = default if options.source == AUTO else options.source
    if which == "centroids":
        return CentroidSource(max_measurements=options.max_measurements, downscale=options.downscale)
    if which == "lofted":
        return LoftedSource(max_measurements=options.max_measurements, downscale=options.downscale,
                            hover_frames=options.hover_frames)
    return PixelSource(max_measurements=options.max_measurements, downscale=options.downscale)


def paper_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """The 2019 paper's filter exactly (``--method paper``): every pixel above the threshold is a
    measurement (III-A), eq. (1), aging (III-C), a static-position random walk with odometry (III-D)."""
    return _with_hints(_particle_filter(options, _pixels(options)))


def heatmap_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """The product's heat-map filter (``--method heatmap``): the paper's pipeline (every above-threshold pixel
    a measurement, on the ground, except the pixels of a blob too large for a ground ball there, which go to
    the ground point under the ball in the air that their size places: :class:`~heatpf_jax.sources.lofted.LoftedSource`,
    its detector's blob size learned from the heat maps; ``FilterOptions(source="pixels")`` keeps every pixel
    where it projects, the paper's source) with a velocity state
    (:class:`~heatpf_jax.motion.constant_velocity.ConstantVelocity`) and a range-aware matched filter over the k nearest
    measurements (:class:`~heatpf_jax.observation.range_aware.FootprintTemplate`, each kernel as wide as
    its pixel's ground footprint) instead of eq. (1)'s inverse distance, and explorers drawn from the
    measurements beside the uniform ones, and as many again at the heat map that shows a ball back where the cloud
    predicts none (:class:`~heatpf_jax.injection.measurement_seeds.ReacquisitionSeeds`, ``resetting="seeds"``;
    ``"fixed"`` draws only the former, the default before); its default params are :func:`heatmap_params`."""
    base = _particle_filter(options, _pixels(options, "lofted"), observation="range_aware")
    return _with_hints(base._replace(motion=_motion(options, "constant_velocity"),
                                     injectors=(*base.injectors, _resetting(options, "seeds"))))


def heatmap_params(model: Filter) -> FilterParams:
    """The heat-map filter's defaults: white-noise acceleration 5 m/s^2, new particles' speed std 3 m/s (a
    kicked ball), aging 0.6 per step (chosen on simulated seeds 100-103), and with the centroid source
    (``source="centroids"``) a blob that spills out of its ground-ball window by more than 1.5 refused
    (chosen on the world family's seeds 100-102)."""
    updates = {"motion.accel_std": 5.0, "motion.spawn_speed_std": 3.0, "buffer.aging": 0.6, "modes.bandwidth": 0.1,
               "source.max_spill": 1.5}
    if isinstance(model.motion, RollingBall):  # its kicks, not a large white-noise acceleration, change its speed
        updates = {k: v for k, v in updates.items() if k != "motion.accel_std"}
    if isinstance(model.observation, GaussianKernel):
        updates |= {"observation.k": min(10, model.observation.k_max), "observation.obs_std": 0.05}
    return P.set_by_name(model.default_params(), model.properties(), updates, skip_unknown=True)


def extended_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """Olufs et al.'s combination (``--method extended``): the mass-inertia motion model (eq. 4-6),
    cluster-wise resampling by mean shift with uniform weights per cluster (sec. 3.2, every cluster a
    hypothesis of its own), random particles (50 of 300) and explorers drawn from the measurements
    beside the uniform explorers, and the dominant mode as the output. The heat map is weighted by a
    Gaussian kernel (0.05 m) summed over the k = 10 nearest pixels: unlike ``heatmap``'s range-aware
    template, whose log-domain sum makes the weight ratio of two equal balls exponential in small
    differences of their pixels' activations, a sum of kernels keeps two hypotheses' weights
    comparable (``two_balls``, seeds 100-103: both balls covered on 99 % of the steps against 39 %).
    Its default params are :func:`extended_params`."""
    box = tuple(float(b) for b in options.spawn_box)
    base = _particle_filter(options, _pixels(options), observation="gaussian")
    return _with_hints(base._replace(
        motion=_motion(options, "mass_inertia"),
        resampling=ClusterResampling(resampler=RESAMPLERS[options.resampler], correct=False),
        estimator=DominantMode(),
        injectors=(*base.injectors, RandomParticles(box=box), _resetting(options)),
    ))


def extended_params(model: Filter) -> FilterParams:
    """The extended filter's defaults, chosen on simulated seeds 100-103 of ``two_balls`` (README, "Defaults"):
    clusters and modes of 0.1 m bandwidth (a ball's particle cloud; 0.3 m merged two balls 0.6 m apart),
    at least 20 % of the particles for every cluster, 5 % explorers at the measurements."""
    updates = {"resampling.bandwidth": 0.1, "resampling.min_share": 0.2, "estimator.bandwidth": 0.1,
               "modes.bandwidth": 0.1}
    return P.set_by_name(heatmap_params(model), model.properties(), updates, skip_unknown=True)


def conventional_filter(options: FilterOptions = FilterOptions()) -> Filter:
    """The paper's conventional filter (IV-B): the same particle filter fed one measurement per heat map,
    the centre of the strongest image-space component."""
    return _with_hints(_particle_filter(options, ClusterCentreSource()))


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
        modes=MODE_FINDERS[options.modes](options.max_modes),
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


def _bitbots_method(model: Filter) -> "Method":
    return Method(model, bitbots2018_params()._replace(modes=model.modes.default_params()))


class Method(NamedTuple):
    """A named method: its model (static) and its default params."""

    model: Any
    params: Any


def _tuned(model, make_params: Callable[[Any], FilterParams]) -> Method:
    return Method(model, make_params(model))


def _with_defaults(make: Callable[[FilterOptions], Any]) -> Callable[[FilterOptions], Method]:
    def method(options: FilterOptions) -> Method:
        model = make(options)
        return Method(model, model.default_params())

    return method


METHODS: dict[str, Callable[[FilterOptions], Method]] = {
    "heatmap": lambda options: _tuned(heatmap_filter(options), heatmap_params),
    "paper": _with_defaults(paper_filter),
    "extended": lambda options: _tuned(extended_filter(options), extended_params),
    "conventional": _with_defaults(conventional_filter),
    "kalman": _with_defaults(kalman_baseline),
    "bitbots2018": lambda options: _bitbots_method(bitbots2018(options)),
}


def build(method: str, options: FilterOptions = FilterOptions()) -> Method:
    """The model and default params of a named method with the given static options.

    Raises:
        ValueError: naming ``method`` or the option that is unusable.
    """
    if method not in METHODS:
        raise ValueError(f"method: must be one of {list(METHODS)}, got {method!r}")
    return METHODS[method](options)
