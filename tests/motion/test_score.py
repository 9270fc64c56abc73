"""Score-form motion gradients: the Gaussian split of every motion model reproduces its ``predict``; the
score wrapper moves the particles exactly as the model does, with a zero-valued log weight whose gradient is
the analytic Gaussian score (NumPy); and the differentiable filter's forward pass is the ordinary filter's."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.motion.random_walk import DiffusionParams
from heatpf_jax.motion.score import ScoredParticles, ScoreMotion, gaussian_log_score
from heatpf_jax.tuning import Checkpointed, differentiable
from tests.conftest import SMALL_OPTIONS, step_inputs

N = 64
ODOMETRY = (0.3, -0.2, 0.15)

MODELS = {
    "random_walk": (hp.motion.RandomWalk(), hp.motion.RandomWalkParams(diffusion_std=0.07, odom_trans_noise=0.2,
                                                          odom_rot_noise=0.3)),
    "diffusion_only": (hp.motion.DiffusionOnly(), DiffusionParams(diffusion_std=0.13)),
    "constant_velocity": (hp.motion.ConstantVelocity(), hp.motion.ConstantVelocityParams(
        accel_std=2.5, diffusion_std=0.04, odom_trans_noise=0.15, odom_rot_noise=0.25, spawn_speed_std=1.5)),
}


def _start(motion, params, seed):
    k_xy, k_spawn = jax.random.split(jax.random.key(seed))
    xy = jax.random.uniform(k_xy, (N, 2), jnp.float32, -3.0, 3.0)
    return motion.spawn(k_spawn, xy, params)


@functools.partial(jax.jit, static_argnames="motion")
def _moves(motion, key, particles, inputs, params):
    """One program per model: its predict, the Gaussian split, the score wrapper, and the wrapper's gradients."""
    std = motion.noise_std(particles, inputs, params)
    normal = jax.random.normal(key, (N, std.shape[-1]), jnp.float32)
    scored = ScoreMotion(motion)
    start = ScoredParticles(state=particles, log_transition=jnp.zeros((N,), jnp.float32))

    def positions(p):
        return jnp.sum(scored.predict(key, start, inputs, p).xy)

    def log_weight(p):
        return jnp.sum(scored.predict(key, start, inputs, p).log_transition)

    return {
        "std": std,
        "normal": normal,
        "std_jacobian": jax.jacobian(lambda p: motion.noise_std(particles, inputs, p)[0])(params),
        "direct": motion.predict(key, particles, inputs, params),
        "split": motion.transition(particles, std * normal, inputs, params),
        "scored": scored.predict(key, start, inputs, params),
        "grad_positions": jax.grad(positions)(params),
        "grad_log_weight": jax.grad(log_weight)(params),
    }


def _assert_close(got, want):
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_gaussian_split_and_score_wrapper_reproduce_predict(small_sequence, name):
    motion, params = MODELS[name]
    params = jax.tree.map(lambda v: jnp.asarray(v, jnp.float32), params)
    particles = _start(motion, params, 1)
    inputs = step_inputs(small_sequence, 1, odometry=ODOMETRY)
    ScoreMotion(motion).validate()
    out = _moves(motion, jax.random.key(7), particles, inputs, params)
    assert out["std"].shape[0] == 1 and np.all(np.asarray(out["std"]) > 0)  # every component moves here
    # Not a no-op: the particles moved.
    assert np.max(np.abs(np.asarray(out["direct"].xy) - np.asarray(particles.xy))) > 1e-2
    # transition(p, noise_std * normal) == predict(key, p) for the key's normals.
    _assert_close(out["split"], out["direct"])
    # The score wrapper moves the particles as the model does, with a log weight that is zero in value.
    _assert_close(out["scored"].state, out["direct"])
    np.testing.assert_array_equal(np.asarray(out["scored"].xy), np.asarray(out["scored"].state.xy))
    assert out["scored"].log_transition.shape == (N,)
    np.testing.assert_array_equal(np.asarray(out["scored"].log_transition), np.zeros(N, np.float32))
    # Its positions carry no gradient of the noise parameters; its log weight carries the Gaussian score
    # sum_ij (n_ij^2 - 1) / sigma_j d sigma_j / d theta (NumPy, with the stds' Jacobian).
    assert all(float(g) == 0.0 for g in jax.tree.leaves(out["grad_positions"]))
    n = np.asarray(out["normal"], np.float64)
    score = np.sum(n**2 - 1.0, axis=0) / np.asarray(out["std"], np.float64)[0]
    grads = jax.tree.leaves(out["grad_log_weight"])
    for got, jac in zip(grads, jax.tree.leaves(out["std_jacobian"]), strict=True):
        want = float(np.asarray(jac, np.float64) @ score)
        np.testing.assert_allclose(float(got), want, rtol=1e-4, atol=1e-4 * np.abs(score).sum())
    assert any(float(g) != 0.0 for g in grads)


