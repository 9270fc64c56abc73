"""Where a reference image was cut from: every place checked against a brute-force search over all offsets."""

import numpy as np

from heatpf_jax.colour.crop import Crop, find_crop


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


def test_what_is_not_cut_out_or_is_ambiguous_is_not_found():
    rng = np.random.default_rng(4)
    images = rng.integers(0, 256, (3, 20, 20, 3), dtype=np.uint8)
    image = images[1, 5:11, 4:12].copy()
    image[3, 2, 1] ^= 1  # one bit of one pixel changed (a lossy copy): not the frame's pixels
    assert _brute_force(images, image) == [] and find_crop(images, image) is None
    assert find_crop(images, rng.integers(0, 256, (21, 5, 3), dtype=np.uint8)) is None  # taller than a frame
    flat = np.zeros((2, 12, 12, 3), np.uint8)
    flat[1, 2:6, 2:6] = 200  # a uniform patch: in frame 1 at 9 places, in frame 0 nowhere
    assert len(_brute_force(flat, np.full((2, 2, 3), 200, np.uint8))) == 9
    assert find_crop(flat, np.full((2, 2, 3), 200, np.uint8)) is None
    assert find_crop(flat, flat[1, 1:7, 1:7]) == Crop(frame=1, x=1, y=1)  # with its border: one place
