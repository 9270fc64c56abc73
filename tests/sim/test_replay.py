"""Real-track replays: the parsers, resampling, the fetch and cache, and the replay worlds.

No network: the parsers read tiny synthetic files in the providers' formats (``tests/data/tiny_tracks``,
values checked by hand below), the fetch runs against a fake ``pip`` that copies a tarball built here, and
the worlds replay tracks made up in the tests. Tests of the real download run only where it is cached.
"""

from __future__ import annotations

import hashlib
import io
import json
import shutil
import subprocess
import sys
import tarfile
from pathlib import Path

import numpy as np
import pytest

from heatpf_jax.camera import camera_pose, project_points
from heatpf_jax.io.sequence import validate_sequence
from heatpf_jax.sim import integrate_odometry
from heatpf_jax.sim import tracks as tracks_module
from heatpf_jax.sim.render import BALL_RADIUS, blob
from heatpf_jax.sim.replay import HEAD_YAW_LIMIT, IN_AIR_HEIGHT, blob_render, replay_segments, replay_world
from heatpf_jax.sim.tracks import (
    KLOPPY_FILES,
    KLOPPY_VERSION,
    BallTrack,
    fetch_kloppy_files,
    load_pff,
    load_skillcorner,
    resample_track,
    segments,
    tracks_directory,
)

TINY = Path(__file__).parent.parent / "data" / "tiny_tracks"
SHRINK = 4  # 50 x 37 heat maps


def make_track(xyz, rate: float = 10.0, visible=None, t0: float = 100.0) -> BallTrack:
    xyz = np.asarray(xyz, np.float64)
    n = xyz.shape[0]
    vis = np.ones(n, bool) if visible is None else np.asarray(visible, bool)
    return BallTrack(t=t0 + np.arange(n) / rate, xyz=np.where(vis[:, None], xyz, 0.0), visible=vis,
                     source="test", rate=rate, height_known=vis.copy())


# --- Parsers ------------------------------------------------------------------------------------------------------


def test_skillcorner_v2_by_hand():
    track = load_skillcorner(TINY / "skillcorner_structured_data.json")
    assert track.source == "skillcorner:9001" and track.rate == 10.0
    np.testing.assert_allclose(track.t, np.arange(15) / 10.0)
    # Frames 0-1 and 10-11 have period null (frame 10's ball is ignored), 6-7 have no ball record.
    assert np.flatnonzero(track.visible).tolist() == [2, 3, 4, 5, 8, 9, 12, 13, 14]
    assert np.flatnonzero(track.height_known).tolist() == [2, 4, 5, 8, 9, 12, 14]
    np.testing.assert_allclose(track.xyz[2], [10.0, -4.0, 0.5])
    np.testing.assert_allclose(track.xyz[3], [11.0, -3.5, 0.0])  # no z: 0
    np.testing.assert_allclose(track.xyz[8], [15.0, -1.5, 0.0])  # group_name "balls", no trackable_object
    np.testing.assert_allclose(track.xyz[9], [16.0, -1.0, -0.05])  # the provider's z as given
    np.testing.assert_allclose(track.xyz[13], [-5.5, 2.5, 0.0])
    np.testing.assert_allclose(track.xyz[~track.visible], 0.0)


def test_skillcorner_v2_without_match_file_and_with_ball_id(tmp_path):
    shutil.copy(TINY / "skillcorner_structured_data.json", tmp_path / "tracking.json")
    guessed = load_skillcorner(tmp_path / "tracking.json")  # the ball is the object with a z
    full = load_skillcorner(TINY / "skillcorner_structured_data.json")
    assert guessed.source == "skillcorner"
    np.testing.assert_array_equal(guessed.visible, full.visible)
    np.testing.assert_allclose(guessed.xyz, full.xyz)
    player = load_skillcorner(tmp_path / "tracking.json", ball_id=7)
    # Object 7 on frames 2, 3, 6, 7; frame 8's "balls" record still counts.
    assert np.flatnonzero(player.visible).tolist() == [2, 3, 6, 7, 8]
    np.testing.assert_allclose(player.xyz[3], [3.2, 2.3, 0.0])


