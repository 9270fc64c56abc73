"""A ROS bag as a version-1 sequence file: ``heatpf import-rosbag``.

Reads a rosbag2 recording (sqlite3 or mcap storage) or a ROS 1 ``.bag`` with the pure-Python
`rosbags <https://gitlab.com/ternaris/rosbags>`_ package (``pip install 'heatpf-jax[ros]'``; no ROS
installation needed) and resamples it onto a fixed filter clock:

* **ticks** at ``rate`` Hz from the first heat map's header stamp to the last; tick ``t`` at time
  ``t0 + t / rate`` collects the heat maps stamped in ``(t0 + (t - 1) / rate, t0 + t / rate]`` and keeps
  the latest (``has_heatmap[t]`` is True where there is one);
* **heat maps** (``sensor_msgs/msg/Image``): ``mono8`` (or ``8UC1``) divided by 255; ``32FC1`` as is,
  clipped to ``[0, 1]`` after checking that no value is non-finite or further than ``CLIP_TOLERANCE``
  outside (a logit map is rejected, not silently clipped); any other encoding is rejected;
* **intrinsics** from the first ``sensor_msgs/msg/CameraInfo`` ``K`` (distortion is ignored), rescaled to
  the heat map's size when the camera info's ``width``/``height`` differ (``sx = W / width``, ``sy = H /
  height``: ``fx sx``, ``fy sy``, ``(cx + 0.5) sx - 0.5``, ``(cy + 0.5) sy - 0.5``, pixel centres at
  integers); the camera info must not change during the bag;
* **cam_to_base** from ``/tf`` and ``/tf_static`` (``tf2_msgs/msg/TFMessage``) at the kept heat map's
  stamp (at the tick time where a tick has none): the transforms along the tree path from
  ``base_frame`` to ``camera_frame`` (default: the heat maps' ``header.frame_id``) are chained, each
  dynamic one interpolated between its neighbouring stamps (linear translation, slerp rotation) and held
  constant before its first and after its last stamp. **The camera frame must be the optical frame** (x
  right, y down, z forward, as in ``*_optical_frame`` by REP 103), not a body-style camera link;
* **odometry** from ``nav_msgs/msg/Odometry`` poses interpolated at the ticks the same way (held at the
  ends), composed with the tf from the message's ``child_frame_id`` to ``base_frame`` where they differ,
  projected onto the ground plane ``(x, y, yaw)`` and written as ``(dx, dy, dtheta)`` from tick ``t - 1``
  to ``t`` in the base frame of ``t - 1``;
* **ground truth** (optional) from ``geometry_msgs/msg/PointStamped`` or
  ``geometry_msgs/msg/PoseWithCovarianceStamped`` (its position): interpolated linearly at the ticks in
  the message frame (held at the ends), then moved into ``base_frame`` with tf at the tick time where
  the message frame is another one (for instance ``odom`` or ``map``).

Every stamp is a message's ``header.stamp``, never the time the bag recorded it. Frame names lose a
leading ``/`` (ROS 1 style). Errors are :class:`~heatpf_jax.io.sequence.SequenceError` with one line that
names the topic, frame or option at fault. The ``heatpf import-rosbag`` command around it is
:mod:`heatpf_jax.cli.import_rosbag`.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np

from heatpf_jax.io import ros_messages as rm
from heatpf_jax.io.ros_messages import CLIP_TOLERANCE
from heatpf_jax.io.sequence import Sequence, SequenceError, validate_sequence

__all__ = ["CLIP_TOLERANCE", "import_rosbag"]

# A heat map stamped this fraction of a period after a tick still belongs to that tick (float rounding).
_TICK_SLACK = 1e-6

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
TF_MESSAGE = "tf2_msgs/msg/TFMessage"
ODOMETRY = "nav_msgs/msg/Odometry"
POINT_STAMPED = "geometry_msgs/msg/PointStamped"
POSE_COV_STAMPED = "geometry_msgs/msg/PoseWithCovarianceStamped"
TF_TOPICS = ("/tf", "/tf_static")


# --- Small rigid-body helpers (NumPy, float64) -------------------------------------------------------------------


_quat_to_matrix = rm.quaternion_to_matrix
_pose_matrix = rm.pose_matrices


def _slerp(q0: np.ndarray, q1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Spherical interpolation ``[N, 4]`` between unit quaternions, the short way round; ``w`` in [0, 1]."""
    dot = np.sum(q0 * q1, axis=-1)
    q1 = np.where(dot[:, None] < 0, -q1, q1)
    theta = np.arccos(np.clip(np.abs(dot), 0.0, 1.0))
    small = theta < 1e-9
    sin = np.where(small, 1.0, np.sin(theta))
    a = np.where(small, 1.0 - w, np.sin((1.0 - w) * theta) / sin)
    b = np.where(small, w, np.sin(w * theta) / sin)
    q = a[:, None] * q0 + b[:, None] * q1
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _invert(pose: np.ndarray) -> np.ndarray:
    out = np.zeros_like(pose)
    rot_t = np.swapaxes(pose[:, :3, :3], 1, 2)
    out[:, :3, :3] = rot_t
    out[:, :3, 3] = -np.einsum("nij,nj->ni", rot_t, pose[:, :3, 3])
    out[:, 3, 3] = 1.0
    return out


