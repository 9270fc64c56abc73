"""What several ``heatpf`` subcommands share: their common options, the ``--params`` file, the error statistics.

The option helpers (:func:`add_set`, :func:`add_burn_in`, :func:`add_method`, :func:`add_params`) give ``run``,
``eval``, ``sweep``, ``tune``, ``demo`` and ``params`` the same option with the same help text;
:func:`checked_params_file` and :func:`settings_with_params` read ``--params`` and lay ``--set`` on top, checking
everything before any work; :func:`error_stats` is the error every command reports after ``--burn-in`` steps;
:func:`progress_bar` and :func:`table_lines` are the progress bar and the text tables they print. The ``--set``
parsing itself is :mod:`heatpf_jax.cli.settings`.
"""

from __future__ import annotations

import sys

import numpy as np

from heatpf_jax.cli.settings import LIST_PARAMS, checked_settings, layered_settings, method_names, method_with_settings
from heatpf_jax.evaluate import DEFAULT_BURN_IN
from heatpf_jax.io.files import check_input

__all__ = [
    "DEFAULT_BURN_IN",
    "INTERRUPTED",
    "add_burn_in",
    "add_method",
    "add_params",
    "add_set",
    "checked_params_file",
    "error_stats",
    "progress_bar",
    "settings_with_params",
    "table_lines",
]

INTERRUPTED = 130  # the shell's code for a command stopped by Ctrl-C (128 + SIGINT)


def error_stats(estimates: np.ndarray, truth: np.ndarray, burn_in: int = 0) -> dict[str, float]:
    """Mean, max and std of the Euclidean error after the first ``burn_in`` steps, metres (Table I's columns).

    The same definition as ``heatpf eval`` and ``heatpf demo`` (:meth:`heatpf_jax.evaluate.MethodResult.stats`).
    """
    err = np.linalg.norm(np.asarray(estimates, np.float64) - np.asarray(truth, np.float64), axis=1)[burn_in:]
    if err.size == 0:
        raise ValueError(f"burn_in: {burn_in} leaves no step of the {len(estimates)} steps")
    return {"mean": float(err.mean()), "max": float(err.max()), "std": float(err.std())}


# ------------------------------------------------------------------------------------------- --params


def checked_params_file(args):
    """The checked ``--params`` file (``None`` without one), every error naming ``--params`` and the file."""
    from heatpf_jax.io.params_file import load_params_file

    if getattr(args, "params", None) is None:
        return None
    try:
        check_input(args.params)
        return load_params_file(args.params)
    except ValueError as err:
        raise ValueError(f"--params: {err}") from None


def settings_with_params(args):
    """``(options, settings, set_settings)`` of run, sweep and tune: the ``--params`` file beneath ``--set``.

    ``args.method`` becomes the file's method when not given (heatpf's ``heatmap`` without a file); a
    different one is refused. ``settings`` are by dotted name, the file's values with ``--set``'s on top;
    ``set_settings`` are ``--set``'s alone. Everything is checked (ranges included) before any work.
    """
    from heatpf_jax.rollout import validate_params

    loaded = checked_params_file(args)
    if loaded is not None and args.method not in (None, loaded.method):
        raise ValueError(f"--params: {args.params} holds parameters of method {loaded.method}, not {args.method}; "
                         f"pass --method {loaded.method} or leave --method out")
    if args.method is None:
        args.method = "heatmap" if loaded is None else loaded.method
    options, set_settings = checked_settings(args, [args.method], None if loaded is None else loaded.options)
    if loaded is None:
        return options, set_settings, set_settings
    settings = layered_settings(args.method, options, loaded.params, set_settings)
    model, params = method_with_settings(args.method, options, settings)
    validate_params(params, model)
    return options, settings, set_settings


# -------------------------------------------------------------------------------------------- printing


def progress_bar(total: int):
    """A ``tqdm`` bar on stderr: live on a terminal, silent in logs and CI."""
    from tqdm import tqdm

    # disable=None: a live bar on a terminal, silence in logs and CI.
    return tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=False, mininterval=0.5, disable=None)


def table_lines(rows: list[tuple[str, ...]]) -> list[str]:
    """``rows`` (the first the header) as left-aligned columns, each line indented by two spaces."""
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


# ----------------------------------------------------------------------------------------------- options


def add_set(p, what: str = "a parameter") -> None:
    """``--set NAME=VALUE`` (repeatable) on ``p``; ``what`` says what a name may be."""
    p.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help=f"{what} (dotted, e.g. motion.diffusion_std, or its last part: diffusion_std) or a static option "
        f"(num_particles, resampler, ...), repeatable, e.g. --set k=3; {LIST_PARAMS}",
    )


def add_burn_in(p) -> None:
    """``--burn-in N`` on ``p``, default :data:`DEFAULT_BURN_IN` as in every command."""
    p.add_argument(
        "--burn-in",
        type=int,
        default=DEFAULT_BURN_IN,
        help=f"first steps left out of the error statistics (default {DEFAULT_BURN_IN}, as in every command)",
    )


def add_method(p, verb: str = "run", params_file: bool = False) -> None:
    """``--method NAME`` on ``p``; with ``params_file`` its default is the ``--params`` file's method."""
    default = "the --params file's method, else heatmap" if params_file else "heatmap"
    p.add_argument(
        "--method", choices=method_names(), default=None if params_file else "heatmap",
        help=f"filter method to {verb} (default {default})",
    )


def add_params(p) -> None:
    """``--params TUNED.json`` on ``p``: a parameter file beneath ``--set``."""
    p.add_argument(
        "--params", metavar="TUNED.json", help="start from a parameter file (`heatpf tune --output`): its "
        "parameters and static options; --set goes on top",
    )
