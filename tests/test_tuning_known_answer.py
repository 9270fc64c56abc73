"""Known answer of the gradient estimators (CI size): a 2-D random walk seen through one exact pixel.

The exact gradient of the mean log-likelihood and of the mean squared error of the posterior mean with respect
to ``(log q, log r)`` comes from ``jax.grad`` through a float64 Kalman filter; the particle filter's estimate
with stop-gradient resampling and score-form motion gradients must agree (mean over seeds within 15 % relative
and 4 standard errors), and the plain-detach control must not. The issue's size (64 seeds, N = 1024,
T = 300) is ``python benchmarks/gradients.py``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.rollout import prepare_run, run_core
from heatpf_jax.sim.linear_gaussian import kalman_losses, linear_gaussian_filter, simulate_linear_gaussian

Q, R = 0.4, 0.8
STEPS, PARTICLES, SEEDS, BURN_IN = 50, 512, 32, 10
THETA0 = np.log([Q, R]) + np.array([0.5, -0.5])


@pytest.fixture(scope="module")
def problem():
    seq = simulate_linear_gaussian(0, STEPS, Q, R)
    z = np.asarray(seq.cam_to_base[:, :2, 3], np.float64)
    truth = np.asarray(seq.ground_truth, np.float64)
    with jax.enable_x64(True):
        theta = jnp.asarray(THETA0, jnp.float64)
        exact = [np.asarray(jax.grad(lambda t, i=i: kalman_losses(t, z, truth, BURN_IN)[i])(theta)) for i in (0, 1)]
    # The float64 Kalman filter against a NumPy one (values), so the reference itself is checked.
    m, p, lls = np.zeros(2), 1e6, []
    q2, r2 = np.exp(2 * THETA0)
    for zt in z:
        p += q2
        s = p + r2
        lls.append(-np.log(2 * np.pi * s) - 0.5 * np.sum((zt - m) ** 2) / s)
        m, p = m + p / s * (zt - m), (1 - p / s) * p
    with jax.enable_x64(True):
        ll, _ = kalman_losses(jnp.asarray(THETA0), z, truth, BURN_IN)
    np.testing.assert_allclose(float(ll), np.mean(lls[BURN_IN:]), rtol=1e-12)
    return seq, exact


@functools.partial(jax.jit, static_argnames="model")
def _gradients(keys, seq, truth, params, theta, model):
    props = model.properties()

    def losses(th, key):
        p = P.set_by_name(params, props, {"diffusion_std": jnp.exp(th[0]), "obs_std": jnp.exp(th[1])})
        info = run_core(key, seq, p, model).info
        return -hp.nll_loss(info, None, BURN_IN), hp.mse_loss(info, truth, BURN_IN)

    return jax.vmap(lambda k: jax.jacrev(losses)(theta, k))(keys)


def _estimate(problem, seeds=SEEDS, **gradients):
    seq, exact = problem
    base, params = linear_gaussian_filter(PARTICLES)
    model = hp.differentiable(base, **gradients)
    s, p = prepare_run(seq, params, model)
    keys = jax.random.split(jax.random.key(1), seeds)
    grads = _gradients(keys, s, jnp.asarray(seq.ground_truth, jnp.float32), p, jnp.asarray(THETA0, jnp.float32), model)
    out = []
    for est, ref in zip(grads, exact, strict=True):
        est = np.asarray(est, np.float64)
        assert np.all(np.isfinite(est))
        mean, se = est.mean(0), est.std(0, ddof=1) / np.sqrt(seeds)
        err = np.abs(mean - ref)
        out.append((mean, se, ref, (err <= 0.15 * np.abs(ref)) & (err <= 4 * se)))
    return out


def test_stop_gradient_score_matches_the_exact_gradient(problem):
    for name, (mean, se, ref, ok) in zip(("log-likelihood", "mse"), _estimate(problem), strict=True):
        print(f"\n{name}: estimate {mean} +- {se}, exact {ref}")
        assert ok.all(), (name, mean, se, ref)


def test_plain_detach_fails_the_same_check(problem):
    results = _estimate(problem, seeds=8, resampling="detach")
    # The control is wrong by far more than the tolerance: the check has power.
    assert not all(ok.all() for *_, ok in results)
    mean, _, ref, _ = results[0]
    assert np.max(np.abs(mean - ref) / np.abs(ref)) > 0.5
