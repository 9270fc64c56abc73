"""Range-aware observation model: footprints against float64 NumPy finite differences of the projection,
the likelihood against a NumPy brute force over all measurements, gradients, properties."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.camera import ground_jacobian
from heatpf_jax.observation.range_aware import (
    FootprintKernel,
    FootprintTemplate,
    FootprintTemplateParams,
    footprint_kernel_log_likelihood,
    footprint_template_log_likelihood,
)
from heatpf_jax.pieces import ObservationModel

INTRINSICS = np.array([143.0, 150.0, 99.5, 74.5])  # the simulator's camera, with fy != fx to catch swaps
PLANE = 0.075
K_MAX = 6
N_PART, N_MEAS = 64, 40

_jacobians = jax.jit(jax.vmap(ground_jacobian, in_axes=(0, None, None, None)))
_loglik = jax.jit(footprint_template_log_likelihood, static_argnames=("k_max", "method"))
_project = jax.jit(hp.measurements.project_heatmap, static_argnames="max_measurements")
_move = jax.jit(hp.measurements.move_measurements)
_age = jax.jit(hp.measurements.age_measurements)
_empty = jax.jit(hp.measurements.empty_measurements, static_argnums=0)
# Test inputs are NumPy throughout: eager `jnp` conversions and `.at[].set()` compile a program each.


# --------------------------------------------------------------------------- references


def ref_hit(uv, pose, plane=PLANE, intrinsics=INTRINSICS):
    """Float64 ray/plane intersection of pixels ``uv [n, 2]`` (NaN where the ray misses in front)."""
    fx, fy, cx, cy = intrinsics
    rays = np.stack([(uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy, np.ones(len(uv))], -1) @ pose[:3, :3].T
    scale = (plane - pose[2, 3]) / rays[:, 2]
    xy = pose[None, :2, 3] + scale[:, None] * rays[:, :2]
    return np.where((scale > 0)[:, None], xy, np.nan)


def ref_jacobian(uv, pose, step=1e-3):
    """Central differences of :func:`ref_hit`: columns d xy / du, d xy / dv, ``[n, 2, 2]``."""
    du, dv = np.array([step, 0.0]), np.array([0.0, step])
    cols = [(ref_hit(uv + d, pose) - ref_hit(uv - d, pose)) / (2 * step) for d in (du, dv)]
    return np.stack(cols, axis=-1)


def ref_loglik(particles, xy, weight, valid, footprint, k, gain, template_px, min_std):
    """Float64 brute force: each particle's k nearest valid measurements by argsort, the template sum."""
    p = np.asarray(particles, np.float64)
    keep = np.asarray(valid)
    xy, w, f = (np.asarray(a, np.float64)[keep] for a in (xy, weight, footprint))
    if xy.shape[0] == 0:
        return np.zeros(p.shape[0])
    cov = template_px**2 * f @ np.swapaxes(f, 1, 2) + min_std**2 * np.eye(2)
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        d = p[i] - xy
        nearest = np.argsort(np.sum(d * d, axis=1), kind="stable")[:k]
        q = np.array([d[j] @ np.linalg.solve(cov[j], d[j]) for j in nearest])
        out[i] = gain * np.sum(w[nearest] * np.exp(-0.5 * q))
    return out


def random_buffer(rng, m=N_MEAS, valid_share=0.75):
    """Measurements around the origin with random (anisotropic, turned) footprints of 5 mm to 0.4 m."""
    xy = rng.uniform(-1.5, 1.5, (m, 2))
    angle = rng.uniform(0, np.pi, m)
    rot = np.stack([np.stack([np.cos(angle), -np.sin(angle)], -1), np.stack([np.sin(angle), np.cos(angle)], -1)], 1)
    footprint = rot @ (rng.uniform(0.005, 0.4, (m, 2))[:, :, None] * np.eye(2)) + rng.normal(0, 0.01, (m, 2, 2))
    valid = rng.random(m) < valid_share
    return hp.Measurements(
        xy=np.asarray(np.where(valid[:, None], xy, 0.0), np.float32),
        weight=np.asarray(np.where(valid, rng.uniform(0.3, 1.0, m), 0.0), np.float32),
        valid=np.asarray(valid),
        footprint=np.asarray(np.where(valid[:, None, None], footprint, 0.0), np.float32),
    )


def random_poses(rng, count):
    return [
        hp.camera.camera_pose(
            height=rng.uniform(0.4, 0.8),
            pitch=np.deg2rad(rng.uniform(15.0, 45.0)),
            yaw=rng.uniform(-0.5, 0.5),
            roll=rng.uniform(-0.1, 0.1),
            x=rng.uniform(-0.1, 0.1),
            y=rng.uniform(-0.1, 0.1),
        )
        for _ in range(count)
    ]


