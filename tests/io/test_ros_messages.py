"""Tests for heatpf_jax.io.ros_messages: messages decoded independently (NumPy on the CDR fields, SciPy rotations),
and the inbound conversions against ``heatpf import-rosbag`` on the import tests' bag."""

import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.highlevel import AnyReader  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from heatpf_jax.estimate.modes import Modes  # noqa: E402
from heatpf_jax.io import ros_messages as rm  # noqa: E402
from heatpf_jax.io.rosbag_import import import_rosbag  # noqa: E402
from heatpf_jax.memory import TrackTable  # noqa: E402
from heatpf_jax.sim import simulate  # noqa: E402
from tests.io.test_rosbag_import import HEATMAP, INFO, ODOM, ROS2, TOPICS, Spec, write_bag  # noqa: E402

STAMP = 1_700_000_000_123_456_789


def _round_trip(msg):
    """Serialised to CDR and back, as a bag or a raw publisher carries it."""
    return ROS2.deserialize_cdr(ROS2.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__)


def _decode_cloud(msg) -> dict[str, np.ndarray]:
    """The fields of a PointCloud2 by their own offsets and datatypes, read with NumPy alone."""
    kinds = {7: "f4", 8: "f8"}
    endian = ">" if msg.is_bigendian else "<"
    fields = msg.fields
    dtype = np.dtype({"names": [f.name for f in fields], "formats": [endian + kinds[f.datatype] for f in fields],
                      "offsets": [f.offset for f in fields], "itemsize": msg.point_step})
    data = np.asarray(msg.data, np.uint8).tobytes()
    assert len(data) == msg.row_step * msg.height
    return {name: arr.astype(np.float64) for name, arr in
            zip(dtype.names, (np.frombuffer(data, dtype)[n] for n in dtype.names), strict=True)}


def test_point_cloud_fields_and_values(rng):
    xy = rng.normal(size=(37, 2)).astype(np.float32)
    weight = rng.uniform(size=37).astype(np.float32)
    msg = _round_trip(rm.point_cloud(xy, weight, STAMP, "base_footprint", z=0.07))
    assert msg.__msgtype__ == "sensor_msgs/msg/PointCloud2"
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, 7, 1), ("y", 4, 7, 1), ("z", 8, 7, 1), ("weight", 12, 7, 1)]
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 37, 16, 16 * 37)
    assert msg.is_dense and not msg.is_bigendian
    assert rm.stamp_ns(msg.header) == STAMP and msg.header.frame_id == "base_footprint"
    cloud = _decode_cloud(msg)
    np.testing.assert_array_equal(cloud["x"], xy[:, 0])
    np.testing.assert_array_equal(cloud["y"], xy[:, 1])
    np.testing.assert_array_equal(cloud["z"], np.float32(0.07))
    np.testing.assert_array_equal(cloud["weight"], weight)
    empty = _round_trip(rm.point_cloud(np.zeros((0, 2)), np.zeros(0), STAMP, "b"))
    assert empty.width == 0 and empty.row_step == 0 and len(empty.data) == 0


def test_particle_and_measurement_clouds(rng):
    xy = rng.normal(size=(10, 2)).astype(np.float32)
    log_w = np.log(rng.dirichlet(np.ones(10))).astype(np.float32)
    state = type("S", (), {"particles": type("P", (), {"xy": xy})(), "log_weights": log_w})()
    cloud = _decode_cloud(rm.particle_cloud(state, 5, "b"))
    np.testing.assert_allclose(cloud["weight"], np.exp(log_w), rtol=1e-6)
    valid = rng.uniform(size=10) < 0.5
    buffer = type("B", (), {"xy": xy, "weight": np.exp(log_w), "valid": valid})()
    cloud = _decode_cloud(rm.measurement_cloud(buffer, 5, "b"))
    np.testing.assert_array_equal(np.stack([cloud["x"], cloud["y"]], -1), xy[valid])


def test_pose_with_covariance_places_the_2x2_block(rng):
    a = rng.normal(size=(2, 2))
    cov = a @ a.T
    msg = _round_trip(rm.pose_with_covariance([1.25, -0.5], cov, STAMP, "base_footprint", z=0.07))
    p = msg.pose.pose
    assert (p.position.x, p.position.y, p.position.z) == (1.25, -0.5, 0.07)
    assert (p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w) == (0, 0, 0, 1)
    full = np.array(msg.pose.covariance).reshape(6, 6)
    np.testing.assert_array_equal(full[[0, 0, 1, 1], [0, 1, 0, 1]], cov.reshape(-1))
    full[:2, :2] = 0
    assert not full.any()
    assert rm.stamp_ns(msg.header) == STAMP


