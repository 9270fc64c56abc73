"""A ROS 2 node around :class:`heatpf_jax.Tracker`: heat maps in, the ball's estimate and particles out.

Run it beside the detector (ROS 2 Humble or later, ``pip install "heatpf-jax[ros]"`` in the same Python)::

    python examples/ros2_node.py --ros-args -p heatmap_topic:=/ball/heatmap \\
        -p camera_info_topic:=/camera/camera_info -p odom_topic:=/odom -p rate:=10.0

**In**: the heat maps (``sensor_msgs/msg/Image``, mono8 or 32FC1, activations in [0, 1]), the camera's
``sensor_msgs/msg/CameraInfo``, the robot's ``nav_msgs/msg/Odometry`` and ``/tf`` + ``/tf_static``
(``tf2_msgs/msg/TFMessage``) for the camera's optical frame in ``base_frame``. **Out**, every ``1 / rate``
seconds (a tick without a new heat map ages the buffer), the messages of
:func:`heatpf_jax.io.ros_messages.step_messages` under ``/heatpf``: ``estimate``
(``geometry_msgs/msg/PoseWithCovarianceStamped``), ``particles`` and ``measurements``
(``sensor_msgs/msg/PointCloud2``), and ``modes`` / ``tracks`` (``visualization_msgs/msg/MarkerArray``) for a
filter that has them, in ``base_frame``, stamped with the node's clock.

The messages are converted by :mod:`heatpf_jax.io.ros_messages`, the same functions as ``heatpf import-rosbag``
and ``heatpf run --bag``: the node subscribes and publishes *serialised* messages (``raw=True``, CDR
bytes) and converts them with rosbags' type store, so it needs no message package beyond ROS's own.

Parameters: ``heatmap_topic``, ``camera_info_topic``, ``odom_topic``, ``base_frame`` (``base_footprint``),
``camera_frame`` (default: the heat maps' ``header.frame_id``; the *optical* frame), ``rate`` (Hz, 10),
``ball_radius`` (m, 0.07), ``method`` (``heatmap``), ``set`` (``heatpf run``'s ``--set`` items separated by
spaces, e.g. ``"num_particles=300 k=5"``), ``seed`` (0).

The :class:`~heatpf_jax.Tracker` is built, and its step compiled, at the first tick that has a heat map,
the camera info and the camera's tf (a few seconds; a second start loads it from the compilation cache).
``rclpy`` is imported in :func:`main` only, so the wiring can be tested without ROS
(``tests/test_examples_ros2_node.py``).
"""

from __future__ import annotations

import sys

import numpy as np

from heatpf_jax.io import ros_messages as rm

IMAGE, CAMERA_INFO, ODOMETRY = "sensor_msgs/msg/Image", "sensor_msgs/msg/CameraInfo", "nav_msgs/msg/Odometry"
TF = rm.TF_TYPE
NAMESPACE = "/heatpf"


