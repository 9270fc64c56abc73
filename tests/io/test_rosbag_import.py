"""Tests for heatpf_jax.io.rosbag_import: bags written with rosbags itself from a simulated sequence, read back.

The reference is the simulated sequence the bag was made from; tf interpolation is checked against
SciPy's ``Slerp``. Small on purpose: 12 steps of a 50 x 37 heat map.
"""

import argparse
import dataclasses

import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402
from scipy.spatial.transform import Rotation, Slerp  # noqa: E402

from heatpf_jax.cli.import_rosbag import add_parser  # noqa: E402
from heatpf_jax.io.rosbag_import import import_rosbag  # noqa: E402
from heatpf_jax.io.sequence import SequenceError, load_sequence  # noqa: E402
from heatpf_jax.sim import integrate_odometry, simulate  # noqa: E402

ROS2 = get_typestore(Stores.ROS2_HUMBLE)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
ROS1.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
T0_NS = 1_700_000_000_123_456_789  # a realistic epoch stamp, so float rounding would show
DT_NS = 100_000_000  # the simulation's 10 Hz
NUM_STEPS = 12
HEATMAP, INFO, ODOM, TRUTH = "/camera/heatmap", "/camera/camera_info", "/odom", "/ball/ground_truth"
TOPICS = {"heatmap_topic": HEATMAP, "camera_info_topic": INFO, "odom_topic": ODOM}
# base_link -> base_footprint (static, a yaw and an offset so composing the odometry matters) and
# head -> camera_optical (static) in the "chain" layout.
FOOT = np.eye(4)
FOOT[:3, :3] = Rotation.from_euler("z", 0.1).as_matrix()
FOOT[:3, 3] = (0.05, -0.02, -0.3)
HEAD_TO_CAM = np.eye(4)
HEAD_TO_CAM[:3, :3] = Rotation.from_euler("xyz", (-1.4, 0.2, -1.5)).as_matrix()
HEAD_TO_CAM[:3, 3] = (0.06, 0.01, 0.04)


@dataclasses.dataclass(frozen=True)
class Spec:
    """How a test bag is written from the simulated sequence."""

    storage: str = "mcap"  # mcap, sqlite3 or ros1
    encoding: str = "mono8"  # mono8, 32FC1, or anything else to provoke an error
    layout: str = "direct"  # direct: base_footprint -> camera_optical; chain: via base_link and head
    truth: str | None = "point"  # point (in base_footprint), pose (in odom) or None
    info_scale: int = 1  # camera info at this multiple of the heat map's size
    drop: tuple[int, ...] = ()  # steps without a heat map
    decoy: tuple[int, ...] = ()  # steps with an extra, older heat map recorded after the real one
    skip_topics: tuple[str, ...] = ()
    omit_children: tuple[str, ...] = ()  # tf children left out
    tf_every: int = 1  # dynamic camera transform only every n-th step
    image_offset_ns: int = 0  # heat-map stamps shifted from the step stamps
    activation_scale: float = 1.0
    image_frame: str = "camera_optical"


def _msg(store, name, **fields):
    """A message of type ``name``; field names case-insensitive (ROS 1 spells ``K``), ``seq`` added where needed."""
    cls = store.types[name]
    names = {f.name.lower(): f.name for f in dataclasses.fields(cls)}
    if "seq" in names:
        fields.setdefault("seq", 0)
    return cls(**{names[k.lower()]: v for k, v in fields.items() if k.lower() in names})


