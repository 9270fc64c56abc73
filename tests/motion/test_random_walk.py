"""Movement model: odometry against SE(2) matrices in NumPy, noise statistics against first-order predictions."""

import jax
import jax.numpy as jnp
import numpy as np

import heatpf_jax as hp
from tests.conftest import blank_inputs

N_STAT = 4000

# Inputs in NumPy: an eager `jnp.asarray` or `jnp.float32` compiles a program of its own per shape.
_apply = jax.jit(hp.motion.apply_odometry)
_move = jax.jit(hp.motion.move_particles)
_diffuse = jax.jit(hp.motion.diffuse)


def se2(odo):
    """Pose of the new base frame in the old one, as a 3x3 homogeneous matrix."""
    dx, dy, th = odo
    return np.array([[np.cos(th), -np.sin(th), dx], [np.sin(th), np.cos(th), dy], [0.0, 0.0, 1.0]])


def ref_apply(points, odo):
    """World-fixed points seen from the new base frame: inverse pose times the homogeneous point."""
    hom = np.concatenate([np.asarray(points, np.float64), np.ones((len(points), 1))], 1)
    return (np.linalg.inv(se2(odo)) @ hom.T).T[:, :2]


def ref_formula(points, odo):
    """R(dtheta)^T (p - (dx, dy)), written out."""
    dx, dy, th = odo
    q = np.asarray(points, np.float64) - [dx, dy]
    return np.stack([np.cos(th) * q[:, 0] + np.sin(th) * q[:, 1], -np.sin(th) * q[:, 0] + np.cos(th) * q[:, 1]], 1)


def random_odometry(rng, n=None):
    shape = (3,) if n is None else (n, 3)
    return rng.uniform([-0.5, -0.5, -1.0], [0.5, 0.5, 1.0], shape)


def test_apply_odometry_matches_formula_and_se2_inverse():
    rng = np.random.default_rng(50)
    pts = rng.uniform(-4, 4, (200, 2)).astype(np.float32)
    for _ in range(5):
        odo = random_odometry(rng)
        got = np.asarray(_apply(pts, odo.astype(np.float32)))
        np.testing.assert_allclose(ref_formula(pts, odo), ref_apply(pts, odo), atol=1e-12)
        np.testing.assert_allclose(got, ref_apply(pts, odo.astype(np.float32)), atol=5e-6)
    # Pure translation shifts, pure rotation by +90 degrees maps the left axis onto the forward axis.
    np.testing.assert_allclose(np.asarray(_apply(pts, np.asarray([0.3, -0.2, 0.0], np.float32))), pts - [0.3, -0.2],
                               atol=1e-6)
    quarter = np.asarray(_apply(pts, np.asarray([0.0, 0.0, np.pi / 2], np.float32)))
    np.testing.assert_allclose(quarter, np.stack([pts[:, 1], -pts[:, 0]], 1), atol=2e-6)


def test_apply_odometry_per_point():
    rng = np.random.default_rng(51)
    pts = rng.uniform(-4, 4, (200, 2)).astype(np.float32)
    odos = random_odometry(rng, 200).astype(np.float32)
    got = np.asarray(_apply(pts, odos))
    want = np.stack([ref_apply(pts[i : i + 1], odos[i])[0] for i in range(200)])
    np.testing.assert_allclose(got, want, atol=5e-6)


