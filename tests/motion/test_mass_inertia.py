"""Olufs et al.'s mass-inertia motion model (eq. 4-6) against NumPy references: exact kinematics without
noise, uniform spreads whose width follows (1.1 - pi'), the stored score, and a filter run with gradients."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy import stats

import heatpf_jax as hp
from heatpf_jax.motion.mass_inertia import InertiaParticles, MassInertia, MassInertiaParams, normalised_score
from tests.conftest import SMALL_OPTIONS, blank_inputs

# The model's methods, one program each (shared by the tests): run eagerly, each of their operations would
# compile on its own. Their inputs are NumPy, as eager `jnp` conversions compile a program each too.
_predict = jax.jit(MassInertia().predict)
_spawn = jax.jit(MassInertia().spawn)
_score = jax.jit(normalised_score)


def test_noise_free_step_is_exact_kinematics_with_odometry(rng):
    xy = rng.normal(size=(50, 2)).astype(np.float32)
    v = rng.normal(size=(50, 2)).astype(np.float32)
    score = rng.uniform(size=50).astype(np.float32)
    odom = np.array([0.2, -0.05, 0.3])
    quiet = MassInertiaParams(rho_move=0.0, rho_position=0.0, noise=0.0, odom_trans_noise=0.0, odom_rot_noise=0.0)
    start = InertiaParticles(xy, v, score)
    out = _predict(jax.random.key(0), start, blank_inputs(odom, 0.25), quiet)
    c, s = np.cos(0.3), np.sin(0.3)
    rt = np.array([[c, s], [-s, c]])
    v_new = v.astype(np.float64) @ rt.T
    xy_new = (xy.astype(np.float64) - odom[:2]) @ rt.T + 0.25 * v_new  # eq. 5: p += v (per step)
    np.testing.assert_allclose(np.asarray(out.v), v_new, atol=1e-5)
    np.testing.assert_allclose(np.asarray(out.xy), xy_new, atol=1e-5)
    np.testing.assert_array_equal(np.asarray(out.score), score)


@pytest.mark.parametrize("score", [0.0, 0.6, 1.0])
def test_spreads_are_uniform_with_width_following_the_weight(score):
    """Eq. 6: velocity change ~ U(-a, a) with a = (1.1 - pi') rho_move / dt; position adds
    (1.1 - pi') rho_position U + noise U. Kolmogorov-Smirnov against scipy's uniform and triangular-free sums."""
    n, dt = 20_000, 0.1
    params = MassInertiaParams(rho_move=0.2, rho_position=0.0, noise=0.0, odom_trans_noise=0.0, odom_rot_noise=0.0)
    start = InertiaParticles(np.zeros((n, 2), np.float32), np.zeros((n, 2), np.float32),
                             np.full((n,), score, np.float32))
    out = _predict(jax.random.key(1), start, blank_inputs(dt=dt), params)
    a = (1.1 - score) * 0.2 / dt
    dv = np.asarray(out.v, np.float64)
    for col in range(2):
        assert stats.kstest(dv[:, col], stats.uniform(loc=-a, scale=2 * a).cdf).pvalue > 1e-3
    np.testing.assert_allclose(np.asarray(out.xy), 0.0, atol=1e-7)  # the new velocity moves it next step
    # Position spread alone: (1.1 - pi') rho_position U, here with rho_position = 0.3.
    params = params._replace(rho_move=1e-6, rho_position=0.3)
    out = _predict(jax.random.key(2), start, blank_inputs(dt=dt), params)
    b = (1.1 - score) * 0.3
    assert stats.kstest(np.asarray(out.xy, np.float64)[:, 0], stats.uniform(loc=-b, scale=2 * b).cdf).pvalue > 1e-3


def test_normalised_score_and_spawn():
    w = np.asarray([0.1, 0.4, 0.2, 0.3], np.float32)
    np.testing.assert_allclose(np.asarray(_score(w)), [0.25, 1.0, 0.5, 0.75], rtol=1e-6)
    assert np.all(np.asarray(_score(np.zeros(3, np.float32))) == 0.0)
    new = _spawn(jax.random.key(0), np.ones((5, 2), np.float32), MassInertiaParams())
    assert np.all(np.asarray(new.v) == 0.0) and np.all(np.asarray(new.score) == 0.0)  # Olufs: start at zero


def test_filter_run_keeps_scores(small_sequence):
    model = hp.paper_filter(SMALL_OPTIONS)._replace(motion=MassInertia(), injectors=())
    params = model.default_params()
    res = hp.run(jax.random.key(0), small_sequence, params, model)
    score = np.asarray(res.final_state.particles.score)
    # Systematic resampling always copies the best particle (weight >= 1/N), whose pi' is exactly 1.
    assert score.max() == 1.0 and score.min() >= 0.0
    anc = np.asarray(res.info.ancestors)[-1]  # indexed in NumPy: a JAX index compiles a program
    for a in np.unique(anc):  # copies of one particle inherit one score
        assert np.unique(score[anc == a]).size == 1
    err = np.linalg.norm(np.asarray(res.info.mean) - small_sequence.ground_truth, axis=1)[-10:].mean()
    assert err < 0.25, err

    # Gradients of a run with this motion model: tests/test_method_gradients.py (the extended method).
