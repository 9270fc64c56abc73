"""The simulated evaluation world: conventions, the sequence contract, and what each scenario promises.

Geometry is checked against independent code: the filter's own ``project_heatmap``/``apply_odometry``
and hand-written rotations here. Heat-map contents are checked with ``scipy.ndimage.label``.
Sizes are small (shrink 2 or more, 60-100 steps) except where a blob must be resolved at full size.
"""

from __future__ import annotations

import functools
import inspect

import jax
import numpy as np
import pytest
from scipy import ndimage

import heatpf_jax as hp
import heatpf_jax.sim as sim
from heatpf_jax.sim import (
    BALL_RADIUS,
    DEFAULT_INTRINSICS,
    HEATMAP_SHAPE,
    SCENARIOS,
    render_heatmap,
    scaled_camera,
    simulate,
    simulate_standard,
    simulate_with_info,
)

DT = 0.1
SEED = 0  # the scenario checks below were run with every seed 0-29 (change it here to re-check)


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _to_base(pose: np.ndarray, point: np.ndarray) -> np.ndarray:
    return _rot(pose[2]).T @ (point - pose[:2])


def _project(point_xy: np.ndarray, intrinsics: np.ndarray, cam: np.ndarray) -> tuple[np.ndarray, float]:
    """Pixel of a ball centre at base ``point_xy`` (height = radius) and its apparent radius in pixels."""
    uv, depth = hp.camera.project_points(np.array([[point_xy[0], point_xy[1], BALL_RADIUS]]), intrinsics, cam)
    depth = float(np.asarray(depth)[0])
    return np.asarray(uv, np.float64)[0], float(intrinsics[0]) * BALL_RADIUS / depth


@functools.partial(jax.jit, static_argnames="max_measurements")
def _project_heatmap(heat, intrinsics, cam, threshold, max_measurements=1024):
    return hp.measurements.project_heatmap(heat, intrinsics, cam, threshold=threshold, plane_height=BALL_RADIUS,
                              max_measurements=max_measurements)


def _centroid(heat: np.ndarray, intrinsics: np.ndarray, cam: np.ndarray, threshold: float = 0.5) -> np.ndarray:
    """Activation-weighted mean of the measurements ``project_heatmap`` makes of a heat map."""
    m = _project_heatmap(heat, intrinsics.astype(np.float32), cam.astype(np.float32), np.float32(threshold))
    valid = np.asarray(m.valid)
    w, xy = np.asarray(m.weight, np.float64)[valid], np.asarray(m.xy, np.float64)[valid]
    assert valid.sum() > 0
    return (w[:, None] * xy).sum(0) / w.sum()


@functools.cache
def _runs(scenario: str) -> tuple[hp.Sequence, dict]:
    """100 steps of a scenario on a 100 x 75 heat map, simulated once per session (callers must not modify it)."""
    return simulate_with_info(scenario, SEED, num_steps=100, shrink=2)


def _components(heat: np.ndarray, threshold: float, min_size: int = 1) -> list[tuple[np.ndarray, float, int]]:
    """(centroid (u, v), peak, size) of each 4-connected component above ``threshold`` with >= ``min_size`` pixels."""
    labels, n = ndimage.label(heat > threshold)
    out = []
    for k in range(1, n + 1):
        rows, cols = np.nonzero(labels == k)
        if rows.size >= min_size:
            out.append((np.array([cols.mean(), rows.mean()]), float(heat[rows, cols].max()), rows.size))
    return out


# --- API ----------------------------------------------------------------------------------------------------------


def test_public_names_and_signatures():
    assert SCENARIOS == (
        "standard", "false_positives", "split", "far", "occlusion", "walking", "sparse_rate", "two_balls", "shot",
        "turning",
    )
    for name in sim.__all__:
        assert hasattr(sim, name), name
    params = inspect.signature(simulate_standard).parameters
    assert [(p.name, p.default, p.kind.name) for p in params.values()] == [
        ("seed", inspect.Parameter.empty, "POSITIONAL_OR_KEYWORD"),
        ("num_steps", 300, "POSITIONAL_OR_KEYWORD"),
        ("dt", 0.1, "POSITIONAL_OR_KEYWORD"),
        ("shrink", 1, "KEYWORD_ONLY"),
    ]
    params = inspect.signature(simulate).parameters
    assert list(params) == ["scenario", "seed", "num_steps", "dt", "shrink", "rgb"]
    assert params["num_steps"].default is None
    assert params["rgb"].default is False and params["rgb"].kind is inspect.Parameter.KEYWORD_ONLY
    params = inspect.signature(render_heatmap).parameters
    assert list(params)[:4] == ["rng", "ball_xy", "intrinsics", "cam_to_base"]
    assert all(params[k].kind is inspect.Parameter.KEYWORD_ONLY for k in ("ball_radius", "shape", "peak", "noise"))
    np.testing.assert_array_equal(DEFAULT_INTRINSICS, [143.0, 143.0, 99.5, 74.5])
    assert HEATMAP_SHAPE == (150, 200) and BALL_RADIUS == 0.075


