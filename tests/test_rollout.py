"""The pipeline and the generic ``run``: pieces added without touching ``step``, the step's
diagnostics against a NumPy reference, baselines through the same ``run``, gradients in
unconstrained coordinates."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import logsumexp

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.buffers.aging import NoParams
from heatpf_jax.injection.explorers import replace_slots, take_slots
from tests.conftest import SMALL_FILTER, step_inputs


@dataclass(frozen=True)
class NoOpInjector:
    """A toy injector that changes nothing."""

    name: str = "noop"

    def default_params(self):
        return NoParams()

    def properties(self):
        return NoParams()

    def inject(self, key, context, params):
        return context


class TeleportParams(NamedTuple):
    count: int = 3


@dataclass(frozen=True)
class Teleport:
    """A toy injector: ``count`` of the lowest-support free slots jump to ``point``."""

    point: tuple[float, float] = (1.25, -0.5)
    name: str = "teleport"

    def default_params(self):
        return TeleportParams()

    def properties(self):
        return TeleportParams(count=P.integer(0, 1000))

    def inject(self, key, context, params):
        n = context.log_weights.shape[0]
        mask = take_slots(context.rank, context.used, params.count)
        xy = jnp.broadcast_to(jnp.asarray(self.point, jnp.float32), (n, 2))
        context = replace_slots(key, context, mask, xy)
        return context._replace(used=context.used + params.count)


def test_a_new_injector_needs_no_edit_of_step(small_sequence):
    """Two injectors in a row take disjoint slots of lowest support; the explorers keep theirs."""
    model = SMALL_FILTER._replace(injectors=(*SMALL_FILTER.injectors, Teleport()))
    params = P.as_arrays(model.make_params(explorer_fraction=0.25), model.properties())
    assert params.injectors["teleport"].count == 3
    state = model.init(jax.random.key(0), params)
    state, info = jax.jit(model.step)(jax.random.key(1), state, step_inputs(small_sequence, 0), params)
    n = model.num_particles
    explorers = round(0.25 * n)
    assert bool(info.resampled)  # resampled: slot i has support rank i
    xy = np.asarray(state.particles.xy)
    teleported = np.all(xy == np.float32([1.25, -0.5]), axis=1)
    np.testing.assert_array_equal(np.flatnonzero(teleported), np.arange(n - explorers - 3, n - explorers))
    # The explorers hold the last slots, uniform over the spawn box, not the teleport point.
    box = SMALL_FILTER.initial.box
    tail = xy[n - explorers :]
    assert np.all((tail[:, 0] >= box[0]) & (tail[:, 0] <= box[1]) & (tail[:, 1] >= box[2]) & (tail[:, 1] <= box[3]))
    assert tail.std(axis=0).min() > 0.5
    np.testing.assert_allclose(np.exp(np.asarray(state.log_weights)).sum(), 1.0, rtol=1e-5)


def test_noop_injector_equals_no_explorers(small_sequence):
    """A do-nothing piece in the injector slot gives exactly the filter with 0 % explorers."""
    key = jax.random.key(3)
    noop = SMALL_FILTER._replace(injectors=(NoOpInjector(),))
    a = hp.run(key, small_sequence, noop.default_params(), noop)
    b = hp.run(key, small_sequence, SMALL_FILTER.make_params(explorer_fraction=0.0), SMALL_FILTER)
    np.testing.assert_array_equal(np.asarray(a.info.mean), np.asarray(b.info.mean))
    np.testing.assert_array_equal(np.asarray(a.final_state.particles.xy), np.asarray(b.final_state.particles.xy))


def test_step_log_likelihood_and_ancestors_against_numpy(small_sequence):
    """Without motion noise the step's particles are the previous ones: log Z and ancestors by hand."""
    model = hp.paper_filter(hp.FilterOptions(num_particles=128, max_measurements=128, k_max=8,
                                               observation="gaussian", knn="dense"))
    params = P.as_arrays(
        model.make_params(k=2, obs_std=0.3, diffusion_std=0.0, odom_trans_noise=0.0, odom_rot_noise=0.0,
                          explorer_fraction=0.0),
        model.properties(),
    )
    state = model.init(jax.random.key(0), params)
    # Non-uniform previous weights, so log Z is a weighted mean.
    prev = jax.nn.log_softmax(jax.random.normal(jax.random.key(9), (128,)))
    state = state._replace(log_weights=prev)
    inputs = step_inputs(small_sequence, 4)
    new_state, info = jax.jit(model.step)(jax.random.key(2), state, inputs, params)
    buffer = model.source.measure(inputs, params.source)
    m = np.asarray(buffer.xy)[np.asarray(buffer.valid)]
    w = np.asarray(buffer.weight)[np.asarray(buffer.valid)]
    assert len(m) > 2
    xy = np.asarray(state.particles.xy, np.float64)
    d2 = ((xy[:, None, :] - m[None, :, :]) ** 2).sum(-1)
    nearest = np.argsort(d2, axis=1, kind="stable")[:, :2]
    lik = np.take_along_axis(w[None, :] * np.exp(-0.5 * d2 / 0.09), nearest, axis=1).sum(1)
    expected = logsumexp(np.asarray(prev, np.float64) + np.log(lik))
    assert float(info.log_likelihood) == pytest.approx(expected, rel=1e-4, abs=1e-4)
    ancestors = np.asarray(info.ancestors)
    assert bool(info.resampled) and ancestors.shape == (128,)
    np.testing.assert_array_equal(np.asarray(new_state.particles.xy), np.asarray(state.particles.xy)[ancestors])
    # The copies follow the weights: the most-copied particle is among the likeliest.
    post = np.asarray(prev, np.float64) + np.log(lik)
    assert np.bincount(ancestors, minlength=128).argmax() in np.argsort(-post)[:5]


