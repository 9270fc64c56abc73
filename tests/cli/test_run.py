"""``heatpf run``: the documented CSVs (estimates, modes, tracks); a bad input or a failed run writes nothing."""

import os
import re
import shutil

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.cli import error_stats, main
from heatpf_jax.cli.run import CSV_HEADER, MODES_HEADER, TRACKS_HEADER
from tests.cli.helpers import SMALL_ARGS, one_error_line
from tests.conftest import SMALL_OPTIONS


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


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
    _assert_printed_stats(printed, 10, stats)
    # Same seed, same file: identical output (the filter is deterministic given the key); --burn-in moves the
    # statistics' first step.
    out2 = tmp_path / "est2.csv"
    assert main(["run", str(path), "-o", str(out2), "--seed", "1", "--burn-in", "3", *SMALL_ARGS]) == 0
    assert out.read_text() == out2.read_text()
    stats = error_stats(table[:, 1:3], seq.ground_truth, 3)
    _assert_printed_stats(capsys.readouterr().out, 3, stats)


def _assert_printed_stats(printed: str, burn_in: int, stats: dict) -> None:
    """The printed ``mean`` and ``max`` after ``burn_in`` are the CSV's to their 4 printed decimals, give or take the
    CSV's own rounding of the estimates (a value on a rounding boundary may print one unit either side)."""
    found = re.search(rf"error \[m\] after step {burn_in}: mean ([0-9.]+)  max ([0-9.]+)", printed)
    assert found, printed
    np.testing.assert_allclose([float(found[1]), float(found[2])], [stats["mean"], stats["max"]], atol=1.5e-4)


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
            assert one_error_line(capsys) == (
                f"heatpf: error: --output: {target} is the input file; choose another --output"
            )
            assert rec.read_bytes() == before

def test_run_writes_modes_and_tracks_csv_equal_to_the_runs(tmp_path, seq_file, capsys):
    path, seq = seq_file
    out, modes, tracks = tmp_path / "est.csv", tmp_path / "modes.csv", tmp_path / "tracks.csv"
    assert main(["run", str(path), "-o", str(out), "--modes", str(out), "--method", "paper", *SMALL_ARGS]) == 2
    assert "--modes" in capsys.readouterr().err and not out.exists()  # one file cannot be both
    assert main(["run", str(path), "-o", str(out), "--tracks", str(tracks), "--method", "paper", *SMALL_ARGS]) == 2
    assert one_error_line(capsys) == ("heatpf: error: --tracks: the filter has no long-term memory; "
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


def test_the_sequences_settings_apply_beneath_set(tmp_path, seq_file, capsys):
    """A sequence's own settings (``heatpf colour`` writes ``source=pixels``) are applied beneath ``--set``, with a
    line naming them: the estimates are those of the same settings given by ``--set``; a name the user sets keeps
    the user's value, a ``--params`` file keeps its own, and a setting a method does not use is said to be unused."""
    path, seq = seq_file
    advised = tmp_path / "advised.npz"
    hp.save_sequence(advised, seq._replace(settings={"source": "pixels", "threshold": 0.6}))

    def estimates(args):
        out = tmp_path / "est.csv"
        assert main(["run", *args, "-o", str(out), "--force", *SMALL_ARGS]) == 0
        return np.loadtxt(out, delimiter=",", skiprows=1), capsys.readouterr().out

    applied, printed = estimates([str(advised)])
    assert (f"{advised}: source=pixels, threshold=0.6 from the sequence's settings (--set NAME=VALUE overrides)"
            in printed)
    by_hand, printed = estimates([str(path), "--set", "source=pixels", "--set", "threshold=0.6"])
    assert "the sequence's settings" not in printed
    np.testing.assert_allclose(applied, by_hand, atol=1e-6)
    default, _ = estimates([str(path)])
    assert not np.allclose(applied, default, atol=1e-3)  # a threshold of 0.6 keeps fewer pixels
    mine, printed = estimates([str(advised), "--set", "threshold=0.3"])
    assert f"{advised}: source=pixels from the sequence's settings" in printed
    assert "its threshold=0.6 not applied (the command line sets them)" in printed
    pixels, _ = estimates([str(path), "--set", "source=pixels"])
    np.testing.assert_allclose(mine, pixels, atol=1e-6)
    assert main(["run", str(advised), "-o", str(tmp_path / "k.csv"), "--method", "kalman"]) == 0
    assert "its source=pixels not used by method kalman" in capsys.readouterr().out
    # A setting the method cannot take is one line naming the file, before any work; nothing is written.
    for settings, message in (({"threshold": 3.0}, "settings: source.threshold: must be in [0, 1], got 3.0"),
                              ({"source": "sky"}, "settings: source: must be one of")):
        bad = tmp_path / "bad.npz"
        hp.save_sequence(bad, seq._replace(settings=settings))
        assert main(["run", str(bad), "-o", str(tmp_path / "never.csv"), *SMALL_ARGS]) == 2
        assert f"{bad}: {message}" in one_error_line(capsys)
        assert not (tmp_path / "never.csv").exists()
