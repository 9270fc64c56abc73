"""``heatpf tune`` and ``--params``: the tuned file holds every parameter; run/eval/sweep read it, --set on top.

One real (tiny) tuning runs once per module; every other test stops before any compilation (checks) or
replaces ``tune`` by a stand-in, so the module stays within a few seconds beyond that one compilation.
"""

import contextlib
import io
import json

import jax
import numpy as np
import pytest

import heatpf_jax as hp
import heatpf_jax.cli.sweep
import heatpf_jax.evaluate
import heatpf_jax.io.sequence
import heatpf_jax.sim
import heatpf_jax.tuning
from heatpf_jax import params as P
from heatpf_jax.cli import main
from heatpf_jax.io.params_file import FORMAT, load_params_file, save_params_file
from heatpf_jax.sim import simulate_standard
from tests.conftest import SMALL_OPTIONS

SMALL_ARGS = sum((["--set", f"{n}={getattr(SMALL_OPTIONS, n)}"] for n in ("num_particles", "max_measurements",
                                                                            "k_max")), [])
# The default method, at test_run's sizes on its sequence's shapes: `run` reuses test_run's compilation.
METHOD = "heatmap"
OTHER = "paper"


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


@pytest.fixture(scope="module")
def tuned(tmp_path_factory):
    """One tiny real tuning: 2 gradient steps of every trainable parameter on two 20-step sequences.

    The sequences, filter seeds and burn-in are those of tests/test_tuning.py, whose `tune` then reuses this
    compiled gradient (one compilation per model, loss, burn-in and shapes, whatever is tuned)."""
    root = tmp_path_factory.mktemp("tune")
    seq = simulate_standard(3, num_steps=20, shrink=4)  # the shapes of conftest's small_sequence
    seq_path, seq2_path, out = root / "seq.npz", root / "seq2.npz", root / "tuned.json"
    hp.save_sequence(seq_path, seq)
    hp.save_sequence(seq2_path, simulate_standard(4, num_steps=20, shrink=4))
    argv = ["tune", str(seq_path), str(seq2_path), "--steps", "2", "--filter-seeds", "2", "--burn-in", "10",
            "--lr", "0.2", "-o", str(out), *SMALL_ARGS]
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        assert main(argv) == 0
    return {"root": root, "seq": seq, "seq_path": seq_path, "out": out, "stdout": stdout.getvalue(),
            "stderr": stderr.getvalue()}


class _Reached(Exception):
    """Raised by a stand-in where the work would start: every check before it passed."""


def _must_not_run(*args, **kwargs):
    raise AssertionError("work started before the checks")


def _reached(*args, **kwargs):
    raise _Reached


def _one_error_line(capsys) -> str:
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err + captured.out
    return lines[0]


@pytest.fixture
def no_work(monkeypatch):
    for module, name in ((heatpf_jax.io.sequence, "load_sequence"), (heatpf_jax.sim, "simulate"),
                         (heatpf_jax.tuning, "tune")):
        monkeypatch.setattr(module, name, _must_not_run)


def test_tune_writes_every_parameter_and_its_history(tuned):
    record = json.loads(tuned["out"].read_text())
    model, defaults = hp.build(METHOD, SMALL_OPTIONS)
    names = P.leaf_names(model.properties())
    assert record["format"] == FORMAT and record["version"] == 1 and record["method"] == METHOD
    assert record["options"]["num_particles"] == SMALL_OPTIONS.num_particles
    assert set(record["options"]) == set(hp.FilterOptions._fields)
    assert list(record["params"]) == names
    assert record["tuned"] == hp.trainable_names(model)  # the default: every trainable parameter
    assert record["loss"] == "mse" and len(record["history"]) == 2 and np.all(np.isfinite(record["history"]))
    assert record["validation"] == [] and record["validation_steps"] == [] and record["seconds"] > 0
    for name, value in zip(names, jax.tree.leaves(defaults), strict=True):
        if name in record["tuned"]:
            assert len(record["path"][name]) == 3
            assert record["path"][name][-1] == pytest.approx(record["params"][name], rel=1e-6)
            assert record["start"][name] == pytest.approx(float(value), rel=1e-6)
        else:  # frozen: as given
            assert record["params"][name] == pytest.approx(float(value), rel=1e-6)
    moved = [n for n in record["tuned"] if record["params"][n] != pytest.approx(record["start"][n], rel=1e-4)]
    assert moved  # two steps with --lr 0.2 move the parameters
    printed = tuned["stdout"]
    assert f"training loss: {record['history'][0]:.6g} at step 0" in printed
    assert all(n in printed for n in record["tuned"]) and f"wrote {tuned['out']}" in printed
    loaded = load_params_file(tuned["out"])
    assert loaded.method == METHOD and loaded.options == SMALL_OPTIONS and loaded.params == record["params"]