def _header(store, ns, frame):
    stamp = _msg(store, "builtin_interfaces/msg/Time", sec=ns // 10**9, nanosec=ns % 10**9)
    return _msg(store, "std_msgs/msg/Header", stamp=stamp, frame_id=frame)


def _vector(store, name, xyz):
    return _msg(store, name, x=float(xyz[0]), y=float(xyz[1]), z=float(xyz[2]))


def _quaternion(store, rot):
    x, y, z, w = Rotation.from_matrix(rot).as_quat()
    return _msg(store, "geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w)


def _pose_msg(store, pose):
    return _msg(store, "geometry_msgs/msg/Pose", position=_vector(store, "geometry_msgs/msg/Point", pose[:3, 3]),
                orientation=_quaternion(store, pose[:3, :3]))


def _planar_matrix(xyt):
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("z", xyt[2]).as_matrix()
    out[:2, 3] = xyt[:2]
    return out


def _image(store, ns, frame, act, encoding, *, pad=0):
    h, w = act.shape
    if encoding == "mono8":
        rows = np.round(act * 255).astype(np.uint8)
        data, step, big = np.concatenate([rows, np.full((h, pad), 7, np.uint8)], axis=1), w + pad, 0
    elif encoding == "32FC1":
        data, step, big = act.astype(">f4").view(np.uint8), 4 * w, 1  # big-endian, to exercise is_bigendian
    else:
        data, step, big = np.repeat(np.round(act * 255).astype(np.uint8), 3, axis=1), 3 * w, 0
    return _msg(store, "sensor_msgs/msg/Image", header=_header(store, ns, frame), height=h, width=w,
                encoding=encoding, is_bigendian=big, step=step, data=np.ascontiguousarray(data).reshape(-1))


def _camera_info(store, ns, intrinsics, shape, scale):
    fx, fy, cx, cy = intrinsics
    h, w = shape
    k = np.array([fx * scale, 0, (cx + 0.5) * scale - 0.5, 0, fy * scale, (cy + 0.5) * scale - 0.5, 0, 0, 1])
    p = np.concatenate([k.reshape(3, 3), np.zeros((3, 1))], axis=1).reshape(-1)
    roi = _msg(store, "sensor_msgs/msg/RegionOfInterest", x_offset=0, y_offset=0, height=0, width=0,
               do_rectify=False)
    return _msg(store, "sensor_msgs/msg/CameraInfo", header=_header(store, ns, "camera_optical"), height=h * scale,
                width=w * scale, distortion_model="plumb_bob", d=np.zeros(5), k=k, r=np.eye(3).reshape(-1), p=p,
                binning_x=0, binning_y=0, roi=roi)


def _transform(store, ns, parent, child, pose):
    tf = _msg(store, "geometry_msgs/msg/Transform",
              translation=_vector(store, "geometry_msgs/msg/Vector3", pose[:3, 3]),
              rotation=_quaternion(store, pose[:3, :3]))
    return _msg(store, "geometry_msgs/msg/TransformStamped", header=_header(store, ns, parent), child_frame_id=child,
                transform=tf)


def _odometry(store, ns, child, pose):
    zero = _vector(store, "geometry_msgs/msg/Vector3", (0, 0, 0))
    return _msg(
        store, "nav_msgs/msg/Odometry", header=_header(store, ns, "odom"), child_frame_id=child,
        pose=_msg(store, "geometry_msgs/msg/PoseWithCovariance", pose=_pose_msg(store, pose), covariance=np.zeros(36)),
        twist=_msg(store, "geometry_msgs/msg/TwistWithCovariance",
                   twist=_msg(store, "geometry_msgs/msg/Twist", linear=zero, angular=zero), covariance=np.zeros(36)),
    )


def write_bag(path, seq, spec: Spec):
    """Writes ``seq`` as a bag following ``spec``; returns the bag's path (a directory, or a .bag file)."""
    store = ROS1 if spec.storage == "ros1" else ROS2
    foot_world = [_planar_matrix(p) for p in integrate_odometry(seq.odometry)]
    rng = np.random.default_rng(7)
    records = []  # (bag time, topic, type, message), written in this order

    def add(ns, topic, msgtype, msg):
        records.append((ns, topic, msgtype, msg))

    def add_tf(ns, topic, parent, child, pose):
        if child not in spec.omit_children:
            add(ns, topic, "tf2_msgs/msg/TFMessage",
                _msg(store, "tf2_msgs/msg/TFMessage", transforms=[_transform(store, ns, parent, child, pose)]))

    if spec.layout == "chain":
        add_tf(T0_NS - DT_NS, "/tf_static", "base_link", "base_footprint", FOOT)
        add_tf(T0_NS - DT_NS, "/tf_static", "head", "camera_optical", HEAD_TO_CAM)
    shape = seq.heatmaps.shape[1:]
    for t in range(seq.num_steps):
        ns = T0_NS + t * DT_NS
        add(ns, INFO, "sensor_msgs/msg/CameraInfo", _camera_info(store, ns, seq.intrinsics, shape, spec.info_scale))
        if spec.layout == "direct":
            add_tf(ns, "/tf", "odom", "base_footprint", foot_world[t])
            if t % spec.tf_every == 0:
                add_tf(ns, "/tf", "base_footprint", "camera_optical", seq.cam_to_base[t])
            odom_child, odom_pose = "base_footprint", foot_world[t]
        else:
            link = foot_world[t] @ np.linalg.inv(FOOT)
            add_tf(ns, "/tf", "odom", "base_link", link)
            add_tf(ns, "/tf", "base_link", "head", FOOT @ seq.cam_to_base[t] @ np.linalg.inv(HEAD_TO_CAM))
            odom_child, odom_pose = "base_link", link
        add(ns, ODOM, "nav_msgs/msg/Odometry", _odometry(store, ns, odom_child, odom_pose))
        if spec.truth == "point":
            point = _vector(store, "geometry_msgs/msg/Point", (*seq.ground_truth[t], 0.07))
            add(ns, TRUTH, "geometry_msgs/msg/PointStamped",
                _msg(store, "geometry_msgs/msg/PointStamped", header=_header(store, ns, "base_footprint"), point=point))
        elif spec.truth == "pose":
            world = foot_world[t] @ np.array([*seq.ground_truth[t], 0.07, 1.0])
            pose = np.eye(4)
            pose[:3, 3] = world[:3]
            cov = _msg(store, "geometry_msgs/msg/PoseWithCovariance", pose=_pose_msg(store, pose),
                       covariance=np.zeros(36))
            add(ns, TRUTH, "geometry_msgs/msg/PoseWithCovarianceStamped",
                _msg(store, "geometry_msgs/msg/PoseWithCovarianceStamped", header=_header(store, ns, "odom"), pose=cov))
        if t not in spec.drop:
            image_ns = ns + spec.image_offset_ns
            act = seq.heatmaps[t] * spec.activation_scale
            add(image_ns, HEATMAP, "sensor_msgs/msg/Image",
                _image(store, image_ns, spec.image_frame, act, spec.encoding, pad=3))
            if t in spec.decoy:  # older stamp, later in the bag: the import must go by stamp
                fake = rng.uniform(0, 1, shape).astype(np.float32)
                add(ns + 1, HEATMAP, "sensor_msgs/msg/Image",
                    _image(store, image_ns - 40_000_000, spec.image_frame, fake, spec.encoding))

    records = [r for r in records if r[1] not in spec.skip_topics]
    if spec.storage == "ros1":
        path = path.with_suffix(".bag")
        writer, serialize = Writer1(path), store.serialize_ros1
    else:
        plugin = StoragePlugin.MCAP if spec.storage == "mcap" else StoragePlugin.SQLITE3
        writer, serialize = Writer(path, version=8, storage_plugin=plugin), store.serialize_cdr
    with writer:
        conns = {}
        for ns, topic, msgtype, msg in records:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], ns, serialize(msg, msgtype))
    return path


