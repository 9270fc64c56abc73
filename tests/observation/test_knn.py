"""Blocked exact k-nearest (heatpf_jax.observation.knn) against the plain top_k formulation
and a float64 NumPy brute force."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.observation.knn import BlockPlan, k_nearest_blocked, plan_blocks
from heatpf_jax.presets import validate_options
from tests.conftest import SMALL_OPTIONS

K_MAX = 8
N_PART = 160
M_RANDOM = 301  # not a multiple of the block size (8) nor of 3 * 2 * 2
M_RASTER = 700  # not a multiple of 8 either
MIN_DISTANCE = 0.01

# One compiled function per shape: k traced, bounded by the static K_MAX.
_blocked = jax.jit(partial(k_nearest_blocked, k_max=K_MAX))
# A deeper hierarchy with an odd block size, selecting in lax.map chunks of 48 particles (160 = 3 * 48 + 16).
_blocked_deep = jax.jit(partial(k_nearest_blocked, k_max=K_MAX, block_size=3, fanouts=(2, 2), chunk_size=48))
_plain = jax.jit(partial(hp.observation.k_nearest, k_max=K_MAX, method="dense"))
_blocked_vmap_k = jax.jit(jax.vmap(partial(k_nearest_blocked, k_max=K_MAX, chunk_size=64), in_axes=(None, None, 0)))
_blocked_concrete = jax.jit(k_nearest_blocked, static_argnums=2)
_plain_concrete = jax.jit(partial(hp.observation.k_nearest, method="dense"), static_argnums=2)


def weights_from(sq, w, selected, valid):
    """particle_weights' reduction (eq. 1) of a (sq_dist, weight, selected) triple."""
    dist = jnp.sqrt(jnp.maximum(sq, MIN_DISTANCE**2))
    out = jnp.sum(w / dist, axis=-1)
    return jnp.where(jnp.any(valid), out, jnp.ones_like(out))


def blocked_weights(particles, meas, k, chunk_size=64):
    return weights_from(*k_nearest_blocked(particles, meas, k, k_max=K_MAX, chunk_size=chunk_size), meas.valid)


_grad_blocked = jax.jit(jax.grad(lambda p, m, k: jnp.sum(blocked_weights(p, m, k))))
_grad_plain = jax.jit(
    jax.grad(lambda p, m, k: jnp.sum(hp.observation.particle_weights(p, m, k, k_max=K_MAX, method="dense")))
)
# The reductions the references are checked against, one program each: eager ops compile one by one.
_weights = jax.jit(weights_from)
_plain_weights = jax.jit(partial(hp.observation.particle_weights, k_max=K_MAX, method="dense"))


# --------------------------------------------------------------------------- references and inputs


def ref_knn(particles, xy, weight, valid, k, kk):
    """Float64 brute force: ``[N, kk]`` squared distances, weights, selected (padded like k_nearest)."""
    p = np.asarray(particles, np.float64)
    pts = np.asarray(xy, np.float64)[np.asarray(valid)]
    w = np.asarray(weight, np.float64)[np.asarray(valid)]
    sq = np.ones((p.shape[0], kk))
    ws = np.zeros((p.shape[0], kk))
    sel = np.zeros((p.shape[0], kk), bool)
    n = min(k, pts.shape[0])
    for i in range(p.shape[0]):
        d2 = np.sum((pts - p[i]) ** 2, axis=1)
        order = np.argsort(d2, kind="stable")[:n]
        sq[i, :n], ws[i, :n], sel[i, :n] = d2[order], w[order], True
    return sq, ws, sel


def ref_weights(sq, ws, sel, valid):
    if not np.any(valid):
        return np.ones(sq.shape[0])
    return np.sum(np.where(sel, ws / np.maximum(np.sqrt(sq), MIN_DISTANCE), 0.0), axis=1)


