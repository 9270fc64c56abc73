"""Settings by name for the command line: ``--set``, ``--grid``, ``--seeds``, ``--burn-in``.

A name is a static option (:class:`~heatpf_jax.presets.FilterOptions`) or a parameter of a method,
dotted (``motion.diffusion_std``) or by its last part where that is unambiguous. Everything here
checks before any data is loaded, simulated or compiled, and fails with one line naming the setting.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "ALIASES",
    "LIST_PARAMS",
    "check_burn_in",
    "checked_settings",
    "format_value",
    "full_name",
    "grid_config",
    "layered_settings",
    "method_names",
    "method_with_settings",
    "option_fields",
    "param_of",
    "parse_grid",
    "parse_seeds",
    "parse_settings",
    "parse_value",
    "scenario_names",
    "sequence_settings",
    "unused_options",
]

# Names of earlier versions, still accepted by --set and --grid.
ALIASES = {"kalman_accel_std": "accel_std", "kalman_meas_std": "meas_std"}
LIST_PARAMS = "list them with `heatpf params --method NAME`"


def method_names() -> list[str]:
    from heatpf_jax.presets import METHODS

    return list(METHODS)


def scenario_names() -> tuple[str, ...]:
    from heatpf_jax.sim import SCENARIOS

    return SCENARIOS


def option_fields() -> tuple[str, ...]:
    from heatpf_jax.presets import FilterOptions

    return FilterOptions._fields


def param_of(name: str, methods, options, typed: str | None = None):
    """The :class:`~heatpf_jax.params.Param` that ``name`` refers to in the first of ``methods`` that has it.

    ``typed`` is the name as the user wrote it (a legacy alias), for the error message.
    """
    import jax

    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    if name == "method":
        raise ValueError(
            f"method: not a parameter; choose the method with --method NAME (one of {', '.join(method_names())}) "
            "in `heatpf run` and `heatpf sweep`; `heatpf eval` and `heatpf demo` run every method"
        )
    known = []
    for method in methods:
        props = build(method, options).model.properties()
        names = P.leaf_names(props)
        full = P.resolve_name(name, names)
        if full is not None:
            return jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))[names.index(full)]
        known += [n for n in names if n not in known]
    where = f"method {methods[0]}" if len(methods) == 1 else "any method"
    raise ValueError(f"{typed or name}: not a parameter of {where} (known: {', '.join(known)}; static options: "
                     f"{', '.join(option_fields())}; {LIST_PARAMS})")


def full_name(name: str, method: str, options) -> str:
    """The dotted name of ``name`` (short or dotted, or an alias) among ``method``'s parameters."""
    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    names = P.leaf_names(build(method, options).model.properties())
    return P.resolve_name(ALIASES.get(name, name), names) or name


# ------------------------------------------------------------------------------------------ settings


def parse_settings(assignments: list[str], methods=("heatmap",), base=None):
    """Parses ``--set name=value`` items into static options and parameter settings.

    A name is a :class:`~heatpf_jax.presets.FilterOptions` field (``num_particles``, ``resampler``,
    ...) or a parameter of one of ``methods``, dotted (``motion.diffusion_std``) or by its last
    part where that is unambiguous (``diffusion_std``). A ``k`` above ``k_max`` raises ``k_max``,
    unless ``k_max`` was given too.

    Args:
        assignments: the ``name=value`` items.
        methods: the methods whose parameters the names may be.
        base: the options the static settings change (default :class:`~heatpf_jax.presets.FilterOptions()`;
            a ``--params`` file's options).

    Returns:
        ``(options, settings)``: a :class:`~heatpf_jax.presets.FilterOptions` and ``{name: value}``.

    Raises:
        ValueError: naming the field when it is unknown or its value does not parse (``method`` points
            to ``--method``).
    """
    from heatpf_jax.presets import FilterOptions, validate_options

    o_updates, raw = {}, {}
    for item in assignments:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--set: expected name=value, got {item!r}")
        if name in FilterOptions._fields:
            default = FilterOptions._field_defaults[name]
            if name == "spawn_box":
                parts = value.split(",")
                if len(parts) != 4:
                    raise ValueError(f"spawn_box: expected x_min,x_max,y_min,y_max, got {value!r}")
                o_updates[name] = tuple(parse_value(name, p, float) for p in parts)
            else:
                o_updates[name] = parse_value(name, value, type(default))
        else:
            raw[name] = value
    options = (FilterOptions() if base is None else base)._replace(**o_updates)
    validate_options(options)
    settings = {}
    for typed, value in raw.items():
        name = ALIASES.get(typed, typed)
        prop = param_of(name, list(methods), options, typed)
        settings[name] = parse_value(typed, value, int if prop.integer else float)
    k = settings.get("k")
    if "k_max" not in o_updates and isinstance(k, int) and k > options.k_max:
        options = options._replace(k_max=k)
    return options, settings


