"""Shared test settings: strict JAX promotion, small shared sizes so compiled functions are reused.

How the tests call JAX: every operation run outside ``jax.jit`` is a program of its own, compiled the first time its
shapes and parameters are seen (about 47 ms on a 2-core machine, plus about 15 ms of lowering); in JAX 0.10 that
includes ``jnp.asarray`` of a NumPy array, ``jnp.float32(x)``, indexing a JAX array and ``.at[].set()``. So a test
calls a library function through one module-level ``jax.jit`` (Python-valued arguments static), builds its inputs in
NumPy and converts results with ``np.asarray`` once; only tests about eager behaviour run eagerly. Written so, the
31 files converted in session 35 compiled 1 106 programs instead of 6 476 (each file run alone); the whole suite,
back to back on one clone of a 2-core machine (``python -m pytest -q -n auto``), took 579 s (user CPU 1115 s) against
689 s (1311 s) before.
"""

import os

# Compile without LLVM's optimisation passes: the suite's time is mostly XLA compiling programs it runs a few times
# (a `heatmap` run compiles in about 0.7 of the time and runs in about 2.5 times as long). Set before JAX starts its
# backend, and inherited by the xdist workers, the notebooks' kernels and the subprocesses tests start. Speed is
# measured in benchmarks/, with JAX's defaults. Tried and not kept (session 26): XLA's elemental emitters
# (``--xla_cpu_use_fusion_emitters=false``) compile faster still with -O0 but computed wrong k-nearest weights
# (tests/observation/test_kernels.py), and with -O2 tests/test_filter.py and tests/memory/test_tracks.py took 108 s of
# CPU against 67-71 s with -O0.
if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
    os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " --xla_backend_optimization_level=0").strip()

import jax  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# The tests never write JAX's persistent compilation cache into the user's cache directory.
os.environ.setdefault("HEATPF_NO_CACHE", "1")

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

import heatpf_jax as hp  # noqa: E402
from heatpf_jax.sim import simulate_standard  # noqa: E402

# One small filter shared by the filter-level tests, so `run` compiles once per shape.
SMALL_OPTIONS = hp.FilterOptions(num_particles=128, max_measurements=128, k_max=8)
SMALL_FILTER = hp.paper_filter(SMALL_OPTIONS)


_CACHE_ENV = "JAX_COMPILATION_CACHE_DIR"
_OWNED_CACHE: list[str] = []


def pytest_configure(config):
    """One JAX compilation cache for the whole run, in a temporary directory removed at its end.

    Set as environment variables by the first process (the controller under ``-n``), so the xdist workers, the
    notebooks' kernels and the subprocesses that tests start share it: a program that one worker compiled, or one
    that another test builds from new closures with the same shapes, is loaded instead of compiled again. Never
    the user's cache directory; a ``JAX_COMPILATION_CACHE_DIR`` already set is left as it is.

    Every program is cached, however quickly it compiled: a single operation run outside ``jit`` (a test calling a
    piece's function directly) is a program of its own, compiled in about 47 ms on a 2-core machine and loaded in
    about 7 ms (lowered to MLIR either way, about 10 ms); there are thousands of them. With the threshold at 0.3 s,
    the suite took 738-786 s (2 cores, ``-n 2``); with none, 655-680 s (session 34, the same machine).
    """
    import tempfile

    from tests.notebook_runs import SHARED_ENV

    if not os.environ.get(SHARED_ENV):  # the executed notebooks, for the worker that checks them
        path = tempfile.mkdtemp(prefix="heatpf-tests-shared-")
        _OWNED_CACHE.append(path)
        os.environ[SHARED_ENV] = path
    if not os.environ.get(_CACHE_ENV):
        path = tempfile.mkdtemp(prefix="heatpf-tests-jax-")
        _OWNED_CACHE.append(path)
        os.environ[_CACHE_ENV] = path
        os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
    jax.config.update("jax_compilation_cache_dir", os.environ[_CACHE_ENV])
    jax.config.update(
        "jax_persistent_cache_min_compile_time_secs",
        float(os.environ.get("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")),
    )


# Tests that compile the same programs (the command line's, tuning's and sweeping's on conftest's small shapes) run in
# one xdist worker (``--dist loadgroup``, pyproject.toml), which compiles each of them once.
_GROUPS = {
    "tests/cli/": "command-line",
    "tests/test_tuning.py": "command-line",
    "tests/test_sweep.py": "command-line",
    "tests/io/test_rosbag_import.py": "command-line",
    "tests/io/test_rosbag_export.py": "command-line",  # `heatpf run --bag` with SMALL_ARGS: test_run.py's program
}


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook reads the groups
def pytest_collection_modifyitems(config, items):
    for item in items:
        for prefix, group in _GROUPS.items():
            if item.nodeid.startswith(prefix):
                item.add_marker(pytest.mark.xdist_group(group))
                break


def pytest_sessionfinish(session):
    """The worker that executes the notebooks stays until they are published (tests/notebook_runs.py)."""
    if not session.config.option.collectonly:
        from tests.notebook_runs import wait

        wait()


def pytest_unconfigure(config):
    import shutil

    for path in _OWNED_CACHE:
        shutil.rmtree(path, ignore_errors=True)


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session):
    """Starts the notebooks in background kernels when their test is selected (tests/notebook_runs.py).

    At the start of the test loop, after ``-k``/``-m`` deselection and never for ``--collect-only``, so
    collecting or running other tests starts no kernel.
    """
    if session.config.option.collectonly:
        return
    if any("test_notebooks.py::test_notebook_executes" in item.nodeid for item in session.items):
        from tests.notebook_runs import start

        start()


@pytest.fixture(scope="session")
def small_filter() -> hp.Filter:
    return SMALL_FILTER


@pytest.fixture(scope="session")
def small_sequence() -> hp.Sequence:
    """20 steps of the standard scenario on a 50 x 37 heat map (shrink 4)."""
    return simulate_standard(3, num_steps=20, shrink=4)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


def step_inputs(seq: hp.Sequence, t: int, *, odometry=(0.0, 0.0, 0.0), has_heatmap: bool | None = None):
    """Step t of ``seq`` as one step's ``StepInputs`` (the given odometry; the file's has_heatmap unless given)."""
    import jax.numpy as jnp

    return hp.StepInputs(
        heatmap=jnp.asarray(seq.heatmaps[t], jnp.float32),
        has_heatmap=jnp.asarray(seq.has_heatmap[t] if has_heatmap is None else has_heatmap),
        cam_to_base=jnp.asarray(seq.cam_to_base[t], jnp.float32),
        odometry=jnp.asarray(odometry, jnp.float32),
        intrinsics=jnp.asarray(seq.intrinsics, jnp.float32),
        plane_height=jnp.asarray(seq.ball_radius, jnp.float32),
        dt=jnp.asarray(seq.dt, jnp.float32),
    )


def blank_inputs(odometry=(0.0, 0.0, 0.0), dt: float = 0.1, has_heatmap: bool = False):
    """One step's ``StepInputs`` for the pieces that read only the odometry, the period and whether a heat map came
    (a 2 x 2 blank heat map, an identity camera). NumPy: built with ``jnp`` each field would compile a program."""
    return hp.StepInputs(
        heatmap=np.zeros((2, 2), np.float32),
        has_heatmap=np.asarray(has_heatmap),
        cam_to_base=np.eye(4, dtype=np.float32),
        odometry=np.asarray(odometry, np.float32),
        intrinsics=np.ones(4, np.float32),
        plane_height=np.float32(0.0),
        dt=np.float32(dt),
    )
