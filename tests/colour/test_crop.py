"""Where a reference image was cut from: every place and difference checked against a brute-force search over all
offsets."""

import numpy as np
import pytest

from heatpf_jax.colour.crop import Crop, find_crop, frame_box


def _brute_force(images: np.ndarray, image: np.ndarray) -> list[tuple[int, int, int]]:
    h, w = image.shape[:2]
    return [(t, x, y) for t in range(images.shape[0]) for y in range(images.shape[1] - h + 1)
            for x in range(images.shape[2] - w + 1) if np.array_equal(images[t, y:y + h, x:x + w], image)]


def test_a_cut_out_box_is_found_where_it_was_cut():
    rng = np.random.default_rng(3)
    images = rng.integers(0, 256, (5, 30, 40, 3), dtype=np.uint8)
    for t, x, y, w, h in ((0, 0, 0, 5, 4), (3, 31, 22, 9, 8), (4, 17, 9, 1, 1), (2, 0, 29, 40, 1)):
        image = images[t, y:y + h, x:x + w].copy()
        hits = _brute_force(images, image)
        first = min(hits)  # the earliest frame; random pixels: one place there
        assert find_crop(images, image) == Crop(frame=first[0], x=first[1], y=first[2])


def _rms_everywhere(images: np.ndarray, image: np.ndarray) -> np.ndarray:
    """``[T, H - h + 1, W - w + 1]`` the RMS difference at every offset, by brute force."""
    h, w = image.shape[:2]
    t_, height, width = images.shape[:3]
    out = np.empty((t_, height - h + 1, width - w + 1))
    for t in range(t_):
        for y in range(height - h + 1):
            for x in range(width - w + 1):
                d = images[t, y:y + h, x:x + w].astype(float) - image
                out[t, y, x] = np.sqrt(np.mean(d**2))
    return out


def test_a_lossy_copy_is_found_at_its_nearest_place():
    """A copy with noise (as a JPEG's) is found where the brute-force RMS difference is smallest, with that RMS; a
    copy changed beyond ``tolerance``, or ``tolerance=0``, finds nothing."""
    rng = np.random.default_rng(5)
    images = rng.integers(0, 256, (4, 24, 30, 3), dtype=np.uint8)
    for t, x, y, w, h in ((2, 7, 5, 8, 6), (0, 22, 18, 8, 6), (3, 0, 0, 5, 9)):
        noisy = np.clip(images[t, y:y + h, x:x + w] + rng.normal(0, 8, (h, w, 3)), 0, 255).astype(np.uint8)
        rms = _rms_everywhere(images, noisy)
        want = np.unravel_index(np.argmin(rms), rms.shape)
        assert tuple(want) == (t, y, x)
        got = find_crop(images, noisy)
        assert got[:3] == (t, x, y) and got.rms == pytest.approx(rms[want], rel=1e-6)
        assert find_crop(images, noisy, tolerance=0.0) is None
        assert find_crop(images, noisy, tolerance=0.5 * rms[want]) is None


def test_what_is_not_cut_out_or_is_ambiguous_is_not_found():
    rng = np.random.default_rng(4)
    images = rng.integers(0, 256, (3, 20, 20, 3), dtype=np.uint8)
    image = images[1, 5:11, 4:12].copy()
    image[3, 2, 1] ^= 1  # one bit of one pixel changed (a lossy copy): not the frame's pixels
    assert _brute_force(images, image) == [] and find_crop(images, image, tolerance=0.0) is None
    assert find_crop(images, image)[:3] == (1, 4, 5)  # but within the tolerance
    other = rng.integers(0, 256, (6, 8, 3), dtype=np.uint8)  # not in the frames: random pixels are 100+ levels off
    assert _rms_everywhere(images, other).min() > 20.0 and find_crop(images, other) is None
    assert find_crop(images, rng.integers(0, 256, (21, 5, 3), dtype=np.uint8)) is None  # taller than a frame
    flat = np.zeros((2, 12, 12, 3), np.uint8)
    flat[1, 2:6, 2:6] = 200  # a uniform patch: in frame 1 at 9 places, in frame 0 nowhere
    assert len(_brute_force(flat, np.full((2, 2, 3), 200, np.uint8))) == 9
    assert find_crop(flat, np.full((2, 2, 3), 200, np.uint8)) is None
    assert find_crop(flat, flat[1, 1:7, 1:7]) == Crop(frame=1, x=1, y=1)  # with its border: one place


def test_a_box_of_the_image_is_the_same_box_of_its_frame():
    rng = np.random.default_rng(6)
    images = rng.integers(0, 256, (2, 20, 24, 3), dtype=np.uint8)
    crop = find_crop(images, images[1, 6:16, 9:21])
    x, y, w, h = frame_box(crop, (2, 3, 4, 5))
    np.testing.assert_array_equal(images[crop.frame, y:y + h, x:x + w], images[1, 6:16, 9:21][3:8, 2:6])