@pytest.fixture(scope="module")
def sim():
    """12 steps of the walking scenario (moving robot, swaying camera, noisy odometry) on a 50 x 37 heat map."""
    return simulate("walking", 4, num_steps=NUM_STEPS, shrink=4)


@pytest.fixture(scope="module")
def mcap_bag(sim, tmp_path_factory):
    spec = Spec(storage="mcap", encoding="mono8", layout="direct", truth="point", info_scale=3, drop=(2, 5, 6),
                decoy=(4, 9))
    return write_bag(tmp_path_factory.mktemp("mcap") / "bag", sim, spec), spec


def _check_round_trip(out, sim, spec):
    expected_has = np.array([t not in spec.drop for t in range(NUM_STEPS)])
    np.testing.assert_array_equal(out.has_heatmap, expected_has)
    assert out.heatmaps.shape == sim.heatmaps.shape and out.heatmaps.dtype == np.float32
    np.testing.assert_array_equal(out.heatmaps[~expected_has], 0.0)
    if spec.encoding == "mono8":
        quantised = np.round(sim.heatmaps * 255).astype(np.uint8).astype(np.float32) / np.float32(255)
        np.testing.assert_array_equal(out.heatmaps[expected_has], quantised[expected_has])
        assert np.abs(out.heatmaps - sim.heatmaps)[expected_has].max() <= 0.5 / 255 + 1e-7
    else:
        np.testing.assert_array_equal(out.heatmaps[expected_has], sim.heatmaps[expected_has])
    np.testing.assert_allclose(out.intrinsics, sim.intrinsics, rtol=0, atol=1e-9)
    np.testing.assert_allclose(out.cam_to_base, sim.cam_to_base, rtol=0, atol=1e-6)
    np.testing.assert_allclose(out.odometry[1:], sim.odometry[1:], rtol=0, atol=1e-6)
    np.testing.assert_array_equal(out.odometry[0], 0.0)
    # The bag's clock per tick: the first heat map's stamp (step 0's heat map is never dropped here), dt apart.
    np.testing.assert_array_equal(out.stamps, T0_NS + np.arange(NUM_STEPS, dtype=np.int64) * DT_NS)
    assert float(out.dt) == pytest.approx(0.1) and float(out.ball_radius) == 0.07
    if spec.truth is None:
        assert out.ground_truth is None
    else:
        np.testing.assert_allclose(out.ground_truth, sim.ground_truth, rtol=0, atol=1e-6)


