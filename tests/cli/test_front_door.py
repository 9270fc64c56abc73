"""Every ``heatpf`` subcommand through its front door: ``main([...])`` on tiny inputs, exit 0, a sensible output file.

One call per subcommand (:data:`FRONT_DOORS`), under ``umask 022`` so each file it writes must come out
``0644`` (``write_atomic`` once left them ``0600``); a subcommand the parser knows but this table lacks fails
:func:`test_every_subcommand_has_a_front_door_test`. Beside them: ``python -m heatpf_jax.cli import-rosbag``
with and without ``--no-cache`` (it once crashed on a missing ``no_cache`` attribute), ``--version``, one-line
usage errors, and the warning for a ``.npz`` archive named ``.npy``.

The inputs and options are those of tests/cli/test_run.py, test_eval.py, test_tune.py and test_colour.py,
tests/test_sweep.py and tests/io/test_rosbag_import.py (same shapes, same static options), so in the full suite
every compiled program but ``demo``'s is reused.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shutil
import stat
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.cli import error_stats, main
from heatpf_jax.cli.parser import _build_parser
from heatpf_jax.cli.run import CSV_HEADER, MODES_HEADER, TRACKS_HEADER
from heatpf_jax.cli.settings import method_names
from heatpf_jax.io.files import write_atomic
from heatpf_jax.io.params_file import load_params_file
from heatpf_jax.sim import simulate, simulate_standard
from tests.cli.helpers import SMALL_ARGS

REPO = Path(__file__).resolve().parents[2]
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


@contextlib.contextmanager
def _umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


# ------------------------------------------------------------------------------------------------ inputs


class Inputs(NamedTuple):
    """The tiny inputs every front door reads (in their own directory, apart from the outputs)."""

    seq_path: Path  # simulate_standard(3, 20 steps, shrink 4): conftest's small_sequence
    seq: hp.Sequence
    seq2_path: Path  # simulate_standard(4, ...): test_tune's second training sequence
    rgb_path: Path  # 4 RGB frames of the standard scenario, shrink 4 (test_colour)
    rgb: hp.Sequence


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Inputs:
    root = tmp_path_factory.mktemp("front_door_inputs")
    seq = simulate_standard(3, num_steps=20, shrink=4)
    rgb = simulate("standard", 0, num_steps=4, shrink=4, rgb=True)
    paths = root / "seq.npz", root / "seq2.npz", root / "rgb.npz"
    hp.save_sequence(paths[0], seq)
    hp.save_sequence(paths[1], simulate_standard(4, num_steps=20, shrink=4))
    hp.save_sequence(paths[2], rgb)
    return Inputs(paths[0], seq, paths[1], paths[2], rgb)


class Bag(NamedTuple):
    path: Path
    sim: hp.Sequence  # the sequence the bag was written from
    topics: list[str]  # the import-rosbag options naming its topics


@pytest.fixture(scope="module")
def bag(tmp_path_factory) -> Bag:
    """test_rosbag_import's mcap bag (12 steps of the walking scenario, shrink 4), default layout."""
    pytest.importorskip("rosbags")
    from tests.io import test_rosbag_import as rb

    sim = simulate("walking", 4, num_steps=rb.NUM_STEPS, shrink=4)
    path = rb.write_bag(tmp_path_factory.mktemp("front_door_bag") / "bag", sim, rb.Spec())
    topics = ["--heatmap-topic", rb.HEATMAP, "--camera-info-topic", rb.INFO, "--odom-topic", rb.ODOM,
              "--ground-truth-topic", rb.TRUTH]
    return Bag(path, sim, topics)


# ----------------------------------------------------------------------------------------- front doors


class FrontDoor(NamedTuple):
    """One subcommand's call: its argv, and a check of its stdout and outputs returning the files it wrote."""

    argv: list[str]
    check: Callable[[str], list[Path]]


def _csv_table(path: Path, header: str, columns: int) -> np.ndarray:
    lines = path.read_text().splitlines()
    assert lines[0] == header
    table = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    assert table.shape == (len(lines) - 1, columns)
    assert np.all(np.isfinite(table))
    return table


def _run_argv(seq_path: Path, out: Path) -> list[str]:
    """test_run's run with --modes and --tracks (paper, memory=tracks, SMALL_ARGS): one compilation for both."""
    return ["run", str(seq_path), "-o", str(out / "est.csv"), "--modes", str(out / "modes.csv"), "--tracks",
            str(out / "tracks.csv"), "--method", "paper", *SMALL_ARGS, "--set", "memory=tracks"]


