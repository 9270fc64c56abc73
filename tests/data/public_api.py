"""Writes ``public_api.json``: the signatures of the public names, the promise that ``tests/test_public_api.py``
holds the code to.

For every name in the ``__all__`` of the public modules: what it is, and for a callable (a function, a class,
a NamedTuple) its parameters in order, each with its kind and whether it has a default. Regenerate after an
intended, compatible extension (a new name, a new parameter with a default):
``python -m tests.data.public_api``; the test says what an incompatible change broke.
"""

from __future__ import annotations

import importlib
import inspect
import json
import warnings
from pathlib import Path

PATH = Path(__file__).with_name("public_api.json")
MODULES = (
    "heatpf_jax",
    "heatpf_jax.sim",
    "heatpf_jax.baselines",
    "heatpf_jax.motion",
    "heatpf_jax.sources",
    "heatpf_jax.buffers",
    "heatpf_jax.observation",
    "heatpf_jax.estimate",
    "heatpf_jax.resampling",
    "heatpf_jax.injection",
    "heatpf_jax.memory",
    "heatpf_jax.colour",
    "heatpf_jax.io",
    "heatpf_jax.camera",
    "heatpf_jax.measurements",
)


def public(module_name: str, name: str):
    """``module.name``; a ``DeprecationWarning`` (a name in its deprecation period) is allowed."""
    module = importlib.import_module(module_name)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return getattr(module, name)


def describe(obj) -> dict:
    """``{"kind": ..., "params": [[name, kind, has_default], ...]}`` of a public object."""
    if inspect.isclass(obj) and issubclass(obj, tuple) and hasattr(obj, "_fields"):
        kind = "namedtuple"
    elif inspect.isclass(obj):
        kind = "class"
    elif callable(obj):
        kind = "function"
    else:
        return {"kind": "value"}
    try:
        signature = inspect.signature(obj)
    except (TypeError, ValueError):  # a builtin without a signature
        return {"kind": kind}
    params = [[p.name, p.kind.name, p.default is not inspect.Parameter.empty]
              for p in signature.parameters.values()]
    return {"kind": kind, "params": params}


def snapshot() -> dict:
    out = {}
    for module_name in MODULES:
        module = importlib.import_module(module_name)
        for name in sorted(module.__all__):
            out[f"{module_name}:{name}"] = describe(public(module_name, name))
    return out


def main() -> None:
    current = snapshot()
    if PATH.exists():  # a name in its deprecation period left ``__all__`` but keeps its promise until removed
        for key, value in json.loads(PATH.read_text()).items():
            module_name, name = key.split(":")
            try:
                public(module_name, name)
            except AttributeError:
                continue
            current.setdefault(key, value)
    entries = sorted(current.items())
    lines = [f"  {json.dumps(key)}: {json.dumps(value)}" for key, value in entries]  # one line per name
    PATH.write_text("{\n" + ",\n".join(lines) + "\n}\n")
    print(f"wrote {PATH}")


if __name__ == "__main__":
    main()
