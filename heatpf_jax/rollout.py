"""``run``: any model with ``init``/``step`` rolled over a whole sequence with ``lax.scan``.

A *model* is a hashable object (the ``jit`` static argument) with ``init(key, params) -> state``,
``step(key, state, inputs, params) -> (state, info)``, ``default_params()``, ``properties()`` and
``validate()``: the particle filter (:class:`heatpf_jax.filter.Filter`) and the baselines
(:class:`heatpf_jax.baselines.KalmanFilter`) alike, so ``run``, ``sweep`` and the evaluation are
written once for all of them.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, Bool, Float, PRNGKeyArray

from heatpf_jax import params as P
from heatpf_jax.io.sequence import Sequence
from heatpf_jax.motion.ego import pose_confidences, pose_deltas
from heatpf_jax.pieces import StepInputs

__all__ = ["RunResult", "prepare_run", "run", "run_core", "stack_params", "validate_params"]


class RunResult(NamedTuple):
    """What :func:`run` returns: the model's per-step info stacked over steps (leading axis T) and its final state."""

    info: Any
    final_state: Any


def validate_params(params, model) -> None:
    """Raises ``ValueError`` naming the parameter (dotted path) if a concrete value is out of range.

    Works on single sets and on batches (every element is checked); traced values are skipped.
    """
    if not isinstance(params, type(model.default_params())):
        raise TypeError(
            f"params: expected {type(model.default_params()).__name__} for {type(model).__name__}, "
            f"got {type(params).__name__}"
        )
    P.validate(params, model.properties())


def stack_params(params_list: list) -> Any:
    """Stacks parameter sets (of one model) along a new leading axis, for ``jax.vmap`` sweeps.

    Leaves become JAX arrays (:func:`run` casts each to its parameter's dtype).
    """
    return jax.tree.map(lambda *xs: jnp.stack([jnp.asarray(x) for x in xs]), *params_list)


class _ScanInputs(NamedTuple):
    key: PRNGKeyArray
    heatmap: Float[Array, "h w"]
    has_heatmap: Bool[Array, ""]
    cam_to_base: Float[Array, "4 4"]
    odometry: Float[Array, "3"]
    pose_delta: Float[Array, "3"] | None
    pose_confidence: Float[Array, ""] | None


def run_core(key: PRNGKeyArray, sequence: Sequence, params, model) -> RunResult:
    """The traced body of :func:`run`, without checks: inputs prepared by :func:`prepare_run`."""
    k_init, k_steps = jax.random.split(key)
    num_steps = sequence.heatmaps.shape[0]
    intrinsics = jnp.asarray(sequence.intrinsics, jnp.float32)
    plane_height = jnp.asarray(sequence.ball_radius, jnp.float32)
    dt = jnp.asarray(sequence.dt, jnp.float32)

    def body(state, x: _ScanInputs):
        inputs = StepInputs(
            heatmap=x.heatmap,
            has_heatmap=x.has_heatmap,
            cam_to_base=x.cam_to_base,
            odometry=x.odometry,
            intrinsics=intrinsics,
            plane_height=plane_height,
            dt=dt,
            pose_delta=x.pose_delta,
            pose_confidence=x.pose_confidence,
        )
        return model.step(x.key, state, inputs, params)

    # Prepared by prepare_run: robot_pose holds the pose deltas and pose_confidence theirs (None unless
    # the model reads them).
    has_pose = sequence.robot_pose is not None

    xs = _ScanInputs(
        key=jax.random.split(k_steps, num_steps),
        heatmap=jnp.asarray(sequence.heatmaps, jnp.float32),
        has_heatmap=jnp.asarray(sequence.has_heatmap, bool),
        cam_to_base=jnp.asarray(sequence.cam_to_base, jnp.float32),
        odometry=jnp.asarray(sequence.odometry, jnp.float32),
        pose_delta=jnp.asarray(sequence.robot_pose, jnp.float32) if has_pose else None,
        pose_confidence=jnp.asarray(sequence.pose_confidence, jnp.float32) if has_pose else None,
    )
    final_state, info = lax.scan(body, model.init(k_init, params), xs)
    return RunResult(info=info, final_state=final_state)