def test_unknown_scenario_and_bad_arguments():
    with pytest.raises(ValueError, match="scenario") as err:
        simulate("penalty_shootout", 0)
    assert all(name in str(err.value) for name in SCENARIOS)
    for kwargs, name in [({"num_steps": 0}, "num_steps"), ({"dt": -0.1}, "dt"), ({"shrink": 0}, "shrink")]:
        with pytest.raises(ValueError, match=name):
            simulate("standard", 0, **kwargs)
    with pytest.raises(ValueError, match="seed"):
        simulate("standard", -1)


def test_standard_alias_and_shrink():
    a = simulate_standard(5, 12, shrink=4)
    b = simulate("standard", 5, num_steps=12, shrink=4)
    for key in hp.Sequence._fields:
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)
    intrinsics, shape = scaled_camera(4)
    assert a.heatmaps.shape == (12, 37, 50) and shape == (37, 50)
    np.testing.assert_allclose(intrinsics, [143 / 4, 143 / 4, (99.5 - 1.5) / 4, (74.5 - 1.5) / 4])
    np.testing.assert_array_equal(a.intrinsics, intrinsics)


def test_default_length_and_rate():
    seq = simulate("walking", 1, shrink=10)
    assert seq.num_steps == 300 and float(seq.dt) == 0.1 and seq.heatmaps.shape == (300, 15, 20)


# --- Conventions --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("height,pitch_deg", [(0.6, 30.0), (0.45, 25.0), (0.7, 35.0)])
def test_rendered_ball_projects_back_onto_the_ball(height, pitch_deg):
    """The blob sits on the ball centre's projection; project_heatmap (plane z = radius) lands on its (x, y)."""
    cam = hp.camera.camera_pose(height=height, pitch=np.deg2rad(pitch_deg))
    rng = np.random.default_rng(0)
    for xy in [(1.0, 0.0), (1.5, 0.4), (2.0, -0.6), (3.0, 0.8)]:
        ball = np.array(xy)
        heat = render_heatmap(rng, ball, DEFAULT_INTRINSICS, cam)
        assert heat.dtype == np.float32 and heat.shape == HEATMAP_SHAPE and 0.0 <= heat.min() <= heat.max() <= 1.0
        uv, radius_px = _project(ball, DEFAULT_INTRINSICS, cam)
        rows, cols = np.nonzero(heat > 0.5)
        weights = heat[rows, cols]
        centre = np.array([cols @ weights, rows @ weights]) / weights.sum()
        assert np.linalg.norm(centre - uv) < 0.3, (centre, uv)
        # Perspective: the blob above half its peak spans about the apparent diameter.
        above = (heat > 0.45).sum()
        assert 0.5 * np.pi * (0.5 * radius_px) ** 2 < above < 2.0 * np.pi * radius_px**2
        err = np.linalg.norm(_centroid(heat, DEFAULT_INTRINSICS, cam) - ball)
        assert err < 0.02, f"{xy}: centroid {err:.3f} m off"


def test_scenario_heatmaps_project_onto_ground_truth_with_the_true_pose():
    """In ``walking`` the true camera pose brings the blob back to the ball; the reported (pitch-off) pose does not."""
    seq, info = simulate_with_info("walking", SEED + 2, num_steps=20, shrink=1)
    err_true, err_given = [], []
    for t in range(0, 20, 4):
        err_true.append(np.linalg.norm(_centroid(seq.heatmaps[t], seq.intrinsics, info["true_cam_to_base"][t])
                                       - seq.ground_truth[t]))
        err_given.append(np.linalg.norm(_centroid(seq.heatmaps[t], seq.intrinsics, seq.cam_to_base[t])
                                        - seq.ground_truth[t]))
    assert max(err_true) < 0.03, err_true
    assert min(err_given) > 0.02 and np.mean(err_given) > 3 * np.mean(err_true), (err_true, err_given)


