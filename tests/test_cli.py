"""The heatpf command: run writes the documented CSV; bad input gives a named error and writes nothing."""

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.cli import CSV_HEADER, error_stats, grid_config, main, parse_settings
from heatpf_jax.params import set_by_name
from heatpf_jax.sim import simulate_standard
from tests.conftest import SMALL_OPTIONS

SMALL_SET = [f"{name}={getattr(SMALL_OPTIONS, name)}" for name in ("num_particles", "max_measurements", "k_max")]


@pytest.fixture(scope="module")
def seq_file(tmp_path_factory):
    seq = simulate_standard(3, num_steps=20, shrink=4)  # same shapes as conftest's small_sequence
    path = tmp_path_factory.mktemp("cli") / "seq.npz"
    hp.save_sequence(path, seq)
    return path, seq


def test_run_writes_csv_and_prints_errors(seq_file, tmp_path, capsys):
    path, seq = seq_file
    out = tmp_path / "est.csv"
    code = main(["run", str(path), "--output", str(out), "--seed", "1", *sum((["--set", s] for s in SMALL_SET), [])])
    assert code == 0
    lines = out.read_text().splitlines()
    assert lines[0] == CSV_HEADER
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape == (seq.num_steps, 6)
    np.testing.assert_array_equal(table[:, 0], np.arange(seq.num_steps))
    assert np.all(table[:, 3] >= 0) and np.all(table[:, 5] >= 0)  # variances
    # The printed statistics are those of the CSV's estimates against the file's ground truth.
    stats = error_stats(table[:, 1:3], seq.ground_truth)
    printed = capsys.readouterr().out
    assert f"mean {stats['mean']:.4f}" in printed and f"max {stats['max']:.4f}" in printed
    # Same seed, same file: identical output (the filter is deterministic given the key).
    out2 = tmp_path / "est2.csv"
    main(["run", str(path), "-o", str(out2), "--seed", "1", *sum((["--set", s] for s in SMALL_SET), [])])
    assert out.read_text() == out2.read_text()


def test_error_stats_against_hand_values():
    est = np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 0.0]])
    truth = np.zeros((3, 2))
    stats = error_stats(est, truth)
    assert stats["mean"] == pytest.approx(2.0) and stats["max"] == pytest.approx(5.0)
    assert stats["std"] == pytest.approx(np.std([0.0, 5.0, 1.0]))


def test_bad_input_file_names_field_and_writes_nothing(tmp_path, seq_file, capsys):
    _, seq = seq_file
    bad = tmp_path / "bad.npz"
    arrays = {k: v for k, v in seq._asdict().items() if v is not None}
    arrays["cam_to_base"] = arrays["cam_to_base"] * 2.0
    np.savez(bad, **arrays)
    out = tmp_path / "never.csv"
    assert main(["run", str(bad), "-o", str(out)]) == 2
    assert "cam_to_base" in capsys.readouterr().err
    assert not out.exists()


def test_existing_output_survives_a_failed_run(tmp_path, seq_file):
    path, _ = seq_file
    out = tmp_path / "keep.csv"
    out.write_text("precious\n")
    assert main(["run", str(path), "-o", str(out), "--set", "threshold=2"]) == 2
    assert out.read_text() == "precious\n"


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
    assert model.resampling.resampler is hp.RESAMPLERS["residual"]
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
    model = hp.heatmap_filter(options)
    params = set_by_name(model.default_params(), model.properties(), settings)
    with pytest.raises(ValueError, match=r"^observation\.k: "):
        hp.validate_params(params, model)
    # A sweep's k grid raises it the same way.
    assert grid_config(hp.FilterOptions(), {"k": [1, default + 5]}, []).k_max == default + 5
    assert grid_config(hp.FilterOptions(), {"k": [1, 2]}, []).k_max == default
    assert grid_config(hp.FilterOptions(k_max=4), {"k": [1, 9]}, ["k_max=4"]).k_max == 4


def test_eval_prints_table_i_and_writes_figures(tmp_path, capsys):
    small = ["--set", "num_particles=64", "--set", "max_measurements=64", "--set", "k_max=4"]
    plots = tmp_path / "plots"
    assert main(["eval", "--scenario", "split", "--seeds", "2", "--steps", "25", "--plot", str(plots), *small]) == 0
    out = capsys.readouterr().out
    assert "scenario split: 2 sequence(s) x 25 steps" in out
    for method in ("heatmap", "conventional", "kalman", "bitbots2018", "no aging"):
        assert method in out
    conventional = next(line for line in out.splitlines() if line.startswith("conventional"))
    assert conventional.split()[4] == "1.000"  # its ratio to itself
    assert sorted(p.name for p in plots.iterdir()) == ["split_errors.png", "split_traces.png"]
    assert all((plots / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in ("split_errors.png", "split_traces.png"))


def test_eval_on_a_recording_and_its_errors(tmp_path, seq_file, capsys):
    path, seq = seq_file
    small = ["--set", "num_particles=128", "--set", "max_measurements=128", "--set", "k_max=8"]
    assert main(["eval", "--input", str(path), *small]) == 0
    assert f"scenario {path.stem}: 1 sequence(s) x {seq.num_steps} steps" in capsys.readouterr().out
    nogt = tmp_path / "nogt.npz"
    hp.save_sequence(nogt, seq._replace(ground_truth=None))
    assert main(["eval", "--input", str(nogt)]) == 2
    assert "ground_truth" in capsys.readouterr().err
    assert main(["eval", "--scenario", "nope"]) == 2
    assert "--scenario" in capsys.readouterr().err
