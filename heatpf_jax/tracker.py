"""``Tracker``: a filter stepped one tick at a time, for a robot's control loop.

:func:`heatpf_jax.run` rolls a model over a recorded sequence; a robot instead gets one heat map (or
none) per tick. A :class:`Tracker` holds the model, its params (converted once), the camera constants
and the carried state, and compiles the step once when it is built::

    tracker = Tracker(jax.random.key(0), heatmap_shape=(150, 200), intrinsics=(143.0, 143.0, 99.5, 74.5),
                      plane_height=0.075, dt=0.1)
    est = tracker.update(heatmap, cam_to_base, odometry=(dx, dy, dtheta))  # heatmap=None: no new map
    x, y = np.asarray(est.mean)

Keys are derived as :func:`~heatpf_jax.run` derives them: ``k_init, k_steps = jax.random.split(key)``
and ``model.init(k_init, params)``. The key of step ``t`` (``t = 0, 1, ...`` since construction or
:meth:`Tracker.reset`) is

* with ``num_steps=T``: ``jax.random.split(k_steps, T)[t]``, exactly ``run``'s, so a tracker fed a
  ``T``-step sequence step by step gives ``run``'s estimates; it refuses a step ``t >= T``;
* with ``num_steps=None`` (the robot default, no end known): ``jax.random.fold_in(k_steps, t)``,
  statistically equivalent but not ``run``'s draws.

Like ``run``, the first step after construction or a reset ignores its odometry (there is no
previous base frame).

**Starting fast.** The step is compiled inside JAX's persistent compilation cache
(:func:`heatpf_jax.io.cache.compilation_cache`, the same directory and the same opt-outs as the ``heatpf``
command: ``$HEATPF_CACHE_DIR``, ``HEATPF_NO_CACHE=1``, or ``cache=False``), so the second start of a robot's
process loads the compiled step instead of compiling it again. JAX's cache settings are restored after the
construction: the rest of the process is left as it was.
"""

from __future__ import annotations

import os
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from heatpf_jax import params as P
from heatpf_jax.estimate.top_fraction import Estimate
from heatpf_jax.io.cache import compilation_cache
from heatpf_jax.motion.ego import pose_deltas
from heatpf_jax.pieces import StepInputs
from heatpf_jax.rollout import validate_params

__all__ = ["Tracker"]


class _Constants(NamedTuple):
    """Per-tracker inputs that never change between ticks (device arrays built once)."""

    intrinsics: Float[Array, "4"]
    plane_height: Float[Array, ""]
    dt: Float[Array, ""]


def _tick(
    model,
    fold: bool,
    step_keys: PRNGKeyArray,
    t: Int[Array, ""],
    state: Any,
    heatmap: Float[Array, "h w"],
    has_heatmap: Bool[Array, ""],
    cam_to_base: Float[Array, "4 4"],
    odometry: Float[Array, "3"],
    pose_delta: Float[Array, "3"],
    pose_confidence: Float[Array, ""],
    constants: _Constants,
    params: Any,
):
    """One tick: the step's key, ``run``'s zero odometry at ``t = 0``, ``model.step``, ``t + 1``."""
    # fold: step_keys is k_steps itself; otherwise it is jax.random.split(k_steps, T), indexed by t.
    key = jax.random.fold_in(step_keys, t) if fold else step_keys[t]
    inputs = StepInputs(
        heatmap=heatmap,
        has_heatmap=has_heatmap,
        cam_to_base=cam_to_base,
        odometry=jnp.where(t > 0, odometry, jnp.zeros_like(odometry)),
        intrinsics=constants.intrinsics,
        plane_height=constants.plane_height,
        dt=constants.dt,
        pose_delta=pose_delta,
        pose_confidence=pose_confidence,
    )
    state, info = model.step(key, state, inputs, params)
    return state, info, t + 1


# One cache for every tracker: two trackers of equal models and shapes share the compilation.
_tick_jit = jax.jit(_tick, static_argnums=(0, 1))
_init_jit = jax.jit(lambda model, key, params: model.init(key, params), static_argnums=0)


def _is_key(key) -> bool:
    if not isinstance(key, jax.Array):
        return False
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        return key.ndim == 0
    return key.dtype == jnp.uint32 and key.shape == (2,)  # a raw jax.random.PRNGKey


