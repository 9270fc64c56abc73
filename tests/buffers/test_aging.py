"""Buffers: the aging buffer (moved by odometry, then eq. 2) and the memoryless buffer, by hand."""

from __future__ import annotations

from functools import partial

import jax
import numpy as np

import heatpf_jax as hp
from tests.conftest import blank_inputs

# Through `jit`, the piece and its params (Python floats) static as they are eagerly: run eagerly, each operation
# compiles a program of its own.
_empty = jax.jit(hp.measurements.empty_measurements, static_argnums=0)


@partial(jax.jit, static_argnames=("piece", "params"))
def _update(piece, buffer, new, inputs, params):
    return piece.update(buffer, new, inputs, params)


def _buffer(xy, weight):
    xy = np.asarray(xy, np.float32)  # NumPy, as above
    return hp.Measurements(
        xy=xy,
        weight=np.asarray(weight, np.float32),
        valid=np.ones(len(xy), bool),
        footprint=np.zeros((len(xy), 2, 2), np.float32),
    )


def test_aging_buffer_moves_then_ages(rng):
    old = _buffer(rng.normal(size=(4, 2)), [0.9, 0.5, 0.35, 0.2])
    odom = np.array([0.3, -0.1, 0.2])
    out = _update(hp.buffers.AgingBuffer(), old, _empty(4), blank_inputs(odom, has_heatmap=False),
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
    out = _update(hp.buffers.AgingBuffer(), old, new, blank_inputs([0.5, 0.0, 0.0], has_heatmap=True),
                  hp.buffers.AgingParams(0.3, 0.1))
    np.testing.assert_allclose(np.asarray(out.xy), [[2.0, 0.0]])  # new measurements are already in this frame
    np.testing.assert_allclose(np.asarray(out.weight), [0.6])


def test_latest_only_keeps_nothing():
    old = _buffer([[1.0, 1.0], [2.0, 2.0]], [0.9, 0.8])
    new = _buffer([[3.0, 0.0], [4.0, 0.0]], [0.6, 0.7])
    piece = hp.buffers.LatestOnly()
    with_map = _update(piece, old, new, blank_inputs([0.5, 0.2, 0.1], has_heatmap=True), piece.default_params())
    np.testing.assert_allclose(np.asarray(with_map.xy), np.asarray(new.xy))  # not moved by odometry
    np.testing.assert_allclose(np.asarray(with_map.weight), [0.6, 0.7])  # not aged
    without = _update(piece, old, _empty(2), blank_inputs([0.5, 0.2, 0.1], has_heatmap=False), piece.default_params())
    assert not np.any(np.asarray(without.valid)) and np.all(np.asarray(without.weight) == 0)