_run_jit = jax.jit(run_core, static_argnames="model")


def prepare_run(sequence: Sequence, params, model) -> tuple[Sequence, Any]:
    """:func:`run`'s checks and host-side preparation: ``(sequence, params)`` ready for :func:`run_core`.

    Raises:
        ValueError: naming a static choice or a parameter that is unusable.
    """
    model.validate()
    validate_params(params, model)
    params = P.as_arrays(params, model.properties())
    # Host-side preparation in NumPy where the inputs are concrete: every eager JAX op would be one more
    # small program to trace and compile before the run (they dominate a warm start from the cache).
    if isinstance(sequence.odometry, jax.core.Tracer):
        odometry = jnp.asarray(sequence.odometry, jnp.float32).at[0].set(0.0)
    else:
        odometry = np.array(sequence.odometry, np.float32)
        odometry[0] = 0.0
    # Ground truth, images, stamps and settings are not inputs: dropping them keeps one compilation with or
    # without them.
    return sequence._replace(odometry=odometry, ground_truth=None, images=None, stamps=None, settings=None,
                             **_pose_inputs(sequence, model)), params


def _pose_inputs(sequence: Sequence, model) -> dict[str, Any]:
    """``robot_pose`` replaced by the pose deltas and ``pose_confidence`` by theirs where the model reads
    them (:mod:`heatpf_jax.motion.ego`); both dropped otherwise (one compilation with or without them)."""
    if "robot_pose" not in getattr(model, "requires", ()):
        return {"robot_pose": None, "pose_confidence": None}
    if sequence.robot_pose is None:
        raise ValueError(
            "robot_pose: the sequence has no robot_pose (self-localisation), which this method's ego-motion "
            "reads; use --set ego=odometry, or a sequence with robot_pose and pose_confidence"
        )
    num_steps = np.shape(sequence.robot_pose)[0]
    if isinstance(sequence.robot_pose, jax.core.Tracer) or isinstance(sequence.pose_confidence, jax.core.Tracer):
        return {  # traced (a vmapped batch of sequences): float32 on the device
            "robot_pose": pose_deltas(sequence.robot_pose, jnp),
            "pose_confidence": jnp.asarray(pose_confidences(sequence.pose_confidence, num_steps, jnp), jnp.float32),
        }
    confidence = None if sequence.pose_confidence is None else np.asarray(sequence.pose_confidence)
    return {
        "robot_pose": pose_deltas(np.asarray(sequence.robot_pose)).astype(np.float32),
        "pose_confidence": pose_confidences(confidence, num_steps).astype(np.float32),
    }


def run(key: PRNGKeyArray, sequence: Sequence, params, model) -> RunResult:
    """Rolls ``model`` over a whole sequence with ``lax.scan`` (jitted once per model and shapes).

    Each heat map is measured inside the step, so every parameter (the threshold included) stays a
    traced value. Row 0 of the odometry is ignored (the first step has no previous base frame). To
    sweep, ``jax.vmap`` :func:`run` over a batch of params (see :func:`stack_params`) or use
    :func:`heatpf_jax.sweep.sweep`; under ``vmap``/``jit`` the eager checks skip traced values.

    Args:
        key: PRNG key.
        sequence: a :class:`~heatpf_jax.io.sequence.Sequence` (see ``load_sequence``).
        params: the model's params (e.g. :class:`~heatpf_jax.filter.FilterParams`).
        model: a :class:`~heatpf_jax.filter.Filter`, a baseline, or any model (static).

    Returns:
        :class:`RunResult` with per-step info (leading axis T).
    """
    sequence, params = prepare_run(sequence, params, model)
    return _run_jit(key, sequence, params, model)
