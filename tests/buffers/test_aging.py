"""Buffers: the aging buffer (moved by odometry, then eq. 2) and the memoryless buffer, by hand."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

import heatpf_jax as hp


def _inputs(odometry, has_heatmap):
    return hp.StepInputs(
        heatmap=jnp.zeros((2, 2), jnp.float32),
        has_heatmap=jnp.asarray(has_heatmap),
        cam_to_base=jnp.eye(4, dtype=jnp.float32),
        odometry=jnp.asarray(odometry, jnp.float32),
        intrinsics=jnp.ones(4, jnp.float32),
        plane_height=jnp.float32(0.0),
        dt=jnp.float32(0.1),
    )


def _buffer(xy, weight):
    xy = jnp.asarray(xy, jnp.float32)
    return hp.Measurements(
        xy=xy,
        weight=jnp.asarray(weight, jnp.float32),
        valid=jnp.ones(len(xy), bool),
        footprint=jnp.zeros((len(xy), 2, 2), jnp.float32),
    )


def test_aging_buffer_moves_then_ages(rng):
    old = _buffer(rng.normal(size=(4, 2)), [0.9, 0.5, 0.35, 0.2])
    odom = np.array([0.3, -0.1, 0.2])
    out = hp.buffers.AgingBuffer().update(old, hp.measurements.empty_measurements(4), _inputs(odom, False),
                                          hp.buffers.AgingParams(0.125, 0.25))
    c, s = np.cos(0.2), np.sin(0.2)
    q = np.asarray(old.xy, np.float64) - odom[:2]
    moved = np.stack([c * q[:, 0] + s * q[:, 1], -s * q[:, 0] + c * q[:, 1]], 1)
    np.testing.assert_array_equal(np.asarray(out.valid), [True, True, False, False])  # 0.225 < 0.25, 0.075 < 0.25
    np.testing.assert_allclose(np.asarray(out.weight), [0.775, 0.375, 0, 0], atol=1e-6)
    np.testing.assert_allclose(np.asarray(out.xy)[:2], moved[:2], atol=1e-6)


def test_aging_buffer_takes_a_new_heat_map():
    old = _buffer([[1.0, 1.0]], [0.9])
    new = _buffer([[2.0, 0.0]], [0.6])
    out = hp.buffers.AgingBuffer().update(old, new, _inputs([0.5, 0.0, 0.0], True), hp.buffers.AgingParams(0.3, 0.1))
    np.testing.assert_allclose(np.asarray(out.xy), [[2.0, 0.0]])  # new measurements are already in this frame
    np.testing.assert_allclose(np.asarray(out.weight), [0.6])


def test_latest_only_keeps_nothing():
    old = _buffer([[1.0, 1.0], [2.0, 2.0]], [0.9, 0.8])
    new = _buffer([[3.0, 0.0], [4.0, 0.0]], [0.6, 0.7])
    piece = hp.buffers.LatestOnly()
    with_map = piece.update(old, new, _inputs([0.5, 0.2, 0.1], True), piece.default_params())
    np.testing.assert_allclose(np.asarray(with_map.xy), np.asarray(new.xy))  # not moved by odometry
    np.testing.assert_allclose(np.asarray(with_map.weight), [0.6, 0.7])  # not aged
    without = piece.update(old, hp.measurements.empty_measurements(2), _inputs([0.5, 0.2, 0.1], False),
                           piece.default_params())
    assert not np.any(np.asarray(without.valid)) and np.all(np.asarray(without.weight) == 0)