def random_buffer(rng, m=M_RANDOM, n_valid=None, extent=3.0):
    """Uniform positions; invalid slots scattered through the buffer and a run of them at the end."""
    xy = rng.uniform(-extent, extent, (m, 2)).astype(np.float32)
    weight = rng.uniform(0.05, 1.0, m).astype(np.float32)
    if n_valid is None:
        n_valid = int(0.7 * m)
    valid = np.zeros(m, bool)
    valid[rng.choice(m - 20, n_valid, replace=False) if n_valid <= m - 20 else np.arange(n_valid)] = True
    # Garbage in invalid slots (large weights, inside the cloud), as a buffer that aged would hold.
    weight[~valid] = rng.uniform(5.0, 50.0, int((~valid).sum())).astype(np.float32)
    # NumPy arrays, for the jitted functions: jnp's would each compile a program of their own.
    return hp.Measurements(xy, weight, valid, np.zeros((len(xy), 2, 2), np.float32))


def heatmap(rng, shape=(37, 50), blobs=((25.0, 24.0, 9.0), (10.0, 30.0, 4.0))):
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    heat = np.zeros(shape)
    for cu, cv, s in blobs:
        heat += 0.9 * np.exp(-0.5 * ((cols - cu) ** 2 + (rows - cv) ** 2) / s**2)
    return np.clip(heat + 0.02 * rng.standard_normal(shape), 0.0, 1.0).astype(np.float32)


_project = jax.jit(hp.measurements.project_heatmap, static_argnames="max_measurements")


def raster_buffer(rng, threshold):
    """A real projected heat map (raster order, valid slots first when they fit)."""
    heat = heatmap(rng)
    return _project(
        heat,
        np.asarray((35.75, 35.75, 24.5, 18.0), np.float32),  # the paper's intrinsics at 1/4 scale
        np.asarray(hp.camera.camera_pose(height=0.6, pitch=0.5), np.float32),
        threshold=np.float32(threshold),
        plane_height=np.float32(0.075),
        max_measurements=M_RASTER,
    )


def particles_around(rng, meas, n=N_PART, spread=0.3, far=0):
    """A Gaussian cloud around the valid measurements' mean, 5 % uniform explorers, ``far`` distant ones."""
    xy = np.asarray(meas.xy)[np.asarray(meas.valid)]
    centre = xy.mean(axis=0) if xy.size else np.zeros(2)
    p = centre + spread * rng.standard_normal((n, 2))
    n_exp = max(1, n // 20)
    p[:n_exp] = rng.uniform((-0.5, -4.0), (6.5, 4.0), (n_exp, 2))
    if far:
        p[n_exp : n_exp + far] = rng.choice([-1.0, 1.0], (far, 2)) * rng.uniform(50.0, 1e3, (far, 2))
    return p.astype(np.float32)


def shuffled_buffer(rng, m, valid_fraction, extent=3.0):
    """Uniform positions in random order, invalid slots (with garbage positions and weights) anywhere."""
    xy = rng.uniform(-extent, extent, (m, 2)).astype(np.float32)
    weight = rng.uniform(0.05, 1.0, m).astype(np.float32)
    valid = rng.uniform(size=m) < valid_fraction
    weight[~valid] = rng.uniform(5.0, 50.0, int((~valid).sum())).astype(np.float32)
    return hp.Measurements(xy, weight, valid, np.zeros((len(xy), 2, 2), np.float32))


def uniform_particles(rng, meas, n=N_PART, far=0):
    """Particles uniform over the valid measurements' bounding box (the whole buffer's if none), ``far`` distant."""
    xy = np.asarray(meas.xy)
    valid = np.asarray(meas.valid)
    box = xy[valid] if valid.any() else xy
    p = rng.uniform(box.min(axis=0), box.max(axis=0), (n, 2))
    if far:
        p[:far] = rng.choice([-1.0, 1.0], (far, 2)) * rng.uniform(50.0, 1e3, (far, 2))
    return p.astype(np.float32)


def assert_same(a, b) -> None:
    """Equal selections, weights and indices; squared distances computed by two programs equal to float rounding.

    Two compilations may contract ``dx * dx + dy * dy`` differently (an FMA or not: XLA's optimisation level, the
    CPU), which moves a distance by an ulp or two; the selections do not move.
    """
    a, b = np.asarray(a), np.asarray(b)
    if np.issubdtype(a.dtype, np.floating):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=0.0)
    else:
        np.testing.assert_array_equal(a, b)