# --------------------------------------------------------------------------- footprint


def test_ground_jacobian_matches_finite_differences_of_the_projection(rng):
    for pose in random_poses(rng, 4):
        uv = np.stack([rng.uniform(0, 199, 64), rng.uniform(0, 149, 64)], -1)
        jac = np.asarray(
            _jacobians(
                np.asarray(uv, np.float32),
                np.asarray(INTRINSICS, np.float32),
                np.asarray(pose, np.float32),
                np.float32(PLANE),
            ),
            np.float64,
        )
        ref = ref_jacobian(uv, pose)
        missed = ~np.all(np.isfinite(ref), axis=(1, 2))
        np.testing.assert_array_equal(jac[missed], 0.0)  # rays above the horizon
        # Within the filter's range (near the horizon float32 loses digits to the steep perspective).
        ok = ~missed & (np.linalg.norm(np.nan_to_num(ref_hit(uv, pose), nan=1e9), axis=1) < 12.0)
        assert ok.sum() > 10
        scale = np.max(np.abs(ref[ok]), axis=(1, 2), keepdims=True)
        np.testing.assert_allclose(jac[ok] / scale, ref[ok] / scale, atol=2e-4)


def test_footprint_is_the_ground_spacing_of_neighbouring_pixels():
    """The simulator's far camera: the pixel seeing ground 5 m ahead spans ~0.3 m radially and ~3.5 cm sideways."""
    pose = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(27.0))
    _, fy, cx, cy = INTRINSICS
    # The row whose ray meets the plane 5 m ahead, at the image centre column.
    v = cy + fy * np.tan(np.arctan2(0.6 - PLANE, 5.0) - np.deg2rad(27.0))
    uv = np.array([[cx, round(v)]])
    jac = np.asarray(
        _jacobians(
            np.asarray(uv, np.float32),
            np.asarray(INTRINSICS, np.float32),
            np.asarray(pose, np.float32),
            np.float32(PLANE),
        ),
        np.float64,
    )[0]
    here = ref_hit(uv, pose)[0]
    assert 4.0 < here[0] < 6.0
    right = ref_hit(uv + [[1.0, 0.0]], pose)[0] - here
    down = ref_hit(uv + [[0.0, 1.0]], pose)[0] - here
    up = here - ref_hit(uv - [[0.0, 1.0]], pose)[0]
    np.testing.assert_allclose(jac[:, 0], right, rtol=1e-3)
    # One row down (nearer) and one row up (farther) bracket the first-order step.
    assert np.linalg.norm(down) < np.linalg.norm(jac[:, 1]) < np.linalg.norm(up)
    np.testing.assert_allclose(np.linalg.norm(jac[:, 1]), 0.5 * (np.linalg.norm(down) + np.linalg.norm(up)), rtol=0.02)
    assert 0.2 < np.linalg.norm(jac[:, 1]) < 0.45 and 0.025 < np.linalg.norm(jac[:, 0]) < 0.045


def test_projected_heatmap_carries_footprints_that_odometry_turns(rng):
    pose = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0), yaw=0.2)
    heat = rng.uniform(0.0, 1.0, (15, 20)).astype(np.float32)
    intr = INTRINSICS / 10.0
    meas = _project(heat, intr, pose, threshold=0.6, plane_height=PLANE, max_measurements=400)
    valid = np.asarray(meas.valid)
    # Passing pixels in raster order (all fit): the reference footprint of each.
    rows, cols = np.nonzero(heat >= 0.6)
    uv = np.stack([cols, rows], -1).astype(np.float64)
    hits = np.isfinite(ref_hit(uv, pose, intrinsics=intr)[:, 0])
    ref = np.stack(
        [
            (ref_hit(uv + d, pose, intrinsics=intr) - ref_hit(uv - d, pose, intrinsics=intr)) / 2e-3
            for d in (np.array([1e-3, 0.0]), np.array([0.0, 1e-3]))
        ],
        -1,
    )[hits]
    got = np.asarray(meas.footprint, np.float64)
    assert valid.sum() == hits.sum() > 20
    np.testing.assert_allclose(got[valid], ref, rtol=1e-3, atol=1e-5)
    np.testing.assert_array_equal(got[~valid], 0.0)
    # Odometry turns footprints with the frame (R^T F) and does not translate them; aging keeps them.
    odometry = np.array([0.3, -0.2, 0.4])
    c, s = np.cos(odometry[2]), np.sin(odometry[2])
    moved = _move(meas, np.asarray(odometry, np.float32))
    np.testing.assert_allclose(np.asarray(moved.footprint)[valid], np.array([[c, s], [-s, c]]) @ got[valid], atol=1e-6)
    aged = _age(meas, np.float32(0.1), np.float32(0.0))
    np.testing.assert_array_equal(np.asarray(aged.footprint), np.asarray(meas.footprint))
    assert not np.any(np.asarray(_empty(5).footprint))