def test_apply_odometry_composes_like_se2():
    """Moving by o1 then o2 equals moving once by the composed SE(2) motion T(o1) T(o2)."""
    rng = np.random.default_rng(52)
    pts = rng.uniform(-4, 4, (200, 2)).astype(np.float32)
    for _ in range(5):
        o1, o2 = random_odometry(rng).astype(np.float32), random_odometry(rng).astype(np.float32)
        total = se2(o1.astype(np.float64)) @ se2(o2.astype(np.float64))
        o12 = np.array([total[0, 2], total[1, 2], np.arctan2(total[1, 0], total[0, 0])])
        assert abs(o12[2] - (o1[2] + o2[2])) < 1e-6  # |o1| + |o2| < pi: no wrap
        two_steps = _apply(_apply(pts, o1), o2)
        one_step = _apply(pts, o12.astype(np.float32))
        want = (np.linalg.inv(total) @ np.concatenate([pts, np.ones((200, 1))], 1).T).T[:, :2]
        np.testing.assert_allclose(np.asarray(two_steps), want, atol=1e-5)
        np.testing.assert_allclose(np.asarray(one_step), want, atol=1e-5)
    # The robot's own position in the old frame is the origin of the new one.
    o = random_odometry(rng).astype(np.float32)
    np.testing.assert_allclose(np.asarray(_apply(o[None, :2], o)), [[0.0, 0.0]], atol=1e-6)


def test_move_particles_without_noise_or_without_motion():
    rng = np.random.default_rng(53)
    pts = rng.uniform(-4, 4, (200, 2)).astype(np.float32)
    key = jax.random.key(0)
    odo = random_odometry(rng).astype(np.float32)
    got = np.asarray(_move(key, pts, odo, np.float32(0.0), np.float32(0.0)))
    np.testing.assert_allclose(got, ref_apply(pts, odo), atol=5e-6)
    # A standing robot adds no noise, whatever the noise parameters.
    still = np.asarray(_move(key, pts, np.zeros(3, np.float32), np.float32(0.5), np.float32(0.8)))
    np.testing.assert_array_equal(still, pts)
    # Pure rotation: only rotational noise, so distances to the robot are preserved exactly (up to rounding).
    turn = np.asarray(_move(key, pts, np.asarray([0.0, 0.0, 0.4], np.float32), np.float32(0.5), np.float32(0.3)))
    np.testing.assert_allclose(np.hypot(*turn.T), np.hypot(*pts.T), rtol=1e-5)
    assert np.max(np.abs(turn - ref_apply(pts, [0.0, 0.0, 0.4]))) > 1e-3  # but the angle is noisy


def test_move_particles_noise_matches_first_order_prediction():
    p = np.array([2.0, 1.0])
    copies = np.tile(p, (N_STAT, 1)).astype(np.float32)

    # Pure translation dx = 1 with trans_noise 0.1: isotropic std 0.1 around p - (1, 0).
    out = np.asarray(_move(jax.random.key(1), copies, np.asarray([1.0, 0.0, 0.0], np.float32), np.float32(0.1),
                           np.float32(0.3)), np.float64)
    np.testing.assert_allclose(out.std(0), [0.1, 0.1], rtol=0.1)
    np.testing.assert_allclose(out.mean(0), p - [1.0, 0.0], atol=5 * 0.1 / np.sqrt(N_STAT))

    # General motion: covariance J diag(st^2, st^2, sr^2) J^T with J the Jacobian of R^T (p - d) wrt (dx, dy, th).
    odo = np.array([0.3, -0.1, 0.25])
    tn, rn = 0.1, 0.2
    st, sr = tn * np.hypot(odo[0], odo[1]), rn * abs(odo[2])
    c, s = np.cos(odo[2]), np.sin(odo[2])
    q = p - odo[:2]
    jac = np.array([[-c, -s, -s * q[0] + c * q[1]], [s, -c, -c * q[0] - s * q[1]]])
    cov = jac @ np.diag([st**2, st**2, sr**2]) @ jac.T
    out = np.asarray(_move(jax.random.key(2), copies, odo.astype(np.float32), np.float32(tn), np.float32(rn)),
                     np.float64)
    emp = np.cov(out.T)
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), np.sqrt(np.diag(cov)), rtol=0.1)
    corr = emp[0, 1] / np.sqrt(emp[0, 0] * emp[1, 1])
    assert abs(corr - cov[0, 1] / np.sqrt(cov[0, 0] * cov[1, 1])) < 0.1
    np.testing.assert_allclose(out.mean(0), ref_apply(p[None], odo)[0], atol=5 * np.sqrt(cov.diagonal().max() / N_STAT))