def _run(inp: Inputs, out: Path) -> FrontDoor:
    def check(stdout: str) -> list[Path]:
        est, modes, tracks = out / "est.csv", out / "modes.csv", out / "tracks.csv"
        n = inp.seq.num_steps
        table = _csv_table(est, CSV_HEADER, 6)
        assert table.shape[0] == n
        np.testing.assert_array_equal(table[:, 0], np.arange(n))
        assert np.all(table[:, 3] > 0) and np.all(table[:, 5] > 0)  # variances
        stats = error_stats(table[:, 1:3], inp.seq.ground_truth, 10)
        assert stats["mean"] < 0.5  # it tracks the ball (0.07 m when written)
        rows = _csv_table(modes, MODES_HEADER, 8)
        assert len(rows) >= n and set(rows[:, 0].astype(int)) <= set(range(n))
        np.testing.assert_allclose(np.bincount(rows[:, 0].astype(int), rows[:, 2]), 1.0, atol=1e-4)
        rows = _csv_table(tracks, TRACKS_HEADER, 7)
        assert len(rows) > 0 and set(rows[:, 0].astype(int)) <= set(range(n))
        assert all(f"wrote {p}" in stdout for p in (est, modes, tracks))
        return [est, modes, tracks]

    return FrontDoor(_run_argv(inp.seq_path, out), check)


def _eval(inp: Inputs, out: Path) -> FrontDoor:
    plots = out / "plots"

    def check(stdout: str) -> list[Path]:
        assert f"scenario seq: 1 sequence(s) x {inp.seq.num_steps} steps, errors after step 10" in stdout
        row = next(line for line in stdout.splitlines() if line.startswith("kalman"))
        assert float(row.split()[1]) < 0.5
        written = [plots / "seq_errors.png", plots / "seq_traces.png"]
        assert sorted(plots.iterdir()) == written
        assert all(p.read_bytes()[:8] == PNG_MAGIC and f"wrote {p}" in stdout for p in written)
        return written

    # kalman (no particle options) on test_run's sequence: test_eval's eval --input compiles the same program.
    return FrontDoor(["eval", "--input", str(inp.seq_path), "--method", "kalman", "--plot", str(plots)], check)


def _sweep(inp: Inputs, out: Path) -> FrontDoor:
    csv = out / "sweep.csv"

    def check(stdout: str) -> list[Path]:
        text = csv.read_text()
        record = [line for line in text.splitlines() if line.startswith("#")]
        body = [line for line in text.splitlines() if not line.startswith("#")]
        assert f"# heatpf_jax = {hp.__version__}" in record
        assert body[0] == "index,k,mean_error,max_error,std_error" and len(body) == 3
        table = np.array([[float(v) for v in line.split(",")] for line in body[1:]])
        np.testing.assert_array_equal(table[:, :2], [[0, 1], [1, 2]])
        assert np.all(np.isfinite(table[:, 2:])) and np.all(table[:, 2] <= table[:, 3])
        assert np.all(table[:, 2] < 0.5) and "best of 2 by mean error" in stdout
        return [csv]

    # test_sweep's grid size and batch: the same vmapped program.
    return FrontDoor(["sweep", str(inp.seq_path), "-o", str(csv), "--grid", "k=1,2", "--batch-size", "2",
                      *SMALL_ARGS], check)


def _tune(inp: Inputs, out: Path) -> FrontDoor:
    tuned, plot = out / "tuned.json", out / "loss.png"

    def check(stdout: str) -> list[Path]:
        record = json.loads(tuned.read_text())
        model, _ = hp.build("heatmap", hp.FilterOptions(num_particles=128, max_measurements=128, k_max=8))
        assert record["method"] == "heatmap" and record["options"]["num_particles"] == 128
        assert list(record["params"]) == P.leaf_names(model.properties())
        assert len(record["history"]) == 2 and np.all(np.isfinite(record["history"]))
        assert load_params_file(tuned).params == record["params"]
        assert plot.read_bytes()[:8] == PNG_MAGIC
        assert f"wrote {tuned}" in stdout and f"wrote {plot}" in stdout
        return [tuned, plot]

    # test_tune's tuning (two sequences, 2 steps, 2 filter seeds, burn-in 10): the same gradient program.
    return FrontDoor(["tune", str(inp.seq_path), str(inp.seq2_path), "--steps", "2", "--filter-seeds", "2",
                      "--burn-in", "10", "--lr", "0.2", "-o", str(tuned), "--plot", str(plot), *SMALL_ARGS], check)


