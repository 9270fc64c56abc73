"""``mean_shift_backprojection`` against OpenCV's meanShift on the same back-projection, window for window."""

import cv2
import jax.numpy as jnp
import numpy as np

from heatpf_jax.baselines.opencv_mean_shift import backprojection, mean_shift_backprojection
from heatpf_jax.colour.space import num_bins, rgi_bins
from tests.baselines.moving_disc import HEIGHT, WIDTH


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
