"""The long-term memory's gates (Olufs et al. 3.4): a lost rolling track takes only what its roll can reach
(:func:`~heatpf_jax.memory.gates.motion_consistent`), against NumPy and on hand-made track tables: a blob behind
the place where the ball vanished (also one nearer the camera, where the occluder stands), or, with a
``memory_lost_turn`` below 90 degrees, beside its line, does not move the lost ball's track, opens a track of its
own and leaves the ball's flag where it is; a blob on the line ahead does move it (a Kalman update, in NumPy)."""

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.memory import MemoryParams
from heatpf_jax.memory.gates import motion_consistent

# The hand-made tables and blobs of the memory's other tests, and their jitted library functions (one compilation
# each per shape: run eagerly, each of their operations compiles on its own).
from tests.memory.test_distractors import DT, EGO, PARAMS, _blobs, _costs, _empty, _np, _predict, _recall, _step, _table

_consistent = jax.jit(motion_consistent)


def _np_consistent(mean, age, hits, static, valid, xy, dt, p: MemoryParams):
    """NumPy float64: ``[P, M]`` whether each point lies in the cone of each lost rolling track (half-angle
    ``memory_lost_turn`` around its motion from where it was last seen, widened by ``m``; ``True`` where the track
    is not lost and moving)."""
    mean = np.asarray(mean, np.float64)
    out = np.ones((xy.shape[0], mean.shape[0]), bool)
    m_ = float(p.memory_redetect_sigmas) * np.sqrt(2) * float(p.memory_obs_std)
    turn = float(p.memory_lost_turn)
    for m in range(mean.shape[0]):
        speed = np.hypot(*mean[m, 2:])
        if not (valid[m] and age[m] > 0 and hits[m] >= p.memory_confirm and not static[m]
                and speed > p.memory_static_speed):
            continue
        u = mean[m, 2:] / speed
        t = age[m] + dt
        p0 = mean[m, :2] - u * (speed * t + 0.5 * float(p.memory_friction) * t * t)
        for i, z in enumerate(np.asarray(xy, np.float64)):
            w = z - p0
            a, b = w @ u, abs(u[0] * w[1] - u[1] * w[0])
            lateral = np.inf if turn >= np.pi / 2 else m_ + np.tan(turn) * max(a, 0.0)
            out[i, m] = a >= -m_ and b <= lateral
    return out


def test_motion_consistent_against_numpy(rng):
    """Random tables (lost and seen, moving and slow, static, confirmed or not) and points around them, for the
    default cone (90 degrees: nothing behind) and narrower ones: the same verdicts as NumPy in float64, away from
    the boundaries."""
    refused = 0
    for turn in (np.pi / 2, 0.6, 0.2):
        params = PARAMS._replace(memory_lost_turn=np.float32(turn))
        ref = MemoryParams(memory_lost_turn=turn)
        for _ in range(3):
            m, n = 6, 40
            mean = np.concatenate([rng.uniform(0, 4, (m, 2)), rng.normal(0, 0.6, (m, 2))], axis=1)
            age = np.where(rng.uniform(size=m) < 0.7, rng.uniform(0.1, 1.5, m), 0.0)
            hits = rng.integers(1, 8, m)
            static = rng.uniform(size=m) < 0.2
            valid = rng.uniform(size=m) < 0.9
            xy = mean[rng.integers(0, m, n), :2] + rng.normal(0, 0.6, (n, 2))
            t = _empty(m)._replace(  # NumPy fields: `jnp.asarray` compiles a program per shape
                valid=valid, mean=np.asarray(mean, np.float32), age=np.asarray(age, np.float32),
                hits=np.asarray(hits, np.int32), static=static)
            got = np.asarray(_consistent(t, np.asarray(xy, np.float32), params, DT))
            mean32 = np.asarray(t.mean)
            want = _np_consistent(mean32, age, hits, static, valid, xy, 0.1, ref)
            # Away from the boundaries: the same verdict for points moved 1 mm either way.
            near = np.zeros_like(want)
            for shift in ((1e-3, 0), (-1e-3, 0), (0, 1e-3), (0, -1e-3)):
                near |= _np_consistent(mean32, age, hits, static, valid, xy + shift, 0.1, ref) != want
            np.testing.assert_array_equal(got[~near], want[~near])
            refused += int((~want).sum())
    assert refused > 30  # not vacuous


def _lost_ball():
    """The ball's track, rolling at 0.5 m/s along x at y = 2 (the robot at the origin looks along y), unobserved
    for 0.2 s, its position known to 0.3 m: a Gaussian gate of ``memory_gate`` = 0.75 m."""
    return _table([dict(mean=(2.0, 2.0, 0.5, 0.0), var=(0.09, 0.09), age=0.2, ball=True)])


def _predicted(tracks):
    return _np(_predict(tracks, DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction,
                        PARAMS.memory_lost_accel_std))


def _refused(blob, params):
    """The lost ball's step with ``blob`` (also the filter's candidate): its track is not moved, keeps its flag,
    and the blob opens a track of its own; nor does the memory's recall re-detect the ball there."""
    pred = _predicted(_lost_ball())
    out = _step(_lost_ball(), blob, _blobs(blob), params=params)
    np.testing.assert_allclose(out.mean[0], pred.mean[0], atol=1e-6)  # untouched: the prediction
    np.testing.assert_allclose(out.age[0], 0.3, atol=1e-6)
    assert bool(out.ball[0]) and not bool(out.found[0])
    assert int(out.id[1]) == 2 and bool(out.valid[1])  # the blob's own track
    np.testing.assert_allclose(out.mean[1], [*blob, 0.0, 0.0], atol=1e-6)
    recall = _np(_recall(_lost_ball(), _blobs(blob), EGO, DT, params))
    assert not bool(recall.redetected[0])


