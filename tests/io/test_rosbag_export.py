"""Tests for ``heatpf run --bag`` (heatpf_jax.io.rosbag_export): the bag read back with rosbags' own Reader and
every message checked against the run, the particle clouds against a Tracker stepped over the same sequence,
and the file-safety rules (checked before any work, never half-written, replaced only with --force)."""

import sys

import jax
import numpy as np
import pytest

pytest.importorskip("rosbags")

from rosbags.rosbag2 import Reader  # noqa: E402

import heatpf_jax as hp  # noqa: E402
from heatpf_jax.cli.parser import main  # noqa: E402
from heatpf_jax.cli.settings import method_with_settings, parse_settings  # noqa: E402
from heatpf_jax.estimate.modes import Modes  # noqa: E402
from heatpf_jax.io import ros_messages as rm  # noqa: E402
from heatpf_jax.io import rosbag_export  # noqa: E402
from heatpf_jax.io.rosbag_export import RunTrace, Snapshot, write_run_bag  # noqa: E402
from heatpf_jax.measurements import Measurements  # noqa: E402
from heatpf_jax.memory import TrackTable  # noqa: E402
from tests.cli.helpers import SMALL_ARGS, SMALL_SET  # noqa: E402
from tests.io.test_ros_messages import _decode_cloud  # noqa: E402

ROS2 = rm.typestore()


def read_bag(path):
    """``{topic: (type, [(bag time, message), ...])}`` and the storage id, with rosbags' rosbag2 Reader."""
    out = {}
    with Reader(path) as reader:
        storage = [f.suffix for f in path.iterdir() if f.name != "metadata.yaml"]
        for conn in reader.connections:
            out[conn.topic] = (conn.msgtype, [])
        for conn, stamp, raw in reader.messages():
            out[conn.topic][1].append((stamp, ROS2.deserialize_cdr(raw, conn.msgtype)))
    return out, storage


@pytest.fixture(scope="module")
def bag_run(small_sequence, tmp_path_factory):
    """``heatpf run SEQ -o est.csv --bag bag`` on the small sequence with the CLI tests' small filter."""
    tmp = tmp_path_factory.mktemp("bag")
    seq_path, csv, bag = tmp / "seq.npz", tmp / "est.csv", tmp / "bag"
    hp.save_sequence(seq_path, small_sequence)
    assert main(["run", str(seq_path), "-o", str(csv), "--seed", "1", "--bag", str(bag), *SMALL_ARGS]) == 0
    return tmp, csv, bag


