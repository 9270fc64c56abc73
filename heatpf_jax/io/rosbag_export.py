"""A run as a ROS 2 bag: ``heatpf run ... --bag OUT``.

Writes a rosbag2 directory (MCAP storage, ``metadata.yaml`` beside it) with the pure-Python
`rosbags <https://gitlab.com/ternaris/rosbags>`_ package (``pip install "heatpf-jax[ros]"``), so that the
run opens in Foxglove and plays with ``ros2 bag play`` beside the robot's own bag. Per filter step
``t``, stamped with the sequence's own clock (``Sequence.stamps``: an imported bag's, so the two line up), or
``start + t dt`` where it has none or a ``start`` is given (0 by default), every message built by
:func:`heatpf_jax.io.ros_messages.step_messages`:

=========================== ========================================== ================================
topic                       type                                       what
=========================== ========================================== ================================
``/heatpf/estimate``        ``geometry_msgs/msg/PoseWithCovarianceStamped`` ``StepInfo.mean``, ``cov``
``/heatpf/particles``       ``sensor_msgs/msg/PointCloud2``            particles after the step, weights
``/heatpf/measurements``    ``sensor_msgs/msg/PointCloud2``            the buffered measurements, weights
``/heatpf/modes``           ``visualization_msgs/msg/MarkerArray``     ``StepInfo.modes`` (if any)
``/heatpf/tracks``          ``visualization_msgs/msg/MarkerArray``     ``StepInfo.tracks`` (if any)
``/tf_static`` or ``/tf``   ``tf2_msgs/msg/TFMessage``                 ``cam_to_base``
=========================== ========================================== ================================

All in the robot's base frame (``frame_id``, default ``base_footprint`` as in ``heatpf import-rosbag``),
at the height of the ball radius. The camera's pose is one message on ``/tf_static`` (latched: transient
local) when ``cam_to_base`` is the same at every step, else one message per step on ``/tf``; its child
frame is ``heatpf_camera_optical`` by default, so that it does not clash with the robot's own tf tree.

The bag is written into a temporary sibling directory and renamed into place at the end: a failure or an
interruption leaves no half-written bag, and an existing bag is replaced only when asked (``--force``).
"""

from __future__ import annotations

import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np

from heatpf_jax.io import ros_messages as rm
from heatpf_jax.io.files import check_writable_dir, same_file
from heatpf_jax.io.sequence import Sequence
from heatpf_jax.pieces import ModelWrapper
from heatpf_jax.rollout import prepare_run, run_core

__all__ = [
    "BagSummary",
    "RunTrace",
    "Snapshot",
    "check_bag_output",
    "describe_bag",
    "record_run",
    "require_rosbags",
    "trace_run",
    "write_run_bag",
]

ROSBAGS_MISSING = '--bag needs rosbags: pip install "heatpf-jax[ros]"'
_STATIC_TOLERANCE = 1e-9  # cam_to_base entries closer than this at every step: one static transform


def require_rosbags() -> None:
    """Raises ``RuntimeError`` with one line (``--bag needs rosbags: ...``) unless ``rosbags`` can be imported."""
    try:
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
    except ImportError:
        raise RuntimeError(ROSBAGS_MISSING) from None


def check_bag_output(path: str | os.PathLike, *, inputs=(), replace: bool = False) -> Path:
    """Checks a ``--bag`` directory before any work (and that ``rosbags`` is installed).

    The directory must not exist, or (with ``replace``) be a rosbag2 directory (it has a
    ``metadata.yaml``); its parent must be a writable directory; no input or other output may lie
    inside it (a replaced bag is deleted).

    Args:
        path: the bag directory to write.
        inputs: files that must not be the bag or lie inside it (the sequence, the other outputs).
        replace: an existing bag may be replaced (``--force``).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        RuntimeError: ``rosbags`` is missing.
        ValueError: one line naming the path and the problem.
    """
    require_rosbags()
    path = Path(path)
    for other in inputs:
        if other is None:
            continue
        other = Path(other)
        if same_file(path, other) or path.resolve() in other.resolve().parents:
            raise ValueError(f"--bag: {path} would hold or replace {other}; choose another --bag")
    if path.exists() or path.is_symlink():
        if not path.is_dir() or path.is_symlink():
            raise ValueError(f"--bag: {path} exists and is not a directory; choose another --bag")
        if not replace:
            raise ValueError(f"--bag: {path} exists; pass --force to replace it, or choose another --bag")
        if not (path / "metadata.yaml").is_file():
            raise ValueError(f"--bag: {path} is a directory but not a rosbag2 bag (no metadata.yaml); it is not "
                             "replaced, choose another --bag")
    parent = path.parent
    if not parent.exists():
        raise ValueError(f"--bag: {path}: the directory {parent} does not exist (create it first)")
    if not parent.is_dir():
        raise ValueError(f"--bag: {path}: {parent} is not a directory")
    check_writable_dir(parent, "--bag")
    return path


