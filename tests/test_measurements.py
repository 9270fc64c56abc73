"""Heat-map projection, down-scaling and the measurement buffer, against NumPy loops and hand-computed values."""


import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp

H, W = 24, 32
INTRINSICS = np.array([32.0, 30.0, 15.5, 11.5])  # heat-map pixels; fx != fy
PLANE = 0.05
POSE = hp.camera.camera_pose(height=0.55, pitch=0.3, yaw=0.2, roll=0.05, x=0.1, y=-0.05)
M_FIT = 300  # fewer slots than pixels: the compaction / top-k paths


def _project(heatmap, threshold, *, max_measurements, max_distance=np.inf, downscale=1, pose=POSE):
    return hp.measurements.project_heatmap(
        heatmap,
        jnp.asarray(INTRINSICS, jnp.float32),
        jnp.asarray(pose, jnp.float32),
        threshold=threshold,
        plane_height=jnp.float32(PLANE),
        max_measurements=max_measurements,
        max_distance=jnp.float32(max_distance),
        downscale=downscale,
    )


# One compiled function per (shape, static size).
_project_jit = jax.jit(_project, static_argnames=("max_measurements", "downscale"))


def project(heatmap, threshold, **kw):
    # NumPy arguments: eager `jnp` conversions would each compile a program of their own.
    out = _project_jit(np.asarray(heatmap, np.float32), np.float32(threshold), **kw)
    return hp.Measurements(*(np.asarray(a) for a in out))


def ref_project(heatmap, threshold, intrinsics=INTRINSICS, pose=POSE, max_distance=np.inf, centres=None):
    """NumPy loop over pixels (raster order): ray through the pixel centre meets z = PLANE in front of the camera.

    Returns (xy [n, 2], weight [n], pixel index [n]) of the passing pixels, in raster order.
    """
    fx, fy, cx, cy = intrinsics
    rot, t = np.asarray(pose, np.float64)[:3, :3], np.asarray(pose, np.float64)[:3, 3]
    xys, ws, idx = [], [], []
    h, w = heatmap.shape
    for v in range(h):
        for u in range(w):
            act = heatmap[v, u]
            if not act >= threshold:
                continue
            uc, vc = (u, v) if centres is None else centres(u, v)
            d = rot @ np.array([(uc - cx) / fx, (vc - cy) / fy, 1.0])
            if abs(d[2]) < 1e-9:
                continue
            s = (PLANE - t[2]) / d[2]
            if s <= 0:
                continue
            p = t[:2] + s * d[:2]
            if np.hypot(*p) > max_distance:
                continue
            xys.append(p)
            ws.append(float(act))
            idx.append(v * w + u)
    return np.array(xys).reshape(-1, 2), np.array(ws), np.array(idx, int)


def ray_dz():
    """[H, W] base-frame z component of each pixel-centre ray (>= 0: at or above the horizon)."""
    fx, fy, cx, cy = INTRINSICS
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    return (POSE[2, 0] * (u - cx) / fx + POSE[2, 1] * (v - cy) / fy + POSE[2, 2])


def random_heatmap(rng, shape=(H, W)):
    return rng.random(shape).astype(np.float32)


def assert_matches_reference(m, ref_xy, ref_w, *, rtol=1e-4):
    got_xy, got_w = m.xy[m.valid], m.weight[m.valid]
    assert got_xy.shape == ref_xy.shape
    # Same measurements in the same (raster) order.
    np.testing.assert_array_equal(got_w, ref_w.astype(np.float32))
    # float32 error grows with the distance (grazing rays near the horizon reach > 100 m).
    err = np.hypot(*(got_xy - ref_xy).T)
    scale = np.maximum(np.hypot(*ref_xy.T), 1.0)
    assert np.all(err <= rtol * scale**2), np.max(err / scale**2)
    # Invalid slots hold zeros.
    np.testing.assert_array_equal(m.xy[~m.valid], 0.0)
    np.testing.assert_array_equal(m.weight[~m.valid], 0.0)