def check_against_references(particles, meas, k, got, *, tol=1e-5):
    """``got`` (blocked) equals the plain formulation and the float64 brute force."""
    kk = got[0].shape[1]
    sq, w, sel = (np.asarray(a) for a in got)
    psq, pw, psel = (np.asarray(a) for a in _plain(particles, meas, jnp.int32(k)))
    np.testing.assert_array_equal(sel, psel)
    np.testing.assert_allclose(sq, psq, rtol=1e-6, atol=0.0)
    np.testing.assert_array_equal(w, pw)
    valid = np.asarray(meas.valid)
    rsq, rw, rsel = ref_knn(particles, meas.xy, meas.weight, valid, k, kk)
    np.testing.assert_array_equal(sel, rsel)
    np.testing.assert_allclose(sq, rsq, rtol=tol, atol=1e-12)
    np.testing.assert_allclose(w, rw, rtol=1e-7)
    ours = np.asarray(_weights(*got, meas.valid))
    plain = np.asarray(_plain_weights(particles, meas, jnp.int32(k)))
    np.testing.assert_allclose(ours, plain, rtol=tol)
    np.testing.assert_allclose(ours, ref_weights(rsq, rw, rsel, valid), rtol=tol)


# --------------------------------------------------------------------------- plans


def test_plan_blocks_covers_the_buffer():
    for m in (1, 5, 8, 9, 301, 700, 1024, 4096, 8192):
        for k_max in (1, 3, 10, 40):
            for block_size in (1, 3, 8):
                plan = plan_blocks(m, k_max, block_size)
                assert isinstance(plan, BlockPlan)
                group = plan.block_size * int(np.prod(plan.fanouts, dtype=np.int64))
                assert plan.padded_size == plan.num_top * group >= m
                assert plan.padded_size - m < group
    assert plan_blocks(4096, 10) == BlockPlan(4, (4, 4), 64, 4096)
    assert plan_blocks(300, 10, 4, fanouts=(2, 3)) == BlockPlan(4, (2, 3), 13, 312)
    with pytest.raises(ValueError, match="chunk_size"):
        k_nearest_blocked(jnp.zeros((3, 2)), hp.measurements.empty_measurements(10), 2, chunk_size=0)
    for bad in ((0, 10), (10, 0)):
        with pytest.raises(ValueError):
            plan_blocks(*bad)
    with pytest.raises(ValueError):
        plan_blocks(100, 10, 0)
    with pytest.raises(ValueError):
        plan_blocks(100, 10, 8, fanouts=(0,))


def test_traced_k_needs_k_max():
    meas = random_buffer(np.random.default_rng(0))
    with pytest.raises(ValueError, match="k_max"):
        jax.jit(lambda p, m, k: k_nearest_blocked(p, m, k))(jnp.zeros((3, 2)), meas, jnp.int32(2))


# --------------------------------------------------------------------------- equality with top_k and brute force


def test_random_layout_every_k_scattered_padding_and_far_particles():
    rng = np.random.default_rng(1)
    for _ in range(2):
        meas = random_buffer(rng)
        parts = particles_around(rng, meas, spread=1.5, far=10)
        for k in range(1, K_MAX + 1):
            check_against_references(parts, meas, k, _blocked(parts, meas, jnp.int32(k)))
            check_against_references(parts, meas, k, _blocked_deep(parts, meas, jnp.int32(k)))


# Random-order buffers (a user's own source, measurements fused from other robots) with particles spread
# over the same area: sizes below, at and above the block size, multiples of it or not (7 < K_MAX).
@pytest.mark.parametrize(("m", "valid_fraction"), [(7, 0.8), (64, 1.0), (301, 0.6), (1027, 0.9)])
def test_random_order_layout_matches_brute_force(m, valid_fraction):
    rng = np.random.default_rng(m)
    meas = shuffled_buffer(rng, m, valid_fraction)
    parts = uniform_particles(rng, meas, far=3)
    for k in (1, 3, K_MAX):
        check_against_references(parts, meas, k, _blocked(parts, meas, jnp.int32(k)))
    check_against_references(parts, meas, K_MAX, _blocked_deep(parts, meas, jnp.int32(K_MAX)))


