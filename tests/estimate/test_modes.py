"""The mode pieces of ``heatpf_jax.estimate.modes`` on weighted blobs, against NumPy weighted statistics.

Blobs far apart (15 standard deviations) make every clustering exact: each mode is one blob, with the
blob's weight share and the blob's weighted mean and covariance (plus ``reg_covar`` for the mixture).
"""

from __future__ import annotations

import dataclasses
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from heatpf_jax import params as P
from heatpf_jax.estimate import modes as M

N = 150
STD = 0.2
CENTRES = np.array([[0.0, 0.0], [3.0, 0.5], [0.5, 3.0]])
SHARES = (0.5, 0.3, 0.2)

PIECES = {
    "kmeans": M.KMeansModes(num_modes=3, num_iters=10),
    "gmm": M.GaussianMixtureModes(num_modes=3, num_iters=20),
    "mean_shift": M.MeanShiftModes(max_modes=3, num_seeds=16, num_iters=10),
}


def _loss(piece, key, xy, weights, params):
    modes = piece.modes(key, xy, weights, params)
    return modes.mean[0, 0] + jnp.sum(modes.weight * modes.mean[:, 1]) + jnp.sum(modes.cov), modes


# Compiling is most of the cost: each piece is compiled once for the whole file, batched over two data
# sets and params (vmap; one key, as batched keys make the random draws far costlier to compile) and
# differentiated in the positions and weights. Every batch element is checked against NumPy, which
# shows that jit, vmap and grad work.
_BATCHED = {
    name: jax.jit(jax.vmap(jax.value_and_grad(partial(_loss, piece), argnums=(1, 2), has_aux=True), (None, 0, 0, 0)))
    for name, piece in PIECES.items()
}


def _run(name, key, xy, weights, params):
    """``(modes, d loss / d xy, d loss / d weights)`` of a batch, as NumPy arrays."""
    args = (jnp.asarray(np.asarray(xy), jnp.float32), jnp.asarray(np.asarray(weights), jnp.float32))
    (_, modes), (g_xy, g_w) = _BATCHED[name](key, *args, params)
    return jax.tree.map(np.asarray, modes), np.asarray(g_xy), np.asarray(g_w)


def _params(piece, *updates: dict):
    """A batch of params, one per dict of updates to the defaults."""
    batch = [P.as_arrays(P.make_params(piece, u), piece.properties()) for u in updates]
    return jax.tree.map(lambda *xs: jnp.stack(xs), *batch)


def _blobs(rng: np.random.Generator, shares=SHARES):
    """Points (float32), positive weights, and the blob of each point; each blob holds its share of the weight."""
    which = np.repeat(np.arange(len(shares)), np.round(np.asarray(shares) * N).astype(int))
    which = which[rng.permutation(N)]
    points = (CENTRES[which] + STD * rng.normal(size=(N, 2))).astype(np.float32)
    weights = rng.gamma(2.0, size=N).astype(np.float32)
    return points, weights, which


def _blob_stats(points, weights, which, k):
    member = which == k
    w = weights[member].astype(np.float64) / weights[member].sum()
    mean = w @ points[member]
    centred = points[member] - mean
    return weights[member].sum() / weights.sum(), mean, (w[:, None] * centred).T @ centred


def _check_blobs(modes: M.Modes, points, weights, which, *, reg: float, num_valid: int = 3):
    """Valid modes first by decreasing weight, each equal to one blob's share, mean and covariance."""
    assert modes.valid.tolist() == [True] * num_valid + [False] * (3 - num_valid)
    assert np.all(np.diff(modes.weight[:num_valid]) <= 0) and np.all(modes.weight[num_valid:] == 0)
    np.testing.assert_allclose(modes.weight.sum(), 1.0, rtol=1e-6)
    stats = [_blob_stats(points, weights, which, k) for k in range(3)]
    total = sum(stats[k][0] for k in range(num_valid))
    for i in range(num_valid):
        k = int(np.argmin(np.linalg.norm(CENTRES - modes.mean[i], axis=1)))
        share, mean, cov = stats[k]
        np.testing.assert_allclose(modes.weight[i], share / total, rtol=1e-4)
        np.testing.assert_allclose(modes.mean[i], mean, atol=1e-5)
        np.testing.assert_allclose(modes.cov[i], cov + reg * np.eye(2), rtol=1e-3, atol=1e-6)


def _expected_position_gradient(modes: M.Modes, xy, w, which):
    """d loss / d xy for hard clusters (one blob each), in closed form.

    With the labels fixed, mode j is its members' weighted mean and covariance (mass m, weight share
    ``s_j``); with ``(dx_i, dy_i) = p_i - mean_j``: ``d/dx_i = [j = 0] w_i/m + 2 w_i (dx_i + dy_i)/m``
    and ``d/dy_i = s_j w_i/m + 2 w_i (dx_i + dy_i)/m`` (the covariance's off-diagonal counts twice).
    """
    slot = np.array([np.argmin(np.linalg.norm(modes.mean - c, axis=1)) for c in CENTRES])[which]
    mass = np.bincount(slot, weights=w.astype(np.float64), minlength=3)[slot]
    common = 2.0 * w * (xy - modes.mean[slot]).sum(axis=1) / mass
    return np.stack([(slot == 0) * w / mass + common, modes.weight[slot] * w / mass + common], axis=1)