def test_skillcorner_v3_by_hand():
    track = load_skillcorner(TINY / "skillcorner_v3_raw_data.jsonl")
    assert track.source == "skillcorner:9002"
    np.testing.assert_allclose(track.t, [0.0, 0.1, 0.2, 0.3, 0.4])
    assert track.visible.tolist() == [False, True, False, True, True]
    assert track.height_known.tolist() == [False, True, False, False, True]
    np.testing.assert_allclose(track.xyz[[1, 3, 4]], [[1.0, 2.0, 0.3], [1.5, 2.5, 0.0], [2.0, 3.0, 0.0]])


def test_pff_by_hand(tmp_path):
    track = load_pff(TINY / "pff_10517.jsonl")
    assert track.source == "pff:10517" and track.rate == pytest.approx(29.97)
    np.testing.assert_allclose(track.t, [10.0, 10.0334, 10.0667, 10.1001, 170.0, 170.0334])
    assert track.visible.tolist() == [True, True, False, True, True, True]
    assert track.height_known.tolist() == [True, True, False, False, True, True]
    np.testing.assert_allclose(track.xyz[1], [1.5, 2.0, 0.5])
    np.testing.assert_allclose(track.xyz[4], [-3.0, -1.0, 1.2])
    other = load_pff(TINY / "pff_3812.jsonl")
    assert other.source == "pff:3812" and other.rate == 25.0
    # Without videoTimeMs the time is frameNum / fps.
    lines = [json.loads(line) for line in (TINY / "pff_3812.jsonl").read_text().splitlines()]
    for line in lines:
        del line["videoTimeMs"]
    (tmp_path / "pff_3812.jsonl").write_text("\n".join(json.dumps(line) for line in lines))
    shutil.copy(TINY / "pff_metadata_3812.json", tmp_path)
    np.testing.assert_allclose(load_pff(tmp_path / "pff_3812.jsonl").t, np.array([150, 151, 152]) / 25.0)


def test_parsers_fail_in_one_line(tmp_path):
    (tmp_path / "text.json").write_text("hello")
    (tmp_path / "object.json").write_text('{"a": 1}\n')
    cases = [(load_skillcorner, tmp_path / "missing.json"), (load_skillcorner, tmp_path / "text.json"),
             (load_skillcorner, tmp_path / "object.json"), (load_pff, tmp_path / "text.json"),
             (load_pff, tmp_path / "object.json"), (load_pff, TINY / "skillcorner_structured_data.json")]
    for load, path in cases:
        with pytest.raises(ValueError, match=path.name) as err:
            load(path)
        assert "\n" not in str(err.value)


# --- Pieces and resampling ----------------------------------------------------------------------------------------


def test_segments_split_at_gaps():
    track = load_skillcorner(TINY / "skillcorner_structured_data.json")
    (whole,) = segments(track, 0.5)
    np.testing.assert_allclose(whole.t[[0, -1]], [0.2, 1.4])
    pieces = list(segments(track, 0.25))
    np.testing.assert_allclose([(p.t[0], p.t[-1]) for p in pieces], [(0.2, 0.5), (0.8, 0.9), (1.2, 1.4)])
    assert all(p.visible[0] and p.visible[-1] for p in pieces)
    assert len(list(segments(track, 0.25, min_length_s=0.15))) == 2  # the 0.1 s piece is left out
    # Speeds between known frames: 11.2 m/s (frames 2-5, 8-9), 7.5 (5 -> 8), 70.7 (9 -> 12), 7.1 (12-14).
    fast = list(segments(track, 0.5, max_speed=20.0))
    np.testing.assert_allclose([(p.t[0], p.t[-1]) for p in fast], [(0.2, 0.9), (1.2, 1.4)])
    slow = list(segments(track, 0.5, max_speed=11.0))
    assert [p.t[0] for p in slow] == pytest.approx([0.2, 0.3, 0.4, 0.5, 0.9, 1.2])


