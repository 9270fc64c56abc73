"""The compilation cache: where it lives, that a second process loads from it, that failures never stop a command."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax

import heatpf_jax.cli.params as cli_params
from heatpf_jax.cli import main
from heatpf_jax.io.cache import cache_directory, compilation_cache, enable_compilation_cache

ROOT = Path(__file__).resolve().parents[2]
SETTINGS = (
    "jax_compilation_cache_dir",
    "jax_persistent_cache_min_compile_time_secs",
    "jax_persistent_cache_min_entry_size_bytes",
)


def _jax_settings() -> dict:
    return {name: getattr(jax.config, name) for name in SETTINGS}


def test_cache_directory_follows_the_environment():
    home = {"HOME": "/home/ada"}
    assert cache_directory(home) == Path("/home/ada/.cache/heatpf_jax/jax")
    assert cache_directory({**home, "XDG_CACHE_HOME": "/var/cache/ada"}) == Path("/var/cache/ada/heatpf_jax/jax")
    # The XDG spec: a relative XDG_CACHE_HOME is invalid and ignored.
    assert cache_directory({**home, "XDG_CACHE_HOME": "rel/cache"}) == Path("/home/ada/.cache/heatpf_jax/jax")
    env = {**home, "XDG_CACHE_HOME": "/var/cache/ada", "HEATPF_CACHE_DIR": "/scratch/jit"}
    assert cache_directory(env) == Path("/scratch/jit")
    for off in ("1", "yes", "true"):
        assert cache_directory({**env, "HEATPF_NO_CACHE": off}) is None
    for on in ("", "0", "false"):
        assert cache_directory({**env, "HEATPF_NO_CACHE": on}) == Path("/scratch/jit")


def test_an_unwritable_cache_directory_warns_once_and_changes_nothing(tmp_path, capsys):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory\n")
    before = _jax_settings()
    assert enable_compilation_cache(blocker / "cache") is None
    assert enable_compilation_cache(blocker / "cache") is None
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("heatpf: warning: compilation cache off: cannot write in ")
    assert str(blocker / "cache") in err[0]
    assert _jax_settings() == before
    assert blocker.read_text() == "not a directory\n"


def test_main_runs_inside_the_cache_and_restores_jax_settings(tmp_path, monkeypatch, capsys):
    """Every subcommand runs with the cache on (or off by --no-cache / HEATPF_NO_CACHE); main() leaves JAX as it was."""
    seen = []
    describe = cli_params.describe_method
    monkeypatch.setattr(cli_params, "describe_method", lambda *a: seen.append(_jax_settings()) or describe(*a))
    monkeypatch.setenv("HEATPF_CACHE_DIR", str(tmp_path / "jit"))
    monkeypatch.delenv("HEATPF_NO_CACHE", raising=False)
    before = _jax_settings()
    assert main(["params"]) == 0
    assert seen[-1] == {
        "jax_compilation_cache_dir": str((tmp_path / "jit").resolve()),
        "jax_persistent_cache_min_compile_time_secs": 0.0,
        "jax_persistent_cache_min_entry_size_bytes": 0,
    }
    assert _jax_settings() == before
    for argv in (["params", "--no-cache"], ["--no-cache", "params"]):
        assert main(argv) == 0
        assert seen[-1] == before
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")
    assert main(["params"]) == 0
    assert seen[-1] == before
    assert "observation.k" in capsys.readouterr().out


def test_the_context_leaves_settings_alone_when_disabled(tmp_path, monkeypatch):
    monkeypatch.setenv("HEATPF_CACHE_DIR", str(tmp_path / "jit"))
    before = _jax_settings()
    with compilation_cache(enabled=False) as directory:
        assert directory is None and _jax_settings() == before
    assert not (tmp_path / "jit").exists()


def test_a_second_process_loads_the_compiled_program_from_the_cache(tmp_path):
    script = textwrap.dedent("""
        import sys
        import jax, jax.numpy as jnp
        from heatpf_jax.io.cache import enable_compilation_cache
        hits = []
        jax.monitoring.register_event_listener(
            lambda event, **kw: hits.append(event) if event == "/jax/compilation_cache/cache_hits" else None)
        print("cache", enable_compilation_cache(sys.argv[1]))
        jax.jit(lambda x: jnp.sin(x) * 3.0 + x)(jnp.arange(5.0)).block_until_ready()
        print("hits", len(hits))
    """)
    cache = tmp_path / "jit"
    env = {k: v for k, v in os.environ.items() if not k.startswith("HEATPF_")}
    env["PYTHONPATH"] = str(ROOT)
    runs = [
        subprocess.run([sys.executable, "-c", script, str(cache)], cwd=ROOT, env=env, capture_output=True, text=True,
                       timeout=120)
        for _ in range(2)
    ]
    for proc in runs:
        assert proc.returncode == 0, proc.stderr[-2000:]
        assert f"cache {cache.resolve()}" in proc.stdout
    hits = [int(proc.stdout.split("hits ")[1]) for proc in runs]
    assert hits[0] == 0 and hits[1] >= 1  # the first process compiled and stored, the second loaded
    assert any(p.name.endswith("-cache") for p in cache.iterdir())


def test_no_cache_environment_turns_it_off(tmp_path, monkeypatch):
    monkeypatch.setenv("HEATPF_CACHE_DIR", str(tmp_path / "jit"))
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")
    before = _jax_settings()
    assert enable_compilation_cache() is None
    assert _jax_settings() == before and not (tmp_path / "jit").exists()


def test_exported_run_is_loaded_and_equals_run(tmp_path, small_sequence, monkeypatch):
    """The second process-equivalent call loads the exported program (no export) and gives run's estimates."""
    import jax
    import numpy as np
    from jax import export

    import heatpf_jax as hp
    from heatpf_jax.io.cache import _program_key, run_estimates
    from tests.conftest import SMALL_FILTER

    params = SMALL_FILTER.make_params(k=2)
    key = jax.random.key(4)
    ref = hp.run(key, small_sequence, params, SMALL_FILTER).info
    mean, cov, _, _ = run_estimates(key, small_sequence, params, SMALL_FILTER, tmp_path)
    files = list((tmp_path / "exports").iterdir())
    assert len(files) == 1
    # Two compilations of one program (exported and loaded, and jit's): equal up to float32 rounding (a run once
    # differed in the last bits here while other tests loaded the machine).
    np.testing.assert_allclose(mean, np.asarray(ref.mean), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(cov, np.asarray(ref.cov), rtol=1e-5, atol=1e-8)
    # Loaded, not exported again: exporting now would fail.
    monkeypatch.setattr(export, "export", lambda *a, **k: (_ for _ in ()).throw(AssertionError("exported again")))
    again, _, _, _ = run_estimates(key, small_sequence, params, SMALL_FILTER, tmp_path)
    np.testing.assert_array_equal(again, mean)
    # Another question (another model, other shapes) is another program's key: it never loads this one.
    monkeypatch.undo()
    args = (np.asarray(jax.random.key_data(key)), *jax.tree.leaves((small_sequence, params)))
    treedef = jax.tree.structure((small_sequence, params))
    assert _program_key(SMALL_FILTER, treedef, args) != _program_key(SMALL_FILTER._replace(num_particles=64), treedef,
                                                                      args)
    assert _program_key(SMALL_FILTER, treedef, args) != _program_key(SMALL_FILTER, treedef, (args[0], *(
        np.zeros((2, *np.shape(a)), np.asarray(a).dtype) if i == 0 else a for i, a in enumerate(args[1:]))))
    # A damaged file is replaced, with the same estimates.
    files[0].write_bytes(b"garbage")
    fixed, _, _, _ = run_estimates(key, small_sequence, params, SMALL_FILTER, tmp_path)
    np.testing.assert_array_equal(fixed, mean)
    assert files[0].read_bytes() != b"garbage"
