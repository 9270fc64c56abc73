"""The heatpf command: run writes the documented CSV; bad input gives a named error and writes nothing."""

import os
import shutil
import tempfile
from pathlib import Path

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.cli import (
    CSV_HEADER,
    describe_method,
    error_stats,
    grid_config,
    main,
    parse_seeds,
    parse_settings,
)
from heatpf_jax.params import set_by_name
from heatpf_jax.sim import SCENARIOS, simulate_standard
from tests.conftest import SMALL_OPTIONS

SMALL_SET = [f"{name}={getattr(SMALL_OPTIONS, name)}" for name in ("num_particles", "max_measurements", "k_max")]
SMALL_ARGS = sum((["--set", s] for s in SMALL_SET), [])


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


@pytest.fixture(scope="module")
def seq_file(tmp_path_factory):
    seq = simulate_standard(3, num_steps=20, shrink=4)  # same shapes as conftest's small_sequence
    path = tmp_path_factory.mktemp("cli") / "seq.npz"
    hp.save_sequence(path, seq)
    return path, seq


def test_run_writes_csv_and_prints_errors(seq_file, tmp_path, capsys):
    path, seq = seq_file
    out = tmp_path / "est.csv"
    code = main(["run", str(path), "--output", str(out), "--seed", "1", *SMALL_ARGS])
    assert code == 0
    lines = out.read_text().splitlines()
    assert lines[0] == CSV_HEADER
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    assert table.shape == (seq.num_steps, 6)
    np.testing.assert_array_equal(table[:, 0], np.arange(seq.num_steps))
    assert np.all(table[:, 3] >= 0) and np.all(table[:, 5] >= 0)  # variances
    # The printed statistics are those of the CSV's estimates against the file's ground truth, after the
    # default burn-in of 10 steps (as in eval and demo).
    stats = error_stats(table[:, 1:3], seq.ground_truth, 10)
    printed = capsys.readouterr().out
    assert f"error [m] after step 10: mean {stats['mean']:.4f}  max {stats['max']:.4f}" in printed
    # Same seed, same file: identical output (the filter is deterministic given the key); --burn-in moves the
    # statistics' first step.
    out2 = tmp_path / "est2.csv"
    assert main(["run", str(path), "-o", str(out2), "--seed", "1", "--burn-in", "3", *SMALL_ARGS]) == 0
    assert out.read_text() == out2.read_text()
    stats = error_stats(table[:, 1:3], seq.ground_truth, 3)
    assert f"error [m] after step 3: mean {stats['mean']:.4f}  max {stats['max']:.4f}" in capsys.readouterr().out


def test_error_stats_against_hand_values():
    est = np.array([[0.0, 0.0], [3.0, 4.0], [1.0, 0.0]])
    truth = np.zeros((3, 2))
    stats = error_stats(est, truth)
    assert stats["mean"] == pytest.approx(2.0) and stats["max"] == pytest.approx(5.0)
    assert stats["std"] == pytest.approx(np.std([0.0, 5.0, 1.0]))
    stats = error_stats(est, truth, burn_in=1)
    assert stats["mean"] == pytest.approx(3.0) and stats["std"] == pytest.approx(2.0)


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
    model = hp.paper_filter(options)
    params = set_by_name(model.default_params(), model.properties(), settings)
    with pytest.raises(ValueError, match=r"^observation\.k: "):
        hp.validate_params(params, model)
    # A sweep's k grid raises it the same way.
    assert grid_config(hp.FilterOptions(), {"k": [1, default + 5]}, []).k_max == default + 5
    assert grid_config(hp.FilterOptions(), {"k": [1, 2]}, []).k_max == default
    assert grid_config(hp.FilterOptions(k_max=4), {"k": [1, 9]}, ["k_max=4"]).k_max == 4