def _resample_brute(t, xyz, visible, has_z, dt, max_gap):
    """Per output time: the known frames before and after it, a linear blend, and the gap between them."""
    tk = [t[i] for i in range(len(t)) if visible[i]]
    idx = [i for i in range(len(t)) if visible[i]]
    out_t, out_xyz, out_vis, out_z = [], [], [], []
    k = 0
    while tk[0] + k * dt <= tk[-1] + 1e-9:
        s = tk[0] + k * dt
        before = max(j for j in range(len(tk)) if tk[j] <= s + 1e-9)
        after = min(j for j in range(len(tk)) if tk[j] >= s - 1e-9)
        a, b = idx[before], idx[after]
        w = 0.0 if after == before else (s - tk[before]) / (tk[after] - tk[before])
        out_t.append(s)
        out_xyz.append((1 - w) * xyz[a] + w * xyz[b])
        out_vis.append(tk[after] - tk[before] <= max_gap + 1e-9)
        out_z.append(has_z[a] and has_z[b])
        k += 1
    return np.array(out_t), np.array(out_xyz), np.array(out_vis), np.array(out_z)


def test_resample_matches_brute_force(rng):
    n = 120
    t = np.cumsum(rng.uniform(0.02, 0.06, n)) + 3.0
    xyz = rng.normal(size=(n, 3)) * [10.0, 5.0, 1.0]
    visible = rng.uniform(size=n) > 0.3
    visible[rng.integers(10, 100):][:15] = False  # one long gap
    visible[[0, -1]] = True
    has_z = visible & (rng.uniform(size=n) > 0.4)
    track = BallTrack(t=t, xyz=np.where(visible[:, None], xyz, 0.0), visible=visible, source="x", rate=25.0,
                      height_known=has_z)
    for dt, gap in ((0.1, 0.2), (0.07, 0.15), (0.033, 1.0)):
        out = resample_track(track, dt, max_gap_s=gap)
        ref_t, ref_xyz, ref_vis, ref_z = _resample_brute(t, xyz, visible, has_z, dt, gap)
        np.testing.assert_allclose(out.t, ref_t, atol=1e-12)
        np.testing.assert_allclose(out.xyz, ref_xyz, atol=1e-9)
        np.testing.assert_array_equal(out.visible, ref_vis)
        np.testing.assert_array_equal(out.height_known, ref_z)
        assert out.rate == pytest.approx(1.0 / dt)
        assert 0 < out.visible.sum() < out.num_frames or gap >= 1.0  # both kinds occur


# --- Replay worlds ------------------------------------------------------------------------------------------------


def _wandering(rng, seconds: float = 8.0, rate: float = 10.0, lift: float = 0.0) -> BallTrack:
    """A ball wandering over a 24 x 16 m area of the pitch (3 x 2 m at 1/8), lifted ``lift`` m half the time."""
    n = int(seconds * rate)
    s = np.arange(n) / rate
    phase = rng.uniform(0, 2 * np.pi, 4)
    x = 30.0 + 12.0 * np.sin(0.4 * s + phase[0]) + 3.0 * np.sin(1.1 * s + phase[1])
    y = -10.0 + 8.0 * np.sin(0.3 * s + phase[2]) + 2.0 * np.sin(0.9 * s + phase[3])
    z = lift * (np.sin(0.8 * s) > 0.0) * np.abs(np.sin(0.8 * s))
    return make_track(np.stack([x, y, z], axis=-1), rate=rate)


