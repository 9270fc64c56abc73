"""Baselines beside the filter, with the same ``init``/``step`` signature (see :mod:`heatpf_jax.rollout`).

The conventional particle filter is not here: it is the particle filter with the cluster-centre
source (:func:`heatpf_jax.presets.conventional_filter`).

The image-space colour trackers of Olufs et al.'s Table 1 live in their own modules:
:mod:`~heatpf_jax.baselines.image_window` (the first frame's window), :mod:`~heatpf_jax.baselines.image_sequences`
(``run``/``track`` over frames), :mod:`~heatpf_jax.baselines.opencv_mean_shift`,
:mod:`~heatpf_jax.baselines.mean_shift`, :mod:`~heatpf_jax.baselines.kalman_mean_shift` and
:mod:`~heatpf_jax.baselines.colour_particles`.
"""

from heatpf_jax.baselines.kalman import (
    KalmanEmissionParams,
    KalmanFilter,
    KalmanMotionParams,
    KalmanParams,
    KalmanState,
    kalman_init,
    kalman_log_likelihood,
    kalman_odometry,
    kalman_predict,
    kalman_update,
)

__all__ = [
    "KalmanEmissionParams",
    "KalmanFilter",
    "KalmanMotionParams",
    "KalmanParams",
    "KalmanState",
    "kalman_init",
    "kalman_log_likelihood",
    "kalman_odometry",
    "kalman_predict",
    "kalman_update",
]


def __getattr__(name: str):
    """``heatpf_jax.baselines.image_trackers``, split by idea in 0.2, still imports (with a warning) until 0.3."""
    if name == "image_trackers":
        from heatpf_jax._moved import moved_module

        return moved_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