def test_tune_names_every_parameter_that_never_moved(tuned):
    """A static robot gives the odometry noises no gradient: each parameter whose path stayed at its start value
    gets one warning line, and no other parameter does."""
    record = json.loads(tuned["out"].read_text())
    still = sorted(n for n in record["tuned"] if len(set(record["path"][n])) == 1)
    warned = sorted(line.split("--tune: ")[1].split(" kept")[0] for line in tuned["stderr"].splitlines()
                    if line.startswith("heatpf: warning: --tune: "))
    assert "odom_rot_noise" in " ".join(still)  # the static robot's odometry is zero
    assert warned == still


def test_run_with_params_equals_run_with_set_and_set_goes_on_top(tuned, tmp_path):
    record = json.loads(tuned["out"].read_text())
    seq_path = str(tuned["seq_path"])
    as_set = sum((["--set", f"{n}={v!r}"] for n, v in record["params"].items()), [])
    from_file, by_set = tmp_path / "file.csv", tmp_path / "set.csv"
    assert main(["run", seq_path, "--params", str(tuned["out"]), "-o", str(from_file)]) == 0  # --method: the file's
    assert main(["run", seq_path, "--method", METHOD, "-o", str(by_set), *SMALL_ARGS, *as_set]) == 0
    assert from_file.read_text() == by_set.read_text()
    # --set goes on top of the file (a short name over the file's dotted one), as it does on the defaults.
    over, over_set = tmp_path / "over.csv", tmp_path / "over_set.csv"
    assert main(["run", seq_path, "--params", str(tuned["out"]), "--method", METHOD, "--set", "diffusion_std=0.5",
                 "-o", str(over)]) == 0
    assert main(["run", seq_path, "--method", METHOD, "-o", str(over_set), *SMALL_ARGS, *as_set,
                 "--set", "diffusion_std=0.5"]) == 0
    assert over.read_text() == over_set.read_text() != from_file.read_text()


def test_eval_and_sweep_read_the_file(tuned, monkeypatch, capsys):
    seen = {}

    def capture(name, sequences, **kwargs):
        seen.update(kwargs)
        raise _Reached

    monkeypatch.setattr(heatpf_jax.evaluate, "evaluate_sequences", capture)
    out, seq_path = str(tuned["out"]), str(tuned["seq_path"])
    record = json.loads(tuned["out"].read_text())
    with pytest.raises(_Reached):
        main(["eval", "--input", seq_path, "--params", out, "--method", METHOD, "--method", OTHER,
              "--set", "aging=0.5"])
    assert seen["options"] == SMALL_OPTIONS  # the file's static options, for every method
    assert seen["settings"] == {"aging": 0.5}  # --set, for every method
    by_name = {v.name: v for v in seen["variants"]}
    model, params = hp.build(METHOD, SMALL_OPTIONS)
    p = P.set_by_name(params, model.properties(), by_name[METHOD].overrides)  # the file's row: --set on top
    assert float(p.buffer.aging) == 0.5
    assert float(p.motion.diffusion_std) == np.float32(record["params"]["motion.diffusion_std"])
    assert by_name[OTHER].overrides == {} and by_name["paper, v=1 (no memory)"].overrides == {"aging": 1.0}
    # A sweep takes the file's parameters beneath --set and its --grid on top (a name in both is fine).
    monkeypatch.setattr(heatpf_jax.io.sequence, "load_sequence", _reached)
    with pytest.raises(_Reached):
        main(["sweep", seq_path, "--params", out, "--grid", "diffusion_std=0.1,0.2", "-o",
              str(tuned["root"] / "sweep.csv")])
    capsys.readouterr()


