"""The constant-velocity motion model against NumPy references: exact kinematics without noise, the
white-noise-acceleration covariance of the Kalman baseline, odometry on positions and velocities."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.baselines.kalman import KalmanState, kalman_predict
from heatpf_jax.motion.constant_velocity import ConstantVelocity, ConstantVelocityParams, VelocityParticles
from tests.conftest import blank_inputs

# Through `jit`, Python-float numbers static as they are eagerly: run eagerly, each operation compiles on its own.
_kalman_predict = jax.jit(kalman_predict, static_argnums=(1, 2))


@partial(jax.jit, static_argnames="params")
def _predict(key, particles, inputs, params):
    return ConstantVelocity().predict(key, particles, inputs, params)


def test_noise_free_step_is_exact_kinematics_with_odometry(rng):
    xy = rng.normal(size=(50, 2)).astype(np.float32)
    v = rng.normal(size=(50, 2)).astype(np.float32)
    odom = np.array([0.2, -0.05, 0.3])
    quiet = ConstantVelocityParams(0.0, 0.0, 0.0, 0.0, 0.0)
    out = _predict(jax.random.key(0), VelocityParticles(xy, v), blank_inputs(odom, 0.25), quiet)
    c, s = np.cos(0.3), np.sin(0.3)
    rt = np.array([[c, s], [-s, c]])
    v_new = v.astype(np.float64) @ rt.T
    xy_new = (xy.astype(np.float64) - odom[:2]) @ rt.T + 0.25 * v_new
    np.testing.assert_allclose(np.asarray(out.v), v_new, atol=1e-5)
    np.testing.assert_allclose(np.asarray(out.xy), xy_new, atol=1e-5)


def test_process_noise_matches_the_kalman_baseline():
    """Sample covariance of (x, vx) after one step from a point equals the Kalman predict's Q."""
    n = 200_000
    params = ConstantVelocityParams(accel_std=2.0, diffusion_std=0.0, odom_trans_noise=0.0, odom_rot_noise=0.0,
                                    spawn_speed_std=0.0)
    start = VelocityParticles(np.zeros((n, 2), np.float32), np.zeros((n, 2), np.float32))
    out = _predict(jax.random.key(1), start, blank_inputs(dt=0.2), params)
    samples = np.concatenate([np.asarray(out.xy), np.asarray(out.v)], axis=1).astype(np.float64)
    cov = np.cov(samples.T)
    q = np.asarray(_kalman_predict(KalmanState(np.zeros(4, np.float32), np.zeros((4, 4), np.float32)), 0.2, 2.0).cov,
                   np.float64)
    # Sampling error of a covariance entry: about sqrt(2 / n) sqrt(q_ii q_jj); allow 4 of them.
    tol = 4 * np.sqrt(2.0 / n) * np.sqrt(np.outer(np.diag(q), np.diag(q))) + 1e-9
    assert np.all(np.abs(cov - q) <= tol), (cov, q)
    assert q[0, 2] > 0 and abs(cov[0, 2] - q[0, 2]) < 0.05 * q[0, 2]  # position-velocity correlation


def test_spawn_and_filter_run(small_sequence):
    model = hp.paper_filter(hp.FilterOptions(num_particles=128, max_measurements=128, k_max=8))
    model = model._replace(motion=ConstantVelocity())
    params = model.default_params()
    spawn_std = jax.jit(lambda key, xy, p: jnp.std(model.motion.spawn(key, xy, p).v))  # one program, as above
    assert float(spawn_std(jax.random.key(2), np.zeros((4000, 2), np.float32), params.motion)) == pytest.approx(
        1.0, rel=0.05)
    res = hp.run(jax.random.key(0), small_sequence, params, model)
    assert res.final_state.particles.v.shape == (128, 2)
    err = np.linalg.norm(np.asarray(res.info.mean) - small_sequence.ground_truth, axis=1)[-10:].mean()
    assert err < 0.2, err

    # Gradients of a run with this motion model: tests/test_method_gradients.py (the heatmap method).
