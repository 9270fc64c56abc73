"""The Kalman baseline: a constant-velocity Kalman filter on the conventional measurement.

What the original team ships today: one point per heat map (the centre of the
strongest image-space cluster, :mod:`heatpf_jax.sources.image_components`) filtered by a
constant-velocity Kalman filter in the robot's base frame. Configured like the
heat-map filter (the same threshold, odometry noise and projection) and
differing only where the method does:

* state ``(x, y, vx, vy)`` with white-noise acceleration ``accel_std``
  (m/s^2) over the sequence's ``dt``;
* odometry moves the state into the new base frame (position ``R^T (p - d)``,
  velocity ``R^T v``) and adds the odometry noise of the particle filter to
  the position covariance, to first order;
* a measurement (when the heat map yields one) updates with isotropic noise
  ``meas_std`` (m); without one the filter only predicts.

:class:`KalmanFilter` is the model: the same ``init``/``step`` signature as the particle filter
(its PRNG keys are ignored), so :func:`heatpf_jax.run` and the sweeps run it unchanged.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray

from heatpf_jax.estimate.modes import Modes
from heatpf_jax.filter import StepInfo
from heatpf_jax.injection.explorers import UniformBox
from heatpf_jax.measurements import empty_measurements
from heatpf_jax.memory.table import empty_tracks
from heatpf_jax.params import make_params, nonnegative, positive
from heatpf_jax.pieces import StepInputs
from heatpf_jax.sources.pixels import ClusterCentreSource, SourceParams

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

_H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0]], np.float32)  # NumPy: no device work at import


class KalmanState(NamedTuple):
    """Mean ``[4]`` = (x, y, vx, vy) and covariance ``[4, 4]``."""

    mean: Float[Array, "4"]
    cov: Float[Array, "4 4"]


def kalman_init(
    centre: Float[ArrayLike, "2"], position_std: Float[ArrayLike, ""], speed_std: float = 3.0
) -> KalmanState:
    """A broad prior: position ``N(centre, position_std^2 I)``, velocity ``N(0, speed_std^2 I)``."""
    centre = jnp.asarray(centre, jnp.float32)
    var = jnp.stack([position_std**2, position_std**2, jnp.float32(speed_std**2), jnp.float32(speed_std**2)])
    return KalmanState(mean=jnp.concatenate([centre, jnp.zeros((2,), jnp.float32)]), cov=jnp.diag(var))


def kalman_odometry(
    state: KalmanState,
    odometry: Float[ArrayLike, "3"],
    trans_noise: Float[ArrayLike, ""],
    rot_noise: Float[ArrayLike, ""],
) -> KalmanState:
    """Expresses the state in the base frame after ``odometry`` (dx, dy, dtheta), adding odometry noise."""
    odometry = jnp.asarray(odometry, jnp.float32)
    c, s = jnp.cos(odometry[2]), jnp.sin(odometry[2])
    rt = jnp.stack([jnp.stack([c, s]), jnp.stack([-s, c])])  # R(dtheta)^T
    zero = jnp.zeros((2, 2), jnp.float32)
    big = jnp.block([[rt, zero], [zero, rt]])
    pos = rt @ (state.mean[:2] - odometry[:2])
    vel = rt @ state.mean[2:]
    cov = big @ state.cov @ big.T
    sq = odometry[0] ** 2 + odometry[1] ** 2
    dist = jnp.where(sq > 0.0, jnp.sqrt(jnp.where(sq > 0.0, sq, 1.0)), 0.0)
    perp = jnp.stack([-pos[1], pos[0]])  # d position / d dtheta, to first order
    pos_noise = (trans_noise * dist) ** 2 * jnp.eye(2, dtype=jnp.float32) + (rot_noise * jnp.abs(odometry[2])) ** 2 * (
        perp[:, None] * perp[None, :]
    )
    cov = cov.at[:2, :2].add(pos_noise)
    return KalmanState(mean=jnp.concatenate([pos, vel]), cov=cov)


def kalman_predict(state: KalmanState, dt: Float[ArrayLike, ""], accel_std: Float[ArrayLike, ""]) -> KalmanState:
    """Constant-velocity prediction with white-noise acceleration."""
    eye = jnp.eye(2, dtype=jnp.float32)
    zero = jnp.zeros((2, 2), jnp.float32)
    f = jnp.block([[eye, dt * eye], [zero, eye]])
    q = accel_std**2 * jnp.block([[dt**4 / 4 * eye, dt**3 / 2 * eye], [dt**3 / 2 * eye, dt**2 * eye]])
    return KalmanState(mean=f @ state.mean, cov=f @ state.cov @ f.T + q)


def kalman_update(
    state: KalmanState, z: Float[ArrayLike, "2"], has_z: Bool[ArrayLike, ""], meas_std: Float[ArrayLike, ""]
) -> KalmanState:
    """Standard update with ``z = (x, y) + N(0, meas_std^2 I)``; a no-op when ``has_z`` is False.

    Uses the Joseph form so the covariance stays symmetric positive definite in float32.
    """
    z = jnp.asarray(z, jnp.float32)
    r = meas_std**2 * jnp.eye(2, dtype=jnp.float32)
    s = _H @ state.cov @ _H.T + r
    gain = jnp.linalg.solve(s, _H @ state.cov).T  # P H^T S^-1 (S symmetric)
    mean = state.mean + gain @ (z - _H @ state.mean)
    a = jnp.eye(4, dtype=jnp.float32) - gain @ _H
    cov = a @ state.cov @ a.T + gain @ r @ gain.T
    cov = 0.5 * (cov + cov.T)
    has_z = jnp.asarray(has_z)
    return KalmanState(mean=jnp.where(has_z, mean, state.mean), cov=jnp.where(has_z, cov, state.cov))


def kalman_log_likelihood(
    state: KalmanState, z: Float[ArrayLike, "2"], meas_std: Float[ArrayLike, ""]
) -> Float[Array, ""]:
    """``log N(z; H m, H P H^T + meas_std^2 I)``: the predictive log-likelihood of a measurement."""
    z = jnp.asarray(z, jnp.float32)
    s = _H @ state.cov @ _H.T + meas_std**2 * jnp.eye(2, dtype=jnp.float32)
    innovation = z - _H @ state.mean
    _, logdet = jnp.linalg.slogdet(s)
    return -0.5 * (innovation @ jnp.linalg.solve(s, innovation) + logdet + 2.0 * math.log(2.0 * math.pi))


class KalmanMotionParams(NamedTuple):
    """Motion numbers of the Kalman baseline.

    Attributes:
        accel_std: white-noise acceleration, m/s^2.
        odom_trans_noise: odometry translation noise, a fraction of the distance moved.
        odom_rot_noise: odometry rotation noise, a fraction of the angle turned.
    """

    accel_std: float = 3.0
    odom_trans_noise: float = 0.1
    odom_rot_noise: float = 0.1


class KalmanEmissionParams(NamedTuple):
    """Measurement numbers of the Kalman baseline.

    Attributes:
        meas_std: isotropic measurement noise, metres.
    """

    meas_std: float = 0.1


class KalmanParams(NamedTuple):
    """Every number of :class:`KalmanFilter` (dynamax's ``(initial, dynamics, emissions)`` shape)."""

    source: SourceParams = SourceParams()
    motion: KalmanMotionParams = KalmanMotionParams()
    emission: KalmanEmissionParams = KalmanEmissionParams()


class KalmanFilter(NamedTuple):
    """The constant-velocity Kalman baseline on the conventional measurement, as a model for :func:`heatpf_jax.run`.

    Attributes:
        source: where its one measurement per heat map comes from.
        initial: its prior is centred on this box, with a std of half its larger side.
    """

    source: ClusterCentreSource = ClusterCentreSource()
    initial: UniformBox = UniformBox()

    def default_params(self) -> KalmanParams:
        return KalmanParams(source=self.source.default_params())

    def properties(self) -> KalmanParams:
        return KalmanParams(
            source=self.source.properties(),
            motion=KalmanMotionParams(accel_std=nonnegative(), odom_trans_noise=nonnegative(),
                                      odom_rot_noise=nonnegative()),
            emission=KalmanEmissionParams(meas_std=positive()),
        )

    def make_params(self, updates: dict | None = None, /, **names) -> KalmanParams:
        """Default params with some replaced by (dotted or unambiguous short) name."""
        return make_params(self, updates, **names)

    def validate(self) -> None:
        self.initial.validate()

    def init(self, key: PRNGKeyArray, params: KalmanParams) -> KalmanState:
        """The prior: centred on ``initial.box``, position std half its larger side, speed std 3 m/s."""
        del key, params
        x0, x1, y0, y1 = self.initial.box
        return kalman_init(
            jnp.array([(x0 + x1) / 2, (y0 + y1) / 2], jnp.float32), jnp.float32(max(x1 - x0, y1 - y0) / 2)
        )

    def step(
        self, key: PRNGKeyArray, state: KalmanState, inputs: StepInputs, params: KalmanParams
    ) -> tuple[KalmanState, StepInfo]:
        """Odometry, prediction, update with the cluster measurement. ``key`` is ignored.

        Its :class:`~heatpf_jax.filter.StepInfo` has ``ess = 0``, ``resampled = False``, no
        ancestors (shape ``[0]``), the predictive log-likelihood of the measurement, and its
        Gaussian as the one mode.
        """
        del key
        m = params.motion
        state = kalman_odometry(state, inputs.odometry, m.odom_trans_noise, m.odom_rot_noise)
        state = kalman_predict(state, inputs.dt, m.accel_std)
        new = lax.cond(
            inputs.has_heatmap,
            lambda _: self.source.measure(inputs, params.source),
            lambda _: empty_measurements(self.source.size),
            None,
        )
        z, has_z = new.xy[0], new.valid[0]
        log_likelihood = jnp.where(has_z, kalman_log_likelihood(state, z, params.emission.meas_std), 0.0)
        state = kalman_update(state, z, has_z, params.emission.meas_std)
        info = StepInfo(
            mean=state.mean[:2],
            cov=state.cov[:2, :2],
            weighted_mean=state.mean[:2],
            ess=jnp.zeros((), jnp.float32),
            num_valid=has_z.astype(jnp.int32),
            resampled=jnp.zeros((), bool),
            log_likelihood=log_likelihood,
            ancestors=jnp.zeros((0,), jnp.int32),
            modes=Modes(
                weight=jnp.ones((1,), jnp.float32),
                mean=state.mean[None, :2],
                cov=state.cov[None, :2, :2],
                valid=jnp.ones((1,), bool),
            ),
            tracks=empty_tracks(0),
        )
        return state, info
