"""What the long-term memory observes under the filter's candidates (Olufs et al. 3.4): one blob, never the mean
of two (:func:`~heatpf_jax.memory.candidates.blob_under`), against NumPy; and on a hand-made table, the ball's
track at the moment the ball vanishes beside a distractor is not dragged onto the mean of the two."""

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.estimate.modes import Modes
from heatpf_jax.measurements import Measurements
from heatpf_jax.memory import MemoryParams, TrackMemory, blob_under, empty_tracks, find_blobs, gate_costs
from heatpf_jax.memory.predict import predict_tracks

PARAMS = jax.tree.map(jnp.asarray, MemoryParams())
DT = jnp.float32(0.1)
EGO = jnp.zeros(3, jnp.float32)
N_BUF = 32


def test_blob_under_against_numpy(rng):
    """Random buffers and candidates: the centroid of the blob with the most weight within the radius, the
    centroid of that weight where none of it is in a blob, the candidate itself where there is none (NumPy)."""
    radius = 0.3
    for _ in range(5):
        centres = rng.uniform(0, 3, (5, 2))
        xy = centres[rng.integers(0, 5, N_BUF)] + rng.normal(0, 0.12, (N_BUF, 2))
        buf = Measurements(jnp.asarray(xy, jnp.float32), jnp.asarray(rng.uniform(0.2, 1.0, N_BUF), jnp.float32),
                           jnp.asarray(rng.uniform(size=N_BUF) < 0.9))
        blobs = find_blobs(buf, PARAMS, 3)  # three blobs: some measurements are in none
        cand = np.concatenate([centres + rng.normal(0, 0.2, (5, 2)), rng.uniform(-1, 4, (3, 2))])
        got = np.asarray(blob_under(jnp.asarray(cand, jnp.float32), buf, blobs.member, blobs.xy, jnp.float32(radius)))
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
    return Measurements(jnp.asarray(xy), jnp.asarray(weight), jnp.asarray(weight > 0))


def test_the_ball_track_is_not_dragged_onto_the_mean_of_two_blobs():
    """The ball's track rolls along x at 0.5 m/s, seen last step at (2, 2). The ball vanishes: its last pixels
    (weight 0.7 each) lie at (2.05, 2), a distractor (weight 1) appears 0.45 m behind at (1.6, 2), and the filter's
    mode lies between them, within 0.3 m of both. The mean of all the weight there, (1.785, 2), lies inside the
    track's gate and would drag it back by half the 0.26 m innovation; the memory observes the distractor's blob
    (the heavier one under the mode) instead, outside the gate: the distractor gets a track of its own and the
    ball's track stays on the ball's own last blob."""
    t = empty_tracks(4)
    tracks = t._replace(
        id=t.id.at[0].set(1), valid=t.valid.at[0].set(True),
        mean=t.mean.at[0].set(jnp.asarray([2.0, 2.0, 0.5, 0.0], jnp.float32)),
        cov=t.cov.at[0].set(jnp.diag(jnp.asarray([0.01, 0.01, 0.04, 0.04], jnp.float32))),
        hits=t.hits.at[0].set(10), carried=t.carried.at[0].set(10), ball=t.ball.at[0].set(True),
        next_id=jnp.int32(2))
    buffer = _buffer(((2.05, 2.0), 0.7), ((1.6, 2.0), 1.0))
    mode = jnp.asarray([[1.83, 2.0]], jnp.float32)
    mix = (5.6 * 2.05 + 8.0 * 1.6) / 13.6
    pred = predict_tracks(tracks, DT, EGO, PARAMS.memory_accel_std, PARAMS.memory_friction,
                          PARAMS.memory_lost_accel_std)
    assert np.isfinite(gate_costs(pred, jnp.asarray([[mix, 2.0]], jnp.float32), PARAMS, DT)[0, 0])
    assert not np.isfinite(gate_costs(pred, jnp.asarray([[1.6, 2.0]], jnp.float32), PARAMS, DT)[0, 0])
    blobs = find_blobs(buffer, PARAMS, 8)
    np.testing.assert_allclose(blob_under(mode, buffer, blobs.member, blobs.xy, PARAMS.memory_support_radius),
                               [[1.6, 2.0]], atol=1e-6)
    modes = Modes(weight=jnp.ones((1,), jnp.float32), mean=mode, cov=0.01 * jnp.eye(2, dtype=jnp.float32)[None],
                  valid=jnp.ones((1,), bool))
    out = jax.jit(TrackMemory(4).update)(tracks, modes, mode[0], buffer, EGO, DT, PARAMS)
    # The ball's track is not the filter's this step; the memory re-detects it on the ball's last pixels.
    assert bool(out.ball[0]) and not bool(out.found[0])
    assert abs(float(out.mean[0, 0]) - 2.05) < 0.01 and abs(float(out.mean[0, 1]) - 2.0) < 1e-5
    assert int(out.id[1]) == 2
    np.testing.assert_allclose(out.mean[1, :2], [1.6, 2.0], atol=1e-6)
