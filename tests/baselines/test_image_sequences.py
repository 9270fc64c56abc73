"""Every image-space tracker run over frames: following a moving disc, and no NaN once the disc has left the
image."""

import jax
import numpy as np
import pytest

from tests.baselines.moving_disc import HEIGHT, TRACKERS, WIDTH, disc_frames, disc_path, run_tracker


@pytest.mark.parametrize("name", list(TRACKERS))
def test_trackers_follow_the_moving_disc(sequence, name):
    """Euclidean error of the reported (u, v) against the disc's true centre, every frame: median < 1 px,
    max < 3 px (the disc moves about 2 px a frame; window half-size 7 px, disc radius 6 px)."""
    frames, path, q = sequence
    _, info = run_tracker(name, frames, q, path[0])
    err = np.linalg.norm(np.asarray(info.position) - path, axis=1)
    assert np.all(np.isfinite(err)) and np.median(err) < 1.0 and err.max() < 3.0, (name, err.round(2))


def test_no_nan_when_the_object_leaves_the_image(sequence):
    """The disc runs out of the right edge (by frame ~17) and is gone; then an all-zero reference: every tracker's
    positions stay finite and inside the image."""
    frames, _, q = sequence
    path = disc_path(speed=4.0)
    gone = disc_frames(np.random.default_rng(5), path)
    for name in TRACKERS:
        for ref in (q, np.zeros_like(q)):
            state, info = run_tracker(name, gone, ref, path[0], key=1)
            pos = np.asarray(info.position)
            assert np.all(np.isfinite(pos)), name
            assert np.all(pos >= 0.0) and np.all(pos <= [WIDTH - 1, HEIGHT - 1]), name
            assert all(np.all(np.isfinite(np.asarray(leaf))) for leaf in jax.tree.leaves(state)), name
