"""What the command-line tests share: the small filter's ``--set`` options and checks of a failed command.

``SMALL_ARGS`` gives ``heatpf run`` the sizes of ``tests.conftest.SMALL_OPTIONS``, so that it compiles what the
filter-level tests compile on the same shapes; the sequence file of those shapes is the ``seq_file`` fixture of
``tests/cli/conftest.py``.
"""

from tests.conftest import SMALL_OPTIONS

__all__ = ["SMALL_ARGS", "SMALL_SET", "must_not_run", "one_error_line"]

SMALL_SET = [f"{name}={getattr(SMALL_OPTIONS, name)}" for name in ("num_particles", "max_measurements", "k_max")]
SMALL_ARGS = sum((["--set", s] for s in SMALL_SET), [])


def must_not_run(*args, **kwargs):
    """A stand-in for where the work would start: a test fails if a command gets there."""
    raise AssertionError("work started before the checks")


def one_error_line(capsys) -> str:
    """The one line a failed command wrote on stderr, with no traceback anywhere."""
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert "Traceback" not in captured.err + captured.out
    return lines[0]
