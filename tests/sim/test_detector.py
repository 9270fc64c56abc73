"""The randomised detector: the sphere's outline, blob placement, smoothing, background, factor draws.

References: the outline against the projection (``hp.camera.project_points``) of the sphere's circle of tangency,
built in 3D; the blob's place against ``hp.camera.project_points`` of the centre; smoothing against
``scipy.ndimage.gaussian_filter``; the clutter's correlation against the Gaussian kernel's
autocorrelation ``exp(-d^2 / (4 sigma^2))``.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.ndimage as ndi

import heatpf_jax as hp
from heatpf_jax.sim.detector import (
    DETECTOR_RANGES,
    DetectorFactors,
    Occluder,
    SceneObject,
    clutter_field,
    draw_detector,
    object_blob,
    render_frame,
    smooth,
    sphere_outline,
)
from heatpf_jax.sim.render import blob

INTRINSICS = np.array([143.0, 143.0, 99.5, 74.5])
SHAPE = (150, 200)
CLEAN = DetectorFactors(noise=0.0, peak=1.0)


def _camera(rng: np.random.Generator) -> np.ndarray:
    return hp.camera.camera_pose(height=rng.uniform(0.45, 0.75), pitch=np.deg2rad(rng.uniform(15.0, 40.0)),
                          roll=np.deg2rad(rng.uniform(-3.0, 3.0)))


def _ball_in_view(rng, cam, radius: float, max_height: float = 0.0) -> np.ndarray:
    """A sphere centre (up to ``max_height`` above the ground) whose projection lies well inside the image."""
    for _ in range(1000):
        centre = np.array([rng.uniform(0.6, 5.0), rng.uniform(-2.5, 2.5), radius + rng.uniform(0.0, max_height)])
        uv, depth = hp.camera.project_points(centre[None], INTRINSICS, cam)
        u, v = np.asarray(uv)[0]
        if float(depth[0]) > 0.3 and 15 <= u <= SHAPE[1] - 16 and 15 <= v <= SHAPE[0] - 16:
            return centre
    raise AssertionError("no place in view")


def _tangent_circle(centre: np.ndarray, radius: float, eye: np.ndarray, n: int = 64) -> np.ndarray:
    """Points ``[n, 3]`` where rays from ``eye`` touch the sphere (its silhouette), built in 3D."""
    axis = centre - eye
    dist = np.linalg.norm(axis)
    axis /= dist
    # The circle of tangency: centre at eye + axis (dist - r^2 / dist), radius r sqrt(1 - r^2 / dist^2).
    mid = eye + axis * (dist - radius**2 / dist)
    rad = radius * np.sqrt(1.0 - radius**2 / dist**2)
    a = np.cross(axis, [0.0, 0.0, 1.0])
    a /= np.linalg.norm(a)
    b = np.cross(axis, a)
    phi = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return mid + rad * (np.cos(phi)[:, None] * a + np.sin(phi)[:, None] * b)


@pytest.mark.parametrize("radius", [0.075, 0.3])
def test_outline_is_the_projected_silhouette(radius):
    rng = np.random.default_rng(1)
    for _ in range(10):
        cam = _camera(rng)
        centre = _ball_in_view(rng, cam, radius)
        c, s = sphere_outline(centre, radius, INTRINSICS, cam)
        uv, _ = hp.camera.project_points(_tangent_circle(centre, radius, cam[:3, 3]), INTRINSICS, cam)
        d = np.asarray(uv, np.float64) - c
        np.testing.assert_allclose(np.einsum("ni,ij,nj->n", d, s, d), 1.0, atol=2e-4)


def test_outline_is_elongated_radially_by_the_off_axis_angle():
    """Semi-axes ``f sin a cos a / (cos^2 t - sin^2 a)`` (radial) and ``f sin a / sqrt(cos^2 t - sin^2 a)``."""
    rng = np.random.default_rng(2)
    for _ in range(10):
        cam = _camera(rng)
        centre = _ball_in_view(rng, cam, 0.2)
        c, s = sphere_outline(centre, 0.2, INTRINSICS, cam)
        c_cam = cam[:3, :3].T @ (centre - cam[:3, 3])
        dist = np.linalg.norm(c_cam)
        alpha, theta = np.arcsin(0.2 / dist), np.arccos(c_cam[2] / dist)
        den = np.cos(theta) ** 2 - np.sin(alpha) ** 2
        eig, vec = np.linalg.eigh(s)
        semi = 1.0 / np.sqrt(eig)  # ascending eigenvalues: the major axis first
        f = INTRINSICS[0]
        np.testing.assert_allclose(semi[0], f * np.sin(alpha) * np.cos(alpha) / den, rtol=1e-6)
        np.testing.assert_allclose(semi[1], f * np.sin(alpha) / np.sqrt(den), rtol=1e-6)
        radial = c - INTRINSICS[2:]
        if np.linalg.norm(radial) > 20:  # the major axis points away from the principal point
            cosine = abs(vec[:, 0] @ radial) / np.linalg.norm(radial)
            assert cosine > 0.999


@pytest.mark.parametrize("shape_name", ["gaussian", "disc"])
def test_blob_lies_where_the_centre_projects(shape_name):
    rng = np.random.default_rng(3)
    for _ in range(8):
        cam = _camera(rng)
        centre = _ball_in_view(rng, cam, 0.075, max_height=0.8)
        factors = CLEAN._replace(blob_shape=shape_name, softness=rng.uniform(0.35, 0.9),
                                 size_scale=rng.uniform(0.8, 1.3), saturation=rng.uniform(0.0, 4.0),
                                 blur_px=rng.uniform(0.0, 1.5))
        heat = render_frame(rng, [SceneObject(centre, 0.075, 1.0)], INTRINSICS, cam, SHAPE, factors)
        uv = np.asarray(hp.camera.project_points(centre[None], INTRINSICS, cam)[0])[0]
        vv, uu = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
        w = np.where(heat > 0.5 * heat.max(), heat, 0.0)
        centroid = np.array([(w * uu).sum(), (w * vv).sum()]) / w.sum()
        assert np.linalg.norm(centroid - uv) < 1.0  # the outline's centre lies a little outward of it
        top = np.argwhere(heat == heat.max())
        radius_px = INTRINSICS[0] * 0.075 / np.linalg.norm(centre - cam[:3, 3]) * factors.size_scale
        assert np.linalg.norm(top[:, ::-1] - uv, axis=1).min() < (1.0 if shape_name == "gaussian" else radius_px)


def test_defaults_are_the_fixed_renderer():
    """``DetectorFactors()`` without noise is ``heatpf_jax.sim.render.blob`` near the optical axis.

    (Off the axis the outline's perspective elongation makes them differ: it is what the detector adds.)
    """
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    for xy in [(1.0, 0.0), (1.2, 0.1), (0.95, -0.1)]:
        centre = np.array([*xy, 0.075])
        ours = object_blob(SceneObject(centre, 0.075, 0.9), INTRINSICS, cam, SHAPE, DetectorFactors())
        np.testing.assert_allclose(ours, blob(centre, 0.075, INTRINSICS, cam, SHAPE, 0.9), atol=0.03)


def test_disc_is_filled_and_saturation_flattens():
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    obj = SceneObject(np.array([1.0, 0.2, 0.075]), 0.075, 0.8)
    disc = object_blob(obj, INTRINSICS, cam, SHAPE, CLEAN._replace(blob_shape="disc"))
    c, s = sphere_outline(obj.centre, obj.radius, INTRINSICS, cam)
    vv, uu = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    d = np.stack([uu - c[0], vv - c[1]], -1)
    q = np.einsum("hwi,ij,hwj->hw", d, s, d)
    assert np.all(disc[q < 0.8] == 0.8) and np.all(disc[q > 1.25] == 0.0)
    linear = object_blob(obj, INTRINSICS, cam, SHAPE, CLEAN)
    flat = object_blob(obj, INTRINSICS, cam, SHAPE, CLEAN._replace(saturation=4.0))
    assert (flat > 0.9 * 0.8).sum() > 3 * (linear > 0.9 * 0.8).sum()
    assert flat.max() == pytest.approx(0.8, abs=1e-3) and linear.max() == pytest.approx(0.8, abs=0.01)


def test_occluders_hide_a_band_or_a_half():
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    centre = np.array([0.9, 0.0, 0.075])
    whole = object_blob(SceneObject(centre, 0.075, 1.0), INTRINSICS, cam, SHAPE, CLEAN)
    band = object_blob(SceneObject(centre, 0.075, 1.0, occluder=Occluder(0.0, 0.0, 0.4)), INTRINSICS, cam, SHAPE,
                       CLEAN)
    half = object_blob(SceneObject(centre, 0.075, 1.0, occluder=Occluder(0.0, 0.0, np.inf)), INTRINSICS, cam, SHAPE,
                       CLEAN)
    c, _ = sphere_outline(centre, 0.075, INTRINSICS, cam)
    col = int(round(c[0]))
    row = int(round(c[1]))
    # A vertical band through the centre: the centre column is zero, the blob's two sides remain.
    assert band[row, col] == 0.0 and band[row, col - 4] > 0.3 and band[row, col + 4] > 0.3
    # The half plane u > c_u is hidden.
    assert half[row, col + 2 :].max() == 0.0
    np.testing.assert_array_equal(half[:, : col - 1], whole[:, : col - 1])
    assert 0.4 < half.sum() / whole.sum() < 0.6


def test_objects_behind_or_at_the_camera_are_not_drawn():
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    behind = SceneObject(np.array([-1.0, 0.0, 0.075]), 0.075, 1.0)
    inside = SceneObject(cam[:3, 3] + np.array([0.05, 0.0, 0.0]), 0.075, 1.0)
    for obj in (behind, inside):
        assert sphere_outline(obj.centre, obj.radius, INTRINSICS, cam) is None
        assert not object_blob(obj, INTRINSICS, cam, SHAPE, CLEAN).any()


@pytest.mark.parametrize("sigma", [0.3, 1.2, 4.5, 17.0])
def test_smooth_equals_scipy(sigma):
    image = np.random.default_rng(4).standard_normal((37, 50))
    np.testing.assert_allclose(smooth(image, sigma), ndi.gaussian_filter(image, sigma, mode="reflect", truncate=3.0),
                               atol=1e-12)


def test_clutter_has_unit_std_and_the_kernel_correlation():
    rng = np.random.default_rng(5)
    sigma = 3.0
    fields = np.stack([clutter_field(rng, (40, 60), sigma) for _ in range(300)])
    np.testing.assert_allclose(fields.std(axis=0).mean(), 1.0, atol=0.03)
    assert np.abs(fields.std(axis=0) - 1.0).max() < 0.2  # the edges too
    mid = fields[:, 10:30, 15:45]
    for lag in (2, 4, 6):
        corr = (mid[:, :, :-lag] * mid[:, :, lag:]).mean()
        assert corr == pytest.approx(np.exp(-(lag**2) / (4 * sigma**2)), abs=0.04)


def test_frame_is_float32_in_unit_range_with_every_artefact():
    rng = np.random.default_rng(6)
    factors = DetectorFactors(blob_shape="disc", saturation=3.0, blur_px=1.2, peak=1.0, dropout=0.2, noise=0.06,
                              clutter_strength=0.3, clutter_length_px=5.0, speckle_density=0.002, speckle_peak=1.0,
                              line_rate=0.03, line_strength=0.15)
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    objects = [SceneObject(np.array([1.5, 0.0, 0.075]), 0.075, 1.0),
               SceneObject(np.array([3.0, 0.5, 0.3]), 0.3, 0.7, "false_positive")]
    heat = render_frame(rng, objects, INTRINSICS, cam, SHAPE, factors)
    assert heat.dtype == np.float32 and heat.shape == SHAPE
    assert heat.min() >= 0.0 and heat.max() <= 1.0
    quiet = render_frame(rng, [], INTRINSICS, cam, SHAPE, DetectorFactors(noise=0.0))
    assert not quiet.any()


def test_draws_cover_the_ranges():
    rng = np.random.default_rng(7)
    draws = [draw_detector(rng) for _ in range(60)]
    for name, spec in DETECTOR_RANGES.items():
        values = [getattr(d, name) for d in draws]
        if isinstance(spec[0], str):
            assert set(values) == set(spec)
        else:
            lo, hi = spec
            assert lo <= min(values) < lo + 0.15 * (hi - lo)
            assert hi - 0.15 * (hi - lo) < max(values) <= hi
    pinned = draw_detector(rng, {"peak": (0.7, 0.7), "blob_shape": ("disc",)})
    assert pinned.peak == 0.7 and pinned.blob_shape == "disc"
    with pytest.raises(ValueError, match="unknown detector factors"):
        draw_detector(rng, {"brightness": (0.0, 1.0)})
