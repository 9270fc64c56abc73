"""LoftedSource: a ball in the air is measured at the ground point under it (NumPy brute-force references)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.pieces import StepInputs
from heatpf_jax.sources.image_centroids import summed_area, summed_areas
from heatpf_jax.sources.lofted import (
    LoftedParams,
    LoftedSource,
    _box_max,
    air_points,
    blob_sizes,
    bright_pixels,
    subpixel_peaks,
)

INTRINSICS = np.array([143.0, 143.0, 99.5, 74.5])
SHAPE = (150, 200)
RADIUS = 0.075
SOURCE = LoftedSource(max_measurements=256)
MEASURE = jax.jit(SOURCE.measure)  # one compilation for every test here
# The paper's source and the functions tested directly, one program each: run eagerly, each of their operations
# would compile on its own.
PAPER = jax.jit(hp.sources.PixelSource(max_measurements=256).measure)
BLOB_SIZES = jax.jit(blob_sizes)
BLOB_ELONGATION = jax.jit(hp.sources.blob_elongation)
BRIGHT_PIXELS = jax.jit(bright_pixels, static_argnames="max_measurements")
AIR_POINTS = jax.jit(air_points)
SUBPIXEL_PEAKS = jax.jit(subpixel_peaks)
SUMMED_AREAS = jax.jit(summed_areas)
SUMMED_AREA = jax.jit(summed_area)
BOX_MAX = jax.jit(_box_max, static_argnums=1)


def _pose(height: float, pitch_deg: float, yaw: float = 0.0) -> np.ndarray:
    """Camera pose (NumPy): optical z forward along the pitched heading, x right, y down."""
    p, y = np.deg2rad(pitch_deg), yaw
    forward = np.array([np.cos(p) * np.cos(y), np.cos(p) * np.sin(y), -np.sin(p)])
    right = np.array([np.sin(y), -np.cos(y), 0.0])
    down = np.cross(forward, right)
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, down, forward], axis=1)
    pose[:3, 3] = (0.0, 0.0, height)
    return pose


def _sphere_heatmap(
    rng, centre: np.ndarray, pose: np.ndarray, peak: float = 0.9, noise: float = 0.02, scale: float = 0.6
) -> np.ndarray:
    """A detector's blob of a sphere, by brute force: the pixels whose rays pass within R of the centre (its exact
    silhouette), then a Gaussian of std ``scale`` (0.6) times the silhouette's equivalent radius at the silhouette's
    centroid."""
    h, w = SHAPE
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    rays = np.stack([(uu - INTRINSICS[2]) / INTRINSICS[0], (vv - INTRINSICS[3]) / INTRINSICS[1], np.ones_like(uu)], -1)
    rays = rays @ pose[:3, :3].T
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    to_c = centre - pose[:3, 3]
    along = rays @ to_c
    miss = np.linalg.norm(to_c[None, None] - along[..., None] * rays, axis=-1)
    inside = (miss <= RADIUS) & (along > 0)
    assert inside.sum() >= 4, "the sphere must be in view"
    u0, v0 = uu[inside].mean(), vv[inside].mean()
    rho = np.sqrt(inside.sum() / np.pi)
    act = peak * np.exp(-0.5 * ((uu - u0) ** 2 + (vv - v0) ** 2) / (scale * rho) ** 2)
    return np.clip(act + noise * rng.standard_normal(SHAPE), 0.0, 1.0).astype(np.float32)


def _inputs(heat: np.ndarray, pose: np.ndarray) -> StepInputs:
    # NumPy arrays, for the jitted functions: jnp's conversions would each compile a program of their own.
    return StepInputs(
        heatmap=np.asarray(heat), has_heatmap=np.asarray(True), cam_to_base=np.asarray(pose, np.float32),
        odometry=np.zeros(3, np.float32), intrinsics=np.asarray(INTRINSICS, np.float32),
        plane_height=np.asarray(RADIUS, np.float32), dt=np.asarray(0.1, np.float32),
    )


def _weighted_xy(m) -> np.ndarray:
    valid = np.asarray(m.valid)
    w = np.asarray(m.weight)[valid]
    return (np.asarray(m.xy)[valid] * w[:, None]).sum(0) / w.sum()


@pytest.mark.parametrize(
    ("ground", "height"),
    [((2.3, 0.4), 0.35), ((3.4, -0.6), 0.6), ((2.8, 0.2), 1.0)],
)
def test_ball_in_the_air_is_measured_under_it(ground, height):
    """A sphere at a known height: every measurement near the ground point under it, where the ground projection
    of its blob lies metres behind (or nowhere, above the horizon)."""
    rng = np.random.default_rng([int(height * 100), 7])
    pose = _pose(0.6, 12.0 + 3.0 * rng.uniform(), yaw=0.05 * rng.standard_normal())
    centre = np.array([*ground, height + RADIUS])
    heat = _sphere_heatmap(rng, centre, pose)
    m = MEASURE(_inputs(heat, pose), SOURCE.default_params())
    assert int(np.asarray(m.valid).sum()) >= 4
    # The ground point under the ball, within 8 % of its range (the size gives the range to a few per cent).
    truth = np.asarray(ground)
    assert np.linalg.norm(_weighted_xy(m) - truth) < 0.08 * np.linalg.norm(truth)
    paper = PAPER(_inputs(heat, pose), hp.sources.SourceParams())
    if np.any(np.asarray(paper.valid)):  # below the horizon: the paper's projection lies far behind the ball
        assert np.linalg.norm(_weighted_xy(paper) - truth) > 0.3


def test_ball_above_the_horizon_is_measured():
    rng = np.random.default_rng(3)
    pose = _pose(0.5, 12.0)
    ground = np.array([3.0, 0.3])
    heat = _sphere_heatmap(rng, np.array([*ground, 0.9]), pose)  # centre 0.4 m above the camera
    paper = PAPER(_inputs(heat, pose), hp.sources.SourceParams())
    assert not np.any(np.asarray(paper.valid))  # no ray of the blob meets the ground
    m = MEASURE(_inputs(heat, pose), SOURCE.default_params())
    # Within 10 % of the range: the sphere's outline, 20 degrees off the optical axis, is an ellipse 6 % longer
    # than the round blob of f R / depth that blob_scale describes, so its size puts the ball a little nearer.
    assert np.linalg.norm(_weighted_xy(m) - ground) < 0.1 * np.linalg.norm(ground)
    # A finite max_ratio refuses a blob above the horizon (its ratio to a ground ball is infinite).
    assert not np.any(np.asarray(MEASURE(_inputs(heat, pose), LoftedParams(max_ratio=50.0)).valid))


def test_ball_on_the_ground_gives_the_papers_measurements():
    """Below ``min_ratio`` nothing changes: a ground ball's pixels are the paper's, exactly."""
    rng = np.random.default_rng(11)
    pose = _pose(0.55, 30.0, yaw=0.3)
    for ground in ((1.6, 0.3), (3.5, 1.0)):
        heat = _sphere_heatmap(rng, np.array([*ground, RADIUS]), pose)
        inputs = _inputs(heat, pose)
        m = MEASURE(inputs, SOURCE.default_params())
        paper = PAPER(inputs, hp.sources.SourceParams())
        for field in ("xy", "weight", "valid", "footprint"):
            np.testing.assert_allclose(np.asarray(getattr(m, field)), np.asarray(getattr(paper, field)), atol=1e-5)
        assert np.linalg.norm(_weighted_xy(m) - np.asarray(ground)) < 0.05 * np.linalg.norm(ground)
    # min_ratio = inf never places a blob by its size: a ball in the air then projects behind it, as the paper's
    # (the same measurements; the slots differ where a pixel's ray meets the ground beyond max_distance).
    heat = _sphere_heatmap(rng, np.array([2.5, 0.0, 0.5]), _pose(0.6, 15.0))
    inputs = _inputs(heat, _pose(0.6, 15.0))
    never = MEASURE(inputs, LoftedParams(min_ratio=float("inf")))
    paper = PAPER(inputs, hp.sources.SourceParams())
    valid_rows = lambda m: np.sort(np.asarray(m.xy)[np.asarray(m.valid)], axis=0)  # noqa: E731
    assert int(np.asarray(never.valid).sum()) == int(np.asarray(paper.valid).sum()) > 0
    np.testing.assert_allclose(valid_rows(never), valid_rows(paper), atol=1e-5)
    # max_ratio = min_ratio refuses the ball in the air: no measurement, instead of one metres behind it.
    placed = MEASURE(inputs, LoftedParams())
    refused = MEASURE(inputs, LoftedParams(max_ratio=1.5))
    assert np.any(np.asarray(placed.valid)) and not np.any(np.asarray(refused.valid))


def test_blob_sizes_recovers_a_gaussian_std():
    """The mass over the threshold gives the std of a Gaussian blob whatever its peak (NumPy-drawn blobs)."""
    rng = np.random.default_rng(5)
    h, w = SHAPE
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    pose = _pose(0.6, 30.0)
    for std, peak in ((1.5, 0.9), (3.0, 0.6), (5.0, 1.0)):
        u0, v0 = rng.uniform(60, 140), rng.uniform(40, 110)
        heat = (peak * np.exp(-0.5 * ((uu - u0) ** 2 + (vv - v0) ** 2) / std**2)).astype(np.float32)
        start = np.array([[round(u0) + 1.0, round(v0)]], np.float32)
        out = BLOB_SIZES(heat, start, INTRINSICS, pose, threshold=0.3, plane_height=RADIUS)
        np.testing.assert_allclose(np.asarray(out.uv)[0], [u0, v0], atol=0.1)
        assert float(np.asarray(out.std_px)[0]) == pytest.approx(std, rel=0.1)


def test_fast_tables_match_brute_force():
    """The blocked summed-area tables and the shifted-maxima local peak against NumPy (float64 sums, a loop max)."""
    rng = np.random.default_rng(13)
    tables = rng.uniform(0.0, 1.0, (3, 37, 53)).astype(np.float32) * (rng.uniform(size=(3, 37, 53)) > 0.5)
    expected = np.pad(tables.astype(np.float64).cumsum(1).cumsum(2), ((0, 0), (1, 0), (1, 0)))
    np.testing.assert_allclose(np.asarray(SUMMED_AREAS(tables)), expected, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(np.asarray(SUMMED_AREAS(tables))[1], np.asarray(SUMMED_AREA(tables[1])), rtol=1e-5,
                               atol=1e-4)
    heat = tables[0]
    padded = np.pad(heat, 3, constant_values=-np.inf)
    brute = np.array([[padded[i:i + 7, j:j + 7].max() for j in range(heat.shape[1])] for i in range(heat.shape[0])])
    np.testing.assert_array_equal(np.asarray(BOX_MAX(heat, 3)), brute)


def test_air_points_inverts_the_projection():
    """A point at depth d seen with radius f R / d is found again (NumPy projection)."""
    rng = np.random.default_rng(9)
    pose = _pose(0.6, 20.0, yaw=-0.4)
    points = np.stack([rng.uniform(1.0, 5.0, 8), rng.uniform(-1.0, 1.0, 8), rng.uniform(0.1, 1.5, 8)], -1)
    cam = (points - pose[:3, 3]) @ pose[:3, :3]
    uv = np.stack([INTRINSICS[0] * cam[:, 0] / cam[:, 2] + INTRINSICS[2],
                   INTRINSICS[1] * cam[:, 1] / cam[:, 2] + INTRINSICS[3]], -1)
    found, ok = AIR_POINTS(uv.astype(np.float32), (INTRINSICS[0] * RADIUS / cam[:, 2]).astype(np.float32),
                           INTRINSICS, pose, RADIUS)
    assert np.all(np.asarray(ok))
    np.testing.assert_allclose(np.asarray(found), points, atol=2e-4)
    assert not np.any(np.asarray(AIR_POINTS(uv[:2].astype(np.float32), np.zeros(2, np.float32), INTRINSICS, pose,
                                            RADIUS)[1]))


def test_lofted_source_as_a_filter_option():
    lofted = hp.build("heatmap", hp.FilterOptions(source="lofted"))
    assert lofted.model == hp.build("heatmap").model._replace(source=LoftedSource())
    assert lofted.params.source == LoftedParams()
    with pytest.raises(ValueError, match="^iterations:"):
        LoftedSource(iterations=0).validate()


@pytest.mark.parametrize(("a", "b", "angle"), [(4.0, 2.0, 0.5), (3.0, 3.0, 0.0), (6.0, 2.5, -1.1)])
def test_blob_elongation_is_the_ratio_of_a_gaussians_stds(a, b, angle):
    """An anisotropic Gaussian blob (stds a >= b, rotated) cut at the threshold: the elongation is a / b."""
    h, w = SHAPE
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    c, s = np.cos(angle), np.sin(angle)
    du, dv = uu - 97.3, vv - 71.8
    x, y = c * du + s * dv, -s * du + c * dv
    heat = (0.9 * np.exp(-0.5 * (x**2 / a**2 + y**2 / b**2))).astype(np.float32)
    uv = np.array([[97.3, 71.8]], np.float32)
    span = np.array([2.5 * np.sqrt(a * b)], np.float32)  # as LoftedSource spans it: 2.5 mass-based stds
    got = float(np.asarray(BLOB_ELONGATION(heat, uv, span, threshold=0.3))[0])
    assert got == pytest.approx(a / b, rel=0.04)


def test_two_ground_blobs_side_by_side_are_not_one_ball_in_the_air():
    """A ball and a ball-sized thing 0.45 m behind it along the ray overlap in the image: their mass and spread read as
    one blob too large for a ground ball, but a sphere's blob is round, and its minor std is a ground ball's: both are
    measured where they project, as the paper's source measures them."""
    rng = np.random.default_rng(2)
    pose = _pose(0.6, 30.0)
    heat = np.maximum(_sphere_heatmap(rng, np.array([2.5, 0.2, RADIUS]), pose),
                      _sphere_heatmap(rng, np.array([2.05, 0.02, RADIUS]), pose))
    inputs = _inputs(heat, pose)
    lofted = LoftedSource(max_measurements=256, calibration_frames=0, hover_frames=0)
    paper = PAPER(inputs, hp.sources.SourceParams())
    blobs = BLOB_SIZES(heat, *BRIGHT_PIXELS(heat, threshold=0.3, max_measurements=256)[:1], INTRINSICS, pose,
                       threshold=0.3, plane_height=RADIUS)
    assert float(np.max(np.asarray(blobs.std_px) / np.asarray(blobs.ground_radius_px))) > 0.6 * 1.25  # by mass: flying
    np.testing.assert_allclose(np.asarray(jax.jit(lofted.measure)(inputs, LoftedParams()).xy), np.asarray(paper.xy),
                               atol=1e-5)