def unused_options(options, methods) -> list[str]:
    """Static options set away from their default that change none of ``methods`` (they would be ignored)."""
    from heatpf_jax.presets import FilterOptions, build

    default = FilterOptions()
    unused = []
    for name in FilterOptions._fields:
        value = getattr(options, name)
        if value == getattr(default, name):
            continue
        candidates = [value, *option_alternatives(name)]
        if all(
            build(m, default._replace(**{name: v})).model == build(m, default).model
            for m in methods
            for v in candidates
        ):
            unused.append(name)
    return unused


def option_alternatives(field: str) -> list:
    """Valid values of a static option other than its default: an option that none of them changes is
    one a method does not use (``"observation"`` needs two: ``"auto"`` is already one of them for a method)."""
    from heatpf_jax.presets import FilterOptions

    others = {"resampler": ["residual"], "spawn": ["gaussian"], "spawn_box": [(0.0, 1.0, 0.0, 1.0)],
              "observation": ["gaussian", "inverse_distance"], "knn": ["dense"], "modes": ["kmeans"],
              "ego": ["none"], "memory": ["tracks"],
              "source": ["pixels", "centroids"], "motion": ["random_walk", "rolling_ball"],
              "resetting": ["support"]}
    if field in others:
        return others[field]
    return [FilterOptions._field_defaults[field] + 1]


def grid_config(options, grid: dict[str, list], assignments: list[str]):
    """The sweep's options: ``k_max`` raised to the grid's largest k (one compilation covers the
    whole grid), unless ``--set k_max=...`` was given."""
    if "k" in grid and not any(item.partition("=")[0].strip() == "k_max" for item in assignments):
        options = options._replace(k_max=max(options.k_max, *grid["k"]))
    return options


def parse_value(name: str, raw: str, kind: type):
    raw = raw.strip()
    try:
        if kind is int:
            value = float(raw)
            if value != int(value):
                raise ValueError
            return int(value)
        if kind is float:
            return float(raw)
        return raw
    except ValueError:
        raise ValueError(f"{name}: expected {kind.__name__}, got {raw!r}") from None


def parse_grid(items: list[str], method: str = "heatmap") -> dict[str, list]:
    """Parses ``--grid name=v1,v2,...`` into ``{name: [values]}`` (parameters of ``method`` only).

    Raises:
        ValueError: naming the field when it is unknown, static, repeated or a value does not parse.
    """
    from heatpf_jax.presets import FilterOptions

    grid: dict[str, list] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep or not name or not raw.strip():
            raise ValueError(f"--grid: expected name=v1,v2,..., got {item!r}")
        if name in FilterOptions._fields:
            raise ValueError(f"{name}: a static option cannot be swept in one compilation; use --set")
        typed, name = name, ALIASES.get(name, name)
        prop = param_of(name, [method], FilterOptions(), typed)
        if name in grid:
            raise ValueError(f"{name}: given twice in --grid")
        grid[name] = [parse_value(name, v, int if prop.integer else float) for v in raw.split(",")]
    if not grid:
        raise ValueError("--grid: give at least one name=v1,v2,...")
    return grid


def parse_seeds(text: str | None, default: int) -> range:
    """``--seeds``: ``N`` (seeds 0 .. N-1) or ``START:STOP`` (seeds START .. STOP-1); ``None`` gives ``default`` seeds.

    Raises:
        ValueError: naming ``--seeds`` when the text does not parse or the range is empty.
    """
    if text is None:
        return range(default)
    first, sep, second = text.partition(":")
    try:
        start, stop = (int(first), int(second)) if sep else (0, int(first))
    except ValueError:
        raise ValueError(f"--seeds: expected N (seeds 0..N-1) or START:STOP, got {text!r}") from None
    if start < 0 or stop <= start:
        raise ValueError(f"--seeds: expected N >= 1 or START:STOP with 0 <= START < STOP, got {text!r}")
    return range(start, stop)


def check_burn_in(burn_in: int, num_steps: int | None = None) -> None:
    """Raises ``ValueError`` naming ``--burn-in`` when it is negative or leaves no step of ``num_steps``."""
    if burn_in < 0:
        raise ValueError(f"--burn-in: must be >= 0, got {burn_in}")
    if num_steps is not None and burn_in >= num_steps:
        raise ValueError(
            f"--burn-in: {burn_in} leaves none of the {num_steps} steps for the error statistics; "
            f"give --burn-in below {num_steps}"
        )


def checked_settings(args, methods, base=None):
    """Parses and checks --set for every method before any data is loaded or simulated.

    ``base``: the options ``--set`` changes (default ``FilterOptions()``; a ``--params`` file's options).
    """
    from heatpf_jax import params as P
    from heatpf_jax.presets import build
    from heatpf_jax.rollout import validate_params

    options, settings = parse_settings(args.set or [], methods, base)
    given = {item.partition("=")[0].strip() for item in args.set or []}
    unused = [name for name in unused_options(options, methods) if name in given]
    if unused:
        which = f"method {methods[0]}" if len(methods) == 1 else "any of the methods run"
        raise ValueError(f"{unused[0]}: a static option not used by {which}; {LIST_PARAMS}")
    for method in methods:
        model, params = build(method, options)
        validate_params(P.set_by_name(params, model.properties(), settings, skip_unknown=True), model)
    return options, settings


