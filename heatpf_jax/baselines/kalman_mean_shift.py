"""The paper's "Mean Shift + KL": mean shift seeded by a constant-velocity Kalman filter in pixels.

:class:`KalmanMeanShiftTracker` ("Mean Shift + KL"): a constant-velocity Kalman filter in pixels
(:func:`heatpf_jax.baselines.kalman_predict` / ``kalman_update`` with ``dt = 1`` frame) whose
prediction seeds the mean-shift search (:class:`heatpf_jax.baselines.mean_shift.MeanShiftTracker`) and
whose update takes the search's result.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray, UInt8

from heatpf_jax.baselines.image_sequences import SequenceTracker
from heatpf_jax.baselines.image_window import _F32, Window, _clip_to_image
from heatpf_jax.baselines.kalman import KalmanState, kalman_predict, kalman_update
from heatpf_jax.baselines.mean_shift import MeanShiftParams, MeanShiftTracker
from heatpf_jax.params import make_params, nonnegative, positive

__all__ = [
    "KalmanMeanShiftInfo",
    "KalmanMeanShiftParams",
    "KalmanMeanShiftState",
    "KalmanMeanShiftTracker",
]


class KalmanMeanShiftParams(NamedTuple):
    """Numbers of :class:`KalmanMeanShiftTracker`.

    Attributes:
        mean_shift: the search's :class:`MeanShiftParams`.
        accel_std: white-noise acceleration, pixels / frame^2.
        meas_std: std of the mean-shift result, pixels.
        init_position_std: prior std of the first position, pixels.
        init_velocity_std: prior std of the first velocity, pixels / frame.
    """

    mean_shift: MeanShiftParams = MeanShiftParams()
    accel_std: float = 1.0
    meas_std: float = 2.0
    init_position_std: float = 2.0
    init_velocity_std: float = 3.0


class KalmanMeanShiftState(NamedTuple):
    """The Kalman state ``(u, v, du, dv)`` (mean ``[4]``, covariance ``[4, 4]``), half-size ``[2]``, ``q [m]``."""

    kalman: KalmanState
    half_size: Float[Array, "2"]
    reference: Float[Array, " m"]


class KalmanMeanShiftInfo(NamedTuple):
    """One frame's result.

    Attributes:
        position: the filtered ``(u, v)``, shape ``[2]``.
        measurement: the mean-shift result ``(u, v)`` the update took, shape ``[2]``.
        rho: Bhattacharyya coefficient at the measurement.
        iterations: mean-shift iterations done.
        found: whether the window held any reference colour (else the filter only predicted).
    """

    position: Float[Array, "2"]
    measurement: Float[Array, "2"]
    rho: Float[Array, ""]
    iterations: Int[Array, ""]
    found: Bool[Array, ""]


@dataclass(frozen=True)
class KalmanMeanShiftTracker(SequenceTracker):
    """The paper's "Mean Shift + KL": mean shift seeded by a constant-velocity Kalman filter, which takes its result.

    Per frame: predict (``F`` = constant velocity over one frame, white-noise acceleration ``accel_std``);
    mean shift from the predicted position (clipped to the image); update with the converged centre as the
    measurement (noise ``meas_std``), skipped when the window holds none of the reference's colours. The
    filtered position is kept in the image, the velocity along a bound it hits set to 0 (no-ops while the
    object is inside).

    Attributes:
        mean_shift: the search (its bins, iterations, window bound, scale adaptation).
    """

    mean_shift: MeanShiftTracker = MeanShiftTracker()

    def default_params(self) -> KalmanMeanShiftParams:
        return KalmanMeanShiftParams(mean_shift=self.mean_shift.default_params())

    def properties(self) -> KalmanMeanShiftParams:
        return KalmanMeanShiftParams(
            mean_shift=self.mean_shift.properties(),
            accel_std=nonnegative(),
            meas_std=positive(),
            init_position_std=positive(),
            init_velocity_std=positive(),
        )

    def make_params(self, updates: dict | None = None, /, **names) -> KalmanMeanShiftParams:
        """Default params with some replaced by (dotted or unambiguous short) name."""
        return make_params(self, updates, **names)

    def init(self, key: PRNGKeyArray, first_window: Window, params: KalmanMeanShiftParams) -> KalmanMeanShiftState:
        """Prior ``N((u, v, 0, 0), diag(s_p^2, s_p^2, s_v^2, s_v^2))`` at the first window (key unused)."""
        del key
        pos_var = jnp.square(jnp.asarray(params.init_position_std, _F32))
        vel_var = jnp.square(jnp.asarray(params.init_velocity_std, _F32))
        mean = jnp.concatenate([jnp.asarray(first_window.centre, _F32), jnp.zeros((2,), _F32)])
        cov = jnp.diag(jnp.stack([pos_var, pos_var, vel_var, vel_var]))
        return KalmanMeanShiftState(
            kalman=KalmanState(mean=mean, cov=cov),
            half_size=self.mean_shift._clip_half(jnp.asarray(first_window.half_size, _F32)),
            reference=jnp.asarray(first_window.reference, _F32),
        )

    def step(
        self,
        key: PRNGKeyArray,
        state: KalmanMeanShiftState,
        image: UInt8[ArrayLike, "h w 3"],
        params: KalmanMeanShiftParams,
    ) -> tuple[KalmanMeanShiftState, KalmanMeanShiftInfo]:
        """Predict, search from the prediction, update with the search's result."""
        del key
        image = jnp.asarray(image)
        predicted = kalman_predict(state.kalman, jnp.float32(1.0), jnp.asarray(params.accel_std, _F32))
        padded = self.mean_shift.padded_bins(image)
        z, half, rho, iterations = self.mean_shift.search(
            padded, predicted.mean[:2], state.half_size, state.reference, params.mean_shift
        )
        found = rho > 0.0
        updated = kalman_update(predicted, z, found, jnp.asarray(params.meas_std, _F32))
        pos = _clip_to_image(updated.mean[:2], image.shape)
        vel = jnp.where(pos != updated.mean[:2], 0.0, updated.mean[2:])
        kalman = KalmanState(mean=jnp.concatenate([pos, vel]), cov=updated.cov)
        info = KalmanMeanShiftInfo(position=pos, measurement=z, rho=rho, iterations=iterations, found=found)
        return KalmanMeanShiftState(kalman=kalman, half_size=half, reference=state.reference), info

