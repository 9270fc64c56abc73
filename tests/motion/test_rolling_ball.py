"""The rolling-ball motion model against NumPy references: friction integrated in fine steps, the stop,
the kick share of a Poisson process, odometry as the constant-velocity model's."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.motion.constant_velocity import ConstantVelocity, ConstantVelocityParams, VelocityParticles
from heatpf_jax.motion.rolling_ball import RollingBall, RollingBallParams, roll
from tests.conftest import blank_inputs

QUIET = RollingBallParams(friction=0.0, kick_rate=0.0, kick_speed_std=0.0, accel_std=0.0, diffusion_std=0.0,
                          odom_trans_noise=0.0, odom_rot_noise=0.0)
# One program each: run eagerly, each operation of a step would compile on its own.
ROLL = jax.jit(roll)
PREDICT = jax.jit(RollingBall().predict)


def _roll_fine(xy, v, friction, dt, substeps=20000):
    """Euler integration of dv/dt = -friction v/|v| until the ball stops, in float64."""
    xy, v = xy.astype(np.float64).copy(), v.astype(np.float64).copy()
    h = dt / substeps
    for _ in range(substeps):
        speed = np.linalg.norm(v, axis=1, keepdims=True)
        step = np.minimum(friction * h, speed)
        v_next = v - np.where(speed > 0, v / np.where(speed > 0, speed, 1), 0) * step
        xy += 0.5 * (v + v_next) * h
        v = v_next
    return xy, v


def test_roll_is_the_integral_of_a_constant_deceleration(rng):
    xy = rng.normal(size=(40, 2)).astype(np.float32)
    v = (rng.normal(size=(40, 2)) * rng.choice([0.05, 0.3, 2.0], size=(40, 1))).astype(np.float32)
    v[0] = 0.0  # a ball at rest stays
    for friction, dt in ((0.6, 0.1), (1.2, 0.5), (0.0, 0.2)):
        got_xy, got_v = ROLL(xy, v, np.float32(friction), np.float32(dt))
        want_xy, want_v = _roll_fine(xy, v, friction, dt)
        np.testing.assert_allclose(np.asarray(got_xy), want_xy, atol=2e-5)
        np.testing.assert_allclose(np.asarray(got_v), want_v, atol=2e-5)
    # A slow ball stops within the step, after s^2 / (2 friction).
    stop_xy, stop_v = ROLL(np.zeros((1, 2), np.float32), np.array([[0.3, 0.4]], np.float32), np.float32(1.0),
                           np.float32(1.0))
    np.testing.assert_allclose(np.asarray(stop_v), 0.0)
    np.testing.assert_allclose(np.asarray(stop_xy), [[0.3 * 0.125 / 0.5 * 1.0, 0.4 * 0.125 / 0.5]], rtol=1e-5)


def test_without_friction_and_kicks_it_is_the_constant_velocity_model(rng):
    xy = rng.normal(size=(64, 2)).astype(np.float32)
    v = rng.normal(size=(64, 2)).astype(np.float32)
    inputs = blank_inputs((0.2, -0.05, 0.3), 0.25)
    got = PREDICT(jax.random.key(0), VelocityParticles(xy, v), inputs, QUIET)
    want = jax.jit(ConstantVelocity().predict)(jax.random.key(0), VelocityParticles(xy, v), inputs,
                                               ConstantVelocityParams(0.0, 0.0, 0.0, 0.0, 0.0))
    np.testing.assert_allclose(np.asarray(got.xy), np.asarray(want.xy), atol=1e-5)
    np.testing.assert_allclose(np.asarray(got.v), np.asarray(want.v), atol=1e-5)


def test_kicks_are_a_poisson_share_with_the_impulse_spread():
    n, rate, dt, std = 100_000, 2.0, 0.1, 1.5
    params = QUIET._replace(kick_rate=rate, kick_speed_std=std)
    out = PREDICT(jax.random.key(3), VelocityParticles(np.zeros((n, 2), np.float32), np.zeros((n, 2), np.float32)),
                  blank_inputs(dt=dt), params)
    v = np.asarray(out.v, np.float64)
    kicked = np.any(v != 0.0, axis=1)
    p = 1.0 - np.exp(-rate * dt)
    assert abs(kicked.mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    np.testing.assert_allclose(v[kicked].std(axis=0), std, rtol=0.03)
    np.testing.assert_array_equal(np.asarray(out.xy), 0.0)  # the impulse acts from the next step on


def test_gradients_flow_to_friction_and_stds():
    start = VelocityParticles(np.zeros((256, 2), np.float32), np.full((256, 2), 0.8, np.float32))

    def final_x(params):
        out = RollingBall().predict(jax.random.key(4), start, blank_inputs(dt=0.1), params)
        return jnp.mean(out.xy[:, 0]) + jnp.mean(out.v[:, 0] ** 2)

    grads = jax.jit(jax.grad(final_x))(RollingBallParams())  # one program: eager ops compile one by one
    assert np.isfinite(np.asarray(jax.tree.leaves(grads))).all()
    assert float(grads.friction) < 0.0  # more friction, less distance
