"""The long-term memory (Olufs et al. 3.4): Kalman prediction and update against NumPy, association,
birth, forgetting, lost tracks, and hint particles (more on hand-made tables: tests/memory/test_distractors.py)."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.injection.explorers import InjectionContext
from heatpf_jax.injection.memory_hints import HintParams, MemoryHints, RedetectionSeeds, SeedParams
from heatpf_jax.measurements import Measurements
from heatpf_jax.memory import (
    MemoryParams,
    Recall,
    TrackMemory,
    TrackTable,
    empty_tracks,
    lost_tracks,
    observed_support,
)
from heatpf_jax.memory.predict import predict_tracks
from heatpf_jax.memory.update import update_tracks
from heatpf_jax.motion.random_walk import Particles, RandomWalk
from heatpf_jax.presets import FilterOptions, build
from heatpf_jax.sim.family import simulate_family_with_info

PARAMS = MemoryParams()
_update = jax.jit(update_tracks)  # one compilation for the tests below (3 slots, 2 candidates)
# The library's functions through one program each: run eagerly, each of their operations compiles on its own.
_empty = jax.jit(empty_tracks, static_argnums=0)
_predict = jax.jit(predict_tracks)
_lost = jax.jit(lost_tracks)
_support = jax.jit(observed_support)
# The memory's Python numbers stay Python numbers, as they are when it runs eagerly.
_recall = jax.jit(TrackMemory(4).recall, static_argnames=("dt", "params"))


@partial(jax.jit, static_argnames=("injector", "params", "seed"))
def _injected(injector, context, params, seed=False):
    """``injector.inject`` (``seed``: ``injector.seed``) on ``context`` without its motion model, which is put back
    here (a random walk): one program, where the eager injector compiles each of its operations on its own."""
    context = context._replace(motion=RandomWalk(), motion_params=RandomWalk().default_params())
    out = (injector.seed if seed else injector.inject)(jax.random.key(0), context, params)
    return out._replace(motion=None, motion_params=None)


def _np(tree):
    """``tree`` in NumPy: the tests look at its fields, where each eager index would compile a program."""
    return jax.tree.map(np.asarray, tree)


def _table(rng, m=3):
    """In NumPy: eager `jnp` (even `jnp.asarray`) compiles a program per shape; the jitted functions take NumPy."""
    a = rng.normal(size=(m, 4, 4))
    return TrackTable(
        id=np.arange(1, m + 1, dtype=np.int32),
        valid=np.ones((m,), bool),
        mean=np.asarray(rng.normal(size=(m, 4)), np.float32),
        cov=np.asarray(a @ a.transpose(0, 2, 1) + np.eye(4), np.float32),
        age=np.zeros((m,), np.float32),
        hits=np.full((m,), 5, np.int32),
        found=np.zeros((m,), bool),
        next_id=np.int32(m + 1),
    )


def test_prediction_against_numpy(rng):
    """Constant velocity for dt, white-noise acceleration, then the robot's motion: NumPy in float64."""
    tracks = _table(rng)
    dt, accel, ego = 0.1, 1.5, np.array([0.2, -0.1, 0.4])
    got = _np(_predict(tracks, np.float32(dt), np.asarray(ego, np.float32), np.float32(accel)))
    f = np.eye(4)
    f[0, 2] = f[1, 3] = dt
    g = np.array([[dt**2 / 2, 0], [0, dt**2 / 2], [dt, 0], [0, dt]])
    q = accel**2 * g @ g.T
    c, s = np.cos(ego[2]), np.sin(ego[2])
    rot_t = np.array([[c, s], [-s, c]])  # world vectors of the old base frame, seen from the new one
    j = np.zeros((4, 4))
    j[:2, :2] = j[2:, 2:] = rot_t
    for i in range(3):
        m = f @ np.asarray(tracks.mean[i], np.float64)
        p = f @ np.asarray(tracks.cov[i], np.float64) @ f.T + q
        want_mean = np.concatenate([rot_t @ (m[:2] - ego[:2]), rot_t @ m[2:]])
        np.testing.assert_allclose(got.mean[i], want_mean, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(got.cov[i], j @ p @ j.T, rtol=1e-4, atol=1e-5)


def test_update_against_numpy_kalman(rng):
    tracks = _table(rng, 3)
    tracks.age[2] = 0.5  # the slot a new track may replace: unobserved longest
    z = np.array([[0.3, -0.2], [5.0, 5.0]])  # the second is outside every gate
    tracks.mean[0, :2] = np.array([0.25, -0.1], np.float32)
    params = jax.tree.map(jnp.asarray, PARAMS._replace(memory_gate=1.0))
    got = _np(_update(tracks, np.asarray(z, np.float32), np.array([True, True]), np.float32(0.0),
                      np.zeros(3, np.float32), params))
    m, p = np.asarray(tracks.mean[0], np.float64), np.asarray(tracks.cov[0], np.float64)
    h = np.eye(2, 4)
    s = h @ p @ h.T + params.memory_obs_std**2 * np.eye(2)
    k = p @ h.T @ np.linalg.inv(s)
    np.testing.assert_allclose(got.mean[0], m + k @ (z[0] - h @ m), rtol=1e-4, atol=1e-5)
    np.testing.assert_allclose(got.cov[0], p - k @ s @ k.T, rtol=1e-3, atol=1e-4)
    assert float(got.age[0]) == 0.0 and int(got.hits[0]) == 6
    # The far candidate could not take a free slot (all full) and is not within a gate: it replaced the
    # track unobserved longest (track 3) as a new track with a new id.
    assert int(got.id[2]) == 4 and np.allclose(got.mean[2], [5.0, 5.0, 0.0, 0.0]) and int(got.next_id) == 5
    assert int(got.id[1]) == 2 and float(got.age[1]) == 0.0  # not observed, but dt = 0


def test_association_birth_forgetting_and_lost():
    params = PARAMS._replace(memory_forget=2.0, memory_confirm=2)
    params = jax.tree.map(jnp.asarray, params)
    tracks = _empty(3)
    dt, ego = np.float32(0.1), np.zeros(3, np.float32)  # NumPy: eager `jnp` compiles a program per shape
    ball, other = np.array([2.0, 0.0]), np.array([3.0, 1.0])
    for k in range(3):  # two objects seen three times: two confirmed tracks, ids 1 and 2; the other one rolls
        both = np.asarray(np.stack([ball, other + [0.0, 0.08 * k]]), np.float32)
        tracks = _np(_update(tracks, both, np.array([True, True]), dt, ego, params))
    assert sorted(np.asarray(tracks.id[tracks.valid]).tolist()) == [1, 2]
    assert not np.any(np.asarray(_lost(tracks, 2)))
    assert not np.any(np.asarray(tracks.static)[np.asarray(tracks.id) == 2])  # it moves: not static clutter
    # Only the ball is seen now (its candidate listed second): the other track ages and is lost ...
    swapped = np.asarray(np.stack([other + 10.0, ball + 0.05]), np.float32)
    tracks = _np(_update(tracks, swapped, np.array([False, True]), dt, ego, params))
    lost = np.asarray(_lost(tracks, 2))
    ids = np.asarray(tracks.id)
    assert ids[lost].tolist() == [2] and np.asarray(tracks.hits)[ids == 1].item() == 4
    # ... kept while unobserved for memory_forget seconds (20 steps of 0.1 s: 2.0000002 s in float32) ...
    for _ in range(19):
        tracks = _np(_update(tracks, swapped, np.array([False, True]), dt, ego, params))
    assert sorted(np.asarray(tracks.id[tracks.valid]).tolist()) == [1, 2]
    # ... and forgotten once unobserved for more.
    tracks = _np(_update(tracks, swapped, np.array([False, True]), dt, ego, params))
    assert np.asarray(tracks.id[tracks.valid]).tolist() == [1]


def test_observed_support_against_brute_force(rng):
    m = 50
    buf = Measurements(  # NumPy, as in _table
        xy=np.asarray(rng.uniform(0, 3, (m, 2)), np.float32),
        weight=np.asarray(rng.uniform(0, 1, m), np.float32),
        valid=rng.uniform(size=m) < 0.7,
        footprint=np.zeros((m, 2, 2), np.float32),
    )
    xy = rng.uniform(0, 3, (4, 2))
    got = np.asarray(_support(np.asarray(xy, np.float32), buf, np.float32(0.5)))
    want = [sum(float(buf.weight[j]) for j in range(m)
                if bool(buf.valid[j]) and np.linalg.norm(np.asarray(buf.xy[j]) - x) <= 0.5) for x in xy]
    np.testing.assert_allclose(got, want, rtol=1e-5)


def test_hints_land_around_lost_tracks_with_their_spread():
    n = 4000
    tracks = _empty(3)
    cov = np.diag(np.array([0.04, 0.01, 1.0, 1.0], np.float32))  # NumPy, as in _table
    tracks = tracks._replace(
        valid=np.array([True, True, True]),
        mean=np.array([[3.0, 1.0, 0, 0], [1.0, -2.0, 0, 0], [9.0, 9.0, 0, 0]], np.float32),
        cov=np.stack([cov, cov, cov]),
    )
    lost = np.array([True, True, False])
    rank = np.asarray(np.random.default_rng(0).permutation(n), np.int32)
    context = InjectionContext(  # without its motion model: _injected puts it back
        particles=Particles(xy=np.full((n, 2), 50.0, np.float32)),
        log_weights=np.full((n,), -np.log(n), np.float32),
        rank=rank, used=np.int32(100), estimate=None, motion=None, motion_params=None, memory=tracks,
        memory_lost=lost,
    )
    out = _injected(MemoryHints(max_hinted=2), context, HintParams(hint_fraction=0.1, hint_std=0.1))
    xy = np.asarray(out.particles.xy)
    moved = np.any(xy != 50.0, axis=1)
    assert moved.sum() == 800 and int(out.used) == 900
    # The hints took the lowest-support free slots: ranks n - 900 .. n - 101.
    r = np.asarray(rank)
    assert np.all((r[moved] >= n - 900) & (r[moved] < n - 100))
    for centre, var in (([3.0, 1.0], [0.05, 0.02]), ([1.0, -2.0], [0.05, 0.02])):
        near = xy[moved & (np.linalg.norm(xy - centre, axis=1) < 1.5)]
        assert len(near) == 400
        np.testing.assert_allclose(near.mean(0), centre, atol=0.04)
        np.testing.assert_allclose(near.var(0), var, rtol=0.2)
    # By default only the lost track observed on most steps gets hints.
    context = context._replace(memory=tracks._replace(hits=np.array([4, 9, 20], np.int32)))
    out = _injected(MemoryHints(), context, HintParams(hint_fraction=0.1, hint_std=0.1))
    xy = np.asarray(out.particles.xy)
    moved = np.any(xy != 50.0, axis=1)
    assert moved.sum() == 400 and np.allclose(xy[moved].mean(0), [1.0, -2.0], atol=0.04)


def test_recall_finds_reappearing_lost_tracks_only():
    """Before the weighting, the memory re-detects the tracks nobody saw last step (NumPy Mahalanobis gate)."""
    rng = np.random.default_rng(3)
    tracks = _table(rng, 4)._replace(  # NumPy, as in _table
        mean=np.array([[2.0, 0.0, 1.0, 0.0], [4.0, 1.0, 0, 0], [0.0, -3.0, 0, 0], [6.0, 6.0, 0, 0]], np.float32),
        cov=np.broadcast_to(0.01 * np.eye(4, dtype=np.float32), (4, 4, 4)),
        age=np.array([1.0, 0.0, 1.0, 1.0], np.float32),  # track 1 was re-detected last step
        found=np.array([False, False, False, True]),  # track 3 was found by the filter
        hits=np.array([9, 9, 2, 9], np.int32),  # track 2 is not confirmed
    )
    dt, ego = 0.1, np.zeros((3,), np.float32)
    xy = np.array([[2.12, 0.02], [2.08, -0.03], [4.0, 1.0], [0.0, -3.0], [6.0, 6.0], [9.0, 9.0]], np.float32)
    buf = Measurements(xy=xy, weight=np.full((6,), 0.8, np.float32), valid=np.ones((6,), bool),
                       footprint=np.zeros((6, 2, 2), np.float32))
    recall = _np(_recall(tracks, buf, ego, dt=dt, params=PARAMS))
    np.testing.assert_array_equal(recall.redetected, [True, False, False, False])
    # Track 0 predicted to (2.1, 0): both nearby measurements, at their weighted centroid.
    pred = _np(_predict(tracks, np.float32(dt), ego, np.float32(PARAMS.memory_accel_std)))
    s = np.asarray(pred.cov[0, :2, :2], np.float64) + PARAMS.memory_obs_std**2 * np.eye(2)
    d = xy - np.asarray(pred.mean[0, :2])
    near = np.einsum("ni,ij,nj->n", d, np.linalg.inv(s), d) <= PARAMS.memory_redetect_sigmas**2
    assert near.sum() == 2
    np.testing.assert_allclose(recall.xy[0], xy[near].mean(0), atol=1e-5)
    empty = buf._replace(valid=np.zeros((6,), bool))
    assert np.asarray(_recall(tracks, empty, ego, dt=dt, params=PARAMS).redetected).sum() == 0


def test_seeds_move_the_least_supported_particles_to_the_most_observed_reappearance():
    n = 2000
    recall = Recall(redetected=np.array([True, True, False]),  # NumPy, as in _table
                    xy=np.array([[3.0, 1.0], [-1.0, 2.0], [7.0, 7.0]], np.float32),
                    hits=np.array([5, 12, 30], np.int32))
    rank = np.asarray(np.random.default_rng(1).permutation(n), np.int32)
    context = InjectionContext(
        particles=Particles(xy=np.full((n, 2), 50.0, np.float32)),
        log_weights=np.full((n,), -np.log(n), np.float32) - 3.0,
        rank=rank, used=np.int32(0), estimate=None, motion=RandomWalk(),
        motion_params=RandomWalk().default_params(), recall=recall,
    )
    out = _injected(RedetectionSeeds(), context._replace(motion=None, motion_params=None),
                    SeedParams(seed_fraction=0.25, seed_std=0.1), seed=True)
    xy = np.asarray(out.particles.xy)
    moved = np.any(xy != 50.0, axis=1)
    assert moved.sum() == 500 and int(out.used) == 500
    assert np.all(np.asarray(rank)[moved] >= n - 500)  # the least supported slots
    np.testing.assert_allclose(xy[moved].mean(0), [-1.0, 2.0], atol=0.02)  # track 1: most hits of the re-detected
    np.testing.assert_allclose(xy[moved].std(0), [0.1, 0.1], rtol=0.15)
    np.testing.assert_allclose(np.asarray(out.log_weights)[moved], -np.log(n), rtol=1e-6)
    np.testing.assert_array_equal(np.asarray(out.log_weights)[~moved], np.asarray(context.log_weights)[~moved])
    assert RedetectionSeeds().inject(jax.random.key(0), context, SeedParams()) is context  # after resampling: nothing
    with pytest.raises(ValueError, match="^injectors: RedetectionSeeds needs a long-term memory"):
        RedetectionSeeds().seed(jax.random.key(0), context._replace(recall=None), SeedParams())


def test_filter_with_memory_runs_vmaps_reports_tracks_and_reacquires_at_once():
    """A kicked ball rolls behind a robot for 1.7 s (``kicked_hidden`` world 201, no distractors, calibrated):
    a track follows it while seen, the ball's track predicts it through the hiding under one id, and the
    memory re-detects it where it reappears and seeds particles there, so the filter is on the ball on the first
    step it is seen again; without the seeds (hints alone) it is not yet."""
    seq, truth_info = simulate_family_with_info(
        "kicked_hidden", 201, num_steps=120, shrink=4,
        overrides={"distractors": 0, "calibration_error_deg": 0.0, "latency_steps": 0, "drop_rate": 0.0})
    m = build("paper", FilterOptions(num_particles=128, max_measurements=128, memory="tracks", max_tracks=3))
    assert isinstance(m.model.memory, TrackMemory)
    assert [inj.name for inj in m.model.injectors[-2:]] == ["hints", "seeds"]
    no_seeds = m.model.make_params(seed_fraction=0.0)  # hints alone: the seeds take no slot
    batch = hp.stack_params([m.params, m.model.make_params(memory_gate=0.5), no_seeds])
    info = jax.vmap(lambda p: hp.run(jax.random.key(0), seq, p, m.model).info)(batch)
    res_info = jax.tree.map(lambda x: np.asarray(x)[0], info)  # NumPy: an eager slice compiles per field
    tracks = jax.tree.map(np.asarray, res_info.tracks)
    assert tracks.valid.shape == (120, 3) and tracks.ball.shape == (120, 3)
    visible, truth = truth_info["visible"], seq.ground_truth
    # While the ball is seen, one track follows it.
    seen = np.flatnonzero(visible[10:]) + 10
    nearest = np.min(np.where(tracks.valid[seen], np.linalg.norm(tracks.mean[seen, :, :2] - truth[seen, None],
                                                                 axis=-1), np.inf), axis=1)
    filter_error = np.linalg.norm(np.asarray(res_info.mean)[seen] - truth[seen], axis=1)
    assert np.median(nearest) < 1.5 * np.median(filter_error) + 0.05, (np.median(nearest), np.median(filter_error))
    assert np.all(tracks.id[tracks.valid] > 0) and np.all(tracks.ball.sum(axis=1) <= 1)
    # Through the first hiding the ball's track (one id) stays within 0.5 m of the hidden ball.
    start, stop = (int(x) for x in truth_info["hidden"][0])
    assert stop - start >= 15 and not visible[start:stop].any() and visible[stop]
    ball_id = tracks.id[start - 1][tracks.ball[start - 1]]
    for t in range(start, stop):
        b = tracks.ball[t] & tracks.valid[t]
        assert tracks.id[t][b].tolist() == ball_id.tolist()
        assert np.linalg.norm(tracks.mean[t][b][0, :2] - truth[t]) < 0.5, t
    # Seen again: the memory re-detects it and seeds particles there.
    error = np.linalg.norm(np.asarray(res_info.mean)[stop] - truth[stop])
    late = np.asarray(info.mean)[2, stop]
    assert error < 0.3 < np.linalg.norm(late - truth[stop]), (error, late)


def test_memory_options_are_checked():
    with pytest.raises(ValueError, match="^memory: must be one of"):
        build("paper", FilterOptions(memory="mht"))
    with pytest.raises(ValueError, match="^max_tracks: must be a positive integer"):
        build("paper", FilterOptions(memory="tracks", max_tracks=0))
