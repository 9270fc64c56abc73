"""Cluster-wise resampling (Olufs et al. sec. 3.2) against NumPy references: largest-remainder counts,
exact offspring per cluster, systematic resampling within each cluster, the importance correction's
unbiasedness, and the piece in a filter step."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.numerics import order_by_weight
from heatpf_jax.resampling.clustered import ClusterParams, ClusterResampling, cluster_counts, resample_by_cluster

# The functions tested directly, one program each (shared by the tests): run eagerly, each of their operations
# would compile on its own. Their inputs are NumPy, as eager `jnp` conversions compile a program each too.
_cluster_counts = jax.jit(cluster_counts, static_argnums=2)
_ess_resample = jax.jit(hp.resampling.ESSResampling().resample)


@jax.jit
def _order(log_w):
    """The step's order by weight, of ``exp(log_w)``."""
    return order_by_weight(jnp.exp(log_w))


def _counts_reference(cw, valid, n, min_share):
    valid = valid & (cw > 0)
    m = max(int(valid.sum()), 1)
    s = min(min_share, 1.0 / m)
    share = np.where(valid, s + (1 - m * s) * np.where(valid, cw, 0) / cw[valid].sum(), 0.0)
    exact = share * n
    base = np.floor(exact).astype(int)
    frac = np.where(valid, exact - base, -1.0)
    extra = np.argsort(-frac, kind="stable")[: n - base.sum()]
    base[extra] += 1
    return base


@pytest.mark.parametrize("min_share", [0.0, 0.05, 0.3])
def test_counts_are_largest_remainder_with_a_floor(rng, min_share):
    for _ in range(5):
        cw = rng.dirichlet(np.ones(5) * 0.3)
        valid = np.array([True, True, True, False, True])
        cw = np.where(valid, cw, 0.0)
        cw = cw / cw.sum()
        got = np.asarray(_cluster_counts(np.asarray(cw, np.float32), valid, 200, min_share))
        assert got.sum() == 200 and np.all(got[~valid] == 0)
        np.testing.assert_array_equal(got, _counts_reference(cw.astype(np.float32), valid, 200, min_share))


@functools.partial(jax.jit, static_argnames="n")
def _by_cluster(key, log_w, labels, valid, min_share, n):
    del n
    order = order_by_weight(jnp.exp(log_w))
    return resample_by_cluster(key, hp.resampling.systematic, log_w, order, labels, valid, min_share)


def _two_clusters(rng, n=200, weak=0.02):
    labels = (np.arange(n) >= 150).astype(np.int32)  # cluster 1: 50 particles
    w = rng.uniform(0.1, 1.0, n)
    w[labels == 0] *= (1 - weak) / w[labels == 0].sum()
    w[labels == 1] *= weak / w[labels == 1].sum()
    return w, labels


@pytest.mark.parametrize("min_share", [0.0, 0.2])
def test_each_cluster_gets_its_count_and_is_resampled_systematically(rng, min_share):
    n = 200
    w, labels = _two_clusters(rng, n)
    valid = np.array([True, True, False])
    counts = _counts_reference(np.array([w[labels == 0].sum(), w[labels == 1].sum(), 0.0]), valid, n, min_share)
    for seed in range(5):
        anc, log_w, rank = (
            np.asarray(x)
            for x in _by_cluster(
                jax.random.key(seed),
                jnp.log(np.asarray(w, np.float32)),
                labels,
                valid,
                min_share,
                n,
            )
        )
        offspring = np.bincount(anc, minlength=n)
        for j in (0, 1):
            member = labels == j
            assert offspring[member].sum() == counts[j]
            # Systematic resampling of the cluster's own weights: floor or ceil of N_j p_i offspring.
            expected = counts[j] * w[member] / w[member].sum()
            assert np.all(offspring[member] >= np.floor(expected - 1e-4))
            assert np.all(offspring[member] <= np.ceil(expected + 1e-4))
        # The correction keeps each cluster's posterior mass.
        new_w = np.exp(log_w)
        assert new_w.sum() == pytest.approx(1.0, abs=1e-5)
        assert new_w[labels[anc] == 1].sum() == pytest.approx(w[labels == 1].sum(), rel=1e-4)
        assert sorted(rank.tolist()) == list(range(n))


