"""``Tracker``: step by step equals ``run`` (its keys, its zero first odometry), ``None`` means no heat
map, ``fold_in`` keys against a hand-written loop, reset, argument checks, and no recompilation."""

from __future__ import annotations

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax import tracker as tracker_module
from tests.conftest import SMALL_FILTER, SMALL_OPTIONS, step_inputs

KALMAN = hp.build("kalman", SMALL_OPTIONS)
MODELS = {
    "filter": (SMALL_FILTER, SMALL_FILTER.make_params(k=3)),
    "kalman": (KALMAN.model, KALMAN.params),
}


def perturbed(seq: hp.Sequence, rng: np.random.Generator) -> hp.Sequence:
    """``seq`` with random odometry (a large row 0, to be ignored) and about a third of the heat maps missing."""
    odometry = rng.normal(0.0, [0.05, 0.05, 0.03], seq.odometry.shape)
    odometry[0] = (0.7, -0.4, 0.5)
    has = rng.random(seq.num_steps) > 0.35
    has[0] = True
    return seq._replace(odometry=odometry, has_heatmap=has)


def make_tracker(seq: hp.Sequence, key, model, params, **kwargs) -> hp.Tracker:
    return hp.Tracker(key, model, params, heatmap_shape=seq.heatmaps.shape[1:], intrinsics=seq.intrinsics,
                      plane_height=seq.ball_radius, dt=seq.dt, **kwargs)


