"""The ``heatpf`` parser and :func:`main`, the console script: each subcommand brings its own options.

The subcommands (``run``, ``eval``, ``sweep``, ``tune``, ``demo``, ``params``, ``colour``, ``import-rosbag``,
``simulate``, ``frame``) each live in a module of :mod:`heatpf_jax.cli` with an ``add_parser`` that registers
them, the options several share being :mod:`heatpf_jax.cli.options`. A user's files come first: every check
(settings, paths, burn-in, seeds) runs before anything is loaded, simulated or compiled; an existing output is
replaced only with ``--force`` (the input never). :func:`main` runs a subcommand inside JAX's persistent
compilation cache (:mod:`heatpf_jax.io.cache`), so that a second run of the same shapes starts fast, and turns
its errors into one ``heatpf: error: ...`` line and an exit code.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from heatpf_jax.cli import colour, demo, import_rosbag, params, run, simulate, sweep, tune
from heatpf_jax.cli import eval as eval_command  # the module of `heatpf eval`; `eval` alone is Python's
from heatpf_jax.cli.options import INTERRUPTED

__all__ = ["main"]


def _global_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the compilation cache (~/.cache/heatpf_jax/jax, or $HEATPF_CACHE_DIR; "
        "HEATPF_NO_CACHE=1 does the same)",
    )
    return parent


class _Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (``heatpf run: error: ...``), not a usage block."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _build_parser() -> argparse.ArgumentParser:
    from heatpf_jax import __version__

    parser = _Parser(
        prog="heatpf",
        description="Heat-map particle filter in Cartesian space (JAX).",
        epilog="Compiled programs are cached on disk (~/.cache/heatpf_jax/jax; $HEATPF_CACHE_DIR moves it), so a "
        "second run of the same shapes starts fast; --no-cache or HEATPF_NO_CACHE=1 turns that off.",
    )
    parser.add_argument(
        "--no-cache", dest="no_cache_global", action="store_true", help="as the subcommands' --no-cache"
    )
    parser.add_argument("--version", action="version", version=f"heatpf {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    parents = [_global_options()]
    # in the order `heatpf --help` lists them
    for command in (run, eval_command, sweep, tune, demo, params, colour, import_rosbag):
        command.add_parser(sub, parents)
    simulate.add_parsers(sub, parents)  # simulate and frame
    return parser


def _os_error_text(err: OSError) -> str:
    where = f"{err.filename}: " if err.filename else ""
    return f"{where}{err.strerror or err}"


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Shows a warning as one ``heatpf: warning: ...`` line on stderr (no source file, no line of code)."""
    print(f"heatpf: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``heatpf`` console script.

    Returns:
        0 on success; 2 after a one-line ``heatpf: error: ...`` on stderr; 130 when interrupted (Ctrl-C).
    """
    from heatpf_jax.io.cache import compilation_cache
    from heatpf_jax.io.sequence import SequenceError

    args = _build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            no_cache = getattr(args, "no_cache", False) or args.no_cache_global
            with compilation_cache(enabled=not no_cache) as cache_dir:
                args.cache_dir = cache_dir
                return args.func(args)
    except KeyboardInterrupt:
        print("heatpf: interrupted", file=sys.stderr)
        return INTERRUPTED
    except (SequenceError, ValueError, TypeError, RuntimeError) as err:
        print(f"heatpf: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `heatpf params | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as err:
        print(f"heatpf: error: {_os_error_text(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
