"""Sweeps: equal to vmapped single runs, bounded memory per chunk, identical on two devices, resumable CLI."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.cli import main, parse_grid
from heatpf_jax.sweep import _sweep_jit, batch_size_of, sweep, sweep_memory
from tests.conftest import SMALL_FILTER, SMALL_OPTIONS

ROOT = Path(__file__).resolve().parents[1]
SMALL_ARGS = [
    "--set", f"num_particles={SMALL_OPTIONS.num_particles}",
    "--set", f"max_measurements={SMALL_OPTIONS.max_measurements}",
    "--set", f"k_max={SMALL_OPTIONS.k_max}",
    "--method", "paper",  # SMALL_FILTER's method, so that runs share its compilation
]


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    """The tests never write into the user's compilation cache."""
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


def _batch():
    sets = [
        SMALL_FILTER.make_params(k=k, threshold=t, diffusion_std=d)
        for k in (1, 4)
        for t in (0.3, 0.5)
        for d in (0.1, 0.2)
    ]
    return hp.stack_params(sets[:7])  # 7: not a multiple of the chunk, exercises padding


def test_sweep_equals_vmapped_runs_for_every_chunk(small_sequence, small_filter):
    batch = _batch()
    key = jax.random.key(4)
    ref = jax.vmap(lambda p: hp.run(key, small_sequence, p, small_filter).info)(batch)
    for chunk in (3, None):  # a remainder chunk (7 = 3 + 3 + 1) and one chunk of all
        out = sweep(key, small_sequence, batch, small_filter, chunk=chunk)
        assert out.mean.shape == (7, small_sequence.num_steps, 2)
        np.testing.assert_allclose(np.asarray(out.mean), np.asarray(ref.mean), rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(np.asarray(out.cov), np.asarray(ref.cov), rtol=1e-4, atol=1e-6)
    # Different parameter sets give different answers (the batch axis is really used).
    assert np.abs(np.asarray(out.mean[0]) - np.asarray(out.mean[5])).max() > 1e-3


def test_sweep_groups_sets_by_k_and_returns_the_callers_order(small_sequence, small_filter):
    """Sets run sorted by k (chunks of similar k run fewer selection rounds); results come back in order."""
    sets = [small_filter.make_params(k=k, threshold=t) for k, t in ((6, 0.3), (1, 0.5), (4, 0.3), (1, 0.3), (6, 0.5))]
    batch = hp.stack_params(sets)
    key = jax.random.key(5)
    ref = jax.vmap(lambda p: hp.run(key, small_sequence, p, small_filter).info)(batch)
    out = sweep(key, small_sequence, batch, small_filter, chunk=2)
    np.testing.assert_allclose(np.asarray(out.mean), np.asarray(ref.mean), rtol=1e-5, atol=1e-5)
    np.testing.assert_array_equal(np.asarray(out.num_valid), np.asarray(ref.num_valid))


def test_sweep_compiles_once_for_repeated_calls(small_sequence, small_filter):
    batch = _batch()
    sweep(jax.random.key(0), small_sequence, batch, small_filter, chunk=2)
    before = _sweep_jit._cache_size()
    other = jax.tree.map(lambda v: v[::-1], batch)  # new values, same shapes
    sweep(jax.random.key(1), small_sequence, other, small_filter, chunk=2)
    assert _sweep_jit._cache_size() == before


def test_peak_memory_grows_with_chunk_not_batch(small_sequence, small_filter):
    key = jax.random.key(0)
    small = hp.stack_params([small_filter.make_params(k=1 + i % 4) for i in range(8)])
    big = hp.stack_params([small_filter.make_params(k=1 + i % 4) for i in range(32)])
    m_small = sweep_memory(key, small_sequence, small, small_filter, chunk=2)
    m_big = sweep_memory(key, small_sequence, big, small_filter, chunk=2)
    m_chunk = sweep_memory(key, small_sequence, big, small_filter, chunk=8)
    # Temporaries: independent of the batch at a fixed chunk, and larger for a larger chunk.
    assert m_big.temp_bytes <= 1.1 * m_small.temp_bytes
    assert m_chunk.temp_bytes > 2 * m_big.temp_bytes


def test_batch_axis_errors():
    with pytest.raises(ValueError, match="params_batch"):
        batch_size_of(SMALL_FILTER.default_params())
    model = hp.paper_filter(hp.FilterOptions(k_max=8))
    with pytest.raises(ValueError, match=r"^observation\.k: "):
        bad = hp.stack_params([model.make_params(k=1), model.make_params(k=99)])
        sweep(jax.random.key(0), None, bad, model)


def test_two_devices_give_identical_results(small_sequence, small_filter, tmp_path):
    batch = _batch()
    key = jax.random.key(2)
    one = np.asarray(sweep(key, small_sequence, batch, small_filter, chunk=2).mean)
    np.save(tmp_path / "one.npy", one)
    script = textwrap.dedent(f"""
        import jax, numpy as np
        assert len(jax.devices()) == 2, jax.devices()
        import heatpf_jax as hp
        from heatpf_jax.sim import simulate_standard
        from heatpf_jax.sweep import sweep
        from tests.test_sweep import _batch
        from tests.conftest import SMALL_FILTER
        seq = simulate_standard(3, num_steps=20, shrink=4)
        two = np.asarray(sweep(jax.random.key(2), seq, _batch(), SMALL_FILTER, chunk=2).mean)
        one = np.load({str(tmp_path / "one.npy")!r})
        np.testing.assert_allclose(two, one, rtol=1e-5, atol=1e-5)
        print("identical on", len(jax.devices()), "devices")
    """)
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2", PYTHONPATH=str(ROOT))
    proc = subprocess.run(
        [sys.executable, "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "identical on 2 devices" in proc.stdout


def _free_port() -> int:
    import socket

    with socket.socket() as sock:
        sock.bind(("localhost", 0))
        return sock.getsockname()[1]


def test_two_processes_as_two_hosts_give_identical_results(small_sequence, small_filter, tmp_path):
    """The multi-host path for real: two processes joined by ``jax.distributed.initialize`` (gloo
    collectives over localhost), one CPU device each; the mesh spans both, results are gathered to both."""
    batch = _batch()
    one = np.asarray(sweep(jax.random.key(2), small_sequence, batch, small_filter, chunk=2).mean)
    np.save(tmp_path / "one.npy", one)
    port = _free_port()
    script = textwrap.dedent(f"""
        import sys
        import jax
        pid = int(sys.argv[1])
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        jax.distributed.initialize(coordinator_address="localhost:{port}", num_processes=2, process_id=pid,
                                   initialization_timeout=120)
        assert jax.process_count() == 2 and len(jax.devices()) == 2 and len(jax.local_devices()) == 1
        import numpy as np
        from heatpf_jax.sim import simulate_standard
        from heatpf_jax.sweep import sweep
        from tests.test_sweep import _batch
        from tests.conftest import SMALL_FILTER
        seq = simulate_standard(3, num_steps=20, shrink=4)
        out = np.asarray(sweep(jax.random.key(2), seq, _batch(), SMALL_FILTER, chunk=2, devices=jax.devices()).mean)
        np.save({str(tmp_path)!r} + f"/host{{pid}}.npy", out)
        print("process", pid, "of", jax.process_count(), "done")
    """)
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["PYTHONPATH"] = str(ROOT)
    procs = [
        subprocess.Popen([sys.executable, "-c", script, str(pid)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
        for pid in (0, 1)
    ]
    outs = [proc.communicate(timeout=300) for proc in procs]
    for pid, (proc, (stdout, stderr)) in enumerate(zip(procs, outs, strict=True)):
        assert proc.returncode == 0, f"process {pid}: {stderr[-3000:]}"
        assert f"process {pid} of 2 done" in stdout
    host0, host1 = np.load(tmp_path / "host0.npy"), np.load(tmp_path / "host1.npy")
    np.testing.assert_array_equal(host0, host1)  # both hosts hold the whole gathered result
    np.testing.assert_allclose(host0, one, rtol=1e-5, atol=1e-5)


def test_parse_grid_errors():
    assert parse_grid(["k=1,3", "aging=0.1,0.2"]) == {"k": [1, 3], "aging": [0.1, 0.2]}
    for bad, field in [
        (["num_particles=10,20"], "num_particles: a static option cannot be swept"),
        (["nope=1"], "nope: not a parameter of method heatmap"),
        (["k=1", "k=2"], "k"),
        (["threshold=x"], "threshold"),
        (["k"], "--grid"),
    ]:
        with pytest.raises(ValueError) as info:
            parse_grid(bad)
        assert str(info.value).startswith(field)


def _counting(monkeypatch, fail_on_call: int | None = None, fake: bool = False) -> list[int]:
    """Replaces the sweep the CLI calls by one that counts its calls (and computes, unless ``fake``)."""
    import heatpf_jax.sweep

    calls = []
    real = heatpf_jax.sweep.sweep

    def counted(key, seq, batch, model, **kwargs):
        calls.append(batch_size_of(batch))
        if len(calls) == fail_on_call:
            raise KeyboardInterrupt
        if fake:  # no compilation: errors equal to the ground truth's distance from the origin
            return SimpleNamespace(mean=np.zeros((calls[-1], seq.num_steps, 2)))
        return real(key, seq, batch, model, **kwargs)

    monkeypatch.setattr(heatpf_jax.sweep, "sweep", counted)
    return calls


def _body(text: str) -> list[str]:
    """The CSV without its record (the # lines)."""
    return [line for line in text.splitlines() if not line.startswith("#")]


def test_cli_sweep_writes_ranks_and_resumes(tmp_path, small_sequence, small_filter, capsys, monkeypatch):
    path = tmp_path / "seq.npz"
    hp.save_sequence(path, small_sequence)
    out = tmp_path / "sweep.csv"
    args = ["sweep", str(path), "-o", str(out), "--grid", "k=1,2,3", "--grid", "diffusion_std=0.1,0.2",
            "--batch-size", "2", *SMALL_ARGS]
    assert main(args) == 0
    full = out.read_text()
    lines = _body(full)
    assert lines[0] == "index,k,diffusion_std,mean_error,max_error,std_error" and len(lines) == 7
    record = [line for line in full.splitlines() if line.startswith("# ")]
    assert f"# heatpf_jax = {hp.__version__}" in record and "# option.num_particles = 128" in record
    assert "# param.motion.odom_trans_noise = 0.1" in record  # fixed parameters are recorded, grid ones are not
    assert not any(line.startswith(("# param.observation.k ", "# param.motion.diffusion_std ")) for line in record)
    # Each row's error is that of a single run with those parameters (same key).
    row = lines[4].split(",")
    params = small_filter.make_params(k=int(row[1]), diffusion_std=float(row[2]))
    info = hp.run(jax.random.key(0), small_sequence, params, small_filter).info
    err = np.linalg.norm(np.asarray(info.mean, np.float64) - small_sequence.ground_truth, axis=1)[10:]
    assert float(row[3]) == pytest.approx(err.mean(), rel=1e-4, abs=1e-6)
    printed = capsys.readouterr().out
    best = min(lines[1:], key=lambda r: float(r.split(",")[3]))
    assert printed.split("best of 6")[1].splitlines()[2].split() == best.split(",")[1:]

    # The same command on the finished file computes nothing and leaves it byte for byte.
    calls = _counting(monkeypatch)
    assert main(args) == 0
    assert calls == [] and out.read_text() == full

    # Interrupted: the last two rows lost and one cut in half. Resuming recomputes only those (one call of 2).
    head = full[: full.index(lines[5])]
    out.write_text(head + lines[5][:7])
    assert main(args) == 0
    assert calls == [2]
    assert "(4 already in" in capsys.readouterr().out
    resumed = _body(out.read_text())
    assert resumed[:5] == lines[:5]  # finished rows untouched, the cut row dropped
    assert sorted(resumed[1:], key=lambda r: int(r.split(",")[0])) == lines[1:]

    # A different sweep into the same file is refused, and the file is kept.
    before = out.read_bytes()
    assert main(["sweep", str(path), "-o", str(out), "--grid", "aging=0.1,0.2"]) == 2
    assert "--output" in capsys.readouterr().err
    assert out.read_bytes() == before and calls == [2]


def _refused(argv, out: Path, capsys, *differs: str) -> None:
    before = out.read_bytes()
    assert main(argv) == 2, argv
    captured = capsys.readouterr()
    err = captured.err.splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err + captured.out, captured.err
    assert err[0].startswith(f"heatpf: error: --output: {out} holds the results of another sweep (")
    assert err[0].endswith("use another --output to start a new file")
    for name in differs:
        assert f"({name}: " in err[0] or f"; {name}: " in err[0], err[0]
    assert out.read_bytes() == before


def test_cli_sweep_never_resumes_another_question_on_a_file(tmp_path, small_sequence, capsys, monkeypatch):
    path = tmp_path / "seq.npz"
    hp.save_sequence(path, small_sequence)
    other = tmp_path / "other.npz"  # same shapes, another recording
    hp.save_sequence(other, small_sequence._replace(ground_truth=small_sequence.ground_truth + 0.5))
    out = tmp_path / "sweep.csv"
    base = ["sweep", str(path), "-o", str(out), "--grid", "k=1,2", "--batch-size", "2", *SMALL_ARGS]
    calls = _counting(monkeypatch, fake=True)
    assert main(base) == 0 and calls == [2]
    capsys.readouterr()
    _refused([*base, "--set", "diffusion_std=0.3"], out, capsys, "param.motion.diffusion_std")
    _refused([*base, "--set", "resampler=residual"], out, capsys, "option.resampler")
    i = base.index(f"max_measurements={SMALL_OPTIONS.max_measurements}")
    conventional = base[: i - 1] + base[i + 1 :]  # without --set max_measurements: an option it does not use
    _refused([*conventional, "--method", "conventional"], out, capsys, "method")
    _refused([*base, "--seed", "1"], out, capsys, "seed")
    _refused([*base, "--burn-in", "5"], out, capsys, "burn_in")
    _refused(["sweep", str(other), *base[2:]], out, capsys, "input_sha256")
    _refused(["sweep", "--scenario", "standard", "--steps", "12", *base[2:]], out, capsys, "input_sha256", "scenario")
    assert calls == [2]  # nothing was computed for a refused command
    # The same question resumes, even under another path to the same content.
    moved = tmp_path / "moved.npz"
    moved.write_bytes(path.read_bytes())
    full = out.read_bytes()
    assert main(["sweep", str(moved), *base[2:]]) == 0
    assert calls == [2] and out.read_bytes() == full
    # --set with a parameter's default value asks the same question.
    assert main([*base, "--set", f"diffusion_std={hp.build('paper')[1].motion.diffusion_std}"]) == 0
    assert calls == [2] and out.read_bytes() == full
    # A file that holds no record is never taken over.
    notes = tmp_path / "notes.csv"
    notes.write_text("index,k,mean_error,max_error,std_error\n0,1,0.1,0.2,0.3\n")
    assert main([*base[:3], str(notes), *base[4:]]) == 2
    assert "holds no record of the sweep" in capsys.readouterr().err
    assert notes.read_text() == "index,k,mean_error,max_error,std_error\n0,1,0.1,0.2,0.3\n"


def test_cli_sweep_never_resumes_another_question_on_a_scenario(tmp_path, capsys, monkeypatch):
    import heatpf_jax.sim

    out = tmp_path / "sweep.csv"
    base = ["sweep", "--scenario", "standard", "--steps", "12", "--seeds", "2", "-o", str(out), "--grid", "k=1,2",
            "--batch-size", "2", *SMALL_ARGS]
    calls = _counting(monkeypatch, fake=True)
    assert main(base) == 0 and calls == [2, 2]  # one call per seed
    capsys.readouterr()

    def no_simulation(*args, **kwargs):
        raise AssertionError("simulated before the check")

    monkeypatch.setattr(heatpf_jax.sim, "simulate", no_simulation)
    _refused([*base, "--scenario", "split"], out, capsys, "scenario")
    _refused([*base, "--seeds", "1:3"], out, capsys, "seeds")
    _refused([*base, "--steps", "13"], out, capsys, "steps")
    assert calls == [2, 2]


def test_cli_sweep_ctrl_c_keeps_finished_rows_and_resumes(tmp_path, small_sequence, capsys, monkeypatch):
    path = tmp_path / "seq.npz"
    hp.save_sequence(path, small_sequence)
    out = tmp_path / "sweep.csv"
    args = ["sweep", str(path), "-o", str(out), "--grid", "k=1,2,3", "--grid", "aging=0.1,0.2", "--batch-size", "2",
            *SMALL_ARGS]
    calls = _counting(monkeypatch, fail_on_call=2, fake=True)
    assert main(args) == 130
    captured = capsys.readouterr()
    assert captured.err.splitlines()[-1] == f"interrupted: 2 rows saved in {out}; run the same command to resume"
    assert "Traceback" not in captured.err + captured.out
    assert [r.split(",")[0] for r in _body(out.read_text())[1:]] == ["0", "1"]
    calls = _counting(monkeypatch, fake=True)
    assert main(args) == 0
    assert calls == [2, 2]  # only the four missing rows
    assert sorted(int(r.split(",")[0]) for r in _body(out.read_text())[1:]) == list(range(6))


def test_idle_axes_names_only_the_axes_along_which_nothing_changes():
    """Hand-made 2 x 3 grid: the errors depend on k only, so aging is idle and k is not; a one-value axis is
    never reported, and a change in one group of rows is enough to keep an axis."""
    from heatpf_jax.cli.sweep import idle_axes

    names = ["k", "aging", "threshold"]
    values = [[k, a, "0.3"] for k in ("1", "3") for a in ("0.3", "0.45", "0.6")]
    errors = [[0.1 * int(v[0]), 0.5, 0.01] for v in values]
    assert idle_axes(names, values, errors) == ["aging"]
    errors[4] = [0.3, 0.51, 0.01]  # k=3, aging=0.45 differs: aging matters somewhere
    assert idle_axes(names, values, errors) == []
    assert idle_axes(["k"], [["1"], ["3"]], [[0.2, 0.4, 0.1], [0.2, 0.4, 0.1 + 1e-12]]) == ["k"]
