"""The long-term memory among distractors, on hand-made track tables (Olufs et al. 3.4; issue "long-term memory
among distractors"): nothing outside a track's gate moves it, a distractor opens a track of its own and becomes
static clutter, the ball's identity stays on the predicted track through a gap, re-detection (and the seeds)
refuse a blob that disagrees with the ball track's motion or that another track explains, and hints go to the
ball first. Expected positions are computed by hand from the rolling model: a speed ``s`` falls by ``f t`` and
the track advances ``s t - f t^2 / 2``."""

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.injection.explorers import InjectionContext
from heatpf_jax.injection.memory_hints import HintParams, MemoryHints, RedetectionSeeds, SeedParams
from heatpf_jax.measurements import Measurements
from heatpf_jax.memory import (
    MemoryParams,
    TrackMemory,
    TrackTable,
    empty_tracks,
    find_blobs,
    gate_costs,
    lost_tracks,
)
from heatpf_jax.memory.blobs import redetect
from heatpf_jax.memory.predict import predict_tracks
from heatpf_jax.memory.update import update_tracks
from heatpf_jax.motion.random_walk import Particles, RandomWalk

PARAMS = jax.tree.map(jnp.asarray, MemoryParams())
# NumPy where the jitted functions take them: eager `jnp` (even `jnp.asarray`) compiles a program per shape.
DT = np.float32(0.1)
EGO = np.zeros(3, np.float32)
FRICTION = float(MemoryParams().memory_friction)
N_BUF = 32
_update = jax.jit(update_tracks)  # one compilation per shape: 4 slots, 1 candidate, 32 measurements
# The library's functions through one program each: run eagerly, each of their operations compiles on its own.
_empty = jax.jit(empty_tracks, static_argnums=0)
_predict = jax.jit(predict_tracks)
_costs = jax.jit(gate_costs)
_lost = jax.jit(lost_tracks)
_recall = jax.jit(TrackMemory(4).recall)
_find_blobs = jax.jit(find_blobs, static_argnames="count")
_redetect = jax.jit(redetect, static_argnames="max_blobs")


def _np(tree):
    """``tree`` in NumPy: the tests look at its fields, where each eager index would compile a program."""
    return jax.tree.map(np.asarray, tree)


def _table(rows, capacity=4) -> TrackTable:
    """A table from ``rows`` of ``dict(mean=(x, y, vx, vy), var=(pos, vel), hits, age, ball, carried, ...)``."""
    t = jax.tree.map(np.array, _empty(capacity))  # NumPy: each `.at[].set()` would compile a scatter
    for i, r in enumerate(rows):
        pos_var, vel_var = r.get("var", (0.01, 0.04))
        t.id[i] = i + 1
        t.valid[i] = True
        t.mean[i] = np.asarray(r["mean"], np.float32)
        t.cov[i] = np.diag(np.asarray([pos_var, pos_var, vel_var, vel_var], np.float32))
        t.age[i] = r.get("age", 0.0)
        t.hits[i] = r.get("hits", 10)
        t.ball[i] = r.get("ball", False)
        t.static[i] = r.get("static", False)
        t.carried[i] = r.get("carried", r.get("hits", 10))
        t.missed[i] = r.get("age", 0.0)
    return t._replace(next_id=np.int32(len(rows) + 1))


def _blobs(*centres, weight=1.0, pixels=8) -> Measurements:
    """``pixels`` measurements of ``weight`` at each centre (a detector blob: the centroid source puts every
    pixel of a blob at its centre), padded to ``N_BUF`` slots."""
    xy = np.zeros((N_BUF, 2), np.float32)
    valid = np.zeros(N_BUF, bool)
    for b, c in enumerate(centres):
        xy[b * pixels : (b + 1) * pixels] = c
        valid[b * pixels : (b + 1) * pixels] = True
    # NumPy, with the zero footprint `Measurements` would make in `jnp` (a program compiled per shape).
    return Measurements(xy, np.where(valid, weight, 0.0).astype(np.float32), valid, np.zeros((N_BUF, 2, 2), np.float32))