# --------------------------------------------------------------------------- project_heatmap


def test_project_heatmap_matches_pixel_loop():
    rng = np.random.default_rng(30)
    assert (ray_dz() >= 0).sum() > 40  # the pose sees the horizon: some pixels are above it
    for threshold in (0.7, 0.75):
        heat = random_heatmap(rng)
        ref_xy, ref_w, _ = ref_project(heat, np.float32(threshold))
        assert 0 < ref_w.size <= M_FIT
        m = project(heat, threshold, max_measurements=M_FIT)
        assert m.valid.sum() == ref_w.size
        # All passing pixels fit: valid ones first, in raster order.
        assert m.valid[: ref_w.size].all() and not m.valid[ref_w.size :].any()
        assert_matches_reference(m, ref_xy, ref_w)
        assert np.all(m.weight[m.valid] >= np.float32(threshold))


def test_project_heatmap_max_distance():
    rng = np.random.default_rng(31)
    heat = random_heatmap(rng)
    limit = 3.0
    ref_xy, ref_w, _ = ref_project(heat, np.float32(0.6), max_distance=limit)
    all_xy, _, _ = ref_project(heat, np.float32(0.6))
    dist = np.hypot(*all_xy.T)
    assert np.all(np.abs(dist - limit) > 1e-3)  # no pixel on the boundary
    assert (dist > limit).any()
    m = project(heat, 0.6, max_measurements=M_FIT, max_distance=limit)
    assert_matches_reference(m, ref_xy, ref_w)
    assert np.all(np.hypot(*m.xy[m.valid].T) <= limit)


def test_project_heatmap_overflow_keeps_strongest_in_raster_order():
    rng = np.random.default_rng(32)
    heat = random_heatmap(rng)
    threshold = np.float32(0.2)
    ref_xy, ref_w, ref_idx = ref_project(heat, threshold)
    assert ref_w.size > M_FIT
    # The reference's top-M_FIT activations (no ties), then back to raster order.
    order = np.argsort(-ref_w, kind="stable")
    assert ref_w[order[M_FIT - 1]] > ref_w[order[M_FIT]]
    keep = np.sort(order[:M_FIT])
    m = project(heat, threshold, max_measurements=M_FIT)
    assert m.valid.sum() == M_FIT
    assert_matches_reference(m, ref_xy[keep], ref_w[keep])
    assert m.weight[m.valid].min() > ref_w[order[M_FIT]]


def test_project_heatmap_traced_threshold_equals_concrete():
    rng = np.random.default_rng(33)
    heat = jnp.asarray(random_heatmap(rng))
    intr = jnp.asarray(INTRINSICS, jnp.float32)
    pose = jnp.asarray(POSE, jnp.float32)
    for threshold in (0.3, 0.8):  # overflow and compaction paths
        concrete = hp.measurements.project_heatmap(
            heat, intr, pose, threshold=threshold, plane_height=PLANE, max_measurements=M_FIT
        )
        traced = _project_jit(heat, jnp.float32(threshold), max_measurements=M_FIT)
        # Same selection and weights; positions up to float32 rounding (eager vs. fused, far points reach 170 m).
        np.testing.assert_array_equal(np.asarray(concrete.valid), np.asarray(traced.valid))
        np.testing.assert_array_equal(np.asarray(concrete.weight), np.asarray(traced.weight))
        np.testing.assert_allclose(np.asarray(concrete.xy), np.asarray(traced.xy), rtol=2e-5, atol=1e-6)
        assert 0 < int(np.asarray(concrete.valid).sum()) <= M_FIT