class HeatpfNode:
    """The node's logic on an rclpy ``Node`` (given, so that a stand-in can be used in a test).

    Args:
        node: an ``rclpy.node.Node``.
        get_message: ``rosidl_runtime_py.utilities.get_message`` (message type by name, for the endpoints).
        qos: ``rclpy.qos``, for the latched ``/tf_static`` subscription.
    """

    def __init__(self, node, get_message, qos) -> None:
        import jax

        from heatpf_jax.cli.settings import method_with_settings, parse_settings

        self.node = node
        param = {name: node.declare_parameter(name, default).value for name, default in (
            ("heatmap_topic", "/heatmap"), ("camera_info_topic", "/camera_info"), ("odom_topic", "/odom"),
            ("base_frame", "base_footprint"), ("camera_frame", ""), ("rate", 10.0), ("ball_radius", 0.07),
            ("method", "heatmap"), ("set", ""), ("seed", 0))}
        self.base_frame = rm.frame_name(param["base_frame"])
        self.camera_frame = rm.frame_name(param["camera_frame"]) or None
        self.dt = 1.0 / float(param["rate"])
        self.ball_radius = float(param["ball_radius"])
        options, settings = parse_settings(str(param["set"]).split(), (param["method"],))
        self.model, self.params = method_with_settings(param["method"], options, settings)
        self.key = jax.random.key(int(param["seed"]))
        self.store = rm.typestore()

        self.tracker = None
        self.intrinsics_msg = None
        self.pending = None  # the latest heat map since the last tick
        self.image_frame = None
        self.odom_pose = None  # the latest odometry pose [4, 4]
        self.last_odom_pose = None  # the odometry pose at the last tick
        self.tf: dict[str, tuple[str, np.ndarray]] = {}  # child -> (parent, parent <- child)

        def sub(msgtype, topic, callback, depth=10):
            node.create_subscription(get_message(msgtype), topic, self._raw(msgtype, callback), depth, raw=True)

        sub(IMAGE, param["heatmap_topic"], self.on_image)
        sub(CAMERA_INFO, param["camera_info_topic"], self.on_camera_info)
        sub(ODOMETRY, param["odom_topic"], self.on_odometry)
        sub(TF, "/tf", self.on_tf, 100)
        latched = qos.QoSProfile(depth=100, durability=qos.DurabilityPolicy.TRANSIENT_LOCAL)
        sub(TF, "/tf_static", self.on_tf, latched)
        topics = {"estimate": rm.ESTIMATE_TYPE, "particles": rm.POINTS_TYPE, "measurements": rm.POINTS_TYPE}
        if getattr(getattr(self.model, "modes", None), "num_modes", 0):
            topics["modes"] = rm.MARKERS_TYPE
        if getattr(getattr(self.model, "memory", None), "capacity", 0):
            topics["tracks"] = rm.MARKERS_TYPE
        self.publishers = {f"{NAMESPACE}/{name}": node.create_publisher(get_message(msgtype), f"{NAMESPACE}/{name}", 10)
                           for name, msgtype in topics.items()}
        node.create_timer(self.dt, self.tick)

    def _raw(self, msgtype: str, callback):
        def on_bytes(data: bytes) -> None:
            callback(self.store.deserialize_cdr(bytes(data), msgtype))

        return on_bytes

    # --- Callbacks ----------------------------------------------------------------------------------------------

    def on_image(self, msg) -> None:
        self.pending = msg
        self.image_frame = rm.frame_name(msg.header.frame_id)

    def on_camera_info(self, msg) -> None:
        self.intrinsics_msg = msg

    def on_odometry(self, msg) -> None:
        self.odom_pose = rm.pose_to_matrix(msg.pose.pose)

    def on_tf(self, msg) -> None:
        for tr in msg.transforms:
            self.tf[rm.frame_name(tr.child_frame_id)] = (rm.frame_name(tr.header.frame_id),
                                                         rm.transform_to_matrix(tr.transform))

    def cam_to_base(self) -> np.ndarray | None:
        """The camera optical frame -> base frame from the latest transforms (``None`` until they join)."""
        frame, pose = self.camera_frame or self.image_frame, np.eye(4)
        for _ in range(len(self.tf) + 1):
            if frame == self.base_frame:
                return pose
            if frame not in self.tf:
                return None
            parent, edge = self.tf[frame]
            frame, pose = parent, edge @ pose
        return None

    # --- The filter clock ---------------------------------------------------------------------------------------

    def tick(self) -> None:
        """One filter step: the latest heat map (or none), the camera's pose, the odometry since the last tick."""
        from heatpf_jax import Tracker

        cam_to_base = self.cam_to_base() if self.image_frame is not None else None
        if cam_to_base is None or self.intrinsics_msg is None or (self.tracker is None and self.pending is None):
            return
        image, self.pending = self.pending, None
        if self.tracker is None:
            shape = (int(image.height), int(image.width))
            self.tracker = Tracker(self.key, self.model, self.params, heatmap_shape=shape,
                                   intrinsics=rm.intrinsics_from_camera_info(self.intrinsics_msg, shape),
                                   plane_height=self.ball_radius, dt=self.dt)
        odometry = np.zeros(3)
        if self.odom_pose is not None:
            if self.last_odom_pose is not None:
                odometry = rm.odometry_deltas(rm.planar_poses(np.stack([self.last_odom_pose, self.odom_pose])))[1]
            self.last_odom_pose = self.odom_pose
        heatmap = None if image is None else rm.heatmap_from_image(image, "heat map")
        self.tracker.update(heatmap, cam_to_base, odometry)
        stamp = self.node.get_clock().now().nanoseconds
        messages = rm.step_messages(self.tracker.last_info, self.tracker.state, stamp, frame_id=self.base_frame,
                                    z=self.ball_radius, namespace=NAMESPACE)
        for topic, msg in messages.items():
            if topic in self.publishers:
                self.publishers[topic].publish(self.store.serialize_cdr(msg, msg.__msgtype__))


def main(argv: list[str] | None = None) -> int:
    """Starts rclpy, spins the node until Ctrl-C, shuts down."""
    import rclpy
    import rclpy.qos
    from rclpy.node import Node
    from rosidl_runtime_py.utilities import get_message

    rclpy.init(args=argv)
    node = Node("heatpf")
    try:
        HeatpfNode(node, get_message, rclpy.qos)
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
