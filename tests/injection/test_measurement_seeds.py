"""Re-acquisition seeds: the gate against a NumPy brute force; before the weighting, the share at this step's
measurements only where nothing lies within the gate of the predicted cloud's mean (a NumPy weighted mean) on this
heat map and the previous one, in random slots; after the resampling the fixed share; and a filter whose step weighs
the seeds on the heat map that first shows the blob."""

from __future__ import annotations

import functools

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.injection import ReacquisitionParams, ReacquisitionSeeds, cloud_mean, has_support, robust_spread
from heatpf_jax.motion.random_walk import Particles

# One program each for the functions tested directly: run eagerly, each of their operations would compile on its own.
_empty_measurements = jax.jit(hp.measurements.empty_measurements, static_argnums=0)
_cloud_mean = jax.jit(cloud_mean)
_robust_spread = jax.jit(robust_spread)
_has_support = jax.jit(has_support)


@functools.partial(jax.jit, static_argnames=("piece", "method", "motion"))
def _apply_jit(key, context, params, *, piece, method, motion):
    return getattr(piece, method)(key, context._replace(motion=motion), params)._replace(motion=None)


def _apply(piece, method: str, key, context, params):
    """``piece.method(key, context, params)`` as one program; the context's motion model (no array) is static."""
    out = _apply_jit(key, context._replace(motion=None), params, piece=piece, method=method, motion=context.motion)
    return out._replace(motion=context.motion)


def _context(rng, n, blob_xy):
    # NumPy arrays, for the jitted functions: jnp's conversions would each compile a program of their own.
    xy = rng.normal(size=(n, 2)) * 0.2 + np.array([1.0, 0.0])
    log_w = np.log(rng.uniform(0.5, 1.5, size=n))
    m = 16
    buffer = _empty_measurements(m)._replace(
        xy=(np.tile(blob_xy, (m, 1)) + rng.normal(size=(m, 2)) * 0.01).astype(np.float32),
        weight=rng.uniform(0.3, 1.0, size=m).astype(np.float32),
        valid=np.arange(m) < 10,
    )
    return hp.injection.InjectionContext(
        particles=Particles(xy.astype(np.float32)), log_weights=log_w.astype(np.float32),
        rank=np.arange(n, dtype=np.int32), used=np.int32(0), estimate=None, motion=hp.motion.RandomWalk(),
        motion_params=hp.motion.RandomWalkParams(), measurements=buffer)


def test_cloud_mean_is_the_weighted_mean(rng):
    xy = rng.normal(size=(50, 2))
    log_w = rng.normal(size=50)
    w = np.exp(log_w) / np.exp(log_w).sum()
    np.testing.assert_allclose(np.asarray(_cloud_mean(xy.astype(np.float32), log_w.astype(np.float32))),
                               w @ xy, rtol=1e-5, atol=1e-6)


def test_robust_spread_is_the_scaled_median_absolute_deviation(rng):
    """Against NumPy: ``1.4826 sqrt(sum_axis MAD^2)``; a Gaussian cloud's is near its std whatever a few far
    explorers add."""
    xy = rng.normal(size=(501, 2)) * np.array([0.3, 0.2])
    mad = np.median(np.abs(xy - np.median(xy, axis=0)), axis=0)
    got = float(_robust_spread(xy.astype(np.float32)))
    np.testing.assert_allclose(got, 1.4826 * np.sqrt(np.sum(mad**2)), rtol=1e-5)
    assert abs(got - np.hypot(0.3, 0.2)) < 0.05
    xy[:25] = rng.uniform(-4.0, 4.0, size=(25, 2))  # 5 % explorers anywhere
    assert abs(float(_robust_spread(xy.astype(np.float32))) - np.hypot(0.3, 0.2)) < 0.06


def test_the_gate_is_pixels_of_the_footprint_at_least_metres(rng):
    """``d^T G^-1 d <= 1``, ``G = px^2 F F^T + gate^2 I``, against a NumPy brute force over random footprints."""
    m = 200
    xy = rng.uniform(-3.0, 3.0, size=(m, 2))
    foot = rng.normal(size=(m, 2, 2)) * 0.2
    weight = rng.uniform(0.0, 1.0, size=m) * (rng.uniform(size=m) < 0.8)
    valid = rng.uniform(size=m) < 0.8
    buffer = hp.measurements.Measurements(xy.astype(np.float32), weight.astype(np.float32), valid,
                                          foot.astype(np.float32))
    for _ in range(30):
        mean = rng.uniform(-3.0, 3.0, size=2)
        gate, px = rng.uniform(0.05, 0.4), rng.uniform(0.0, 3.0)
        g = px**2 * foot @ np.swapaxes(foot, 1, 2) + gate**2 * np.eye(2)
        d = mean - xy
        q = np.einsum("mi,mij,mj->m", d, np.linalg.inv(g), d)
        expected = bool(np.any(valid & (weight > 0) & (q <= 1.0)))
        if np.any(np.abs(q[valid & (weight > 0)] - 1.0) < 1e-3):
            continue  # too close to the gate's edge for float32
        assert bool(_has_support(buffer, mean.astype(np.float32), np.float32(gate), np.float32(px))) == expected


