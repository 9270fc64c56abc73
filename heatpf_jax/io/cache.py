"""JAX's persistent compilation cache for the ``heatpf`` command: the second run of a shape starts fast.

Compiling the filter's ``lax.scan`` takes seconds; JAX can keep compiled programs on disk and load
them in the next process. The command turns this on (:func:`enable_compilation_cache`) before any JAX
work. Where the cache lives:

* ``$HEATPF_CACHE_DIR`` when set;
* else ``$XDG_CACHE_HOME/heatpf_jax/jax`` (an absolute ``XDG_CACHE_HOME``), else
  ``~/.cache/heatpf_jax/jax``.

``HEATPF_NO_CACHE=1`` (or ``heatpf --no-cache``) turns it off. A directory that cannot be written
gives one warning on stderr and the command runs on without the cache. The directory may be deleted
at any time; JAX fills it again.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
import sys
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = [
    "CACHE_DIR_ENV",
    "NO_CACHE_ENV",
    "cache_directory",
    "compilation_cache",
    "enable_compilation_cache",
    "run_estimates",
]

CACHE_DIR_ENV = "HEATPF_CACHE_DIR"
NO_CACHE_ENV = "HEATPF_NO_CACHE"
_OFF_VALUES = ("", "0", "false", "no", "off")
_warned: set[str] = set()
_SETTINGS = (
    "jax_compilation_cache_dir",
    "jax_persistent_cache_min_compile_time_secs",
    "jax_persistent_cache_min_entry_size_bytes",
)


def cache_directory(environ: Mapping[str, str] | None = None) -> Path | None:
    """The cache directory the environment asks for, or ``None`` when ``HEATPF_NO_CACHE`` turns it off.

    Args:
        environ: the environment (default ``os.environ``).

    Returns:
        ``$HEATPF_CACHE_DIR``, else ``$XDG_CACHE_HOME/heatpf_jax/jax`` (when absolute), else
        ``~/.cache/heatpf_jax/jax``; ``None`` when ``HEATPF_NO_CACHE`` is set to anything but
        empty, ``0``, ``false``, ``no`` or ``off``, or no home directory is known.
    """
    env = os.environ if environ is None else environ
    if env.get(NO_CACHE_ENV, "").strip().lower() not in _OFF_VALUES:
        return None
    if env.get(CACHE_DIR_ENV):
        return Path(env[CACHE_DIR_ENV]).expanduser()
    xdg = env.get("XDG_CACHE_HOME", "")
    if xdg and Path(xdg).is_absolute():  # the XDG spec: a relative path is invalid and ignored
        return Path(xdg) / "heatpf_jax" / "jax"
    home = env.get("HOME")
    try:
        base = Path(home) if home else Path.home()
    except RuntimeError:  # no home directory to be found
        return None
    return base / ".cache" / "heatpf_jax" / "jax"


def _unusable(directory: Path) -> str | None:
    """Why no file can be created in ``directory`` (created if missing), or ``None`` when one can."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".heatpf-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        return err.strerror or type(err).__name__
    return None


def enable_compilation_cache(directory: str | os.PathLike | None = None) -> Path | None:
    """Turns on JAX's persistent compilation cache in ``directory`` (default: :func:`cache_directory`).

    Every compiled program is kept (no minimum compile time or size). Call it before the first
    compilation; a later call with another directory moves the cache there.

    Args:
        directory: where to keep compiled programs; ``None`` for the environment's choice.

    Returns:
        The directory in use, or ``None`` when the cache stays off (turned off by ``HEATPF_NO_CACHE``,
        or the directory cannot be written: then one warning goes to stderr and nothing changes).
    """
    path = cache_directory() if directory is None else Path(directory).expanduser()
    if path is None:
        return None
    problem = _unusable(path)
    if problem is not None:
        if str(path) not in _warned:
            _warned.add(str(path))
            print(
                f"heatpf: warning: compilation cache off: cannot write in {path} ({problem}); "
                f"set {CACHE_DIR_ENV} to a writable directory, or {NO_CACHE_ENV}=1 to silence this",
                file=sys.stderr,
            )
        return None
    import jax
    from jax.experimental.compilation_cache import compilation_cache as jax_cache

    path = path.resolve()
    if jax.config.jax_compilation_cache_dir != str(path):
        jax.config.update("jax_compilation_cache_dir", str(path))
        jax_cache.reset_cache()  # JAX opens its cache once per process: reopen it here
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


