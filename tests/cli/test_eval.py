"""``heatpf eval``: Table I and the figures per scenario or recording; its options checked before any work."""

import pytest

import heatpf_jax as hp
from heatpf_jax.cli import main
from tests.cli.helpers import must_not_run, one_error_line


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


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
    assert "the sequence's settings" not in out
    advised = tmp_path / "advised.npz"  # paper's source is already the pixels: a setting that changes nothing
    hp.save_sequence(advised, seq._replace(settings={"source": "pixels"}))
    assert main(["eval", "--input", str(advised), "--method", "paper", "--method", "kalman", *small]) == 0
    assert f"{advised}: its source=pixels not used by any of the methods run" in capsys.readouterr().out
    nogt = tmp_path / "nogt.npz"
    hp.save_sequence(nogt, seq._replace(ground_truth=None))
    assert main(["eval", "--input", str(nogt)]) == 2
    assert "ground_truth" in capsys.readouterr().err
    assert main(["eval", "--scenario", "nope"]) == 2
    assert "--scenario" in capsys.readouterr().err

def test_eval_checks_its_options_before_any_work(tmp_path, seq_file, capsys, monkeypatch):
    import heatpf_jax.sim

    monkeypatch.setattr(heatpf_jax.sim, "simulate", must_not_run)
    monkeypatch.setattr(heatpf_jax.sim, "simulate_with_info", must_not_run)
    path, _ = seq_file
    for argv, start in [
        (["eval", "--input", str(path), "--seeds", "3"], "--seeds: applies to the simulated scenarios"),
        (["eval", "--scenario", "split", "--seeds", "4:4"], "--seeds: "),
        (["eval", "--scenario", "split", "--steps", "10"], "--burn-in: 10 leaves none of the 10 steps"),
        (["eval", "--scenario", "split", "--steps", "30", "--burn-in", "-1"], "--burn-in: must be >= 0"),
    ]:
        assert main(argv) == 2
        assert one_error_line(capsys).startswith(f"heatpf: error: {start}")
