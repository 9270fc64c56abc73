"""Parameter properties (heatpf_jax.params): constraints, names, validation, unconstrained coordinates.

References are hand-computed (log / logit by NumPy) and the filters' own documented constraints.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P


def test_param_check_bounds_and_messages():
    prop = P.unit_interval(high_closed=False)
    prop.check("share", 0.0)
    prop.check("share", np.array([0.1, 0.999]))
    with pytest.raises(ValueError, match=r"^share: must be in \[0, 1\), got 1.0"):
        prop.check("share", 1.0)
    with pytest.raises(ValueError, match="^share: must be finite"):
        prop.check("share", float("nan"))
    with pytest.raises(ValueError, match="^share:"):
        prop.check("share", np.array([0.5, -0.1]))  # one bad element of a batch
    pos = P.positive()
    with pytest.raises(ValueError, match=r"^s: must be in \(0, inf\)"):
        pos.check("s", 0.0)
    with pytest.raises(ValueError, match="^s: must be finite"):
        pos.check("s", math.inf)
    P.positive(allow_inf=True).check("d", math.inf)  # "no limit" where allowed
    k = P.integer(1, 8)
    assert not k.trainable and k.dtype == jnp.int32
    for bad in (0, 9, 2.5):
        with pytest.raises(ValueError, match=r"^k: must be an integer in \[1, 8\]"):
            k.check("k", bad)
    k.check("k", np.int64(8))
    # Traced values are skipped (checked eagerly before any compilation instead).
    jax.jit(lambda x: (pos.check("s", x), x)[1])(jnp.float32(-1.0))


@pytest.mark.parametrize(
    "prop, values",
    [
        (P.positive(), [1e-3, 0.2, 7.0]),
        (P.nonnegative(), [1e-4, 0.1, 3.0]),
        (P.unit_interval(), [0.01, 0.5, 0.97]),
        (P.interval(-2.0, 3.0), [-1.5, 0.0, 2.9]),
    ],
)
def test_unconstrained_round_trip_and_reference(prop, values):
    x = np.array(values, np.float32)
    u = np.asarray(prop.to_unconstrained(x), np.float64)
    np.testing.assert_allclose(np.asarray(prop.from_unconstrained(u)), x, rtol=1e-5)
    if math.isfinite(prop.high):
        p = (x.astype(np.float64) - prop.low) / (prop.high - prop.low)
        np.testing.assert_allclose(u, np.log(p / (1 - p)), rtol=1e-4, atol=1e-5)
    else:
        np.testing.assert_allclose(u, np.log(x.astype(np.float64) - prop.low), rtol=1e-5)
    # Every real number maps into the constraint.
    for v in np.asarray(prop.from_unconstrained(np.array([-30.0, -1.0, 0.0, 1.0, 30.0], np.float32))):
        assert prop.low <= v <= prop.high


def test_boundary_values_stay_finite_in_unconstrained_space():
    assert np.isfinite(float(P.nonnegative().to_unconstrained(0.0)))
    assert np.all(np.isfinite(np.asarray(P.unit_interval().to_unconstrained(np.array([0.0, 1.0], np.float32)))))


def test_names_resolution_and_set_by_name():
    model = hp.paper_filter()
    names = P.leaf_names(model.properties())
    assert "motion.diffusion_std" in names and "observation.k" in names
    assert "injectors.explorers.explorer_fraction" in names
    assert len(names) == len(set(names)) == len(jax.tree.leaves(model.default_params()))
    assert P.resolve_name("diffusion_std", names) == "motion.diffusion_std"
    assert P.resolve_name("explorers.explorer_fraction", names) == "injectors.explorers.explorer_fraction"
    assert P.resolve_name("nope", names) is None
    # A short name shared by two parameters is ambiguous (the Kalman model has odom noise only once,
    # so build a tree that has it twice).
    with pytest.raises(ValueError, match="^x: ambiguous"):
        P.resolve_name("x", ["a.x", "b.x"])
    params = model.make_params(k=3, **{"motion.diffusion_std": 0.05})
    assert params.observation.k == 3 and params.motion.diffusion_std == 0.05
    assert params.buffer == model.default_params().buffer  # the rest untouched
    with pytest.raises(ValueError, match="^bogus: unknown parameter"):
        model.make_params(bogus=1.0)
    same = P.set_by_name(params, model.properties(), {"bogus": 1.0, "aging": 0.5}, skip_unknown=True)
    assert same.buffer.aging == 0.5


def test_properties_mark_discrete_parameters_frozen():
    model = hp.paper_filter(hp.FilterOptions(k_max=6))
    props = model.properties()
    assert props.observation.k == P.integer(1, 6)
    leaves = jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))
    trainable = {n for n, p in zip(P.leaf_names(props), leaves, strict=True) if p.trainable}
    assert trainable == {"motion.diffusion_std", "motion.odom_trans_noise", "motion.odom_rot_noise", "buffer.aging",
                         "observation.min_distance"}


def test_partition_combine_and_unconstrained_tree():
    model = hp.paper_filter()
    props = model.properties()
    params = P.as_arrays(model.make_params(k=4, diffusion_std=0.3), props)
    assert params.observation.k.dtype == jnp.int32 and params.motion.diffusion_std.dtype == jnp.float32
    trainable, frozen = P.partition(params, props)
    assert trainable.observation.k is None and frozen.observation.k == 4
    assert frozen.motion.diffusion_std is None
    back = P.combine(trainable, frozen)
    for a, b in zip(jax.tree.leaves(back), jax.tree.leaves(params), strict=True):
        np.testing.assert_array_equal(a, b)
    u = P.to_unconstrained(trainable, props)
    np.testing.assert_allclose(float(u.motion.diffusion_std), math.log(0.3), rtol=1e-6)
    again = P.from_unconstrained(u, props)
    np.testing.assert_allclose(float(again.motion.diffusion_std), 0.3, rtol=1e-6)


def test_validate_names_the_dotted_path():
    model = hp.paper_filter(hp.FilterOptions(k_max=8))
    with pytest.raises(ValueError, match=r"^observation.k: must be an integer in \[1, 8\], got 9"):
        hp.validate_params(model.make_params(k=9), model)
    with pytest.raises(ValueError, match=r"^injectors.explorers.explorer_fraction:"):
        hp.validate_params(model.make_params(explorer_fraction=1.0), model)
    with pytest.raises(TypeError, match="^params: expected FilterParams"):
        hp.validate_params(hp.baselines.KalmanParams(), model)
