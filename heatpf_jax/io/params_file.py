"""Parameter files: one method's parameters and static options as JSON (``heatpf tune --output``, ``--params``).

Version 1 of the format, an object with::

    "format": "heatpf-params", "version": 1,
    "method": "heatmap",                        a name in heatpf_jax.presets.METHODS
    "options": {"num_particles": 500, ...},     every FilterOptions field (spawn_box as a list)
    "params": {"motion.diffusion_std": 0.05, ...}   every parameter by dotted name

and whatever else the writer adds (``heatpf tune`` adds ``tuned``, ``start``, ``loss``, ``history``,
``validation``, ``validation_steps``, ``path``, ``seconds`` and ``training``): kept, never checked.
A hand-written file may leave options and parameters out: they keep their defaults. Floats are written
in their shortest float32 form; an infinite value (a parameter that allows it) as JSON's ``Infinity``,
which Python reads back. :func:`load_params_file` checks everything before any data is loaded and
fails with one line naming the file and the field.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from heatpf_jax.io.files import write_atomic

__all__ = [
    "FORMAT",
    "VERSION",
    "ParamsFile",
    "json_floats",
    "load_params_file",
    "params_by_name",
    "save_params_file",
]

FORMAT = "heatpf-params"
VERSION = 1
_RESERVED = ("format", "version", "method", "options", "params")
_SCALAR_LIST = re.compile(r"\[\s*\n\s*([^\[\]{}]*?)\s*\n\s*\]")


class ParamsFile(NamedTuple):
    """A checked parameter file.

    Attributes:
        method: the method's name.
        options: a :class:`~heatpf_jax.presets.FilterOptions` (the file's, defaults for those it leaves out).
        params: ``{dotted name: int | float}``, the parameters the file gives (all, as written by
            :func:`save_params_file`).
        info: the file's other keys (what ``heatpf tune`` recorded).
    """

    method: str
    options: Any
    params: dict
    info: dict


def _number(value, integer: bool) -> int | float:
    if integer:
        return int(value)
    return float(str(np.float32(value)))  # the shortest text that gives back the same float32


def params_by_name(params, model) -> dict[str, int | float]:
    """``{dotted name: value}`` of every parameter of ``model`` (ints for integer parameters, else floats)."""
    import jax

    from heatpf_jax import params as P

    props = model.properties()
    leaves = jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))
    values = jax.tree.leaves(params)
    return {
        name: _number(np.asarray(v).item(), prop.integer)
        for name, v, prop in zip(P.leaf_names(props), values, leaves, strict=True)
    }


def save_params_file(path: str | os.PathLike, method: str, options, params, /, **info) -> None:
    """Writes ``params`` (every parameter of ``method`` built with ``options``) atomically as a version-1 file.

    Args:
        path: the JSON file (replaced if it exists: check it first, :func:`heatpf_jax.io.files.check_output`).
        method: a name in ``heatpf_jax.presets.METHODS``.
        options: the :class:`~heatpf_jax.presets.FilterOptions` the method was built with.
        params: its params (a :class:`~heatpf_jax.filter.FilterParams`, or the method's own type).
        **info: further JSON-serialisable keys (``history=[...]``); not one of the reserved five.
    """
    from heatpf_jax.presets import build

    clash = [k for k in info if k in _RESERVED]
    if clash:
        raise ValueError(f"{clash[0]}: reserved by the file format; choose another key")
    model = build(method, options).model
    record = {
        "format": FORMAT,
        "version": VERSION,
        "method": method,
        "options": {k: list(v) if isinstance(v, tuple) else v for k, v in options._asdict().items()},
        "params": params_by_name(params, model),
        **info,
    }
    text = _SCALAR_LIST.sub(lambda m: "[" + ", ".join(re.split(r",\s*\n\s*", m.group(1))) + "]",
                            json.dumps(record, indent=2)) + "\n"  # a list of numbers or strings on one line
    write_atomic(Path(path), lambda fh: fh.write(text))


def _options(raw, where: str):
    from heatpf_jax.presets import FilterOptions, validate_options

    if not isinstance(raw, dict):
        raise ValueError(f"{where}options: expected an object of static options, got {type(raw).__name__}")
    updates = {}
    for name, value in raw.items():
        if name not in FilterOptions._fields:
            raise ValueError(f"{where}options.{name}: not a static option (known: {', '.join(FilterOptions._fields)})")
        default = FilterOptions._field_defaults[name]
        if name == "spawn_box":
            ok = isinstance(value, list) and len(value) == 4 and all(_is_number(v) for v in value)
            if not ok:
                raise ValueError(f"{where}options.spawn_box: expected [x_min, x_max, y_min, y_max], got {value!r}")
            value = tuple(float(v) for v in value)
        elif isinstance(default, int) and not (isinstance(value, int) and not isinstance(value, bool)):
            raise ValueError(f"{where}options.{name}: expected an integer, got {value!r}")
        elif isinstance(default, str) and not isinstance(value, str):
            raise ValueError(f"{where}options.{name}: expected a string, got {value!r}")
        updates[name] = value
    options = FilterOptions()._replace(**updates)
    try:
        validate_options(options)
    except ValueError as err:
        raise ValueError(f"{where}options.{err}") from None
    return options


def _is_number(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _params(raw, method: str, options, where: str) -> dict:
    import jax

    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    if not isinstance(raw, dict):
        raise ValueError(f"{where}params: expected an object of parameters by dotted name, got {type(raw).__name__}")
    props = build(method, options).model.properties()
    names = P.leaf_names(props)
    leaves = dict(zip(names, jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param)), strict=True))
    out = {}
    for name, value in raw.items():
        if name not in leaves:
            raise ValueError(f"{where}params.{name}: not a parameter of method {method} (known: {', '.join(names)})")
        prop = leaves[name]
        if not _is_number(value) or (prop.integer and isinstance(value, float) and not value.is_integer()):
            kind = "an integer" if prop.integer else "a number"
            raise ValueError(f"{where}params.{name}: expected {kind}, got {value!r}")
        try:
            prop.check(f"params.{name}", value)
        except ValueError as err:
            raise ValueError(f"{where}{err}") from None
        out[name] = int(value) if prop.integer else float(value)
    return out


def load_params_file(path: str | os.PathLike) -> ParamsFile:
    """Reads and checks a parameter file (format, version, method, every option and parameter and its range).

    Raises:
        ValueError: one line ``PATH: FIELD: problem`` (``PATH: problem`` when the file is no JSON object).
        OSError: the file cannot be read.
    """
    from heatpf_jax.presets import METHODS

    where = f"{path}: "
    try:
        text = Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{where}not a text file (expected a JSON parameter file)") from None
    try:
        record = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{where}not JSON ({err.msg} at line {err.lineno}, column {err.colno})") from None
    if not isinstance(record, dict):
        raise ValueError(f"{where}expected a JSON object, got {type(record).__name__}")
    if record.get("format") != FORMAT:
        raise ValueError(f"{where}format: expected {FORMAT!r}, got {record.get('format')!r}")
    version = record.get("version")
    if version != VERSION:
        newer = " (written by a newer heatpf_jax?)" if _is_number(version) and version > VERSION else ""
        raise ValueError(f"{where}version: expected {VERSION}, got {version!r}{newer}")
    method = record.get("method")
    if not isinstance(method, str) or method not in METHODS:
        raise ValueError(f"{where}method: expected one of {', '.join(METHODS)}, got {method!r}")
    options = _options(record.get("options", {}), where)
    if "params" not in record:
        raise ValueError(f"{where}params: missing (an object of parameters by dotted name)")
    params = _params(record["params"], method, options, where)
    info = {k: v for k, v in record.items() if k not in _RESERVED}
    return ParamsFile(method, options, params, info)


def json_floats(values) -> list:
    """``values`` as a list of floats for strict JSON (float32 precision, shortest form), ``None`` where one
    is not finite."""
    return [_number(v, False) if math.isfinite(v) else None for v in np.asarray(values, np.float64).ravel().tolist()]