def _step(tracks, estimate, buffer, observed=True, params=PARAMS):
    est = np.asarray(estimate, np.float32)
    return _np(_update(tracks, est[None], np.array([observed]), DT, EGO, params, buffer, est))


def _rolled(x0, v0, t, f=FRICTION):
    """Hand-computed rolling position along x: ``x0 + v0 t - f t^2 / 2`` until the ball stops."""
    t_stop = v0 / f
    t = min(t, t_stop)
    return x0 + v0 * t - 0.5 * f * t * t, v0 - f * t


def _slot(tracks, track_id):
    return int(np.flatnonzero(np.asarray(tracks.id) == track_id)[0])


def test_rolling_prediction_by_hand():
    tracks = _table([dict(mean=(2.0, 0.0, 1.0, 0.0)), dict(mean=(1.0, 1.0, 0.0, 0.1))])
    for _ in range(10):
        tracks = _predict(tracks, DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction)
    tracks = _np(tracks)
    x, v = _rolled(2.0, 1.0, 1.0)  # 2.85 m, 0.7 m/s
    np.testing.assert_allclose(tracks.mean[0], [x, 0.0, v, 0.0], atol=1e-5)
    # 0.1 m/s stops within 1/3 s, after 0.1^2 / (2 * 0.3) = 1/60 m.
    np.testing.assert_allclose(tracks.mean[1], [1.0, 1.0 + 0.01 / 0.6, 0.0, 0.0], atol=1e-5)


def test_a_measurement_outside_the_gate_never_moves_a_track():
    """A candidate 0.5 m beside the prediction (inside 0.75 m, outside 3 sigmas) and one 0.9 m from a track whose
    covariance has grown huge (inside 3 sigmas, outside 0.75 m) move nothing: each opens a track of its own."""
    ball = dict(mean=(2.0, 0.0, 1.0, 0.0), var=(0.01, 0.04), ball=True)
    x, v = _rolled(2.0, 1.0, 0.1)  # 2.0985 m, 0.97 m/s
    beside = (x, 0.5)
    tracks = _step(_table([ball]), beside, _blobs(beside))
    np.testing.assert_allclose(tracks.mean[0], [x, 0.0, v, 0.0], atol=1e-6)  # the prediction, untouched
    assert float(tracks.age[0]) > 0 and not bool(tracks.found[0])
    assert np.asarray(tracks.valid).sum() == 2 and int(tracks.id[1]) == 2  # one new track, at the candidate
    np.testing.assert_allclose(tracks.mean[1], [x, 0.5, 0.0, 0.0], atol=1e-6)
    assert np.asarray(tracks.ball).tolist() == [True, False, False, False]  # the flag stayed
    # The gate in sigmas alone would take it; the gate in metres does not.
    lost = dict(mean=(2.0, 0.0, 1.0, 0.0), var=(4.0, 4.0), ball=True, age=1.0)
    far = (x + 0.9, 0.0)
    predicted = _np(_predict(_table([lost]), DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction))
    d2 = 0.9**2 / (float(predicted.cov[0, 0, 0]) + 0.01)
    assert d2 < 9.0 and not np.isfinite(np.asarray(_costs(predicted, np.asarray([far], np.float32), PARAMS))[0, 0])
    tracks = _step(_table([lost]), far, _blobs(far))
    np.testing.assert_allclose(tracks.mean[0], [x, 0.0, v, 0.0], atol=1e-6)
    np.testing.assert_allclose(tracks.mean[1, :2], far, atol=1e-6)


def _np_cost(tracks, j, point):
    """NumPy float64: the gate cost of ``point`` for track ``j`` (inf outside its gate)."""
    s = np.asarray(tracks.cov[j, :2, :2], np.float64) + 0.01 * np.eye(2)
    d = np.asarray(point, np.float64) - np.asarray(tracks.mean[j, :2], np.float64)
    d2 = d @ np.linalg.solve(s, d)
    if not bool(tracks.valid[j]) or d2 > 9.0 or np.linalg.norm(d) > 0.75:
        return np.inf
    return 0.5 * d2 + 0.5 * np.log(np.linalg.det(s))


