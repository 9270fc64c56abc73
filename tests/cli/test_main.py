"""The heatpf command as a whole: outputs replaced only with --force, every check before any work, help, Ctrl-C."""

import os
import tempfile
from pathlib import Path

import pytest

from heatpf_jax.cli import CSV_HEADER, main
from heatpf_jax.sim import SCENARIOS
from tests.cli.helpers import SMALL_ARGS, must_not_run, one_error_line


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


def test_existing_outputs_are_replaced_only_with_force(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.sim

    path, seq = seq_file
    out = tmp_path / "keep.csv"
    out.write_text("precious\n")
    monkeypatch.setattr(heatpf_jax.sim, "simulate", must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", must_not_run)
    for argv in (["run", str(path), "-o", str(out), *SMALL_ARGS], ["demo", "--steps", "12", "-o", str(out)]):
        assert main(argv) == 2
        assert one_error_line(capsys) == (
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
    import heatpf_jax.io.sequence
    import heatpf_jax.rollout
    import heatpf_jax.sim

    for module, name in ((heatpf_jax.io.sequence, "load_sequence"), (heatpf_jax.sim, "simulate"),
                         (heatpf_jax.rollout, "run")):
        monkeypatch.setattr(module, name, must_not_run)
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
        assert one_error_line(capsys).startswith(f"heatpf: error: {start}")
    assert a_file.read_text() == "mine\n" and not missing.parent.exists()

def test_burn_in_must_leave_steps_and_nothing_is_silently_ignored(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.rollout
    import heatpf_jax.sim

    monkeypatch.setattr(heatpf_jax.rollout, "run", must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate", must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", must_not_run)
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
        line = one_error_line(capsys)
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

def test_ctrl_c_exits_130_in_one_line_and_writes_nothing(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.io.sequence

    def interrupted(path):
        raise KeyboardInterrupt

    monkeypatch.setattr(heatpf_jax.io.sequence, "load_sequence", interrupted)
    out = tmp_path / "x.csv"
    assert main(["run", str(seq_file[0]), "-o", str(out)]) == 130
    assert one_error_line(capsys) == "heatpf: interrupted"
    assert not out.exists()
