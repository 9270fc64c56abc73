"""Colour-histogram heat maps (Olufs et al. eq. 1-3): r'g'I bins, histograms, the windowed likelihood against a
NumPy brute force, the expected ball size against OpenCV's projection, and what the map shows."""

import cv2
import jax
import numpy as np
import pytest
from scipy.ndimage import convolve1d

from heatpf_jax.camera import camera_pose
from heatpf_jax.colour.likelihood import (
    ColourParams,
    blob_half_size,
    colour_heatmaps,
    colour_likelihood,
    expected_radius_px,
)
from heatpf_jax.colour.space import (
    balance,
    channel_means,
    exact_top_bins,
    histogram,
    num_bins,
    patch_histogram,
    rgi_bins,
    smooth_chromaticity,
    smooth_intensity,
)

M = num_bins()
_likelihood = jax.jit(colour_likelihood, static_argnames=("bins", "top_bins", "blob_window"))
# One program each for the helpers run here: eager, each of their operations would compile on its own.
_histogram = jax.jit(histogram, static_argnums=1)
_patch_histogram = jax.jit(patch_histogram, static_argnums=1)
_smooth_intensity = jax.jit(smooth_intensity)
_smooth_chromaticity = jax.jit(smooth_chromaticity)
_expected_radius = jax.jit(expected_radius_px, static_argnums=3)


def _scene(rng, h=24, w=32, centre=(12, 15), radius=4.0):
    """Grass with noise, a white disc with a few dark dots, a reddish square."""
    img = np.empty((h, w, 3))
    img[:] = (45, 120, 45)
    img += rng.normal(0, 4, img.shape)
    vv, uu = np.mgrid[:h, :w]
    disc = (vv - centre[0]) ** 2 + (uu - centre[1]) ** 2 <= radius**2
    img[disc] = (230, 230, 228)
    img[disc & ((vv + uu) % 5 == 0)] = (40, 40, 45)
    img[2:6, 24:29] = (180, 60, 50)
    return np.clip(img, 0, 255).astype(np.uint8)


