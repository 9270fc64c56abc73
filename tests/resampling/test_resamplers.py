"""Statistical tests of the resamplers and the effective sample size.

References are independent of the implementation: the expected number of copies
of particle i is ``m * w_i`` for every unbiased resampler, with the binomial
variance ``m w_i (1 - w_i)`` as an upper bound on the per-index variance (exact
for multinomial); systematic resampling gives ``floor`` or ``ceil`` of ``m w_i``
copies, stratified within one of those, residual at least ``floor(m w_i)``.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import heatpf_jax as hp

NAMES = ("systematic", "stratified", "multinomial", "residual")
NUM_KEYS = 2000


@functools.partial(jax.jit, static_argnames=("name", "num_samples"))
def _draw_jit(keys, weights, name: str, num_samples: int):
    return jax.vmap(lambda k: hp.resampling.RESAMPLERS[name](k, weights, num_samples))(keys)


def _draw(name: str, weights: np.ndarray, num_samples: int, seed: int = 0) -> np.ndarray:
    """``[NUM_KEYS, num_samples]`` indices from independent keys (one compilation per name and shape)."""
    keys = jax.random.split(jax.random.key(seed), NUM_KEYS)
    # NumPy weights: an eager `jnp` conversion would compile a program per shape.
    return np.asarray(_draw_jit(keys, np.asarray(weights, np.float32), name=name, num_samples=num_samples))


def _counts(indices: np.ndarray, n: int) -> np.ndarray:
    """``[K, n]`` copies of each index per draw (NumPy bincount)."""
    return np.stack([np.bincount(row, minlength=n) for row in indices])


def _assert_unbiased(counts: np.ndarray, m: int, weights: np.ndarray) -> None:
    """Total copies over the keys lie in the central 1 - 2e-7 interval of Binomial(K m, p_i).

    That is the exact law for multinomial resampling and wider than the law of the
    lower-variance schemes; it stays valid for rare indices where a normal approximation fails.
    """
    p = weights.astype(np.float64) / weights.sum(dtype=np.float64)
    trials = counts.shape[0] * m
    total = counts.sum(0)
    low = stats.binom.ppf(1e-7, trials, p)
    high = stats.binom.isf(1e-7, trials, p)
    bad = np.flatnonzero((total < low) | (total > high))
    assert bad.size == 0, f"indices {bad.tolist()}: totals {total[bad]} outside [{low[bad]}, {high[bad]}]"


def _dirichlet_away_from_integers(rng: np.random.Generator, n: int, m: int) -> np.ndarray:
    """Random normalised float32 weights whose ``m w_i`` are not within 1e-3 of an integer.

    (Keeps float32 rounding out of the floor/ceil bounds.)
    """
    for _ in range(100):
        w = rng.dirichlet(np.full(n, 0.7)).astype(np.float32)
        w = w / w.sum(dtype=np.float64)
        mw = m * w.astype(np.float64)
        if np.min(np.abs(mw - np.round(mw))) > 1e-3:
            return w.astype(np.float32)
    raise AssertionError("could not draw weights away from integers")


# The functions tested directly, one program each: run eagerly, each of their operations would compile on its own.
_systematic = jax.jit(hp.resampling.systematic, static_argnums=2)
_ess = jax.jit(hp.resampling.effective_sample_size)
_ess_trigger = jax.jit(hp.resampling.ess_trigger)


@functools.partial(jax.jit, static_argnums=0)
def _resample_piece(piece, key, w, resample_threshold):
    """``(log w, piece.resample(...))`` with the step's order of ``w`` by weight (through ``exp(log w)``): one
    program for both thresholds."""
    from heatpf_jax.numerics import order_by_weight

    log_w = jnp.log(w)
    order = order_by_weight(jnp.exp(log_w))
    return log_w, piece.resample(key, jnp.zeros((log_w.shape[0], 2)), log_w, order,
                                 hp.resampling.ESSParams(resample_threshold))


# Two shapes shared by every statistical test (each name and shape compiles once):
# more samples than weights, and fewer.
SHAPES = [(12, 50), (40, 17)]


def test_registry_names_the_four_resamplers():
    assert set(hp.resampling.RESAMPLERS) == set(NAMES)
    assert hp.resampling.RESAMPLERS["systematic"] is hp.resampling.systematic
    assert hp.resampling.RESAMPLERS["stratified"] is hp.resampling.stratified
    assert hp.resampling.RESAMPLERS["multinomial"] is hp.resampling.multinomial
    assert hp.resampling.RESAMPLERS["residual"] is hp.resampling.residual


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("n, m", SHAPES)
def test_mean_counts_are_unbiased(name, n, m, rng):
    """Mean number of copies over many keys equals m * w_i within 5 binomial standard errors (m != n)."""
    w = _dirichlet_away_from_integers(rng, n, m)
    idx = _draw(name, w, m)
    assert idx.shape == (NUM_KEYS, m)
    assert idx.dtype == np.int32
    assert idx.min() >= 0 and idx.max() < n
    _assert_unbiased(_counts(idx, n), m, w)


def test_multinomial_matches_categorical_distribution(rng):
    """Pooled multinomial draws pass a chi-square test; per-index variance and covariance are multinomial."""
    n, m = SHAPES[0]
    w = _dirichlet_away_from_integers(rng, n, m).astype(np.float64)
    counts = _counts(_draw("multinomial", w, m, seed=3), n)
    pooled = counts.sum(0)
    expected = pooled.sum() * w / w.sum()
    assert stats.chisquare(pooled, expected).pvalue > 1e-4
    var_ref = m * w * (1 - w)
    big = var_ref > 1.0
    assert big.sum() >= 3
    np.testing.assert_allclose(counts.var(0)[big], var_ref[big], rtol=0.2)
    # Counts of different indices are negatively correlated: cov = -m w_i w_j.
    cov = np.cov(counts.T)
    i, j = np.argsort(w)[-2:]
    np.testing.assert_allclose(cov[i, j], -m * w[i] * w[j], rtol=0.3)


@pytest.mark.parametrize("n, m", SHAPES)
def test_systematic_counts_are_floor_or_ceil(n, m, rng):
    w = _dirichlet_away_from_integers(rng, n, m)
    counts = _counts(_draw("systematic", w, m), n)
    mw = m * w.astype(np.float64)
    assert np.all(counts >= np.floor(mw)) and np.all(counts <= np.ceil(mw))
    assert np.all(counts.sum(1) == m)


@pytest.mark.parametrize("n, m", SHAPES)
def test_stratified_counts_within_one_of_floor_ceil(n, m, rng):
    """An interval of length L = m w_i holds floor(L) - 1 .. ceil(L) + 1 of the m stratified points."""
    w = _dirichlet_away_from_integers(rng, n, m)
    counts = _counts(_draw("stratified", w, m), n)
    mw = m * w.astype(np.float64)
    assert np.all(counts >= np.floor(mw) - 1) and np.all(counts <= np.ceil(mw) + 1)
    # Stratified is less regular than systematic: some count leaves {floor, ceil}.
    assert np.any((counts < np.floor(mw)) | (counts > np.ceil(mw)))


@pytest.mark.parametrize("n, m", SHAPES)
def test_residual_keeps_the_deterministic_copies(n, m, rng):
    """Residual: at least floor(m w_i) copies; the excess is Multinomial(m - sum floor, residuals)."""
    w = _dirichlet_away_from_integers(rng, n, m)
    counts = _counts(_draw("residual", w, m, seed=1), n)
    mw = m * w.astype(np.float64)
    floor = np.floor(mw)
    assert np.all(counts >= floor)
    n_rest = m - floor.sum()
    r = (mw - floor) / (mw - floor).sum()
    var_ref = n_rest * r * (1 - r)
    big = var_ref > 0.3
    assert big.sum() >= 3
    np.testing.assert_allclose(counts.var(0)[big], var_ref[big], rtol=0.2)


@pytest.mark.parametrize("name", NAMES)
def test_boundary_weights_stay_in_range(name):
    """float32 edge cases: huge dynamic range, single survivor at either end, cumsum not ending at 1."""
    (n1, m1), (n2, m2) = SHAPES
    # Huge dynamic range 1e-30 .. 1: the mass sits in the last few indices.
    w = np.logspace(-30, 0, n2).astype(np.float32)
    idx = _draw(name, w, m2)
    assert idx.min() >= 0 and idx.max() < n2
    _assert_unbiased(_counts(idx, n2), m2, w)
    # One survivor at the last index, or at the first with a denormal-free tiny weight.
    last = np.zeros(n1, np.float32)
    last[-1] = 1.0
    assert np.all(_draw(name, last, m1) == n1 - 1)
    first = np.zeros(n2, np.float32)
    first[0] = 1e-30
    assert np.all(_draw(name, first, m2) == 0)
    # Normalised weights whose float32 total is below 1 (12 x float32(1/12) = 0.99999994).
    third = np.full(n1, 1.0 / n1, np.float32)
    assert np.sum(third, dtype=np.float32) < 1.0
    idx = _draw(name, third, m1)
    assert idx.min() >= 0 and idx.max() < n1
    _assert_unbiased(_counts(idx, n1), m1, third)


@pytest.mark.parametrize("name", NAMES)
def test_many_tiny_weights(name):
    """10007 weights of 1e-4 (float32 cumulative sum ends at about 1.0007, not 1): indices uniform and in range."""
    n_tiny = 10007
    tiny = np.full(n_tiny, 1e-4, np.float32)
    assert np.cumsum(tiny, dtype=np.float32)[-1] != 1.0
    idx = _draw(name, tiny, 64)
    assert idx.min() >= 0 and idx.max() < n_tiny
    # Mean index (n - 1) / 2 within 5 standard errors (iid bound, conservative for the others).
    se = np.sqrt((n_tiny**2 - 1) / 12 / idx.size)
    assert abs(idx.mean() - (n_tiny - 1) / 2) < 5 * se
    # Every decile of the index range receives its share.
    hist = np.histogram(idx, bins=10, range=(0, n_tiny))[0] / idx.size
    np.testing.assert_allclose(hist, 0.1, atol=0.01)


@pytest.mark.parametrize("name", NAMES)
def test_zero_weights_are_never_selected_small(name):
    """Zero-weight particles (between and after positive ones) are never chosen (small n)."""
    n, m = SHAPES[0]
    w = np.zeros(n, np.float32)
    w[[1, 4, 5, 8]] = [0.3, 0.5, 0.15, 0.05]
    idx = _draw(name, w, m)
    assert np.all(w[idx] > 0)


# --- Regression: float32 rounding must never select a zero-weight particle. ------------------------------------------


def test_systematic_never_selects_trailing_zero_weight():
    w = np.ones(1000, np.float32)
    w[-1] = 0.0
    # jax.random.key(3593) draws the offset u = 1 - 2**-24 (on jax 0.10 CPU); (999 + u) / 1000 == 1.0 in float32.
    idx = np.asarray(_systematic(jax.random.key(3593), w, 1000))
    assert np.all(w[idx] > 0), f"zero-weight index selected: {sorted(set(idx[w[idx] == 0].tolist()))}"


@pytest.mark.parametrize("name", sorted(hp.resampling.RESAMPLERS))
def test_zero_weights_never_selected_over_many_keys(name):
    # Interior zeros in a long vector: XLA's blocked float32 cumsum is not exactly monotone there,
    # and trailing zeros: a position can round to 1.0. Neither may ever pick a zero-weight particle.
    n = 1708
    gen = np.random.default_rng(0)
    w = (gen.random(n) ** 6).astype(np.float32)
    w[gen.random(n) < 0.5] = 0.0
    w[-3:] = 0.0
    keys = jax.random.split(jax.random.key(83), 1500)
    draw = jax.jit(jax.vmap(lambda key: hp.resampling.RESAMPLERS[name](key, jnp.asarray(w), n)))
    idx = np.asarray(draw(keys))
    assert np.all(w[idx] > 0), f"{name}: zero-weight index selected"


@pytest.mark.parametrize("name", sorted(hp.resampling.RESAMPLERS))
def test_indices_are_non_decreasing(name):
    """The contract the filter's explorer selection relies on: copies of a particle are contiguous.

    Checked on the statistical tests' draws, on float32 edge cases and on the long vector with
    interior zeros where XLA's cumsum is not exactly monotone.
    """
    rng = np.random.default_rng(11)
    cases = [(_dirichlet_away_from_integers(rng, n, m), m) for n, m in SHAPES]
    cases.append((np.logspace(-30, 0, SHAPES[1][0]).astype(np.float32), SHAPES[1][1]))
    for w, m in cases:
        idx = _draw(name, w, m)
        assert np.all(np.diff(idx, axis=1) >= 0)
    n = 1708
    gen = np.random.default_rng(0)
    w = (gen.random(n) ** 6).astype(np.float32)
    w[gen.random(n) < 0.5] = 0.0
    keys = jax.random.split(jax.random.key(84), 300)
    idx = np.asarray(jax.jit(jax.vmap(lambda key: hp.resampling.RESAMPLERS[name](key, jnp.asarray(w), n)))(keys))
    assert np.all(np.diff(idx, axis=1) >= 0) and np.all(w[idx] > 0)


# --- Effective sample size. -----------------------------------------------------------------------------------------


def test_ess_uniform_and_one_hot():
    # NumPy weights here and below: eager `jnp` and `.at[].set()` compile a program each.
    for n in (1, 7, 500):
        assert float(_ess(np.full((n,), 1.0 / n, np.float32))) == pytest.approx(n, rel=1e-5)
        # Unnormalised uniform weights give the same.
        assert float(_ess(np.full((n,), 3.5, np.float32))) == pytest.approx(n, rel=1e-5)
    one_hot = np.zeros((64,), np.float32)
    one_hot[17] = 0.25
    assert float(_ess(one_hot)) == pytest.approx(1.0, rel=1e-6)


def test_ess_matches_numpy(rng):
    w = rng.gamma(0.3, size=200)
    ref = w.sum() ** 2 / np.sum(w**2)
    got = float(_ess(np.asarray(w, np.float32)))
    assert got == pytest.approx(ref, rel=1e-5)
    # Two equal survivors: ESS = 2.
    two = np.zeros((10,), np.float32)
    two[[2, 8]] = 1.0
    assert float(_ess(two)) == pytest.approx(2.0, rel=1e-6)


def test_ess_resampling_piece_ancestors_and_ranks(rng):
    """Resampled: ancestors follow the weights and slot i has rank i; not resampled: identity and weight ranks."""
    import math

    n = 64
    w = rng.random(n).astype(np.float32) ** 4
    w /= w.sum()
    piece = hp.resampling.ESSResampling(resampler=hp.resampling.systematic)
    ess = 1.0 / np.sum(w.astype(np.float64) ** 2)
    log_w, res = _resample_piece(piece, jax.random.key(0), w, 1.0)
    assert bool(res.resampled) and float(res.ess) == pytest.approx(ess, rel=1e-4)
    np.testing.assert_array_equal(np.asarray(res.rank), np.arange(n))
    counts = np.bincount(np.asarray(res.ancestors), minlength=n)
    assert np.all(np.abs(counts - n * w) < 1.0 + 1e-4)  # systematic: floor or ceil of n w
    # Copies of one particle are contiguous, and support decreases with the slot.
    anc = np.asarray(res.ancestors)
    assert np.all(np.diff(w[anc]) <= 1e-7)
    np.testing.assert_allclose(np.asarray(res.log_weights), -math.log(n), rtol=1e-6)
    kept = _resample_piece(piece, jax.random.key(0), w, 0.0)[1]
    assert not bool(kept.resampled)
    np.testing.assert_array_equal(np.asarray(kept.ancestors), np.arange(n))
    np.testing.assert_array_equal(np.asarray(kept.rank), np.argsort(np.argsort(-w, kind="stable"), kind="stable"))
    np.testing.assert_array_equal(np.asarray(kept.log_weights), np.asarray(log_w))


def test_ess_trigger_against_numpy():
    """``ess_trigger``: the effective sample size 1 / sum(w^2) and whether it is below threshold * N."""
    rng = np.random.default_rng(3)
    w = rng.gamma(0.3, size=50)
    w /= w.sum()
    ess, below = _ess_trigger(np.asarray(w, np.float32), 0.5)
    np.testing.assert_allclose(float(ess), 1.0 / np.sum(w**2), rtol=1e-5)
    assert bool(below) == (1.0 / np.sum(w**2) < 25.0)
    assert not bool(_ess_trigger(np.full(8, 1 / 8, np.float32), 0.99)[1])