def test_replay_scale_and_resampling(rng):
    track = _wandering(rng, seconds=6.0, rate=25.0, lift=4.0)
    for scale in (1 / 8, 1 / 4):
        seq, info = replay_world(track, 3, scale=scale, shrink=SHRINK, dt=0.1)
        res = resample_track(track, 0.1)
        assert seq.num_steps == res.num_frames == info["time"].shape[0]
        np.testing.assert_allclose(info["ball_pitch"], res.xyz)
        # A rigid map of the scaled pitch: distances between steps scale by `scale`.
        d_world = np.linalg.norm(info["ball_world"][:, None] - info["ball_world"][None], axis=-1)
        d_pitch = np.linalg.norm(res.xyz[:, None, :2] - res.xyz[None, :, :2], axis=-1)
        np.testing.assert_allclose(d_world, scale * d_pitch, atol=1e-9)
        np.testing.assert_allclose(info["ball_height"], scale * np.maximum(res.xyz[:, 2], 0.0))
        np.testing.assert_array_equal(info["in_air"], info["ball_height"] > IN_AIR_HEIGHT)
        assert info["start_time"] == pytest.approx(track.t[0]) and info["scale"] == scale
        assert np.all(info["robot_pose"] == 0.0) and np.all(seq.odometry == 0.0)
        d = np.linalg.norm(seq.ground_truth, axis=1)
        assert np.mean((d >= 0.5) & (d <= 6.0)) > 0.9  # placed so the ball stays in front
        assert info["in_view"][~info["in_air"]].mean() > 0.8  # a ball in the air may leave the image's top


def test_head_follows_the_bearing_with_its_lag():
    a, b = [40.0, 0.0, 0.0], [40.0, 20.0, 0.0]  # 2.5 m apart at 1/8: a step of the bearing
    track = make_track([a] * 30 + [b] * 30)
    for seed in range(3):
        seq, info = replay_world(track, seed, shrink=SHRINK)
        target = np.clip(info["ball_bearing"], -HEAD_YAW_LIMIT, HEAD_YAW_LIMIT)
        yaw, tau = info["head_yaw"], info["head_tau"]
        assert 0.3 <= tau <= 0.6 and np.all(np.abs(yaw) <= HEAD_YAW_LIMIT)
        np.testing.assert_allclose(yaw[:30], target[0])  # settled on the ball before the step
        jump = target[30] - yaw[29]
        assert abs(jump) > 0.1
        k = np.arange(30)
        np.testing.assert_allclose(target[30:] - yaw[30:], jump * np.exp(-(k + 1) * 0.1 / tau), atol=1e-12)
        for t in (0, 30, 45):
            np.testing.assert_allclose(seq.cam_to_base[t], camera_pose(
                height=info["camera_height"], pitch=info["camera_pitch"], yaw=yaw[t]), atol=1e-12)
        assert 0.45 <= info["camera_height"] <= 0.7 and 25 <= np.rad2deg(info["camera_pitch"]) <= 35


def test_walking_robot_approaches_and_odometry_integrates():
    # The ball rolls 16 m (2 m scaled) in 20 s, then lies still for 20 s.
    n = 400
    x = 20.0 + 16.0 * np.minimum(np.arange(n) / 200.0, 1.0)
    track = make_track(np.stack([x, 5.0 + 0.0 * x, 0.0 * x], axis=-1))
    seq, info = replay_world(track, 1, robot="walking", shrink=SHRINK, heights="flat")
    pose, dt = info["robot_pose"], 0.1
    dist = np.linalg.norm(seq.ground_truth, axis=1)
    assert dist[-1] == pytest.approx(info["stop_distance"], abs=0.1) and dist[-1] < dist[0]
    step = np.linalg.norm(np.diff(pose[:, :2], axis=0), axis=1) / dt
    turn = np.abs(np.diff(np.unwrap(pose[:, 2]))) / dt
    assert step.max() <= info["walk_speed_limit"] + 1e-9 and step.max() > 0.2
    assert turn.max() <= info["turn_rate_limit"] + 1e-9
    np.testing.assert_allclose(integrate_odometry(info["true_odometry"]), pose, atol=1e-9)
    given = integrate_odometry(seq.odometry)
    drift = np.linalg.norm(given[:, :2] - pose[:, :2], axis=1).max()
    assert 0.0 < drift < 0.1 * np.sum(step * dt)
    # The ground truth is the ball in the base frame of each step.
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    rel = info["ball_world"] - pose[:, :2]
    np.testing.assert_allclose(seq.ground_truth, np.stack([c * rel[:, 0] + s * rel[:, 1],
                                                           -s * rel[:, 0] + c * rel[:, 1]], -1), atol=1e-9)