class _Track:
    """A time series of rigid transforms, interpolated between samples and held at the ends."""

    def __init__(self, times: np.ndarray, trans: np.ndarray, quat: np.ndarray):
        order = np.argsort(times, kind="stable")
        times, trans, quat = times[order], trans[order], quat[order]
        # Repeated stamps: the one recorded last wins.
        keep = np.append(times[1:] != times[:-1], True)
        self.times, self.trans = times[keep], trans[keep]
        quat = quat[keep]
        self.quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)

    def at(self, query: np.ndarray) -> np.ndarray:
        """Transforms ``[N, 4, 4]`` at ``query`` times ``[N]``."""
        n = self.times.shape[0]
        if n == 1:
            return _pose_matrix(np.repeat(self.trans, query.shape[0], 0), np.repeat(self.quat, query.shape[0], 0))
        q = np.clip(query, self.times[0], self.times[-1])
        i = np.clip(np.searchsorted(self.times, q, side="right") - 1, 0, n - 2)
        w = (q - self.times[i]) / (self.times[i + 1] - self.times[i])
        trans = self.trans[i] + w[:, None] * (self.trans[i + 1] - self.trans[i])
        return _pose_matrix(trans, _slerp(self.quat[i], self.quat[i + 1], w))


# --- Reading the bag ---------------------------------------------------------------------------------------------


_stamp_ns = rm.stamp_ns
_frame = rm.frame_name
_quat = rm.quaternion
_vec = rm.vector3


def _decode_image(msg, topic: str) -> np.ndarray:
    try:
        return rm.heatmap_from_image(msg, f"--heatmap-topic: {topic}")
    except ValueError as err:
        raise SequenceError(str(err)) from None


@dataclasses.dataclass
class _Bag:
    """What the import needs from a bag, decoded (stamps in ns, frames without a leading '/')."""

    image_stamps: list = dataclasses.field(default_factory=list)
    image_frames: list = dataclasses.field(default_factory=list)
    images: list = dataclasses.field(default_factory=list)
    camera_infos: list = dataclasses.field(default_factory=list)  # (stamp, width, height, K[9])
    tf: list = dataclasses.field(default_factory=list)  # (stamp, parent, child, trans[3], quat[4], static)
    odom: list = dataclasses.field(default_factory=list)  # (stamp, frame, child, trans[3], quat[4])
    truth: list = dataclasses.field(default_factory=list)  # (stamp, frame, point[3])