@pytest.mark.parametrize("name", list(PIECES))
def test_pieces_recover_separated_blobs(name, rng):
    piece = PIECES[name]
    data = [_blobs(rng) for _ in range(2)]
    # Batch element 1: a min_weight that the smallest blob (20 %) falls below.
    params = _params(piece, {}, {"min_weight": 0.25})
    modes, g_xy, g_w = _run(name, jax.random.key(0), [d[0] for d in data], [d[1] for d in data], params)
    assert modes.weight.shape == (2, 3) and modes.mean.shape == (2, 3, 2) and modes.cov.shape == (2, 3, 2, 2)
    assert modes.valid.shape == (2, 3) and piece.num_modes == 3
    reg = float(params.reg_covar[0]) if name == "gmm" else 0.0
    for i, num_valid in enumerate((3, 2)):
        _check_blobs(jax.tree.map(lambda x, i=i: x[i], modes), *data[i], reg=reg, num_valid=num_valid)
    assert np.all(np.isfinite(g_xy)) and np.all(np.isfinite(g_w))
    # The blobs are far apart: the mixture's responsibilities are exactly 0 or 1, its last M-step
    # is then a hard clustering's statistics, and all three share the closed-form gradient.
    xy, w, which = data[0]
    expected = _expected_position_gradient(jax.tree.map(lambda x: x[0], modes), xy, w, which)
    np.testing.assert_allclose(g_xy[0], expected, rtol=1e-3, atol=1e-5)


def test_mean_shift_finds_as_many_modes_as_there_are(rng):
    data = [_blobs(rng, shares=(1.0,)) for _ in range(2)]
    xy, w = [d[0] for d in data], [d[1] for d in data]
    shifted, _, _ = _run("mean_shift", jax.random.key(1), xy, w, _params(PIECES["mean_shift"], {}, {}))
    assert shifted.valid.tolist() == [[True, False, False]] * 2
    for i in range(2):
        np.testing.assert_allclose(shifted.mean[i, 0], np.average(xy[i], axis=0, weights=w[i]), atol=1e-6)
    # k-means always splits into num_modes clusters.
    split, _, _ = _run("kmeans", jax.random.key(1), xy, w, _params(PIECES["kmeans"], {}, {}))
    assert bool(np.all(split.valid))


@pytest.mark.parametrize("name", list(PIECES))
def test_zero_weights_count_as_uniform(name, rng):
    piece = PIECES[name]
    points, _, which = _blobs(rng)
    key = jax.random.key(2)
    weights = np.stack([np.zeros(N, np.float32), np.ones(N, np.float32)])
    modes, g_xy, g_w = _run(name, key, [points, points], weights, _params(piece, {}, {}))
    assert np.all(np.isfinite(g_xy)) and np.all(np.isfinite(g_w))
    for leaf in modes:
        assert np.all(np.isfinite(leaf))
        np.testing.assert_allclose(leaf[0], leaf[1])
    reg = float(piece.default_params().reg_covar) if name == "gmm" else 0.0
    _check_blobs(jax.tree.map(lambda x: x[0], modes), points, weights[1], which, reg=reg)


def test_no_modes_is_empty():
    piece = M.NoModes()
    out = jax.jit(piece.modes)(jax.random.key(0), jnp.zeros((N, 2)), jnp.ones(N), piece.default_params())
    assert piece.num_modes == 0
    assert out.weight.shape == (0,) and out.mean.shape == (0, 2) and out.cov.shape == (0, 2, 2)
    assert out.valid.shape == (0,) and out.valid.dtype == jnp.bool_
    assert P.leaf_names(piece.properties()) == []


@pytest.mark.parametrize(
    ("piece", "field"),
    [
        (M.KMeansModes(num_modes=0), "num_modes"),
        (M.KMeansModes(num_iters=-1), "num_iters"),
        (M.GaussianMixtureModes(num_modes=2.5), "num_modes"),
        (M.GaussianMixtureModes(kmeans_iters=-1), "kmeans_iters"),
        (M.GaussianMixtureModes(num_iters=0), "num_iters"),
        (M.MeanShiftModes(max_modes=0), "max_modes"),
        (M.MeanShiftModes(max_modes=40, num_seeds=32), "max_modes"),
        (M.MeanShiftModes(num_seeds=True), "num_seeds"),
        (M.MeanShiftModes(kernel="box"), "kernel"),
    ],
)
def test_validate_names_the_bad_field(piece, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        piece.validate()


@pytest.mark.parametrize("piece", [*PIECES.values(), M.NoModes()])
def test_default_params_are_valid_and_pieces_hash_by_value(piece):
    piece.validate()
    P.validate(piece.default_params(), piece.properties())
    copy = dataclasses.replace(piece)
    assert copy == piece and hash(copy) == hash(piece)


def test_properties_reject_bad_params():
    with pytest.raises(ValueError, match="^bandwidth:"):
        P.validate(M.MeanShiftParams(bandwidth=0.0), M.MeanShiftModes().properties())
    with pytest.raises(ValueError, match="^reg_covar:"):
        P.validate(M.GaussianMixtureParams(reg_covar=-1.0), M.GaussianMixtureModes().properties())
    with pytest.raises(ValueError, match="^min_weight:"):
        P.validate(M.KMeansParams(min_weight=1.5), M.KMeansModes().properties())