def test_kalman_baseline_runs_through_the_same_run(small_sequence):
    method = hp.build("kalman")
    res = hp.run(jax.random.key(0), small_sequence, method.params, method.model)
    assert np.asarray(res.info.mean).shape == (small_sequence.num_steps, 2)
    assert np.asarray(res.info.ancestors).shape == (small_sequence.num_steps, 0)
    err = np.linalg.norm(np.asarray(res.info.mean) - small_sequence.ground_truth, axis=1)[-10:].mean()
    assert err < 0.2, err
    # Its key is ignored: another key gives the same run.
    other = hp.run(jax.random.key(5), small_sequence, method.params, method.model)
    np.testing.assert_array_equal(np.asarray(res.info.mean), np.asarray(other.info.mean))


def test_trainable_partition_of_the_paper_filter():
    """``k`` and the other frozen parameters are left out of gradients; the paper filter's trainable ones round-trip
    through unconstrained coordinates. (Gradients of runs: tests/test_filter.py, test_method_gradients.py and
    test_tuning.py.)"""
    model = SMALL_FILTER
    props = model.properties()
    params = P.as_arrays(model.make_params(aging=0.1), props)
    trainable, frozen = P.partition(params, props)
    assert frozen.observation.k is not None and trainable.observation.k is None
    assert set(hp.trainable_names(model)) == {"motion.diffusion_std", "motion.odom_trans_noise",
                                              "motion.odom_rot_noise", "buffer.aging", "observation.min_distance"}
    back = P.from_unconstrained(P.to_unconstrained(trainable, props), props)
    for a, b in zip(jax.tree.leaves(back), jax.tree.leaves(trainable), strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-5)


def test_run_validates_before_compiling(small_sequence, monkeypatch):
    import heatpf_jax.rollout as rollout

    monkeypatch.setattr(rollout, "_run_jit", lambda *a: pytest.fail("compiled before validating"))
    with pytest.raises(ValueError, match="^injectors: names must differ"):
        bad = SMALL_FILTER._replace(injectors=(NoOpInjector(name="x"), NoOpInjector(name="x")))
        hp.run(jax.random.key(0), small_sequence, bad.default_params(), bad)
    with pytest.raises(ValueError, match=r"^buffer.aging: must be finite"):
        hp.run(jax.random.key(0), small_sequence, SMALL_FILTER.make_params(aging=math.nan), SMALL_FILTER)