def test_run_bag_matches_the_run(small_sequence, bag_run, capsys):
    tmp, csv, bag = bag_run
    seq = small_sequence
    num_steps = seq.num_steps
    topics, storage = read_bag(bag)
    assert storage == [".mcap"] and "storage_identifier: mcap" in (bag / "metadata.yaml").read_text()
    assert sorted(p.name for p in tmp.iterdir()) == ["bag", "est.csv", "seq.npz"]  # no temporary directory left
    assert {t: (ty, len(msgs)) for t, (ty, msgs) in topics.items()} == {
        "/tf_static": ("tf2_msgs/msg/TFMessage", 1),
        "/heatpf/estimate": ("geometry_msgs/msg/PoseWithCovarianceStamped", num_steps),
        "/heatpf/particles": ("sensor_msgs/msg/PointCloud2", num_steps),
        "/heatpf/measurements": ("sensor_msgs/msg/PointCloud2", num_steps),
    }
    stamps = np.round(np.arange(num_steps) * float(seq.dt) * 1e9).astype(np.int64)  # no clock in the file: from 0
    for _, msgs in topics.values():
        for stamp, msg in msgs:
            assert msg.header.frame_id == "base_footprint" if hasattr(msg, "header") else True
    for topic in ("/heatpf/estimate", "/heatpf/particles", "/heatpf/measurements"):
        np.testing.assert_array_equal([s for s, _ in topics[topic][1]], stamps)
        np.testing.assert_array_equal([rm.stamp_ns(m.header) for _, m in topics[topic][1]], stamps)

    # The camera: one latched transform base_footprint -> heatpf_camera_optical, the sequence's cam_to_base.
    (tr,) = topics["/tf_static"][1][0][1].transforms
    assert (tr.header.frame_id, tr.child_frame_id) == ("base_footprint", "heatpf_camera_optical")
    np.testing.assert_allclose(rm.transform_to_matrix(tr.transform), seq.cam_to_base[0], atol=1e-9)

    # The estimate against the CSV and against hp.run with the same method, settings and seed.
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    options, settings = parse_settings(SMALL_SET, ("heatmap",))
    model, params = method_with_settings("heatmap", options, settings)
    info = hp.run(jax.random.key(1), seq, params, model).info
    pose = np.array([[m.pose.pose.position.x, m.pose.pose.position.y] for _, m in topics["/heatpf/estimate"][1]])
    cov = np.array([np.asarray(m.pose.covariance).reshape(6, 6) for _, m in topics["/heatpf/estimate"][1]])
    np.testing.assert_array_equal(pose, np.asarray(info.mean, np.float64))
    np.testing.assert_array_equal(cov[:, :2, :2], np.asarray(info.cov, np.float64))
    np.testing.assert_allclose(pose, table[:, 1:3], rtol=0, atol=5.1e-7)
    np.testing.assert_allclose(cov[:, [0, 0, 1], [0, 1, 1]], table[:, 3:6], rtol=0, atol=5.1e-7)  # 6 decimals
    assert not np.delete(cov.reshape(num_steps, 36), [0, 1, 6, 7], axis=1).any()
    assert {m.pose.pose.position.z for _, m in topics["/heatpf/estimate"][1]} == {float(seq.ball_radius)}

    # Particles and buffered measurements against a Tracker stepped over the same sequence (run's keys).
    tracker = hp.Tracker(jax.random.key(1), model, params, heatmap_shape=seq.heatmaps.shape[1:],
                         intrinsics=seq.intrinsics, plane_height=float(seq.ball_radius), dt=float(seq.dt),
                         num_steps=num_steps)
    for t in range(num_steps):
        tracker.update(seq.heatmaps[t] if seq.has_heatmap[t] else None, seq.cam_to_base[t], seq.odometry[t])
        state = tracker.state
        particles = _decode_cloud(topics["/heatpf/particles"][1][t][1])
        np.testing.assert_allclose(np.stack([particles["x"], particles["y"]], -1), state.particles.xy, atol=1e-5)
        np.testing.assert_allclose(particles["weight"], np.exp(np.asarray(state.log_weights)), rtol=1e-5)
        np.testing.assert_array_equal(particles["z"], np.float32(seq.ball_radius))
        assert particles["weight"].sum() == pytest.approx(1.0, rel=1e-4)
        measured = _decode_cloud(topics["/heatpf/measurements"][1][t][1])
        valid = np.asarray(state.buffer.valid)
        assert measured["x"].size == valid.sum() == int(info.num_valid[t])
        np.testing.assert_allclose(np.stack([measured["x"], measured["y"]], -1), np.asarray(state.buffer.xy)[valid],
                                   atol=1e-5)
        np.testing.assert_allclose(measured["weight"], np.asarray(state.buffer.weight)[valid], atol=1e-6)