def feed(tracker: hp.Tracker, seq: hp.Sequence) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every step of ``seq`` through ``update`` (``None`` where there is no heat map): means, covariances
    and the ancestors of every step."""
    means, covs, ancestors = [], [], []
    for t in range(seq.num_steps):
        heat = seq.heatmaps[t] if seq.has_heatmap[t] else None
        est = tracker.update(heat, seq.cam_to_base[t], seq.odometry[t])
        means.append(np.asarray(est.mean))
        covs.append(np.asarray(est.cov))
        ancestors.append(np.asarray(tracker.last_info.ancestors))
    return np.stack(means), np.stack(covs), np.stack(ancestors)


@pytest.mark.parametrize("name", list(MODELS))
def test_step_by_step_equals_run(name, small_sequence, rng):
    """With ``num_steps=T`` the tracker draws ``run``'s keys: the same estimates (up to float32 rounding of
    two compilations) and, for the particle filter, the same resampling ancestors at every step."""
    model, params = MODELS[name]
    seq = perturbed(small_sequence, rng)
    key = jax.random.key(int(rng.integers(1 << 30)))
    ref = hp.run(key, seq, params, model)

    tracker = make_tracker(seq, key, model, params, num_steps=seq.num_steps)
    means, covs, ancestors = feed(tracker, seq)

    assert tracker.t == seq.num_steps
    np.testing.assert_allclose(means, np.asarray(ref.info.mean), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(covs, np.asarray(ref.info.cov), rtol=1e-5, atol=1e-6)
    np.testing.assert_array_equal(np.asarray(tracker.last_info.num_valid), np.asarray(ref.info.num_valid[-1]))
    # The same draws, not only close numbers: every step resamples from the same ancestors.
    np.testing.assert_array_equal(ancestors, np.asarray(ref.info.ancestors))
    for got, want in zip(jax.tree.leaves(tracker.state), jax.tree.leaves(ref.final_state), strict=True):
        np.testing.assert_allclose(np.asarray(got, np.float64), np.asarray(want, np.float64), rtol=1e-5, atol=1e-6)

    with pytest.raises(RuntimeError, match="^num_steps: all 20 steps taken"):
        tracker.update(None, seq.cam_to_base[0])


def test_fold_in_keys_and_missing_heatmaps_match_a_hand_loop(small_sequence, rng):
    """``num_steps=None``: step t uses ``fold_in(k_steps, t)``; ``None`` is a step with ``has_heatmap`` False
    (the reference keeps the file's heat map, which the step must then ignore); the first odometry is dropped."""
    model, params = MODELS["filter"]
    seq = perturbed(small_sequence, rng).head(8)
    key = jax.random.key(int(rng.integers(1 << 30)))
    tracker = make_tracker(seq, key, model, params)
    means, _, ancestors = feed(tracker, seq)

    arrays = P.as_arrays(params, model.properties())
    k_init, k_steps = jax.random.split(key)
    state = model.init(k_init, arrays)
    step = jax.jit(model.step)
    want = []
    for t in range(seq.num_steps):
        odometry = (0.0, 0.0, 0.0) if t == 0 else seq.odometry[t]
        inputs = step_inputs(seq, t, odometry=odometry, has_heatmap=bool(seq.has_heatmap[t]))
        state, info = step(jax.random.fold_in(k_steps, t), state, inputs, arrays)
        want.append(np.asarray(info.mean))
    assert not seq.has_heatmap.all()
    np.testing.assert_allclose(means, np.stack(want), rtol=1e-6, atol=1e-6)
    np.testing.assert_array_equal(ancestors[-1], np.asarray(info.ancestors))


def test_reset_restores_the_initial_state(small_sequence, rng):
    model, params = MODELS["filter"]
    key = jax.random.key(3)
    tracker = make_tracker(small_sequence, key, model, params)
    initial = jax.tree.map(np.asarray, tracker.state)
    assert tracker.t == 0 and tracker.last_info is None
    first = np.asarray(tracker.update(small_sequence.heatmaps[0], small_sequence.cam_to_base[0]).mean)
    for t in range(1, 4):
        tracker.update(None if t == 2 else small_sequence.heatmaps[t], small_sequence.cam_to_base[t],
                       rng.normal(0.0, 0.05, 3))
    assert tracker.t == 4

    tracker.reset(key)
    assert tracker.t == 0 and tracker.last_info is None
    jax.tree.map(np.testing.assert_array_equal, jax.tree.map(np.asarray, tracker.state), initial)
    again = np.asarray(tracker.update(small_sequence.heatmaps[0], small_sequence.cam_to_base[0]).mean)
    np.testing.assert_array_equal(again, first)

    other = jax.random.key(11)
    tracker.reset(other)
    arrays = P.as_arrays(params, model.properties())
    want = model.init(jax.random.split(other)[0], arrays)
    for got, ref in zip(jax.tree.leaves(tracker.state), jax.tree.leaves(want), strict=True):
        np.testing.assert_allclose(np.asarray(got), np.asarray(ref), rtol=1e-6, atol=1e-6)


def test_no_recompilation_across_updates(small_sequence, rng, caplog):
    """After construction, updates (NumPy float64 or float32 maps, ``None``, a reset) trace and compile nothing."""
    model, params = MODELS["filter"]
    tracker = make_tracker(small_sequence, jax.random.key(5), model, params)
    size = tracker._step._cache_size()
    seq = small_sequence
    with caplog.at_level(logging.WARNING), jax.log_compiles():
        for t in range(6):
            heat = [seq.heatmaps[t], None, seq.heatmaps[t].astype(np.float64)][t % 3]
            tracker.update(heat, seq.cam_to_base[t], rng.normal(0.0, 0.05, 3))
        tracker.reset(jax.random.key(6))
        tracker.update(None, seq.cam_to_base[0])
        tracker.update(seq.heatmaps[1], seq.cam_to_base[1], (0.1, 0.0, 0.02))
        jax.block_until_ready(tracker.state)
    compiles = [r.getMessage() for r in caplog.records if "Compiling" in r.getMessage()]
    assert compiles == []
    assert tracker._step._cache_size() == size
    # A device-resident heat map adds a dispatch-cache entry but traces and compiles nothing.
    on_device = jax.block_until_ready(jnp.asarray(seq.heatmaps[2]))
    caplog.clear()
    with caplog.at_level(logging.WARNING), jax.log_compiles():
        jax.block_until_ready(tracker.update(on_device, seq.cam_to_base[2]))
    assert [r for r in caplog.records if "Compiling" in r.getMessage() or "tracing" in r.getMessage()] == []


GOOD = {"heatmap_shape": (37, 50), "intrinsics": (36.0, 36.0, 24.5, 18.0), "plane_height": 0.075, "dt": 0.1}


@pytest.mark.parametrize(
    ("name", "args", "kwargs"),
    [
        ("key", (np.zeros(2, np.int64),), {}),
        ("key", (jax.random.split(jax.random.key(0)),), {}),
        ("model", (jax.random.key(0), "heatmap"), {}),
        ("model", (jax.random.key(0), hp.build("heatmap", SMALL_OPTIONS)), {}),
        ("model", (jax.random.key(0), SMALL_FILTER._replace(num_particles=0)), {}),
        ("params", (jax.random.key(0), SMALL_FILTER, KALMAN.params), {}),
        ("params", (jax.random.key(0), SMALL_FILTER, SMALL_FILTER.make_params(k=0)), {}),
        ("params", (jax.random.key(0), SMALL_FILTER, hp.stack_params([SMALL_FILTER.default_params()] * 2)), {}),
        ("heatmap_shape", (jax.random.key(0), SMALL_FILTER), {"heatmap_shape": (37,)}),
        ("heatmap_shape", (jax.random.key(0), SMALL_FILTER), {"heatmap_shape": (37, 0)}),
        ("heatmap_shape", (jax.random.key(0), SMALL_FILTER), {"heatmap_shape": (37.0, 50)}),
        ("intrinsics", (jax.random.key(0), SMALL_FILTER), {"intrinsics": (36.0, 36.0, 24.5)}),
        ("intrinsics", (jax.random.key(0), SMALL_FILTER), {"intrinsics": (-36.0, 36.0, 24.5, 18.0)}),
        ("intrinsics", (jax.random.key(0), SMALL_FILTER), {"intrinsics": (36.0, np.nan, 24.5, 18.0)}),
        ("plane_height", (jax.random.key(0), SMALL_FILTER), {"plane_height": -0.1}),
        ("plane_height", (jax.random.key(0), SMALL_FILTER), {"plane_height": "high"}),
        ("dt", (jax.random.key(0), SMALL_FILTER), {"dt": 0.0}),
        ("dt", (jax.random.key(0), SMALL_FILTER), {"dt": (0.1, 0.1)}),
        ("num_steps", (jax.random.key(0), SMALL_FILTER), {"num_steps": 0}),
        ("num_steps", (jax.random.key(0), SMALL_FILTER), {"num_steps": 2.5}),
        ("cache", (jax.random.key(0), SMALL_FILTER), {"cache": 3}),
    ],
)
def test_bad_arguments_raise_one_line_errors_before_compiling(name, args, kwargs):
    before = tracker_module._tick_jit._cache_size()
    with pytest.raises(ValueError, match=f"^{name}:") as err:
        hp.Tracker(*args, **{**GOOD, **kwargs})
    assert "\n" not in str(err.value)
    assert tracker_module._tick_jit._cache_size() == before


def test_compiles_into_the_persistent_cache_and_restores_jax_settings(tmp_path, monkeypatch):
    """The step compiled at construction lands in the cache directory (``$HEATPF_CACHE_DIR`` by default, or
    ``cache=DIR``), where a second process loads it; JAX's cache settings are as they were afterwards;
    ``cache=False`` writes nothing."""
    names = ("jax_compilation_cache_dir", "jax_persistent_cache_min_compile_time_secs")
    before = {name: getattr(jax.config, name) for name in names}
    monkeypatch.delenv("HEATPF_NO_CACHE", raising=False)
    monkeypatch.setenv("HEATPF_CACHE_DIR", str(tmp_path / "env"))
    kwargs = {"intrinsics": (10.0, 10.0, 8.0, 6.0), "plane_height": 0.075, "dt": 0.1}

    def written(directory):
        return [p for p in directory.rglob("*") if p.is_file() and not p.name.startswith(".heatpf-probe")]

    # Shapes no other test compiles: each construction must compile.
    hp.Tracker(jax.random.key(0), KALMAN.model, KALMAN.params, cache=False, heatmap_shape=(13, 17), **kwargs)
    assert not (tmp_path / "env").exists() or not written(tmp_path / "env")
    hp.Tracker(jax.random.key(0), KALMAN.model, KALMAN.params, heatmap_shape=(14, 17), **kwargs)
    assert written(tmp_path / "env"), "nothing was written to $HEATPF_CACHE_DIR"
    hp.Tracker(jax.random.key(0), KALMAN.model, KALMAN.params, cache=tmp_path / "own", heatmap_shape=(15, 17),
               **kwargs)
    assert written(tmp_path / "own"), "nothing was written to cache=DIR"
    assert {name: getattr(jax.config, name) for name in names} == before


def test_bad_update_inputs(small_sequence):
    model, params = MODELS["filter"]
    tracker = make_tracker(small_sequence, jax.random.key(0), model, params)
    cam = small_sequence.cam_to_base[0]
    with pytest.raises(ValueError, match=r"^heatmap: expected shape \(37, 50\), got \(50, 37\)"):
        tracker.update(small_sequence.heatmaps[0].T, cam)
    with pytest.raises(ValueError, match="^cam_to_base:"):
        tracker.update(None, cam[:3])
    with pytest.raises(ValueError, match="^odometry:"):
        tracker.update(None, cam, (0.1, 0.2))
    with pytest.raises(ValueError, match="^key:"):
        tracker.reset(0)
    assert tracker.t == 0


def test_self_localisation_tick_by_tick_equals_run(small_sequence, rng):
    """With ``ego=pose_full`` and poses given each tick, the tracker's estimates are ``run``'s: the deltas
    and their confidences (the lower of two poses') are computed alike."""
    seq = perturbed(small_sequence, rng)
    poses = np.cumsum(rng.normal(0.0, [0.05, 0.05, 0.1], (seq.num_steps, 3)), axis=0) + [40.0, -12.0, 0.0]
    conf = rng.uniform(0.0, 1.0, seq.num_steps)
    seq = seq._replace(robot_pose=poses, pose_confidence=conf)
    model = SMALL_FILTER._replace(ego=hp.motion.LocalisationEgo(translate=True))
    params = model.make_params(k=3)
    key = jax.random.key(5)
    ref = hp.run(key, seq, params, model)
    tracker = make_tracker(seq, key, model, params, num_steps=seq.num_steps)
    with pytest.raises(ValueError, match="^robot_pose: this model's ego-motion reads the self-localisation"):
        tracker.update(None, seq.cam_to_base[0])
    means = []
    for t in range(seq.num_steps):
        heat = seq.heatmaps[t] if seq.has_heatmap[t] else None
        est = tracker.update(heat, seq.cam_to_base[t], seq.odometry[t], robot_pose=poses[t], pose_confidence=conf[t])
        means.append(np.asarray(est.mean))
    np.testing.assert_allclose(np.stack(means), np.asarray(ref.info.mean), rtol=1e-6, atol=1e-6)