def test_eval_prints_table_i_and_writes_figures(tmp_path, capsys, monkeypatch):
    import heatpf_jax.sim

    simulated = []
    simulate = heatpf_jax.sim.simulate_with_info
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info",
                        lambda name, seed, **kw: simulated.append(seed) or simulate(name, seed, **kw))
    small = ["--set", "num_particles=64", "--set", "max_measurements=64", "--set", "k_max=4"]
    plots = tmp_path / "plots"
    methods = ["--method", "paper", "--method", "conventional"]  # paper brings its two aging ablations
    assert main(["eval", "--scenario", "split", "--seeds", "3:5", "--steps", "25", "--plot", str(plots), *methods,
                 *small]) == 0
    assert simulated == [3, 4]  # --seeds START:STOP, as the README uses it
    out = capsys.readouterr().out
    assert "scenario split: 2 sequence(s) x 25 steps, errors after step 10" in out
    rows = [line.split()[0] for line in out.splitlines()[2:] if line.strip() and not line.startswith("wrote")]
    assert rows == ["conventional", "paper", "paper,", "paper,"] and "no aging" in out
    conventional = next(line for line in out.splitlines() if line.startswith("conventional"))
    assert conventional.split()[4] == "1.000"  # its ratio to itself
    assert sorted(p.name for p in plots.iterdir()) == ["split_errors.png", "split_traces.png"]
    assert all((plots / n).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for n in ("split_errors.png", "split_traces.png"))


def test_eval_on_a_recording_and_its_errors(tmp_path, seq_file, capsys):
    path, seq = seq_file
    small = ["--set", "num_particles=128", "--set", "max_measurements=128", "--set", "k_max=8"]
    assert main(["eval", "--input", str(path), "--method", "paper", "--method", "kalman", *small]) == 0
    out = capsys.readouterr().out
    assert f"scenario {path.stem}: 1 sequence(s) x {seq.num_steps} steps" in out
    shown = [line.split()[0] for line in out.splitlines()[2:] if line.strip()]
    assert shown == ["kalman", "paper", "paper,", "paper,"]  # --method picks methods (paper with its ablations)
    nogt = tmp_path / "nogt.npz"
    hp.save_sequence(nogt, seq._replace(ground_truth=None))
    assert main(["eval", "--input", str(nogt)]) == 2
    assert "ground_truth" in capsys.readouterr().err
    assert main(["eval", "--scenario", "nope"]) == 2
    assert "--scenario" in capsys.readouterr().err