def test_buffer_order_changes_nothing():
    """Any permutation of the buffer (raster, reversed, random) gives the same outputs: same kernel, same work."""
    rng = np.random.default_rng(15)
    raster = raster_buffer(rng, 0.2)
    parts = uniform_particles(rng, raster, far=2)
    want = [np.asarray(a) for a in _blocked(parts, raster, jnp.int32(K_MAX))]
    for order in (np.arange(M_RASTER)[::-1], rng.permutation(M_RASTER)):
        permuted = jax.tree.map(lambda a, order=order: np.asarray(a)[order], raster)  # NumPy: no gather to compile
        got = [np.asarray(a) for a in _blocked(parts, permuted, jnp.int32(K_MAX))]
        for a, b in zip(got, want, strict=True):
            assert_same(a, b)
    check_against_references(parts, permuted, K_MAX, _blocked(parts, permuted, jnp.int32(K_MAX)))


@pytest.mark.parametrize("threshold", [0.05, 0.35])  # more pixels than slots / fewer (invalid run at the end)
def test_projected_heat_map_layout(threshold):
    rng = np.random.default_rng(2)
    meas = raster_buffer(rng, threshold)
    n_valid = int(np.sum(np.asarray(meas.valid)))
    assert (n_valid == M_RASTER) == (threshold < 0.1) and n_valid > 50
    parts = particles_around(rng, meas, far=5)
    for k in (1, 2, 5, K_MAX):
        check_against_references(parts, meas, k, _blocked(parts, meas, jnp.int32(k)))
    # The same buffer with a third of its slots invalidated at random: scattered valid slots.
    keep = np.asarray(meas.valid) & (rng.uniform(size=M_RASTER) > 0.33)
    holes = meas._replace(weight=np.where(keep, np.asarray(meas.weight), np.float32(7.0)), valid=keep)
    for k in (1, K_MAX):
        check_against_references(parts, holes, k, _blocked(parts, holes, jnp.int32(k)))


def test_fewer_valid_than_k_and_none_valid():
    rng = np.random.default_rng(3)
    for n_valid in (0, 1, 3, 7):
        meas = random_buffer(rng, n_valid=n_valid)
        parts = particles_around(rng, meas, spread=2.0, far=3)
        for k in (1, 4, K_MAX):
            got = _blocked(parts, meas, jnp.int32(k))
            check_against_references(parts, meas, k, got)
            assert int(np.sum(np.asarray(got[2]), axis=1).max()) == min(k, n_valid)
    empty = jax.jit(hp.measurements.empty_measurements, static_argnums=0)(M_RANDOM)  # one program, not one per field
    sq, w, sel = (np.asarray(a) for a in _blocked(parts, empty, jnp.int32(3)))
    assert not sel.any() and (sq == 1.0).all() and (w == 0.0).all()
    np.testing.assert_array_equal(np.asarray(_weights(sq, w, sel, empty.valid)), np.ones(N_PART))


def test_buffer_smaller_than_k_and_concrete_k():
    rng = np.random.default_rng(4)
    meas = random_buffer(rng, m=5, n_valid=4)
    parts = particles_around(rng, meas, n=20, spread=3.0)
    for k in (1, 3, 5, 8):
        got = _blocked_concrete(parts, meas, k)
        want = _plain_concrete(parts, meas, k)
        assert got[0].shape == want[0].shape == (20, min(k, 5))
        for a, b in zip(got, want, strict=True):
            assert_same(a, b)