def test_odometry_convention_matches_the_filter():
    """Applying the true odometry to ground_truth[t-1] gives the ball's world position of t-1 seen from t."""
    seq, info = simulate_with_info("walking", SEED + 3, num_steps=60, shrink=8)
    pose, ball, odom = info["robot_pose"], info["ball_world"], info["true_odometry"]
    np.testing.assert_array_equal(odom[0], 0.0)
    for t in range(1, 60):
        moved = _rot(odom[t, 2]).T @ (seq.ground_truth[t - 1] - odom[t, :2])
        np.testing.assert_allclose(moved, _to_base(pose[t], ball[t - 1]), atol=1e-9)
    filt = np.asarray(hp.motion.apply_odometry(seq.ground_truth[:-1].astype(np.float32), odom[1:].astype(np.float32)))
    expected = np.stack([_to_base(pose[t], ball[t - 1]) for t in range(1, 60)])
    np.testing.assert_allclose(filt, expected, atol=1e-4)


# --- Every scenario -----------------------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_scenario_validates_reproduces_and_varies(scenario):
    seq, info = _runs(scenario)
    assert hp.validate_sequence(seq) is not None and seq.ground_truth is not None
    assert seq.heatmaps.dtype == np.float32 and seq.heatmaps.shape == (100, 75, 100)
    assert seq.cam_to_base.shape == (100, 4, 4) and seq.odometry.shape == (100, 3)
    again, info_again = simulate_with_info(scenario, SEED, num_steps=100, shrink=2)
    for key in hp.Sequence._fields:
        np.testing.assert_array_equal(getattr(again, key), getattr(seq, key), err_msg=key)
    for key, value in info.items():
        np.testing.assert_array_equal(info_again[key], value, err_msg=key)
    other = simulate(scenario, SEED + 1, num_steps=100, shrink=2)
    assert not np.allclose(other.ground_truth, seq.ground_truth)
    assert not np.array_equal(other.heatmaps, seq.heatmaps)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_world_consistency_and_speed(scenario):
    seq, info = _runs(scenario)
    pose, ball = info["robot_pose"], info["ball_world"]
    truth = np.stack([_to_base(pose[t], ball[t]) for t in range(seq.num_steps)])
    np.testing.assert_allclose(seq.ground_truth, truth, atol=1e-9)
    speed = np.linalg.norm(np.diff(ball, axis=0), axis=1) / DT
    assert speed.max() <= (8.0 if scenario == "shot" else 3.0) + 1e-9 and speed.mean() > 0.05
    np.testing.assert_array_equal(seq.odometry[0], 0.0)
    if scenario not in ("walking", "turning"):  # a static robot: odometry zero, base = world, exact camera
        np.testing.assert_array_equal(seq.odometry, 0.0)
        np.testing.assert_allclose(seq.ground_truth, ball)
        np.testing.assert_array_equal(seq.cam_to_base, info["true_cam_to_base"])
        assert np.all(seq.cam_to_base == seq.cam_to_base[0])
    # The camera is a humanoid's head camera: 0.4-0.7 m high, pitched down 25-35 degrees.
    cam = info["true_cam_to_base"]
    optical_axis = cam[:, :3, 2]
    pitch = np.degrees(np.arcsin(-optical_axis[:, 2]))
    assert np.all((cam[:, 2, 3] > 0.4) & (cam[:, 2, 3] < 0.7)) and np.all((pitch > 24) & (pitch < 36))
    # The ball is in view where the scenario does not hide it (the standard path leaves the image edge briefly).
    assert info["in_view"].mean() > (0.5 if scenario == "turning" else 0.85)


def test_standard_like_scenarios_share_the_standard_world():
    std = simulate("standard", SEED, num_steps=100, shrink=2)
    for scenario in ("false_positives", "occlusion", "sparse_rate"):
        seq, _ = _runs(scenario)
        np.testing.assert_array_equal(seq.ground_truth, std.ground_truth)
    sparse, _ = _runs("sparse_rate")
    has = sparse.has_heatmap
    np.testing.assert_array_equal(sparse.heatmaps[has], std.heatmaps[has])


# --- What each scenario contains ----------------------------------------------------------------------------------