DEMO_STEPS = 12


def _demo(inp: Inputs, out: Path) -> FrontDoor:
    csv = out / "demo.csv"

    def check(stdout: str) -> list[Path]:
        table = _csv_table(csv, CSV_HEADER, 6)
        np.testing.assert_array_equal(table[:, 0], np.arange(DEMO_STEPS))
        truth = simulate("standard", 0, num_steps=DEMO_STEPS).ground_truth  # the demo's sequence (seed 0)
        stats = error_stats(table[:, 1:3], truth, 2)
        row = next(line for line in stdout.splitlines() if line.startswith("heatmap "))
        assert float(row.split()[1]) == pytest.approx(stats["mean"], abs=6e-5)  # the table is of these estimates
        assert stats["mean"] < 0.5 and f"wrote {csv}" in stdout
        return [csv]

    return FrontDoor(["demo", "--steps", str(DEMO_STEPS), "--burn-in", "2", "-o", str(csv), *SMALL_ARGS], check)


def _params(inp: Inputs, out: Path) -> FrontDoor:
    def check(stdout: str) -> list[Path]:
        model, _ = hp.build("paper")
        assert stdout.startswith("parameters of paper")
        assert all(f"  {name} " in stdout for name in P.leaf_names(model.properties()))
        assert "num_particles" in stdout
        return []

    return FrontDoor(["params", "--method", "paper"], check)


def _colour(inp: Inputs, out: Path) -> FrontDoor:
    npz = out / "colour.npz"

    def check(stdout: str) -> list[Path]:
        got = hp.load_sequence(npz)
        assert got.heatmaps.shape == inp.rgb.heatmaps.shape and got.heatmaps.dtype == np.float32
        assert np.all((got.heatmaps >= 0) & (got.heatmaps <= 1)) and got.heatmaps.max() > 0
        np.testing.assert_array_equal(got.images, inp.rgb.images)
        np.testing.assert_array_equal(got.ground_truth, inp.rgb.ground_truth)
        assert f"wrote {npz}" in stdout
        return [npz]

    # test_colour's box and frame: the same compiled colour likelihood.
    return FrontDoor(["colour", str(inp.rgb_path), "--box", "20,10,4,4", "--frame", "1", "-o", str(npz)], check)


def _check_imported(path: Path, bag: Bag) -> None:
    got = hp.load_sequence(path)
    assert got.heatmaps.shape == bag.sim.heatmaps.shape and bool(np.all(got.has_heatmap))
    np.testing.assert_allclose(got.ground_truth, bag.sim.ground_truth, rtol=0, atol=1e-6)
    np.testing.assert_allclose(got.cam_to_base, bag.sim.cam_to_base, rtol=0, atol=1e-6)
    assert np.abs(got.heatmaps - bag.sim.heatmaps).max() <= 0.5 / 255 + 1e-7  # mono8


def _import_rosbag(inp: Inputs, out: Path, bag: Bag) -> FrontDoor:
    npz = out / "bag.npz"

    def check(stdout: str) -> list[Path]:
        _check_imported(npz, bag)
        assert f"-> {npz}" in stdout
        return [npz]

    return FrontDoor(["import-rosbag", str(bag.path), *bag.topics, "-o", str(npz)], check)


def _simulate(inp: Inputs, out: Path) -> FrontDoor:
    npz = out / "sim.npz"

    def check(stdout: str) -> list[Path]:
        got = hp.load_sequence(npz)
        for name in ("heatmaps", "ground_truth", "cam_to_base", "odometry", "has_heatmap"):
            np.testing.assert_allclose(getattr(got, name), getattr(inp.seq, name), rtol=0, atol=1e-6, err_msg=name)
        assert got.images is None and f"wrote {npz}" in stdout
        return [npz]

    # The inputs' own sequence (simulate_standard(3, 20 steps, shrink 4)), from the command line.
    return FrontDoor(["simulate", "standard", "--seed", "3", "--steps", "20", "--shrink", "4", "-o", str(npz)], check)


def _frame(inp: Inputs, out: Path) -> FrontDoor:
    png = out / "frame.png"

    def check(stdout: str) -> list[Path]:
        assert png.read_bytes()[:8] == PNG_MAGIC
        height, width = inp.rgb.images.shape[1:3]
        assert f"step 1: RGB frame, {width} x {height} pixels" in stdout and f"wrote {png}" in stdout
        return [png]

    return FrontDoor(["frame", str(inp.rgb_path), "--step", "1", "-o", str(png)], check)