def test_blobs_and_redetection_against_brute_force(rng):
    """Blobs: the strongest free pixel and every free pixel within 0.3 m or 3 sigmas of its ball-sized blob
    ``r^2 / (4 |J e_u|^2) J J^T + obs^2 I`` (``J`` its footprint); then blobs and tracks paired by increasing cost,
    centroids inside the gates; a lost track is re-detected on a blob of enough weight (NumPy, float64)."""
    rows = [dict(mean=(*rng.uniform(1, 3, 2), *rng.normal(0, 0.5, 2)), var=(v, 0.1), age=0.3)
            for v in rng.uniform(0.005, 0.1, 4)]
    tracks = _table(rows)
    footprint = rng.normal(0, 0.01, (N_BUF, 2, 2)) + np.array([[0.02, 0.0], [0.0, 0.08]])
    centres = rng.uniform(1, 3, (5, 2))
    xy = centres[rng.integers(0, 5, N_BUF)] + rng.normal(0, 0.1, (N_BUF, 2))
    buf = Measurements(np.asarray(xy, np.float32), np.asarray(rng.uniform(0.2, 1.0, N_BUF), np.float32),
                       rng.uniform(size=N_BUF) < 0.9, np.asarray(footprint, np.float32))
    params = PARAMS._replace(memory_min_support=np.float32(0.5))
    blobs = _np(_find_blobs(buf, params, 6))
    w, ok = np.asarray(buf.weight, np.float64), np.asarray(buf.valid)
    free, r = ok.copy(), float(PARAMS.memory_blob_radius)
    for b in range(6):
        i = int(np.argmax(np.where(free, w, 0.0)))
        j_i = footprint[i]
        cov = r**2 / (4 * np.sum(j_i[:, 0] ** 2)) * j_i @ j_i.T + 0.01 * np.eye(2)
        d = xy - xy[i]
        near = free & ((np.sum(d * d, axis=1) <= 0.09) | (np.einsum("ni,ij,nj->n", d, np.linalg.inv(cov), d) <= 9.0))
        np.testing.assert_array_equal(np.asarray(blobs.member) == b, near)
        np.testing.assert_allclose(blobs.weight[b], w[near].sum(), rtol=1e-5)
        if near.any():
            np.testing.assert_allclose(blobs.xy[b], w[near] @ xy[near] / w[near].sum(), atol=1e-5)
        free &= ~near
    assert np.asarray(blobs.valid).sum() >= 3  # not vacuous
    lost = np.array([True, True, False, True])
    again, centroid = _np(_redetect(tracks, lost, buf, params, max_blobs=6))
    costs = np.array([[_np_cost(tracks, j, blobs.xy[b]) if bool(blobs.valid[b]) else np.inf for j in range(4)]
                      for b in range(6)])
    paired = {}
    while np.isfinite(costs).any():
        b, j = np.unravel_index(np.argmin(costs), costs.shape)
        paired[j] = b
        costs[b, :] = costs[:, j] = np.inf
    for j in range(4):
        want = bool(lost[j]) and j in paired
        assert bool(again[j]) == want
        if want:
            np.testing.assert_allclose(centroid[j], blobs.xy[paired[j]], atol=1e-6)
    assert np.asarray(again).any()