def test_mcap_mono8_round_trip(sim, mcap_bag):
    path, spec = mcap_bag
    out = import_rosbag(path, **TOPICS, ground_truth_topic=TRUTH)
    _check_round_trip(out, sim, spec)


@pytest.mark.parametrize("storage", ["sqlite3", "ros1"])
def test_chained_tf_32fc1_round_trip(sim, tmp_path, storage):
    """base_footprint <- base_link -> head -> camera (dynamic + static), odometry of base_link, truth in odom."""
    spec = Spec(storage=storage, encoding="32FC1", layout="chain", truth="pose", drop=(7,), image_frame="")
    path = write_bag(tmp_path / "bag", sim, spec)
    out = import_rosbag(path, **TOPICS, camera_frame="/camera_optical", ground_truth_topic=TRUTH)
    _check_round_trip(out, sim, spec)


def test_tf_interpolation_matches_scipy_slerp(sim, tmp_path):
    """Camera tf every third step, heat maps 37 ms before the steps: slerp / linear between tf stamps, held after."""
    spec = Spec(tf_every=3, image_offset_ns=-37_000_000, truth=None)
    path = write_bag(tmp_path / "bag", sim, spec)
    out = import_rosbag(path, **TOPICS)
    assert out.has_heatmap.all() and out.num_steps == NUM_STEPS
    keys = np.arange(0, NUM_STEPS, 3)
    query = np.clip(np.arange(NUM_STEPS) * 0.1 - 0.037, 0.0, keys[-1] * 0.1)
    slerp = Slerp(keys * 0.1, Rotation.from_matrix(sim.cam_to_base[keys, :3, :3]))
    np.testing.assert_allclose(out.cam_to_base[:, :3, :3], slerp(query).as_matrix(), rtol=0, atol=1e-9)
    trans = np.stack([np.interp(query, keys * 0.1, sim.cam_to_base[keys, i, 3]) for i in range(3)], axis=-1)
    np.testing.assert_allclose(out.cam_to_base[:, :3, 3], trans, rtol=0, atol=1e-12)


def test_lower_rate_keeps_latest_heatmap_per_tick(sim, mcap_bag):
    """At 5 Hz tick k covers steps 2k-1 and 2k; it keeps step 2k, the later one."""
    path, _ = mcap_bag
    out = import_rosbag(path, **TOPICS, rate=5.0, ball_radius=0.1)
    assert out.num_steps == 7 and float(out.dt) == 0.2 and float(out.ball_radius) == 0.1
    # Step 2 is dropped, step 1 is there: tick 1 keeps step 1; steps 5 and 6 dropped: tick 3 is empty.
    kept = [0, 1, 4, None, 8, 10, 11]
    np.testing.assert_array_equal(out.has_heatmap, [k is not None for k in kept])
    for tick, step in enumerate(kept):
        if step is not None:
            assert np.abs(out.heatmaps[tick] - sim.heatmaps[step]).max() <= 0.5 / 255 + 1e-7
            np.testing.assert_allclose(out.cam_to_base[tick], sim.cam_to_base[step], rtol=0, atol=1e-9)
    poses = integrate_odometry(sim.odometry)[np.minimum(2 * np.arange(7), NUM_STEPS - 1)]
    for tick in range(1, 7):
        c, s = np.cos(poses[tick - 1, 2]), np.sin(poses[tick - 1, 2])
        d = poses[tick, :2] - poses[tick - 1, :2]
        expected = (c * d[0] + s * d[1], -s * d[0] + c * d[1], poses[tick, 2] - poses[tick - 1, 2])
        np.testing.assert_allclose(out.odometry[tick], expected, rtol=0, atol=1e-9)