# --- The run, with the state of every step -----------------------------------------------------------------------


class Snapshot(NamedTuple):
    """What a bag shows of the carried state after each step (leading axis ``T``; ``None`` without particles).

    Attributes:
        particles: ``float32 [T, N, 2]`` the particles' positions (``state.particles.xy``).
        log_weights: ``float32 [T, N]`` their normalised log weights.
        measurements: the buffer (:class:`~heatpf_jax.measurements.Measurements`, ``[T, M, ...]``).
    """

    particles: Any
    log_weights: Any
    measurements: Any


class RunTrace(NamedTuple):
    """:func:`trace_run`'s result: ``info`` (the model's per-step info, as :func:`heatpf_jax.run`'s) and
    ``snapshots`` (a :class:`Snapshot` of the state after every step)."""

    info: Any
    snapshots: Snapshot


def _snapshot(state) -> Snapshot:
    particles = getattr(getattr(state, "particles", None), "xy", None)
    return Snapshot(
        particles=particles,
        log_weights=getattr(state, "log_weights", None) if particles is not None else None,
        measurements=getattr(state, "buffer", None),
    )


@dataclass(frozen=True)
class _Recording(ModelWrapper):
    """A model whose step also returns a :class:`Snapshot` of its new state (hashable if the model is)."""

    model: Any

    def step(self, key, state, inputs, params):
        state, info = self.model.step(key, state, inputs, params)
        return state, (info, _snapshot(state))


_trace_jit = jax.jit(run_core, static_argnames="model")


def trace_run(key, sequence: Sequence, params, model) -> RunTrace:
    """:func:`heatpf_jax.run` with the state after every step kept: the same keys, steps and ``info``.

    Args:
        key: PRNG key (as for :func:`heatpf_jax.run`).
        sequence: the sequence.
        params: the model's params.
        model: a :class:`~heatpf_jax.filter.Filter` or any model with ``init``/``step``.

    Returns:
        :class:`RunTrace` of NumPy arrays with a leading ``T`` axis.
    """
    wrapped = _Recording(model)
    sequence, params = prepare_run(sequence, params, wrapped)
    info, snapshots = _trace_jit(key, sequence, params, wrapped).info
    return RunTrace(*jax.tree.map(np.asarray, (info, snapshots)))


# --- The bag -----------------------------------------------------------------------------------------------------


class BagSummary(NamedTuple):
    """What :func:`write_run_bag` wrote: ``{topic: (message type, count)}`` and the stamps ``int64 [T]`` (ns)."""

    topics: dict
    stamps: np.ndarray


class _At(NamedTuple):
    xy: Any


class _StateView(NamedTuple):
    """The fields of a filter state that :func:`~heatpf_jax.io.ros_messages.step_messages` reads."""

    particles: Any
    log_weights: Any
    buffer: Any


def _at(tree, t: int):
    return jax.tree.map(lambda x: x[t], tree)


def _qos(latched: bool):
    from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime

    never = QosTime(sec=0, nsec=0)  # rosbag2's "default" durations
    return [Qos(history=QosHistory.KEEP_LAST, depth=1 if latched else 10, reliability=QosReliability.RELIABLE,
                durability=QosDurability.TRANSIENT_LOCAL if latched else QosDurability.VOLATILE, deadline=never,
                lifespan=never, liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
                avoid_ros_namespace_conventions=False)]


