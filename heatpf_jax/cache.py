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
import os
import sys
import tempfile
from collections.abc import Iterator, Mapping
from pathlib import Path

__all__ = ["CACHE_DIR_ENV", "NO_CACHE_ENV", "cache_directory", "compilation_cache", "enable_compilation_cache"]

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
def compilation_cache(enabled: bool = True) -> Iterator[Path | None]:
    """:func:`enable_compilation_cache` for the duration of a block; JAX's cache settings are restored after it.

    The ``heatpf`` command runs inside this, so calling its ``main()`` from Python (a notebook, the
    tests) leaves the process's JAX configuration as it found it.

    Args:
        enabled: ``False`` leaves the cache as it is (``--no-cache``).

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
        yield enable_compilation_cache()
    finally:
        if any(getattr(jax.config, name) != value for name, value in saved.items()):
            for name, value in saved.items():
                jax.config.update(name, value)
            jax_cache.reset_cache()
