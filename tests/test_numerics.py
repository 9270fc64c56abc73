"""Numerical helpers (heatpf_jax.numerics) against NumPy."""

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.numerics import order_by_weight


def test_order_by_weight_is_a_stable_descending_argsort_up_to_near_ties():
    """The step's packed-key sort against NumPy: exact for weights apart by more than its resolution."""
    rng = np.random.default_rng(21)
    order = jax.jit(order_by_weight)
    for n in (1, 2, 97, 500, 1000):
        # Distinct weights 1 % apart (far above the key's resolution) in random order, zeros and exact ties.
        w = (1.01 ** -rng.permutation(n).astype(np.float64)).astype(np.float32)
        w[rng.random(n) < 0.2] = 0.0
        w[: n // 10] = w[n // 10]
        w = w / max(w.sum(), 1e-30)
        got = np.asarray(order(jnp.asarray(w)))
        assert sorted(got.tolist()) == list(range(n))
        np.testing.assert_array_equal(got, np.argsort(-w, kind="stable"))
        # Always: weights are non-increasing up to the key's resolution, zeros last in index order.
        sw = w[got]
        assert np.all(sw[1:] <= sw[:-1] * (1 + 2.0 ** (max(1, (n - 1).bit_length()) - 22)))
        zeros = got[sw == 0]
        np.testing.assert_array_equal(zeros, np.sort(zeros))
    # Weights closer than the resolution (here 2**-15 apart at n = 500) may come in index order instead.
    w = np.float32(0.5) * (1 + np.float32(2.0**-20) * np.arange(500, dtype=np.float32))
    got = np.asarray(order(jnp.asarray(w)))
    assert sorted(got.tolist()) == list(range(500))
    np.testing.assert_allclose(w[got], np.sort(w)[::-1], rtol=2.0**-13)
    # Beyond 2**16 particles the order is the exact stable argsort.
    w = jnp.asarray(rng.random(70000), jnp.float32)
    np.testing.assert_array_equal(np.asarray(order(w)), np.argsort(-np.asarray(w), kind="stable"))