def _read_bag(path: Path, topics: dict[str, tuple[str, tuple[str, ...]]], ground_truth_topic: str | None) -> _Bag:
    """Decodes the wanted topics; ``topics`` maps a topic to (option name, accepted message types)."""
    try:
        from rosbags.highlevel import AnyReader, AnyReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise RuntimeError(
            "import-rosbag needs the 'rosbags' package: pip install 'heatpf-jax[ros]' (or 'rosbags>=0.10')"
        ) from None

    if not path.exists():
        raise SequenceError(f"{path}: no such bag (a rosbag2 directory or a ROS 1 .bag file)")
    bag = _Bag()
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            present: dict[str, str] = {}
            for conn in reader.connections:
                present.setdefault(conn.topic, conn.msgtype)
            listing = ", ".join(f"{t} ({present[t]})" for t in sorted(present)) or "none"
            for topic, (option, types) in topics.items():
                if topic not in present:
                    raise SequenceError(f"{option}: topic {topic} is not in {path.name} (its topics: {listing})")
                if present[topic] not in types:
                    raise SequenceError(
                        f"{option}: topic {topic} carries {present[topic]}, expected {' or '.join(types)}"
                    )
            wanted = {**topics, **{t: ("tf", (TF_MESSAGE,)) for t in TF_TOPICS if present.get(t) == TF_MESSAGE}}
            conns = [c for c in reader.connections if c.topic in wanted and c.msgtype in wanted[c.topic][1]]
            counts = dict.fromkeys(topics, 0)
            for conn, _, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                topic = conn.topic
                if topic in counts:
                    counts[topic] += 1
                if topic in TF_TOPICS and topic not in topics:
                    static = topic == "/tf_static"
                    for tr in msg.transforms:
                        bag.tf.append((_stamp_ns(tr.header), _frame(tr.header.frame_id), _frame(tr.child_frame_id),
                                       _vec(tr.transform.translation), _quat(tr.transform.rotation), static))
                    continue
                if conn.msgtype == IMAGE:
                    bag.image_stamps.append(_stamp_ns(msg.header))
                    bag.image_frames.append(_frame(msg.header.frame_id))
                    bag.images.append(_decode_image(msg, topic))
                elif conn.msgtype == CAMERA_INFO:
                    bag.camera_infos.append((_stamp_ns(msg.header), *rm.camera_matrix(msg)))
                elif conn.msgtype == ODOMETRY:
                    bag.odom.append((_stamp_ns(msg.header), _frame(msg.header.frame_id), _frame(msg.child_frame_id),
                                     _vec(msg.pose.pose.position), _quat(msg.pose.pose.orientation)))
                elif topic == ground_truth_topic:
                    point = msg.point if conn.msgtype == POINT_STAMPED else msg.pose.pose.position
                    bag.truth.append((_stamp_ns(msg.header), _frame(msg.header.frame_id), _vec(point)))
    except (AnyReaderError, FileNotFoundError) as err:
        raise SequenceError(f"{path}: cannot read the bag ({err})") from None
    for topic, count in counts.items():
        if count == 0:
            raise SequenceError(f"{topics[topic][0]}: topic {topic} has no messages in {path.name}")
    return bag


# --- The tf tree -------------------------------------------------------------------------------------------------


class _TfTree:
    """The tf tree of a bag: each child frame has one parent and a static or dynamic transform."""

    def __init__(self, records: list):
        self.parent: dict[str, str] = {}
        self.static: dict[str, np.ndarray] = {}
        samples: dict[str, list] = {}
        for stamp, parent, child, trans, quat, static in records:
            if not parent or not child:
                raise SequenceError(f"tf: a transform with an empty frame name ({parent!r} -> {child!r})")
            if self.parent.setdefault(child, parent) != parent:
                raise SequenceError(
                    f"tf: frame {child!r} has two parents, {self.parent[child]!r} and {parent!r}"
                )
            if np.linalg.norm(quat) < 1e-6:
                raise SequenceError(f"tf: zero rotation quaternion for {parent!r} -> {child!r} at stamp {stamp} ns")
            if static:
                self.static[child] = _pose_matrix(trans[None], quat[None])[0]
            else:
                samples.setdefault(child, []).append((stamp, trans, quat))
        self._stamps = {child: np.array([s[0] for s in rows], np.int64) for child, rows in samples.items()}
        self._samples = samples
        self._tracks: dict[tuple[str, int], _Track] = {}

    def frames(self) -> list[str]:
        return sorted(set(self.parent) | set(self.parent.values()))

    def _edge(self, child: str, times: np.ndarray, t0_ns: int) -> np.ndarray:
        """The transform parent <- child ``[N, 4, 4]`` at ``times`` (seconds after ``t0_ns``)."""
        if child in self.static:
            return np.broadcast_to(self.static[child], (times.shape[0], 4, 4))
        key = (child, t0_ns)
        if key not in self._tracks:
            rows = self._samples[child]
            rel = (self._stamps[child] - t0_ns) * 1e-9
            self._tracks[key] = _Track(rel, np.stack([r[1] for r in rows]), np.stack([r[2] for r in rows]))
        return self._tracks[key].at(times)

    def _chain(self, frame: str) -> list[str]:
        chain = [frame]
        while chain[-1] in self.parent and len(chain) <= len(self.parent):
            chain.append(self.parent[chain[-1]])
        return chain

    def lookup(self, target: str, source: str, times: np.ndarray, t0_ns: int, *, what: str) -> np.ndarray:
        """Transforms ``[N, 4, 4]`` taking ``source`` coordinates to ``target`` coordinates at ``times``.

        Raises:
            SequenceError: no tree path joins the two frames (the message names both, and ``what``).
        """
        up_t, up_s = self._chain(target), self._chain(source)
        common = next((f for f in up_s if f in up_t), None)
        if common is None:
            known = ", ".join(self.frames()) or "none: the bag has no /tf or /tf_static"
            raise SequenceError(
                f"{what}: no tf path between frames {target!r} and {source!r} (frames in /tf and /tf_static: {known})"
            )
        n = times.shape[0]

        def to_common(chain: list[str]) -> np.ndarray:
            pose = np.broadcast_to(np.eye(4), (n, 4, 4))
            for child in chain[: chain.index(common)]:
                pose = self._edge(child, times, t0_ns) @ pose
            return pose

        return _invert(np.ascontiguousarray(to_common(up_t))) @ to_common(up_s)