def test_concrete_k_unrolled_path_on_hierarchies():
    """A concrete k runs every round unrolled (no null groups): same references as the traced path."""
    rng = np.random.default_rng(14)
    meas = random_buffer(rng)
    parts = particles_around(rng, meas, spread=1.5, far=4)
    deep = jax.jit(partial(k_nearest_blocked, block_size=3, fanouts=(2, 2), chunk_size=48), static_argnums=2)
    for k in (1, 3, K_MAX):
        for fn in (_blocked_concrete, deep):
            got = tuple(np.asarray(a) for a in fn(parts, meas, k))
            traced = tuple(np.asarray(a)[:, :k] for a in _blocked(parts, meas, jnp.int32(k)))
            for a, b in zip(got, traced, strict=True):
                assert_same(a, b)
            rsq, rw, rsel = ref_knn(parts, meas.xy, meas.weight, np.asarray(meas.valid), k, k)
            np.testing.assert_array_equal(got[2], rsel)
            np.testing.assert_allclose(got[0], rsq, rtol=1e-5, atol=1e-12)


@pytest.mark.parametrize("shuffle", [False, True])
def test_distance_ties_give_a_valid_neighbour_set(shuffle):
    """A lattice with particles on lattice points and cell centres: many exact ties; equal weights.

    In row order, or shuffled (the invalid slot then lands anywhere in the buffer).
    """
    gx, gy = np.meshgrid(np.arange(20.0), np.arange(15.0))
    xy = np.stack([gx.ravel(), gy.ravel()], -1).astype(np.float32)
    xy = np.concatenate([xy, np.zeros((1, 2), np.float32)])  # 301 slots, the last one invalid
    valid = np.ones(M_RANDOM, bool)
    valid[-1] = False
    rng = np.random.default_rng(5)
    if shuffle:
        order = rng.permutation(M_RANDOM)
        xy, valid = xy[order], valid[order]
    meas = hp.Measurements(xy, np.ones(M_RANDOM, np.float32), valid, np.zeros((M_RANDOM, 2, 2), np.float32))
    parts = np.concatenate([rng.integers(0, 15, (80, 2)), rng.integers(0, 14, (80, 2)) + 0.5]).astype(np.float32)
    for k in range(1, K_MAX + 1):
        for fn in (_blocked, _blocked_deep):
            sq, w, sel = (np.asarray(a) for a in fn(parts, meas, jnp.int32(k)))
            psq, pw, psel = (np.asarray(a) for a in _plain(parts, meas, jnp.int32(k)))
            # Sorted distances and weights agree even where the tied members chosen differ.
            np.testing.assert_array_equal(sq, psq)
            np.testing.assert_array_equal(w, pw)
            np.testing.assert_array_equal(sel, psel)


# --------------------------------------------------------------------------- transformations


@pytest.mark.parametrize("particles", ["cloud", "uniform"])
def test_vmap_over_k(particles):
    rng = np.random.default_rng(6)
    meas = random_buffer(rng)  # random order, invalid slots scattered and a run at the end
    parts = particles_around(rng, meas, spread=1.0) if particles == "cloud" else uniform_particles(rng, meas, far=2)
    ks = np.arange(1, K_MAX + 1, dtype=np.int32)
    batched = [np.asarray(a) for a in _blocked_vmap_k(parts, meas, ks)]  # indexed in NumPy: no slice to compile
    for i, k in enumerate(range(1, K_MAX + 1)):
        check_against_references(parts, meas, k, tuple(a[i] for a in batched))


def test_vmap_over_buffers_and_scan():
    rng = np.random.default_rng(7)
    m1, m2 = random_buffer(rng), random_buffer(rng, n_valid=100)
    stacked = jax.tree.map(lambda a, b: np.stack([a, b]), m1, m2)
    p1, p2 = particles_around(rng, m1, spread=1.0), particles_around(rng, m2, spread=1.0)
    parts = np.stack([p1, p2])
    batched = jax.vmap(partial(k_nearest_blocked, k_max=K_MAX, chunk_size=64), in_axes=(0, 0, None))
    got = [np.asarray(a) for a in jax.jit(batched)(parts, stacked, 5)]  # indexed in NumPy: no slice to compile
    for i, (p, m) in enumerate(((p1, m1), (p2, m2))):
        check_against_references(p, m, 5, tuple(a[i] for a in got))

    def rollout(weights_fn, p, m):
        def body(p, shift):
            w = weights_fn(p, m, jnp.int32(4))
            return p + shift[None, :], w

        return jax.lax.scan(body, p, jnp.asarray([[0.1, 0.0], [0.0, -0.2], [0.3, 0.3]], jnp.float32))[1]

    plain = partial(hp.observation.particle_weights, k_max=K_MAX, method="dense")
    ours = jax.jit(partial(rollout, blocked_weights))(p1, m1)
    want = jax.jit(partial(rollout, plain))(p1, m1)
    np.testing.assert_allclose(np.asarray(ours), np.asarray(want), rtol=1e-5)


