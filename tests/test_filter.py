"""The filter (``init``/``step``/``run``) against independent references.

* A linear-Gaussian toy (random-walk ball, one exact ground measurement per step
  through a camera looking straight down, Gaussian observation with k = 1) is a
  bootstrap particle filter for a model whose exact posterior is a Kalman filter,
  written here in NumPy.
* Measurement aging and odometry are checked against hand-computed expectations.
* Compilation counts, determinism, jit / no-jit, vmap over parameters, gradients
  (against central finite differences with common random numbers) and validation.

To keep compile time low, filter runs share a few filters and shapes:
``SMALL_FILTER`` with the 20-step 37 x 50 ``small_sequence`` shape, and one
Kalman-toy filter with one 40-step 3 x 3 sequence.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
import heatpf_jax.rollout as rollout
from heatpf_jax.params import set_by_name
from heatpf_jax.presets import validate_options
from heatpf_jax.sim import render_heatmap
from tests.conftest import SMALL_FILTER, SMALL_OPTIONS

# --- Helpers --------------------------------------------------------------------------------------------------------


def _leaves(tree) -> list[np.ndarray]:
    return [np.asarray(x) for x in jax.tree.leaves(tree)]


def _with_steps(seq: hp.Sequence, **arrays) -> hp.Sequence:
    """A copy of ``seq`` with some per-step arrays replaced (same shapes: no recompilation)."""
    return seq._replace(**arrays)


def _first_steps(seq: hp.Sequence, num: int) -> hp.Sequence:
    per_step = ("heatmaps", "has_heatmap", "cam_to_base", "odometry", "ground_truth")
    return seq._replace(**{k: None if getattr(seq, k) is None else getattr(seq, k)[:num] for k in per_step})


def _set(params: hp.FilterParams, model: hp.Filter, **names) -> hp.FilterParams:
    """``params`` with some values replaced by name (values may be traced)."""
    return set_by_name(params, model.properties(), names)


def _error(info_mean, truth) -> np.ndarray:
    return np.linalg.norm(np.asarray(info_mean, np.float64) - truth, axis=-1)


# --- Linear-Gaussian toy against the exact Kalman posterior ---------------------------------------------------------

KF_STEPS = 40
KF_Q = 0.2  # random-walk (diffusion) std per step
KF_R = 0.3  # measurement std
KF_RUNS = 32
KF_MODEL = hp.paper_filter(
    hp.FilterOptions(
        num_particles=1000, max_measurements=16, k_max=1, observation="gaussian", spawn_box=(-4.0, 4.0, -4.0, 4.0)
    )
)
KF_PARAMS = KF_MODEL.make_params(
    k=1,
    threshold=0.5,
    obs_std=KF_R,
    diffusion_std=KF_Q,
    explorer_fraction=0.0,
    top_fraction=1.0,
    aging=0.0,
    odom_trans_noise=0.0,
    odom_rot_noise=0.0,
)


@pytest.fixture(scope="module")
def kalman_toy():
    """A random walk seen through one exact ground pixel per step, and its exact Kalman posterior."""
    gen = np.random.default_rng(7)
    truth = np.array([0.5, -0.3]) + np.cumsum(KF_Q * gen.standard_normal((KF_STEPS, 2)), axis=0)
    z = truth + KF_R * gen.standard_normal((KF_STEPS, 2))
    # A 3 x 3 heat map whose centre pixel is the only one above the threshold; a camera 1 m above z_t
    # looking straight down projects that pixel exactly onto z_t (plane height 0).
    heat = np.zeros((KF_STEPS, 3, 3), np.float32)
    heat[:, 1, 1] = 1.0
    poses = np.stack([hp.camera.camera_pose(height=1.0, pitch=np.pi / 2, x=zt[0], y=zt[1]) for zt in z])
    seq = hp.validate_sequence(
        hp.Sequence(
            heatmaps=heat,
            has_heatmap=np.ones(KF_STEPS, bool),
            intrinsics=np.array([1.0, 1.0, 1.0, 1.0]),
            cam_to_base=poses,
            odometry=np.zeros((KF_STEPS, 3)),
            ball_radius=np.asarray(0.0),
            dt=np.asarray(0.1),
            ground_truth=truth,
        )
    )
    # The centre pixel really projects onto z_t (one program: eager ops compile one by one).
    xy, ok = jax.jit(hp.camera.project_pixel)(np.array([1.0, 1.0], np.float32), np.asarray(seq.intrinsics, np.float32),
                                              np.asarray(poses[5], np.float32), np.float32(0.0))
    assert bool(ok)
    np.testing.assert_allclose(xy, z[5], atol=1e-6)
    # Exact posterior (isotropic, so a scalar variance): diffuse prior, predict then update at every step.
    mean, var = np.zeros(2), 1e4
    kf_mean, kf_var = np.zeros((KF_STEPS, 2)), np.zeros(KF_STEPS)
    for t in range(KF_STEPS):
        var = var + KF_Q**2
        gain = var / (var + KF_R**2)
        mean = mean + gain * (z[t] - mean)
        var = (1.0 - gain) * var
        kf_mean[t], kf_var[t] = mean, var
    return seq, kf_mean, kf_var


@functools.partial(jax.jit, static_argnames="model")
def _batched_run(keys, sequence, params, model):
    """``run`` vmapped over keys and parameter sets together (one compilation for the Kalman tests)."""
    return jax.vmap(lambda k, p: hp.run(k, sequence, p, model))(keys, params)


def test_linear_gaussian_matches_kalman_posterior(kalman_toy):
    seq, kf_mean, kf_var = kalman_toy
    keys = jax.random.split(jax.random.key(2024), KF_RUNS)
    res = _batched_run(keys, seq, hp.stack_params([KF_PARAMS] * KF_RUNS), KF_MODEL)
    info = res.info
    assert np.all(np.asarray(info.num_valid) == 1)  # exactly one measurement per step
    late = slice(10, None)  # the uniform initial cloud has washed out by then
    for name in ("weighted_mean", "mean"):
        est = np.asarray(getattr(info, name), np.float64)  # [R, T, 2]
        avg = est.mean(0)
        se = est.std(0, ddof=1) / np.sqrt(KF_RUNS)
        dev = np.abs(avg - kf_mean)[late]
        # Monte-Carlo error plus a small allowance for the O(1/N) particle-filter bias.
        worst = f"{name}: max deviation {dev.max():.4f} m, {(dev / se[late]).max():.2f} SE"
        print(f"\nKalman toy, {worst}")
        assert np.all(dev <= 5 * se[late] + 0.02), worst
    cov = np.asarray(info.cov, np.float64).mean(0)[late]
    var = kf_var[late]
    ratios = np.concatenate([cov[:, 0, 0] / var, cov[:, 1, 1] / var])
    print(f"Kalman toy, PF / Kalman variance ratio: {ratios.min():.3f} to {ratios.max():.3f}")
    np.testing.assert_allclose(cov[:, 0, 0] / var, 1.0, atol=0.2)
    np.testing.assert_allclose(cov[:, 1, 1] / var, 1.0, atol=0.2)
    assert np.all(np.abs(cov[:, 0, 1]) < 0.2 * var)
    # Single runs are close to the posterior mean too (a few posterior std, not just on average).
    assert np.all(_error(info.mean, kf_mean)[:, late] < 4 * np.sqrt(var))
    # With 1000 particles and a likelihood about as wide as the prior, the ESS stays high.
    assert np.median(np.asarray(info.ess)[:, late]) > 300


def test_gradient_matches_finite_difference(kalman_toy):
    """d/d diffusion_std of the tracking error agrees with a central difference at the same key.

    Without resampling (resample_threshold = 0), explorers (fraction 0) and top-fraction cut
    (1.0) the output is a smooth function of the diffusion std. The weights degenerate
    over long horizons, so the loss uses the first 12 steps.
    """
    seq, _, _ = kalman_toy
    truth = jnp.asarray(seq.ground_truth[:12], jnp.float32)
    params = _set(KF_PARAMS, KF_MODEL, resample_threshold=0.0)
    key = jax.random.key(5)

    @jax.jit  # one program (and its derivative's), not one per eager op
    def loss_of(mean):
        return jnp.mean(jnp.sum((mean[:12] - truth) ** 2, axis=-1))

    def loss(d):
        return loss_of(hp.run(key, seq, _set(params, KF_MODEL, diffusion_std=d), KF_MODEL).info.mean)

    value, grad = jax.value_and_grad(loss)(jnp.float32(KF_Q))
    assert np.isfinite(float(grad)) and abs(float(grad)) > 1e-2
    # Central differences with common random numbers, evaluated in the batched compilation. The
    # loss is curved at this key (h = 0.01 is 15 % off, 0.005 4 %, 0.002 0.6 %: the O(h^2) error of a
    # central difference), so the steps are small.
    steps = (0.004, 0.002)
    ds = [KF_Q] + [KF_Q + s * h for h in steps for s in (1, -1)]
    ds += [KF_Q] * (KF_RUNS - len(ds))
    batch = hp.stack_params([_set(params, KF_MODEL, diffusion_std=d) for d in ds])
    res = _batched_run(jnp.stack([key] * KF_RUNS), seq, batch, KF_MODEL)
    losses = np.asarray(jax.vmap(loss_of)(res.info.mean), np.float64)
    assert losses[0] == pytest.approx(float(value), rel=1e-5)  # same key: same random numbers
    for i, h in enumerate(steps):
        fd = (losses[1 + 2 * i] - losses[2 + 2 * i]) / (2 * h)
        print(f"\ngradient {float(grad):.4f} vs central difference (h={h}) {fd:.4f}: {fd / float(grad) - 1:+.2%}")
        assert fd == pytest.approx(float(grad), rel=0.05), f"h={h}: finite difference {fd:.4f}, grad {float(grad):.4f}"
    assert not np.any(np.asarray(res.info.resampled))


# --- vmap, compilation, determinism, jit --------------------------------------------------------------------------


def test_vmap_over_params_equals_single_runs(small_sequence, small_filter):
    p1 = small_filter.make_params(k=3, threshold=0.3, aging=0.05, diffusion_std=0.15)
    p2 = small_filter.make_params(k=7, threshold=0.5, aging=0.2, diffusion_std=0.3)
    key = jax.random.key(11)
    batched = jax.vmap(lambda p: hp.run(key, small_sequence, p, small_filter))(hp.stack_params([p1, p2]))
    for i, p in enumerate((p1, p2)):
        single = hp.run(key, small_sequence, p, small_filter)
        # Indexed in NumPy: indexing a JAX array compiles a slice per leaf.
        for a, b in zip(_leaves(single), [x[i] for x in _leaves(batched)], strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    # The two parameter sets really give different runs.
    assert not np.allclose(*np.asarray(batched.info.mean)[:2])


def test_second_run_does_not_recompile(small_sequence, small_filter):
    hp.run(jax.random.key(0), small_sequence, small_filter.default_params(), small_filter)
    size = rollout._run_jit._cache_size()
    # Different key, different parameter values (and Python / NumPy scalar types).
    other = small_filter.make_params(k=np.int64(2), threshold=np.float32(0.5), aging=0.1,
                                     diffusion_std=np.float64(0.05), explorer_fraction=0.0, top_fraction=1,
                                     resample_threshold=0.5)
    res = hp.run(jax.random.key(1), small_sequence, other, small_filter)
    assert rollout._run_jit._cache_size() == size
    # Without ground truth, and with other per-step values of the same shapes.
    hp.run(jax.random.key(2), small_sequence._replace(ground_truth=None), other, small_filter)
    hp.run(jax.random.key(2), _with_steps(small_sequence, has_heatmap=~small_sequence.has_heatmap), other, small_filter)
    assert rollout._run_jit._cache_size() == size
    assert np.all(np.isfinite(np.asarray(res.info.mean)))


def test_same_key_is_bit_identical_and_keys_matter(small_sequence, small_filter):
    params = small_filter.default_params()
    a = hp.run(jax.random.key(3), small_sequence, params, small_filter)
    b = hp.run(jax.random.key(3), small_sequence, params, small_filter)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)
    c = hp.run(jax.random.key(4), small_sequence, params, small_filter)
    assert not np.array_equal(np.asarray(a.info.mean), np.asarray(c.info.mean))
    assert not np.array_equal(np.asarray(a.final_state.particles.xy), np.asarray(c.final_state.particles.xy))


def test_jit_equals_no_jit(small_sequence, small_filter):
    seq = _first_steps(small_sequence, 1)  # eager steps cost seconds each (carries across steps: test_tracker)
    params = small_filter.default_params()
    jitted = hp.run(jax.random.key(6), seq, params, small_filter)
    with jax.disable_jit():
        eager = hp.run(jax.random.key(6), seq, params, small_filter)
    np.testing.assert_array_equal(jitted.info.num_valid, eager.info.num_valid)
    np.testing.assert_array_equal(jitted.info.resampled, eager.info.resampled)
    for x, y in zip(_leaves(jitted), _leaves(eager), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-5, atol=1e-5)


# --- Behaviour on simulated sequences ------------------------------------------------------------------------------

TRACKING_BOUND = 0.2  # metres; measured about 0.07 - 0.11 over keys 0 - 9 (0.098 for key 0)


def test_tracks_the_simulated_ball(small_sequence, small_filter):
    res = hp.run(jax.random.key(0), small_sequence, small_filter.default_params(), small_filter)
    truth = small_sequence.ground_truth
    err = _error(res.info.mean, truth)[-10:].mean()
    # A constant guess at the mean of the true path (an oracle the filter does not have) does much worse.
    baseline = _error(truth.mean(0), truth)[-10:].mean()
    assert err < TRACKING_BOUND, f"mean error over the last 10 steps {err:.3f} m"
    assert err < 0.5 * baseline, f"{err:.3f} m vs constant-guess baseline {baseline:.3f} m"
    assert np.all(np.asarray(res.info.num_valid) > 0)


def test_no_heatmap_keeps_uniform_weights(small_sequence, small_filter):
    seq = _with_steps(small_sequence, has_heatmap=np.zeros(small_sequence.num_steps, bool))
    res = hp.run(jax.random.key(0), seq, small_filter.default_params(), small_filter)
    info = res.info
    assert np.all(np.isfinite(np.asarray(info.mean))) and np.all(np.isfinite(np.asarray(info.cov)))
    assert np.all(np.isfinite(np.asarray(res.final_state.particles.xy)))
    np.testing.assert_allclose(info.ess, small_filter.num_particles, rtol=1e-5)
    np.testing.assert_array_equal(info.num_valid, 0)
    np.testing.assert_allclose(np.exp(np.asarray(res.final_state.log_weights)), 1.0 / small_filter.num_particles,
                               rtol=1e-5)


def test_aging_removes_measurements_at_the_predicted_step(small_sequence, small_filter):
    """One heat map at step 0, then nothing (and one empty heat map): eq. (2) by hand.

    12 pixels at 0.875 and 4 at 0.625, v = 0.125, l = 0.25 (all exact in binary):
    after s steps without input the weights are a - s v; a measurement is dropped
    once a - s v < l, i.e. at s = 4 for 0.625 and s = 6 for 0.875.
    """
    heat = np.zeros_like(small_sequence.heatmaps)
    heat[0, 25:28, 20:24] = 0.875  # 12 pixels, all below the horizon (the camera pitches down 30 degrees)
    heat[0, 30:32, 10:12] = 0.625  # 4 pixels
    has = np.zeros(small_sequence.num_steps, bool)
    has[0] = True
    has[3] = True  # a heat map with nothing above the threshold is no new input: the buffer keeps aging
    seq = _with_steps(small_sequence, heatmaps=heat, has_heatmap=has, ground_truth=None)
    params = small_filter.make_params(threshold=0.5, aging=0.125, min_weight=0.25)
    res = hp.run(jax.random.key(0), seq, params, small_filter)
    expected = np.zeros(small_sequence.num_steps, np.int32)
    for s in range(small_sequence.num_steps):
        expected[s] = 12 * (0.875 - 0.125 * s >= 0.25) + 4 * (0.625 - 0.125 * s >= 0.25)
    np.testing.assert_array_equal(expected[:7], [16, 16, 16, 16, 12, 12, 0])
    np.testing.assert_array_equal(res.info.num_valid, expected)
    buffer = res.final_state.buffer
    assert not np.any(np.asarray(buffer.valid)) and np.all(np.asarray(buffer.weight) == 0)


def _moving_robot_sequence(small_sequence: hp.Sequence, seed: int = 1):
    """A static ball at world (3.3, 0.3); the robot drives an arc (0.1 m forward, then 0.02 rad left, per step),
    reports it as odometry, and gets a heat map every 3rd step.

    Ground truth is the ball in the base frame of each step: ``R(-theta_t) (ball - p_t)``.
    """
    steps = small_sequence.num_steps
    pose = small_sequence.cam_to_base[0]
    gen = np.random.default_rng(seed)
    ball = np.array([3.3, 0.3])
    position, heading = np.zeros(2), 0.0
    relative = np.zeros((steps, 2))
    odometry = np.zeros((steps, 3))
    for t in range(steps):
        if t > 0:
            # Motion in the base frame of step t - 1: forward 0.1 m, then turn.
            odometry[t] = (0.1, 0.0, 0.02)
            position = position + 0.1 * np.array([np.cos(heading), np.sin(heading)])
            heading += 0.02
        c, s = np.cos(heading), np.sin(heading)
        relative[t] = np.array([[c, s], [-s, c]]) @ (ball - position)
    has = np.arange(steps) % 3 == 0
    shape = small_sequence.heatmaps.shape[1:]
    heat = np.stack([
        render_heatmap(gen, relative[t], small_sequence.intrinsics, pose, shape=shape) if has[t]
        else np.zeros(shape, np.float32)
        for t in range(steps)
    ])
    return _with_steps(small_sequence, heatmaps=heat, has_heatmap=has, odometry=odometry, ground_truth=relative)


def test_odometry_moves_particles_and_buffered_measurements(small_sequence, small_filter):
    seq = _moving_robot_sequence(small_sequence)
    # The ball is in view at every heat map, and moves in the base frame (x shrinks, y swings right).
    assert seq.ground_truth[-1, 0] < 1.6 and seq.ground_truth[-1, 1] < -0.5
    params = small_filter.make_params(aging=0.02)
    still = _with_steps(seq, odometry=np.zeros_like(seq.odometry))  # the same data without the odometry
    err, err_still = [], []
    for k in range(3):
        res = hp.run(jax.random.key(k), seq, params, small_filter)
        assert np.all(np.asarray(res.info.num_valid) > 0)  # measurements found at every heat map and kept
        err.append(_error(res.info.mean, seq.ground_truth))
        err_still.append(_error(hp.run(jax.random.key(k), still, params, small_filter).info.mean, seq.ground_truth))
    err, err_still = np.array(err)[:, 3:], np.array(err_still)[:, 3:]
    assert err.mean() < 0.08, f"mean error with odometry {err.mean():.3f} m"
    assert err.mean() < 0.4 * err_still.mean(), f"{err.mean():.3f} m vs {err_still.mean():.3f} m without odometry"
    # Between heat maps (steps 3k + 1, 3k + 2) the moved buffer keeps the estimate on the ball.
    between = np.flatnonzero(np.arange(3, small_sequence.num_steps) % 3 != 0)
    assert err[:, between].mean() < 0.08


def test_first_odometry_row_is_ignored(small_sequence, small_filter):
    seq = _moving_robot_sequence(small_sequence)
    odometry = seq.odometry.copy()
    odometry[0] = (5.0, -3.0, 1.0)
    a = hp.run(jax.random.key(0), seq, small_filter.default_params(), small_filter)
    b = hp.run(jax.random.key(0), _with_steps(seq, odometry=odometry), small_filter.default_params(), small_filter)
    for x, y in zip(_leaves(a), _leaves(b), strict=True):
        np.testing.assert_array_equal(x, y)


def test_gradients_are_finite_with_odometry(small_sequence, small_filter):
    seq = _moving_robot_sequence(small_sequence)
    truth = jnp.asarray(seq.ground_truth, jnp.float32)
    base = small_filter.make_params(aging=0.02)

    @jax.jit  # one program (and its derivative's), not one per eager op
    def loss_of(mean):
        return jnp.mean(jnp.sum((mean - truth) ** 2, axis=-1))

    def loss(d, trans, rot, sequence):
        params = _set(base, small_filter, diffusion_std=d, odom_trans_noise=trans, odom_rot_noise=rot)
        return loss_of(hp.run(jax.random.key(0), sequence, params, small_filter).info.mean)

    grad = jax.grad(loss, argnums=(0, 1, 2))
    point = (jnp.float32(0.2), jnp.float32(0.1), jnp.float32(0.1))
    grads = np.array([float(g) for g in grad(*point, seq)])
    assert np.all(np.isfinite(grads)), grads
    assert np.all(grads != 0.0), grads  # diffusion, translation and rotation noise all act on the particles
    # Without odometry the odometry noise scales with zero motion and has exactly no effect.
    still = np.array([float(g) for g in grad(*point, _with_steps(seq, odometry=np.zeros_like(seq.odometry)))])
    assert np.isfinite(still[0]) and still[0] != 0.0
    np.testing.assert_array_equal(still[1:], 0.0)


@pytest.mark.parametrize(
    "change",
    [{"resampler": "systematic"}, {"resampler": "stratified"}, {"resampler": "multinomial"},
     {"resampler": "residual"}, {"spawn": "gaussian"}],
    ids=["systematic", "stratified", "multinomial", "residual", "spawn-gaussian"],
)
def test_every_resampler_and_spawn_runs(change, small_sequence):
    model = hp.paper_filter(SMALL_OPTIONS._replace(**change))
    res = hp.run(jax.random.key(1), small_sequence, model.default_params(), model)
    for leaf in _leaves(res):
        if leaf.dtype.kind == "f":
            assert np.all(np.isfinite(leaf))
    assert _error(res.info.mean, small_sequence.ground_truth)[-10:].mean() < 0.25
    assert np.all(np.asarray(res.info.resampled))  # resample_threshold = 1: SIR


# --- Validation -----------------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "field, value, observation",
    [
        ("k", 0, "inverse_distance"),
        ("k", 9, "inverse_distance"),  # k_max = 8 in the shared small filter
        ("k", 2.5, "inverse_distance"),
        ("threshold", 1.5, "inverse_distance"),
        ("top_fraction", 0.0, "inverse_distance"),
        ("diffusion_std", -0.1, "inverse_distance"),
        ("aging", float("nan"), "inverse_distance"),
        ("explorer_fraction", 1.0, "inverse_distance"),
        ("min_distance", 0.0, "inverse_distance"),
        ("obs_std", 0.0, "gaussian"),  # only the Gaussian observation model has obs_std
        ("odom_trans_noise", float("inf"), "inverse_distance"),
    ],
)
def test_invalid_params_raise_naming_the_field(field, value, observation, small_sequence, small_filter, monkeypatch):
    model = small_filter if observation == SMALL_OPTIONS.observation else hp.paper_filter(
        SMALL_OPTIONS._replace(observation=observation)
    )
    assert model.observation.k_max == 8
    params = model.make_params({field: value})
    match = rf"^(\w+\.)*{field}:"  # the dotted name, e.g. observation.k
    with pytest.raises(ValueError, match=match):
        hp.validate_params(params, model)
    # A batch with one bad element is rejected too.
    with pytest.raises(ValueError, match=match):
        hp.validate_params(jax.tree.map(lambda a, b: np.array([a, b]), model.default_params(), params), model)

    def must_not_run(*args, **kwargs):
        raise AssertionError("run() compiled or ran before validating")

    monkeypatch.setattr(rollout, "_run_jit", must_not_run)
    with pytest.raises(ValueError, match=match):
        hp.run(jax.random.key(0), small_sequence, params, model)


def test_valid_params_reach_the_compiled_run(small_sequence, small_filter, monkeypatch):
    """The hook used above is the real one: valid parameters get through to ``_run_jit``."""
    hp.validate_params(small_filter.default_params(), small_filter)
    hp.validate_params(
        hp.stack_params([small_filter.default_params(), small_filter.make_params(k=8, top_fraction=1.0)]), small_filter
    )
    calls = []
    monkeypatch.setattr(rollout, "_run_jit", lambda *args: calls.append(args) or "ran")
    assert hp.run(jax.random.key(0), small_sequence, small_filter.default_params(), small_filter) == "ran"
    assert len(calls) == 1


_BAD_BOX = (1.0, 0.0, -1.0, 1.0)


@pytest.mark.parametrize(
    "field, change, model",
    [
        ("resampler", {"resampler": "bogus"},
         SMALL_FILTER._replace(resampling=hp.resampling.ESSResampling(resampler="bogus"))),
        # The spawn and observation names choose a piece's type: no piece holds an unknown name.
        ("spawn", {"spawn": "normal"}, None),
        ("observation", {"observation": "cauchy"}, None),
        ("num_particles", {"num_particles": 0}, SMALL_FILTER._replace(num_particles=0)),
        ("k_max", {"k_max": 1.5}, SMALL_FILTER._replace(observation=hp.observation.InverseDistance(k_max=1.5))),
        ("knn", {"knn": "kdtree"},
         SMALL_FILTER._replace(observation=hp.observation.InverseDistance(k_max=8, knn="kdtree"))),
        ("spawn_box", {"spawn_box": _BAD_BOX}, SMALL_FILTER._replace(initial=hp.injection.UniformBox(box=_BAD_BOX))),
        ("spawn_box", {"spawn_box": _BAD_BOX},
         SMALL_FILTER._replace(injectors=(hp.injection.UniformExplorers(box=_BAD_BOX),))),
    ],
    ids=["resampler", "spawn", "observation", "num_particles", "k_max", "knn", "spawn_box-initial",
         "spawn_box-explorers"],
)
def test_invalid_config_raises_naming_the_field(field, change, model, small_sequence, monkeypatch):
    options = SMALL_OPTIONS._replace(**change)
    with pytest.raises(ValueError, match=rf"^{field}:"):
        validate_options(options)
    with pytest.raises(ValueError, match=rf"^{field}:"):
        hp.paper_filter(options)
    if model is None:
        return
    # A model built directly with the bad value: run() refuses it before anything is compiled.
    with pytest.raises(ValueError, match=rf"^{field}:"):
        model.validate()
    monkeypatch.setattr(rollout, "_run_jit", lambda *args: pytest.fail("run() did not validate the model first"))
    with pytest.raises(ValueError, match=rf"^{field}:"):
        hp.run(jax.random.key(0), small_sequence, model.default_params(), model)
