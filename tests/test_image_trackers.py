"""Image-space colour trackers (Olufs et al.'s Table 1 contestants): OpenCV's meanShift on the same
back-projection, the particle filter's window histograms against NumPy, the Kalman variant against a NumPy
Kalman filter, every tracker following a moving disc, and no NaN once the disc has left the image."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from heatpf_jax.baselines.image_trackers import (
    ColourParticleTracker,
    KalmanMeanShiftTracker,
    MeanShiftTracker,
    backprojection,
    mean_shift_backprojection,
    run,
    window_histograms,
)
from heatpf_jax.colour_space import num_bins, patch_histogram, rgi_bins

NUM_FRAMES, HEIGHT, WIDTH, RADIUS = 30, 60, 80, 6.0
HALF = 7.0  # window half-size: the disc's radius and a pixel of grass

TRACKERS = {
    "mean_shift": MeanShiftTracker(max_half_size=12),
    "mean_shift_scale": MeanShiftTracker(max_half_size=12, adapt_scale=True),
    "mean_shift_kalman": KalmanMeanShiftTracker(MeanShiftTracker(max_half_size=12)),
    "particles": ColourParticleTracker(),
}


def _path(num=NUM_FRAMES, speed=1.8):
    """The disc's centres ``(u, v)``: about 2 px a frame, right and down with a wiggle."""
    t = np.arange(num, dtype=np.float64)
    return np.stack([14.0 + speed * t, 18.0 + 0.8 * t + 3.0 * np.sin(t / 4.0)], axis=1)


def _frames(rng, path, h=HEIGHT, w=WIDTH, radius=RADIUS):
    """Noisy green grass with a white disc (dark dots on it) at each centre of ``path``."""
    vv, uu = np.mgrid[:h, :w]
    frames = []
    for u, v in path:
        img = np.empty((h, w, 3))
        img[:] = (45, 120, 45)
        disc = (uu - u) ** 2 + (vv - v) ** 2 <= radius**2
        img[disc] = (230, 230, 228)
        img[disc & ((uu % 4 == 0) & (vv % 4 == 0))] = (40, 40, 45)
        frames.append(np.clip(img + rng.normal(0.0, 4.0, img.shape), 0, 255).astype(np.uint8))
    return np.stack(frames)


@pytest.fixture(scope="module")
def sequence():
    rng = np.random.default_rng(7)
    path = _path()
    frames = _frames(rng, path)
    u, v = np.round(path[0]).astype(int)
    q = np.asarray(patch_histogram(frames[0], (u - 4, v - 4, 9, 9)))
    return frames, path, q


# --- OpenCV's meanShift ----------------------------------------------------------------------------------------


def _cv_window(prob, window, max_iter, eps):
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, max_iter, eps)
    _, got = cv2.meanShift(prob, tuple(int(v) for v in window), criteria)
    return np.array(got)