@pytest.mark.parametrize(("blob", "before", "seeded"), [
    ((3.0, 2.0), None, True),  # nothing near the cloud, no previous buffer known
    ((3.0, 2.0), (3.0, 2.0), True),  # nothing near it on the previous heat map either
    ((3.0, 2.0), (1.1, 0.0), False),  # the cloud had support on the previous heat map: a frame's dropout
    ((1.3, 0.1), None, False),  # a measurement inside the gate now
])
def test_seeds_before_the_weighting_only_where_the_cloud_has_no_support(rng, blob, before, seeded):
    """A blob 2.8 m from the cloud's mean: 8 of 40 particles (0.2) moved onto it, unless the previous heat map had a
    measurement near the cloud; 0.32 m away (inside the 0.5 m gate): none moved."""
    n = 40
    ctx = _context(rng, n, np.array(blob))
    if before is not None:
        previous = _context(rng, n, np.array(before)).measurements
        ctx = ctx._replace(previous_measurements=previous)
    out = _apply(ReacquisitionSeeds(), "seed", jax.random.key(3), ctx,
                 ReacquisitionParams(measurement_fraction=0.2, measurement_jitter=0.02))
    moved = np.any(np.asarray(out.particles.xy) != np.asarray(ctx.particles.xy), axis=1)
    assert moved.sum() == (8 if seeded else 0)
    assert int(out.used) == (8 if seeded else 0)
    if seeded:
        np.testing.assert_allclose(np.asarray(out.particles.xy)[moved], np.tile(blob, (8, 1)), atol=0.15)
        # Random slots, not the last ranks (rank is 0..n-1 by slot here).
        assert not np.array_equal(np.flatnonzero(moved), np.arange(n - 8, n))


def test_the_fixed_share_after_the_resampling(rng):
    """``inject`` is ``MeasurementExplorers``'s: the share of the lowest-support slots, wherever the cloud is."""
    n = 40
    ctx = _context(rng, n, np.array([1.2, 0.0]))._replace(
        estimate=hp.Estimate(np.zeros(2, np.float32), np.eye(2, dtype=np.float32), np.zeros(2, np.float32)))
    params = ReacquisitionParams(measurement_fraction=0.25)
    out = _apply(ReacquisitionSeeds(), "inject", jax.random.key(0), ctx, params)
    ref = _apply(hp.injection.MeasurementExplorers(), "inject", jax.random.key(0), ctx,
                 hp.injection.MeasurementParams(0.25))
    np.testing.assert_array_equal(np.asarray(out.particles.xy), np.asarray(ref.particles.xy))
    assert int(out.used) == 10


@pytest.mark.parametrize(("which", "offset", "on_ball"), [
    ("seeds", (2.0, 0.0), True),  # a cloud 2 m beyond the ball, in view, and a heat map that shows the ball
    ("fixed", (2.0, 0.0), False),  # the fixed share after the resampling alone
    ("seeds", (0.0, 2.0), False),  # a cloud 2 m beside the ball, out of the camera's view: nothing seeded
    ("wide", (0.0, 2.0), True),  # the same place, a cloud too wide (seed_spread 0.01 m) to predict anything: seeded
])
def test_a_filter_weighs_the_seeds_on_the_heat_map_that_first_shows_the_blob(small_sequence, which, offset, on_ball):
    """A cloud 2 m from the ball and a heat map that shows it (eq. 1, 128 particles): with the seeds the step's estimate
    has moved most of the way to the ball (under 1 m from it); with the fixed share after the resampling alone it is
    still at the cloud (over 1.8 m), and so it is with the seeds where the cloud lies out of the camera's view (a ball
    there is not expected on the heat map: :func:`in_view` against a NumPy pinhole projection), unless the cloud is
    wider than ``seed_spread``."""
    from tests.conftest import SMALL_FILTER, step_inputs

    inputs = step_inputs(small_sequence, 5)
    ball = np.asarray(small_sequence.ground_truth[5])
    away = ball + np.array(offset)
    # The camera sees the cloud's place exactly where a NumPy pinhole projection puts it on the heat map.
    pose, (fx, fy, cx, cy) = np.asarray(inputs.cam_to_base, np.float64), np.asarray(inputs.intrinsics, np.float64)
    p = pose[:3, :3].T @ (np.array([*away, float(inputs.plane_height)]) - pose[:3, 3])
    u, v = fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy
    h, w = small_sequence.heatmaps.shape[1:]
    visible = bool(p[2] > 0 and -0.5 <= u <= w - 0.5 and -0.5 <= v <= h - 0.5)
    assert visible == (offset == (2.0, 0.0))
    assert bool(np.asarray(jax.jit(hp.injection.in_view)(away[None].astype(np.float32), inputs))[0]) == visible
    injector = hp.injection.MeasurementExplorers() if which == "fixed" else ReacquisitionSeeds()
    model = SMALL_FILTER._replace(injectors=(*SMALL_FILTER.injectors, injector))
    params = model.default_params()
    if which == "wide":
        injectors = dict(params.injectors)
        injectors["measurement"] = injectors["measurement"]._replace(seed_spread=0.01)
        params = params._replace(injectors=injectors)
    state = jax.jit(model.init)(jax.random.key(0), params)  # one program, not one per operation
    n = state.particles.xy.shape[0]
    cloud = np.random.default_rng(0).normal(size=(n, 2)) * 0.05 + away
    state = state._replace(particles=state.particles._replace(xy=cloud.astype(np.float32)))
    _, info = jax.jit(model.step)(jax.random.key(1), state, inputs, params)  # one compilation, not one per operation
    distance = float(np.linalg.norm(np.asarray(info.mean) - ball))
    assert (distance < 1.0) if on_ball else (distance > 1.8), distance
