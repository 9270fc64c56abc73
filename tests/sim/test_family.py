"""The world family: determinism, the factors' documented ranges, and what each factor promises.

References: ``hp.camera.project_points`` of the ball's 3D centre with the true camera pose (where its blob must be),
the rotation angle ``arccos((tr(R_g^T R_t) - 1) / 2)`` between the sequence's and the true camera
(the calibration error), the world-to-base transform written out here (the ground truth), and the
documented ranges of :mod:`heatpf_jax.sim.family` (every factor over 30 seeds).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sim import detector, family, simulate
from heatpf_jax.sim.detector import DetectorFactors, SceneObject, render_frame
from heatpf_jax.sim.family import FAMILY, draw_factors, factor_ranges, simulate_family, simulate_family_with_info

SHRINK = 4
STEPS = 60
# A detector without noise, background or partial occlusion, and no false positives: only the ball is drawn.
CLEAN = {"noise": 0.0, "clutter_strength": 0.0, "speckle_density": 0.0, "line_rate": 0.0, "dropout": 0.0,
         "occlusion_rate": 0.0, "fp_count": 0, "peak_jitter": 0.0}


@functools.cache
def _sim(member: str, seed: int, num_steps: int = STEPS, shrink: int = SHRINK, **overrides):
    return simulate_family_with_info(member, seed, num_steps=num_steps, shrink=shrink, overrides=overrides or None)


def _clean(member: str, seed: int, num_steps: int = STEPS, shrink: int = 2, **more):
    return _sim(member, seed, num_steps, shrink, **{**CLEAN, **more})


def _base(pose: np.ndarray, xy: np.ndarray) -> np.ndarray:
    c, s = np.cos(pose[2]), np.sin(pose[2])
    d = xy - pose[:2]
    return np.array([c * d[0] + s * d[1], -s * d[0] + c * d[1]])


def _ball_uv(seq, info, t: int) -> tuple[np.ndarray, float]:
    """Where the ball of heat map t projects with the true camera, and its apparent radius (px)."""
    s = info["render_step"][t]
    centre = np.r_[seq.ground_truth[s], float(seq.ball_radius) + info["ball_height"][s]]
    cam = info["true_cam_to_base"][s]
    uv, depth = hp.camera.project_points(centre[None], seq.intrinsics, cam)
    return np.asarray(uv, np.float64)[0], float(seq.intrinsics[0]) * float(seq.ball_radius) / float(depth[0])


def _centroid(heat: np.ndarray) -> tuple[np.ndarray, int]:
    """Centroid ``(u, v)`` of the pixels above half the maximum, and their count."""
    vv, uu = np.mgrid[0 : heat.shape[0], 0 : heat.shape[1]]
    w = np.where(heat > 0.5 * heat.max(), heat, 0.0)
    return np.array([(w * uu).sum(), (w * vv).sum()]) / w.sum(), int((w > 0).sum())


def _inside(uv: np.ndarray, margin: float, shape) -> bool:
    return margin <= uv[0] <= shape[1] - 1 - margin and margin <= uv[1] <= shape[0] - 1 - margin


# --- Determinism and ranges ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("member", FAMILY)
def test_same_member_and_seed_same_world(member):
    seq, info = _sim(member, 3)
    again, info_again = simulate_family_with_info(member, 3, num_steps=STEPS, shrink=SHRINK)
    for name in seq._fields:
        a, b = getattr(seq, name), getattr(again, name)
        assert (a is None and b is None) or np.array_equal(a, b), name
    assert info["factors"] == info_again["factors"] == draw_factors(member, 3)
    assert info["member"] == info["scenario"] == member and info["seed"] == 3 and not info["fixed"]
    other, info_other = _sim(member, 4)
    assert info_other["factors"] != info["factors"]
    assert not np.array_equal(other.heatmaps, seq.heatmaps)


def test_members_draw_independent_factors():
    a, b = draw_factors("standard", 5), draw_factors("occlusion", 5)
    assert a["camera_height_m"] != b["camera_height_m"] and a["peak"] != b["peak"]


def _pooled(member: str, seeds: range) -> dict[str, list]:
    pooled: dict[str, list] = {}
    specs = factor_ranges(member)
    for seed in seeds:
        for name, value in draw_factors(member, seed).items():
            pooled.setdefault(name, []).extend(value if specs[name].per_object else [value])
    return pooled


@pytest.mark.parametrize("member", FAMILY)
def test_factors_cover_their_documented_ranges(member):
    specs = factor_ranges(member)
    pooled = _pooled(member, range(30))
    assert set(pooled) == set(specs)
    for name, spec in specs.items():
        values = pooled[name]
        assert name in family.__doc__ or name in detector.__doc__, name
        if not values:  # per-object factors of a member without false positives
            assert spec.per_object and specs["fp_count"].fixed
            continue
        if spec.choices is not None:
            assert set(values) == set(spec.choices), name
            continue
        if spec.fixed:
            assert set(values) == {spec.low}, name
            continue
        lo, hi = spec.low, spec.high
        assert lo <= min(values) and max(values) <= hi, name
        if spec.integer:
            assert min(values) == lo and max(values) == hi, name
        else:
            span = np.log(hi / lo) if spec.log else hi - lo
            low_end = np.log(min(values) / lo) if spec.log else min(values) - lo
            high_end = np.log(hi / max(values)) if spec.log else hi - max(values)
            assert low_end < 0.25 * span and high_end < 0.25 * span, name


def test_the_table_names_every_member_that_differs():
    rows = {}
    for line in family.__doc__.splitlines():
        if line.startswith("| ") and not line.startswith("| factor"):
            rows[line.split("|")[1].strip()] = line
    defaults = factor_ranges("standard")
    for name in defaults:
        assert (name if name not in detector.DETECTOR_RANGES else "blob_shape ... line_strength") in rows, name
    for member in FAMILY:
        for name, spec in factor_ranges(member).items():
            if spec != defaults[name]:
                row = rows[name if name not in detector.DETECTOR_RANGES else "blob_shape ... line_strength"]
                assert member in row or (member == "kicked_hidden" and "k.h." in row), (member, name)


def test_false_positives_member_has_one_brighter_than_the_ball():
    for seed in range(20):
        f = draw_factors("false_positives", seed)
        assert 2 <= f["fp_count"] == len(f["fp_brightness"]) <= 5
        assert max(f["fp_brightness"]) >= 1.05


def test_overrides_pin_factors_and_keep_the_other_draws():
    f = draw_factors("kicked_hidden", 2)
    g = draw_factors("kicked_hidden", 2, overrides={"distractors": 0, "peak": 0.5})
    assert g["distractors"] == 0 and g["peak"] == 0.5
    assert {k: v for k, v in g.items() if k not in ("distractors", "peak")} == {
        k: v for k, v in f.items() if k not in ("distractors", "peak")}
    h = draw_factors("standard", 1, overrides={"fp_count": 3})
    assert len(h["fp_brightness"]) == len(h["fp_moving"]) == 3
    with pytest.raises(ValueError, match="unknown factor"):
        draw_factors("standard", 1, overrides={"brightness": 1.0})
    with pytest.raises(ValueError, match="fp_count"):
        draw_factors("standard", 1, overrides={"fp_count": 9})


def test_bad_arguments():
    with pytest.raises(ValueError, match="valid names: standard"):
        simulate_family("nowhere", 0)
    with pytest.raises(ValueError, match="seed"):
        simulate_family("standard", -1)
    with pytest.raises(ValueError, match="shrink"):
        simulate_family("standard", 0, shrink=0)
    with pytest.raises(ValueError, match="no fixed scenario"):
        simulate_family("lofted", 0, fixed=True)


@pytest.mark.parametrize("member", ["standard", "split", "walking", "far"])
def test_fixed_members_are_todays_scenarios(member):
    seq, info = simulate_family_with_info(member, 0, num_steps=20, shrink=SHRINK, fixed=True)
    today = simulate(member, 0, num_steps=20, shrink=SHRINK)
    np.testing.assert_array_equal(seq.heatmaps, today.heatmaps)
    np.testing.assert_array_equal(seq.ground_truth, today.ground_truth)
    assert info["fixed"] and info["factors"] == {}


@pytest.mark.parametrize("member", FAMILY)
def test_the_world_is_the_same_at_every_shrink(member):
    a, info_a = _sim(member, 1, STEPS, 4)
    b, info_b = _sim(member, 1, STEPS, 8)
    np.testing.assert_array_equal(a.ground_truth, b.ground_truth)
    np.testing.assert_array_equal(a.cam_to_base, b.cam_to_base)
    np.testing.assert_array_equal(a.has_heatmap, b.has_heatmap)
    np.testing.assert_array_equal(info_a["ball_height"], info_b["ball_height"])
    assert a.heatmaps.shape[1:] == (37, 50) and b.heatmaps.shape[1:] == (18, 25)


# --- What the factors do ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("member", FAMILY)
def test_ground_truth_and_calibration_error(member):
    seq, info = _sim(member, 2)
    f = info["factors"]
    truth = np.stack([_base(p, b) for p, b in zip(info["robot_pose"], info["ball_world"], strict=True)])
    np.testing.assert_allclose(seq.ground_truth, truth, atol=1e-12)
    rel = np.einsum("tji,tjk->tik", seq.cam_to_base[:, :3, :3], info["true_cam_to_base"][:, :3, :3])
    angle = np.rad2deg(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)))
    np.testing.assert_allclose(angle, f["calibration_error_deg"], atol=1e-5)
    assert 1.0 <= f["calibration_error_deg"] <= 3.0
    np.testing.assert_array_equal(seq.cam_to_base[:, :3, 3], info["true_cam_to_base"][:, :3, 3])
    np.testing.assert_array_equal(info["render_step"], np.maximum(np.arange(STEPS) - f["latency_steps"], 0))


@pytest.mark.parametrize("shape_name", ["gaussian", "disc"])
@pytest.mark.parametrize("member", ["standard", "walking", "far", "kicked_hidden"])
def test_blob_lies_where_the_ball_projects(member, shape_name):
    checked = 0
    for seed in (0, 1):
        more = {"distractors": 0} if member == "kicked_hidden" else {}
        seq, info = _clean(member, seed, blob_shape=shape_name, **more)
        for t in np.flatnonzero(info["visible"]):
            uv, radius_px = _ball_uv(seq, info, t)
            if not _inside(uv, 2.0 * radius_px + 1.0, seq.heatmaps.shape[1:]):
                continue
            centroid, _ = _centroid(seq.heatmaps[t])
            assert np.linalg.norm(centroid - uv) < 1.0, (seed, t)
            checked += 1
    assert checked > 20


def test_latency_shows_an_earlier_world():
    seq, info = _clean("standard", 0, 80, latency_steps=2, blob_shape="gaussian")
    moving = [t for t in np.flatnonzero(info["visible"]) if t >= 2
              and np.linalg.norm(seq.ground_truth[t] - seq.ground_truth[t - 2]) > 0.1]
    assert moving
    for t in moving:
        assert info["render_step"][t] == t - 2
        uv, _ = _ball_uv(seq, info, t)
        now, _ = hp.camera.project_points(np.r_[seq.ground_truth[t], float(seq.ball_radius)][None], seq.intrinsics,
                                   info["true_cam_to_base"][t])
        centroid, _ = _centroid(seq.heatmaps[t])
        assert np.linalg.norm(centroid - uv) < 1.0
        assert np.linalg.norm(centroid - np.asarray(now)[0]) > np.linalg.norm(centroid - uv)


def test_lofted_ball_is_drawn_at_its_3d_place_and_larger_than_on_the_ground():
    # Wide blobs, so that no blob is as thin as the renderer's floor (0.7 px) and sizes can be compared.
    seq, info = _clean("lofted", 0, 200, blob_shape="gaussian", softness=0.9, size_scale=1.2)
    f = info["factors"]
    det = DetectorFactors(**{name: f[name] for name in DetectorFactors._fields})
    assert info["in_air"].any() and 0.2 < info["ball_height"].max() <= 1.4
    np.testing.assert_array_equal(info["in_air"], info["ball_height"] > 0)
    checked = 0
    for t in np.flatnonzero(info["visible"]):
        s = info["render_step"][t]
        if not 0.1 < info["ball_height"][s] < 0.9:
            continue
        uv, radius_px = _ball_uv(seq, info, t)
        if not _inside(uv, 2.0 * radius_px + 1.0, seq.heatmaps.shape[1:]):
            continue
        centroid, _ = _centroid(seq.heatmaps[t])
        assert np.linalg.norm(centroid - uv) < 1.0
        # Balls on the ground drawn by the same detector with the same camera: the one at the ground point is
        # lower in the image (and smaller where the flying ball is nearer the camera); the one on the same ray
        # (where a filter would put the blob) is farther away and smaller.
        radius, cam = float(seq.ball_radius), info["true_cam_to_base"][s]
        ground = np.r_[seq.ground_truth[s], radius]
        air = ground + np.array([0.0, 0.0, info["ball_height"][s]])
        shape, peak = seq.heatmaps.shape[1:], float(info["ball_peak"][t])

        def draw(centre):
            return render_frame(np.random.default_rng(0), [SceneObject(centre, radius, peak)], seq.intrinsics, cam,
                                shape, det)

        at_ground = draw(ground)
        assert centroid[1] < _centroid(at_ground)[0][1] - 1.0
        if np.linalg.norm(air - cam[:3, 3]) < 0.95 * np.linalg.norm(ground - cam[:3, 3]):
            assert seq.heatmaps[t].sum() > at_ground.sum()  # the blob's mass grows with its area
        ray_xy, ok = hp.camera.project_pixel(uv, seq.intrinsics, cam, radius)
        if bool(ok):  # (a ball above the camera is seen above the horizon: no ray meets the ground)
            along_ray = draw(np.r_[np.asarray(ray_xy, np.float64), radius])
            assert np.linalg.norm(_centroid(along_ray)[0] - centroid) < 1.0
            assert seq.heatmaps[t].sum() > along_ray.sum()
            checked += 1
    assert checked >= 3


def test_kicked_hidden_hides_the_ball_exactly_in_its_windows_with_distractors_on():
    for seed, count in ((0, 2), (1, 1)):
        seq, info = _clean("kicked_hidden", seed, 100, distractors=count, blob_shape="gaussian")
        windows = info["hidden_kicks"]
        np.testing.assert_array_equal(info["hidden"], [(w.start, w.stop) for w in windows])
        assert windows and info["distractor_world"].shape == (count * len(windows), 2)
        hidden = np.zeros(100, bool)
        for w in windows:
            hidden[w.start : w.stop] = True
        s = info["render_step"]
        frames = seq.has_heatmap & info["in_view"]
        np.testing.assert_array_equal(info["visible"][frames], ~hidden[s][frames])
        np.testing.assert_array_equal(info["occluded"], hidden[s])
        for t in np.flatnonzero(frames & ~hidden[s]):
            uv, _ = _ball_uv(seq, info, t)
            u, v = np.clip(np.round(uv).astype(int), 0, np.array(seq.heatmaps.shape[:0:-1]) - 1)
            assert seq.heatmaps[t, v, u] > 0.3
        on = info["distractor_on"]
        for w_index, w in enumerate(windows):
            cols = np.arange(count) + count * w_index
            np.testing.assert_array_equal(on[:, cols].any(axis=1), on[:, cols].all(axis=1))
            expect = (np.arange(100) >= w.start) & (np.arange(100) < w.after)
            for c in cols:
                np.testing.assert_array_equal(on[:, c], expect)
        # The heat maps show each distractor exactly where it is on (the ball far from it).
        for m, place in enumerate(info["distractor_world"]):
            uv, _ = hp.camera.project_points(np.r_[place, float(seq.ball_radius)][None], seq.intrinsics,
                                      info["true_cam_to_base"][0])
            u, v = np.round(np.asarray(uv)[0]).astype(int)
            for t in np.flatnonzero(seq.has_heatmap):
                if np.linalg.norm(seq.ground_truth[s[t]] - place) < 0.4:
                    continue
                assert (seq.heatmaps[t, v, u] > 0.3) == on[s[t], m], (seed, m, t)
        # Without distractors: the same ball, the same windows.
        bare, bare_info = _clean("kicked_hidden", seed, 100, distractors=0, blob_shape="gaussian")
        np.testing.assert_array_equal(bare.ground_truth, seq.ground_truth)
        assert bare_info["hidden_kicks"] == windows and bare_info["distractor_world"].shape == (0, 2)


def test_occlusion_and_split_members_do_what_they_say():
    seq, info = _sim("occlusion", 0, 300, 10)
    assert len(info["hidden"]) and info["occluded"].any()
    assert not info["visible"][info["occluded"]].any()
    f = info["factors"]
    for start, stop in info["hidden"]:
        assert 0.5 - 1e-9 <= (stop - start) * 0.1 <= f["hide_seconds_max"] + 0.05
    seq, info = _sim("split", 0, 300, 10)
    share = info["split"][info["visible"]].mean()
    assert abs(share - info["factors"]["split_rate"]) < 0.25
    assert (np.linalg.norm(seq.ground_truth, axis=1) <= 1.3 + 1e-9).all()


def test_far_member_keeps_the_ball_far():
    seq, _ = _sim("far", 0, 300, 10)
    dist = np.linalg.norm(seq.ground_truth, axis=1)
    assert dist.min() >= 4.0 - 0.1 and dist.max() <= 7.0 + 1e-9


@pytest.mark.parametrize("pattern", ["regular", "jittered", "bursty"])
def test_heat_map_timing(pattern):
    seq, info = _sim("standard", 0, 300, 25, rate_pattern=pattern, drop_rate=0.3, drop_burst_steps=6.0)
    has = seq.has_heatmap
    assert abs((~has).mean() - 0.3) < 0.12
    gaps = np.diff(np.flatnonzero(has))
    if pattern == "jittered":
        assert gaps.max() <= 3
    if pattern == "bursty":
        assert gaps.max() >= 5
    sparse, sparse_info = _sim("sparse_rate", 0, 300, 25)
    assert abs((~sparse.has_heatmap).mean() - sparse_info["factors"]["drop_rate"]) < 0.15


def test_walking_robot_sways_at_the_step_frequency_and_its_odometry_is_noisy():
    seq, info = _sim("walking", 0, 300, 25)
    f = info["factors"]
    assert np.linalg.norm(info["robot_pose"][-1, :2]) > 0.2
    z = info["true_cam_to_base"][:, 2, 3] - f["camera_height_m"]
    np.testing.assert_allclose(np.abs(z).max(), f["gait_height_m"], rtol=0.1)
    spectrum = np.abs(np.fft.rfft(z))
    freqs = np.fft.rfftfreq(300, 0.1)
    assert abs(freqs[np.argmax(spectrum)] - f["gait_frequency_hz"]) <= 1.0 / 30.0
    # Multiplicative noise of std odometry_noise plus an additive 1 mm, 1 mm, 2 mrad: normalised residuals of std 1.
    true, given = info["true_odometry"][1:], seq.odometry[1:]
    scale = np.sqrt((f["odometry_noise"] * true) ** 2 + np.array([0.001, 0.001, 0.002]) ** 2)
    assert 0.8 < ((given - true) / scale).std() < 1.2
