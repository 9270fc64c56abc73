"""ROS 2 messages in and out of the filter: pure conversions between messages and arrays.

Used by ``heatpf import-rosbag`` (:mod:`heatpf_jax.io.rosbag_import`), ``heatpf run --bag``
(:mod:`heatpf_jax.io.rosbag_export`) and a robot's node (``examples/ros2_node.py``), so that all three read
and write the same thing.

**In** (any object with the ROS 2 field names: `rosbags <https://gitlab.com/ternaris/rosbags>`_'
messages, rclpy's, or a stand-in): :func:`heatmap_from_image` (``sensor_msgs/msg/Image``),
:func:`intrinsics_from_camera_info` (``sensor_msgs/msg/CameraInfo``), :func:`transform_to_matrix` and
:func:`pose_to_matrix` (``geometry_msgs`` transforms and poses), :func:`planar_poses` and
:func:`odometry_deltas` (``nav_msgs/msg/Odometry`` poses to the filter's ``(dx, dy, dtheta)``), and
:func:`step_inputs`, which makes one step's :class:`~heatpf_jax.pieces.StepInputs` of them. These need
NumPy only.

**Out** (rosbags' message classes of the ROS 2 Humble type store; ``pip install "heatpf-jax[ros]"``):
:func:`pose_with_covariance` (the estimate), :func:`point_cloud` (points with a weight),
:func:`particle_cloud` and :func:`measurement_cloud` (from the filter's state), :func:`mode_markers` and
:func:`track_markers` (``StepInfo.modes`` and ``StepInfo.tracks``), :func:`tf_message` (a camera pose),
and :func:`step_messages`, every message of one step by topic. Serialise them with
``typestore().serialize_cdr(msg, msg.__msgtype__)`` for a bag or an rclpy raw publisher.

Everything is in the robot's base frame on the ground plane; ``z`` is the plane the filter works in
(the ball radius). Stamps are integer nanoseconds.
"""

from __future__ import annotations

import functools
from typing import Any

import numpy as np

from heatpf_jax.pieces import StepInputs

__all__ = [
    "CLIP_TOLERANCE",
    "ESTIMATE_TYPE",
    "MARKERS_TYPE",
    "POINTS_TYPE",
    "TF_TYPE",
    "camera_matrix",
    "frame_name",
    "heatmap_from_image",
    "intrinsics_from_camera_info",
    "matrix_to_quaternion",
    "measurement_cloud",
    "mode_markers",
    "odometry_deltas",
    "particle_cloud",
    "planar_poses",
    "point_cloud",
    "pose_matrices",
    "pose_to_matrix",
    "pose_with_covariance",
    "quaternion",
    "quaternion_to_matrix",
    "scale_intrinsics",
    "stamp_ns",
    "step_inputs",
    "step_messages",
    "tf_message",
    "track_markers",
    "transform_to_matrix",
    "typestore",
    "vector3",
]

ESTIMATE_TYPE = "geometry_msgs/msg/PoseWithCovarianceStamped"
POINTS_TYPE = "sensor_msgs/msg/PointCloud2"
MARKERS_TYPE = "visualization_msgs/msg/MarkerArray"
TF_TYPE = "tf2_msgs/msg/TFMessage"
CLIP_TOLERANCE = 1e-3  # 32FC1 activations this far outside [0, 1] are clipped; further out is an error
ROSBAGS_HINT = 'pip install "heatpf-jax[ros]"'


@functools.cache
def typestore():
    """rosbags' ROS 2 Humble type store: its ``types[name]`` are the message classes written here.

    Raises:
        RuntimeError: the ``rosbags`` package is not installed (one line with the install command).
    """
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise RuntimeError(f"ROS messages need rosbags: {ROSBAGS_HINT}") from None
    return get_typestore(Stores.ROS2_HUMBLE)


# --- In: messages to arrays --------------------------------------------------------------------------------------