def _brute_force(image, q, half, params, white=None):
    h, w = image.shape[:2]
    if white is not None:  # von Kries: each channel scaled to the reference light's mean
        image = np.clip(np.round(image * (np.asarray(white) / image.reshape(-1, 3).mean(axis=0))), 0, 255)
    idx = np.asarray(rgi_bins(image))
    out = np.zeros((h, w))
    for v in range(h):
        for u in range(w):
            if half[v, u] <= 0:
                continue
            inner = int(np.clip(np.round(params.window_scale * half[v, u]), params.min_half_size, params.max_half_size))
            outer = max(int(np.round(params.ring_scale * inner)), inner + 1)
            # The cross of a wide and a tall rectangle (the square when b = inner), pixel by pixel.
            b = int(min(max(np.round(np.float32(params.window_waist) * np.float32(inner)), 0), inner))
            rows, cols = np.mgrid[v - inner:v + inner + 1, u - inner:u + inner + 1]
            cross = (np.abs(rows - v) <= b) | (np.abs(cols - u) <= b)
            inside = cross & (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
            win = idx[rows[inside], cols[inside]]
            big = idx[max(v - outer, 0): v + outer + 1, max(u - outer, 0): u + outer + 1].ravel()
            n_in = np.bincount(win, minlength=M).astype(float)
            n_ring = np.bincount(big, minlength=M) - n_in
            p_obj = n_in / n_in.sum()
            p_bck = n_ring / max(n_ring.sum(), 1.0)
            rho = np.sum(np.sqrt(q) * np.maximum(np.sqrt(p_obj) - np.sqrt(p_bck), 0.0)) / params.reference_score
            out[v, u] = np.clip(max(rho - params.theta, 0.0) / (1.0 - params.theta), 0.0, 1.0)
    return out


def _brute_blob_half(first, half, reach):
    """Each pixel's ``half`` at the weighted centroid of ``first`` in its square of half-size round(reach * half)."""
    h, w = first.shape
    out = half.astype(float).copy()
    for v in range(h):
        for u in range(w):
            r = max(int(np.round(reach * half[v, u])), 1)
            win = first[max(v - r, 0): v + r + 1, max(u - r, 0): u + r + 1].astype(float)
            if half[v, u] <= 0 or win.sum() <= 1e-6:
                continue
            vv, uu = np.mgrid[max(v - r, 0): min(v + r + 1, h), max(u - r, 0): min(u + r + 1, w)]
            cu, cv = (win * uu).sum() / win.sum(), (win * vv).sum() / win.sum()
            if min(abs(cu % 1 - 0.5), abs(cv % 1 - 0.5)) < 1e-3:  # a rounding tie: float32 may go either way
                out[v, u] = np.nan
                continue
            at = half[int(np.round(cv)), int(np.round(cu))]
            if at > 0:
                out[v, u] = at
    return out


def test_bins_and_histograms_against_numpy(rng):
    img = rng.integers(0, 256, (9, 11, 3), dtype=np.uint8)
    img[0] = img[0, :, :1]  # greys: r = g = b, at the middle of the chromaticity range
    idx = np.asarray(rgi_bins(img))
    rgb = img.astype(float) + 1.0
    ang = lambda a, b: np.clip(np.floor((np.arctan2(a, b) * 2 / np.pi + 1e-4) * 12), 0, 11)  # noqa: E731
    want = (ang(rgb[..., 0], rgb[..., 1]) * 12 + ang(rgb[..., 1], rgb[..., 2])) * 4 + np.floor(
        (img.astype(float).sum(-1) / 3.0) * 4 / 256)
    np.testing.assert_array_equal(idx, want.astype(int))
    assert np.all(idx[0] // 4 == 6 * 12 + 6)  # grey, white and black share the chromaticity bin
    np.testing.assert_array_equal(np.asarray(jax.jit(rgi_bins)(img)), idx)  # jit rounds alike
    np.testing.assert_allclose(_histogram(idx, M), np.bincount(idx.ravel(), minlength=M) / idx.size, rtol=1e-6)
    np.testing.assert_allclose(_patch_histogram(img, (2, 3, 4, 5)),
                               np.bincount(idx[3:8, 2:6].ravel(), minlength=M) / 20, rtol=1e-6)
    q = rng.uniform(size=M) * (rng.uniform(size=M) < 0.1)
    q = q / q.sum()
    k = np.array([0.25, 0.5, 0.25])
    want = np.stack([np.convolve(row, k, mode="same") for row in q.reshape(-1, 4)]).ravel()
    np.testing.assert_allclose(_smooth_intensity(q), want / want.sum(), rtol=1e-5, atol=1e-8)
    # Along r' and g': scipy's convolution with zero padding, renormalised.
    want = convolve1d(convolve1d(q.reshape(12, 12, 4), k, axis=0, mode="constant"), k, axis=1, mode="constant")
    np.testing.assert_allclose(_smooth_chromaticity(q), want.ravel() / want.sum(), rtol=1e-5, atol=1e-8)


@pytest.mark.parametrize(("top_bins", "waist"), [(M, 1.0), (64, 0.618), ("exact", 1.0)])
def test_likelihood_against_brute_force(rng, top_bins, waist):
    image = _scene(rng)
    q = np.asarray(_patch_histogram(image, (12, 9, 6, 6)), np.float64)
    assert np.count_nonzero(q) <= 64  # the truncated tables are exact for this reference
    if top_bins == "exact":  # the least power of two (>= 8) holding every non-empty bin
        top_bins = exact_top_bins(q)
        nonzero = np.count_nonzero(q)
        assert top_bins == max(8, 2 ** int(np.ceil(np.log2(nonzero)))) and top_bins < 64, (top_bins, nonzero)
    half = rng.integers(0, 6, image.shape[:2]).astype(np.float32)  # every size, and 0 (no ball possible)
    params = ColourParams(theta=0.15, window_scale=0.8, ring_scale=2.0, min_half_size=1.0, max_half_size=4.0,
                          window_waist=waist)
    q32 = q.astype(np.float32)  # NumPy: jnp's cast compiles
    got = np.asarray(_likelihood(image, q32, half, params, top_bins=top_bins, blob_window=False))
    first = _brute_force(image, q, half, params)
    np.testing.assert_allclose(got, first, atol=2e-5)
    # The second pass: every pixel's window from the first map's local centroid.
    half2 = _brute_blob_half(first, half, params.blob_reach)
    ok = np.isfinite(half2)  # a centroid on a rounding tie: float32 may go either way, that pixel is not compared
    assert ok.mean() > 0.99 and np.any(half2[ok] != half[ok])  # the windows did move
    got2 = np.asarray(_likelihood(image, q32, half, params, top_bins=top_bins))
    np.testing.assert_allclose(got2[ok], _brute_force(image, q, np.where(ok, half2, half), params)[ok], atol=2e-5)


def test_reference_score_and_light_against_brute_force(rng):
    """The coefficient divided by the reference's own score before theta; a frame under another light (a gain
    and a colour cast) brought under the reference's (von Kries, grey world) first."""
    image = _scene(rng)
    q = np.asarray(_patch_histogram(image, (12, 9, 6, 6)), np.float64)
    half = rng.integers(0, 6, image.shape[:2]).astype(np.float32)
    params = ColourParams(theta=0.3, window_scale=0.8, max_half_size=4.0, reference_score=0.55)
    cast = np.clip(np.round(image * np.array([1.1, 0.95, 0.75])), 0, 255).astype(np.uint8)
    white = np.asarray(channel_means(image))
    np.testing.assert_allclose(white, image.reshape(-1, 3).mean(axis=0), rtol=1e-6)
    want = np.clip(np.round(cast * (white / cast.reshape(-1, 3).mean(axis=0))), 0, 255)
    np.testing.assert_array_equal(balance(cast, white), want)
    assert np.abs(want - image).mean() < 3.0  # the cast undone, but for rounding and clipping
    q32 = q.astype(np.float32)  # NumPy: jnp's cast compiles
    for frame, light in ((image, None), (cast, white)):
        got = np.asarray(_likelihood(frame, q32, half, params, top_bins=64, blob_window=False, white=light))
        np.testing.assert_allclose(got, _brute_force(frame, q, half, params, light), atol=3e-5)
    assert got.max() == 1.0  # the object scores above the given reference score: clipped


def test_blob_half_size_against_brute_force(rng):
    first = rng.uniform(size=(20, 26)) * (rng.uniform(size=(20, 26)) < 0.15)  # sparse responses
    first[12:15, 3:6] = 0.0
    half = np.broadcast_to(np.linspace(0.0, 6.0, 20)[:, None], (20, 26)).astype(np.float32)  # 0 rows: no ball
    for reach in (1.0, 2.5):
        want = _brute_blob_half(first, half, reach)
        got = np.asarray(jax.jit(blob_half_size)(first, half, reach))
        ok = np.isfinite(want)
        assert ok.mean() > 0.95
        np.testing.assert_array_equal(got[ok], want[ok].astype(np.float32))


def test_map_peaks_at_the_ball_and_stays_low_without_it(rng):
    image = _scene(rng, h=40, w=48, centre=(20, 22), radius=5.0)
    q = _smooth_intensity(_patch_histogram(image, (19, 17, 6, 6)))
    half = np.full(image.shape[:2], 5.0, np.float32)
    heat = np.asarray(_likelihood(image, q, half, ColourParams()))
    peak = np.unravel_index(np.argmax(heat), heat.shape)
    assert abs(peak[0] - 20) <= 1 and abs(peak[1] - 22) <= 1 and heat.max() > 0.5
    empty = _scene(rng, h=40, w=48, centre=(-30, -30))
    assert np.asarray(_likelihood(empty, q, half, ColourParams())).max() < 0.1
    # A darker light moves intensities, not chromaticities: the peak stays where it was.
    darker = (image * 0.85).astype(np.uint8)
    heat_dark = np.asarray(_likelihood(darker, q, half, ColourParams()))
    assert np.unravel_index(np.argmax(heat_dark), heat.shape) == peak and heat_dark.max() > 0.5 * heat.max()


def test_expected_radius_against_opencv_projection():
    intrinsics = np.array([143.0, 143.0, 99.5, 74.5])
    pose = camera_pose(height=0.6, pitch=np.deg2rad(15.0), yaw=0.1)  # the top rows see above the horizon
    radius = 0.075
    got = np.asarray(_expected_radius(intrinsics, pose, radius, (150, 200)))
    assert np.all(got[:5] == 0.0)  # above the horizon no ball can be
    k = np.array([[143.0, 0, 99.5], [0, 143.0, 74.5], [0, 0, 1]])
    base_to_cam = np.linalg.inv(pose)
    rvec, _ = cv2.Rodrigues(base_to_cam[:3, :3])
    for u, v in [(100, 80), (20, 140), (180, 100), (60, 75)]:
        ray = pose[:3, :3] @ np.array([(u - 99.5) / 143.0, (v - 74.5) / 143.0, 1.0])
        centre = pose[:3, 3] + ray * (radius - pose[2, 3]) / ray[2]
        side = np.cross(ray, [0.0, 0.0, 1.0])
        offset = radius * side / np.linalg.norm(side)
        pts = np.stack([centre, centre + offset, centre - offset])
        img, _ = cv2.projectPoints(pts, rvec, base_to_cam[:3, 3], k, None)
        img = img.reshape(3, 2)
        np.testing.assert_allclose(img[0], [u, v], atol=1e-4)
        want = 0.5 * (np.linalg.norm(img[1] - img[0]) + np.linalg.norm(img[2] - img[0]))
        np.testing.assert_allclose(got[v, u], want, rtol=1e-4)


def test_heatmaps_of_a_sequence_match_frame_by_frame(rng):
    intrinsics = np.array([40.0, 40.0, 15.5, 11.5])
    poses = np.stack([camera_pose(height=0.6, pitch=np.deg2rad(p)) for p in (25.0, 35.0)])
    images = np.stack([_scene(rng), _scene(rng, centre=(15, 10))])
    q = _patch_histogram(images[0], (12, 9, 6, 6))
    heat = np.asarray(colour_heatmaps(images, q, intrinsics, poses, 0.075, ColourParams()))
    for t in range(2):
        half = _expected_radius(intrinsics, poses[t], 0.075, (24, 32))
        np.testing.assert_allclose(heat[t], _likelihood(images[t], q, half, ColourParams()), atol=1e-6)
    assert heat.min() >= 0.0 and heat.max() <= 1.0
