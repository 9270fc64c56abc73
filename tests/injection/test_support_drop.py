"""Explorers at the measurements as far as the estimate's support drops (Augmented MCL): the support against a NumPy
brute force, the averages and the refilled share against hand-computed values, no new evidence without a heat map,
the slots refilled, and a filter that carries the averages from step to step."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.injection import SupportDropExplorers, SupportDropParams, SupportState, support_at, support_update
from heatpf_jax.motion.random_walk import Particles

# The functions tested, one program each (shared by the tests): run eagerly, each of their operations would compile
# on its own. Their inputs are NumPy, as eager `jnp` conversions compile a program each too.
_support_at = jax.jit(support_at)
_support_update = jax.jit(support_update)


@jax.jit
def _inject_state(key, xy, rank, buffer, params, state):
    """:meth:`SupportDropExplorers.inject_state` on a context of uniform weights with three slots used: one
    program."""
    n = xy.shape[0]
    ctx = hp.injection.InjectionContext(
        particles=Particles(xy), log_weights=jnp.full((n,), -np.log(n), jnp.float32), rank=rank, used=jnp.int32(3),
        estimate=hp.Estimate(jnp.zeros(2), jnp.eye(2), jnp.zeros(2)), motion=hp.motion.RandomWalk(),
        motion_params=hp.motion.RandomWalkParams(), measurements=buffer, has_heatmap=jnp.asarray(True))
    out, new = SupportDropExplorers().inject_state(key, ctx, params, state)
    return out._replace(motion=None), new  # the motion model is not an array: not returned


def _buffer(rng, m=64):
    xy = rng.uniform(-2.0, 2.0, size=(m, 2))
    weight = rng.uniform(0.0, 1.0, size=m)
    valid = rng.uniform(size=m) < 0.7
    # With the zero footprint of `empty_measurements`.
    return hp.Measurements(np.asarray(xy, np.float32), np.asarray(weight, np.float32), valid,
                           np.zeros((m, 2, 2), np.float32))


def test_support_is_the_strongest_valid_measurement_within_the_gate(rng):
    for _ in range(5):
        buffer = _buffer(rng)
        mean = rng.uniform(-1.0, 1.0, size=2)
        gate = rng.uniform(0.2, 1.5)
        xy, w, valid = (np.asarray(a) for a in (buffer.xy, buffer.weight, buffer.valid))
        near = valid & (np.linalg.norm(xy - mean, axis=1) <= gate)
        want = w[near].max() if near.any() else 0.0
        got = _support_at(buffer, np.asarray(mean, np.float32), np.float32(gate))
        np.testing.assert_allclose(float(got), want, rtol=1e-6)
    assert float(_support_at(buffer, np.asarray([50.0, 50.0], np.float32), np.float32(1.0))) == 0.0


def test_averages_and_share_against_hand_computed_values():
    params = SupportDropParams(measurement_fraction=0.1, slow_rate=0.2, fast_rate=0.5)
    state = SupportState(np.float32(0.5), np.float32(0.5))
    # The ball still seen as before: no drop, no explorers.
    new, share = _support_update(state, np.float32(0.5), np.asarray(True), params)
    np.testing.assert_allclose([float(new.slow), float(new.fast), float(share)], [0.5, 0.5, 0.0], atol=1e-7)
    # The support gone: slow 0.5 - 0.2 * 0.5 = 0.4, fast 0.25, share 0.1 * (1 - 0.25 / 0.4) = 0.0375.
    new, share = _support_update(state, np.float32(0.0), np.asarray(True), params)
    np.testing.assert_allclose([float(new.slow), float(new.fast), float(share)], [0.4, 0.25, 0.0375], rtol=1e-6)
    # A brighter blob at the estimate (fast above slow): none.
    _, share = _support_update(state, np.float32(0.9), np.asarray(True), params)
    assert float(share) == 0.0
    # No new heat map: the averages stay, the share is that of the averages.
    dropped = SupportState(np.float32(0.4), np.float32(0.1))
    new, share = _support_update(dropped, np.float32(0.0), np.asarray(False), params)
    np.testing.assert_allclose([float(new.slow), float(new.fast), float(share)], [0.4, 0.1, 0.075], rtol=1e-6)
    # Nothing tracked yet (slow average 0): the whole share.
    _, share = _support_update(SupportState(np.float32(0.0), np.float32(0.0)), np.float32(0.0), np.asarray(True),
                               params)
    np.testing.assert_allclose(float(share), 0.1)


@pytest.mark.parametrize(("state", "count"), [((0.6, 0.6), 5), ((0.0, 0.0), 10), ((0.8, 0.4), 7)])
def test_refills_the_share_of_lowest_support_slots(rng, state, count):
    """Support 0 at the estimate: averages (0.6, 0.6) -> (0.57, 0.3), share 0.25 (1 - 0.3 / 0.57) = 0.118, 5 of 40
    slots; (0.8, 0.4) -> (0.76, 0.2), 7 slots; nothing tracked yet, the whole 10. The slots taken are the next
    lowest-support ones, refilled at the measurements."""
    n = 40
    buffer = _buffer(rng)._replace(xy=np.full((64, 2), 30.0, np.float32))  # nothing near the estimate
    rank = np.asarray(rng.permutation(n), np.int32)
    xy = np.asarray(rng.normal(size=(n, 2)) - 20.0, np.float32)  # the particles, far from the measurements
    params = SupportDropParams(measurement_fraction=0.25, slow_rate=0.05, fast_rate=0.5)
    slow, fast = 0.95 * state[0], 0.5 * state[1]
    share = 0.25 * (1.0 - fast / slow) if slow > 0 else 0.25
    assert round(share * n) == count
    out, new = _inject_state(jax.random.key(0), xy, rank, buffer, params,
                             SupportState(np.float32(state[0]), np.float32(state[1])))
    np.testing.assert_allclose([float(new.slow), float(new.fast)], [slow, fast], rtol=1e-6)
    r = np.asarray(rank)
    taken = (r >= n - 3 - count) & (r < n - 3)
    moved = np.any(np.asarray(out.particles.xy) != xy, axis=1)
    np.testing.assert_array_equal(moved, taken)
    assert int(out.used) == 3 + count
    if count:
        np.testing.assert_allclose(np.asarray(out.particles.xy)[taken], 30.0, atol=0.5)  # at the measurements


def test_a_filter_carries_the_averages_from_step_to_step(small_sequence):
    """With the piece among its injectors the filter's state holds its averages (``()`` for the others), which
    follow the support at the estimate; a filter without such a piece carries nothing."""
    from tests.conftest import SMALL_FILTER

    model = SMALL_FILTER._replace(injectors=(*SMALL_FILTER.injectors, SupportDropExplorers()))
    params = model.default_params()
    # One program for the initial state (eagerly each of its operations would compile on its own); the other
    # filter's state only for its structure.
    state = jax.jit(model.init)(jax.random.key(0), params)
    assert state.injection[0] == () and float(state.injection[1].slow) == 0.0
    assert jax.eval_shape(SMALL_FILTER.init, jax.random.key(0), SMALL_FILTER.default_params()).injection == ()
    final = hp.run(jax.random.key(0), small_sequence, params, model).final_state
    slow, fast = float(final.injection[1].slow), float(final.injection[1].fast)
    assert 0.0 < slow <= 1.0 and 0.0 <= fast <= 1.0  # the ball's activation tracked (weights in [0, 1])