def test_a_distractor_opens_its_own_track_and_becomes_static_clutter():
    """The ball is hidden (its track rolls on, lost); a blob appears 0.9 m away, where no track predicts
    anything. Whether the filter's estimate jumps onto it or stays elsewhere, the blob gets a track of its own,
    which is static clutter after three observations: never the ball, never lost, never hinted."""
    for on_it in (True, False):
        tracks = _table([dict(mean=(2.0, 0.0, 0.5, 0.0), ball=True, age=0.3)])
        d = (2.4, 0.8)
        for step in range(1, 6):
            tracks = _step(tracks, d if on_it else (0.0, 0.0), _blobs(d), observed=on_it)
            other = 1 - _slot(tracks, 1)
            np.testing.assert_allclose(tracks.mean[other, :2], d, atol=1e-5)
            assert int(tracks.id[other]) == 2 and int(tracks.hits[other]) == step
            assert int(tracks.carried[other]) == (step if on_it else 0)
            assert bool(tracks.static[other]) == (step >= 3) and not bool(tracks.ball[other])
            x, v = _rolled(2.0, 0.5, 0.1 * step)
            np.testing.assert_allclose(tracks.mean[_slot(tracks, 1)], [x, 0.0, v, 0.0], atol=1e-5)
            assert bool(tracks.ball[_slot(tracks, 1)])
        assert np.asarray(_lost(tracks, PARAMS.memory_confirm)).tolist() == [True, False, False, False]


def test_the_ball_keeps_its_identity_through_a_gap_among_distractors():
    """Seen rolling for 1 s, hidden for 1.2 s while the filter's estimate sits on a distractor, seen again where
    the track predicts while the estimate stays two more steps on the distractor: the ball's flag stays on
    track 1 throughout; the memory re-detects it on its own, then the filter finds it again."""
    tracks = _table([])
    x0, v0 = 1.5, 0.8
    ball_at = lambda t: np.array([_rolled(x0, v0, t, f=0.3)[0], 0.2], np.float32)  # noqa: E731
    d = ball_at(1.0) + np.array([-0.2, 0.6], np.float32)  # beside the vanishing ball, outside its gate
    for k in range(10):
        tracks = _step(tracks, ball_at(0.1 * k), _blobs(ball_at(0.1 * k)))
    assert np.asarray(tracks.ball).tolist() == [True, False, False, False] and int(tracks.id[0]) == 1
    for k in range(10, 22):  # hidden; the estimate on the distractor
        tracks = _step(tracks, d, _blobs(d))
        b = _slot(tracks, 1)
        assert bool(tracks.ball[b]) and np.asarray(tracks.ball).sum() == 1
        assert np.linalg.norm(np.asarray(tracks.mean[b, :2]) - ball_at(0.1 * k)) < 0.1
    assert bool(tracks.static[_slot(tracks, 2)]) and not bool(tracks.found[_slot(tracks, 1)])
    for k in range(22, 26):  # seen again; the estimate leaves the distractor on the third step
        estimate = d if k < 24 else ball_at(0.1 * k)
        tracks = _step(tracks, estimate, _blobs(ball_at(0.1 * k), d))
        b = _slot(tracks, 1)
        assert bool(tracks.ball[b]) and float(tracks.age[b]) == 0.0 and bool(tracks.found[b]) == (k >= 24)
        assert np.linalg.norm(np.asarray(tracks.mean[b, :2]) - ball_at(0.1 * k)) < 0.05
    assert sorted(np.asarray(tracks.id[tracks.valid]).tolist()) == [1, 2]


def _context(recall=None, tracks=None, lost=None, n=2000):
    return InjectionContext(
        particles=Particles(xy=jnp.full((n, 2), 50.0, jnp.float32)),
        log_weights=jnp.full((n,), -np.log(n), jnp.float32),
        rank=jnp.asarray(np.random.default_rng(1).permutation(n), jnp.int32),
        used=jnp.int32(0), estimate=None, motion=RandomWalk(), motion_params=RandomWalk().default_params(),
        recall=recall, memory=tracks, memory_lost=lost,
    )