def test_run_bag_refuses_before_any_work(small_sequence, tmp_path, capsys, monkeypatch):
    seq_path, csv, bag = tmp_path / "seq.npz", tmp_path / "est.csv", tmp_path / "bag"
    hp.save_sequence(seq_path, small_sequence)

    def error(argv) -> str:
        assert main(["run", str(seq_path), "-o", str(csv), *argv, *SMALL_ARGS]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and not csv.exists()
        return lines[0]

    bag.mkdir()
    (bag / "metadata.yaml").write_text("precious\n")
    assert error(["--bag", str(bag)]) == (f"heatpf: error: --bag: {bag} exists; pass --force to replace it, or "
                                          "choose another --bag")
    assert (bag / "metadata.yaml").read_text() == "precious\n"
    other = tmp_path / "notabag"
    other.mkdir()
    assert "is a directory but not a rosbag2 bag (no metadata.yaml)" in error(["--bag", str(other), "--force"])
    assert "would hold or replace" in error(["--bag", str(tmp_path), "--force"])  # the input lies inside
    assert "--bag: " in error(["--bag", str(tmp_path / "missing" / "bag")])
    assert error(["--bag-frame", "odom"]) == "heatpf: error: --bag-frame: only with --bag"
    monkeypatch.setitem(sys.modules, "rosbags.rosbag2", None)  # rosbags not installed
    missing = 'heatpf: error: --bag needs rosbags: pip install "heatpf-jax[ros]"'
    assert error(["--bag", str(tmp_path / "new")]) == missing
    assert not (tmp_path / "new").exists()


def _trace(rng, num_steps=4, n=6, k=2, m=3):
    """A hand-made RunTrace with modes, tracks, particles and a buffer (NumPy, leading axis T)."""
    info = hp.StepInfo(
        mean=rng.normal(size=(num_steps, 2)).astype(np.float32),
        cov=np.tile(np.diag([0.04, 0.01]).astype(np.float32), (num_steps, 1, 1)),
        weighted_mean=np.zeros((num_steps, 2), np.float32), ess=np.ones(num_steps, np.float32),
        num_valid=np.full(num_steps, 2, np.int32), resampled=np.zeros(num_steps, bool),
        log_likelihood=np.zeros(num_steps, np.float32), ancestors=np.zeros((num_steps, n), np.int32),
        modes=Modes(weight=np.full((num_steps, k), 0.5), mean=rng.normal(size=(num_steps, k, 2)),
                    cov=np.tile(np.eye(2) * 0.01, (num_steps, k, 1, 1)), valid=np.tile([True, False], (num_steps, 1))),
        tracks=TrackTable(id=np.tile(np.arange(m), (num_steps, 1)), valid=np.tile([True, True, False], (num_steps, 1)),
                          mean=rng.normal(size=(num_steps, m, 4)), cov=np.zeros((num_steps, m, 4, 4)),
                          age=np.zeros((num_steps, m)), hits=np.zeros((num_steps, m), int),
                          found=np.zeros((num_steps, m), bool), next_id=np.full(num_steps, m)),
    )
    snaps = Snapshot(particles=rng.normal(size=(num_steps, n, 2)).astype(np.float32),
                     log_weights=np.full((num_steps, n), -np.log(n), np.float32),
                     measurements=Measurements(xy=rng.normal(size=(num_steps, 4, 2)).astype(np.float32),
                                               weight=np.ones((num_steps, 4), np.float32),
                                               valid=np.tile([True, False, True, False], (num_steps, 1))))
    return RunTrace(info=info, snapshots=snaps)


def test_write_run_bag_modes_tracks_moving_camera_and_replace(small_sequence, tmp_path, rng):
    seq = small_sequence.head(4)
    cam = seq.cam_to_base.copy()
    cam[:, 0, 3] += np.arange(4) * 0.01  # a camera that moves: /tf per step instead of /tf_static
    seq = seq._replace(cam_to_base=cam)
    trace = _trace(rng)
    bag = tmp_path / "bag"
    start = 1_700_000_000_000_000_123
    summary = write_run_bag(bag, seq, trace, frame_id="base_link", start_ns=start)
    topics, _ = read_bag(bag)
    assert summary.topics == {t: (ty, len(msgs)) for t, (ty, msgs) in topics.items()}
    assert {t: len(msgs) for t, (_, msgs) in topics.items()} == {
        "/tf": 4, "/heatpf/estimate": 4, "/heatpf/particles": 4, "/heatpf/measurements": 4, "/heatpf/modes": 4,
        "/heatpf/tracks": 4}
    np.testing.assert_array_equal([s for s, _ in topics["/heatpf/modes"][1]], start + np.arange(4) * 100_000_000)
    for t, (_, msg) in enumerate(topics["/tf"][1]):
        np.testing.assert_allclose(rm.transform_to_matrix(msg.transforms[0].transform), cam[t], atol=1e-9)
        assert msg.transforms[0].header.frame_id == "base_link"
    for t, (_, msg) in enumerate(topics["/heatpf/modes"][1]):
        (mark,) = msg.markers[1:]
        assert (mark.pose.position.x, mark.pose.position.y) == tuple(trace.info.modes.mean[t, 0])
        assert mark.header.frame_id == "base_link"
    for t, (_, msg) in enumerate(topics["/heatpf/tracks"][1]):
        spheres = [m for m in msg.markers if m.ns == "tracks"]
        assert [m.id for m in spheres] == [0, 1]
        np.testing.assert_array_equal([[m.pose.position.x, m.pose.position.y] for m in spheres],
                                      trace.info.tracks.mean[t, :2, :2])
    for t, (_, msg) in enumerate(topics["/heatpf/measurements"][1]):
        cloud = _decode_cloud(msg)
        np.testing.assert_array_equal(np.stack([cloud["x"], cloud["y"]], -1),
                                      trace.snapshots.measurements.xy[t, [0, 2]])

    # A failure half-way leaves the old bag as it was and no temporary directory.
    before = {p.name: p.read_bytes() for p in bag.iterdir()}
    calls = []

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return rm.step_messages(*args, **kwargs)

    original = rm.step_messages
    rm.step_messages = failing
    try:
        with pytest.raises(KeyboardInterrupt):
            write_run_bag(bag, seq, trace)
    finally:
        rm.step_messages = original
    assert {p.name: p.read_bytes() for p in bag.iterdir()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]

    # Replaced (the check allows it with --force): the new bag, nothing else left.
    rosbag_export.check_bag_output(bag, replace=True)
    write_run_bag(bag, seq._replace(cam_to_base=small_sequence.cam_to_base[:4]), trace)
    topics, _ = read_bag(bag)
    assert "/tf" not in topics and len(topics["/tf_static"][1]) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bag"]

    # A sequence with its own clock (an imported bag's): every message carries its step's stamp, irregular or not;
    # an explicit start overrides it.
    clock = 1_700_000_000_000_000_000 + np.array([0, 100_000_000, 250_000_000, 300_000_000], np.int64)
    timed = seq._replace(cam_to_base=small_sequence.cam_to_base[:4], stamps=clock)
    write_run_bag(bag, timed, trace)
    topics, _ = read_bag(bag)
    np.testing.assert_array_equal([t for t, _ in topics["/heatpf/estimate"][1]], clock)
    np.testing.assert_array_equal([rm.stamp_ns(m.header) for _, m in topics["/heatpf/estimate"][1]], clock)
    write_run_bag(bag, timed, trace, start_ns=5)
    topics, _ = read_bag(bag)
    np.testing.assert_array_equal([t for t, _ in topics["/heatpf/estimate"][1]],
                                  5 + np.round(np.arange(4) * float(seq.dt) * 1e9).astype(np.int64))


def test_run_bag_reads_with_the_mcap_reference_decoder(bag_run):
    """What Foxglove needs: the .mcap file alone, read by the MCAP project's own reader and ROS 2 decoder (not
    rosbags, which wrote it): every channel a ``ros2msg`` schema and ``cdr`` messages that decode, in time order,
    with the estimate's values as rosbags reads them."""
    mcap_reader = pytest.importorskip("mcap.reader")
    mcap_ros2 = pytest.importorskip("mcap_ros2.decoder")
    _, _, bag = bag_run
    (path,) = bag.glob("*.mcap")
    with path.open("rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_ros2.DecoderFactory()])
        summary = reader.get_summary()
        assert {s.encoding for s in summary.schemas.values()} == {"ros2msg"}
        assert {c.message_encoding for c in summary.channels.values()} == {"cdr"}
        decoded = {}
        times = []
        for schema, channel, message, ros_msg in reader.iter_decoded_messages(log_time_order=True):
            decoded.setdefault(channel.topic, []).append(ros_msg)
            times.append(message.log_time)
    assert times == sorted(times)
    topics, _ = read_bag(bag)
    assert {t: len(m) for t, m in decoded.items()} == {t: len(m) for t, (_, m) in topics.items()}
    ours = [(m.pose.pose.position.x, m.pose.pose.position.y) for _, m in topics["/heatpf/estimate"][1]]
    theirs = [(m.pose.pose.position.x, m.pose.pose.position.y) for m in decoded["/heatpf/estimate"]]
    assert theirs == ours
    cloud = decoded["/heatpf/particles"][0]
    assert [f.name for f in cloud.fields] == ["x", "y", "z", "weight"] and cloud.width * cloud.point_step == len(
        cloud.data)