def stamp_ns(header) -> int:
    """A ``std_msgs/msg/Header``'s stamp in integer nanoseconds."""
    return int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)


def frame_name(name: str) -> str:
    """A frame id without a leading ``/`` (ROS 1 style)."""
    return str(name).lstrip("/")


def vector3(msg) -> np.ndarray:
    """``float64 [3]`` of a ``Vector3`` or ``Point``."""
    return np.array([msg.x, msg.y, msg.z], np.float64)


def quaternion(msg) -> np.ndarray:
    """``float64 [4]`` of a ``Quaternion``, in ROS order ``(x, y, z, w)``."""
    return np.array([msg.x, msg.y, msg.z, msg.w], np.float64)


def quaternion_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices ``[N, 3, 3]`` from quaternions ``[N, 4]`` in ROS order ``(x, y, z, w)`` (normalised here)."""
    x, y, z, w = np.moveaxis(q / np.linalg.norm(q, axis=-1, keepdims=True), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def matrix_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """The unit quaternion ``(x, y, z, w)`` ``float64 [4]`` (``w >= 0``) of a rotation matrix ``[3, 3]``."""
    r = np.asarray(rot, np.float64)
    # Shepperd's method: start from the largest of 4 w^2, 4 x^2, 4 y^2, 4 z^2 (no cancellation).
    diag = np.array([np.trace(r), r[0, 0], r[1, 1], r[2, 2]])
    i = int(np.argmax([diag[0], 2 * r[0, 0] - diag[0], 2 * r[1, 1] - diag[0], 2 * r[2, 2] - diag[0]]))
    if i == 0:
        w = 0.5 * np.sqrt(max(1.0 + diag[0], 0.0))
        q = np.array([(r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w), w])
    elif i == 1:
        x = 0.5 * np.sqrt(max(1.0 + 2 * r[0, 0] - diag[0], 0.0))
        q = np.array([x, (r[0, 1] + r[1, 0]) / (4 * x), (r[0, 2] + r[2, 0]) / (4 * x), (r[2, 1] - r[1, 2]) / (4 * x)])
    elif i == 2:
        y = 0.5 * np.sqrt(max(1.0 + 2 * r[1, 1] - diag[0], 0.0))
        q = np.array([(r[0, 1] + r[1, 0]) / (4 * y), y, (r[1, 2] + r[2, 1]) / (4 * y), (r[0, 2] - r[2, 0]) / (4 * y)])
    else:
        z = 0.5 * np.sqrt(max(1.0 + 2 * r[2, 2] - diag[0], 0.0))
        q = np.array([(r[0, 2] + r[2, 0]) / (4 * z), (r[1, 2] + r[2, 1]) / (4 * z), z, (r[1, 0] - r[0, 1]) / (4 * z)])
    q = q / np.linalg.norm(q)
    return -q if q[3] < 0 else q


def pose_matrices(trans: np.ndarray, quat: np.ndarray) -> np.ndarray:
    """Homogeneous transforms ``[N, 4, 4]`` from translations ``[N, 3]`` and quaternions ``[N, 4]``."""
    out = np.zeros((trans.shape[0], 4, 4))
    out[:, :3, :3] = quaternion_to_matrix(quat)
    out[:, :3, 3] = trans
    out[:, 3, 3] = 1.0
    return out


def transform_to_matrix(msg) -> np.ndarray:
    """``float64 [4, 4]`` of a ``geometry_msgs/msg/Transform`` (child coordinates to parent coordinates)."""
    return pose_matrices(vector3(msg.translation)[None], quaternion(msg.rotation)[None])[0]


def pose_to_matrix(msg) -> np.ndarray:
    """``float64 [4, 4]`` of a ``geometry_msgs/msg/Pose``."""
    return pose_matrices(vector3(msg.position)[None], quaternion(msg.orientation)[None])[0]


def _bytes(data) -> np.ndarray:
    if isinstance(data, bytes | bytearray | memoryview):
        return np.frombuffer(data, np.uint8)
    return np.asarray(data, np.uint8)


def heatmap_from_image(msg, name: str = "image") -> np.ndarray:
    """The activations ``float32 [H, W]`` in ``[0, 1]`` of a ``sensor_msgs/msg/Image`` heat map.

    ``mono8`` (or ``8UC1``) is divided by 255; ``32FC1`` is taken as is (either byte order) and clipped to
    ``[0, 1]`` after checking that no value is non-finite or further than ``CLIP_TOLERANCE`` outside (a
    logit map is rejected, not silently clipped). Row padding (``step > width * bytes``) is dropped.

    Args:
        msg: the image.
        name: what the error messages call it (an option and a topic, say).

    Raises:
        ValueError: ``"{name} has ..."``: another encoding, a malformed or non-finite image, activations
            outside ``[0, 1]``.
    """
    enc = str(msg.encoding)
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    data = _bytes(msg.data)
    stamp = stamp_ns(msg.header)
    if enc in ("mono8", "8UC1"):
        itemsize, dtype = 1, np.dtype(np.uint8)
    elif enc == "32FC1":
        itemsize, dtype = 4, np.dtype(">f4" if msg.is_bigendian else "<f4")
    else:
        raise ValueError(f"{name} has encoding {enc!r} (stamp {stamp} ns); supported: mono8 (or 8UC1), 32FC1")
    if h < 1 or w < 1 or step < w * itemsize or data.size < h * step:
        raise ValueError(
            f"{name} has a malformed image at stamp {stamp} ns ({h} x {w}, step {step}, {data.size} bytes)"
        )
    rows = data[: h * step].reshape(h, step)[:, : w * itemsize]
    if itemsize == 1:
        return rows.astype(np.float32) / np.float32(255.0)
    act = np.ascontiguousarray(rows).view(dtype).astype(np.float32)
    if not np.all(np.isfinite(act)):
        raise ValueError(f"{name} has a non-finite activation at stamp {stamp} ns")
    lo, hi = float(act.min()), float(act.max())
    if lo < -CLIP_TOLERANCE or hi > 1.0 + CLIP_TOLERANCE:
        raise ValueError(
            f"{name} has activations in [{lo:.6g}, {hi:.6g}] at stamp {stamp} ns; "
            "32FC1 heat maps must lie in [0, 1] (apply the sigmoid to a logit map before recording)"
        )
    return np.clip(act, 0.0, 1.0)


def camera_matrix(msg) -> tuple[int, int, np.ndarray]:
    """``(width, height, K [9])`` of a ``sensor_msgs/msg/CameraInfo`` (ROS 1's ``K`` read as well)."""
    k = msg.k if hasattr(msg, "k") else msg.K
    return int(msg.width), int(msg.height), np.asarray(k, np.float64).reshape(9)


def scale_intrinsics(k: np.ndarray, width: int, height: int, shape: tuple[int, int]) -> np.ndarray:
    """``(fx, fy, cx, cy)`` ``float64 [4]`` of ``K`` for a ``width x height`` image, rescaled to a heat map ``shape``.

    With ``sx = W / width`` and ``sy = H / height``: ``fx sx``, ``fy sy``, ``(cx + 0.5) sx - 0.5``,
    ``(cy + 0.5) sy - 0.5`` (pixel centres at integers). Distortion is ignored.
    """
    h, w = shape
    sx, sy = w / width, h / height
    fx, fy, cx, cy = k[0], k[4], k[2], k[5]
    return np.array([fx * sx, fy * sy, (cx + 0.5) * sx - 0.5, (cy + 0.5) * sy - 0.5], np.float64)


def intrinsics_from_camera_info(msg, shape: tuple[int, int], name: str = "camera info") -> np.ndarray:
    """The heat map's ``(fx, fy, cx, cy)`` ``float64 [4]`` from a ``CameraInfo`` (:func:`scale_intrinsics`).

    Raises:
        ValueError: ``"{name} has ..."``: no calibration (``fx`` or ``fy`` not positive) or no image size.
    """
    width, height, k = camera_matrix(msg)
    if k[0] <= 0 or k[4] <= 0:
        raise ValueError(f"{name} has no calibration (K = {k.tolist()})")
    if width <= 0 or height <= 0:
        raise ValueError(f"{name} has an image size of {width} x {height}")
    return scale_intrinsics(k, width, height, shape)


def planar_poses(pose: np.ndarray) -> np.ndarray:
    """``(x, y, yaw)`` ``[N, 3]`` of poses ``[N, 4, 4]`` projected onto the ground plane."""
    return np.stack([pose[:, 0, 3], pose[:, 1, 3], np.arctan2(pose[:, 1, 0], pose[:, 0, 0])], axis=-1)


def odometry_deltas(planar: np.ndarray) -> np.ndarray:
    """``(dx, dy, dtheta)`` ``[T, 3]`` between consecutive planar poses ``[T, 3]``, in the base frame of the
    earlier one (the sequence file's ``odometry``; row 0 is zero)."""
    odom = np.zeros_like(planar)
    delta = planar[1:, :2] - planar[:-1, :2]
    c, s = np.cos(planar[:-1, 2]), np.sin(planar[:-1, 2])
    odom[1:, 0] = c * delta[:, 0] + s * delta[:, 1]
    odom[1:, 1] = -s * delta[:, 0] + c * delta[:, 1]
    dth = planar[1:, 2] - planar[:-1, 2]
    odom[1:, 2] = np.arctan2(np.sin(dth), np.cos(dth))
    return odom


def step_inputs(
    image,
    camera_info,
    cam_to_base: np.ndarray,
    odometry=(0.0, 0.0, 0.0),
    *,
    plane_height: float,
    dt: float,
    heatmap_shape: tuple[int, int] | None = None,
) -> StepInputs:
    """One filter step's :class:`~heatpf_jax.pieces.StepInputs` (NumPy ``float32``) from messages.

    Args:
        image: the ``sensor_msgs/msg/Image`` heat map of this step, or ``None`` (no new heat map: a zero map of
            ``heatmap_shape`` with ``has_heatmap`` False).
        camera_info: the heat maps' ``sensor_msgs/msg/CameraInfo``.
        cam_to_base: ``[4, 4]`` camera optical frame -> base frame now (:func:`transform_to_matrix` of the tf).
        odometry: ``(dx, dy, dtheta)`` since the previous step (:func:`odometry_deltas`).
        plane_height: the ball radius, metres.
        dt: the filter period, seconds.
        heatmap_shape: ``(H, W)``; required when ``image`` is ``None``.
    """
    if image is None:
        if heatmap_shape is None:
            raise ValueError("heatmap_shape: required for a step without a heat map")
        heatmap, has = np.zeros(heatmap_shape, np.float32), False
    else:
        heatmap, has = heatmap_from_image(image), True
    return StepInputs(
        heatmap=heatmap,
        has_heatmap=np.asarray(has),
        cam_to_base=np.asarray(cam_to_base, np.float32),
        odometry=np.asarray(odometry, np.float32),
        intrinsics=intrinsics_from_camera_info(camera_info, heatmap.shape).astype(np.float32),
        plane_height=np.asarray(plane_height, np.float32),
        dt=np.asarray(dt, np.float32),
    )


# --- Out: arrays to messages -------------------------------------------------------------------------------------


def _msg(name: str, **fields):
    return typestore().types[name](**fields)


def _header(stamp: int, frame_id: str):
    stamp = int(stamp)
    time = _msg("builtin_interfaces/msg/Time", sec=stamp // 1_000_000_000, nanosec=stamp % 1_000_000_000)
    return _msg("std_msgs/msg/Header", stamp=time, frame_id=frame_id)


def _point(x: float, y: float, z: float):
    return _msg("geometry_msgs/msg/Point", x=float(x), y=float(y), z=float(z))


def _yaw_quaternion(yaw: float):
    return _msg("geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=float(np.sin(yaw / 2)), w=float(np.cos(yaw / 2)))


def pose_with_covariance(mean, cov, stamp: int, frame_id: str, z: float = 0.0):
    """The estimate as a ``geometry_msgs/msg/PoseWithCovarianceStamped``.

    Args:
        mean: ``[2]`` ``(x, y)`` in ``frame_id``.
        cov: ``[2, 2]`` its covariance: the 6 x 6 covariance's ``(x, y)`` block (row-major indices 0, 1, 6, 7);
            every other entry is zero. The orientation is the identity.
        stamp: nanoseconds.
        frame_id: the robot's base frame.
        z: the height of the point (the ball radius).
    """
    mean, cov = np.asarray(mean, np.float64), np.asarray(cov, np.float64)
    full = np.zeros((6, 6))
    full[:2, :2] = cov
    pose = _msg("geometry_msgs/msg/Pose", position=_point(mean[0], mean[1], z), orientation=_yaw_quaternion(0.0))
    return _msg(
        ESTIMATE_TYPE,
        header=_header(stamp, frame_id),
        pose=_msg("geometry_msgs/msg/PoseWithCovariance", pose=pose, covariance=full.reshape(36)),
    )


def point_cloud(xy, weight, stamp: int, frame_id: str, z: float = 0.0):
    """Points with a weight as a ``sensor_msgs/msg/PointCloud2``: fields ``x, y, z, weight``, ``float32``.

    One row (``height = 1``, ``width = N``), little-endian, 16 bytes a point (offsets 0, 4, 8, 12), dense.

    Args:
        xy: ``[N, 2]`` positions in ``frame_id``.
        weight: ``[N]`` their weights.
        stamp: nanoseconds.
        frame_id: the robot's base frame.
        z: the height of every point.
    """
    xy, weight = np.asarray(xy, np.float32).reshape(-1, 2), np.asarray(weight, np.float32).reshape(-1)
    n = xy.shape[0]
    points = np.empty((n, 4), "<f4")
    points[:, :2], points[:, 2], points[:, 3] = xy, np.float32(z), weight
    field = typestore().types["sensor_msgs/msg/PointField"]
    fields = [field(name=name, offset=4 * i, datatype=field.FLOAT32, count=1)
              for i, name in enumerate(("x", "y", "z", "weight"))]
    return _msg(
        POINTS_TYPE,
        header=_header(stamp, frame_id),
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=16,
        row_step=16 * n,
        data=points.reshape(-1).view(np.uint8),
        is_dense=True,
    )


def particle_cloud(state, stamp: int, frame_id: str, z: float = 0.0):
    """A particle filter state's particles (``state.particles.xy``) with their weights
    (``exp(state.log_weights)``) as a :func:`point_cloud`."""
    return point_cloud(np.asarray(state.particles.xy), np.exp(np.asarray(state.log_weights)), stamp, frame_id, z)


def measurement_cloud(buffer, stamp: int, frame_id: str, z: float = 0.0):
    """The valid measurements of a buffer (:class:`~heatpf_jax.measurements.Measurements`, e.g.
    ``state.buffer``) with their weights as a :func:`point_cloud`, in slot order."""
    valid = np.asarray(buffer.valid, bool)
    return point_cloud(np.asarray(buffer.xy)[valid], np.asarray(buffer.weight)[valid], stamp, frame_id, z)


def _colour(r: float, g: float, b: float, a: float):
    return _msg("std_msgs/msg/ColorRGBA", r=float(r), g=float(g), b=float(b), a=float(a))


def _marker(stamp, frame_id, ns, ident, kind, *, action=0, xyz=(0.0, 0.0, 0.0), yaw=0.0, scale=(0.0, 0.0, 0.0),
            colour=(0.0, 0.0, 0.0, 0.0), points=()):
    store = typestore().types
    return store["visualization_msgs/msg/Marker"](
        header=_header(stamp, frame_id),
        ns=ns,
        id=int(ident),
        type=int(kind),
        action=int(action),
        pose=store["geometry_msgs/msg/Pose"](position=_point(*xyz), orientation=_yaw_quaternion(yaw)),
        scale=store["geometry_msgs/msg/Vector3"](x=float(scale[0]), y=float(scale[1]), z=float(scale[2])),
        color=_colour(*colour),
        lifetime=store["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
        frame_locked=False,
        points=[_point(*p) for p in points],
        colors=[],
        texture_resource="",
        texture=store["sensor_msgs/msg/CompressedImage"](
            header=_header(0, ""), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[],
        text="",
        mesh_resource="",
        mesh_file=store["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


def _delete_all(stamp, frame_id):
    marker = typestore().types["visualization_msgs/msg/Marker"]
    return _marker(stamp, frame_id, "", 0, 0, action=marker.DELETEALL)


def _ellipse(cov: np.ndarray, sigmas: float = 2.0) -> tuple[float, float, float]:
    """``(diameter along the major axis, along the minor axis, yaw of the major axis)`` of ``sigmas``-sigma."""
    vals, vecs = np.linalg.eigh(np.asarray(cov, np.float64))
    vals = np.maximum(vals, 0.0)
    yaw = float(np.arctan2(vecs[1, 1], vecs[0, 1]))
    return 2 * sigmas * float(np.sqrt(vals[1])), 2 * sigmas * float(np.sqrt(vals[0])), yaw


def mode_markers(modes, stamp: int, frame_id: str, z: float = 0.0):
    """One step's modes (:class:`~heatpf_jax.estimate.modes.Modes`, ``StepInfo.modes`` at step ``t``) as a
    ``visualization_msgs/msg/MarkerArray``.

    A ``DELETEALL`` marker first (the previous step's modes disappear), then one flat ``CYLINDER`` per valid
    mode (namespace ``modes``, id = the mode's slot): centred on its mean, its diameters the 2-sigma
    ellipse of its covariance (major axis along the marker's x), 2 cm high, its opacity the mode's weight.
    """
    marker = typestore().types["visualization_msgs/msg/Marker"]
    weight, mean, cov, valid = (np.asarray(x) for x in (modes.weight, modes.mean, modes.cov, modes.valid))
    out = [_delete_all(stamp, frame_id)]
    for k in np.flatnonzero(valid):
        major, minor, yaw = _ellipse(cov[k])
        alpha = float(np.clip(0.2 + 0.8 * weight[k], 0.0, 1.0))
        out.append(_marker(stamp, frame_id, "modes", k, marker.CYLINDER, xyz=(mean[k, 0], mean[k, 1], z), yaw=yaw,
                           scale=(major, minor, 0.02), colour=(0.1, 0.4, 1.0, alpha)))
    return _msg(MARKERS_TYPE, markers=out)


def track_markers(tracks, stamp: int, frame_id: str, z: float = 0.0, horizon: float = 1.0):
    """One step's long-term memory tracks (:class:`~heatpf_jax.memory.table.TrackTable`, ``StepInfo.tracks`` at step
    ``t``) as a ``visualization_msgs/msg/MarkerArray``.

    A ``DELETEALL`` marker first, then per valid track a ``SPHERE`` of 10 cm at its position (namespace
    ``tracks``, id = the track's id) and an ``ARROW`` from there to where its velocity takes it in ``horizon``
    seconds (namespace ``track_velocity``, same id).
    """
    marker = typestore().types["visualization_msgs/msg/Marker"]
    ids, valid, mean = (np.asarray(x) for x in (tracks.id, tracks.valid, tracks.mean))
    out = [_delete_all(stamp, frame_id)]
    for m in np.flatnonzero(valid):
        x, y, vx, vy = (float(v) for v in mean[m])
        out.append(_marker(stamp, frame_id, "tracks", ids[m], marker.SPHERE, xyz=(x, y, z), scale=(0.1, 0.1, 0.1),
                           colour=(1.0, 0.5, 0.0, 0.9)))
        out.append(_marker(stamp, frame_id, "track_velocity", ids[m], marker.ARROW, scale=(0.02, 0.04, 0.0),
                           colour=(1.0, 0.5, 0.0, 0.9),
                           points=((x, y, z), (x + horizon * vx, y + horizon * vy, z))))
    return _msg(MARKERS_TYPE, markers=out)


def tf_message(pose: np.ndarray, stamp: int, parent: str, child: str):
    """A ``tf2_msgs/msg/TFMessage`` with one transform: ``pose`` ``[4, 4]`` takes ``child`` coordinates to
    ``parent`` coordinates (``cam_to_base``: parent the base frame, child the camera's optical frame)."""
    pose = np.asarray(pose, np.float64)
    qx, qy, qz, qw = matrix_to_quaternion(pose[:3, :3])
    types = typestore().types
    transform = types["geometry_msgs/msg/Transform"](
        translation=types["geometry_msgs/msg/Vector3"](x=float(pose[0, 3]), y=float(pose[1, 3]), z=float(pose[2, 3])),
        rotation=types["geometry_msgs/msg/Quaternion"](x=float(qx), y=float(qy), z=float(qz), w=float(qw)),
    )
    stamped = types["geometry_msgs/msg/TransformStamped"](header=_header(stamp, parent), child_frame_id=child,
                                                          transform=transform)
    return _msg(TF_TYPE, transforms=[stamped])


def step_messages(
    info, state, stamp: int, *, frame_id: str = "base_footprint", z: float = 0.0, namespace: str = "/heatpf"
) -> dict[str, Any]:
    """Every message of one filter step, by topic (``{namespace}/...``).

    * ``estimate``: :func:`pose_with_covariance` of ``info.mean`` and ``info.cov``;
    * ``particles``, ``measurements``: :func:`particle_cloud` and :func:`measurement_cloud` of ``state``
      (the state after the step), where the model has particles and a buffer (not a Kalman baseline);
    * ``modes``, ``tracks``: :func:`mode_markers` and :func:`track_markers`, where the filter has modes
      (``K > 0``) and a long-term memory (capacity > 0).

    Args:
        info: one step's :class:`~heatpf_jax.filter.StepInfo` (no leading axis), NumPy or JAX.
        state: the state after that step (:class:`~heatpf_jax.filter.FilterState`), or ``None``.
        stamp: nanoseconds.
        frame_id: the robot's base frame.
        z: the height of every point (the ball radius).
        namespace: the topics' prefix.
    """
    out = {f"{namespace}/estimate": pose_with_covariance(info.mean, info.cov, stamp, frame_id, z)}
    if state is not None and hasattr(state, "particles") and hasattr(state.particles, "xy"):
        out[f"{namespace}/particles"] = particle_cloud(state, stamp, frame_id, z)
    if state is not None and hasattr(state, "buffer"):
        out[f"{namespace}/measurements"] = measurement_cloud(state.buffer, stamp, frame_id, z)
    modes = getattr(info, "modes", None)
    if modes is not None and np.shape(modes.valid)[-1] > 0:
        out[f"{namespace}/modes"] = mode_markers(modes, stamp, frame_id, z)
    tracks = getattr(info, "tracks", None)
    if tracks is not None and np.shape(tracks.valid)[-1] > 0:
        out[f"{namespace}/tracks"] = track_markers(tracks, stamp, frame_id, z)
    return out