def test_spawn_starts_with_a_zero_log_weight():
    motion, params = MODELS["constant_velocity"]
    xy = jax.random.normal(jax.random.key(3), (N, 2), jnp.float32)
    out = ScoreMotion(motion).spawn(jax.random.key(4), xy, params)
    want = motion.spawn(jax.random.key(4), xy, params)
    np.testing.assert_array_equal(np.asarray(out.state.v), np.asarray(want.v))
    np.testing.assert_array_equal(np.asarray(out.log_transition), np.zeros(N, np.float32))


def test_gaussian_log_score_gradient_is_the_analytic_score(rng):
    sigma = np.array([0.3, 1.7, 0.0, 0.05], np.float32)  # one component without noise
    normal = rng.standard_normal((N, 4)).astype(np.float32)
    noise = (sigma * normal).astype(np.float32)

    @jax.jit
    @jax.grad
    def score(std):
        return jnp.sum(gaussian_log_score(jnp.asarray(noise), std))

    value = gaussian_log_score(jnp.asarray(noise), jnp.asarray(sigma[None, :]))
    np.testing.assert_array_equal(np.asarray(value), np.zeros(N, np.float32))
    grad = np.asarray(score(jnp.asarray(sigma[None, :])))[0]
    # d/dsigma_j sum_i log N(sigma_j n_ij; 0, sigma_j^2) = sum_i (n_ij^2 - 1) / sigma_j (noise held fixed).
    n64 = noise.astype(np.float64) / np.where(sigma > 0, sigma, 1.0).astype(np.float64)
    want = np.where(sigma > 0, np.sum(n64**2 - 1.0, axis=0) / np.where(sigma > 0, sigma, 1.0), 0.0)
    assert np.all(np.isfinite(grad))
    assert grad[2] == 0.0
    np.testing.assert_allclose(grad, want, rtol=1e-4, atol=1e-3)

    # Per-particle stds ([N, D]): each row's gradient is its own score.
    per_row = np.asarray(score(jnp.asarray(np.broadcast_to(sigma, (N, 4)))))
    want_rows = np.where(sigma > 0, (n64**2 - 1.0) / np.where(sigma > 0, sigma, 1.0), 0.0)
    assert np.all(np.isfinite(per_row))
    np.testing.assert_allclose(per_row, want_rows, rtol=1e-4, atol=1e-3)


def test_score_motion_needs_gaussian_noise():
    with pytest.raises(ValueError, match=r"^motion:"):
        ScoreMotion(hp.motion.MassInertia()).validate()


# Each resampling estimator and each motion form once (every run compiles anew: ~2 s each).
VARIANTS = [("stop_gradient", "score")]  # the default; the others wrap the same pieces (test_resampling_gradients)


def test_differentiable_forward_pass_is_the_filter(small_sequence):
    """Gradient estimators change only the backward pass: the estimates are the plain filter's, bit for bit
    (score-form motion moves the particles with the wrapped model's own ``predict``)."""
    model, params = hp.build("heatmap", SMALL_OPTIONS)
    key = jax.random.key(5)
    plain = np.asarray(hp.run(key, small_sequence, params, model).info.mean)
    assert np.all(np.isfinite(plain))
    for resampling, motion in VARIANTS:
        diff = differentiable(model, resampling=resampling, motion=motion, checkpoint=True)
        assert isinstance(diff, Checkpointed)
        assert isinstance(diff.model.motion, ScoreMotion) == (motion == "score")
        got = np.asarray(hp.run(key, small_sequence, params, diff).info.mean)
        np.testing.assert_array_equal(got, plain, err_msg=f"{resampling}/{motion}")