def test_method_mismatch_is_refused_in_one_line(tuned, capsys, no_work, tmp_path):
    out, seq_path = str(tuned["out"]), str(tuned["seq_path"])
    csv = str(tmp_path / "x.csv")
    cases = [
        (["run", seq_path, "--params", out, "--method", OTHER, "-o", csv],
         f"--params: {out} holds parameters of method {METHOD}, not {OTHER}"),
        (["sweep", seq_path, "--params", out, "--method", OTHER, "--grid", "k=1,2", "-o", csv],
         f"--params: {out} holds parameters of method {METHOD}, not {OTHER}"),
        (["eval", "--input", seq_path, "--params", out, "--method", OTHER],
         f"--params: {out} holds parameters of method {METHOD}, which --method leaves out"),
        (["tune", seq_path, "--params", out, "--method", OTHER, "-o", str(tmp_path / "t.json")],
         f"--params: {out} holds parameters of method {METHOD}, not {OTHER}"),
    ]
    for argv, start in cases:
        assert main(argv) == 2, argv
        assert _one_error_line(capsys).startswith(f"heatpf: error: {start}")


def test_malformed_params_files_name_the_file_and_field(tuned, tmp_path, capsys, no_work):
    good = json.loads(tuned["out"].read_text())
    bad = tmp_path / "bad.json"

    def edited(**changes):
        record = {**good, **changes}
        return json.dumps({k: v for k, v in record.items() if v is not None})

    cases = [
        ("{not json", "not JSON"),
        ("[1, 2]", "expected a JSON object"),
        (edited(format="something"), "format: expected 'heatpf-params'"),
        (edited(version=2), "version: expected 1, got 2"),
        (edited(method="nope"), "method: expected one of"),
        (edited(params=None), "params: missing"),
        (edited(params={**good["params"], "motion.nope": 1.0}), "params.motion.nope: not a parameter of method"),
        (edited(params={**good["params"], "motion.diffusion_std": -1.0}), "params.motion.diffusion_std: must be"),
        (edited(params={**good["params"], "observation.k": 1.5}), "params.observation.k: expected an integer"),
        (edited(params={**good["params"], "observation.k": 9}), "params.observation.k: must be"),  # > k_max 8
        (edited(params={**good["params"], "buffer.aging": "0.3"}), "params.buffer.aging: expected a number"),
        (edited(options={"num_particles": 0}), "options.num_particles: must be a positive integer"),
        (edited(options={"particles": 5}), "options.particles: not a static option"),
        (edited(options={"spawn_box": [0, 1]}), "options.spawn_box: expected [x_min"),
    ]
    out = tmp_path / "x.csv"
    for text, problem in cases:
        bad.write_text(text)
        assert main(["run", str(tuned["seq_path"]), "--params", str(bad), "-o", str(out)]) == 2, problem
        line = _one_error_line(capsys)
        assert line.startswith(f"heatpf: error: --params: {bad}: {problem}"), line
    assert main(["run", str(tuned["seq_path"]), "--params", str(tmp_path / "none.json"), "-o", str(out)]) == 2
    assert _one_error_line(capsys) == f"heatpf: error: --params: {tmp_path / 'none.json'}: no such file"
    assert not out.exists()