def test_pixels_above_horizon_never_valid():
    heat = np.ones((H, W), np.float32)
    dz = ray_dz()
    above = dz >= 0
    assert above.sum() > 40 and above[0].all() and not above[-1].any()
    ref_xy, ref_w, ref_idx = ref_project(heat, np.float32(0.5))
    near = np.abs(dz) < 1e-5  # float32 may decide either way on the horizon itself (min |dz| here: 9e-5)
    assert not near.any()
    np.testing.assert_array_equal(np.sort(ref_idx), np.flatnonzero(~above.ravel()))
    for size in (M_FIT, H * W + 40):
        m = project(heat, 0.5, max_measurements=size)
        n = min(size, ref_w.size)
        assert m.valid.sum() == n
        if size > ref_w.size:
            assert_matches_reference(m, ref_xy, ref_w)
        # Every valid measurement lies ahead of the camera along its heading (never behind, from the sky).
        heading = POSE[:2, 2] / np.linalg.norm(POSE[:2, 2])
        assert np.all((m.xy[m.valid] - POSE[:2, 3]) @ heading > 0)


def test_project_heatmap_pads_when_larger_than_image():
    rng = np.random.default_rng(34)
    heat = random_heatmap(rng)
    size = H * W + 40
    ref_xy, ref_w, ref_idx = ref_project(heat, np.float32(0.5))
    m = project(heat, 0.5, max_measurements=size)
    assert m.xy.shape == (size, 2) and m.weight.shape == (size,) and m.valid.shape == (size,)
    assert not m.valid[H * W :].any()
    assert_matches_reference(m, ref_xy, ref_w)


def test_project_heatmap_valid_first_when_padded():
    rng = np.random.default_rng(35)
    heat = random_heatmap(rng)
    m = project(heat, 0.5, max_measurements=H * W + 40)
    n = int(m.valid.sum())
    assert 0 < n < H * W
    assert m.valid[:n].all()


# --------------------------------------------------------------------------- downscale


# One program per (shape, factor): run eagerly, each of its operations would compile on its own.
_downscale = jax.jit(hp.measurements.downscale_heatmap, static_argnums=2)


@pytest.mark.parametrize("factor, shape", [(2, (24, 32)), (3, (25, 34)), (4, (24, 32))])
def test_downscale_heatmap_block_mean_and_pixel_centres(factor, shape):
    rng = np.random.default_rng(36 + factor)
    heat = random_heatmap(rng, shape)
    small, intr = _downscale(heat, INTRINSICS.astype(np.float32), factor)
    small, intr = np.asarray(small), np.asarray(intr, np.float64)
    h2, w2 = shape[0] // factor, shape[1] // factor
    assert small.shape == (h2, w2)
    want = np.empty((h2, w2))
    for i in range(h2):
        for j in range(w2):
            want[i, j] = heat[i * factor : (i + 1) * factor, j * factor : (j + 1) * factor].astype(np.float64).mean()
    np.testing.assert_allclose(small, want, rtol=1e-6)
    # The ray of new pixel (u', v') is the ray of old continuous pixel factor * (u', v') + (factor - 1) / 2.
    fx, fy, cx, cy = INTRINSICS
    for up, vp in rng.uniform(-2, max(h2, w2) + 2, (20, 2)):
        new_ray = np.array([(up - intr[2]) / intr[0], (vp - intr[3]) / intr[1], 1.0])
        uo, vo = factor * up + (factor - 1) / 2, factor * vp + (factor - 1) / 2
        np.testing.assert_allclose(new_ray, [(uo - cx) / fx, (vo - cy) / fy, 1.0], atol=1e-6)
    # factor 1 is the identity.
    same, intr1 = _downscale(heat, INTRINSICS.astype(np.float32), 1)
    np.testing.assert_array_equal(np.asarray(same), heat)
    np.testing.assert_array_equal(np.asarray(intr1), INTRINSICS.astype(np.float32))


def test_downscale_bad_factor_raises():
    heat = jnp.ones((6, 8), jnp.float32)
    with pytest.raises(ValueError):
        hp.measurements.downscale_heatmap(heat, jnp.asarray(INTRINSICS, jnp.float32), 0)
    with pytest.raises(ValueError):
        hp.measurements.downscale_heatmap(heat, jnp.asarray(INTRINSICS, jnp.float32), 7)