def test_move_particles_keys():
    rng = np.random.default_rng(54)
    pts = rng.uniform(-4, 4, (N_STAT, 2)).astype(np.float32)
    odo = np.asarray([0.2, 0.1, 0.3], np.float32)
    a = np.asarray(_move(jax.random.key(7), pts, odo, np.float32(0.2), np.float32(0.2)))
    b = np.asarray(_move(jax.random.key(7), pts, odo, np.float32(0.2), np.float32(0.2)))
    c = np.asarray(_move(jax.random.key(8), pts, odo, np.float32(0.2), np.float32(0.2)))
    np.testing.assert_array_equal(a, b)
    assert np.all(np.any(a != c, axis=1))


def test_move_particles_noise_gradient_is_reparameterised():
    """d/d(tn) of the mean squared deviation from the noiseless move is 2 tn |d|^2 (pure translation)."""
    copies = np.tile([1.5, -0.5], (N_STAT, 1)).astype(np.float32)
    odo = np.asarray([0.6, 0.8, 0.0], np.float32)  # |d| = 1
    base = _apply(copies, odo)

    def msd(tn):
        moved = hp.motion.move_particles(jax.random.key(3), copies, odo, tn, jnp.float32(0.0))
        return jnp.mean(jnp.square(moved - base))

    tn = np.float32(0.2)
    value, g = jax.jit(jax.value_and_grad(msd))(tn)
    g = float(g)
    assert np.isfinite(g)
    np.testing.assert_allclose(g, 2 * 0.2 * 1.0, rtol=0.07)
    # Exact identity for noise linear in tn: d msd / d tn = 2 msd / tn.
    np.testing.assert_allclose(g, 2 * float(value) / 0.2, rtol=1e-4)


def test_diffuse_statistics_and_gradient():
    rng = np.random.default_rng(55)
    pts = rng.uniform(-4, 4, (N_STAT, 2)).astype(np.float32)
    std = 0.3
    out = np.asarray(_diffuse(jax.random.key(4), pts, np.float32(std)), np.float64)
    disp = out - pts
    np.testing.assert_allclose(disp.mean(0), [0.0, 0.0], atol=5 * std / np.sqrt(N_STAT))
    np.testing.assert_allclose(disp.std(0), [std, std], rtol=0.05)
    assert abs(np.corrcoef(disp.T)[0, 1]) < 0.06
    # Zero std leaves particles where they are; the same key gives the same noise.
    np.testing.assert_array_equal(np.asarray(_diffuse(jax.random.key(4), pts, np.float32(0.0))), pts)
    again = np.asarray(_diffuse(jax.random.key(4), pts, np.float32(std)), np.float64)
    np.testing.assert_array_equal(again, out)

    # Reparameterised: d/d std of the mean squared displacement is 2 std E[n^2] = 2 std.
    def msd(s):
        return jnp.mean(jnp.square(hp.motion.diffuse(jax.random.key(5), jnp.asarray(pts), s) - jnp.asarray(pts)))

    value, g = jax.jit(jax.value_and_grad(msd))(np.float32(std))
    g = float(g)
    # MC error of mean(n^2) over 8000 normals: sqrt(2 / 8000) = 1.6 %.
    np.testing.assert_allclose(g, 2 * std, rtol=0.07)
    np.testing.assert_allclose(g, 2 * float(value) / std, rtol=1e-3)


_move_and_diffuse = jax.jit(hp.motion.move_and_diffuse)


