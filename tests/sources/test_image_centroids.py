"""Each pixel's blob centre: the window mean shift against a NumPy brute force, and what it is for."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
import heatpf_jax.sim.render
from heatpf_jax.sim import scaled_camera
from heatpf_jax.sim.render import blob
from heatpf_jax.sources.image_centroids import ball_radius_px, blob_centres, summed_area

INTRINSICS, SHAPE = scaled_camera(2)  # 100 x 75
CAM = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
RADIUS = 0.075
# Through `jit`: run eagerly, each of their operations compiles a program of its own (per shape).
_summed_area = jax.jit(summed_area)
_ball_radius_px = jax.jit(ball_radius_px)
_blob_centres = jax.jit(blob_centres, static_argnames="iterations")
_project_pixel = jax.jit(hp.camera.project_pixel)  # one program for every pixel


def _centres(heat, start, **kwargs):
    """:func:`blob_centres` of ``start`` padded with copies of its first pixel to a multiple of 256, the padding
    cut off again: each pixel's mean shift is its own, and the calls with the same ``iterations`` share one program
    (about 0.7 s to compile, where each start count would compile its own)."""
    m = len(start)
    padded = np.concatenate([start, np.repeat(start[:1], -m % 256, axis=0)])
    return jax.tree.map(lambda x: np.asarray(x)[:m], _blob_centres(heat, padded, INTRINSICS, CAM, **kwargs))


def _radius_np(u: float, v: float) -> float:
    fx, fy, cx, cy = INTRINSICS
    ray = CAM[:3, :3] @ np.array([(u - cx) / fx, (v - cy) / fy, 1.0])
    if abs(ray[2]) < 1e-9:
        return 0.0
    depth = (RADIUS - CAM[2, 3]) / ray[2]
    return fx * RADIUS / depth if depth > 0 else 0.0


def _mean_shift_np(heat, start, threshold, reach, iterations):
    """The same windows, summed pixel by pixel in float64."""
    h, w = heat.shape
    mass = np.where(heat >= threshold, heat.astype(np.float64), 0.0)
    out = []
    for u, v in start:
        for i in range(iterations + 1):
            half = max(np.round(reach * _radius_np(u, v)), 1.0)
            u0, u1 = (int(np.clip(np.round(x), 0, w - 1)) for x in (u - half, u + half))
            v0, v1 = (int(np.clip(np.round(x), 0, h - 1)) for x in (v - half, v + half))
            win = mass[v0 : v1 + 1, u0 : u1 + 1]
            if i == iterations:
                count = np.sum(heat[v0 : v1 + 1, u0 : u1 + 1] >= threshold)
                b0, b1 = (int(np.clip(np.round(x), 0, w - 1)) for x in (u - 2 * half, u + 2 * half))
                c0, c1 = (int(np.clip(np.round(x), 0, h - 1)) for x in (v - 2 * half, v + 2 * half))
                around = np.sum(heat[c0 : c1 + 1, b0 : b1 + 1] >= threshold)
                out.append((u, v, win.sum(), count / win.size, around / count if count else 1.0))
                break
            if win.sum() > 0:
                vv, uu = np.mgrid[v0 : v1 + 1, u0 : u1 + 1]
                u, v = (win * uu).sum() / win.sum(), (win * vv).sum() / win.sum()
    return np.array(out)


def test_summed_area_boxes(rng):
    table = rng.uniform(size=(7, 9)).astype(np.float32)
    s = np.asarray(_summed_area(table))
    assert s.shape == (8, 10) and np.all(s[0] == 0) and np.all(s[:, 0] == 0)
    np.testing.assert_allclose(s[5, 7] - s[2, 7] - s[5, 3] + s[2, 3], table[2:5, 3:7].sum(), rtol=1e-5)


def test_ball_radius_is_f_r_over_depth():
    uv = np.array([[50.0, 60.0], [10.0, 40.0], [50.0, 2.0]])
    got = np.asarray(_ball_radius_px(uv, INTRINSICS, CAM, RADIUS))
    np.testing.assert_allclose(got, [_radius_np(*p) for p in uv], rtol=1e-5)


@pytest.mark.parametrize("reach, iterations", [(1.5, 3), (1.0, 1), (2.5, 2)])
def test_mean_shift_against_brute_force(rng, reach, iterations):
    heat = np.zeros(SHAPE)
    for x, y, peak in ((1.2, 0.1, 0.9), (2.5, -0.6, 0.7), (1.25, 0.35, 0.8)):
        heat = np.maximum(heat, blob(np.array([x, y, RADIUS]), RADIUS, INTRINSICS, CAM, SHAPE, peak))
    heat = np.clip(heat + 0.04 * rng.standard_normal(SHAPE), 0, 1).astype(np.float32)
    v, u = np.nonzero(heat >= 0.3)
    start = np.stack([u, v], axis=1).astype(np.float32)
    got = _centres(heat, start, threshold=0.3, plane_height=RADIUS, reach=reach, iterations=iterations)
    want = _mean_shift_np(heat, start, 0.3, reach, iterations)
    # Window bounds are rounded: a float32 centroid at x.5 may round the other way than float64 does.
    close = np.all(np.abs(np.asarray(got.uv) - want[:, :2]) < 1e-3, axis=1)
    assert close.mean() > 0.97
    np.testing.assert_allclose(np.asarray(got.mass)[close], want[close, 2], rtol=1e-4)
    np.testing.assert_allclose(np.asarray(got.fill)[close], want[close, 3], atol=1e-6)
    np.testing.assert_allclose(np.asarray(got.spill)[close], want[close, 4], rtol=1e-4)


def test_every_pixel_of_a_blob_ends_at_its_centre_and_projects_onto_the_ball(rng):
    """A ball 3.5 m away: its pixels span rows whose ground points lie 0.6 m apart along the ray; their blob
    centres all project within a few centimetres of the ball, a far false positive keeps its own."""
    ball, fp = np.array([3.5, 0.4, RADIUS]), np.array([2.0, -1.0, RADIUS])
    heat = np.maximum(blob(ball, RADIUS, INTRINSICS, CAM, SHAPE, 0.9), blob(fp, RADIUS, INTRINSICS, CAM, SHAPE, 0.6))
    heat = np.clip(heat + 0.02 * rng.standard_normal(SHAPE), 0, 1).astype(np.float32)
    v, u = np.nonzero(heat >= 0.3)
    start = np.stack([u, v], axis=1).astype(np.float32)
    got = _centres(heat, start, threshold=0.3, plane_height=RADIUS)
    raw = np.array([_project_pixel(p, INTRINSICS, CAM, RADIUS)[0] for p in start])
    moved = np.array([_project_pixel(p, INTRINSICS, CAM, RADIUS)[0] for p in np.asarray(got.uv)])
    near_ball = np.linalg.norm(raw - ball[:2], axis=1) < 1.0
    assert near_ball.sum() >= 4 and (~near_ball).sum() >= 4
    assert np.ptp(raw[near_ball, 0]) > 0.4  # the pixels' own ground points spread along the ray
    assert np.abs(moved[near_ball] - ball[:2]).max() < 0.06
    assert np.abs(moved[~near_ball] - fp[:2]).max() < 0.06


def _disc(centre, radius, peak):
    u0, v0, depth = hp.sim.render.project_centre(centre, INTRINSICS, CAM)
    vv, uu = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    return peak * np.clip(INTRINSICS[0] * radius / depth + 0.5 - np.hypot(uu - u0, vv - v0), 0, 1)


@pytest.mark.parametrize("shape", ["gaussian", "disc"])
def test_a_ball_in_the_air_spills_out_of_its_window_and_a_ground_ball_does_not(shape):
    """A ball 0.35 m up, 2.5 m away, projects onto the ground 4.2 m away, where a ground ball would look
    0.6 times as large: its blob spills out of the window sized for that ground ball (by 1.3-1.5 here). The
    ground ball's blob, Gaussian or a saturated disc, stays inside its own."""
    render = (lambda c: blob(c, RADIUS, INTRINSICS, CAM, SHAPE, 0.9)) if shape == "gaussian" else (
        lambda c: _disc(c, RADIUS, 0.95))
    spills = {}
    for name, centre in (("ground", np.array([2.5, 0.3, RADIUS])), ("air", np.array([2.5, 0.3, RADIUS + 0.35]))):
        heat = render(centre).astype(np.float32)
        v, u = np.nonzero(heat >= 0.3)
        got = _centres(heat, np.stack([u, v], 1).astype(np.float32), threshold=0.3, plane_height=RADIUS)
        spills[name] = np.asarray(got.spill)
    assert np.all(spills["ground"] <= 1.05) and np.median(spills["air"]) > 1.3
