"""Baselines beside the filter, with the same ``init``/``step`` signature (see :mod:`heatpf_jax.rollout`).

The conventional particle filter is not here: it is the particle filter with the cluster-centre
source (:func:`heatpf_jax.presets.conventional_filter`).
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