def test_seeds_refuse_a_blob_inconsistent_with_the_ball_tracks_motion():
    """The ball's track was last seen at (2, 0) rolling at 1 m/s along x, 0.9 s ago: it is predicted at
    x = 2.85 m. A blob where it was last seen (a ball that stopped, or a distractor there) is 0.85 m behind the
    prediction and re-detects nothing, however wide the track's uncertainty has grown; so is a blob inside its
    gate that a static clutter track explains better. A blob at the prediction is taken and seeded."""
    tracks = _table([dict(mean=(2.0, 0.0, 1.0, 0.0), ball=True, hits=12)])
    for _ in range(9):
        tracks = _predict(tracks, DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction)
    tracks = jax.tree.map(np.array, tracks)
    tracks.age[0] = tracks.missed[0] = 0.9
    x, _ = _rolled(2.0, 1.0, 1.0)

    @jax.jit
    def seeds(table, recall):
        context = _context(recall, tracks=table)
        return RedetectionSeeds().seed(jax.random.key(0), context, SeedParams(0.25, 0.05)).particles.xy

    def seeded(table, buffer):
        recall = _recall(table, buffer, EGO, DT, PARAMS)
        xy = np.asarray(seeds(table, recall))
        recall = _np(recall)
        moved = np.any(xy != 50.0, axis=1)
        return recall, moved, xy[moved]

    recall, moved, _ = seeded(tracks, _blobs((2.0, 0.0)))
    assert not bool(recall.redetected[0]) and moved.sum() == 0
    clutter = dict(mean=(x - 0.35, 0.1, 0.0, 0.0), var=(0.0004, 0.0004), static=True, hits=20, carried=0)
    with_clutter = _table([dict(mean=(2.0, 0.0, 1.0, 0.0), ball=True, hits=12), clutter])
    for _ in range(9):
        with_clutter = _predict(with_clutter, DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction)
    with_clutter = jax.tree.map(np.array, with_clutter)
    with_clutter.age[0] = 0.9
    recall, moved, _ = seeded(with_clutter, _blobs((x - 0.35, 0.1)))
    assert not bool(recall.redetected[0]) and moved.sum() == 0
    recall, moved, xy = seeded(tracks, _blobs((x + 0.1, 0.05)))
    assert bool(recall.redetected[0]) and moved.sum() == 500
    np.testing.assert_allclose(xy.mean(0), [x + 0.1, 0.05], atol=0.01)


@jax.jit
def _hinted(tracks, lost):
    """The particles after :class:`MemoryHints`: one program, where the eager injector compiles each operation."""
    out = MemoryHints().inject(jax.random.key(0), _context(tracks=tracks, lost=lost), HintParams(0.1, 0.05))
    return out.particles.xy


def test_hints_go_to_the_ball_track_first():
    """Two lost tracks: a moving one the filter carried on more steps, and the ball's: the one hint goes to
    the ball."""
    tracks = _table([dict(mean=(1.0, -1.0, 0.5, 0.0), hits=40, age=0.5),
                     dict(mean=(3.0, 1.0, 0.5, 0.0), hits=8, age=0.5, ball=True)])
    lost = _lost(tracks, PARAMS.memory_confirm)
    assert np.asarray(lost).tolist() == [True, True, False, False]
    xy = np.asarray(_hinted(tracks, lost))
    moved = np.any(xy != 50.0, axis=1)
    assert moved.sum() == 200
    np.testing.assert_allclose(xy[moved].mean(0), [3.0, 1.0], atol=0.02)


def test_a_new_track_never_takes_the_balls_slot():
    """A full table: the filter's candidate far from everything takes the slot of the least useful track (a
    memory-only static one), never the lost ball's, even when the ball's is the oldest."""
    tracks = _table([dict(mean=(2.0, 0.0, 0.0, 0.0), ball=True, age=1.5, hits=30),
                     dict(mean=(1.0, 1.0, 0.0, 0.0), age=0.4, hits=5),
                     dict(mean=(1.0, -1.0, 0.0, 0.0), age=0.2, static=True, hits=6, carried=0),
                     dict(mean=(3.0, 1.5, 0.0, 0.0), age=0.3, hits=5)])
    tracks = _step(tracks, (4.0, -1.5), _blobs((4.0, -1.5)))
    assert np.asarray(tracks.id).tolist() == [1, 2, 5, 4] and bool(tracks.ball[0])