def _clean_render(calls):
    def render(rng, centres, radius, intrinsics, cam_to_base, shape):
        calls.append(np.array(centres))
        act = np.zeros(shape)
        for c in centres:
            act = np.maximum(act, blob(c, radius, intrinsics, cam_to_base, shape, 0.9))
        return act.astype(np.float32)

    return render


def test_heights_kept_render_the_3d_centre_and_flat_the_ground():
    track = make_track([[30.0, 0.0, 2.4]] * 20)  # 0.3 m above the ground at 1/8
    calls: list[np.ndarray] = []
    kept, info = replay_world(track, 2, shrink=SHRINK, render=_clean_render(calls))
    flat, info_flat = replay_world(track, 2, shrink=SHRINK, heights="flat", render=_clean_render([]))
    assert len(calls) == 20 and all(c.shape == (1, 3) for c in calls)
    np.testing.assert_allclose(info["ball_height"], 0.3) and np.testing.assert_allclose(info_flat["ball_height"], 0)
    assert info["in_air"].all() and not info_flat["in_air"].any()
    np.testing.assert_allclose(kept.ground_truth, flat.ground_truth)
    np.testing.assert_allclose(kept.ground_truth, info["ball_centre_base"][:, :2])
    for seq, heights, z in ((kept, info, 0.3 + BALL_RADIUS), (flat, info_flat, BALL_RADIUS)):
        centre = np.concatenate([seq.ground_truth[-1], [z]])
        np.testing.assert_allclose(heights["ball_centre_base"][-1], centre)
        uv, depth = project_points(centre[None], seq.intrinsics, seq.cam_to_base[-1])
        peak = np.unravel_index(np.argmax(seq.heatmaps[-1]), seq.heatmaps.shape[1:])
        assert float(depth[0]) > 0 and np.abs(np.array(peak[::-1]) - np.asarray(uv[0])).max() <= 0.5 + 1e-6
    # The two peaks differ: the ball in the air sits higher in the image.
    assert np.argmax(kept.heatmaps[-1]) != np.argmax(flat.heatmaps[-1])
    # With the default renderer the peak is still there, under noise.
    noisy, _ = replay_world(track, 2, shrink=SHRINK)
    peaks = [np.unravel_index(np.argmax(s.heatmaps[-1]), s.heatmaps.shape[1:]) for s in (noisy, kept)]
    assert np.abs(np.subtract(*peaks)).max() <= 1


def test_a_ball_above_the_horizon_renders_nothing():
    track = make_track([[30.0, 0.0, 12.0]] * 5 + [[30.0, 0.0, 0.0]] * 5)  # 1.5 m up, then on the ground
    calls: list[np.ndarray] = []
    seq, info = replay_world(track, 0, shrink=SHRINK, render=_clean_render(calls))
    assert info["above_horizon"][:5].all() and not info["above_horizon"][5:].any()
    assert not info["visible"][:5].any() and info["visible"][5:].all()
    assert [c.shape[0] for c in calls] == [0] * 5 + [1] * 5
    assert seq.heatmaps[:5].max() == 0.0 and seq.heatmaps[5:].max() > 0.5