def sequence_settings(seq, label: str, methods, options, settings: dict, given, pinned: bool = False):
    """The sequence's own settings (``Sequence.settings``: ``heatpf colour``'s ``source=pixels``) beneath the user's.

    Each setting that the user did not give (``given``: the names of ``--set``) and that changes one of ``methods`` is
    applied; with ``pinned`` (a ``--params`` file holds the options and parameters) none is. One line names what
    was applied and what was not, and why.

    Args:
        seq: the loaded :class:`~heatpf_jax.io.sequence.Sequence`.
        label: the sequence's name in the printed line (its file).
        methods: the methods run.
        options: the :class:`~heatpf_jax.presets.FilterOptions` so far.
        settings: the parameter settings so far, ``{name: value}``.
        given: the names the user set (short, dotted or aliases).
        pinned: a ``--params`` file gives the options and parameters.

    Returns:
        ``(options, settings)`` with the sequence's settings applied.

    Raises:
        ValueError: ``LABEL: settings: ...`` where a value does not parse or lies outside its range.
    """
    from heatpf_jax import params as P
    from heatpf_jax.presets import FilterOptions, build
    from heatpf_jax.rollout import validate_params

    carried = seq.settings or {}
    if not carried:
        return options, settings
    methods = list(methods)
    given = set(given)
    given_full = given | {full_name(g, m, options) for g in given for m in methods}
    applied, overridden, unused = [], [], []
    settings = dict(settings)
    for name, value in carried.items():
        item = f"{name}={format_value(value)}"
        if pinned or name in given_full or any(full_name(name, m, options) in given_full for m in methods):
            overridden.append(item)
            continue
        if name not in FilterOptions._fields:
            try:
                param_of(ALIASES.get(name, name), methods, options)
            except ValueError:
                unused.append(item)
                continue
        try:
            new_options, new = parse_settings([item], methods, options)
            for method in methods:  # ranges too, before any work
                model, params = build(method, new_options)
                validate_params(P.set_by_name(params, model.properties(), new, skip_unknown=True), model)
        except ValueError as err:
            raise ValueError(f"{label}: settings: {err}") from None
        if name in FilterOptions._fields and all(
            build(m, new_options).model == build(m, options).model for m in methods
        ):
            unused.append(item)
            continue
        options, settings = new_options, {**settings, **new}
        applied.append(item)
    which = f"method {methods[0]}" if len(methods) == 1 else "any of the methods run"
    parts = []
    if applied:
        parts.append(f"{', '.join(applied)} from the sequence's settings (--set NAME=VALUE overrides)")
    if overridden:
        why = "the --params file gives the settings" if pinned else "the command line sets them"
        parts.append(f"its {', '.join(overridden)} not applied ({why})")
    if unused:
        parts.append(f"its {', '.join(unused)} not used by {which}")
    print(f"{label}: " + "; ".join(parts))
    return options, settings


def layered_settings(method: str, options, *layers: dict, skip_unknown: bool = False) -> dict:
    """``{dotted name: value}`` of ``method`` from several ``{name: value}`` layers, a later layer winning.

    Names may be short or aliases (``diffusion_std``, ``kalman_meas_std``): each layer's names are made
    full first, so a short name in a later layer replaces the dotted one of an earlier layer.

    Args:
        method: a name in ``heatpf_jax.presets.METHODS``.
        options: the static options (they decide which parameters exist).
        *layers: e.g. a ``--params`` file's parameters, then ``--set``'s.
        skip_unknown: leave out names that are no parameter of ``method`` (settings shared by several
            methods); otherwise they are kept as given (and refused where they are applied).
    """
    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    names = P.leaf_names(build(method, options).model.properties())
    out = {}
    for layer in layers:
        for name, value in layer.items():
            full = P.resolve_name(ALIASES.get(name, name), names)
            if full is None and skip_unknown:
                continue
            out[full or name] = value
    return out


def method_with_settings(method: str, options, settings):
    """The model of ``method`` and its params with every setting applied (each must be one of its parameters)."""
    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    model, params = build(method, options)
    return model, P.set_by_name(params, model.properties(), settings)


def format_value(value) -> str:
    """A setting's value as text: shortest round-trip floats, ``a,b,c`` for tuples."""
    if isinstance(value, str):
        return value
    if isinstance(value, tuple | list):
        return ",".join(format_value(v) for v in value)
    arr = np.asarray(value)
    if arr.ndim:
        return ",".join(format_value(v) for v in arr.ravel().tolist())
    item = arr.item()
    return str(item) if isinstance(item, bool | int) else repr(float(item))