def test_tune_checks_every_argument_before_any_work(tuned, tmp_path, capsys, no_work):
    seq_path = str(tuned["seq_path"])
    out = str(tmp_path / "t.json")
    existing = tmp_path / "keep.json"
    existing.write_text("precious\n")
    base = ["tune", seq_path, "-o", out]
    cases = [
        (["tune", seq_path, "-o", str(existing)], f"--output: {existing} exists; pass --force"),
        ([*base, "--plot", str(existing)], f"--plot: {existing} exists; pass --force"),
        ([*base, "--plot", out, "--force"], f"--plot: {out} is also --output"),
        (["tune", seq_path, "-o", seq_path, "--force"], f"--output: {seq_path} is the input file"),
        ([*base, "--tune", "diffusion_std,nope"], "--tune: nope: not a parameter of method heatmap (trainable: "),
        ([*base, "--tune", "k"], "--tune: observation.k: frozen"),
        ([*base, "--method", "kalman"], "--method: kalman is no particle filter"),
        ([*base, "--set", "k=0"], "observation.k: "),
        ([*base, "--steps", "0"], "--steps: must be >= 1"),
        ([*base, "--lr", "nan"], "--lr: must be a positive number"),
        ([*base, "--filter-seeds", "0"], "--filter-seeds: must be >= 1"),
        ([*base, "--seeds", "2"], "--seeds: applies to --scenario"),
        ([*base, "--validate-seeds", "2"], "--validate-seeds: applies to --scenario"),
        ([*base, "--validate", str(tmp_path / "missing.npz")], f"{tmp_path / 'missing.npz'}: no such file"),
        (["tune", "-o", out], "tune: give INPUT.npz files or --scenario NAME"),
        ([*base, "--scenario", "split"], "tune: give INPUT.npz files or --scenario NAME"),
        (["tune", "--scenario", "nope", "-o", out], "--scenario: unknown 'nope'"),
        (["tune", "--scenario", "split", "--seeds", "3:3", "-o", out], "--seeds: "),
        (["tune", "--scenario", "split", "--validate-seeds", "0", "-o", out], "--validate-seeds: must be >= 1"),
        (["tune", "--scenario", "split", "--length", "10", "-o", out], "--burn-in: 10 leaves none of the 10"),
    ]
    for argv, start in cases:
        assert main(argv) == 2, argv
        line = _one_error_line(capsys)
        assert line.startswith(f"heatpf: error: {start}"), line
    assert existing.read_text() == "precious\n"
    assert not (tmp_path / "t.json").exists()
    with pytest.raises(SystemExit):
        main([*base, "--loss", "bogus"])
    assert "--loss" in capsys.readouterr().err


def test_tune_on_a_scenario_validates_on_the_next_seeds_and_plots(tuned, tmp_path, monkeypatch, capsys):
    """The stand-in ``tune`` receives what the command would tune; the file and the PNG follow its result."""
    simulated, given = [], {}
    seq = tuned["seq"]
    monkeypatch.setattr(heatpf_jax.sim, "simulate",
                        lambda name, seed, num_steps: simulated.append((name, seed, num_steps)) or seq)

    def fake_tune(key, sequences, init_params, model, **kwargs):
        given.update(kwargs, sequences=sequences, init_params=init_params)
        names = kwargs["names"]
        return hp.TuneResult(
            params=init_params, history=np.array([0.3, 0.2, 0.1]), validation=np.array([0.4, 0.25]),
            validation_steps=np.array([0, 3]), path={n: np.array([0.1, 0.2, 0.3, 0.4]) for n in names},
            names=names, seconds=1.5,
        )

    monkeypatch.setattr(heatpf_jax.tuning, "tune", fake_tune)
    out, png = tmp_path / "t.json", tmp_path / "loss.png"
    out.write_text("old\n")
    argv = ["tune", "--scenario", "split", "--seeds", "2", "--validate-seeds", "3", "--length", "20", "--steps",
            "3", "--tune", "diffusion_std", "--tune", "aging", "--set", "diffusion_std=0.3", "--loss", "nll",
            "--validate-every", "3", "-o", str(out), "--plot", str(png), "--force"]
    assert main(argv) == 0
    assert [s for _, s, _ in simulated] == [0, 1, 2, 3, 4]  # training 0, 1; validation right after: 2, 3, 4
    assert {(n, t) for n, _, t in simulated} == {("split", 20)}
    assert len(given["sequences"]) == 2 and len(given["validation"]) == 3
    assert given["names"] == ["motion.diffusion_std", "buffer.aging"] and given["loss"] == "nll"
    assert given["steps"] == 3 and given["validate_every"] == 3 and given["num_seeds"] == 2
    assert float(given["init_params"].motion.diffusion_std) == pytest.approx(0.3)  # --set: the starting point
    record = json.loads(out.read_text())
    assert record["validation"] == [0.4, 0.25] and record["validation_steps"] == [0, 3]
    assert record["history"] == [0.3, 0.2, 0.1] and record["loss"] == "nll" and record["method"] == "heatmap"
    assert record["training"]["seeds"] == "0:2" and record["training"]["validate_seeds"] == "2:5"
    assert record["start"]["motion.diffusion_std"] == pytest.approx(0.3)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "validation loss: 0.4 (step 0), 0.25 (step 3)" in printed
    assert "training loss: 0.3 at step 0, 0.1 at step 2" in printed and f"wrote {png}" in printed