def test_mean_shift_backprojection_is_opencvs_on_the_same_backprojection(sequence):
    """Same uint8 back-projection (and its float32 copy) into both; the windows agree exactly (uint8) and to
    1 px (float32, OpenCV's moments are in double)."""
    frames, path, q = sequence
    rng = np.random.default_rng(3)
    cases = 0
    for t in (2, 11, 19, 27):
        prob8 = np.asarray(backprojection(frames[t], q))
        assert prob8.dtype == np.uint8 and prob8.max() == 255
        # OpenCV's own back-projection of the scaled histogram; a bin at x.5 after scaling may round either way.
        scaled = np.round(q.astype(np.float32) * np.float32(255) / q.max().astype(np.float32))
        bins_f = np.asarray(rgi_bins(frames[t])).astype(np.float32)
        cv_prob = cv2.calcBackProject([bins_f], [0], scaled, [0, num_bins()], 1)
        assert np.abs(prob8.astype(int) - cv_prob.astype(int)).max() <= 1
        u, v = path[t]
        windows = [(int(u) - 9, int(v) - 3, 11, 9), (int(u) + 2, int(v) + 4, 8, 12), (-4, 50, 15, 15),
                   (70, -5, 14, 20)] + [(int(rng.integers(-5, 75)), int(rng.integers(-5, 55)),
                                         int(rng.integers(3, 25)), int(rng.integers(3, 25))) for _ in range(4)]
        for window in windows:
            max_iter, eps = int(rng.integers(1, 12)), float(rng.choice([0.0, 0.5, 1.0, 2.0]))
            want = _cv_window(prob8, window, max_iter, eps)
            got = np.asarray(mean_shift_backprojection(prob8, jnp.asarray(window), max_iter, eps))
            np.testing.assert_array_equal(got, want, err_msg=f"{t=} {window=} {max_iter=} {eps=}")
            prob32 = prob8.astype(np.float32) / 255.0
            want32 = _cv_window(prob32, window, max_iter, eps)
            got32 = np.asarray(mean_shift_backprojection(prob32, jnp.asarray(window), max_iter, eps))
            assert np.abs(got32 - want32).max() <= 1, (t, window, got32, want32)
            cases += 1
    # Random probability images: many iterations, clipping at every border, an empty window, zero mass.
    for i in range(12):
        prob = cv2.GaussianBlur(rng.integers(0, 256, (HEIGHT, WIDTH)).astype(np.uint8), (0, 0), 3.0)
        prob[rng.random(prob.shape) < 0.3] = 0
        if i == 0:
            prob[:] = 0
        window = (int(rng.integers(-20, 90)), int(rng.integers(-20, 70)), int(rng.integers(1, 40)),
                  int(rng.integers(1, 40)))
        max_iter, eps = int(rng.integers(1, 30)), float(rng.choice([0.0, 1.0, 1.5]))
        want = _cv_window(prob, window, max_iter, eps)
        got = np.asarray(mean_shift_backprojection(prob, jnp.asarray(window), max_iter, eps))
        np.testing.assert_array_equal(got, want, err_msg=f"{window=} {max_iter=} {eps=}")
        cases += 1
    assert cases == 44


# --- The particle filter's window histograms -------------------------------------------------------------------


def test_window_histograms_against_numpy(sequence):
    frames, _, q = sequence
    rng = np.random.default_rng(11)
    image = frames[5]
    idx = np.asarray(rgi_bins(image))
    centres = np.concatenate([rng.uniform(-4.0, 84.0, (14, 2)), [[-30.0, 10.0], [40.0, 100.0]]]).astype(np.float32)
    half = np.array([4.0, 2.6], np.float32)  # rounds to 4 and 3: 9 x 7 windows
    hist, q_top, top_index = (np.asarray(a) for a in window_histograms(image, q, centres, half, top_bins=num_bins()))
    np.testing.assert_array_equal(q_top, q[top_index])
    for i, (u, v) in enumerate(np.round(centres).astype(int)):
        win = idx[max(v - 3, 0): max(v + 4, 0), max(u - 4, 0): max(u + 5, 0)].ravel()
        full = np.bincount(win, minlength=num_bins()) / max(win.size, 1)
        np.testing.assert_allclose(hist[i], full[top_index], atol=1e-6, err_msg=f"{i=}")
        # Every bin kept: the exact Bhattacharyya coefficient.
        np.testing.assert_allclose(np.sum(np.sqrt(hist[i] * q_top)), np.sum(np.sqrt(full * q)), atol=1e-5)
    assert np.all(hist[-2:] == 0.0)  # windows entirely outside the image
    # 78,000 pixels, most of them grass: the uint16 summed-area table wraps, the window counts do not.
    big = np.clip(rng.normal((45, 120, 45), 1.0, (300, 260, 3)), 0, 255).astype(np.uint8)
    big[250:280, 200:240] = (230, 230, 228)
    idx = np.asarray(rgi_bins(big))
    assert np.bincount(idx.ravel()).max() >= 2**16
    centres = np.array([[220.0, 265.0], [258.7, 298.6], [130.0, 150.0], [5.0, 290.0]], np.float32)
    hist, q_top, top_index = (np.asarray(a) for a in window_histograms(big, q, centres, 20.0, top_bins=8))
    for i, (u, v) in enumerate(np.round(centres).astype(int)):
        win = idx[max(v - 20, 0): v + 21, max(u - 20, 0): u + 21].ravel()
        full = np.bincount(win, minlength=num_bins()) / win.size
        np.testing.assert_allclose(hist[i], full[top_index], atol=1e-6, err_msg=f"big {i=}")
    np.testing.assert_array_equal(q_top, q[top_index])  # the reference's 8 largest bins
    assert np.all(np.diff(q_top) <= 0) and np.all(q[np.setdiff1d(np.arange(num_bins()), top_index)] <= q_top[-1])


