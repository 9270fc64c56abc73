"""The Kalman baseline against a textbook NumPy Kalman filter, and the baselines on a standing ball."""

import jax
import numpy as np
import pytest
from scipy.stats import multivariate_normal

import heatpf_jax as hp
from heatpf_jax.baselines.kalman import (
    KalmanState,
    kalman_log_likelihood,
    kalman_odometry,
    kalman_predict,
    kalman_update,
)
from heatpf_jax.sim import render_heatmap
from tests.conftest import SMALL_OPTIONS

# Through `jit`, inputs in NumPy: run eagerly, each operation (even `jnp.asarray`) compiles a program of its own.
_predict = jax.jit(kalman_predict)
_update = jax.jit(kalman_update)
_odometry = jax.jit(kalman_odometry)
_log_likelihood = jax.jit(kalman_log_likelihood)


def _np_predict(m, p, dt, q):
    f = np.block([[np.eye(2), dt * np.eye(2)], [np.zeros((2, 2)), np.eye(2)]])
    qq = q**2 * np.block([[dt**4 / 4 * np.eye(2), dt**3 / 2 * np.eye(2)], [dt**3 / 2 * np.eye(2), dt**2 * np.eye(2)]])
    return f @ m, f @ p @ f.T + qq


def _np_update(m, p, z, r):
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    s = h @ p @ h.T + r**2 * np.eye(2)
    k = p @ h.T @ np.linalg.inv(s)
    return m + k @ (z - h @ m), (np.eye(4) - k @ h) @ p


def test_predict_update_sequence_matches_numpy():
    rng = np.random.default_rng(0)
    m = np.array([1.0, -0.5, 0.3, 0.1])
    a = rng.normal(size=(4, 4))
    p = a @ a.T * 0.1 + 0.05 * np.eye(4)
    state = KalmanState(m.astype(np.float32), p.astype(np.float32))
    for t in range(15):
        z = rng.normal(size=2)
        has = t % 3 != 2
        m, p = _np_predict(m, p, 0.1, 2.0)
        if has:
            m, p = _np_update(m, p, z, 0.15)
        state = _predict(state, np.float32(0.1), np.float32(2.0))
        state = _update(state, z.astype(np.float32), np.asarray(has), np.float32(0.15))
    np.testing.assert_allclose(np.asarray(state.mean), m, rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(np.asarray(state.cov), p, rtol=1e-3, atol=1e-6)


def test_odometry_moves_mean_like_world_fixed_points():
    m = np.array([2.0, 1.0, 0.5, -0.2])
    p = np.diag([0.1, 0.2, 0.3, 0.4])
    odo = np.array([0.3, -0.1, 0.2])
    start = KalmanState(m.astype(np.float32), p.astype(np.float32))
    out = jax.tree.map(np.asarray, _odometry(start, odo.astype(np.float32), np.float32(0.0), np.float32(0.0)))
    c, s = np.cos(odo[2]), np.sin(odo[2])
    rt = np.array([[c, s], [-s, c]])
    np.testing.assert_allclose(np.asarray(out.mean[:2]), rt @ (m[:2] - odo[:2]), rtol=1e-5)
    np.testing.assert_allclose(np.asarray(out.mean[2:]), rt @ m[2:], rtol=1e-5)
    big = np.block([[rt, np.zeros((2, 2))], [np.zeros((2, 2)), rt]])
    np.testing.assert_allclose(np.asarray(out.cov), big @ p @ big.T, rtol=1e-5, atol=1e-7)
    noisy = jax.tree.map(np.asarray, _odometry(start, odo.astype(np.float32), np.float32(0.1), np.float32(0.1)))
    assert np.all(np.linalg.eigvalsh(np.asarray(noisy.cov - out.cov)) > -1e-7)  # noise only adds uncertainty


def test_log_likelihood_matches_scipy():
    rng = np.random.default_rng(1)
    for _ in range(20):
        m = rng.normal(size=4)
        a = rng.normal(size=(4, 4))
        p = a @ a.T * 0.1 + 0.05 * np.eye(4)
        z = m[:2] + rng.normal(size=2)
        r = rng.uniform(0.05, 0.5)
        state = KalmanState(m.astype(np.float32), p.astype(np.float32))
        got = _log_likelihood(state, z.astype(np.float32), np.float32(r))
        want = multivariate_normal.logpdf(z, mean=m[:2], cov=p[:2, :2] + r**2 * np.eye(2))
        np.testing.assert_allclose(float(got), want, rtol=1e-4, atol=1e-4)


@pytest.fixture(scope="module")
def standing_ball():
    rng = np.random.default_rng(5)
    intr = np.array([143.0, 143.0, 99.5, 74.5]) / np.array([4, 4, 4, 4]) - np.array([0, 0, 0.375, 0.375])
    pose = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    ball = np.array([2.0, -0.4])
    t = 20  # the shapes of conftest's small_sequence: the filters' programs are those other tests compile
    heat = np.stack([render_heatmap(rng, ball, intr, pose, shape=(37, 50)) for _ in range(t)])
    return hp.Sequence(heatmaps=heat, has_heatmap=np.ones(t, bool), intrinsics=intr,
                       cam_to_base=np.repeat(pose[None], t, 0), odometry=np.zeros((t, 3)),
                       ball_radius=np.asarray(0.075), dt=np.asarray(0.1), ground_truth=np.repeat(ball[None], t, 0))


@pytest.mark.parametrize("method", ["conventional", "kalman", "heatmap"])
def test_baselines_recover_a_standing_ball(standing_ball, method):
    model, params = hp.build(method, SMALL_OPTIONS)
    result = hp.run(jax.random.key(0), standing_ball, params, model)
    err = np.linalg.norm(np.asarray(result.info.mean) - standing_ball.ground_truth, axis=1)
    assert np.all(np.isfinite(err))
    assert err[-10:].mean() < 0.04, (method, err[-10:])  # measured, keys 0-4: 0.015-0.022, 0.008, 0.016-0.026 m
    valid = np.asarray(result.info.num_valid)
    if method != "heatmap":
        assert set(valid.tolist()) <= {0, 1} and valid.sum() >= 15  # one measurement per heat map


def test_kalman_step_log_likelihood_is_zero_without_a_heat_map(standing_ball):
    """The per-step predictive log-likelihood: finite everywhere, exactly 0 on steps without a heat map."""
    t = 12
    has = np.arange(t) % 3 != 1  # every third step without a heat map
    seq = standing_ball._replace(
        heatmaps=standing_ball.heatmaps[:t], has_heatmap=has, cam_to_base=standing_ball.cam_to_base[:t],
        odometry=standing_ball.odometry[:t], ground_truth=standing_ball.ground_truth[:t],
    )
    model, params = hp.build("kalman", SMALL_OPTIONS)
    info = hp.run(jax.random.key(0), seq, params, model).info
    ll = np.asarray(info.log_likelihood)
    valid = np.asarray(info.num_valid)
    assert ll.shape == (t,) and np.all(np.isfinite(ll))
    assert np.all(ll[~has] == 0.0) and np.all(valid[~has] == 0)
    assert np.all(valid[has] == 1) and np.all(ll[has] != 0.0)  # each heat map gives its measurement