def test_move_and_diffuse_has_the_distribution_of_move_then_diffuse():
    """Three normals per particle give the law of move_particles followed by diffuse (two-sample tests)."""
    from scipy import stats

    n = 20000
    p = np.tile([2.0, 1.0], (n, 1)).astype(np.float32)
    odo = np.asarray([0.3, -0.1, 0.25], np.float32)
    tn, rn, s = np.float32(0.3), np.float32(0.4), np.float32(0.05)
    k1, k2, k3 = jax.random.split(jax.random.key(9), 3)
    two = np.asarray(_diffuse(k2, _move(k1, p, odo, tn, rn), s), np.float64)
    one = np.asarray(_move_and_diffuse(k3, p, odo, tn, rn, s), np.float64)
    for axis in range(2):
        assert stats.ks_2samp(two[:, axis], one[:, axis]).pvalue > 1e-3
    # Along the direction that mixes both noises too, and the covariances agree.
    assert stats.ks_2samp(two @ [0.6, 0.8], one @ [0.6, 0.8]).pvalue > 1e-3
    np.testing.assert_allclose(np.cov(one.T), np.cov(two.T), rtol=0.06, atol=2e-5)
    # Exact special cases: no noise at all is the noiseless move; a standing robot only diffuses.
    zero = np.float32(0.0)
    np.testing.assert_allclose(np.asarray(_move_and_diffuse(k3, p[:5], odo, zero, zero, zero)),
                               ref_apply(np.asarray(p[:5]), np.asarray(odo)), atol=5e-6)
    still = np.asarray(_move_and_diffuse(k3, p, np.zeros(3, np.float32), tn, rn, s), np.float64)
    np.testing.assert_allclose(still.std(0), [0.05, 0.05], rtol=0.03)
    np.testing.assert_allclose(still.mean(0), [2.0, 1.0], atol=5 * 0.05 / np.sqrt(n))


def test_move_and_diffuse_gradients_are_reparameterised():
    """Mean squared deviation from the noiseless move is (tn |d|)^2 + s^2 per axis: its gradients match."""
    n = N_STAT
    p = np.tile([1.5, -0.5], (n, 1)).astype(np.float32)
    odo = np.asarray([0.4, 0.3, 0.0], np.float32)  # |d| = 0.5, no turn
    base = p - odo[None, :2]

    def msd(tn, s):
        out = hp.motion.move_and_diffuse(jax.random.key(3), p, odo, tn, jnp.float32(0.1), s)
        return jnp.mean(jnp.sum((out - base) ** 2, axis=1)) / 2

    grad = jax.jit(jax.grad(msd, argnums=(0, 1)))  # one program for both points: eagerly each operation compiles
    g_tn, g_s = grad(np.float32(0.2), np.float32(0.1))
    # d/dtn [(tn |d|)^2 + s^2] = 2 tn |d|^2 = 0.1; d/ds = 2 s = 0.2 (up to the sample's scatter).
    np.testing.assert_allclose([float(g_tn), float(g_s)], [0.1, 0.2], rtol=0.1)
    assert np.all(np.isfinite(grad(np.float32(0.0), np.float32(0.0))))


def test_motion_pieces():
    """RandomWalk is move_and_diffuse on the positions; DiffusionOnly ignores the odometry."""
    # NumPy inputs and the three calls in one program: eagerly each operation compiles a program of its own.
    xy = np.random.default_rng(0).normal(size=(100, 2)).astype(np.float32)
    inputs = blank_inputs((0.3, 0.1, 0.2))
    key = jax.random.key(4)

    @jax.jit
    def pieces(key, xy, inputs):
        walk = hp.motion.RandomWalk().predict(key, hp.motion.Particles(xy), inputs,
                                              hp.motion.RandomWalkParams(0.2, 0.1, 0.05))
        ref = hp.motion.move_and_diffuse(key, xy, inputs.odometry, 0.1, 0.05, 0.2)
        still = hp.motion.DiffusionOnly().predict(key, hp.motion.Particles(xy), inputs,
                                                  hp.motion.DiffusionOnly().default_params()._replace(diffusion_std=0.0))
        return walk, ref, still

    walk, ref, still = pieces(key, xy, inputs)
    np.testing.assert_array_equal(np.asarray(walk.xy), np.asarray(ref))
    np.testing.assert_array_equal(np.asarray(still.xy), np.asarray(xy))
