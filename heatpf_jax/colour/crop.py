"""Where a reference image was cut from: a user's picture of the ball is often a box cut out of one of the frames.

``heatpf colour --reference BALL.png`` takes the reference from an image of the object. Without surroundings, its
background model is the input's frames as a whole (:func:`~heatpf_jax.colour.reference.frames_histogram`), not the
ring around the ball that a box in a frame has (:func:`~heatpf_jax.colour.reference.ring_histogram`). But a user
who wants the ball's picture usually cuts it out of a frame of the same recording and saves it losslessly (PNG, or
``.npy``): then the image is, pixel for pixel, a box of that frame, and the reference is the one its box in its
frame gives. :func:`find_crop` finds that box: the first frame in which the image occurs at exactly one place.

A JPEG, a resized image or one from another recording is not found, and the reference is taken from the image
itself. Host-side NumPy (a few milliseconds for 200 frames of 200 x 150).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["Crop", "find_crop"]


class Crop(NamedTuple):
    """Where an image occurs in a sequence's frames.

    Attributes:
        frame: the frame's index.
        x: the image's left column in the frame.
        y: its top row.
    """

    frame: int
    x: int
    y: int


def find_crop(images: np.ndarray, image: np.ndarray) -> Crop | None:
    """The first frame of ``images`` holding ``image`` pixel for pixel at exactly one place, and that place.

    Args:
        images: ``uint8 [T, H, W, 3]`` the frames.
        image: ``uint8 [h, w, 3]`` the reference image.

    Returns:
        A :class:`Crop`, or ``None`` when no frame holds the image (or each that does holds it at several places: a
        patch of uniform colour says nothing of where it came from).
    """
    images = np.asarray(images)
    image = np.asarray(image)
    if images.ndim != 4 or image.ndim != 3 or image.shape[2] != images.shape[3]:
        return None
    _, height, width, _ = images.shape
    h, w = image.shape[:2]
    if h > height or w > width or h < 1 or w < 1:
        return None
    corner = image[0, 0]
    for t, frame in enumerate(images):
        # Candidates: where the frame has the image's top-left pixel; each is then compared whole.
        rows, cols = np.nonzero(np.all(frame[: height - h + 1, : width - w + 1] == corner, axis=-1))
        hits = [(int(y), int(x)) for y, x in zip(rows, cols, strict=True)
                if np.array_equal(frame[y:y + h, x:x + w], image)]
        if len(hits) == 1:
            return Crop(frame=t, x=hits[0][1], y=hits[0][0])
    return None