# Subcommand -> its front door. A factory takes the inputs and the output directory (and the bag if it asks
# for one: import-rosbag).
FRONT_DOORS: dict[str, Callable[..., FrontDoor]] = {
    "run": _run,
    "eval": _eval,
    "sweep": _sweep,
    "tune": _tune,
    "demo": _demo,
    "params": _params,
    "colour": _colour,
    "import-rosbag": _import_rosbag,
    "simulate": _simulate,
    "frame": _frame,
}


def _subcommands() -> set[str]:
    actions = [a for a in _build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    assert len(actions) == 1
    return set(actions[0].choices)


def test_every_subcommand_has_a_front_door_test():
    commands = _subcommands()
    assert {"run", "eval", "sweep", "tune", "demo", "params", "colour", "import-rosbag"} <= commands
    assert commands - set(FRONT_DOORS) == set(), "add a front door for these subcommands to FRONT_DOORS"
    assert set(FRONT_DOORS) - commands == set(), "these FRONT_DOORS are no subcommand any more"


@pytest.mark.parametrize("command", sorted(FRONT_DOORS))
def test_front_door(command, inputs, tmp_path, capsys, request):
    """Exit 0, the outputs as documented, each file (and nothing else) in the output directory, mode 0644."""
    out = tmp_path / "out"
    out.mkdir()
    extra = [request.getfixturevalue("bag")] if command == "import-rosbag" else []
    door = FRONT_DOORS[command](inputs, out, *extra)
    with _umask(0o022):
        code = main(door.argv)
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "Traceback" not in captured.err and "heatpf: error" not in captured.err
    written = door.check(captured.out)
    files = sorted(p for p in out.rglob("*") if p.is_file())
    assert files == sorted(written)  # no temporary file left behind
    assert {p.name: oct(_mode(p)) for p in files} == {p.name: oct(0o644) for p in files}


# ----------------------------------------------------------------------------------- python -m, --no-cache


@pytest.mark.parametrize("where", ["none", "global", "subcommand"])
def test_python_m_import_rosbag_with_and_without_no_cache(bag, tmp_path, where):
    out = tmp_path / "bag.npz"
    command = ["import-rosbag", str(bag.path), *bag.topics, "-o", str(out)]
    args = {"none": command, "global": ["--no-cache", *command], "subcommand": [*command, "--no-cache"]}[where]
    argv = [sys.executable, "-m", "heatpf_jax.cli", *args]
    env = {**os.environ, "HEATPF_NO_CACHE": "1"}
    with _umask(0o022):
        done = subprocess.run(argv, cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr == "" and f"-> {out}" in done.stdout
    _check_imported(out, bag)
    assert _mode(out) == 0o644


def test_python_m_runs_main():
    done = subprocess.run([sys.executable, "-m", "heatpf_jax.cli", "--version"], cwd=REPO, capture_output=True,
                          text=True, timeout=120)
    assert (done.returncode, done.stdout, done.stderr) == (0, f"heatpf {hp.__version__}\n", "")


# --------------------------------------------------------------------------------------------- write_atomic


@pytest.mark.parametrize("mode", [0o640, 0o664, 0o600, 0o444], ids=oct)
def test_write_atomic_keeps_the_mode_of_the_file_it_replaces(tmp_path, mode):
    path = tmp_path / "est.csv"
    path.write_text("old\n")
    path.chmod(mode)
    with _umask(0o022):
        write_atomic(path, lambda fh: fh.write("new\n"))
        assert os.umask(0o022) == 0o022  # the umask is left as it was
    assert path.read_text() == "new\n" and _mode(path) == mode
    assert [p.name for p in tmp_path.iterdir()] == ["est.csv"]


@pytest.mark.parametrize("mask, mode", [(0o027, 0o640), (0o022, 0o644), (0o002, 0o664), (0o077, 0o600)], ids=oct)
def test_write_atomic_gives_a_new_file_the_umask_mode(tmp_path, mask, mode):
    path = tmp_path / "new.npz"
    with _umask(mask):
        write_atomic(path, lambda fh: fh.write(b"\x00\x01"), binary=True)
        assert os.umask(mask) == mask
        plain = tmp_path / "plain"
        plain.write_bytes(b"")  # what open() gives under the same umask: the reference
    assert path.read_bytes() == b"\x00\x01"
    assert _mode(path) == mode == _mode(plain)


# ------------------------------------------------------------------------------------------- the parser


def test_version_prints_the_package_version(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0
    captured = capsys.readouterr()
    assert captured.out == f"heatpf {hp.__version__}\n" and captured.err == ""


def test_unknown_method_is_one_usage_line_listing_the_methods(tmp_path, capsys):
    out = tmp_path / "y.csv"
    with pytest.raises(SystemExit) as exit_:
        main(["run", str(tmp_path / "x.npz"), "-o", str(out), "--method", "nosuch"])
    assert exit_.value.code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and captured.err.endswith("\n"), captured.err
    line = lines[0]
    assert line.startswith("heatpf run: error: argument --method: invalid choice: 'nosuch'")
    assert line.endswith("(see heatpf run --help)")
    assert all(f"'{name}'" in line for name in ("heatmap", "paper", "kalman", *method_names()))
    assert not out.exists()


@pytest.mark.parametrize("argv, names", [
    (["nosuch"], ["heatpf: error: argument command: invalid choice: 'nosuch'", "'import-rosbag'"]),
    (["run", "x.npz"], ["heatpf run: error: the following arguments are required: --output/-o"]),
    (["sweep", "--batch-size", "two"], ["heatpf sweep: error: argument --batch-size: invalid int value: 'two'"]),
    (["import-rosbag", "bag"], ["heatpf import-rosbag: error: the following arguments are required: --heatmap-topic"]),
])
def test_usage_errors_are_one_line(capsys, argv, names):
    with pytest.raises(SystemExit) as exit_:
        main(argv)
    assert exit_.value.code == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert captured.out == "" and len(lines) == 1, captured.err
    assert all(n in lines[0] for n in names) and "usage:" not in lines[0]


# --------------------------------------------------------------------------------------- .npz named .npy


def test_npz_named_npy_warns_in_one_line_and_is_read(inputs, tmp_path, capsys):
    renamed = tmp_path / "seq.npy"
    shutil.copyfile(inputs.seq_path, renamed)
    (tmp_path / "npy").mkdir()
    (tmp_path / "npz").mkdir()
    assert main(_run_argv(renamed, tmp_path / "npy")) == 0  # the front door's run: no new compilation
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "warning" in line.lower()]
    assert len(warned) == 1, err
    assert warned[0].startswith("heatpf: warning: ") and str(renamed) in warned[0] and "'.npy'" in warned[0]
    assert "UserWarning" not in err and "warnings.warn" not in err  # not Python's two-line format
    # The same file under its own suffix: no warning, and the same estimates.
    assert main(_run_argv(inputs.seq_path, tmp_path / "npz")) == 0
    assert "warning" not in capsys.readouterr().err.lower()
    for name in ("est.csv", "modes.csv", "tracks.csv"):
        assert (tmp_path / "npy" / name).read_text() == (tmp_path / "npz" / name).read_text()


def test_eval_plot_with_methods_outside_the_papers_figures(inputs, tmp_path, capsys):
    """``eval --plot`` with only ``paper`` crashed after all the computing (``max() arg is an empty sequence``),
    leaving an empty plot directory; now the figures show the methods that ran, written like every output."""
    plots = tmp_path / "plots"
    with _umask(0o027):
        code = main(["eval", "--input", str(inputs.seq_path), "--method", "paper", "--plot", str(plots),
                     *SMALL_ARGS])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    written = [plots / "seq_errors.png", plots / "seq_traces.png"]
    assert sorted(plots.iterdir()) == written
    assert all(p.read_bytes()[:8] == PNG_MAGIC and _mode(p) == 0o640 for p in written)


def test_eval_family_prints_each_member_with_a_factor_breakdown(capsys):
    """``eval --family``: the member's table, named family/MEMBER, and a line per varying numeric factor."""
    from heatpf_jax.sim.family import draw_factors

    code = main(["eval", "--family", "--scenario", "standard", "--seeds", "2", "--steps", "12", "--method", "kalman"])
    out = capsys.readouterr().out
    assert code == 0
    assert "scenario family/standard: 2 sequence(s) x 12 steps" in out and "radial rms" in out
    drawn = [draw_factors("standard", s) for s in (0, 1)]
    varying = [n for n, v in drawn[0].items() if isinstance(v, int | float) and not isinstance(v, bool)
               and v != drawn[1][n]]
    breakdown = out.split("family/standard: mean error [m] with the factor at or below / above its median")[1]
    assert len(varying) > 10 and all(f"  {name} " in breakdown for name in varying)
