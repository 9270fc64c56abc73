"""What the long-term memory observes under the filter's candidates (Olufs et al. 3.4): one blob, never the mean
of two (:func:`~heatpf_jax.memory.candidates.blob_under`), against NumPy; and on a hand-made table, the ball's
track at the moment the ball vanishes beside a distractor is not dragged onto the mean of the two."""

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.estimate.modes import Modes
from heatpf_jax.measurements import Measurements
from heatpf_jax.memory import MemoryParams, TrackMemory, blob_under, empty_tracks, find_blobs, gate_costs
from heatpf_jax.memory.predict import predict_tracks

PARAMS = jax.tree.map(jnp.asarray, MemoryParams())
# NumPy where the jitted functions take them: eager `jnp` (even `jnp.asarray`) compiles a program per shape.
DT = np.float32(0.1)
EGO = np.zeros(3, np.float32)
N_BUF = 32
_empty = jax.jit(empty_tracks, static_argnums=0)  # one program, where eagerly each field's fill compiles its own


@partial(jax.jit, static_argnames="count")
def _blob_under(xy, buffer, params, radius, count):
    """``count`` blobs of ``buffer`` and :func:`blob_under` on them: one program, where run eagerly each of their
    operations compiles on its own."""
    blobs = find_blobs(buffer, params, count)
    return blobs, blob_under(xy, buffer, blobs.member, blobs.xy, radius)


@jax.jit
def _gate_costs(tracks, xy, dt, ego, params):
    """:func:`gate_costs` (given the step's length) of ``xy`` for ``tracks`` predicted by ``dt``: one program."""
    pred = predict_tracks(tracks, dt, ego, params.memory_accel_std, params.memory_friction,
                          params.memory_lost_accel_std)
    return gate_costs(pred, xy, params, dt)


def test_blob_under_against_numpy(rng):
    """Random buffers and candidates: the centroid of the blob with the most weight within the radius, the
    centroid of that weight where none of it is in a blob, the candidate itself where there is none (NumPy)."""
    radius = 0.3
    for _ in range(5):
        centres = rng.uniform(0, 3, (5, 2))
        xy = centres[rng.integers(0, 5, N_BUF)] + rng.normal(0, 0.12, (N_BUF, 2))
        # NumPy, with the zero footprint `Measurements` would make in `jnp` (a program compiled per shape).
        buf = Measurements(np.asarray(xy, np.float32), np.asarray(rng.uniform(0.2, 1.0, N_BUF), np.float32),
                           rng.uniform(size=N_BUF) < 0.9, np.zeros((N_BUF, 2, 2), np.float32))
        cand = np.concatenate([centres + rng.normal(0, 0.2, (5, 2)), rng.uniform(-1, 4, (3, 2))])
        # Three blobs: some measurements are in none.
        blobs, got = _blob_under(np.asarray(cand, np.float32), buf, PARAMS, np.float32(radius), 3)
        blobs, got = jax.tree.map(np.asarray, blobs), np.asarray(got)
        w_all = np.where(np.asarray(buf.valid), np.asarray(buf.weight, np.float64), 0.0)
        member = np.asarray(blobs.member)
        for k, c in enumerate(cand):
            w = np.where(np.sum((xy - c) ** 2, axis=1) <= radius**2, w_all, 0.0)
            per_blob = np.array([w[member == b].sum() for b in range(3)])
            if per_blob.max() > 0:
                want = np.asarray(blobs.xy[int(np.argmax(per_blob))])
            elif w.sum() > 0:
                want = w @ xy / w.sum()
            else:
                want = c
            np.testing.assert_allclose(got[k], want, atol=1e-5)


def _buffer(*blobs, pixels=8):
    """``pixels`` measurements of each ``(centre, weight)``, padded to ``N_BUF``."""
    xy = np.zeros((N_BUF, 2), np.float32)
    weight = np.zeros(N_BUF, np.float32)
    for b, (c, w) in enumerate(blobs):
        xy[b * pixels : (b + 1) * pixels] = c
        weight[b * pixels : (b + 1) * pixels] = w
    return Measurements(xy, weight, weight > 0, np.zeros((N_BUF, 2, 2), np.float32))  # NumPy, as above


def test_the_ball_track_is_not_dragged_onto_the_mean_of_two_blobs():
    """The ball's track rolls along x at 0.5 m/s, seen last step at (2, 2). The ball vanishes: its last pixels
    (weight 0.7 each) lie at (2.05, 2), a distractor (weight 1) appears 0.45 m behind at (1.6, 2), and the filter's
    mode lies between them, within 0.3 m of both. The mean of all the weight there, (1.785, 2), lies inside the
    track's gate and would drag it back by half the 0.26 m innovation; the memory observes the distractor's blob
    (the heavier one under the mode) instead, outside the gate: the distractor gets a track of its own and the
    ball's track stays on the ball's own last blob."""
    # In NumPy: each eager `.at[].set()` and `jnp` operation compiles a program of its own.
    tracks = jax.tree.map(np.array, _empty(4))
    tracks.id[0], tracks.valid[0], tracks.hits[0], tracks.carried[0], tracks.ball[0] = 1, True, 10, 10, True
    tracks.mean[0] = np.asarray([2.0, 2.0, 0.5, 0.0], np.float32)
    tracks.cov[0] = np.diag(np.asarray([0.01, 0.01, 0.04, 0.04], np.float32))
    tracks = tracks._replace(next_id=np.int32(2))
    buffer = _buffer(((2.05, 2.0), 0.7), ((1.6, 2.0), 1.0))
    mode = np.asarray([[1.83, 2.0]], np.float32)
    mix = (5.6 * 2.05 + 8.0 * 1.6) / 13.6

    def cost(xy):  # of one point, for the ball's track predicted by a step
        return np.asarray(_gate_costs(tracks, np.asarray([xy], np.float32), DT, EGO, PARAMS))[0, 0]

    assert np.isfinite(cost((mix, 2.0)))
    assert not np.isfinite(cost((1.6, 2.0)))
    np.testing.assert_allclose(_blob_under(mode, buffer, PARAMS, PARAMS.memory_support_radius, 8)[1],
                               [[1.6, 2.0]], atol=1e-6)
    modes = Modes(weight=np.ones((1,), np.float32), mean=mode,
                  cov=np.float32(0.01) * np.eye(2, dtype=np.float32)[None], valid=np.ones((1,), bool))
    out = jax.tree.map(np.asarray, jax.jit(TrackMemory(4).update)(tracks, modes, mode[0], buffer, EGO, DT, PARAMS))
    # The ball's track is not the filter's this step; the memory re-detects it on the ball's last pixels.
    assert bool(out.ball[0]) and not bool(out.found[0])
    assert abs(float(out.mean[0, 0]) - 2.05) < 0.01 and abs(float(out.mean[0, 1]) - 2.0) < 1e-5
    assert int(out.id[1]) == 2
    np.testing.assert_allclose(out.mean[1, :2], [1.6, 2.0], atol=1e-6)