def test_gaps_hide_the_ball_and_the_world_is_deterministic(rng):
    track = _wandering(rng, seconds=5.0)
    visible = track.visible.copy()
    visible[20:32] = False  # 1.3 s without the ball: longer than max_gap_s
    track = track._replace(visible=visible, xyz=np.where(visible[:, None], track.xyz, 0.0))
    seq, info = replay_world(track, 7, shrink=SHRINK, num_steps=40, robot="walking")
    assert seq.heatmaps.shape == (40, 37, 50) and seq.heatmaps.dtype == np.float32
    validate_sequence(seq)
    assert not info["track_known"][20:32].any() and info["track_known"][:20].all()
    assert not info["visible"][20:32].any()
    again, info2 = replay_world(track, 7, shrink=SHRINK, num_steps=40, robot="walking")
    for key in ("heatmaps", "cam_to_base", "odometry", "ground_truth"):
        np.testing.assert_array_equal(getattr(seq, key), getattr(again, key))
    np.testing.assert_array_equal(info["robot_pose"], info2["robot_pose"])
    other, _ = replay_world(track, 8, shrink=SHRINK, num_steps=40, robot="walking")
    assert not np.array_equal(seq.heatmaps, other.heatmaps)
    with pytest.raises(ValueError, match="num_steps"):
        replay_world(track, 7, shrink=SHRINK, num_steps=1000)
    for bad in ({"robot": "running"}, {"heights": "high"}, {"scale": 0.0}, {"shrink": 0}, {"render": 3}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            replay_world(track, 7, **bad)


def test_default_render_is_blob_plus_noise():
    rng_a, rng_b = np.random.default_rng(0), np.random.default_rng(0)
    cam = camera_pose(height=0.6, pitch=0.5)
    intr = np.array([35.75, 35.75, 24.5, 18.25])
    centre = np.array([[1.5, 0.2, BALL_RADIUS]])
    frame = blob_render(rng_a, centre, BALL_RADIUS, intr, cam, (37, 50))
    ref = np.clip(blob(centre[0], BALL_RADIUS, intr, cam, (37, 50), 0.9) + 0.03 * rng_b.standard_normal((37, 50)),
                  0, 1)
    np.testing.assert_allclose(frame, ref.astype(np.float32))
    assert blob_render(rng_a, np.zeros((0, 3)), BALL_RADIUS, intr, cam, (37, 50)).max() < 0.2


# --- The fetch and its cache --------------------------------------------------------------------------------------


def _tarball(folder: Path) -> Path:
    """A tiny stand-in for kloppy's sdist: the tiny tracks under the real names, a licence, a Hawk-Eye file."""
    path = folder / "kloppy.tar.gz"
    prefix = f"kloppy-{KLOPPY_VERSION}"
    with tarfile.open(path, "w:gz") as archive:
        for name in KLOPPY_FILES:
            archive.add(TINY / name, arcname=f"{prefix}/kloppy/tests/files/{name}")
        for name, text in (("LICENSE", b"BSD 3-Clause License\n"),
                           ("kloppy/tests/files/hawkeye_1_1.football.samples.ball", b"reserved\n"),
                           ("kloppy/tests/files/hawkeye_meta.json", b"{}\n")):
            info = tarfile.TarInfo(f"{prefix}/{name}")
            info.size = len(text)
            archive.addfile(info, io.BytesIO(text))
    return path


@pytest.fixture
def fake_pip(tmp_path, monkeypatch):
    """``subprocess.run`` as pip would be: copies the tiny tarball to ``-d``; records the commands."""
    tarball = _tarball(tmp_path)
    monkeypatch.setattr(tracks_module, "_SDIST_SHA256", hashlib.sha256(tarball.read_bytes()).hexdigest())
    calls = []

    def run(command, **kwargs):
        calls.append(command)
        assert command[:4] == [sys.executable, "-m", "pip", "download"] and f"kloppy=={KLOPPY_VERSION}" in command
        shutil.copy(tarball, Path(command[command.index("-d") + 1]) / f"kloppy-{KLOPPY_VERSION}.tar.gz")
        return subprocess.CompletedProcess(command, 0, "", "")

    monkeypatch.setattr(tracks_module.subprocess, "run", run)
    return calls


def test_fetch_extracts_once_with_its_source(tmp_path, fake_pip, monkeypatch):
    cache = tmp_path / "cache"
    monkeypatch.setenv("HEATPF_TRACKS_DIR", str(cache))
    assert tracks_directory() == cache
    folder = fetch_kloppy_files()
    assert folder == cache / f"kloppy-{KLOPPY_VERSION}" and len(fake_pip) == 1
    names = sorted(p.name for p in folder.iterdir())
    assert names == sorted([*KLOPPY_FILES, "LICENSE-kloppy.txt", "SOURCE.txt"])
    assert [p.name for p in cache.iterdir()] == [folder.name]  # no temporary folder left
    assert not [p for p in cache.rglob("*") if "hawkeye" in p.name.lower()]
    source = (folder / "SOURCE.txt").read_text()
    assert tracks_module._SDIST_SHA256 in source and "BSD 3-Clause" in source and "MIT License" in source
    assert all(name in source for name in KLOPPY_FILES) and "hawkeye_" not in source
    assert (folder / "pff_3812.jsonl").read_bytes() == (TINY / "pff_3812.jsonl").read_bytes()
    assert fetch_kloppy_files(cache) == folder and len(fake_pip) == 1  # the cache is reused
    pieces = replay_segments("skillcorner", min_length_s=0.2, max_gap_s=0.25, cache_dir=cache)
    assert [round(p.t[0], 6) for p in pieces] == [0.2, 1.2]
    assert [p.source for p in replay_segments("pff", min_length_s=0.0, cache_dir=cache)] == ["pff:10517"] * 2 + [
        "pff:3812"]


def test_fetch_failures_leave_nothing(tmp_path, fake_pip, monkeypatch):
    cache = tmp_path / "cache"

    def failing(command, **kwargs):
        return subprocess.CompletedProcess(command, 1, "", "ERROR: No matching distribution found for kloppy\n")

    monkeypatch.setattr(tracks_module.subprocess, "run", failing)
    with pytest.raises(RuntimeError, match="No matching distribution.*network") as err:
        fetch_kloppy_files(cache)
    assert "\n" not in str(err.value) and list(cache.iterdir()) == []

    def offline(command, **kwargs):
        raise OSError("network unreachable")

    monkeypatch.setattr(tracks_module.subprocess, "run", offline)
    with pytest.raises(RuntimeError, match="could not run"):
        fetch_kloppy_files(cache)
    assert list(cache.iterdir()) == []


def test_fetch_interrupted_or_tampered_leaves_nothing(tmp_path, fake_pip, monkeypatch):
    cache = tmp_path / "cache"

    def interrupt(*args):
        raise KeyboardInterrupt

    with monkeypatch.context() as patch:
        patch.setattr(tracks_module, "_source_text", interrupt)
        with pytest.raises(KeyboardInterrupt):
            fetch_kloppy_files(cache)
    assert list(cache.iterdir()) == []
    with monkeypatch.context() as patch:
        patch.setattr(tracks_module, "_SDIST_SHA256", "0" * 64)
        with pytest.raises(RuntimeError, match="sha256"):
            fetch_kloppy_files(cache)
    assert list(cache.iterdir()) == []
    assert fetch_kloppy_files(cache).is_dir() and len(fake_pip) == 3  # a later call completes


# --- The real download (only where it is cached) ------------------------------------------------------------------

REAL = tracks_directory() / f"kloppy-{KLOPPY_VERSION}"


@pytest.mark.skipif(not (REAL / "SOURCE.txt").is_file(), reason="kloppy's files are not cached (fetch_kloppy_files)")
def test_real_tracks_load():
    pff = load_pff(REAL / "pff_10517.jsonl")
    assert pff.source == "pff:10517" and pff.num_frames == 200 and pff.visible.sum() == 148
    skill = load_skillcorner(REAL / "skillcorner_structured_data.json")
    assert skill.source == "skillcorner:2417" and skill.num_frames == 68101
    assert 3000 < skill.visible.sum() / skill.rate < 3200  # about 51 minutes with the ball known
    assert len(list(segments(skill, 0.5, min_length_s=30.0))) >= 5