# --------------------------------------------------------------------------- likelihood


@pytest.mark.parametrize("method", ["dense", "blocked"])
def test_log_likelihood_matches_numpy_brute_force(rng, method):
    meas = random_buffer(rng)
    # Particles near measurements (the kernel matters) and far from all (it vanishes).
    near = np.asarray(meas.xy)[np.asarray(meas.valid)][rng.integers(0, 20, N_PART // 2)]
    particles = np.concatenate([near + rng.normal(0, 0.1, near.shape), rng.uniform(-2.5, 2.5, (N_PART // 2, 2))])
    for k, gain, template_px, min_std in [(1, 3.0, 1.0, 0.05), (3, 7.0, 0.5, 0.12), (K_MAX, 10.0, 2.0, 0.01)]:
        got = _loglik(
            np.asarray(particles, np.float32),
            meas,
            np.int32(k),
            gain=np.float32(gain),
            template_px=np.float32(template_px),
            min_std=np.float32(min_std),
            k_max=K_MAX,
            method=method,
        )
        ref = ref_loglik(particles, meas.xy, meas.weight, meas.valid, meas.footprint, k, gain, template_px, min_std)
        assert np.mean(ref[: N_PART // 2] > 1e-3 * gain) > 0.8
        np.testing.assert_allclose(np.asarray(got, np.float64), ref, rtol=2e-5, atol=1e-5 * gain)


def test_fewer_valid_than_k_sums_all_and_none_valid_gives_zeros(rng):
    meas = random_buffer(rng)
    particles = rng.uniform(-1.0, 1.0, (N_PART, 2))
    few = meas._replace(valid=meas.valid & (np.arange(N_MEAS) < 8))
    assert 1 <= int(few.valid.sum()) < K_MAX
    args = dict(
        gain=np.float32(5.0), template_px=np.float32(3.0), min_std=np.float32(0.3), k_max=K_MAX, method="dense"
    )
    got = _loglik(np.asarray(particles, np.float32), few, np.int32(K_MAX), **args)
    ref = ref_loglik(particles, few.xy, few.weight, few.valid, few.footprint, K_MAX, 5.0, 3.0, 0.3)
    np.testing.assert_allclose(np.asarray(got, np.float64), ref, rtol=2e-5, atol=5e-5)
    none = meas._replace(valid=np.zeros(N_MEAS, bool))
    np.testing.assert_array_equal(_loglik(np.asarray(particles, np.float32), none, np.int32(3), **args), 0.0)


def test_gradients_are_finite_and_match_finite_differences(rng):
    meas = random_buffer(rng)
    near = np.asarray(meas.xy)[np.asarray(meas.valid)][:N_PART]
    particles = np.asarray(near + rng.normal(0, 0.05, near.shape), np.float32)
    coeff = np.asarray(rng.uniform(0.5, 1.5, particles.shape[0]), np.float32)

    def total(theta, xy, meas):  # the buffer an argument: NumPy arrays cannot be indexed by traced ones
        gain, template_px, min_std = theta[0], theta[1], theta[2]
        ll = footprint_template_log_likelihood(
            xy, meas, 3, gain=gain, template_px=template_px, min_std=min_std, k_max=K_MAX, method="dense"
        )
        return jnp.sum(coeff * ll)

    theta = np.asarray([7.0, 1.0, 0.12], np.float32)
    value_and_grads = jax.jit(jax.value_and_grad(total, argnums=(0, 1)))
    g_theta, g_xy = jax.tree.map(np.asarray, value_and_grads(theta, particles, meas)[1])
    assert np.all(np.isfinite(g_theta)) and np.all(np.isfinite(g_xy)) and np.all(np.asarray(g_theta) != 0.0)

    def f(theta, xy):
        return float(value_and_grads(theta, xy, meas)[0])  # the same compiled function

    for i in range(3):
        h = 1e-3 * float(theta[i])
        e = np.zeros(3, np.float32)
        e[i] = h
        fd = (f(theta + e, particles) - f(theta - e, particles)) / (2 * h)
        assert float(g_theta[i]) == pytest.approx(fd, rel=2e-2, abs=1e-2)
    # One particle coordinate.
    h = 1e-3
    e = np.zeros_like(particles)
    e[0, 1] = h
    fd = (f(theta, particles + e) - f(theta, particles - e)) / (2 * h)
    assert float(g_xy[0, 1]) == pytest.approx(fd, rel=2e-2, abs=5e-2)


# --------------------------------------------------------------------------- the piece


def test_piece_properties_validation_and_filter_params():
    piece = FootprintTemplate()
    assert isinstance(piece, ObservationModel)
    assert hash(piece) == hash(FootprintTemplate()) and piece == FootprintTemplate()
    params = piece.default_params()
    assert params == FootprintTemplateParams(k=10, gain=2.0, template_px=1.0, min_std=0.08)
    assert FootprintTemplate(k_max=4).default_params().k == 4
    props = piece.properties()
    assert jax.tree.structure(params) == jax.tree.structure(props, is_leaf=lambda x: isinstance(x, P.Param))
    assert props.k.integer and not props.k.trainable and props.gain.trainable and props.min_std.trainable
    P.validate(params, props)
    for name in ("gain", "template_px", "min_std"):
        with pytest.raises(ValueError, match=rf"^{name}:"):
            P.validate(params._replace(**{name: 0.0}), props)
    with pytest.raises(ValueError, match="^k:"):
        P.validate(params._replace(k=11), props)
    for bad, field in [({"k_max": 0}, "k_max"), ({"knn": "kdtree"}, "knn")]:
        with pytest.raises(ValueError, match=rf"^{field}:"):
            FootprintTemplate(**bad).validate()
    # In a filter its numbers are set by name like any piece's.
    model = hp.Filter(observation=FootprintTemplate())
    fp = model.make_params(gain=5.0, min_std=0.2)
    assert fp.observation == FootprintTemplateParams(gain=5.0, min_std=0.2)
    # The log-likelihood method is the function.
    meas = random_buffer(np.random.default_rng(5))
    xy = np.asarray(np.random.default_rng(6).uniform(-1, 1, (N_PART, 2)), np.float32)
    piece6 = FootprintTemplate(k_max=K_MAX, knn="dense")
    p6 = FootprintTemplateParams(
        k=np.int32(3), gain=np.float32(7.0), template_px=np.float32(1.0), min_std=np.float32(0.12)
    )
    np.testing.assert_array_equal(
        jax.jit(piece6.log_likelihood)(xy, meas, p6),
        _loglik(
            xy,
            meas,
            np.int32(3),
            gain=np.float32(7.0),
            template_px=np.float32(1.0),
            min_std=np.float32(0.12),
            k_max=K_MAX,
            method="dense",
        ),
    )


# --------------------------------------------------------------------------- the kernel mixture

_mixture = jax.jit(footprint_kernel_log_likelihood, static_argnames=("k_max", "method"))


@pytest.mark.parametrize("k", [1, 4, K_MAX])
def test_footprint_kernel_is_the_log_of_the_brute_force_kernel_sum(rng, k):
    buf = random_buffer(rng)
    particles = np.asarray(rng.uniform(-1.8, 1.8, (N_PART, 2)), np.float32)
    got = np.asarray(_mixture(particles, buf, k, template_px=0.7, min_std=0.04, k_max=K_MAX))
    # The template sum with gain 1 is the kernel sum itself.
    want = np.log(ref_loglik(particles, buf.xy, buf.weight, buf.valid, buf.footprint, k, 1.0, 0.7, 0.04))
    finite = np.isfinite(want) & (want > np.log(1e-25))
    assert finite.mean() > 0.5
    np.testing.assert_allclose(got[finite], want[finite], rtol=1e-4, atol=1e-4)


def test_footprint_kernel_keeps_two_blobs_in_the_ratio_of_their_activations():
    """A mixture, not a product: a blob of k measurements of weight 0.9 beside one of weight 0.6 gives
    particles on them a likelihood ratio 0.9 / 0.6, where the template's log-domain sum gives exp(gain k 0.3)."""
    xy = np.r_[np.tile([[1.0, 0.0]], (K_MAX, 1)), np.tile([[2.0, 1.0]], (K_MAX, 1))]
    buf = hp.Measurements(np.asarray(xy, np.float32), np.asarray([0.9] * K_MAX + [0.6] * K_MAX, np.float32),
                          np.ones(2 * K_MAX, bool),
                          np.asarray(np.tile(np.eye(2) * 0.01, (2 * K_MAX, 1, 1)), np.float32))
    at = np.asarray([[1.0, 0.0], [2.0, 1.0]], np.float32)
    got = np.asarray(_mixture(at, buf, K_MAX, template_px=1.0, min_std=0.05, k_max=K_MAX))
    assert got[0] - got[1] == pytest.approx(np.log(0.9 / 0.6), abs=1e-5)
    model = FootprintKernel(k_max=K_MAX)
    assert isinstance(model, ObservationModel) and model.default_params().k == K_MAX
    empty = hp.Measurements(np.zeros((4, 2), np.float32), np.zeros(4, np.float32), np.zeros(4, bool),
                            np.zeros((4, 2, 2), np.float32))  # the zero footprint, in NumPy
    np.testing.assert_array_equal(np.asarray(jax.jit(model.log_likelihood)(at, empty, model.default_params())), 0.0)