def test_false_positives_are_spurious_blobs_at_fixed_places():
    seq, info = simulate_with_info("false_positives", SEED, num_steps=200, shrink=1)
    places = info["false_positive_world"]
    assert 3 <= len(places) <= 5
    # Long run (info only, tiny heat maps): each place on 30-60 % of the frames on average, in bursts.
    _, long = simulate_with_info("false_positives", SEED, num_steps=300, shrink=10)
    share = long["false_positive_on"].mean(0)
    assert np.all((share > 0.15) & (share < 0.85)) and 0.3 < share.mean() < 0.65, share
    switches = np.abs(np.diff(long["false_positive_on"].astype(int), axis=0)).sum(0)
    assert np.all(switches < 0.5 * 300 * 2 * share * (1 - share)), switches  # bursty, not independent per frame
    spurious_frames, brighter = 0, 0
    # Spurious objects are rendered like balls of their own radius (centre at that height).
    radii = info["false_positive_radius"]
    fp_uv, fp_depth = hp.camera.project_points(np.c_[places, radii], seq.intrinsics, seq.cam_to_base[0])
    fp_uv, fp_radius_px = np.asarray(fp_uv, np.float64), seq.intrinsics[0] * radii / np.asarray(fp_depth)
    for t in range(seq.num_steps):
        ball_uv, radius_px = _project(seq.ground_truth[t], seq.intrinsics, seq.cam_to_base[t])
        comps = _components(seq.heatmaps[t], 0.5)
        ball_peak = max((c[1] for c in comps if np.linalg.norm(c[0] - ball_uv) < radius_px + 2), default=0.0)
        away = [c for c in comps if np.linalg.norm(c[0] - ball_uv) > 2 * radius_px + 3]
        spurious_frames += bool(away)
        assert not away or info["false_positive_count"][t] > 0
        # Every blob away from the ball sits on one of the fixed places.
        for centre, _, _ in away:
            assert np.any(np.linalg.norm(centre - fp_uv, axis=1) < fp_radius_px + 2.0)
        brighter += ball_peak > 0 and any(c[1] > ball_peak for c in away)
    assert spurious_frames >= 0.5 * seq.num_steps, spurious_frames
    assert spurious_frames >= 0.8 * (info["false_positive_count"] > 0).sum()
    assert brighter >= 3, brighter
    assert np.all(info["false_positive_count"] == info["false_positive_on"].sum(1))


def test_split_frames_have_two_clusters_on_a_close_ball():
    seq, info = _runs("split")
    dist = np.linalg.norm(seq.ground_truth, axis=1)
    assert dist.min() >= 0.4 and dist.max() <= 1.2
    split = np.flatnonzero(info["split"])
    assert len(split) >= 0.5 * seq.num_steps
    for threshold in (0.3, 0.5):
        two = 0
        for t in split:
            uv, radius_px = _project(seq.ground_truth[t], seq.intrinsics, seq.cam_to_base[t])
            comps = _components(seq.heatmaps[t], threshold, min_size=3)
            near = [c for c in comps if np.linalg.norm(c[0] - uv) < radius_px + 1]
            two += len(near) >= 2
        assert two >= 0.8 * len(split), (threshold, two, len(split))
    # Unsplit frames show the ball as one cluster (activation noise may leave single pixels at its rim).
    whole = np.flatnonzero(~info["split"])
    assert len(whole) > 0
    for t in whole:
        uv, radius_px = _project(seq.ground_truth[t], seq.intrinsics, seq.cam_to_base[t])
        comps = _components(seq.heatmaps[t], 0.3, min_size=3)
        near = [c for c in comps if np.linalg.norm(c[0] - uv) < radius_px + 1]
        assert len(near) == 1


def test_far_ball_is_a_few_weak_pixels():
    seq, info = simulate_with_info("far", SEED, num_steps=60, shrink=1)
    dist = np.linalg.norm(seq.ground_truth, axis=1)
    assert dist.min() >= 4.0 and dist.max() <= 7.0
    count = (seq.heatmaps > 0.3).sum(axis=(1, 2))
    assert count.max() <= 25 and count.mean() <= 12, count
    assert seq.heatmaps.max() < 0.85 and info["ball_peak"].max() <= 0.75
    # Compare: the same camera sees a ball at 2 m as many more pixels.
    near = render_heatmap(np.random.default_rng(0), np.array([2.0, 0.0]), seq.intrinsics, seq.cam_to_base[0])
    assert (near > 0.3).sum() > 3 * count.max()


