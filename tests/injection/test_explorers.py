"""Explorer selection and spawn distributions.

References: NumPy stable argsort for the lowest-support particles; the moments
and CDFs of the uniform and normal distributions (scipy.stats KS tests).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import stats

import heatpf_jax as hp

# Through `jit` (traced arguments, or static where Python-valued): run eagerly, each operation compiles on its own.
_explorer_mask = jax.jit(hp.injection.explorer_mask)
_explorer_slots = jax.jit(hp.injection.explorer_slots, static_argnums=0)
_spawn_uniform = jax.jit(hp.injection.spawn_uniform, static_argnums=(1, 2))
_take_slots = jax.jit(hp.injection.take_slots)
# `explorer_mask` with a Python-float (concrete) fraction stays eager: static under `jit`, every fraction would
# compile a program (about 0.09 s), more than its few eager operations cost once per particle count.


def _reference_mask(support: np.ndarray, fraction: float) -> np.ndarray:
    n = support.shape[0]
    count = int(np.round(fraction * n))
    mask = np.zeros(n, bool)
    mask[np.argsort(support, kind="stable")[:count]] = True
    return mask


# fraction * n is never within 0.05 of a .5 tie, so float32 and float64 rounding agree.
@pytest.mark.parametrize("n", [128, 97])
@pytest.mark.parametrize("fraction", [0.0, 0.05, 0.1, 0.37, 0.9, 1.0])
def test_explorer_mask_marks_lowest_support(n, fraction, rng):
    support = rng.gamma(0.5, size=n).astype(np.float32)
    mask = np.asarray(hp.injection.explorer_mask(jnp.asarray(support), fraction))
    assert mask.dtype == bool and mask.shape == (n,)
    assert mask.sum() == round(fraction * n)
    np.testing.assert_array_equal(mask, _reference_mask(support, fraction))
    if 0 < mask.sum() < n:
        assert support[mask].max() <= support[~mask].min()


def test_explorer_mask_ties_by_index_and_traced_fraction(rng):
    support = np.repeat(np.float32([0.5, 0.1, 0.5, 0.1]), 16)  # many ties
    for fraction in (0.2, 0.5, 0.7):
        got = np.asarray(_explorer_mask(support, np.float32(fraction)))
        np.testing.assert_array_equal(got, _reference_mask(support, fraction))
        np.testing.assert_array_equal(got, np.asarray(hp.injection.explorer_mask(jnp.asarray(support), fraction)))
    # Traced fraction under vmap equals the NumPy reference for each fraction.
    fractions = np.array([0.0, 0.05, 0.5], np.float32)
    support = rng.random(128).astype(np.float32)
    batch = np.asarray(jax.jit(jax.vmap(hp.injection.explorer_mask, in_axes=(None, 0)))(support, fractions))
    for i, fraction in enumerate((0.0, 0.05, 0.5)):
        np.testing.assert_array_equal(batch[i], _reference_mask(support, fraction))


def test_spawn_uniform_inside_box_with_uniform_moments():
    box = (-1.0, 3.0, 2.0, 2.5)
    n = 20000
    pts = np.asarray(_spawn_uniform(jax.random.key(0), n, box), np.float64)
    assert pts.shape == (n, 2)
    assert np.all(pts[:, 0] >= box[0]) and np.all(pts[:, 0] < box[1])
    assert np.all(pts[:, 1] >= box[2]) and np.all(pts[:, 1] < box[3])
    for axis, (lo, hi) in enumerate([(box[0], box[1]), (box[2], box[3])]):
        width = hi - lo
        # Mean (lo + hi) / 2 with standard error width / sqrt(12 n).
        assert abs(pts[:, axis].mean() - (lo + hi) / 2) < 5 * width / np.sqrt(12 * n)
        # Variance width^2 / 12; the sample variance of a uniform has relative SE sqrt(0.8 / n).
        np.testing.assert_allclose(pts[:, axis].var(), width**2 / 12, rtol=5 * np.sqrt(0.8 / n))
        assert stats.kstest(pts[:, axis], stats.uniform(lo, width).cdf).pvalue > 1e-4
    assert abs(np.corrcoef(pts.T)[0, 1]) < 5 / np.sqrt(n)
    # Keys matter.
    other = np.asarray(_spawn_uniform(jax.random.key(1), n, box))
    assert not np.allclose(other, pts)


def test_spawn_gaussian_moments():
    n = 20000
    mean = np.array([1.5, -0.5])
    std = 0.3
    pts = np.asarray(hp.injection.spawn_gaussian(jax.random.key(2), n, jnp.asarray(mean, jnp.float32), std), np.float64)
    assert pts.shape == (n, 2)
    np.testing.assert_array_less(np.abs(pts.mean(0) - mean), 5 * std / np.sqrt(n))
    # Sample variance of a normal: relative SE sqrt(2 / n).
    np.testing.assert_allclose(pts.var(0), std**2, rtol=5 * np.sqrt(2 / n))
    assert abs(np.corrcoef(pts.T)[0, 1]) < 5 / np.sqrt(n)
    for axis in range(2):
        assert stats.kstest(pts[:, axis], stats.norm(mean[axis], std).cdf).pvalue > 1e-4
    # A traced std and mean under jit give the same draw as concrete ones.
    jitted = jax.jit(hp.injection.spawn_gaussian, static_argnums=1)
    np.testing.assert_allclose(
        jitted(jax.random.key(2), n, jnp.asarray(mean, jnp.float32), jnp.float32(std)), pts, rtol=1e-6, atol=1e-6
    )


@pytest.mark.parametrize("name", sorted(hp.resampling.RESAMPLERS))
def test_explorer_slots_after_sorted_resampling_are_the_lowest_support(name, rng):
    """The filter's shortcut: resample particles sorted by decreasing weight, respawn the last slots.

    The supports of those slots are exactly the ``round(f n)`` lowest supports (the multiset
    ``explorer_mask`` selects), for every resampler, since their indices are non-decreasing.
    """
    n = 97
    draw = jax.jit(lambda key, w: hp.resampling.RESAMPLERS[name](key, w, n))
    for trial in range(20):
        weights = rng.gamma(0.3, size=n).astype(np.float32)
        weights[rng.random(n) < 0.2] = 0.0
        weights[:3] = weights[3]  # ties in weight
        order = np.argsort(-weights, kind="stable")
        sorted_w = weights[order]
        support = sorted_w[np.asarray(draw(jax.random.key(trial), sorted_w))]
        for fraction in (0.0, 0.05, 0.3, 1.0):
            slots = np.asarray(_explorer_slots(n, np.float32(fraction)))
            assert slots.sum() == round(fraction * n) and np.all(slots[n - slots.sum():])
            lowest = np.asarray(hp.injection.explorer_mask(jnp.asarray(support), fraction))
            np.testing.assert_array_equal(np.sort(support[slots]), np.sort(support[lowest]))


def test_take_slots_chain_disjoint_lowest_support(rng):
    """Injectors in a row take disjoint slots, lowest support (highest rank) first, from any rank layout."""
    n = 50
    rank = rng.permutation(n).astype(np.int32)
    first = np.asarray(_take_slots(rank, 0, 5))
    second = np.asarray(_take_slots(rank, 5, 7))
    r = np.asarray(rank)
    np.testing.assert_array_equal(np.sort(r[first]), np.arange(45, 50))
    np.testing.assert_array_equal(np.sort(r[second]), np.arange(38, 45))
    assert not np.any(first & second)
    assert not np.any(np.asarray(_take_slots(rank, 3, 0)))


def test_explorer_pieces_refill_the_lowest_support_slots(rng):
    from heatpf_jax.motion.random_walk import Particles

    n = 40
    xy = rng.normal(size=(n, 2)).astype(np.float32)
    rank = rng.permutation(n).astype(np.int32)

    @jax.jit  # one program, the context built in it: run eagerly, each operation compiles on its own
    def inject(key, xy, rank):
        ctx = hp.injection.InjectionContext(
            particles=Particles(xy), log_weights=jnp.full((n,), -np.log(n), jnp.float32), rank=rank,
            used=jnp.int32(2), estimate=hp.Estimate(jnp.array([10.0, 10.0]), jnp.eye(2), jnp.zeros(2)),
            motion=hp.motion.RandomWalk(), motion_params=hp.motion.RandomWalkParams(),
        )
        uni = hp.injection.UniformExplorers(box=(20.0, 21.0, 30.0, 31.0)).inject(key, ctx,
                                                                                 hp.injection.ExplorerParams(0.25))
        gau = hp.injection.GaussianExplorers().inject(key, ctx, hp.injection.GaussianExplorerParams(0.25, 0.1))
        return uni._replace(motion=None), gau._replace(motion=None)  # the motion model is not an array

    uni, gau = jax.tree.map(np.asarray, inject(jax.random.key(0), xy, rank))
    r = np.asarray(rank)
    taken = (r >= n - 2 - 10) & (r < n - 2)  # ranks 28..37: 10 slots after the 2 already used
    for out, centre in ((uni, [20.5, 30.5]), (gau, [10.0, 10.0])):
        assert int(out.used) == 12
        moved = np.any(np.asarray(out.particles.xy) != np.asarray(xy), axis=1)
        np.testing.assert_array_equal(moved, taken)
        assert np.all(np.abs(np.asarray(out.particles.xy)[taken] - centre) < 0.6)


def test_random_particles_after_explorers_take_the_next_slots(rng):
    """Olufs's random particles: uniform over their box, in the free slots after the explorers'."""
    from heatpf_jax.injection.explorers import RandomParams
    from heatpf_jax.motion.random_walk import Particles

    n = 60
    xy = rng.normal(size=(n, 2)).astype(np.float32)
    rank = rng.permutation(n).astype(np.int32)

    @jax.jit  # one program, the context built in it: run eagerly, each operation compiles on its own
    def inject(key0, key1, xy, rank):
        ctx = hp.injection.InjectionContext(
            particles=Particles(xy), log_weights=jnp.full((n,), -np.log(n), jnp.float32), rank=rank,
            used=jnp.int32(0), estimate=hp.Estimate(jnp.zeros(2), jnp.eye(2), jnp.zeros(2)),
            motion=hp.motion.RandomWalk(), motion_params=hp.motion.RandomWalkParams(),
        )
        ctx = hp.injection.UniformExplorers(box=(20.0, 21.0, 30.0, 31.0)).inject(key0, ctx,
                                                                                 hp.injection.ExplorerParams(0.1))
        ctx = hp.injection.RandomParticles(box=(-5.0, -4.0, 8.0, 9.0)).inject(key1, ctx, RandomParams(0.25))
        return ctx._replace(motion=None)  # the motion model is not an array

    ctx = inject(jax.random.key(0), jax.random.key(1), xy, rank)
    assert int(ctx.used) == 6 + 15
    r = np.asarray(rank)
    out = np.asarray(ctx.particles.xy)
    explorers, randoms = r >= n - 6, (r >= n - 21) & (r < n - 6)
    assert np.all((out[explorers, 0] >= 20) & (out[explorers, 0] <= 21))
    assert np.all((out[randoms, 0] >= -5) & (out[randoms, 0] <= -4) & (out[randoms, 1] >= 8) & (out[randoms, 1] <= 9))
    np.testing.assert_array_equal(out[~(explorers | randoms)], np.asarray(xy)[~(explorers | randoms)])