def test_project_heatmap_downscale_uses_block_centres():
    rng = np.random.default_rng(40)
    factor = 2
    heat = random_heatmap(rng)
    blocks = heat.reshape(H // factor, factor, W // factor, factor).astype(np.float64).mean(axis=(1, 3))
    blocks32 = blocks.astype(np.float32)
    threshold = np.float32(0.55)
    ref_xy, ref_w, _ = ref_project(
        blocks32, threshold, centres=lambda u, v: (factor * u + 0.5, factor * v + 0.5)
    )
    m = project(heat, threshold, max_measurements=M_FIT, downscale=factor)
    got_w = m.weight[m.valid]
    # Block means can differ from the float64 ones in the last bit: compare weights to 1e-6.
    assert got_w.size == ref_w.size
    np.testing.assert_allclose(got_w, ref_w, rtol=1e-6)
    err = np.hypot(*(m.xy[m.valid] - ref_xy).T)
    scale = np.maximum(np.hypot(*ref_xy.T), 1.0)
    assert np.all(err <= 1e-4 * scale**2), np.max(err / scale**2)
    assert np.all(np.abs(blocks - threshold) > 1e-6)  # no block on the threshold


# --------------------------------------------------------------------------- buffer: aging, update, motion


def make_buffer(weights, valid, xy=None):
    n = len(weights)
    if xy is None:
        xy = np.random.default_rng(41).uniform(-2, 2, (n, 2))
    # NumPy, for the jitted functions: `jnp` conversions would each compile a program of their own.
    return hp.Measurements(
        np.asarray(xy, np.float32),
        np.asarray(weights, np.float32),
        np.asarray(valid, bool),
        np.zeros((n, 2, 2), np.float32),
    )


_update = jax.jit(hp.measurements.update_buffer)
_age = jax.jit(hp.measurements.age_measurements)


def test_age_measurements_subtracts_and_invalidates():
    weights = np.array([1.0, 0.55, 0.45, 0.3, 0.9, 0.0], np.float32)
    valid = np.array([True, True, True, True, False, False])
    buf = make_buffer(weights, valid)
    out = _age(buf, np.float32(0.3), np.float32(0.2))
    want_w = np.array([0.7, 0.25, 0.0, 0.0, 0.0, 0.0])
    want_valid = np.array([True, True, False, False, False, False])  # 0.15 < 0.2, 0.0 < 0.2; invalid stay invalid
    np.testing.assert_array_equal(np.asarray(out.valid), want_valid)
    np.testing.assert_allclose(np.asarray(out.weight), want_w, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(out.xy), np.asarray(buf.xy))


def test_update_buffer_aging_schedule():
    """Weight 1.0, v = 0.3, l = 0.2: valid for exactly the steps n with 1 - 0.3 n >= 0.2 (n = 0, 1, 2)."""
    weights = [1.0, 0.9, 0.65, 0.45, 0.7]
    valid = [True, True, True, True, False]
    buf = make_buffer(weights, valid)
    never = make_buffer([0.9] * 5, [True] * 5)  # a valid heat map that is not delivered
    aging, min_w = np.float32(0.3), np.float32(0.2)
    expected = []
    for n in range(1, 6):
        w = np.array(weights) - 0.3 * n
        ok = np.array(valid) & (w >= 0.2)  # no value lands within 0.05 of l
        assert np.all(np.abs(w - 0.2) > 0.04)
        expected.append((np.where(ok, w, 0.0), ok))
    # Hand check of the table: 1.0 -> 0.7, 0.4, dead; 0.9 -> 0.6, 0.3, dead; 0.65 -> 0.35, dead; 0.45 -> dead.
    np.testing.assert_array_equal([e[1].sum() for e in expected], [3, 2, 0, 0, 0])
    for n in range(5):
        buf = _update(buf, never, np.asarray(False), aging, min_w)
        np.testing.assert_array_equal(np.asarray(buf.valid), expected[n][1])
        np.testing.assert_allclose(np.asarray(buf.weight), expected[n][0], atol=1e-5)
    assert not np.asarray(buf.valid).any()


def test_update_buffer_replaces_only_with_usable_new_measurements():
    rng = np.random.default_rng(42)
    buf = make_buffer([0.9, 0.8, 0.5, 0.0], [True, True, True, False], rng.uniform(-2, 2, (4, 2)))
    aging, min_w = np.float32(0.1), np.float32(0.45)
    aged_w = np.array([0.8, 0.7, 0.0, 0.0])
    aged_valid = np.array([True, True, False, False])

    def check(out, want_xy, want_w, want_valid):
        want_valid = np.asarray(want_valid)
        np.testing.assert_array_equal(np.asarray(out.valid), want_valid)
        np.testing.assert_allclose(np.asarray(out.weight), want_w, atol=1e-6)
        np.testing.assert_allclose(np.asarray(out.xy)[want_valid], want_xy[want_valid], atol=0)

    new_xy = rng.uniform(-2, 2, (4, 2)).astype(np.float32)
    # Usable new measurements replace the buffer; those below l are dropped, nothing is aged.
    new = make_buffer([0.95, 0.3, 0.6, 0.8], [True, True, True, False], new_xy)
    check(_update(buf, new, np.asarray(True), aging, min_w), new_xy, [0.95, 0.0, 0.6, 0.0], [True, False, True, False])
    old_xy = np.asarray(buf.xy)
    # has_new False: the buffer ages, the new set is ignored.
    check(_update(buf, new, np.asarray(False), aging, min_w), old_xy, aged_w, aged_valid)
    # A heat map with no valid measurement counts as no input.
    empty = make_buffer([0.9, 0.9, 0.9, 0.9], [False] * 4, new_xy)
    check(_update(buf, empty, np.asarray(True), aging, min_w), old_xy, aged_w, aged_valid)
    # So does one whose valid measurements are all below l.
    weak = make_buffer([0.3, 0.2, 0.44, 0.9], [True, True, True, False], new_xy)
    check(_update(buf, weak, np.asarray(True), aging, min_w), old_xy, aged_w, aged_valid)


def test_move_measurements_world_fixed_points():
    rng = np.random.default_rng(43)
    n = 50
    xy = rng.uniform(-3, 3, (n, 2)).astype(np.float32)
    valid = rng.random(n) < 0.6
    weights = rng.uniform(0.1, 1.0, n).astype(np.float32)
    xy_in = np.where(valid[:, None], xy, 0.0)
    buf = make_buffer(weights, valid, xy_in)
    move = jax.jit(hp.measurements.move_measurements)
    for odo in rng.uniform([-0.3, -0.3, -0.8], [0.3, 0.3, 0.8], (3, 3)):
        out = move(buf, np.asarray(odo, np.float32))
        c, s = np.cos(odo[2]), np.sin(odo[2])
        rot = np.array([[c, -s], [s, c]])
        want = (xy.astype(np.float64) - odo[:2]) @ rot  # rows: R^T (p - d)
        np.testing.assert_allclose(np.asarray(out.xy)[valid], want[valid], atol=2e-6)
        np.testing.assert_array_equal(np.asarray(out.xy)[~valid], 0.0)
        np.testing.assert_array_equal(np.asarray(out.valid), valid)
        np.testing.assert_array_equal(np.asarray(out.weight), weights)
        # Distances between world-fixed points are preserved.
        d_in = np.linalg.norm(xy[valid][1:] - xy[valid][0], axis=1)
        d_out = np.linalg.norm(np.asarray(out.xy)[valid][1:] - np.asarray(out.xy)[valid][0], axis=1)
        np.testing.assert_allclose(d_out, d_in, atol=1e-5)