def test_weighted_estimate_stays_unbiased_with_a_floor(rng):
    """E[sum_i w'_i f(x_{a_i})] = sum_i w_i f(x_i) over random keys (the min share is a proposal choice)."""
    n = 200
    w, labels = _two_clusters(rng, n, weak=0.01)
    f = rng.normal(size=n)
    keys = jax.random.split(jax.random.key(3), 400)
    log_w = jnp.log(np.asarray(w, np.float32))
    run = jax.vmap(lambda k: _by_cluster(k, log_w, jnp.asarray(labels), jnp.asarray([True, True, False]), 0.25, n))
    anc, new_log_w, _ = run(keys)
    est = np.sum(np.exp(np.asarray(new_log_w)) * f[np.asarray(anc)], axis=1)
    exact = float(np.sum(w * f))
    assert abs(est.mean() - exact) < 4 * est.std() / np.sqrt(len(est)) + 1e-4, (est.mean(), exact)


_cluster_resample = jax.jit(ClusterResampling().resample)  # one compilation for the tests below


def test_one_cluster_is_plain_resampling(rng):
    n = 128
    log_w = np.asarray(np.log(rng.dirichlet(np.ones(n))), np.float32)
    xy = np.asarray(rng.normal(scale=0.05, size=(n, 2)), np.float32)  # one blob, far below the bandwidth
    order = _order(log_w)
    key = jax.random.key(7)
    plain = _ess_resample(key, xy, log_w, order, hp.resampling.ESSParams(1.0))
    ours = _cluster_resample(key, xy, log_w, order, ClusterParams(bandwidth=0.5))
    np.testing.assert_array_equal(np.asarray(ours.ancestors), np.asarray(plain.ancestors))
    np.testing.assert_allclose(np.asarray(ours.log_weights), np.asarray(plain.log_weights), atol=1e-5)


def test_a_weak_second_object_survives_cluster_wise_resampling(rng):
    """Two blobs 2 m apart, the second with 3 % of the weight: with a 15 % floor it keeps >= 15 % of the
    particles; plain resampling leaves it about 3 %."""
    n = 128
    xy = np.concatenate([rng.normal([1.0, 0.0], 0.05, (64, 2)), rng.normal([1.0, 2.0], 0.05, (64, 2))])
    w = np.where(np.arange(n) < 64, 0.97 / 64, 0.03 / 64)
    log_w = np.asarray(np.log(w), np.float32)
    order = _order(log_w)
    res = _cluster_resample(
        jax.random.key(0), np.asarray(xy, np.float32), log_w, order, ClusterParams(bandwidth=0.3, min_share=0.15)
    )
    second = np.asarray(res.ancestors) >= 64
    assert second.sum() >= 0.15 * n
    assert np.exp(np.asarray(res.log_weights))[second].sum() == pytest.approx(0.03, rel=1e-3)
    # Not resampled below the ESS threshold: every particle stays in its slot.
    kept = _cluster_resample(
        jax.random.key(0), np.asarray(xy, np.float32), log_w, order, ClusterParams(resample_threshold=0.0)
    )
    np.testing.assert_array_equal(np.asarray(kept.ancestors), np.arange(n))


def test_validate_and_properties():
    with pytest.raises(ValueError, match="max_clusters"):
        ClusterResampling(max_clusters=0).validate()
    with pytest.raises(ValueError, match="resampler"):
        ClusterResampling(resampler=None).validate()
    props = ClusterResampling().properties()
    assert not props.bandwidth.trainable and props.min_share.high == 1.0
