"""The example node (examples/ros2_node.py) wired to a stand-in for rclpy: fake messages in through its
subscriptions, and what it publishes equal to the conversion functions applied to a Tracker fed the same
inputs (rclpy itself is not installed here; the example imports it in ``main`` only)."""

import importlib.util
import sys
import types
from pathlib import Path

import jax
import numpy as np
import pytest

pytest.importorskip("rosbags")

import heatpf_jax as hp  # noqa: E402
from heatpf_jax.cli.settings import method_with_settings, parse_settings  # noqa: E402
from heatpf_jax.io import ros_messages as rm  # noqa: E402
from heatpf_jax.sim import integrate_odometry  # noqa: E402
from tests.cli.helpers import SMALL_SET  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
ROS2 = rm.typestore()
T0 = 1_700_000_000_000_000_000


def _load_example():
    spec = importlib.util.spec_from_file_location("heatpf_example_ros2_node", ROOT / "examples" / "ros2_node.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


class FakeNode:
    """What the example uses of ``rclpy.node.Node``."""

    params: dict = {}  # noqa: RUF012 (set by the test before main)

    def __init__(self, name):
        self.name, self.subs, self.pubs, self.timers, self.clock, self.destroyed = name, {}, {}, [], 0, False

    def declare_parameter(self, name, default):
        return types.SimpleNamespace(value=self.params.get(name, default))

    def create_subscription(self, msg_type, topic, callback, qos, raw=False):
        assert raw
        self.subs[topic] = (msg_type, callback, qos)

    def create_publisher(self, msg_type, topic, qos):
        pub = types.SimpleNamespace(msg_type=msg_type, sent=[])
        pub.publish = pub.sent.append
        self.pubs[topic] = pub
        return pub

    def create_timer(self, period, callback):
        self.timers.append((period, callback))

    def get_clock(self):
        return types.SimpleNamespace(now=lambda: types.SimpleNamespace(nanoseconds=self.clock))

    def destroy_node(self):
        self.destroyed = True


def _stand_ins(monkeypatch, spin):
    rclpy = types.ModuleType("rclpy")
    rclpy.calls = []
    rclpy.init = lambda args=None: rclpy.calls.append(("init", args))
    rclpy.shutdown = lambda: rclpy.calls.append(("shutdown",))
    rclpy.spin = spin
    node_mod, qos = types.ModuleType("rclpy.node"), types.ModuleType("rclpy.qos")
    node_mod.Node = FakeNode
    qos.DurabilityPolicy = types.SimpleNamespace(TRANSIENT_LOCAL="transient_local")
    qos.QoSProfile = lambda depth, durability: ("qos", depth, durability)
    rclpy.node, rclpy.qos = node_mod, qos
    rosidl, utilities = types.ModuleType("rosidl_runtime_py"), types.ModuleType("rosidl_runtime_py.utilities")
    utilities.get_message = lambda name: ("type", name)
    rosidl.utilities = utilities
    for name, mod in (("rclpy", rclpy), ("rclpy.node", node_mod), ("rclpy.qos", qos), ("rosidl_runtime_py", rosidl),
                      ("rosidl_runtime_py.utilities", utilities)):
        monkeypatch.setitem(sys.modules, name, mod)
    return rclpy


def _header(ns, frame):
    return ROS2.types["std_msgs/msg/Header"](
        stamp=ROS2.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


def _messages(seq, t, world):
    """Step ``t`` of ``seq`` as the robot would publish it: {topic: message}."""
    ns = T0 + t * int(round(float(seq.dt) * 1e9))
    types_ = ROS2.types
    out = {"/tf": rm.tf_message(seq.cam_to_base[t], ns, "base_footprint", "camera_optical")}
    fx, fy, cx, cy = seq.intrinsics
    h, w = seq.heatmaps.shape[1:]
    out["/camera_info"] = types_["sensor_msgs/msg/CameraInfo"](
        header=_header(ns, "camera_optical"), height=h, width=w, distortion_model="plumb_bob", d=np.zeros(5),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1.0]), r=np.eye(3).reshape(-1), p=np.zeros(12), binning_x=0,
        binning_y=0, roi=types_["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                                     do_rectify=False))
    pose = np.eye(4)
    c, s = np.cos(world[t, 2]), np.sin(world[t, 2])
    pose[:2, :2], pose[:2, 3] = [[c, -s], [s, c]], world[t, :2]
    odom = rm.pose_with_covariance(pose[:2, 3], np.eye(2), ns, "odom")
    odom.pose.pose.orientation = types_["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=float(np.sin(world[t, 2] / 2)),
                                                                        w=float(np.cos(world[t, 2] / 2)))
    zero = types_["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
    out["/odom"] = types_["nav_msgs/msg/Odometry"](
        header=odom.header, child_frame_id="base_footprint", pose=odom.pose,
        twist=types_["geometry_msgs/msg/TwistWithCovariance"](
            twist=types_["geometry_msgs/msg/Twist"](linear=zero, angular=zero), covariance=np.zeros(36)))
    if seq.has_heatmap[t]:
        act = np.ascontiguousarray(seq.heatmaps[t], "<f4")
        out["/heatmap"] = types_["sensor_msgs/msg/Image"](
            header=_header(ns, "camera_optical"), height=h, width=w, encoding="32FC1", is_bigendian=0, step=4 * w,
            data=act.view(np.uint8).reshape(-1))
    return ns, out


def test_node_publishes_the_conversions_of_a_tracker_run(small_sequence, monkeypatch):
    seq = small_sequence.head(8)
    example = _load_example()
    assert "rclpy" not in sys.modules  # importing the example does not need ROS
    world = integrate_odometry(seq.odometry)
    FakeNode.params = {"set": " ".join(SMALL_SET), "rate": 1.0 / float(seq.dt), "ball_radius": float(seq.ball_radius),
                       "seed": 3, "heatmap_topic": "/heatmap"}
    fed, nodes = [], []

    def spin(node):
        nodes.append(node)
        (period, tick), = node.timers
        assert period == pytest.approx(float(seq.dt))
        tick()  # nothing known yet: no step, nothing published
        assert all(not pub.sent for pub in node.pubs.values())
        for t in range(seq.num_steps):
            ns, msgs = _messages(seq, t, world)
            for topic, msg in msgs.items():
                node.subs[topic][1](ROS2.serialize_cdr(msg, msg.__msgtype__))
            node.clock = ns + 5
            tick()
            fed.append((ns + 5, msgs))

    rclpy = _stand_ins(monkeypatch, spin)
    assert example.main(["heatpf", "--ros-args"]) == 0
    (node,) = nodes
    assert rclpy.calls == [("init", ["heatpf", "--ros-args"]), ("shutdown",)] and node.destroyed
    assert {topic: sub[0][1] for topic, sub in node.subs.items()} == {
        "/heatmap": "sensor_msgs/msg/Image", "/camera_info": "sensor_msgs/msg/CameraInfo",
        "/odom": "nav_msgs/msg/Odometry", "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}
    assert node.subs["/tf_static"][2] == ("qos", 100, "transient_local")
    assert {topic: pub.msg_type[1] for topic, pub in node.pubs.items()} == {
        "/heatpf/estimate": rm.ESTIMATE_TYPE, "/heatpf/particles": rm.POINTS_TYPE,
        "/heatpf/measurements": rm.POINTS_TYPE}

    # The same inputs through the conversion functions into a Tracker of the same method, settings and seed.
    options, settings = parse_settings(SMALL_SET, ("heatmap",))
    model, params = method_with_settings("heatmap", options, settings)
    shape = seq.heatmaps.shape[1:]
    tracker = hp.Tracker(jax.random.key(3), model, params, heatmap_shape=shape,
                         intrinsics=rm.intrinsics_from_camera_info(fed[0][1]["/camera_info"], shape),
                         plane_height=float(seq.ball_radius), dt=float(seq.dt))
    poses = np.stack([rm.pose_to_matrix(msgs["/odom"].pose.pose) for _, msgs in fed])
    odometry = rm.odometry_deltas(rm.planar_poses(poses))
    np.testing.assert_allclose(odometry[1:], seq.odometry[1:], atol=1e-9)  # the robot's motion, recovered
    for t, (stamp, msgs) in enumerate(fed):
        image = msgs.get("/heatmap")
        heatmap = None if image is None else rm.heatmap_from_image(image)
        if heatmap is not None:
            np.testing.assert_array_equal(heatmap, seq.heatmaps[t])
        cam = rm.transform_to_matrix(msgs["/tf"].transforms[0].transform)
        np.testing.assert_allclose(cam, seq.cam_to_base[t], atol=1e-12)
        tracker.update(heatmap, cam, odometry[t])
        expected = rm.step_messages(tracker.last_info, tracker.state, stamp, frame_id="base_footprint",
                                    z=float(seq.ball_radius))
        assert set(expected) == set(node.pubs)
        for topic, msg in expected.items():
            assert node.pubs[topic].sent[t] == ROS2.serialize_cdr(msg, msg.__msgtype__), (topic, t)
        estimate = ROS2.deserialize_cdr(node.pubs["/heatpf/estimate"].sent[t], rm.ESTIMATE_TYPE)
        assert rm.stamp_ns(estimate.header) == stamp
        np.testing.assert_array_equal([estimate.pose.pose.position.x, estimate.pose.pose.position.y],
                                      np.asarray(tracker.last_info.mean, np.float64))
    assert all(len(pub.sent) == seq.num_steps for pub in node.pubs.values())
