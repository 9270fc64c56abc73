"""Image-space colour trackers (Olufs et al.'s Table 1 contestants): OpenCV's meanShift on the same
back-projection, histograms against NumPy, and every tracker following a moving disc."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from heatpf_jax.baselines.image_space import (
    ColourParticleTracker,
    KalmanMeanShiftTracker,
    MeanShiftTracker,
    backprojection,
    mean_shift_window,
    track,
)
from heatpf_jax.colour_space import num_bins, patch_histogram, rgi_bins

_window = jax.jit(mean_shift_window, static_argnames=("max_iter",))


def _frames(rng, num=24, h=48, w=64, radius=4.5):
    """A white disc with dark dots moving 1.5-2 px a frame over noisy grass; and its centres."""
    path = np.stack([12.0 + 1.8 * np.arange(num), 14.0 + 0.9 * np.arange(num) + 3 * np.sin(np.arange(num) / 4)], 1)
    vv, uu = np.mgrid[:h, :w]
    frames = []
    for u, v in path:
        img = np.empty((h, w, 3))
        img[:] = (45, 120, 45)
        disc = (uu - u) ** 2 + (vv - v) ** 2 <= radius**2
        img[disc] = (230, 230, 228)
        img[disc & ((uu + vv) % 4 == 0)] = (40, 40, 45)
        frames.append(np.clip(img + rng.normal(0, 4, img.shape), 0, 255).astype(np.uint8))
    return np.stack(frames), path


def test_mean_shift_window_is_opencvs(rng):
    frames, path = _frames(rng)
    q = patch_histogram(frames[0], (9, 11, 7, 7))
    for t in (3, 10, 17):
        prob = np.asarray(backprojection(frames[t], q))
        prob8 = np.round(prob * 255).astype(np.uint8)  # OpenCV's usual 8-bit back-projection
        for x, y, w, h in [(int(path[t, 0]) - 8, int(path[t, 1]) - 4, 11, 9), (2, 3, 15, 15), (50, 30, 14, 20),
                           (-3, 40, 10, 10)]:
            criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 10, 1.0)
            _, want = cv2.meanShift(prob8, (x, y, w, h), criteria)
            got = _window(jnp.asarray(prob8, jnp.float32), (x, y, w, h), max_iter=10, eps=1.0)
            assert tuple(int(v) for v in got) == tuple(want), ((x, y, w, h), got, want)


def test_particle_window_histograms_against_numpy(rng):
    frames, _ = _frames(rng, num=1)
    q = patch_histogram(frames[0], (9, 11, 7, 7))
    tracker = ColourParticleTracker(top_bins=num_bins())
    centres = jnp.asarray(rng.uniform(-3, 66, (12, 2)), jnp.float32)
    hist, q_top = tracker.window_histograms(frames[0], q, centres, 3.0)
    idx = np.asarray(rgi_bins(frames[0]))
    order = np.asarray(jax.lax.top_k(jnp.asarray(q), num_bins())[1])
    for i, (u, v) in enumerate(np.round(np.asarray(centres)).astype(int)):
        win = idx[max(v - 3, 0): max(v + 4, 0), max(u - 3, 0): max(u + 4, 0)].ravel()
        want = np.bincount(win, minlength=num_bins())[order] / max(win.size, 1)
        np.testing.assert_allclose(hist[i], want, atol=1e-6)


@pytest.mark.parametrize("tracker", [MeanShiftTracker(), KalmanMeanShiftTracker(), ColourParticleTracker()],
                         ids=["mean_shift", "mean_shift_kalman", "particles"])
def test_trackers_follow_a_moving_disc(rng, tracker):
    frames, path = _frames(rng)
    q = patch_histogram(frames[0], (int(path[0, 0]) - 3, int(path[0, 1]) - 3, 7, 7))
    out = np.asarray(track(jax.random.key(0), frames, q, path[0], 5.0, tracker.default_params(), tracker))
    err = np.linalg.norm(out - path, axis=1)
    assert np.all(np.isfinite(out)) and np.median(err) < 1.5 and err.max() < 4.0, err


def test_no_nan_when_the_object_leaves(rng):
    frames, path = _frames(rng)
    empty = np.broadcast_to(frames[0, :1, :1], frames.shape).copy()  # grass only from frame 8 on
    frames[8:] = empty[8:]
    q = patch_histogram(frames[0], (int(path[0, 0]) - 3, int(path[0, 1]) - 3, 7, 7))
    for tracker in (MeanShiftTracker(), KalmanMeanShiftTracker(), ColourParticleTracker()):
        out = np.asarray(track(jax.random.key(1), frames, q, path[0], 5.0, tracker.default_params(), tracker))
        assert np.all(np.isfinite(out))