def test_matrix_to_quaternion_against_scipy():
    rots = Rotation.random(500, random_state=3)
    for r, q in zip(rots.as_matrix(), rots.as_quat(), strict=True):
        got = rm.matrix_to_quaternion(r)
        np.testing.assert_allclose(got, q if q[3] >= 0 else -q, atol=1e-12)
    for axis in np.eye(3):  # 180-degree turns: w = 0
        r = Rotation.from_rotvec(np.pi * axis).as_matrix()
        np.testing.assert_allclose(rm.quaternion_to_matrix(rm.matrix_to_quaternion(r)[None])[0], r, atol=1e-12)


def test_tf_message_round_trip(rng):
    pose = np.eye(4)
    pose[:3, :3] = Rotation.from_euler("xyz", rng.uniform(-3, 3, 3)).as_matrix()
    pose[:3, 3] = rng.normal(size=3)
    msg = _round_trip(rm.tf_message(pose, STAMP, "base_footprint", "heatpf_camera_optical"))
    (tr,) = msg.transforms
    assert (tr.header.frame_id, tr.child_frame_id, rm.stamp_ns(tr.header)) == (
        "base_footprint", "heatpf_camera_optical", STAMP)
    q = rm.quaternion(tr.transform.rotation)
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), pose[:3, :3], atol=1e-12)
    np.testing.assert_allclose(rm.transform_to_matrix(tr.transform), pose, atol=1e-12)


def test_mode_markers_ellipses():
    turn = Rotation.from_euler("z", 0.6).as_matrix()[:2, :2]
    cov = np.stack([turn @ np.diag([0.09, 0.01]) @ turn.T, np.diag([0.04, 0.04]), np.eye(2)])
    modes = Modes(weight=np.array([0.7, 0.3, 0.0]), mean=np.array([[1.0, 2.0], [3.0, -1.0], [0.0, 0.0]]), cov=cov,
                  valid=np.array([True, True, False]))
    msg = _round_trip(rm.mode_markers(modes, STAMP, "base_footprint", z=0.07))
    first, *marks = msg.markers
    assert first.action == 3  # DELETEALL: the previous step's modes go
    assert [(m.ns, m.id, m.type, m.action) for m in marks] == [("modes", 0, 3, 0), ("modes", 1, 3, 0)]
    m = marks[0]
    assert (m.pose.position.x, m.pose.position.y, m.pose.position.z) == (1.0, 2.0, 0.07)
    np.testing.assert_allclose((m.scale.x, m.scale.y), (4 * 0.3, 4 * 0.1), rtol=1e-9)  # 2-sigma diameters
    yaw = 2 * np.arctan2(m.pose.orientation.z, m.pose.orientation.w)
    assert np.sin(yaw - 0.6) == pytest.approx(0.0, abs=1e-9)  # the major axis, either way round
    assert marks[0].color.a > marks[1].color.a > 0
    assert rm.stamp_ns(m.header) == STAMP and m.header.frame_id == "base_footprint"


def test_track_markers():
    tracks = TrackTable(id=np.array([4, 9, 2]), valid=np.array([True, False, True]),
                        mean=np.array([[1.0, 0.5, 0.2, -0.1], [0, 0, 0, 0], [2.0, -1.0, 0.0, 0.0]]),
                        cov=np.zeros((3, 4, 4)), age=np.zeros(3), hits=np.zeros(3, int), found=np.zeros(3, bool),
                        next_id=np.array(10))
    msg = _round_trip(rm.track_markers(tracks, STAMP, "base_footprint", z=0.07, horizon=2.0))
    assert msg.markers[0].action == 3
    got = [(m.ns, m.id, m.type) for m in msg.markers[1:]]
    assert got == [("tracks", 4, 2), ("track_velocity", 4, 0), ("tracks", 2, 2), ("track_velocity", 2, 0)]
    arrow = msg.markers[2]
    assert [(p.x, p.y, p.z) for p in arrow.points] == [(1.0, 0.5, 0.07), (1.4, 0.3, 0.07)]


