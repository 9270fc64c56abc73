"""``heatpf run --plot``: the replayed state of a step is the run's own (against ``hp.run``'s final state), the
picture is written for a particle filter and for the Kalman filter, and bad ``--plot`` input is one line before
any work."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.cli import main
from heatpf_jax.cli.run_plot import default_step, state_at
from tests.cli.helpers import SMALL_ARGS
from tests.conftest import SMALL_OPTIONS

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


def test_state_at_the_last_step_is_runs_final_state(small_sequence):
    model, params = hp.build("heatmap", SMALL_OPTIONS)
    key = jax.random.key(7)
    final = hp.run(key, small_sequence, params, model).final_state
    got = state_at(key, small_sequence, params, model, small_sequence.num_steps - 1)
    np.testing.assert_allclose(got.particles.xy, final.particles.xy, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(np.exp(got.log_weights), np.exp(final.log_weights), rtol=1e-4, atol=1e-7)
    np.testing.assert_allclose(got.buffer.xy, final.buffer.xy, rtol=1e-5, atol=1e-5)


def test_default_step_is_the_last_with_a_heat_map():
    assert default_step(np.array([True, True, False, True, False])) == 3
    assert default_step(np.array([False, False])) == 1


@pytest.mark.parametrize("method", ["paper", "kalman"])
def test_run_plot_writes_the_picture(method, tmp_path, small_sequence, capsys):
    seq_path = tmp_path / "seq.npz"
    hp.save_sequence(seq_path, small_sequence)
    csv, png = tmp_path / "est.csv", tmp_path / "run.png"
    extra = SMALL_ARGS if method == "paper" else []
    assert main(["run", str(seq_path), "-o", str(csv), "--method", method, "--plot", str(png),
                 "--plot-step", "5", *extra]) == 0
    out = capsys.readouterr().out
    assert png.read_bytes()[:8] == PNG_MAGIC and f"wrote {png} (step 5)" in out
    assert csv.is_file()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--plot-step", "3"], "--plot-step: only with --plot"),
        (["--plot", "{png}", "--plot-step", "99"], "--plot-step: must be in [0, 19], got 99"),
        (["--plot", "{csv}"], "--plot: "),
        (["--plot", "{seq}"], "--plot: "),
    ],
)
def test_bad_plot_input_is_one_line_and_writes_nothing(extra, message, tmp_path, small_sequence, capsys,
                                                       monkeypatch):
    seq_path, csv, png = tmp_path / "seq.npz", tmp_path / "est.csv", tmp_path / "run.png"
    hp.save_sequence(seq_path, small_sequence)
    before = seq_path.read_bytes()
    monkeypatch.setattr("heatpf_jax.cli.run._run_filter", lambda *a: pytest.fail("work started before the checks"))
    names = {"png": png, "csv": csv, "seq": seq_path}
    assert main(["run", str(seq_path), "-o", str(csv), *[a.format(**names) for a in extra]]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"heatpf: error: {message}") and err.count("\n") == 1, err
    assert not csv.exists() and not png.exists() and seq_path.read_bytes() == before
