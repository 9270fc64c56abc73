"""The numbers of the long-term memory (Olufs et al. 3.4): :class:`MemoryParams`.

What each number does is described step by step in :mod:`heatpf_jax.memory`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

__all__ = ["MemoryParams"]


class MemoryParams(NamedTuple):
    """Numbers of :class:`~heatpf_jax.memory.track_memory.TrackMemory`.

    Attributes:
        memory_forget: seconds a track survives unobserved (Olufs et al.: 2 s).
        memory_gate: the gate's largest radius, metres: nothing farther from a track's prediction moves it.
        memory_accel_std: the tracks' white-noise acceleration while they are seen, m/s^2 (kicks the filter
            follows).
        memory_lost_accel_std: the same for a track unobserved since the last step, m/s^2: an unseen ball rolls
            on, so its gate grows slowly and does not reach over the distractors beside its path.
        memory_obs_std: std of a candidate's position, metres.
        memory_spawn_speed_std: prior std of a new track's velocity, m/s.
        memory_min_support: buffered weight near a mode for it to count as observed (and to re-detect a track).
        memory_support_radius: radius of that neighbourhood, metres.
        memory_confirm: observations before a track can be lost (and get hints) or count as static.
        memory_redetect_sigmas: the gate in Mahalanobis sigmas of a track's predicted position
            (``P_xy + memory_obs_std^2 I``), for candidates and re-detection alike.
        memory_friction: the tracks' rolling deceleration, m/s^2 (0: constant velocity).
        memory_static_speed: a confirmed track slower than this (m/s) that is not the ball is static clutter.
        memory_birth_support: buffered weight of a blob outside every gate for the memory to open a track on it.
        memory_blob_radius: radius of a ball-sized blob on the ground, metres: the pixels of one blob spread along
            the ray by its footprint (:func:`~heatpf_jax.memory.blobs.find_blobs`).
        memory_redetect_share: the memory re-detects a track on its own only on a blob of at least this share of
            the track's usual blob weight (``TrackTable.blob``).
        memory_lost_turn: the largest turn, radians, a lost rolling track's path may have taken: a point outside
            the cone of this half-angle around its motion from where it was last seen (widened by the observation
            noise) does not move it (:func:`~heatpf_jax.memory.gates.motion_consistent`); ``pi / 2``, the default,
            refuses only what lies behind: a rolling ball does not roll back.
    """

    memory_forget: float = 2.0
    memory_gate: float = 0.75
    memory_accel_std: float = 2.0
    memory_obs_std: float = 0.1
    memory_spawn_speed_std: float = 1.0
    memory_min_support: float = 1.0
    memory_support_radius: float = 0.3
    memory_confirm: int = 3
    memory_redetect_sigmas: float = 3.0
    memory_friction: float = 0.3
    memory_static_speed: float = 0.15
    memory_birth_support: float = 3.0
    memory_blob_radius: float = 0.1
    memory_lost_accel_std: float = 0.5
    memory_redetect_share: float = 0.3
    memory_lost_turn: float = math.pi / 2
