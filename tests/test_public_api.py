"""Public behaviour is a promise: every public name keeps its signature compatible (tests/data/public_api.py).

A public name (in the ``__all__`` of ``heatpf_jax``, ``heatpf_jax.sim`` or ``heatpf_jax.baselines``) stays
reachable (a removal goes through a ``DeprecationWarning`` period); every parameter or field it had keeps its
place and kind, one that had a default keeps one, and a new one comes with a default. So a user's
``hp.Measurements(xy, weight, valid)`` keeps working when a field is added.
"""

from __future__ import annotations

import json
import warnings

import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from tests.data.public_api import PATH, describe, public

SNAPSHOT = json.loads(PATH.read_text())
POSITIONAL = ("POSITIONAL_ONLY", "POSITIONAL_OR_KEYWORD")


def _problems(old: dict, new: dict) -> list[str]:
    """What in ``new`` breaks a caller of ``old``."""
    if old["kind"] != new["kind"]:
        return [f"was a {old['kind']}, is a {new['kind']}"]
    if "params" not in old:
        return []
    if "params" not in new:
        return ["has no inspectable signature any more"]
    problems = []
    current = {p[0]: (i, p[1], p[2]) for i, p in enumerate(new["params"])}
    for i, (name, kind, had_default) in enumerate(old["params"]):
        if name not in current:
            if not any(k == "VAR_KEYWORD" for _, k, _ in new["params"]):
                problems.append(f"lost its parameter {name!r}")
            continue
        j, new_kind, has_default = current[name]
        if kind in POSITIONAL and (new_kind not in POSITIONAL or j != i):
            problems.append(f"parameter {name!r} moved from position {i} ({kind}) to {j} ({new_kind})")
        if kind == "KEYWORD_ONLY" and new_kind not in ("KEYWORD_ONLY", "POSITIONAL_OR_KEYWORD"):
            problems.append(f"parameter {name!r} can no longer be passed by keyword")
        if had_default and not has_default:
            problems.append(f"parameter {name!r} lost its default")
    known = {p[0] for p in old["params"]}
    for name, kind, has_default in new["params"]:
        if name not in known and not has_default and kind not in ("VAR_POSITIONAL", "VAR_KEYWORD"):
            problems.append(f"new parameter {name!r} has no default: every existing call breaks")
    return problems


def test_snapshot_covers_the_public_modules():
    assert len(SNAPSHOT) > 100 and "heatpf_jax:Measurements" in SNAPSHOT


@pytest.mark.parametrize("key", sorted(SNAPSHOT))
def test_public_name_keeps_its_signature(key):
    module_name, name = key.split(":")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # only a DeprecationWarning is allowed, and public() allows it
        try:
            obj = public(module_name, name)
        except AttributeError:
            pytest.fail(f"{key} was removed without a deprecation period")
    assert not _problems(SNAPSHOT[key], describe(obj)), _problems(SNAPSHOT[key], describe(obj))


def test_the_checker_catches_a_new_required_field_and_a_lost_default():
    old = {"kind": "namedtuple", "params": [["xy", "POSITIONAL_OR_KEYWORD", False],
                                           ["weight", "POSITIONAL_OR_KEYWORD", True]]}
    new = {"kind": "namedtuple", "params": [["xy", "POSITIONAL_OR_KEYWORD", False],
                                           ["weight", "POSITIONAL_OR_KEYWORD", False],
                                           ["footprint", "POSITIONAL_OR_KEYWORD", False]]}
    assert _problems(old, new) == ["parameter 'weight' lost its default",
                                   "new parameter 'footprint' has no default: every existing call breaks"]
    assert _problems(old, {**new, "params": new["params"][::-1]})[0].startswith("parameter 'xy' moved")


def test_measurements_built_with_three_fields_weight_particles_like_explicit_zero_footprints(rng):
    """The construction of user scripts written before the footprint existed, positional and by keyword."""
    xy = jnp.asarray(rng.normal(size=(12, 2)), jnp.float32)
    weight = jnp.asarray(rng.uniform(0.3, 1.0, size=12), jnp.float32)
    valid = jnp.asarray(rng.uniform(size=12) < 0.8)
    positional = hp.Measurements(xy, weight, valid)
    keywords = hp.Measurements(xy=xy, weight=weight, valid=valid)
    explicit = hp.Measurements(xy, weight, valid, jnp.zeros((12, 2, 2), jnp.float32))
    for m in (positional, keywords):
        assert m.footprint.shape == (12, 2, 2) and m.footprint.dtype == jnp.float32
        np.testing.assert_array_equal(np.asarray(m.footprint), 0.0)
    particles = jnp.asarray(rng.normal(size=(30, 2)), jnp.float32)
    got = np.asarray(hp.observation.particle_weights(particles, positional, k=3))
    np.testing.assert_allclose(got, np.asarray(hp.observation.particle_weights(particles, explicit, k=3)), rtol=1e-6)
    # Eq. 1 by brute force: the sum over the 3 nearest valid measurements of weight / distance.
    d = np.linalg.norm(np.asarray(particles)[:, None] - np.asarray(xy)[None], axis=-1)
    d = np.where(np.asarray(valid)[None], d, np.inf)
    nearest = np.argsort(d, axis=1)[:, :3]
    floor = float(hp.observation.DEFAULT_MIN_DISTANCE)
    want = (np.asarray(weight)[nearest] / np.maximum(np.take_along_axis(d, nearest, axis=1), floor)).sum(axis=1)
    np.testing.assert_allclose(got, want, rtol=1e-4)
