"""``heatpf params``: a method's parameters (dotted names, values, allowed ranges, trainable or frozen) and options.

:func:`describe_method` is the text it prints: every parameter of the method with the defaults, a ``--params``
file's values or ``--set``'s on top, and every static option of :class:`heatpf_jax.presets.FilterOptions` with its
allowed values, marking those the method does not use. These are the names ``--set``, ``--grid`` and ``--tune``
take in the other subcommands.
"""

from __future__ import annotations

import argparse

from heatpf_jax.cli.options import add_method, settings_with_params, table_lines
from heatpf_jax.cli.settings import format_value, method_with_settings, option_alternatives, unused_options

__all__ = ["add_parser", "cmd_params", "describe_method"]


def _option_choices() -> dict[str, str]:
    from heatpf_jax.motion.ego import EGO_MOTIONS
    from heatpf_jax.observation.kernels import KNN_METHODS
    from heatpf_jax.presets import (
        MEMORIES,
        MODE_FINDERS,
        MOTIONS,
        OBSERVATIONS,
        RESAMPLERS,
        RESETTINGS,
        SOURCES,
        SPAWNS,
    )

    return {
        "resampler": "one of " + ", ".join(sorted(RESAMPLERS)),
        "spawn": "one of " + ", ".join(SPAWNS),
        "spawn_box": "x_min,x_max,y_min,y_max (metres)",
        "observation": "one of auto, " + ", ".join(OBSERVATIONS),
        "modes": "one of " + ", ".join(MODE_FINDERS),
        "knn": "one of " + ", ".join(KNN_METHODS),
        "ego": "one of " + ", ".join(EGO_MOTIONS),
        "memory": "one of " + ", ".join(MEMORIES),
        "source": "one of auto, " + ", ".join(SOURCES),
        "motion": "one of auto, " + ", ".join(MOTIONS),
        "resetting": "one of auto, " + ", ".join(RESETTINGS),
    }


def describe_method(method: str, options=None, settings: dict | None = None) -> str:
    """Every parameter of ``method`` (dotted name, value, allowed range, trainable or frozen) and the static options.

    Args:
        method: a name in ``heatpf_jax.presets.METHODS``.
        options: the static options (default :class:`~heatpf_jax.presets.FilterOptions()`).
        settings: ``{name: value}`` applied to the defaults first.

    Returns:
        The text ``heatpf params`` prints.
    """
    import jax

    from heatpf_jax import params as P
    from heatpf_jax.presets import FilterOptions

    options = FilterOptions() if options is None else options
    model, params = method_with_settings(method, options, settings or {})
    props = model.properties()
    rows = [("name", "value", "allowed", "tuning")]
    for name, value, prop in zip(
        P.leaf_names(props), jax.tree.leaves(params), jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param)),
        strict=True,
    ):
        rows.append((name, format_value(value), prop.describe(), "trainable" if prop.trainable else "frozen"))
    unused = {
        f for f in FilterOptions._fields
        if f in unused_options(FilterOptions()._replace(**{f: option_alternatives(f)[0]}), [method])
    }
    choices = _option_choices()
    o_rows = [("name", "value", "allowed")]
    for name, value in options._asdict().items():
        note = choices.get(name, "a positive integer")
        o_rows.append((name, format_value(value), note + (f" (not used by {method})" if name in unused else "")))
    first, value = rows[1][0], rows[1][1]
    return "\n".join([
        f"parameters of {method} (--set NAME=VALUE, or --grid NAME=V1,V2 in `heatpf sweep`; the last part of a",
        f"name is enough where it is unambiguous: --set {first.rsplit('.', 1)[-1]}={value} sets {first}):",
        *table_lines(rows),
        "static options (--set NAME=VALUE; each value compiles its own program, so they cannot be swept):",
        *table_lines(o_rows),
    ])


def cmd_params(args: argparse.Namespace) -> int:
    """Runs ``heatpf params`` on the parsed ``args``; returns the exit code (0)."""
    options, settings, _ = settings_with_params(args)
    print(describe_method(args.method, options, settings))
    return 0


def add_parser(sub, parents: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Registers ``params`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser."""
    p = sub.add_parser(
        "params", parents=parents, help="list a method's parameters (names, defaults, ranges) and the static options"
    )
    add_method(p, "describe", params_file=True)
    p.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="show the values with these settings (e.g. --set observation=gaussian)")
    p.add_argument("--params", metavar="TUNED.json", help="show the values of a parameter file "
                   "(`heatpf tune --output`), --set on top")
    p.set_defaults(func=cmd_params)
    return p
