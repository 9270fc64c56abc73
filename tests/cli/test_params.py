"""``heatpf params``: every parameter and static option of a method, as :func:`describe_method` gives them."""

import jax
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.cli import describe_method, main


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


@pytest.mark.parametrize("method", ["heatmap", "kalman", "bitbots2018"])
def test_params_lists_every_parameter_and_option(method, capsys):
    assert main(["params", "--method", method]) == 0
    out = capsys.readouterr().out
    assert out == describe_method(method) + "\n"
    lines = out.splitlines()
    model, params = hp.build(method)
    props = model.properties()
    leaves = jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))
    for name, value, prop in zip(P.leaf_names(props), jax.tree.leaves(params), leaves, strict=True):
        row = next(line.split(None, 1) for line in lines if line.split()[:1] == [name])
        assert row[1].startswith(f"{value!r} ") or row[1].startswith(f"{float(value)!r} ")
        assert prop.describe() in row[1] and row[1].rstrip().endswith("trainable" if prop.trainable else "frozen")
    for field, default in hp.FilterOptions._field_defaults.items():
        row = next(line.split() for line in lines if line.split()[:1] == [field])
        assert row[1] == (",".join(map(str, default)) if isinstance(default, tuple) else str(default))
    # Named options list their names, not "a positive integer".
    rows = {line.split()[0]: line for line in lines if line.split()[:1] in (["ego"], ["memory"])}
    assert "one of odometry, none, pose" in rows["ego"] and "one of none, tracks" in rows["memory"]
    # Settings show through: a Gaussian observation has its own parameter.
    assert main(["params", "--set", "observation=gaussian", "--set", "diffusion_std=0.5"]) == 0
    shown = capsys.readouterr().out
    assert any(line.split()[:2] == ["motion.diffusion_std", "0.5"] for line in shown.splitlines())
    assert "obs_std" in shown
