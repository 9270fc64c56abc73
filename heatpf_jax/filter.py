"""The heat-map particle filter (Fig. 2): ``init``, ``step`` and ``run``.

One filter step, in the order of the sequence-file contract:

1. odometry moves the particles (with motion-scaled noise) and the buffered
   measurements (without) into the base frame of this step; every particle is
   diffused by Gaussian noise (III-D); both noises come from one draw
   (:func:`~heatpf_jax.motion.move_and_diffuse`);
2. a new heat map, if any, is projected (III-A) and replaces the buffer when it
   yields a measurement; otherwise the buffer ages (III-C, eq. 2);
3. particles are weighted by eq. (1) (III-B) and the weights multiplied into
   the carried ones;
4. the estimate is the weighted mean and covariance of the best
   ``top_fraction`` of the weighted particles (III-F);
5. particles are resampled when the effective sample size falls below
   ``resample_threshold * N`` (the default 1.0 resamples every step, as SIR),
   then the ``explorer_fraction`` with the lowest support respawn as explorers (III-E).

Steps 4 and 5 share one sort of the particles by decreasing weight: the kept
``top_fraction`` are the first particles, and since resampling indices are
non-decreasing the copies with the lowest support end up in the last slots,
which become the explorers. A step that does not resample leaves every
particle in its slot.

``FilterParams`` holds every tunable number as an array, so a batch of them (a
leading axis on every field) can be swept with ``jax.vmap``; ``FilterConfig``
holds static sizes and choices.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from heatpf_jax.clusters import cluster_measurement
from heatpf_jax.estimate import Estimate, sorted_top_fraction_estimate
from heatpf_jax.explorers import explorer_slots, spawn_gaussian, spawn_uniform
from heatpf_jax.kalman import KalmanState, kalman_init, kalman_odometry, kalman_predict, kalman_update
from heatpf_jax.measurements import (
    Measurements,
    empty_measurements,
    move_measurements,
    project_heatmap,
    update_buffer,
)
from heatpf_jax.motion import move_and_diffuse
from heatpf_jax.observation import KNN_METHODS, gaussian_particle_weights, particle_weights
from heatpf_jax.resampling import RESAMPLERS, effective_sample_size
from heatpf_jax.sequence import Sequence

__all__ = [
    "FilterConfig",
    "FilterParams",
    "FilterState",
    "RunResult",
    "StepInfo",
    "StepInputs",
    "init",
    "kalman_init_state",
    "kalman_step",
    "measure",
    "run",
    "stack_params",
    "step",
    "validate_config",
    "validate_params",
]

METHODS = ("heatmap", "conventional", "kalman")
OBSERVATIONS = ("inverse_distance", "gaussian")
SPAWNS = ("uniform", "gaussian")


class FilterConfig(NamedTuple):
    """Static sizes and choices (hashable; changing one recompiles).

    Attributes:
        num_particles: N. 500, as the original team ran the filter.
        max_measurements: size of the measurement buffer; the strongest pixels are kept.
        k_max: static upper bound on the traced ``FilterParams.k``: k can be swept from 1 to
            ``k_max`` without recompiling. The search costs grow with it even when k is smaller
            (its arrays are sized for ``k_max``), so keep it near the largest k you use.
        resampler: ``"systematic"`` (default), ``"stratified"``, ``"multinomial"`` or ``"residual"``.
        spawn: explorer spawn distribution, ``"uniform"`` over ``spawn_box`` (default)
            or ``"gaussian"`` around the current estimate with ``FilterParams.explorer_std``.
        spawn_box: ``(x_min, x_max, y_min, y_max)`` in the base frame, metres: where
            particles start and uniform explorers spawn. The default covers what a
            humanoid's head camera sees of a RoboCup field in front of it.
        downscale: integer block-averaging of the heat map before projection (III-A).
        observation: ``"inverse_distance"`` (eq. 1, default) or ``"gaussian"``
            (Gaussian kernel with ``FilterParams.obs_std``).
        method: ``"heatmap"`` (the paper's filter, default); ``"conventional"``: the
            same particle filter fed one measurement per heat map, the centre of the
            strongest image-space cluster (IV-B, :mod:`heatpf_jax.clusters`), with a
            one-slot buffer; ``"kalman"``: a constant-velocity Kalman filter on that
            same measurement (:mod:`heatpf_jax.kalman`).
        knn: k-nearest search of eq. (1): ``"auto"`` (default: the exact blocked kernel
            of :mod:`heatpf_jax.knn` for buffers of 256 slots or more, the plain ``top_k``
            below), ``"blocked"`` or ``"dense"``. All give the same weights.
    """

    num_particles: int = 500
    max_measurements: int = 1024
    k_max: int = 10
    resampler: str = "systematic"
    spawn: str = "uniform"
    spawn_box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)
    downscale: int = 1
    observation: str = "inverse_distance"
    method: str = "heatmap"
    knn: str = "auto"

    @property
    def buffer_size(self) -> int:
        """Slots in the measurement buffer: one for the single-measurement baselines."""
        return self.max_measurements if self.method == "heatmap" else 1


class FilterParams(NamedTuple):
    """Every tunable number of the filter. Fields are scalars (or arrays with a
    leading batch axis for sweeps); ``run`` converts Python numbers to arrays.

    Attributes:
        k: neighbours per particle in eq. (1), ``1 <= k <= k_max`` (int).
        threshold: minimum heat-map activation projected (III-A).
        aging: v, weight subtracted from buffered measurements per step without input (eq. 2).
        min_weight: l, measurements with a weight below it are removed (III-C).
        diffusion_std: Gaussian diffusion per filter step, metres (III-D).
        odom_trans_noise: odometry translation noise, fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, fraction of the angle turned.
        explorer_fraction: share of lowest-support particles respawned (III-E); 5 % in the paper.
        explorer_std: std of the Gaussian spawn distribution, metres.
        top_fraction: share of best particles averaged for the output (III-F); 95 % in the paper.
        resample_threshold: resample when ESS < resample_threshold * N.
        min_distance: distance floor of eq. (1), metres.
        max_distance: projected pixels farther from the robot are dropped, metres.
        obs_std: kernel std of the ``"gaussian"`` observation model, metres.
        kalman_accel_std: white-noise acceleration of the ``"kalman"`` baseline, m/s^2.
        kalman_meas_std: measurement noise of the ``"kalman"`` baseline, metres.
    """

    k: int = 1
    threshold: float = 0.3
    aging: float = 0.3
    min_weight: float = 0.1
    diffusion_std: float = 0.2
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1
    explorer_fraction: float = 0.05
    explorer_std: float = 0.5
    top_fraction: float = 0.95
    resample_threshold: float = 1.0
    min_distance: float = 0.01
    max_distance: float = 12.0
    obs_std: float = 0.2
    kalman_accel_std: float = 3.0
    kalman_meas_std: float = 0.1

    def as_arrays(self) -> FilterParams:
        """Every field as a JAX array (``int32`` for ``k``, ``float32`` otherwise), as ``step`` expects."""
        return FilterParams(
            *(
                jnp.asarray(v, jnp.int32 if name in _INT_FIELDS else jnp.float32)
                for name, v in zip(FilterParams._fields, self, strict=True)
            )
        )


_INT_FIELDS = ("k",)


def stack_params(params_list: list[FilterParams]) -> FilterParams:
    """Stacks parameter sets along a new leading axis, for ``jax.vmap`` sweeps."""
    arrays = [p.as_arrays() for p in params_list]
    return jax.tree.map(lambda *xs: jnp.stack(xs), *arrays)


class FilterState(NamedTuple):
    """The carried state of the filter.

    Attributes:
        particles: ``float32 [N, 2]`` positions in the current base frame.
        log_weights: ``float32 [N]`` normalised log weights (uniform after resampling).
        buffer: the measurement buffer (size ``max_measurements``).
        mean: ``float32 [2]`` the last estimate (centre of Gaussian explorers).
        t: ``int32 []`` number of steps taken.
    """

    particles: Float[Array, "n 2"]
    log_weights: Float[Array, " n"]
    buffer: Measurements
    mean: Float[Array, "2"]
    t: Int[Array, ""]


class StepInputs(NamedTuple):
    """What one filter step receives.

    Attributes:
        heatmap: ``float32 [H, W]`` activations (ignored unless ``has_heatmap``).
        has_heatmap: ``bool []``.
        cam_to_base: ``float32 [4, 4]`` camera pose at this step.
        odometry: ``float32 [3]`` motion since the previous step, ``(dx, dy, dtheta)``.
        intrinsics: ``float32 [4]`` ``(fx, fy, cx, cy)``.
        plane_height: ``float32 []`` the ball radius.
        dt: ``float32 []`` the filter period, seconds (used by the Kalman baseline).
    """

    heatmap: Float[Array, "h w"]
    has_heatmap: Bool[Array, ""]
    cam_to_base: Float[Array, "4 4"]
    odometry: Float[Array, "3"]
    intrinsics: Float[Array, "4"]
    plane_height: Float[Array, ""]
    dt: Float[Array, ""]


class StepInfo(NamedTuple):
    """Per-step output and diagnostics.

    Attributes:
        mean: ``[2]`` top-fraction mean (the filter's estimate).
        cov: ``[2, 2]`` top-fraction covariance.
        weighted_mean: ``[2]`` weighted mean of all particles.
        ess: ``[]`` effective sample size before resampling.
        num_valid: ``int32 []`` valid measurements in the buffer.
        resampled: ``bool []`` whether this step resampled.
    """

    mean: Float[Array, "2"]
    cov: Float[Array, "2 2"]
    weighted_mean: Float[Array, "2"]
    ess: Float[Array, ""]
    num_valid: Int[Array, ""]
    resampled: Bool[Array, ""]


class RunResult(NamedTuple):
    """What :func:`run` returns: ``info`` stacked over steps (leading axis T) and the final state
    (a :class:`FilterState`, or a :class:`~heatpf_jax.kalman.KalmanState` for ``method="kalman"``)."""

    info: StepInfo
    final_state: FilterState | KalmanState


def validate_config(config: FilterConfig) -> None:
    """Raises ``ValueError`` naming the field if ``config`` is unusable."""
    if not isinstance(config, FilterConfig):
        raise TypeError(f"config: expected FilterConfig, got {type(config).__name__}")
    for name in ("num_particles", "max_measurements", "k_max", "downscale"):
        value = getattr(config, name)
        if not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name}: must be a positive integer, got {value!r}")
    if config.resampler not in RESAMPLERS:
        raise ValueError(f"resampler: must be one of {sorted(RESAMPLERS)}, got {config.resampler!r}")
    if config.spawn not in SPAWNS:
        raise ValueError(f"spawn: must be one of {list(SPAWNS)}, got {config.spawn!r}")
    if config.method not in METHODS:
        raise ValueError(f"method: must be one of {list(METHODS)}, got {config.method!r}")
    if config.knn not in KNN_METHODS:
        raise ValueError(f"knn: must be one of {list(KNN_METHODS)}, got {config.knn!r}")
    if config.observation not in OBSERVATIONS:
        raise ValueError(f"observation: must be one of {list(OBSERVATIONS)}, got {config.observation!r}")
    box = tuple(config.spawn_box)
    if len(box) != 4 or not all(math.isfinite(b) for b in box) or box[0] >= box[1] or box[2] >= box[3]:
        raise ValueError(f"spawn_box: must be finite (x_min, x_max, y_min, y_max) with min < max, got {box!r}")


_RANGES = {
    # name: (low, high, low inclusive, high inclusive)
    "threshold": (0.0, 1.0, True, True),
    "aging": (0.0, math.inf, True, False),
    "min_weight": (0.0, math.inf, True, False),
    "diffusion_std": (0.0, math.inf, True, False),
    "odom_trans_noise": (0.0, math.inf, True, False),
    "odom_rot_noise": (0.0, math.inf, True, False),
    "explorer_fraction": (0.0, 1.0, True, False),
    "explorer_std": (0.0, math.inf, False, False),
    "top_fraction": (0.0, 1.0, False, True),
    "resample_threshold": (0.0, 1.0, True, True),
    "min_distance": (0.0, math.inf, False, False),
    "max_distance": (0.0, math.inf, False, True),
    "obs_std": (0.0, math.inf, False, False),
    "kalman_accel_std": (0.0, math.inf, True, False),
    "kalman_meas_std": (0.0, math.inf, False, False),
}


def validate_params(params: FilterParams, config: FilterConfig) -> None:
    """Raises ``ValueError`` naming the field if a concrete parameter is out of range.

    Works on single sets and on batches (every element is checked). Traced
    values are skipped.
    """
    if not isinstance(params, FilterParams):
        raise TypeError(f"params: expected FilterParams, got {type(params).__name__}")
    for name, value in zip(FilterParams._fields, params, strict=True):
        if isinstance(value, jax.core.Tracer):
            continue
        arr = np.asarray(value, dtype=np.float64)
        if not np.all(np.isfinite(arr)) and not (name == "max_distance" and np.all(~np.isnan(arr))):
            raise ValueError(f"{name}: must be finite, got {value!r}")
        if name == "k":
            if np.any(arr != np.round(arr)) or np.any(arr < 1) or np.any(arr > config.k_max):
                raise ValueError(f"k: must be an integer in [1, k_max={config.k_max}], got {value!r}")
            continue
        low, high, low_in, high_in = _RANGES[name]
        ok_low = arr >= low if low_in else arr > low
        ok_high = arr <= high if high_in else arr < high
        if not (np.all(ok_low) and np.all(ok_high)):
            lo = "[" if low_in else "("
            hi = "]" if high_in else ")"
            raise ValueError(f"{name}: must lie in {lo}{low}, {high}{hi}, got {value!r}")


def init(key: PRNGKeyArray, config: FilterConfig, params: FilterParams) -> FilterState:
    """Draws the initial particles uniformly over ``config.spawn_box`` (Fig. 2, initial distribution).

    Args:
        key: PRNG key.
        config: static configuration.
        params: filter parameters (unused by the uniform initial distribution;
            kept so every initial distribution has the same signature).

    Returns:
        A :class:`FilterState` with uniform weights and an empty buffer.
    """
    del params
    n = config.num_particles
    particles = spawn_uniform(key, n, config.spawn_box)
    return FilterState(
        particles=particles,
        log_weights=jnp.full((n,), -math.log(n), jnp.float32),
        buffer=empty_measurements(config.buffer_size),
        mean=jnp.mean(particles, axis=0),
        t=jnp.zeros((), jnp.int32),
    )


def _log(x: Float[Array, "..."]) -> Float[Array, "..."]:
    """log with log(0) = -inf and finite gradients elsewhere."""
    positive = x > 0
    return jnp.where(positive, jnp.log(jnp.where(positive, x, 1.0)), -jnp.inf)


def _normalise_log(log_w: Float[Array, " n"]) -> Float[Array, " n"]:
    total = jax.nn.logsumexp(log_w)
    n = log_w.shape[0]
    return jnp.where(jnp.isfinite(total), log_w - total, jnp.full_like(log_w, -math.log(n)))


def _order_by_weight(weights: Float[Array, " n"]) -> Int[Array, " n"]:
    """Particle indices by decreasing weight, from one sort of ``int32`` keys.

    A single-operand integer sort is about three times faster on XLA:CPU than an argsort
    (which sorts a key and an index payload with a compiled comparator). The key is the
    weight's bit pattern (monotone for non-negative floats) with its ``ceil(log2 n)`` low
    bits replaced by the index, so weights that agree to within ``2**(ceil(log2 n) - 24)``
    relative (6e-5 for 500 particles) are ordered by index, as exact ties are. Resampling
    is valid in any order; the top-fraction estimate and the explorer choice only move
    between such near-equal weights.
    """
    n = weights.shape[0]
    bits = max(1, (n - 1).bit_length())
    if bits > 16:  # the key would lose more than half of the mantissa: sort exactly
        return jnp.argsort(-weights, stable=True).astype(jnp.int32)
    low = (1 << bits) - 1
    # Equal weight bits: the larger (low - index), i.e. the smaller index, comes first. ~key sorts
    # ascending exactly as key sorts descending.
    key = (lax.bitcast_convert_type(weights, jnp.int32) & ~low) | (low - lax.iota(jnp.int32, n))
    return low - (~jnp.sort(~key) & low)


def _observe(particles, buffer: Measurements, params: FilterParams, config: FilterConfig):
    if config.observation == "gaussian":
        return gaussian_particle_weights(
            particles, buffer, params.k, std=params.obs_std, k_max=config.k_max, method=config.knn
        )
    return particle_weights(
        particles, buffer, params.k, k_max=config.k_max, min_distance=params.min_distance, method=config.knn
    )


def measure(inputs: StepInputs, params: FilterParams, config: FilterConfig) -> Measurements:
    """This step's measurements from its heat map: every pixel (III-A), or one cluster centre (IV-B)."""
    if config.method == "heatmap":
        return project_heatmap(
            inputs.heatmap,
            inputs.intrinsics,
            inputs.cam_to_base,
            threshold=params.threshold,
            plane_height=inputs.plane_height,
            max_measurements=config.max_measurements,
            max_distance=params.max_distance,
            downscale=config.downscale,
        )
    return cluster_measurement(
        inputs.heatmap,
        inputs.intrinsics,
        inputs.cam_to_base,
        threshold=params.threshold,
        plane_height=inputs.plane_height,
        size=config.buffer_size,
        max_distance=params.max_distance,
    )


def step(
    key: PRNGKeyArray,
    state: FilterState,
    inputs: StepInputs,
    params: FilterParams,
    config: FilterConfig,
) -> tuple[FilterState, StepInfo]:
    """One particle-filter step (see the module docstring for the order).

    For ``config.method == "kalman"`` use :func:`kalman_step`; :func:`run` dispatches.

    Args:
        key: PRNG key.
        state: the previous state.
        inputs: this step's heat map, pose and odometry.
        params: filter parameters (arrays; traced under ``jit``/``vmap``).
        config: static configuration.

    Returns:
        ``(new_state, info)``.
    """
    n = config.num_particles
    k_move, k_res, k_exp = jax.random.split(key, 3)

    # 1. Movement model (III-D), for particles and buffered measurements: odometry noise and
    #    diffusion in one draw of 3 normals per particle (the same distribution as two draws).
    particles = move_and_diffuse(
        k_move,
        state.particles,
        inputs.odometry,
        params.odom_trans_noise,
        params.odom_rot_noise,
        params.diffusion_std,
    )
    buffer = move_measurements(state.buffer, inputs.odometry)

    # 2. New measurements (III-A) or aging (III-C, eq. 2).
    new = lax.cond(
        inputs.has_heatmap,
        lambda _: measure(inputs, params, config),
        lambda _: empty_measurements(config.buffer_size),
        None,
    )
    buffer = update_buffer(buffer, new, inputs.has_heatmap, params.aging, params.min_weight)

    # 3. Observation model (III-B, eq. 1).
    likelihood = _observe(particles, buffer, params, config)
    log_w = _normalise_log(state.log_weights + _log(likelihood))
    weights = jnp.exp(log_w)

    # One sort by decreasing weight serves the output, resampling and the explorers.
    order = _order_by_weight(weights)
    sorted_particles, sorted_weights = particles[order], weights[order]

    # 4. Output (III-F): the best top_fraction are the first ones.
    est: Estimate = sorted_top_fraction_estimate(sorted_particles, sorted_weights, params.top_fraction)

    # 5. Resampling and explorers (III-E). Resampling indices are non-decreasing, so after
    #    resampling the sorted particles the last slots hold the copies with the lowest support:
    #    they respawn as explorers. Without resampling the particles keep their slots (permuting
    #    them would hand each one another particle's noise next step, so a loss would jump
    #    whenever two weights swap ranks) and the explorers are the last-ranked ones.
    ess = effective_sample_size(weights)
    resampled = ess < params.resample_threshold * n
    idx = RESAMPLERS[config.resampler](k_res, sorted_weights, n)
    particles = jnp.where(resampled, sorted_particles[idx], particles)
    log_w = jnp.where(resampled, jnp.full_like(log_w, -math.log(n)), log_w)
    slots = jnp.arange(n, dtype=jnp.int32)
    rank = jnp.zeros((n,), jnp.int32).at[order].set(slots, unique_indices=True)
    last = explorer_slots(n, params.explorer_fraction)
    explorers = jnp.where(resampled, last, last[rank])
    if config.spawn == "gaussian":
        spawned = spawn_gaussian(k_exp, n, est.mean, params.explorer_std)
    else:
        spawned = spawn_uniform(k_exp, n, config.spawn_box)
    particles = jnp.where(explorers[:, None], spawned, particles)
    log_w = _normalise_log(jnp.where(explorers, -math.log(n), log_w))

    new_state = FilterState(particles=particles, log_weights=log_w, buffer=buffer, mean=est.mean, t=state.t + 1)
    info = StepInfo(
        mean=est.mean,
        cov=est.cov,
        weighted_mean=est.weighted_mean,
        ess=ess,
        num_valid=jnp.sum(buffer.valid).astype(jnp.int32),
        resampled=resampled,
    )
    return new_state, info


def kalman_init_state(config: FilterConfig) -> KalmanState:
    """The Kalman baseline's prior: centred on ``spawn_box`` with a std of half its larger side."""
    x0, x1, y0, y1 = config.spawn_box
    return kalman_init(jnp.array([(x0 + x1) / 2, (y0 + y1) / 2], jnp.float32), jnp.float32(max(x1 - x0, y1 - y0) / 2))


def kalman_step(
    state: KalmanState, inputs: StepInputs, params: FilterParams, config: FilterConfig
) -> tuple[KalmanState, StepInfo]:
    """One step of the Kalman baseline: odometry, prediction, update with the cluster measurement.

    Its :class:`StepInfo` has ``ess = 0`` and ``resampled = False`` (no particles).
    """
    state = kalman_odometry(state, inputs.odometry, params.odom_trans_noise, params.odom_rot_noise)
    state = kalman_predict(state, inputs.dt, params.kalman_accel_std)
    new = lax.cond(
        inputs.has_heatmap,
        lambda _: measure(inputs, params, config),
        lambda _: empty_measurements(config.buffer_size),
        None,
    )
    state = kalman_update(state, new.xy[0], new.valid[0], params.kalman_meas_std)
    info = StepInfo(
        mean=state.mean[:2],
        cov=state.cov[:2, :2],
        weighted_mean=state.mean[:2],
        ess=jnp.zeros((), jnp.float32),
        num_valid=new.valid[0].astype(jnp.int32),
        resampled=jnp.zeros((), bool),
    )
    return state, info


class _ScanInputs(NamedTuple):
    key: PRNGKeyArray
    heatmap: Float[Array, "h w"]
    has_heatmap: Bool[Array, ""]
    cam_to_base: Float[Array, "4 4"]
    odometry: Float[Array, "3"]


def _run(key: PRNGKeyArray, sequence: Sequence, params: FilterParams, config: FilterConfig) -> RunResult:
    k_init, k_steps = jax.random.split(key)
    num_steps = sequence.heatmaps.shape[0]
    intrinsics = jnp.asarray(sequence.intrinsics, jnp.float32)
    plane_height = jnp.asarray(sequence.ball_radius, jnp.float32)
    dt = jnp.asarray(sequence.dt, jnp.float32)

    def inputs_of(x: _ScanInputs) -> StepInputs:
        return StepInputs(
            heatmap=x.heatmap,
            has_heatmap=x.has_heatmap,
            cam_to_base=x.cam_to_base,
            odometry=x.odometry,
            intrinsics=intrinsics,
            plane_height=plane_height,
            dt=dt,
        )

    if config.method == "kalman":
        state = kalman_init_state(config)

        def body(carry, x: _ScanInputs):
            return kalman_step(carry, inputs_of(x), params, config)
    else:
        state = init(k_init, config, params)

        def body(carry, x: _ScanInputs):
            return step(x.key, carry, inputs_of(x), params, config)

    xs = _ScanInputs(
        key=jax.random.split(k_steps, num_steps),
        heatmap=jnp.asarray(sequence.heatmaps, jnp.float32),
        has_heatmap=jnp.asarray(sequence.has_heatmap, bool),
        cam_to_base=jnp.asarray(sequence.cam_to_base, jnp.float32),
        odometry=jnp.asarray(sequence.odometry, jnp.float32),
    )
    final_state, info = lax.scan(body, state, xs)
    return RunResult(info=info, final_state=final_state)


_run_jit = jax.jit(_run, static_argnames="config")


def run(key: PRNGKeyArray, sequence: Sequence, params: FilterParams, config: FilterConfig) -> RunResult:
    """Rolls the filter over a whole sequence with ``lax.scan`` (jitted once per config and shapes).

    Each heat map is projected inside the step, so ``params.threshold`` stays a
    traced parameter. Row 0 of the odometry is ignored (the first step has no
    previous base frame). To sweep, ``jax.vmap`` :func:`run` over a batch of
    params (see :func:`stack_params`); under ``vmap``/``jit`` the eager checks
    are skipped for traced values.

    Args:
        key: PRNG key.
        sequence: a :class:`~heatpf_jax.sequence.Sequence` (see ``load_sequence``).
        params: :class:`FilterParams`.
        config: :class:`FilterConfig` (static).

    Returns:
        :class:`RunResult` with per-step :class:`StepInfo` (leading axis T).
    """
    validate_config(config)
    validate_params(params, config)
    params = params.as_arrays()
    odometry = jnp.asarray(sequence.odometry, jnp.float32).at[0].set(0.0)
    # Ground truth is not an input: dropping it keeps one compilation with or without it.
    sequence = sequence._replace(odometry=odometry, ground_truth=None)
    return _run_jit(key, sequence, params, config)
