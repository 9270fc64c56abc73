"""A user's files: checked before any work, written atomically, never confused with each other.

Writes go to a temporary file that is renamed into place (:func:`write_atomic`). The checks
(:func:`check_output`, :func:`check_output_dir`, :func:`check_input`) run before anything is loaded or
computed and fail with one line naming the path and the problem.
"""

from __future__ import annotations

import hashlib
import os
import stat
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import IO

__all__ = [
    "check_input",
    "check_output",
    "check_output_dir",
    "check_writable_dir",
    "same_file",
    "sha256_of",
    "write_atomic",
]


def write_atomic(path: str | os.PathLike, write: Callable[[IO], None], *, binary: bool = False) -> None:
    """Calls ``write(fh)`` on a temporary file beside ``path`` and renames it to ``path`` when it returns.

    A failure or an interruption (any exception, ``KeyboardInterrupt`` included) leaves ``path`` as it
    was and removes the temporary file: a reader never sees a half-written file.
    """
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", suffix=path.suffix + ".tmp")
    try:
        # mkstemp creates 0600; the result gets the mode a plain open() would give it (0666 less the umask),
        # or the mode of the file it replaces.
        os.fchmod(fd, _mode_for(path))
        with os.fdopen(fd, "wb" if binary else "w") as fh:
            write(fh)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


_UMASK_LOCK = threading.Lock()


def _mode_for(path: Path) -> int:
    """The permission bits a new file at ``path`` gets: those of the file it replaces, else 0666 & ~umask."""
    try:
        return stat.S_IMODE(path.stat().st_mode)
    except OSError:
        pass
    with _UMASK_LOCK:  # the umask can only be read by setting it
        umask = os.umask(0o022)
        os.umask(umask)
    return 0o666 & ~umask


def same_file(a: Path, b: str | os.PathLike) -> bool:
    """Whether two paths name one file (through symlinks, ``..`` or hard links)."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist: compare where they point
        return a.resolve() == Path(b).resolve()


def check_writable_dir(directory: Path, option: str) -> None:
    """Raises ``ValueError`` naming ``option`` unless a file can be created in ``directory``."""
    try:
        fd, probe = tempfile.mkstemp(dir=directory, prefix=".heatpf-probe-")
    except OSError as err:
        raise ValueError(f"{option}: cannot write in {directory} ({err.strerror})") from None
    os.close(fd)
    os.unlink(probe)


def check_output(option: str, path: str | os.PathLike, *, inputs=(), replace: bool = False) -> Path:
    """Checks an output file before any work: not an input, not a directory, in a writable directory.

    Args:
        option: the option's name, for messages (``--output``).
        path: the output file.
        inputs: input files it must not be (compared as files, not as strings).
        replace: an existing file may be replaced (``--force``, or a sweep that resumes it).

    Returns:
        ``path`` as a :class:`~pathlib.Path`.

    Raises:
        ValueError: one line naming the path and the problem.
    """
    path = Path(path)
    for source in inputs:
        if source is not None and same_file(path, source):
            raise ValueError(f"{option}: {path} is the input file; choose another {option}")
    if path.is_dir():
        raise ValueError(f"{option}: {path} is a directory; give a file name")
    parent = path.parent
    if not parent.exists():
        raise ValueError(f"{option}: {path}: the directory {parent} does not exist (create it first)")
    if not parent.is_dir():
        raise ValueError(f"{option}: {path}: {parent} is not a directory")
    if path.exists() and not replace:
        raise ValueError(f"{option}: {path} exists; pass --force to replace it, or choose another {option}")
    check_writable_dir(parent, option)
    return path


def check_output_dir(path: str | os.PathLike) -> Path:
    """Checks a ``--plot`` directory before any work: a directory (or creatable as one) that can be written."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise ValueError(f"--plot: {path} exists and is not a directory")
        check_writable_dir(path, "--plot")
        return path
    ancestor = next((p for p in path.parents if p.exists()), None)
    if ancestor is None or not ancestor.is_dir():
        raise ValueError(f"--plot: {path}: {ancestor} is not a directory")
    check_writable_dir(ancestor, "--plot")
    return path


def check_input(path: str | os.PathLike) -> Path:
    path = Path(path)
    if not path.exists():
        raise ValueError(f"{path}: no such file")
    if not path.is_file():
        raise ValueError(f"{path}: not a file")
    return path


def sha256_of(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
