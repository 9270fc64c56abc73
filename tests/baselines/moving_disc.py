"""The image-space trackers' test scene: a white disc with dark dots moving over noisy green grass, and the
trackers under test (shared by the baselines' tests, so ``run`` compiles once per tracker)."""

import jax
import numpy as np

from heatpf_jax.baselines.colour_particles import ColourParticleTracker
from heatpf_jax.baselines.image_sequences import run
from heatpf_jax.baselines.kalman_mean_shift import KalmanMeanShiftTracker
from heatpf_jax.baselines.mean_shift import MeanShiftTracker

NUM_FRAMES, HEIGHT, WIDTH, RADIUS = 30, 60, 80, 6.0
HALF = 7.0  # window half-size: the disc's radius and a pixel of grass

TRACKERS = {
    "mean_shift": MeanShiftTracker(max_half_size=12),
    "mean_shift_scale": MeanShiftTracker(max_half_size=12, adapt_scale=True),
    "mean_shift_kalman": KalmanMeanShiftTracker(MeanShiftTracker(max_half_size=12)),
    "particles": ColourParticleTracker(),
}


def disc_path(num=NUM_FRAMES, speed=1.8):
    """The disc's centres ``(u, v)``: about 2 px a frame, right and down with a wiggle."""
    t = np.arange(num, dtype=np.float64)
    return np.stack([14.0 + speed * t, 18.0 + 0.8 * t + 3.0 * np.sin(t / 4.0)], axis=1)


def disc_frames(rng, path, h=HEIGHT, w=WIDTH, radius=RADIUS):
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


def run_tracker(name, frames, q, start, key=0):
    tracker = TRACKERS[name]
    return run(jax.random.key(key), frames, q, start, HALF, tracker.default_params(), tracker=tracker)