# --- Trackers on the moving disc -------------------------------------------------------------------------------


def _run(name, frames, q, start, key=0):
    tracker = TRACKERS[name]
    return run(jax.random.key(key), frames, q, start, HALF, tracker.default_params(), tracker=tracker)


@pytest.mark.parametrize("name", list(TRACKERS))
def test_trackers_follow_the_moving_disc(sequence, name):
    """Euclidean error of the reported (u, v) against the disc's true centre, every frame: median < 1 px,
    max < 3 px (the disc moves about 2 px a frame; window half-size 7 px, disc radius 6 px)."""
    frames, path, q = sequence
    _, info = _run(name, frames, q, path[0])
    err = np.linalg.norm(np.asarray(info.position) - path, axis=1)
    assert np.all(np.isfinite(err)) and np.median(err) < 1.0 and err.max() < 3.0, (name, err.round(2))


def test_kalman_variant_is_a_kalman_filter_on_its_measurements(sequence):
    """The filtered positions equal a NumPy constant-velocity Kalman filter run on the mean-shift results
    the tracker recorded (the disc stays inside the image, so the in-image clip is a no-op)."""
    frames, path, q = sequence
    tracker = TRACKERS["mean_shift_kalman"]
    p = tracker.default_params()
    _, info = _run("mean_shift_kalman", frames, q, path[0])
    assert np.all(np.asarray(info.found))
    f = np.eye(4)
    f[0, 2] = f[1, 3] = 1.0
    g = np.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]])
    qn = p.accel_std**2 * g @ g.T
    hm = np.eye(2, 4)
    r = p.meas_std**2 * np.eye(2)
    x = np.array([path[0, 0], path[0, 1], 0.0, 0.0])
    cov = np.diag([p.init_position_std**2] * 2 + [p.init_velocity_std**2] * 2)
    want = []
    for z in np.asarray(info.measurement, np.float64):
        x, cov = f @ x, f @ cov @ f.T + qn
        s = hm @ cov @ hm.T + r
        gain = cov @ hm.T @ np.linalg.inv(s)
        x = x + gain @ (z - hm @ x)
        cov = (np.eye(4) - gain @ hm) @ cov
        want.append(x[:2])
    np.testing.assert_allclose(np.asarray(info.position), np.array(want), atol=2e-3)
    # And the measurements are the mean shift's: not simply the true path (the filter does something).
    assert not np.allclose(np.asarray(info.position), np.asarray(info.measurement), atol=1e-2)


def test_no_nan_when_the_object_leaves_the_image(sequence):
    """The disc runs out of the right edge (by frame ~17) and is gone; then an all-zero reference: every tracker's
    positions stay finite and inside the image."""
    frames, _, q = sequence
    path = _path(speed=4.0)
    gone = _frames(np.random.default_rng(5), path)
    for name in TRACKERS:
        for ref in (q, np.zeros_like(q)):
            state, info = _run(name, gone, ref, path[0], key=1)
            pos = np.asarray(info.position)
            assert np.all(np.isfinite(pos)), name
            assert np.all(pos >= 0.0) and np.all(pos <= [WIDTH - 1, HEIGHT - 1]), name
            assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree.leaves(state)), name