@contextlib.contextmanager
def compilation_cache(
    enabled: bool = True, directory: str | os.PathLike | None = None
) -> Iterator[Path | None]:
    """:func:`enable_compilation_cache` for the duration of a block; JAX's cache settings are restored after it.

    The ``heatpf`` command runs inside this, so calling its ``main()`` from Python (a notebook, the
    tests) leaves the process's JAX configuration as it found it; :class:`~heatpf_jax.tracker.Tracker`
    compiles its step inside it.

    Args:
        enabled: ``False`` leaves the cache as it is (``--no-cache``).
        directory: where to keep compiled programs; ``None`` (default) for the environment's choice
            (:func:`cache_directory`).

    Yields:
        The directory in use, or ``None``.
    """
    if not enabled:
        yield None
        return
    import jax
    from jax.experimental.compilation_cache import compilation_cache as jax_cache

    saved = {name: getattr(jax.config, name) for name in _SETTINGS}
    try:
        yield enable_compilation_cache(directory)
    finally:
        if any(getattr(jax.config, name) != value for name, value in saved.items()):
            for name, value in saved.items():
                jax.config.update(name, value)
            jax_cache.reset_cache()


# --- Exported programs: a warm start without tracing -------------------------------------------------------------

_EXPORTS = "exports"
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")


def _source_digest() -> str:
    """sha256 of every module of the package: a program exported by other code is never loaded."""
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parent
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _program_key(model, treedef, args) -> str:
    """What a compiled estimates program depends on: versions, source, model, input structure, shapes, device."""
    import jax
    import numpy as np

    device = jax.devices()[0]
    parts = (
        jax.__version__,
        getattr(jax.lib, "__version__", ""),
        _source_digest(),
        _ADDRESS.sub("", repr(model)),
        _ADDRESS.sub("", str(treedef)),
        [(tuple(np.shape(a)), str(np.asarray(a).dtype)) for a in args],
        device.platform,
        getattr(device, "device_kind", ""),
    )
    return hashlib.sha256(repr(parts).encode()).hexdigest()


def run_estimates(key, sequence, params, model, directory: str | os.PathLike | None):
    """``run(key, sequence, params, model).info``'s ``mean``, ``cov``, ``modes`` and ``tracks`` as NumPy arrays,
    from an exported program: ``(mean [T, 2], cov [T, 2, 2], modes, tracks)`` with ``modes`` a
    :class:`~heatpf_jax.estimate.modes.Modes` and ``tracks`` a
    :class:`~heatpf_jax.memory.table.TrackTable` of NumPy arrays
    with a leading ``T`` axis.

    With a cache ``directory``, the traced and lowered run is kept as a serialized ``jax.export``
    program under ``directory/exports``, keyed by everything it depends on (JAX version, this
    package's source, the model, the input structure, shapes and dtypes, the device). A later process
    loads it instead of tracing the filter again, and JAX's persistent cache supplies the compiled
    executable: together they make a second ``heatpf run`` of the same shapes start in about half the
    time of the compilation cache alone. The estimates are those of :func:`heatpf_jax.run`, bit for
    bit. Without a directory, or when the program cannot be exported, loaded or written, this is
    plain :func:`heatpf_jax.run`.
    """
    import jax
    import numpy as np

    from heatpf_jax.io.files import write_atomic
    from heatpf_jax.rollout import prepare_run, run, run_core

    def plain():
        info = run(key, sequence, params, model).info
        return _numpy((info.mean, info.cov, *info.modes, *info.tracks))

    if directory is None:
        return plain()
    seq, arrays = prepare_run(sequence, params, model)
    leaves, treedef = jax.tree.flatten((seq, arrays))
    args = (np.asarray(jax.random.key_data(key)), *leaves)

    def estimates(key_data, *flat):
        s, p = jax.tree.unflatten(treedef, flat)
        info = run_core(jax.random.wrap_key_data(key_data), s, p, model).info
        return (info.mean, info.cov, *info.modes, *info.tracks)  # a plain tuple: exports keep standard pytrees

    path = Path(directory) / _EXPORTS / f"{_program_key(model, treedef, args)}.bin"
    exported = None
    try:
        from jax import export

        if path.is_file():
            try:
                exported = export.deserialize(bytearray(path.read_bytes()))
            except Exception:  # a damaged or foreign file: export again and replace it
                exported = None
        if exported is None:
            shapes = [jax.ShapeDtypeStruct(np.shape(a), np.asarray(a).dtype) for a in args]
            exported = export.export(jax.jit(estimates))(*shapes)
            blob = exported.serialize()
            path.parent.mkdir(parents=True, exist_ok=True)
            write_atomic(path, lambda fh: fh.write(blob), binary=True)
    except (ImportError, OSError):  # no flatbuffers, or the cache cannot be written: just run
        return plain() if exported is None else _call(exported, args)
    return _call(exported, args)


def _numpy(outputs):
    import numpy as np

    from heatpf_jax.estimate.modes import Modes
    from heatpf_jax.memory.table import TrackTable

    mean, cov, *rest = (np.asarray(x) for x in outputs)
    k = len(Modes._fields)
    return mean, cov, Modes(*rest[:k]), TrackTable(*rest[k:])


def _call(exported, args):
    return _numpy(exported.call(*args))