def _one_line_error(match, fn, *args, **kwargs):
    with pytest.raises(ValueError, match=match) as info:
        fn(*args, **kwargs)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_missing_topic_names_it_and_lists_the_bags_topics(sim, tmp_path):
    path = write_bag(tmp_path / "bag", sim, Spec(skip_topics=(ODOM,), truth=None))
    msg = _one_line_error("--odom-topic: topic /odom is not in", import_rosbag, path, **TOPICS)
    assert HEATMAP in msg and INFO in msg and "/tf" in msg


def test_wrong_message_type_is_named(mcap_bag):
    path, _ = mcap_bag
    wrong = {**TOPICS, "camera_info_topic": TRUTH}
    _one_line_error("--camera-info-topic: topic /ball/ground_truth carries geometry_msgs/msg/PointStamped, "
                    "expected sensor_msgs/msg/CameraInfo", import_rosbag, path, **wrong)
    twice = {**TOPICS, "camera_info_topic": HEATMAP}
    _one_line_error("--heatmap-topic and --camera-info-topic: both name topic /camera/heatmap", import_rosbag, path,
                    **twice)


def test_no_tf_path_names_both_frames(sim, tmp_path):
    path = write_bag(tmp_path / "bag", sim, Spec(layout="chain", omit_children=("head",)))
    with pytest.raises(SequenceError, match="no tf path between frames 'base_footprint' and 'camera_optical'"):
        import_rosbag(path, **TOPICS)


def test_unsupported_encoding_is_named(sim, tmp_path):
    path = write_bag(tmp_path / "bag", sim, Spec(encoding="rgb8"))
    _one_line_error("encoding 'rgb8'.*supported: mono8", import_rosbag, path, **TOPICS)


def test_32fc1_outside_unit_range_is_refused(sim, tmp_path):
    path = write_bag(tmp_path / "bag", sim, Spec(encoding="32FC1", activation_scale=3.0))
    _one_line_error(r"must lie in \[0, 1\]", import_rosbag, path, **TOPICS)


def test_empty_image_frame_asks_for_camera_frame(sim, tmp_path):
    path = write_bag(tmp_path / "bag", sim, Spec(image_frame=""))
    _one_line_error("empty header.frame_id; pass --camera-frame", import_rosbag, path, **TOPICS)


def test_bad_arguments(mcap_bag, tmp_path):
    path, _ = mcap_bag
    _one_line_error("--rate: must be positive", import_rosbag, path, **TOPICS, rate=0.0)
    _one_line_error("no such bag", import_rosbag, tmp_path / "nothing", **TOPICS)


def test_cli_writes_a_sequence_and_refuses_to_overwrite(sim, mcap_bag, tmp_path, capsys):
    path, spec = mcap_bag
    parser = argparse.ArgumentParser(prog="heatpf")
    add_parser(parser.add_subparsers(dest="command", required=True))
    out = tmp_path / "seq.npz"
    argv = ["import-rosbag", str(path), "--heatmap-topic", HEATMAP, "--camera-info-topic", INFO, "--odom-topic", ODOM,
            "--ground-truth-topic", TRUTH, "--output", str(out)]
    args = parser.parse_args(argv)
    assert args.func(args) == 0
    assert "12 steps at 10 Hz, 9 with a 50 x 37 heat map, with ground truth" in capsys.readouterr().out
    _check_round_trip(load_sequence(out), sim, spec)
    with pytest.raises(ValueError, match="exists; pass --force"):
        args.func(parser.parse_args(argv))
    args = parser.parse_args([*argv, "--force", "--rate", "5"])
    assert args.func(args) == 0 and load_sequence(out).num_steps == 7
