"""``--set`` and ``--seeds`` by name: values reach the parameters and options, bad ones name their field."""

import pytest

import heatpf_jax as hp
from heatpf_jax.cli import grid_config, main, parse_seeds, parse_settings
from heatpf_jax.params import set_by_name


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


@pytest.mark.parametrize(
    "assignment, field",
    [("k=0", "observation.k"), ("nope=1", "nope"), ("k=2.5", "k"), ("threshold=abc", "threshold"),
     ("resampler=bogus", "resampler"), ("spawn_box=1,2,3", "spawn_box"), ("top_fraction=0", "estimator.top_fraction")],
)
def test_bad_overrides_name_the_field(tmp_path, seq_file, capsys, assignment, field):
    path, _ = seq_file
    assert main(["run", str(path), "-o", str(tmp_path / "x.csv"), "--set", assignment]) == 2
    assert capsys.readouterr().err.startswith(f"heatpf: error: {field}")

def test_overrides_reach_params_and_options():
    options, settings = parse_settings(["k=7", "aging=0.2", "resampler=residual", "spawn_box=-1,1,-2,2"])
    assert settings["k"] == 7 and isinstance(settings["k"], int) and settings["aging"] == 0.2
    assert options.resampler == "residual" and options.spawn_box == (-1.0, 1.0, -2.0, 2.0)
    # The settings reach the method's params and the options its model.
    model, params = hp.build("heatmap", options)
    params = set_by_name(params, model.properties(), settings)
    assert params.observation.k == 7 and params.buffer.aging == 0.2
    assert model.resampling.resampler is hp.resampling.RESAMPLERS["residual"]
    assert model.initial.box == (-1.0, 1.0, -2.0, 2.0)
    # The Kalman baseline's names of earlier versions are still accepted.
    _, settings = parse_settings(["kalman_accel_std=2", "kalman_meas_std=0.2"], methods=("kalman",))
    assert settings == {"accel_std": 2.0, "meas_std": 0.2}

def test_k_above_the_default_bound_raises_k_max_unless_given():
    default = hp.FilterOptions().k_max
    options, _ = parse_settings([f"k={default + 2}"])
    assert options.k_max == default + 2
    options, _ = parse_settings(["k=2"])
    assert options.k_max == default
    # An explicit k_max stays, and the out-of-range k is then refused, naming the field.
    options, settings = parse_settings([f"k={default + 2}", "k_max=4"])
    assert options.k_max == 4
    model = hp.paper_filter(options)
    params = set_by_name(model.default_params(), model.properties(), settings)
    with pytest.raises(ValueError, match=r"^observation\.k: "):
        hp.validate_params(params, model)
    # A sweep's k grid raises it the same way.
    assert grid_config(hp.FilterOptions(), {"k": [1, default + 5]}, []).k_max == default + 5
    assert grid_config(hp.FilterOptions(), {"k": [1, 2]}, []).k_max == default
    assert grid_config(hp.FilterOptions(k_max=4), {"k": [1, 9]}, ["k_max=4"]).k_max == 4

def test_parse_seeds():
    assert parse_seeds("5", 1) == range(5)
    assert parse_seeds("200:216", 1) == range(200, 216)
    assert parse_seeds(None, 3) == range(3)
    for bad in ("0", "3:3", "5:2", "-1:2", "a", "1:b", ""):
        with pytest.raises(ValueError, match="^--seeds: "):
            parse_seeds(bad, 1)
