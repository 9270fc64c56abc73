"""Observation model, eq. (1): compared with a float64 NumPy brute force over the valid measurements."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.observation.kernels import AUTO_BLOCKED_MIN_SIZE

K_MAX = 8
N_PART = 200
N_MEAS = 300

# One compiled function per shape: k traced, bounded by the static K_MAX.
_pw = jax.jit(partial(hp.observation.particle_weights, k_max=K_MAX))
_pw_floor = jax.jit(partial(hp.observation.particle_weights, k_max=K_MAX, min_distance=0.25))
_gpw = jax.jit(partial(hp.observation.gaussian_particle_weights, k_max=K_MAX))
_pw_vmap_k = jax.jit(jax.vmap(partial(hp.observation.particle_weights, k_max=K_MAX), in_axes=(None, None, 0)))
# Concrete k (a static Python int inside jit: no k_max given, so k itself bounds the selection).
_pw_concrete = jax.jit(hp.observation.particle_weights, static_argnums=2)
_k_nearest = jax.jit(partial(hp.observation.k_nearest, k_max=K_MAX))
_empty = jax.jit(hp.measurements.empty_measurements, static_argnums=0)
# Test inputs are NumPy throughout: eager `jnp` conversions compile a program each.


def _grad_sum(particles, meas, k):
    return jax.grad(lambda p: jnp.sum(hp.observation.particle_weights(p, meas, k, k_max=K_MAX)))(particles)


_grad_pw = jax.jit(_grad_sum)


def _grad_sum_weights(particles, meas, k):
    def total(w):
        return jnp.sum(hp.observation.particle_weights(particles, meas._replace(weight=w), k, k_max=K_MAX))

    return jax.grad(total)(meas.weight)


_grad_pw_weights = jax.jit(_grad_sum_weights)


# --------------------------------------------------------------------------- references


def ref_weights(particles, xy, weight, valid, k, min_distance=0.01):
    """Eq. (1) by brute force in float64: argsort of the distances to the valid measurements, per particle."""
    p = np.asarray(particles, np.float64)
    xy = np.asarray(xy, np.float64)[np.asarray(valid)]
    w = np.asarray(weight, np.float64)[np.asarray(valid)]
    if xy.shape[0] == 0:
        return np.ones(p.shape[0])
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        d = np.sqrt(np.sum((xy - p[i]) ** 2, axis=1))
        order = np.argsort(d, kind="stable")[:k]
        out[i] = np.sum(w[order] / np.maximum(d[order], min_distance))
    return out


def ref_gaussian(particles, xy, weight, valid, k, std):
    p = np.asarray(particles, np.float64)
    xy = np.asarray(xy, np.float64)[np.asarray(valid)]
    w = np.asarray(weight, np.float64)[np.asarray(valid)]
    if xy.shape[0] == 0:
        return np.ones(p.shape[0])
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        d2 = np.sum((xy - p[i]) ** 2, axis=1)
        order = np.argsort(d2, kind="stable")[:k]
        out[i] = np.sum(w[order] * np.exp(-d2[order] / (2.0 * std**2)))
    return out


def ref_grad(particles, xy, weight, valid, k, min_distance=0.01):
    """Analytic gradient of sum_i w_i(p_i) wrt p_i: -w_j (p_i - m_j) / d^3 over the k nearest (0 on the floor)."""
    p = np.asarray(particles, np.float64)
    xy = np.asarray(xy, np.float64)[np.asarray(valid)]
    w = np.asarray(weight, np.float64)[np.asarray(valid)]
    g = np.zeros_like(p)
    for i in range(p.shape[0]):
        diff = p[i] - xy
        d = np.sqrt(np.sum(diff**2, axis=1))
        for j in np.argsort(d, kind="stable")[:k]:
            if d[j] > min_distance:
                g[i] -= w[j] * diff[j] / d[j] ** 3
    return g


# --------------------------------------------------------------------------- inputs


def make_measurements(rng, m=N_MEAS, n_valid=None, extent=4.0):
    """A padded buffer: valid slots at random positions, invalid slots holding random garbage."""
    xy = rng.uniform(-extent, extent, (m, 2)).astype(np.float32)
    weight = rng.uniform(0.05, 1.0, m).astype(np.float32)
    valid = np.zeros(m, bool)
    if n_valid is None:
        n_valid = int(0.6 * m)
    valid[rng.choice(m, n_valid, replace=False)] = True
    # Garbage in the invalid slots: large weights, positions in the same region (often nearest to a particle).
    weight[~valid] = rng.uniform(5.0, 50.0, int((~valid).sum())).astype(np.float32)
    meas = hp.Measurements(xy, weight, valid, np.zeros((len(valid), 2, 2), np.float32))
    return meas, xy, weight, valid


def make_particles(rng, n=N_PART, extent=4.5):
    return rng.uniform(-extent, extent, (n, 2)).astype(np.float32)


def rel_err(got, want):
    got = np.asarray(got, np.float64)
    return float(np.max(np.abs(got - want) / np.abs(want)))


# --------------------------------------------------------------------------- eq. (1)


def test_particle_weights_match_brute_force_every_k_with_padding():
    rng = np.random.default_rng(0)
    worst = 0.0
    for trial in range(3):
        meas, xy, w, valid = make_measurements(rng)
        parts = make_particles(rng)
        assert not valid.all() and valid.any()
        for k in range(1, K_MAX + 1):
            want = ref_weights(parts, xy, w, valid, k)
            got_concrete = _pw_concrete(parts, meas, k)
            got_traced = _pw(parts, meas, np.int32(k))
            worst = max(worst, rel_err(got_concrete, want), rel_err(got_traced, want))
            np.testing.assert_allclose(np.asarray(got_concrete), want, rtol=1e-5)
            np.testing.assert_allclose(np.asarray(got_traced), want, rtol=1e-5)
    print(f"\nparticle_weights vs float64 brute force: max relative error {worst:.3g}")
    assert worst < 1e-5


def test_particle_weights_garbage_in_invalid_slots_is_ignored():
    rng = np.random.default_rng(1)
    meas, xy, w, valid = make_measurements(rng)
    parts = make_particles(rng)
    # Same valid content, different garbage: identical weights.
    xy2, w2 = xy.copy(), w.copy()
    xy2[~valid] = rng.uniform(-1e3, 1e3, ((~valid).sum(), 2)).astype(np.float32)
    w2[~valid] = rng.uniform(-10.0, 10.0, (~valid).sum()).astype(np.float32)
    meas2 = hp.Measurements(xy2, w2, valid, np.zeros((len(valid), 2, 2), np.float32))
    for k in (1, 5):
        a = np.asarray(_pw(parts, meas, np.int32(k)))
        b = np.asarray(_pw(parts, meas2, np.int32(k)))
        np.testing.assert_array_equal(a, b)
        # Garbage would change the result if it were used: put each particle on top of an invalid slot.
        bad = xy[~valid][:N_PART]
        got = np.asarray(_pw(bad, meas, np.int32(k)))
        np.testing.assert_allclose(got, ref_weights(bad, xy, w, valid, k), rtol=1e-5)


def test_particle_weights_fewer_valid_than_k_sums_all_valid():
    rng = np.random.default_rng(2)
    for n_valid in (1, 3, 7):
        meas, xy, w, valid = make_measurements(rng, n_valid=n_valid)
        parts = make_particles(rng)
        for k in (n_valid, n_valid + 1, K_MAX):
            got = np.asarray(_pw(parts, meas, np.int32(k)))
            want = ref_weights(parts, xy, w, valid, k)
            # Independent of the ordering: the sum over all valid measurements.
            d = np.sqrt(((parts[:, None, :].astype(np.float64) - xy[valid][None].astype(np.float64)) ** 2).sum(-1))
            all_valid = (w[valid][None, :] / np.maximum(d, 0.01)).sum(-1)
            np.testing.assert_allclose(want, all_valid, rtol=1e-12)
            np.testing.assert_allclose(got, want, rtol=1e-5)


def test_particle_weights_buffer_smaller_than_k():
    """A buffer with fewer slots than k (k_max is clipped to the buffer size)."""
    rng = np.random.default_rng(3)
    meas, xy, w, valid = make_measurements(rng, m=5, n_valid=4)
    parts = make_particles(rng, n=20)
    for k in (3, 5, 8):
        got = np.asarray(_pw_concrete(parts, meas, k))
        np.testing.assert_allclose(got, ref_weights(parts, xy, w, valid, k), rtol=1e-5)


def test_particle_weights_no_valid_measurement_gives_ones():
    rng = np.random.default_rng(4)
    meas, _, _, _ = make_measurements(rng, n_valid=0)
    parts = make_particles(rng)
    for k in (1, 4, 8):
        got = np.asarray(_pw(parts, meas, np.int32(k)))
        np.testing.assert_array_equal(got, np.ones(N_PART, np.float32))
    g = np.asarray(_gpw(parts, meas, np.int32(3), std=np.float32(0.5)))
    np.testing.assert_array_equal(g, np.ones(N_PART, np.float32))
    empty = _empty(N_MEAS)
    np.testing.assert_array_equal(np.asarray(_pw(parts, empty, np.int32(2))), np.ones(N_PART))


def test_particle_weights_distance_floor():
    rng = np.random.default_rng(5)
    meas, xy, w, valid = make_measurements(rng)
    parts = make_particles(rng)
    # Particles exactly on valid measurements, and some closer than the floor.
    on = xy[valid][:60]
    parts[:60] = on
    near = xy[valid][60:120] + rng.uniform(-0.004, 0.004, (60, 2)).astype(np.float32)
    parts[60:120] = near
    for k in (1, 3, 8):
        got = np.asarray(_pw(parts, meas, np.int32(k)))
        want = ref_weights(parts, xy, w, valid, k)
        np.testing.assert_allclose(got, want, rtol=1e-5)
        assert np.all(np.isfinite(got))
        # The measurement under the particle contributes w / min_distance.
        assert np.all(got[:60] >= w[valid][:60] / 0.01 * (1 - 1e-6))
    # A custom floor.
    got = np.asarray(_pw_floor(parts, meas, np.int32(4)))
    np.testing.assert_allclose(got, ref_weights(parts, xy, w, valid, 4, min_distance=0.25), rtol=1e-5)
    # Gradients stay finite on top of a measurement.
    g = np.asarray(_grad_pw(parts, meas, np.int32(3)))
    assert np.all(np.isfinite(g))
    np.testing.assert_allclose(g, ref_grad(parts, xy, w, valid, 3), rtol=1e-3, atol=1e-2)


def test_particle_weights_traced_k_and_vmap_over_k():
    rng = np.random.default_rng(6)
    meas, xy, w, valid = make_measurements(rng)
    parts = make_particles(rng)
    traced = jax.jit(lambda p, m, k: hp.observation.particle_weights(p, m, k, k_max=8))
    ks = np.arange(1, K_MAX + 1, dtype=np.int32)
    swept = np.asarray(_pw_vmap_k(parts, meas, ks))
    assert swept.shape == (K_MAX, N_PART)
    for i, k in enumerate(range(1, K_MAX + 1)):
        concrete = np.asarray(_pw_concrete(parts, meas, k))
        np.testing.assert_allclose(np.asarray(traced(parts, meas, np.int32(k))), concrete, rtol=1e-6)
        np.testing.assert_allclose(swept[i], concrete, rtol=1e-6)
    # More neighbours never decrease a sum of positive terms.
    assert np.all(np.diff(swept, axis=0) > 0)


def test_particle_weights_bad_k_max_raises():
    rng = np.random.default_rng(7)
    meas, _, _, _ = make_measurements(rng, m=10)
    parts = make_particles(rng, n=4)
    with pytest.raises(ValueError):
        hp.observation.particle_weights(parts, meas, 2, k_max=0)


def test_particle_weights_traced_k_without_k_max_raises():
    rng = np.random.default_rng(7)
    meas, _, _, _ = make_measurements(rng, m=10)
    parts = make_particles(rng, n=4)
    with pytest.raises(ValueError):
        jax.jit(lambda k: hp.observation.particle_weights(parts, meas, k))(np.int32(2))
    with pytest.raises(ValueError):
        jax.jit(lambda k: hp.observation.gaussian_particle_weights(parts, meas, k, std=0.5))(np.int32(2))


def test_k_nearest_selection_mask():
    rng = np.random.default_rng(8)
    meas, xy, w, valid = make_measurements(rng, m=40, n_valid=5)
    parts = make_particles(rng, n=30)
    for k in (2, 5, 8):
        sq, wsel, sel = _k_nearest(parts, meas, np.int32(k))
        sel = np.asarray(sel)
        assert sel.shape == (30, 8)
        np.testing.assert_array_equal(sel.sum(1), np.full(30, min(k, 5)))
        # Selected squared distances: the k smallest over the valid measurements, increasing.
        d2 = ((parts[:, None, :].astype(np.float64) - xy[valid][None].astype(np.float64)) ** 2).sum(-1)
        want = np.sort(d2, axis=1)[:, : min(k, 5)]
        got = np.where(sel, np.asarray(sq), np.nan)[:, : min(k, 5)]
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        assert np.all(np.asarray(wsel)[~sel] == 0)


def test_particle_weights_gradient_matches_analytic_and_finite_differences():
    rng = np.random.default_rng(9)
    # 20 valid measurements on a jittered grid (well separated), garbage in the other slots, shuffled.
    gx, gy = np.meshgrid(np.arange(5) * 1.3, np.arange(4) * 1.3)
    grid = np.stack([gx.ravel(), gy.ravel()], 1) + rng.uniform(-0.2, 0.2, (20, 2))
    xy = np.concatenate([grid, rng.uniform(0, 5, (N_MEAS - 20, 2))]).astype(np.float32)
    w = rng.uniform(0.2, 1.0, N_MEAS).astype(np.float32)
    valid = np.arange(N_MEAS) < 20
    perm = rng.permutation(N_MEAS)
    xy, w, valid = xy[perm], w[perm], valid[perm]
    meas = hp.Measurements(xy, w, valid, np.zeros((len(valid), 2, 2), np.float32))

    # Particles away from ties and from the floor: nearest distance > 0.3, neighbour-rank gaps > 0.05.
    k = 3
    cand = rng.uniform(0, 5, (3000, 2))
    d = np.sort(np.sqrt(((cand[:, None] - xy[valid][None].astype(np.float64)) ** 2).sum(-1)), axis=1)
    ok = (d[:, 0] > 0.3) & np.all(np.diff(d[:, : k + 1], axis=1) > 0.05, axis=1)
    parts = cand[ok][:N_PART].astype(np.float32)
    assert parts.shape[0] == N_PART

    g = np.asarray(_grad_pw(parts, meas, np.int32(k)))
    assert np.all(np.isfinite(g))
    want = ref_grad(parts, xy, w, valid, k)
    np.testing.assert_allclose(g, want, rtol=1e-4, atol=1e-5)

    # Central differences of the float32 function (each particle's weight depends on that particle only).
    eps = 1e-3
    fd = np.zeros_like(want)
    for axis in range(2):
        step = np.zeros((1, 2), np.float32)
        step[0, axis] = eps
        plus = np.asarray(_pw(parts + step, meas, np.int32(k)), np.float64)
        minus = np.asarray(_pw(parts - step, meas, np.int32(k)), np.float64)
        true_step = (parts + step).astype(np.float64)[:, axis] - (parts - step).astype(np.float64)[:, axis]
        fd[:, axis] = (plus - minus) / true_step
    scale = np.linalg.norm(want, axis=1, keepdims=True)
    fd_err = np.max(np.abs(fd - g) / scale)
    assert fd_err < 1e-2, fd_err

    # Gradient wrt the measurement weights: sum over the particles selecting j of 1 / d_ij (eq. 1 is linear in w).
    gw = np.asarray(_grad_pw_weights(parts, meas, np.int32(k)))
    dist = np.sqrt(((parts[:, None].astype(np.float64) - xy[None].astype(np.float64)) ** 2).sum(-1))
    nearest = np.argsort(np.where(valid[None, :], dist, np.inf), axis=1)[:, :k]
    want_w = np.zeros(N_MEAS)
    for i in range(N_PART):
        want_w[nearest[i]] += 1.0 / dist[i, nearest[i]]
    np.testing.assert_allclose(gw, want_w, rtol=1e-5, atol=1e-7)
    assert np.all(gw[~valid] == 0)


def test_gaussian_particle_weights_match_brute_force():
    rng = np.random.default_rng(10)
    meas, xy, w, valid = make_measurements(rng, extent=3.0)
    parts = make_particles(rng, extent=3.0)
    worst = 0.0
    for std in (0.4, 1.3):
        for k in (1, 2, 5, 8):
            got = np.asarray(_gpw(parts, meas, np.int32(k), std=np.float32(std)))
            want = ref_gaussian(parts, xy, w, valid, k, std)
            worst = max(worst, rel_err(got, want))
            np.testing.assert_allclose(got, want, rtol=2e-5)
    # k = 1 with one measurement is the Gaussian likelihood.
    one = np.zeros(N_MEAS, bool)
    one[17] = True
    meas1 = meas._replace(valid=one)
    got = np.asarray(_gpw(parts, meas1, np.int32(1), std=np.float32(0.7)))
    d2 = ((parts.astype(np.float64) - xy[17].astype(np.float64)) ** 2).sum(1)
    np.testing.assert_allclose(got, w[17] * np.exp(-d2 / (2 * 0.49)), rtol=2e-5, atol=1e-30)
    # Few valid measurements.
    meas3, xy3, w3, valid3 = make_measurements(rng, n_valid=3, extent=3.0)
    got = np.asarray(_gpw(parts, meas3, np.int32(8), std=np.float32(1.0)))
    np.testing.assert_allclose(got, ref_gaussian(parts, xy3, w3, valid3, 8, 1.0), rtol=2e-5)


def test_observation_pieces_are_logs_of_the_weight_functions():
    rng = np.random.default_rng(3)
    particles = np.asarray(rng.normal(size=(30, 2)) * 2, np.float32)
    buf = hp.Measurements(
        xy=np.asarray(rng.normal(size=(12, 2)), np.float32),
        weight=np.asarray(rng.random(12), np.float32),
        valid=np.asarray(rng.random(12) < 0.8),
        footprint=np.zeros((12, 2, 2), np.float32),
    )
    inv = hp.observation.InverseDistance(k_max=4, knn="dense")
    # Each piece's log-likelihood as one program: run eagerly, each of its operations would compile on its own.
    ll = np.asarray(jax.jit(inv.log_likelihood)(particles, buf,
                                                 hp.observation.InverseDistanceParams(k=3, min_distance=0.05)),
                    np.float64)
    # NumPy brute force of eq. (1).
    m, w = np.asarray(buf.xy)[np.asarray(buf.valid)], np.asarray(buf.weight)[np.asarray(buf.valid)]
    d = np.linalg.norm(np.asarray(particles)[:, None] - m[None], axis=-1)
    idx = np.argsort(d, axis=1)[:, :3]
    ref = np.log(np.sum(np.take_along_axis(w[None] / np.maximum(d, 0.05), idx, axis=1), axis=1))
    np.testing.assert_allclose(ll, ref, rtol=1e-5)
    floored = hp.observation.Floored(inv)
    params = floored.default_params()._replace(base=hp.observation.InverseDistanceParams(k=3, min_distance=0.05),
                                               weight_floor=0.5)
    np.testing.assert_allclose(np.asarray(jax.jit(floored.log_likelihood)(particles, buf, params)),
                               np.maximum(ref, np.log(0.5)), rtol=1e-5)
    assert floored.properties().base == inv.properties()


# --------------------------------------------------------------------------- the default search


def _all_three(method):
    """The three public functions at their default ``method`` (None) or at an explicit one, in one compiled call."""
    kw = {} if method is None else {"method": method}

    def f(particles, meas, k):
        return (
            hp.observation.particle_weights(particles, meas, k, k_max=10, **kw),
            hp.observation.gaussian_particle_weights(particles, meas, k, std=jnp.float32(0.3), k_max=10, **kw),
            hp.observation.k_nearest(particles, meas, k, k_max=10, **kw),
        )

    return jax.jit(f)


def raster_measurements(rng, side=32, spacing=0.1):
    """A heat map's measurements: a jittered ``side x side`` ground grid in raster order, 80% valid."""
    gy, gx = np.meshgrid(np.arange(side) * spacing, np.arange(side) * spacing, indexing="ij")
    xy = np.stack([gx.ravel(), gy.ravel()], 1) + rng.uniform(-0.3, 0.3, (side * side, 2)) * spacing
    weight = rng.uniform(0.05, 1.0, side * side)
    valid = rng.random(side * side) < 0.8
    weight[~valid] = rng.uniform(5.0, 50.0, int((~valid).sum()))  # garbage the search must skip
    return xy.astype(np.float32), weight.astype(np.float32), valid


