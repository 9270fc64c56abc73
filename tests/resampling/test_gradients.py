"""Gradient estimators through resampling: the wrappers keep the wrapped strategy's values exactly, and their
Jacobians (new log weights w.r.t. the old ones, at a fixed key) are the ancestors' one-hot matrix (stop
gradient), zero (detach) or the identity (no resampling); soft resampling's weighted draw is unbiased
(Monte Carlo over keys against the exact weighted mean) and its Jacobian is that of ``normalise(lw[a])``."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.numerics import order_by_weight
from heatpf_jax.resampling.gradients import DetachResampling, SoftResampling, StopGradientResampling

N = 16
NUM_KEYS = 2000

STRATEGIES = {
    "ess": (hp.resampling.ESSResampling(), hp.resampling.ESSParams(resample_threshold=1.0)),
    # min_share > 0 with the importance correction: non-uniform weights after resampling.
    "cluster": (hp.resampling.ClusterResampling(num_seeds=N, max_clusters=3, num_iters=5),
                hp.resampling.ClusterParams(bandwidth=0.3, min_share=0.2, resample_threshold=1.0)),
}


def _case(rng: np.random.Generator):
    """Two clouds of particles (a heavy and a light one) with random normalised log weights."""
    xy = np.concatenate([rng.normal(0.0, 0.1, (N - 5, 2)), rng.normal(2.0, 0.1, (5, 2))]).astype(np.float32)
    w = rng.uniform(0.2, 1.0, N) * np.where(np.arange(N) < N - 5, 1.0, 0.1)
    lw = np.log(w / w.sum()).astype(np.float32)
    return jnp.asarray(xy), jnp.asarray(lw)


def _no_resampling(params):
    return params._replace(resample_threshold=jnp.float32(0.0))  # ESS < 0 never holds


@functools.partial(jax.jit, static_argnames=("strategies", "jacobians"))
def _resample(strategies, key, xy, lw, params, jacobians=None):
    """Each strategy's :class:`Resampled` and, where ``jacobians`` asks, the Jacobian of its new log weights
    w.r.t. ``lw`` at the fixed key (else ``None``): one program for all, each strategy traced once."""
    order = order_by_weight(jnp.exp(lw))
    out = []
    for strategy, jacobian in zip(strategies, jacobians or (False,) * len(strategies), strict=True):
        def new_log_weights(x, s=strategy):
            res = s.resample(key, xy, x, order, params)
            return res.log_weights, res

        if jacobian:
            jac, res = jax.jacfwd(new_log_weights, has_aux=True)(lw)
        else:
            jac, res = None, new_log_weights(lw)[1]
        out.append((res, jac))
    return out


def _arrays(params):
    return jax.tree.map(lambda v: jnp.asarray(v, jnp.float32), params)


@pytest.mark.parametrize("resample", [True, False], ids=["resampled", "kept"])
@pytest.mark.parametrize("name", sorted(STRATEGIES))
def test_wrappers_keep_the_strategy_values_and_route_gradients(rng, name, resample):
    base, params = STRATEGIES[name]
    params = _arrays(params if resample else _no_resampling(params))
    xy, lw = _case(rng)
    key = jax.random.key(3)
    wrappers = (StopGradientResampling(base), DetachResampling(base))
    (want, _), *wrapped = _resample((base, *wrappers), key, xy, lw, params, jacobians=(False, True, True))
    assert bool(want.resampled) == resample
    if resample and name == "cluster":
        assert np.ptp(np.asarray(want.log_weights)) > 0.1  # the correction: not uniform
    eye = np.eye(N, dtype=np.float32)
    one_hot = eye[np.asarray(want.ancestors)]
    for wrapper, (got, jac) in zip(wrappers, wrapped, strict=True):
        wrapper.validate()
        assert wrapper.default_params() == base.default_params()
        assert wrapper.properties() == base.properties()
        for field in want._fields:
            np.testing.assert_array_equal(np.asarray(getattr(got, field)), np.asarray(getattr(want, field)),
                                          err_msg=f"{type(wrapper).__name__}.{field}")
        jac = np.asarray(jac)
        if not resample:
            expected = eye  # every particle keeps its own weight and gradient
        elif isinstance(wrapper, StopGradientResampling):
            expected = one_hot  # d new_i / d lw_j = [a_i == j]
        else:
            expected = np.zeros((N, N), np.float32)
        np.testing.assert_array_equal(jac, expected, err_msg=type(wrapper).__name__)


def test_soft_with_alpha_one_is_plain_systematic(rng):
    xy, lw = _case(rng)
    params = _arrays(hp.resampling.ESSParams(1.0))
    for seed in range(3):
        key = jax.random.key(seed)
        (plain, _), (soft, _) = _resample(
            (hp.resampling.ESSResampling(hp.resampling.systematic),
             SoftResampling(hp.resampling.systematic, alpha=1.0)),
            key, xy, lw, params,
        )
        assert bool(soft.resampled)
        np.testing.assert_array_equal(np.asarray(soft.ancestors), np.asarray(plain.ancestors))
        np.testing.assert_array_equal(np.asarray(soft.rank), np.asarray(plain.rank))
        np.testing.assert_allclose(np.asarray(soft.log_weights), np.full(N, -np.log(N)), atol=1e-5)


@pytest.mark.parametrize("resample", [True, False], ids=["resampled", "kept"])
def test_soft_ranks_and_jacobian(rng, resample):
    xy, lw = _case(rng)
    params = _arrays(hp.resampling.ESSParams(1.0) if resample else _no_resampling(hp.resampling.ESSParams(1.0)))
    key = jax.random.key(9)
    soft = SoftResampling(alpha=0.5)
    soft.validate()
    (got, jac), (plain, _) = _resample((soft, hp.resampling.ESSResampling()), key, xy, lw, params,
                                       jacobians=(True, False))
    assert bool(got.resampled) == resample
    np.testing.assert_allclose(float(jax.nn.logsumexp(got.log_weights)), 0.0, atol=1e-5)
    jac = np.asarray(jac)
    if not resample:
        np.testing.assert_array_equal(np.asarray(got.ancestors), np.arange(N))
        np.testing.assert_array_equal(np.asarray(got.log_weights), np.asarray(lw))
        np.testing.assert_array_equal(np.asarray(got.rank), np.asarray(plain.rank))
        np.testing.assert_array_equal(jac, np.eye(N, dtype=np.float32))
        return
    # Slot i has support rank i: the ancestors run through the particles by decreasing weight.
    np.testing.assert_array_equal(np.asarray(got.rank), np.arange(N))
    position = np.argsort(np.asarray(order_by_weight(jnp.exp(lw))))
    assert np.all(np.diff(position[np.asarray(got.ancestors)]) >= 0)
    # Non-uniform weights w[a] / q[a] (the forward pass changes), and NumPy's reference of them.
    w = np.exp(np.asarray(lw, np.float64))
    a = np.asarray(got.ancestors)
    ratio = w[a] / (0.5 * w[a] + 0.5 / N)
    np.testing.assert_allclose(np.exp(np.asarray(got.log_weights, np.float64)), ratio / ratio.sum(), rtol=1e-5)
    assert np.ptp(ratio) > 0.1
    # Gradient of normalise(lw[a] - log q[a]) with q held fixed: (I - 1 w_new^T) onehot(a).
    new = ratio / ratio.sum()
    expected = (np.eye(N) - new[None, :]) @ np.eye(N)[a]
    np.testing.assert_allclose(jac, expected, atol=1e-5)


def test_soft_weighted_draw_is_unbiased(rng):
    xy, lw = _case(rng)
    params = _arrays(hp.resampling.ESSParams(1.0))
    h = np.asarray(xy[:, 0], np.float64) + np.asarray(xy[:, 1], np.float64) ** 2
    soft = SoftResampling(alpha=0.5)

    @jax.jit
    def estimates(keys):
        def one(k):
            out = soft.resample(k, xy, lw, order_by_weight(jnp.exp(lw)), params)
            return jnp.sum(jnp.exp(out.log_weights) * jnp.asarray(h, jnp.float32)[out.ancestors])

        return jax.vmap(one)(keys)

    est = np.asarray(estimates(jax.random.split(jax.random.key(0), NUM_KEYS)), np.float64)
    target = float(np.sum(np.exp(np.asarray(lw, np.float64)) * h))
    se = est.std(ddof=1) / np.sqrt(NUM_KEYS)
    assert se > 0  # the draw varies with the key
    assert abs(est.mean() - target) < 4 * se, (est.mean(), target, se)


def test_soft_validates_alpha():
    for alpha in (-0.1, 1.5, "half"):
        with pytest.raises(ValueError, match=r"^alpha:"):
            SoftResampling(alpha=alpha).validate()


def test_stop_gradient_of_a_zero_weight_is_no_nan():
    """A particle of weight zero (log -inf) kept in its slot (no resampling) inherits neither NaN nor gradient."""
    strategy = StopGradientResampling(hp.resampling.ESSResampling())
    params = hp.resampling.ESSParams(resample_threshold=0.0)  # never resample: every slot keeps its own weight
    base = jnp.array([0.0, -1.0, -jnp.inf, -2.0], jnp.float32)

    def total(shift):
        lw = base + shift * jnp.arange(4.0, dtype=jnp.float32)
        lw = lw - jax.nn.logsumexp(lw)
        res = strategy.resample(jax.random.key(0), jnp.zeros((4, 2)), lw, order_by_weight(jnp.exp(lw)), params)
        return res.log_weights, jnp.sum(jnp.exp(res.log_weights) * jnp.arange(4.0, dtype=jnp.float32))

    values = jax.jit(jax.vmap(total))
    new, sums = values(jnp.array([0.1, 0.1 + 1e-3, 0.1 - 1e-3], jnp.float32))
    assert not np.any(np.isnan(np.asarray(new))) and np.asarray(new)[0, 2] == -np.inf
    grad = jax.jit(jax.grad(lambda s: total(s)[1]))(jnp.float32(0.1))
    # Against a central difference of the same (smooth, resampling-free) function.
    fd = (float(sums[1]) - float(sums[2])) / (2 * 1e-3)
    assert np.isfinite(float(grad)) and float(grad) == pytest.approx(fd, rel=1e-2)
