"""The colour particle filter's window histograms against NumPy."""

import numpy as np

from heatpf_jax.baselines.colour_particles import window_histograms
from heatpf_jax.colour.space import num_bins, rgi_bins


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