def test_save_and_load_round_trip(tmp_path):
    options = hp.FilterOptions(num_particles=64, k_max=3, spawn_box=(-1.0, 2.0, -3.0, 4.0))
    model, params = hp.build("heatmap", options)
    params = P.set_by_name(params, model.properties(), {"diffusion_std": 0.123, "k": 3})
    path = tmp_path / "p.json"
    save_params_file(path, "heatmap", options, params, note="hand-made")
    loaded = load_params_file(path)
    assert loaded.options == options and loaded.info == {"note": "hand-made"}
    assert loaded.params["motion.diffusion_std"] == 0.123 and loaded.params["observation.k"] == 3
    assert isinstance(loaded.params["observation.k"], int)
    back = P.set_by_name(model.default_params(), model.properties(), loaded.params)
    for a, b in zip(jax.tree.leaves(back), jax.tree.leaves(params), strict=True):
        assert np.float32(a) == np.float32(b)  # float32 values survive the shortest text form
    with pytest.raises(ValueError, match="^params: reserved"):
        save_params_file(path, "heatmap", options, params, params={})


def test_sweep_and_tune_follow_the_files_settings(tuned, tmp_path, monkeypatch, capsys):
    """A sequence's settings (``heatpf colour``'s ``source=pixels``) reach the model of sweep and tune, beneath
    ``--set`` and the grid, with a line naming them; tune takes what every one of its files asks alike."""
    seq = tuned["seq"]
    a, b = tmp_path / "a.npz", tmp_path / "b.npz"
    hp.save_sequence(a, seq._replace(settings={"source": "pixels", "threshold": 0.5}))
    hp.save_sequence(b, seq._replace(settings={"source": "pixels", "threshold": 0.6}))
    seen = {}

    def stand_in(key, train, params, model, **kwargs):
        seen.update(model=model, params=params, names=kwargs["names"])
        raise _Reached

    monkeypatch.setattr(heatpf_jax.tuning, "tune", stand_in)
    with pytest.raises(_Reached):
        main(["tune", str(a), str(b), "--steps", "1", "-o", str(tmp_path / "t.json"), *SMALL_ARGS])
    assert "the sequence files: source=pixels from the sequence's settings" in capsys.readouterr().out
    assert isinstance(seen["model"].source, hp.sources.PixelSource)
    assert float(seen["params"].source.threshold) == pytest.approx(0.3)  # the files disagree on it: not applied

    def capture(args, out, model, sets, combos, todo, sequences, saved):
        seen.update(model=model, sets=sets)
        raise _Reached

    monkeypatch.setattr(heatpf_jax.cli.sweep, "_sweep_rows", capture)
    with pytest.raises(_Reached):
        main(["sweep", str(a), "--grid", "k=1,2", "--set", "threshold=0.4", "-o", str(tmp_path / "s.csv"),
              *SMALL_ARGS])
    printed = capsys.readouterr().out
    assert f"{a}: source=pixels from the sequence's settings" in printed
    assert "its threshold=0.5 not applied (the command line sets them)" in printed
    assert isinstance(seen["model"].source, hp.sources.PixelSource)
    assert [float(p.source.threshold) for p in seen["sets"]] == pytest.approx([0.4, 0.4])
    # A --params file holds every option and parameter: the file's settings give way to it.
    with pytest.raises(_Reached):
        main(["sweep", str(a), "--params", str(tuned["out"]), "--grid", "k=1,2", "-o", str(tmp_path / "p.csv")])
    assert (f"{a}: its source=pixels, threshold=0.5 not applied (the --params file gives the settings)"
            in capsys.readouterr().out)
    assert isinstance(seen["model"].source, hp.sources.LoftedSource)