def _positive_int(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool) and value >= 1


def _floats(name: str, value, shape: tuple[int, ...]) -> np.ndarray:
    try:
        arr = np.asarray(value, np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected numbers of shape {shape}, got {value!r}") from None
    if arr.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: must be finite, got {arr.tolist()}")
    return arr


def _check_model(model) -> None:
    missing = [m for m in ("init", "step", "default_params", "properties", "validate") if not hasattr(model, m)]
    if missing:
        hint = " (a Method: pass method.model and method.params)" if hasattr(model, "model") else ""
        raise ValueError(f"model: expected a model with init/step/default_params/properties/validate, "
                         f"got {type(model).__name__} without {', '.join(missing)}{hint}")
    try:
        hash(model)
    except TypeError:
        raise ValueError(f"model: must be hashable (it is jit's static argument), got {type(model).__name__}") from None
    try:
        model.validate()
    except ValueError as err:
        raise ValueError(f"model: {err}") from None


def _check_params(params, model) -> None:
    try:
        validate_params(params, model)
    except (TypeError, ValueError) as err:
        raise ValueError(f"params: {err}") from None
    leaves = jax.tree.leaves(params, is_leaf=lambda x: x is None)
    for name, leaf in zip(P.leaf_names(model.properties()), leaves, strict=True):
        if np.ndim(leaf) != 0:
            raise ValueError(f"params: one parameter set expected, {name} has shape {np.shape(leaf)} (a batch?)")


def _as_f32(name: str, value, shape: tuple[int, ...]):
    """``value`` as float32 of ``shape`` without leaving the device it is on (a cheap check, no copy when it fits)."""
    if isinstance(value, jax.Array):
        if value.dtype != jnp.float32:
            value = value.astype(jnp.float32)
    else:
        value = np.asarray(value, np.float32)
    if value.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {value.shape}")
    return value


class Tracker:
    """A model stepped one tick at a time: compiled once, state carried between calls.

    Built once per camera set-up; it checks every argument (one-line ``ValueError`` naming it) before
    anything compiles, converts the params to arrays, initialises the state, then compiles and warms up
    the step with two dummy ticks (a heat map, then none) whose results are thrown away (the state is
    immutable, so the real one is untouched). Every :meth:`update` then reuses that compilation: a
    missing heat map is a zero map of the same shape with ``has_heatmap`` False. See the module
    docstring for how keys are derived.

    Args:
        key: PRNG key (split as :func:`heatpf_jax.run` splits it).
        model: a model with ``init``/``step`` (a :class:`~heatpf_jax.filter.Filter`, a
            :class:`~heatpf_jax.baselines.KalmanFilter`, ...); ``None``: the ``heatmap`` method
            (``hp.build("heatmap")``).
        params: the model's params; ``None``: the ``heatmap`` method's params when ``model`` is ``None``,
            else ``model.default_params()``.
        heatmap_shape: ``(H, W)``, rows and columns of every heat map (a 200 x 150 map is ``(150, 200)``).
        intrinsics: ``(fx, fy, cx, cy)`` in heat-map pixels.
        plane_height: the ball radius, metres (``>= 0``).
        dt: the filter period, seconds (``> 0``).
        num_steps: ``T`` to draw ``run``'s keys for a ``T``-step sequence (and refuse more steps);
            ``None`` (default) for an open-ended loop (``fold_in`` keys).
        cache: compile inside JAX's persistent compilation cache: ``True`` (default) in the environment's
            directory (:func:`heatpf_jax.io.cache.cache_directory`; ``HEATPF_NO_CACHE=1`` turns it off), a path
            for that directory, ``False`` to leave JAX's cache settings alone.

    Raises:
        ValueError: an argument is unusable; the message starts with its name.
    """

    def __init__(
        self,
        key: PRNGKeyArray,
        model=None,
        params=None,
        *,
        heatmap_shape: tuple[int, int],
        intrinsics: Float[ArrayLike, "4"],
        plane_height: float,
        dt: float,
        num_steps: int | None = None,
        cache: bool | str | os.PathLike = True,
    ) -> None:
        if not _is_key(key):
            raise ValueError(f"key: expected a PRNG key (jax.random.key(seed)), got {type(key).__name__} "
                             f"{getattr(key, 'dtype', '')}{list(np.shape(key))}")
        method_params = None
        if model is None:
            from heatpf_jax.presets import build

            model, method_params = build("heatmap")
        _check_model(model)
        if params is None:
            params = model.default_params() if method_params is None else method_params
        _check_params(params, model)
        shape = tuple(heatmap_shape) if isinstance(heatmap_shape, tuple | list) else None
        if shape is None or len(shape) != 2 or not all(_positive_int(s) for s in shape):
            raise ValueError(f"heatmap_shape: expected (H, W), two positive integers, got {heatmap_shape!r}")
        shape = (int(shape[0]), int(shape[1]))
        factor = getattr(getattr(model, "source", None), "downscale", 1)
        if min(shape) < factor:
            raise ValueError(f"heatmap_shape: {shape} is smaller than the source's downscale factor {factor}")
        intr = _floats("intrinsics", intrinsics, (4,))
        if intr[0] <= 0 or intr[1] <= 0:
            raise ValueError(f"intrinsics: fx and fy must be positive, got {intr[:2].tolist()}")
        height = float(_floats("plane_height", plane_height, ()))
        if height < 0:
            raise ValueError(f"plane_height: must be >= 0, got {height}")
        period = float(_floats("dt", dt, ()))
        if period <= 0:
            raise ValueError(f"dt: must be positive, got {period}")
        if num_steps is not None and not _positive_int(num_steps):
            raise ValueError(f"num_steps: must be a positive integer or None, got {num_steps!r}")

        self._model = model
        self._params = jax.device_put(P.as_arrays(params, model.properties()))  # on the device once
        self._heatmap_shape = shape
        self._num_steps = None if num_steps is None else int(num_steps)
        self._constants = _Constants(
            intrinsics=jnp.asarray(intr, jnp.float32),
            plane_height=jnp.asarray(height, jnp.float32),
            dt=jnp.asarray(period, jnp.float32),
        )
        self._no_heatmap = jnp.zeros(shape, jnp.float32)
        self._true, self._false = jnp.asarray(True), jnp.asarray(False)
        self._step = _tick_jit
        if not isinstance(cache, bool | str | os.PathLike):
            raise ValueError(f"cache: expected True, False or a directory, got {type(cache).__name__}")
        directory = None if isinstance(cache, bool) else cache
        with compilation_cache(enabled=cache is not False, directory=directory):
            self.reset(key)
            # Compile and warm up on the initial state (results dropped): a host heat map, then none. The
            # second call compiles nothing; it only adds the device-resident zero map to jit's dispatch cache.
            pose, still = np.eye(4, dtype=np.float32), np.zeros((3,), np.float32)
            sure = np.float32(1.0)
            for heat, has in ((np.zeros(shape, np.float32), self._true), (self._no_heatmap, self._false)):
                jax.block_until_ready(self._step(self._model, self._fold, self._step_keys, self._t_dev, self._state,
                                                 heat, has, pose, still, still, sure, self._constants, self._params))

    def reset(self, key: PRNGKeyArray) -> None:
        """Starts again from ``model.init`` with a new key: ``t = 0``, no ``last_info``; nothing recompiles."""
        if not _is_key(key):
            raise ValueError(f"key: expected a PRNG key (jax.random.key(seed)), got {type(key).__name__}")
        k_init, k_steps = jax.random.split(key)
        self._fold = self._num_steps is None
        self._step_keys = k_steps if self._fold else jax.random.split(k_steps, self._num_steps)
        self._state = _init_jit(self._model, k_init, self._params)
        self._t = 0
        self._t_dev = jnp.zeros((), jnp.int32)
        self._last_info = None
        self._last_pose = None  # the previous tick's robot_pose (float64) and its confidence

    def update(
        self,
        heatmap: Float[ArrayLike, "h w"] | None,
        cam_to_base: Float[ArrayLike, "4 4"],
        odometry: Float[ArrayLike, "3"] = (0.0, 0.0, 0.0),
        robot_pose: Float[ArrayLike, "3"] | None = None,
        pose_confidence: float = 1.0,
    ) -> Estimate:
        """One filter tick.

        Does not wait for the step to finish (JAX dispatches asynchronously): reading the estimate
        (``np.asarray(est.mean)``, ``float(...)``) waits. Only the shapes are checked here.

        Args:
            heatmap: ``[H, W]`` activations in ``[0, 1]`` (NumPy or JAX), or ``None`` when no new heat
                map arrived this tick (the buffer ages).
            cam_to_base: ``[4, 4]`` camera optical frame -> robot base frame now.
            odometry: ``(dx, dy, dtheta)`` from the previous tick's base frame to this one's; ignored on
                the first tick after construction or :meth:`reset`.
            robot_pose: the self-localisation's ``(x, y, theta)`` in a world frame now, for a model whose
                ego-motion reads it (``--set ego=pose``, :mod:`heatpf_jax.motion.ego`; required there): the
                motion since the previous tick's pose is computed here in float64.
            pose_confidence: its confidence in ``[0, 1]``.

        Returns:
            :class:`~heatpf_jax.estimate.top_fraction.Estimate` (``mean [2]``, ``cov [2, 2]``, ``weighted_mean [2]``);
            the whole :class:`~heatpf_jax.filter.StepInfo` is :attr:`last_info`.

        Raises:
            ValueError: an input has the wrong shape.
            RuntimeError: a tracker built with ``num_steps=T`` has taken its ``T`` steps.
        """
        if self._num_steps is not None and self._t >= self._num_steps:
            raise RuntimeError(f"num_steps: all {self._num_steps} steps taken; reset(key) to start again")
        if heatmap is None:
            heatmap, has_heatmap = self._no_heatmap, self._false
        else:
            heatmap, has_heatmap = _as_f32("heatmap", heatmap, self._heatmap_shape), self._true
        cam_to_base = _as_f32("cam_to_base", cam_to_base, (4, 4))
        odometry = _as_f32("odometry", odometry, (3,))
        delta, confidence = self._pose_motion(robot_pose, pose_confidence)
        self._state, info, self._t_dev = self._step(
            self._model, self._fold, self._step_keys, self._t_dev, self._state, heatmap, has_heatmap,
            cam_to_base, odometry, delta, confidence, self._constants, self._params,
        )
        self._t += 1
        self._last_info = info
        return Estimate(mean=info.mean, cov=info.cov, weighted_mean=info.weighted_mean)

    def _pose_motion(self, robot_pose, pose_confidence) -> tuple[np.ndarray, np.float32]:
        """The pose delta since the previous tick and its confidence (:func:`heatpf_jax.motion.ego.pose_deltas`)."""
        if robot_pose is None:
            if "robot_pose" in getattr(self._model, "requires", ()):
                raise ValueError("robot_pose: this model's ego-motion reads the self-localisation; pass robot_pose "
                                 "(x, y, theta) on every tick")
            return np.zeros((3,), np.float32), np.float32(1.0)
        pose = _floats("robot_pose", robot_pose, (3,))
        conf = float(_floats("pose_confidence", pose_confidence, ()))
        if not 0.0 <= conf <= 1.0:
            raise ValueError(f"pose_confidence: must lie in [0, 1], got {conf}")
        previous, self._last_pose = self._last_pose, (pose, conf)
        if previous is None:
            return np.zeros((3,), np.float32), np.float32(conf)
        delta = pose_deltas(np.stack([previous[0], pose]))[1]
        return delta.astype(np.float32), np.float32(min(conf, previous[1]))

    @property
    def state(self):
        """The model's carried state after the last tick (``model.init``'s after construction or a reset)."""
        return self._state

    @property
    def t(self) -> int:
        """Ticks taken since construction or the last :meth:`reset`."""
        return self._t

    @property
    def last_info(self):
        """The :class:`~heatpf_jax.filter.StepInfo` of the last tick (``None`` before the first)."""
        return self._last_info

    @property
    def model(self):
        """The model (static)."""
        return self._model

    @property
    def params(self):
        """The params, as arrays (converted once at construction)."""
        return self._params

    @property
    def heatmap_shape(self) -> tuple[int, int]:
        """``(H, W)`` every heat map must have."""
        return self._heatmap_shape

    @property
    def num_steps(self) -> int | None:
        """``T`` for ``run``'s keys, or ``None`` (``fold_in`` keys)."""
        return self._num_steps

    def __repr__(self) -> str:
        keys = f"num_steps={self._num_steps}" if self._num_steps is not None else "fold_in keys"
        return (f"Tracker({type(self._model).__name__}, heatmap_shape={self._heatmap_shape}, t={self._t}, "
                f"{keys})")