def test_subpixel_peaks_restore_a_gaussians_peak():
    """A Gaussian blob whose centre falls between pixels: its largest pixel is below the peak (by up to
    ``exp(-1 / 4 s^2)``); the refined maximum is the peak. A speck, a saturated plateau and every pixel that is no
    local maximum keep their activations."""
    rng = np.random.default_rng(9)
    vv, uu = np.mgrid[0:31, 0:31].astype(np.float64)
    for _ in range(12):
        s, peak = rng.uniform(1.0, 3.0), rng.uniform(0.4, 1.0)
        cu, cv = 15.0 + rng.uniform(-0.5, 0.5, 2)
        heat = peak * np.exp(-((uu - cu) ** 2 + (vv - cv) ** 2) / (2.0 * s * s))
        refined = np.asarray(SUBPIXEL_PEAKS(heat.astype(np.float32)))
        assert refined.max() == pytest.approx(peak, rel=2e-3)
        assert np.all(refined >= heat.astype(np.float32))
        changed = refined != heat.astype(np.float32)
        assert changed.sum() <= 4 and np.all(heat[changed] >= 0.5 * heat.max())  # only the top pixels
    speck = np.zeros((9, 9), np.float32)
    speck[4, 4] = 0.9
    np.testing.assert_array_equal(np.asarray(SUBPIXEL_PEAKS(speck)), speck)
    plateau = np.clip(3.0 * np.exp(-((uu - 15.3) ** 2 + (vv - 14.8) ** 2) / 18.0), 0.0, 1.0).astype(np.float32)
    assert float(np.asarray(SUBPIXEL_PEAKS(plateau)).max()) == 1.0