def test_default_method_is_the_exact_blocked_search_and_equals_dense():
    """The default ("auto") takes the blocked kernel from AUTO_BLOCKED_MIN_SIZE slots on and gives dense's results."""
    parts = np.zeros((4, 2), np.float32)
    for size, blocked in ((AUTO_BLOCKED_MIN_SIZE - 1, False), (AUTO_BLOCKED_MIN_SIZE, True)):
        meas = jax.eval_shape(partial(hp.measurements.empty_measurements, size))  # shapes only: nothing compiled
        jaxpr = str(
            jax.make_jaxpr(lambda p, m: hp.observation.particle_weights(p, m, jnp.int32(3), k_max=10))(parts, meas)
        )
        assert ("top_k" not in jaxpr) == blocked, size  # dense is lax.top_k; the blocked kernel has none

    rng = np.random.default_rng(11)
    xy, weight, valid = raster_measurements(rng)
    assert xy.shape[0] == 1024
    particles = rng.uniform(-0.3, 3.4, (300, 2)).astype(np.float32)
    default, dense = _all_three(None), _all_three("dense")
    perm = rng.permutation(xy.shape[0])
    for order in (np.arange(xy.shape[0]), perm):  # raster order, then random order
        meas = hp.Measurements(xy[order], weight[order], valid[order], np.zeros((len(order), 2, 2), np.float32))
        # Float32 squared distances to the valid measurements, sorted: ties at the k-th are the only freedom.
        p = np.asarray(particles)
        d2 = np.sort(((p[:, None, :] - xy[valid][None]) ** 2).sum(-1, dtype=np.float32), axis=1)
        for k in (1, 10):
            untied = d2[:, k] - d2[:, k - 1] > 1e-6 * d2[:, k]
            assert untied.mean() > 0.95
            (w, g, (sq, ws, sel)), (w_ref, g_ref, (sq_ref, ws_ref, sel_ref)) = (
                default(particles, meas, np.int32(k)),
                dense(particles, meas, np.int32(k)),
            )
            np.testing.assert_allclose(np.asarray(w)[untied], np.asarray(w_ref)[untied], rtol=1e-6)
            np.testing.assert_allclose(np.asarray(g)[untied], np.asarray(g_ref)[untied], rtol=1e-6)
            np.testing.assert_array_equal(np.asarray(sel)[untied], np.asarray(sel_ref)[untied])
            np.testing.assert_allclose(np.asarray(sq)[untied], np.asarray(sq_ref)[untied], rtol=1e-6)
            np.testing.assert_array_equal(np.asarray(ws)[untied], np.asarray(ws_ref)[untied])
            # And both are eq. (1) by float64 brute force.
            np.testing.assert_allclose(np.asarray(w), ref_weights(p, xy[order], weight[order], valid[order], k),
                                       rtol=1e-5)