@pytest.mark.parametrize("layout", ["raster", "random"])
def test_grad_matches_plain_formulation(layout):
    rng = np.random.default_rng(8)
    if layout == "raster":
        meas = raster_buffer(rng, 0.2)
        parts = np.array(particles_around(rng, meas, far=3))
    else:
        meas = shuffled_buffer(rng, M_RANDOM, 0.7)
        parts = np.array(uniform_particles(rng, meas, far=3))
    first_valid = int(np.flatnonzero(np.asarray(meas.valid))[0])
    parts[-1] = np.asarray(meas.xy)[first_valid]  # on top of a measurement: inside the distance floor
    for k in (1, 3, K_MAX):
        g = np.asarray(_grad_blocked(parts, meas, jnp.int32(k)))
        want = np.asarray(_grad_plain(parts, meas, jnp.int32(k)))
        assert np.all(np.isfinite(g))
        np.testing.assert_allclose(g, want, rtol=1e-5, atol=1e-6 * np.abs(want).max())
    # Gradients reach the measurement weights through the selected slots only.
    # Jitted, one program each where eager ops compile one by one; the buffer an argument (NumPy arrays are not
    # indexed by traced slots).
    gw = jax.jit(jax.grad(lambda w, m: jnp.sum(blocked_weights(parts, m._replace(weight=w), jnp.int32(3)))))(
        meas.weight, meas)
    dense = partial(hp.observation.particle_weights, k_max=K_MAX, method="dense")
    gw_plain = jax.jit(jax.grad(lambda w, m: jnp.sum(dense(parts, m._replace(weight=w), jnp.int32(3)))))(
        meas.weight, meas)
    np.testing.assert_allclose(np.asarray(gw), np.asarray(gw_plain), rtol=1e-5, atol=1e-7)


def test_filter_gives_the_same_run_with_blocked_and_dense_search(small_sequence):
    key = jax.random.key(9)
    dense_filter = hp.paper_filter(SMALL_OPTIONS._replace(knn="dense"))
    blocked_filter = hp.paper_filter(SMALL_OPTIONS._replace(knn="blocked"))
    params = dense_filter.make_params(k=4)
    dense = hp.run(key, small_sequence, params, dense_filter)
    blocked = hp.run(key, small_sequence, params, blocked_filter)
    np.testing.assert_allclose(np.asarray(blocked.info.mean), np.asarray(dense.info.mean), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(
        np.asarray(blocked.final_state.particles.xy), np.asarray(dense.final_state.particles.xy)
    )


def test_unknown_search_method_is_refused():
    meas = hp.measurements.empty_measurements(8)
    with pytest.raises(ValueError, match="method"):
        hp.observation.particle_weights(jnp.zeros((2, 2), jnp.float32), meas, 1, method="kdtree")
    with pytest.raises(ValueError, match="knn"):
        validate_options(hp.FilterOptions(knn="kdtree"))


def test_batched_k_shares_one_unbatched_round_count():
    """Under vmap over k the selection loops share the batch's largest k as an unbatched bound (no carry
    selects): out_axes=None would fail if the count were batched. Results stay exact (test_vmap_over_k)."""
    from heatpf_jax.observation.knn import _shared_round_count

    ks = jnp.array([2, 7, 3], jnp.int32)
    assert int(jax.vmap(_shared_round_count, out_axes=None)(ks)) == 7
    assert int(jax.jit(jax.vmap(_shared_round_count, out_axes=None))(ks)) == 7
    assert int(_shared_round_count(jnp.int32(4))) == 4