def write_run_bag(
    path: str | os.PathLike,
    sequence: Sequence,
    trace: RunTrace,
    *,
    frame_id: str = "base_footprint",
    camera_frame: str = "heatpf_camera_optical",
    namespace: str = "/heatpf",
    start_ns: int | None = None,
) -> BagSummary:
    """Writes a run as a rosbag2 directory (MCAP), atomically; see the module docstring for the topics.

    Args:
        path: the bag directory (checked by :func:`check_bag_output`; an existing one is replaced).
        sequence: the sequence the run was made on (``dt``, ``ball_radius``, ``cam_to_base``).
        trace: :func:`trace_run`'s result on it.
        frame_id: the robot's base frame.
        camera_frame: the child frame of the camera's transform.
        namespace: the prefix of the run's topics.
        start_ns: the stamp of step 0, nanoseconds, the others ``dt`` apart; ``None`` (default): the sequence's
            ``stamps`` where it has them, else from 0.

    Returns:
        :class:`BagSummary`.
    """
    require_rosbags()
    from rosbags.rosbag2 import StoragePlugin, Writer

    store = rm.typestore()
    path = Path(path)
    num_steps = sequence.num_steps
    dt_ns = float(sequence.dt) * 1e9
    if start_ns is None and sequence.stamps is not None:
        stamps = np.asarray(sequence.stamps, np.int64)
    else:
        stamps = int(start_ns or 0) + np.round(np.arange(num_steps) * dt_ns).astype(np.int64)
    z = float(sequence.ball_radius)
    cam = np.asarray(sequence.cam_to_base, np.float64)
    static = bool(np.all(np.abs(cam - cam[0]) <= _STATIC_TOLERANCE))
    info, snaps = trace
    has_particles = snaps.particles is not None
    counts: dict[str, list] = {}

    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.tmp-"))
    try:
        inner = tmp / path.name
        with Writer(inner, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
            conns: dict[str, Any] = {}

            def write(topic: str, stamp: int, msg, latched: bool = False) -> None:
                if topic not in conns:
                    conns[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=store,
                                                         offered_qos_profiles=_qos(latched))
                    counts[topic] = [msg.__msgtype__, 0]
                writer.write(conns[topic], int(stamp), store.serialize_cdr(msg, msg.__msgtype__))
                counts[topic][1] += 1

            if static:
                write("/tf_static", stamps[0], rm.tf_message(cam[0], stamps[0], frame_id, camera_frame), latched=True)
            for t in range(num_steps):
                if not static:
                    write("/tf", stamps[t], rm.tf_message(cam[t], stamps[t], frame_id, camera_frame))
                state = None
                if has_particles:
                    state = _StateView(_At(snaps.particles[t]), snaps.log_weights[t], _at(snaps.measurements, t))
                elif snaps.measurements is not None:
                    state = _StateView(None, None, _at(snaps.measurements, t))
                messages = rm.step_messages(_at(info, t), state, stamps[t], frame_id=frame_id, z=z,
                                            namespace=namespace)
                for topic, msg in messages.items():
                    write(topic, stamps[t], msg)
        if path.exists():  # replace (checked by check_bag_output): the old bag goes only once the new one is whole
            old = Path(tempfile.mkdtemp(dir=path.parent, prefix=f".{path.name}.old-"))
            os.replace(path, old / path.name)
            os.replace(inner, path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(inner, path)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return BagSummary(topics={k: tuple(v) for k, v in counts.items()}, stamps=stamps)


def record_run(
    path: str | os.PathLike,
    key,
    sequence: Sequence,
    params,
    model,
    *,
    frame_id: str = "base_footprint",
    start_ns: int | None = None,
) -> BagSummary:
    """:func:`trace_run` then :func:`write_run_bag`: the bag of ``heatpf run --bag``."""
    return write_run_bag(path, sequence, trace_run(key, sequence, params, model), frame_id=frame_id,
                         start_ns=start_ns)


def describe_bag(path: Path, summary: BagSummary) -> str:
    """One line for the command: ``wrote BAG (rosbag2, mcap): N messages on K topics (/heatpf/estimate 20, ...)``."""
    total = sum(count for _, count in summary.topics.values())
    listing = ", ".join(f"{topic} {count}" for topic, (_, count) in summary.topics.items())
    return f"wrote {path} (rosbag2, mcap): {total} messages on {len(summary.topics)} topics ({listing})"