def test_a_lost_rolling_track_is_not_moved_behind_where_it_vanished():
    """Last seen 0.3 s ago at x0 = 2.0485 - (0.47 * 0.3 + 0.15 * 0.09) = 1.894 m (the rolling model backwards from
    the prediction). A blob 0.70 m behind the prediction (0.54 m behind x0, more than m = 3 sqrt(2) 0.1 = 0.42 m)
    and one 0.5 m behind x0 and 0.2 m nearer the camera (the occluder's side) lie inside the Gaussian gate, yet
    neither moves the track."""
    pred = _predicted(_lost_ball())
    x, v = float(pred.mean[0, 0]), float(pred.mean[0, 2])
    np.testing.assert_allclose([x, v], [2.0 + 0.05 - 0.0015, 0.47], atol=1e-6)
    x0 = x - (v * 0.3 + 0.5 * 0.3 * 0.09)
    np.testing.assert_allclose(x0, 1.894, atol=1e-3)
    behind, nearer = (x - 0.70, 2.0), (x0 - 0.5, 1.8)
    points = np.asarray([behind, nearer], np.float32)
    assert np.isfinite(np.asarray(_costs(pred, points, PARAMS))[:, 0]).all()  # the Gaussian gate takes both
    assert not np.isfinite(np.asarray(_costs(pred, points, PARAMS, DT))[:, 0]).any()
    for blob in (behind, nearer):
        _refused(blob, PARAMS)


def test_a_narrower_cone_refuses_a_blob_beside_the_line():
    """A blob beside the prediction, 0.55 m nearer the camera: ahead of x0 by a = 0.1545 m, so the default cone
    (90 degrees) takes it, and so does the track; a cone of 0.5 rad refuses it
    (0.55 > 0.42 + tan(0.5) 0.1545 = 0.51 m)."""
    pred = _predicted(_lost_ball())
    beside = (float(pred.mean[0, 0]), 2.0 - 0.55)
    # Weakly typed as PARAMS's numbers (the same float32 0.5): the jitted update and recall compile once for both.
    narrow = PARAMS._replace(memory_lost_turn=jnp.asarray(0.5))
    point = np.asarray([beside], np.float32)
    assert bool(np.asarray(_consistent(pred, point, PARAMS, DT))[0, 0])
    assert not bool(np.asarray(_consistent(pred, point, narrow, DT))[0, 0])
    out = _step(_lost_ball(), beside, _blobs(beside))
    assert float(out.age[0]) == 0.0 and bool(out.found[0])  # the default cone: taken
    _refused(beside, narrow)


def test_a_blob_on_the_line_ahead_moves_the_lost_track():
    """A blob 0.15 m ahead of the prediction and 0.05 m off the line is the rolling ball: the track takes it (the
    Kalman update, NumPy float64), its age returns to 0; the memory's recall re-detects it there too."""
    pred = _predicted(_lost_ball())
    blob = (float(pred.mean[0, 0]) + 0.15, 2.05)
    assert bool(np.asarray(_consistent(pred, np.asarray([blob], np.float32), PARAMS, DT))[0, 0])
    out = _step(_lost_ball(), blob, _blobs(blob))
    p = np.asarray(pred.cov[0], np.float64)
    h = np.eye(2, 4)
    s = h @ p @ h.T + 0.01 * np.eye(2)
    gain = p @ h.T @ np.linalg.inv(s)
    want = np.asarray(pred.mean[0], np.float64) + gain @ (np.asarray(blob) - np.asarray(pred.mean[0, :2]))
    np.testing.assert_allclose(out.mean[0], want, atol=1e-5)
    assert float(out.age[0]) == 0.0 and bool(out.found[0]) and bool(out.ball[0])
    assert int(np.asarray(out.valid).sum()) == 1  # no new track
    recall = _np(_recall(_lost_ball(), _blobs(blob), EGO, DT, PARAMS))
    assert bool(recall.redetected[0])
    np.testing.assert_allclose(recall.xy[0], blob, atol=1e-6)


def test_the_test_leaves_seen_slow_static_and_unconfirmed_tracks_alone():
    """A track observed last step, one predicted slower than ``memory_static_speed``, static clutter and a track
    seen fewer than ``memory_confirm`` times keep their Gaussian gates: a point behind them is consistent."""
    tracks = _table([dict(mean=(2.0, 2.0, 0.5, 0.0), age=0.0),
                     dict(mean=(2.0, 2.0, 0.1, 0.0), age=0.5),
                     dict(mean=(2.0, 2.0, 0.5, 0.0), age=0.5, static=True),
                     dict(mean=(2.0, 2.0, 0.5, 0.0), age=0.5, hits=2)])
    pred = _predicted(tracks)
    behind = pred.mean[:, :2] - np.asarray([[1.0, 0.0]], np.float32)
    assert np.asarray(_consistent(pred, behind, PARAMS, DT)).all()
    lost = _table([dict(mean=(2.0, 2.0, 0.5, 0.0), age=0.5)])
    assert not bool(np.asarray(_consistent(_predicted(lost), behind[:1], PARAMS, DT))[0, 0])