def test_step_messages_topics():
    info = type("I", (), {"mean": np.zeros(2), "cov": np.eye(2), "modes": Modes(np.zeros(0), np.zeros((0, 2)),
                          np.zeros((0, 2, 2)), np.zeros(0, bool)), "tracks": None})()
    assert list(rm.step_messages(info, None, 0)) == ["/heatpf/estimate"]
    state = type("S", (), {"particles": type("P", (), {"xy": np.zeros((3, 2))})(), "log_weights": np.zeros(3),
                           "buffer": type("B", (), {"xy": np.zeros((2, 2)), "weight": np.ones(2),
                                                    "valid": np.ones(2, bool)})()})()
    out = rm.step_messages(info, state, 0, namespace="/ball")
    assert list(out) == ["/ball/estimate", "/ball/particles", "/ball/measurements"]


def test_heatmap_from_image_errors_and_bytes():
    image = ROS2.types["sensor_msgs/msg/Image"]
    header = ROS2.types["std_msgs/msg/Header"](stamp=ROS2.types["builtin_interfaces/msg/Time"](sec=1, nanosec=2),
                                              frame_id="cam")
    act = np.array([[0, 128, 255], [1, 2, 3]], np.uint8)
    msg = image(header=header, height=2, width=3, encoding="mono8", is_bigendian=0, step=3, data=act.reshape(-1))
    np.testing.assert_array_equal(rm.heatmap_from_image(msg), act / np.float32(255))
    as_bytes = dataclasses.replace(msg, data=act.tobytes())  # rclpy-style bytes
    np.testing.assert_array_equal(rm.heatmap_from_image(as_bytes), act / np.float32(255))
    with pytest.raises(ValueError, match=r"^heat map has encoding 'rgb8' \(stamp 1000000002 ns\)"):
        rm.heatmap_from_image(dataclasses.replace(msg, encoding="rgb8"), "heat map")
    logit = np.full((2, 3), 2.0, "<f4")
    with pytest.raises(ValueError, match=r"activations in \[2, 2\]"):
        rm.heatmap_from_image(dataclasses.replace(msg, encoding="32FC1", step=12, data=logit.view(np.uint8).ravel()))


def test_messages_in_give_the_import_step_inputs(tmp_path):
    """Each step's messages through step_inputs equal the imported sequence's step (heat map, intrinsics,
    cam_to_base, odometry), on a bag of the import tests (camera info at 3x the heat map's size)."""
    sim = simulate("walking", 4, num_steps=8, shrink=4)
    path = write_bag(tmp_path / "bag", sim, Spec(storage="mcap", encoding="32FC1", truth=None, info_scale=3))
    seq = import_rosbag(path, **TOPICS)
    images, infos, cams, odoms = [], [], [], []
    with AnyReader([path], default_typestore=ROS2) as reader:
        for conn, _, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == HEATMAP:
                images.append(msg)
            elif conn.topic == INFO:
                infos.append(msg)
            elif conn.topic == ODOM:
                odoms.append(rm.pose_to_matrix(msg.pose.pose))
            elif conn.topic == "/tf" and msg.transforms[0].child_frame_id == "camera_optical":
                cams.append(rm.transform_to_matrix(msg.transforms[0].transform))
    odometry = rm.odometry_deltas(rm.planar_poses(np.stack(odoms)))
    for t in range(seq.num_steps):
        got = rm.step_inputs(images[t], infos[t], cams[t], odometry[t], plane_height=0.07, dt=0.1)
        np.testing.assert_array_equal(got.heatmap, seq.heatmaps[t])
        assert bool(got.has_heatmap) == bool(seq.has_heatmap[t])
        np.testing.assert_array_equal(got.intrinsics, seq.intrinsics.astype(np.float32))
        np.testing.assert_allclose(got.cam_to_base, seq.cam_to_base[t], rtol=0, atol=1e-6)
        np.testing.assert_allclose(got.odometry, seq.odometry[t], rtol=0, atol=1e-6)
        np.testing.assert_allclose(got.odometry, sim.odometry[t] if t else 0.0, rtol=0, atol=1e-5)
    none = rm.step_inputs(None, infos[0], cams[0], plane_height=0.07, dt=0.1, heatmap_shape=(37, 50))
    assert not none.has_heatmap and none.heatmap.shape == (37, 50) and not none.heatmap.any()