def test_occlusion_windows_hide_a_moving_ball():
    seq, info = _runs("occlusion")
    np.testing.assert_array_equal(info["visible"], info["in_view"] & ~info["occluded"])
    _, long = simulate_with_info("occlusion", SEED, shrink=10)
    for occluded, num_windows in ((info["occluded"], (1, 3)), (long["occluded"], (2, 3))):
        edges = np.diff(np.r_[0, occluded.astype(int), 0])
        starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        assert num_windows[0] <= len(starts) <= num_windows[1]
        assert np.all((stops - starts >= 5) & (stops - starts <= 20)), stops - starts
    edges = np.diff(np.r_[0, info["occluded"].astype(int), 0])
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        assert seq.has_heatmap[start:stop].all()
        assert seq.heatmaps[start:stop].max() < 0.25  # only activation noise
        assert np.linalg.norm(seq.ground_truth[stop - 1] - seq.ground_truth[start]) > 0.01  # the ball moves on
    visible = np.flatnonzero(info["visible"])
    assert seq.heatmaps[visible].max(axis=(1, 2)).min() > 0.5


def test_walking_robot_noisy_odometry_and_pitch_error():
    seq, info = simulate_with_info("walking", SEED, num_steps=300, shrink=10)
    pose, true_odom = info["robot_pose"], info["true_odometry"]
    speed = np.linalg.norm(np.diff(pose[:, :2], axis=0), axis=1) / DT
    turn = np.abs(np.diff(pose[:, 2])) / DT
    assert 0.08 <= speed.min() and speed.max() <= 0.35
    assert 0.15 <= turn.max() <= 0.55
    # The reported odometry is noisy but close: integrating it tracks the true walk.
    odom = seq.odometry
    assert np.all(np.linalg.norm(odom[1:, :2], axis=1) > 0)
    rel = (odom[1:] - true_odom[1:])[:, 0] / true_odom[1:, 0]
    assert 0.03 < rel.std() < 0.15
    est = np.zeros(3)
    for t in range(1, seq.num_steps):
        est = np.r_[est[:2] + _rot(est[2]) @ odom[t, :2], est[2] + odom[t, 2]]
        if t % 50 == 0 or t == seq.num_steps - 1:
            travelled = np.linalg.norm(np.diff(pose[: t + 1, :2], axis=0), axis=1).sum()
            assert np.linalg.norm(est[:2] - pose[t, :2]) < 0.15 * travelled + 0.05
            assert abs(est[2] - pose[t, 2]) < 0.25
    true_est = np.zeros(3)
    for t in range(1, seq.num_steps):
        true_est = np.r_[true_est[:2] + _rot(true_est[2]) @ true_odom[t, :2], true_est[2] + true_odom[t, 2]]
    np.testing.assert_allclose(true_est, pose[-1], atol=1e-9)
    # The reported camera pose is off by 1-2 degrees (same position); the true one sways.
    true_cam = info["true_cam_to_base"]
    rel_rot = np.einsum("tji,tjk->tik", true_cam[:, :3, :3], seq.cam_to_base[:, :3, :3])
    angle = np.degrees(np.arccos(np.clip((np.trace(rel_rot, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    assert angle.min() >= 0.99 and angle.max() <= 2.01, (angle.min(), angle.max())
    np.testing.assert_allclose(true_cam[:, :3, 3], seq.cam_to_base[:, :3, 3])
    assert np.ptp(true_cam[:, 2, 3]) > 0.005 and np.ptp(true_cam[:, 1, 3]) > 0.01
    assert info["in_view"].mean() > 0.95


def test_sparse_rate_heatmaps_arrive_irregularly():
    seq, info = _runs("sparse_rate")
    long = simulate("sparse_rate", SEED, shrink=10)
    for has in (seq.has_heatmap, long.has_heatmap):
        assert 0.25 <= has.mean() <= 0.45, has.mean()
        gaps = np.diff(np.flatnonzero(has))
        assert gaps.min() >= 1 and gaps.max() <= 6 and len(np.unique(gaps)) >= 4
    assert not seq.heatmaps[~seq.has_heatmap].any()
    np.testing.assert_array_equal(info["visible"], seq.has_heatmap & info["in_view"])
