"""Image-space colour trackers over a sequence: the contestants of Olufs et al.'s Table 1 (section 4).

Olufs et al. compare their tracker with "Mean Shift" [5], "Mean Shift + KL" (mean shift with a Kalman
filter) and the "MC Tracker", the colour-based particle filter [7, 13]; all track a colour histogram
(eq. 1, here the r'g'I bins of :mod:`heatpf_jax.colour.space`) with the Bhattacharyya coefficient
``rho[p, q] = sum_u sqrt(p_u q_u)`` (eq. 2) directly in the image, and none re-detects a lost object:
:class:`~heatpf_jax.baselines.mean_shift.MeanShiftTracker`,
:class:`~heatpf_jax.baselines.kalman_mean_shift.KalmanMeanShiftTracker` and
:class:`~heatpf_jax.baselines.colour_particles.ColourParticleTracker` (and, beside them, OpenCV's meanShift
in :mod:`heatpf_jax.baselines.opencv_mean_shift`).

Every tracker is a frozen (hashable) dataclass of static choices with a params ``NamedTuple`` of numbers,
``init(key, first_window, params)`` (a :class:`~heatpf_jax.baselines.image_window.Window`) and
``step(key, state, image, params) -> (state, info)``; :func:`run` scans ``step`` over the frames (jitted
with the tracker static) and :func:`track` returns its positions.
"""

from __future__ import annotations

from functools import partial
from typing import Any

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray, UInt8

from heatpf_jax.baselines.image_window import _window

__all__ = ["SequenceTracker", "run", "track"]


@partial(jax.jit, static_argnames=("tracker",))
def run(
    key: PRNGKeyArray,
    images: UInt8[ArrayLike, "t h w 3"],
    q: Float[ArrayLike, " m"],
    start_uv: Float[ArrayLike, "2"],
    half_size: Float[ArrayLike, "*2"],
    params: Any,
    *,
    tracker: Any,
) -> tuple[Any, Any]:
    """Runs ``tracker`` over the frames with ``lax.scan``: ``(final state, per-frame info)``.

    Args:
        key: PRNG key (split into the init's and one per frame).
        images: ``uint8 [T, H, W, 3]`` RGB frames.
        q: the reference histogram ``[m]``.
        start_uv: the object's centre ``(u, v)`` in the first frame, pixels.
        half_size: the window's half-size, scalar or ``[2]`` (half width, half height), pixels.
        params: the tracker's params.
        tracker: :class:`MeanShiftTracker`, :class:`KalmanMeanShiftTracker` or :class:`ColourParticleTracker`
            (static).

    Returns:
        The final state and the tracker's info ``NamedTuple`` with a leading ``T`` axis.
    """
    images = jnp.asarray(images)
    k_init, k_steps = jax.random.split(key)
    state = tracker.init(k_init, _window(start_uv, half_size, q), params)

    def body(state, inputs):
        k, image = inputs
        return tracker.step(k, state, image, params)

    return lax.scan(body, state, (jax.random.split(k_steps, images.shape[0]), images))


def track(
    key: PRNGKeyArray,
    images: UInt8[ArrayLike, "t h w 3"],
    q: Float[ArrayLike, " m"],
    start_uv: Float[ArrayLike, "2"],
    half_size: Float[ArrayLike, "*2"],
    params: Any,
    *,
    tracker: Any,
) -> Float[Array, "t 2"]:
    """The ``(u, v)`` that ``tracker`` reports for each frame, ``float32 [T, 2]`` (the jitted :func:`run`'s)."""
    return run(key, images, q, start_uv, half_size, params, tracker=tracker)[1].position


class SequenceTracker:
    """What every image-space tracker gets from the sequence runner: ``tracker.track(...)``, :func:`track` with
    this tracker (a base of the trackers; it holds no fields, so a frozen dataclass tracker still hashes by
    value as ``run``'s static argument)."""

    def track(
        self,
        key: PRNGKeyArray,
        images: UInt8[ArrayLike, "t h w 3"],
        q: Float[ArrayLike, " m"],
        start_uv: Float[ArrayLike, "2"],
        half_size: Float[ArrayLike, "*2"],
        params: Any,
    ) -> Float[Array, "t 2"]:
        """:func:`track` with this tracker."""
        return track(key, images, q, start_uv, half_size, params, tracker=self)