def test_eval_checks_its_options_before_any_work(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.sim

    monkeypatch.setattr(heatpf_jax.sim, "simulate", _must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", _must_not_run)
    path, _ = seq_file
    for argv, start in [
        (["eval", "--input", str(path), "--seeds", "3"], "--seeds: applies to the simulated scenarios"),
        (["eval", "--scenario", "split", "--seeds", "4:4"], "--seeds: "),
        (["eval", "--scenario", "split", "--steps", "10"], "--burn-in: 10 leaves none of the 10 steps"),
        (["eval", "--scenario", "split", "--steps", "30", "--burn-in", "-1"], "--burn-in: must be >= 0"),
    ]:
        assert main(argv) == 2
        assert _one_error_line(capsys).startswith(f"heatpf: error: {start}")


def _must_not_run(*args, **kwargs):
    raise AssertionError("work started before the checks")


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err + captured.out
    return lines[0]


def test_parse_seeds():
    assert parse_seeds("5", 1) == range(5)
    assert parse_seeds("200:216", 1) == range(200, 216)
    assert parse_seeds(None, 3) == range(3)
    for bad in ("0", "3:3", "5:2", "-1:2", "a", "1:b", ""):
        with pytest.raises(ValueError, match="^--seeds: "):
            parse_seeds(bad, 1)


def test_run_refuses_its_input_as_output_by_any_path(tmp_path, seq_file, capsys):
    rec = tmp_path / "rec.npz"
    shutil.copyfile(seq_file[0], rec)
    before = rec.read_bytes()
    (tmp_path / "sub").mkdir()
    os.symlink(rec, tmp_path / "link.npz")
    os.link(rec, tmp_path / "hard.npz")
    variants = [
        (rec, rec),
        (rec, tmp_path / "sub" / ".." / "rec.npz"),
        (tmp_path / "link.npz", rec),
        (rec, tmp_path / "link.npz"),
        (rec, tmp_path / "hard.npz"),
    ]
    for source, target in variants:
        for force in ([], ["--force"]):  # --force never makes the input an output
            assert main(["run", str(source), "--output", str(target), *force]) == 2
            assert _one_error_line(capsys) == (
                f"heatpf: error: --output: {target} is the input file; choose another --output"
            )
            assert rec.read_bytes() == before


def test_existing_outputs_are_replaced_only_with_force(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.sim

    path, seq = seq_file
    out = tmp_path / "keep.csv"
    out.write_text("precious\n")
    monkeypatch.setattr(heatpf_jax.sim, "simulate", _must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", _must_not_run)
    for argv in (["run", str(path), "-o", str(out), *SMALL_ARGS], ["demo", "--steps", "12", "-o", str(out)]):
        assert main(argv) == 2
        assert _one_error_line(capsys) == (
            f"heatpf: error: --output: {out} exists; pass --force to replace it, or choose another --output"
        )
        assert out.read_text() == "precious\n"
    assert main(["run", str(path), "-o", str(out), "--force", *SMALL_ARGS]) == 0
    assert out.read_text().splitlines()[0] == CSV_HEADER
    assert len(out.read_text().splitlines()) == seq.num_steps + 1


@pytest.fixture
def unwritable_dir(tmp_path):
    """A directory in which no file can be created: read-only for an ordinary user; /sys for root."""
    if os.geteuid() != 0:
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        yield ro
        ro.chmod(0o700)
        return
    try:
        fd, probe = tempfile.mkstemp(dir="/sys")
    except OSError:
        yield Path("/sys")
        return
    os.close(fd)
    os.unlink(probe)
    pytest.skip("no directory here refuses root")


def test_bad_output_locations_fail_before_any_work(tmp_path, seq_file, capsys, monkeypatch, unwritable_dir):
    import heatpf_jax.rollout
    import heatpf_jax.sequence
    import heatpf_jax.sim

    for module, name in ((heatpf_jax.sequence, "load_sequence"), (heatpf_jax.sim, "simulate"),
                         (heatpf_jax.rollout, "run")):
        monkeypatch.setattr(module, name, _must_not_run)
    path, _ = seq_file
    a_file = tmp_path / "a_file.txt"
    a_file.write_text("mine\n")
    missing = tmp_path / "missing" / "out.csv"
    cases = [
        (["run", str(path), "-o", str(missing)], f"--output: {missing}: the directory {missing.parent} does not exist"),
        (["run", str(path), "-o", str(tmp_path)], f"--output: {tmp_path} is a directory"),
        (["run", str(path), "-o", str(a_file / "out.csv")], f"--output: {a_file / 'out.csv'}: {a_file} is not a"),
        (["run", str(path), "-o", str(unwritable_dir / "o.csv")], f"--output: cannot write in {unwritable_dir}"),
        (["demo", "-o", str(missing)], f"--output: {missing}: the directory {missing.parent} does not exist"),
        (["eval", "--plot", str(a_file), "--scenario", "split"], f"--plot: {a_file} exists and is not a directory"),
        (["eval", "--plot", str(unwritable_dir / "plots")], f"--plot: cannot write in {unwritable_dir}"),
        (["sweep", str(path), "--grid", "k=1,2", "-o", str(missing)], f"--output: {missing}: the directory"),
        (["sweep", str(path), "--grid", "k=1,2", "-o", str(path)], f"--output: {path} is the input file"),
    ]
    for argv, start in cases:
        assert main(argv) == 2, argv
        assert _one_error_line(capsys).startswith(f"heatpf: error: {start}")
    assert a_file.read_text() == "mine\n" and not missing.parent.exists()


def test_burn_in_must_leave_steps_and_nothing_is_silently_ignored(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.rollout
    import heatpf_jax.sim

    monkeypatch.setattr(heatpf_jax.rollout, "run", _must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate", _must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", _must_not_run)
    path, seq = seq_file
    out = str(tmp_path / "x.csv")
    cases = [
        (["run", str(path), "-o", out, "--burn-in", str(seq.num_steps)],
         f"--burn-in: {seq.num_steps} leaves none of the {seq.num_steps} steps"),
        (["demo", "--steps", "8"], "--burn-in: 10 leaves none of the 8 steps"),
        (["sweep", "--scenario", "split", "--steps", "10", "--grid", "k=1,2", "-o", out], "--burn-in: 10 leaves none"),
        (["run", str(path), "-o", out, "--set", "method=kalman"], "method: not a parameter; choose the method with "
         "--method NAME"),
        (["sweep", str(path), "-o", out, "--grid", "method=1"], "method: not a parameter; choose the method with"),
        (["run", str(path), "-o", out, "--method", "kalman", "--set", "num_particles=64"],
         "num_particles: a static option not used by method kalman"),
        (["run", str(path), "-o", out, "--set", "nope=1"], "nope: not a parameter of method heatmap"),
        (["sweep", str(path), "-o", out, "--grid", "k=1,2", "--set", "observation.k=3"],
         "observation.k: given in both --set and --grid"),
        (["sweep", str(path), "-o", out, "--grid", "k=1,2", "--seeds", "2"], "--seeds: applies to --scenario"),
    ]
    for argv, start in cases:
        assert main(argv) == 2, argv
        line = _one_error_line(capsys)
        assert line.startswith(f"heatpf: error: {start}"), line
    assert not os.path.exists(out)


def test_help_lists_scenarios_and_how_to_list_parameters(capsys):
    for command in ("eval", "sweep"):
        with pytest.raises(SystemExit) as info:
            main([command, "--help"])
        assert info.value.code == 0
        text = " ".join(capsys.readouterr().out.split())
        assert all(name in text for name in SCENARIOS) and "--no-cache" in text
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    assert "heatpf params --method NAME" in " ".join(capsys.readouterr().out.split())


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


def test_ctrl_c_exits_130_in_one_line_and_writes_nothing(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.sequence

    def interrupted(path):
        raise KeyboardInterrupt

    monkeypatch.setattr(heatpf_jax.sequence, "load_sequence", interrupted)
    out = tmp_path / "x.csv"
    assert main(["run", str(seq_file[0]), "-o", str(out)]) == 130
    assert _one_error_line(capsys) == "heatpf: interrupted"
    assert not out.exists()


def test_run_writes_modes_and_tracks_csv_equal_to_the_runs(tmp_path, seq_file, capsys):
    from heatpf_jax.cli import MODES_HEADER, TRACKS_HEADER

    path, seq = seq_file
    out, modes, tracks = tmp_path / "est.csv", tmp_path / "modes.csv", tmp_path / "tracks.csv"
    assert main(["run", str(path), "-o", str(out), "--modes", str(out), "--method", "paper", *SMALL_ARGS]) == 2
    assert "--modes" in capsys.readouterr().err and not out.exists()  # one file cannot be both
    assert main(["run", str(path), "-o", str(out), "--tracks", str(tracks), "--method", "paper", *SMALL_ARGS]) == 2
    assert _one_error_line(capsys) == ("heatpf: error: --tracks: the filter has no long-term memory; "
                                       "add --set memory=tracks")
    assert main(["run", str(path), "-o", str(out), "--modes", str(modes), "--tracks", str(tracks), "--method",
                 "paper", *SMALL_ARGS, "--set", "memory=tracks"]) == 0
    lines = modes.read_text().splitlines()
    assert lines[0] == MODES_HEADER
    table = np.loadtxt(modes, delimiter=",", skiprows=1, ndmin=2)
    options = SMALL_OPTIONS._replace(modes="meanshift", memory="tracks")
    model, params = hp.build("paper", options)
    info = hp.run(jax.random.key(0), seq, params, model).info
    ref_tracks = info.tracks
    assert tracks.read_text().splitlines()[0] == TRACKS_HEADER
    rows = np.loadtxt(tracks, delimiter=",", skiprows=1, ndmin=2)
    t_valid, slot = np.nonzero(np.asarray(ref_tracks.valid))
    assert rows.shape == (len(t_valid), 7) and len(rows) > 0
    np.testing.assert_array_equal(rows[:, 0], t_valid)
    np.testing.assert_array_equal(rows[:, 1], np.asarray(ref_tracks.id)[t_valid, slot])
    np.testing.assert_allclose(rows[:, 2], np.asarray(ref_tracks.age)[t_valid, slot], atol=1e-3)
    np.testing.assert_allclose(rows[:, 3:], np.asarray(ref_tracks.mean)[t_valid, slot], atol=2e-6)
    ref = info.modes
    valid = np.asarray(ref.valid)
    assert table.shape == (int(valid.sum()), 8)
    t, j = table[:, 0].astype(int), table[:, 1].astype(int)
    assert np.all(valid[t, j])
    np.testing.assert_allclose(table[:, 2], np.asarray(ref.weight)[t, j], atol=2e-6)
    np.testing.assert_allclose(table[:, 3:5], np.asarray(ref.mean)[t, j], atol=2e-6)
    cov = np.asarray(ref.cov)[t, j]
    np.testing.assert_allclose(table[:, 5:], np.stack([cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]], 1), atol=2e-6)
    np.testing.assert_allclose(np.bincount(t, table[:, 2]), 1.0, atol=1e-4)  # weights sum to 1 per step