# --- The import --------------------------------------------------------------------------------------------------


def _check_number(name: str, value, *, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise ValueError(f"{name}: expected a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or (value <= 0 if positive else value < 0):
        raise ValueError(f"{name}: must be {'positive' if positive else '>= 0'}, got {value!r}")
    return value


def _intrinsics(bag: _Bag, shape: tuple[int, int], topic: str) -> np.ndarray:
    stamp, width, height, k = bag.camera_infos[0]
    for other in bag.camera_infos[1:]:
        if other[1:3] != (width, height) or not np.allclose(other[3], k, rtol=1e-9, atol=0.0):
            raise SequenceError(
                f"--camera-info-topic: {topic} changes at stamp {other[0]} ns (K {other[3][[0, 4, 2, 5]].tolist()}, "
                f"{other[1]} x {other[2]}; first K {k[[0, 4, 2, 5]].tolist()}, {width} x {height}); a sequence "
                "has one set of intrinsics"
            )
    if k[0] <= 0 or k[4] <= 0:
        raise SequenceError(f"--camera-info-topic: {topic} has no calibration (K = {k.tolist()})")
    if width <= 0 or height <= 0:
        raise SequenceError(f"--camera-info-topic: {topic} has an image size of {width} x {height}")
    return rm.scale_intrinsics(k, width, height, shape)


def _one_frame(frames, what: str) -> str:
    names = sorted(set(frames))
    if len(names) > 1:
        raise SequenceError(f"{what}: messages in several frames ({', '.join(repr(n) for n in names)})")
    return names[0]


_planar = rm.planar_poses
_odometry = rm.odometry_deltas


def import_rosbag(
    bag_path: str | os.PathLike,
    *,
    heatmap_topic: str,
    camera_info_topic: str,
    odom_topic: str,
    base_frame: str = "base_footprint",
    camera_frame: str | None = None,
    rate: float = 10.0,
    ball_radius: float = 0.07,
    ground_truth_topic: str | None = None,
) -> Sequence:
    """Reads a ROS bag into a validated version-1 sequence (see the module docstring for the rules).

    Args:
        bag_path: a rosbag2 directory (sqlite3 or mcap storage) or a ROS 1 ``.bag`` file.
        heatmap_topic: ``sensor_msgs/msg/Image`` heat maps (mono8, 8UC1 or 32FC1).
        camera_info_topic: ``sensor_msgs/msg/CameraInfo`` of the camera the heat maps come from.
        odom_topic: ``nav_msgs/msg/Odometry`` of the robot.
        base_frame: the robot base frame (x forward, y left, z up on the ground).
        camera_frame: the camera's *optical* frame in tf; default the heat maps' ``header.frame_id``.
        rate: filter rate in Hz; ``dt = 1 / rate``.
        ball_radius: metres, written as ``ball_radius``.
        ground_truth_topic: optional ``geometry_msgs/msg/PointStamped`` or
            ``geometry_msgs/msg/PoseWithCovarianceStamped`` of the ball.

    Returns:
        A validated :class:`~heatpf_jax.io.sequence.Sequence` of ``T = ceil((last - first heat-map stamp) * rate) + 1``
        steps, with ``ground_truth`` when ``ground_truth_topic`` is given.

    Raises:
        SequenceError: a missing topic (the message lists the bag's topics), a topic of the wrong type or
            without messages, an unsupported encoding, no tf path between two frames (both named), or
            anything else that breaks the sequence contract.
        ValueError: a bad ``rate`` or ``ball_radius``.
        RuntimeError: the ``rosbags`` package is not installed.
    """
    rate = _check_number("--rate", rate, positive=True)
    ball_radius = _check_number("--ball-radius", ball_radius, positive=False)
    given = [
        (heatmap_topic, "--heatmap-topic", (IMAGE,)),
        (camera_info_topic, "--camera-info-topic", (CAMERA_INFO,)),
        (odom_topic, "--odom-topic", (ODOMETRY,)),
    ]
    if ground_truth_topic is not None:
        given.append((ground_truth_topic, "--ground-truth-topic", (POINT_STAMPED, POSE_COV_STAMPED)))
    topics = {topic: (option, types) for topic, option, types in given}
    if len(topics) < len(given):
        twice = next(t for t, *_ in given if sum(t == u for u, *_ in given) > 1)
        options = " and ".join(option for t, option, _ in given if t == twice)
        raise ValueError(f"{options}: both name topic {twice}; each option needs its own topic")
    base_frame = _frame(base_frame)
    bag = _read_bag(Path(bag_path), topics, ground_truth_topic)

    # The clock: ticks from the first heat map to the last; each keeps its latest heat map.
    shape = bag.images[0].shape
    for stamp, image in zip(bag.image_stamps, bag.images, strict=True):
        if image.shape != shape:
            raise SequenceError(f"--heatmap-topic: {heatmap_topic} changes size from {shape} to {image.shape} "
                                f"at stamp {stamp} ns")
    stamps = np.array(bag.image_stamps, np.int64)
    t0 = int(stamps.min())
    rel = (stamps - t0) * 1e-9
    tick_of = np.maximum(np.ceil(rel * rate - _TICK_SLACK), 0).astype(np.int64)
    num_steps = int(tick_of.max()) + 1
    chosen = np.full(num_steps, -1, np.int64)
    for j in np.argsort(stamps, kind="stable"):
        chosen[tick_of[j]] = j
    has = chosen >= 0
    ticks = np.arange(num_steps) / rate
    heatmaps = np.zeros((num_steps, *shape), np.float32)
    heatmaps[has] = np.stack([bag.images[j] for j in chosen[has]])

    intrinsics = _intrinsics(bag, shape, camera_info_topic)

    tree = _TfTree(bag.tf)
    if camera_frame is None:
        camera_frame = _one_frame(bag.image_frames, f"--heatmap-topic: {heatmap_topic} header.frame_id")
        if not camera_frame:
            raise SequenceError(f"--heatmap-topic: {heatmap_topic} has an empty header.frame_id; "
                                "pass --camera-frame (the camera's optical frame)")
    camera_frame = _frame(camera_frame)
    cam_times = np.where(has, rel[np.maximum(chosen, 0)], ticks)
    cam_to_base = tree.lookup(base_frame, camera_frame, cam_times, t0, what="--camera-frame")

    # Odometry: the base pose in the odometry frame at each tick, projected onto the ground.
    odom_stamps = np.array([o[0] for o in bag.odom], np.int64)
    quats = np.stack([o[4] for o in bag.odom])
    if np.any(np.linalg.norm(quats, axis=-1) < 1e-6):
        bad = int(odom_stamps[np.argmax(np.linalg.norm(quats, axis=-1) < 1e-6)])
        raise SequenceError(f"--odom-topic: {odom_topic} has a zero orientation quaternion at stamp {bad} ns")
    track = _Track((odom_stamps - t0) * 1e-9, np.stack([o[3] for o in bag.odom]), quats)
    pose = track.at(ticks)
    child = _one_frame([o[2] for o in bag.odom], f"--odom-topic: {odom_topic} child_frame_id") or base_frame
    if child != base_frame:
        pose = pose @ tree.lookup(child, base_frame, ticks, t0, what=f"--odom-topic ({odom_topic} child_frame_id)")
    odometry = _odometry(_planar(pose))

    ground_truth = None
    if ground_truth_topic is not None:
        frame = _one_frame([g[1] for g in bag.truth], f"--ground-truth-topic: {ground_truth_topic}") or base_frame
        gt_rel = (np.array([g[0] for g in bag.truth], np.int64) - t0) * 1e-9
        points = np.stack([g[2] for g in bag.truth])
        order = np.argsort(gt_rel, kind="stable")
        gt_rel, points = gt_rel[order], points[order]
        at_ticks = np.stack([np.interp(ticks, gt_rel, points[:, i]) for i in range(3)], axis=-1)
        if frame != base_frame:
            to_base = tree.lookup(base_frame, frame, ticks, t0, what=f"--ground-truth-topic ({ground_truth_topic})")
            at_ticks = np.einsum("nij,nj->ni", to_base[:, :3, :3], at_ticks) + to_base[:, :3, 3]
        ground_truth = at_ticks[:, :2]

    return validate_sequence(
        Sequence(
            heatmaps=heatmaps,
            has_heatmap=has,
            intrinsics=intrinsics,
            cam_to_base=np.ascontiguousarray(cam_to_base, np.float64),
            odometry=odometry,
            ball_radius=np.asarray(ball_radius, np.float64),
            dt=np.asarray(1.0 / rate, np.float64),
            ground_truth=ground_truth,
            stamps=t0 + np.round(np.arange(num_steps) * (1e9 / rate)).astype(np.int64),  # the bag's clock per tick
        )
    )
