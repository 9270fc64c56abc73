"""The moving-disc sequence of :mod:`tests.baselines.moving_disc`, for the image-space trackers' tests."""

import numpy as np
import pytest

from heatpf_jax.colour.space import patch_histogram
from tests.baselines.moving_disc import disc_frames, disc_path


@pytest.fixture(scope="module")
def sequence():
    rng = np.random.default_rng(7)
    path = disc_path()
    frames = disc_frames(rng, path)
    u, v = np.round(path[0]).astype(int)
    q = np.asarray(patch_histogram(frames[0], (u - 4, v - 4, 9, 9)))
    return frames, path, q
