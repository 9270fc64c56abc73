"""The names and module paths that moved when the package was grouped by stage keep working for one release.

``hp.ConstantVelocity`` is now ``hp.motion.ConstantVelocity`` and ``heatpf_jax.motion_velocity`` is
``heatpf_jax.motion.constant_velocity``: the old ones still give the same objects, with a ``DeprecationWarning``
that names the new place. ``tests/data/moved_modules.json`` holds every old module's ``__all__`` as it was
before the move, so the check does not depend on the tables it checks.
"""

from __future__ import annotations

import ast
import importlib
import json
import sys
import warnings
from pathlib import Path

import pytest

import heatpf_jax as hp
from heatpf_jax._moved import MOVED_MODULES, MOVED_NAMES

OLD_MODULES = json.loads((Path(__file__).parent / "data" / "moved_modules.json").read_text())
PACKAGE = Path(hp.__file__).parent


def _quietly(fn):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return fn()


@pytest.mark.parametrize("name", sorted(MOVED_NAMES))
def test_an_old_top_level_name_warns_and_is_the_new_object(name):
    new = getattr(importlib.import_module(MOVED_NAMES[name]), name)
    with pytest.warns(DeprecationWarning, match=rf"heatpf_jax\.{name} moved to {MOVED_NAMES[name]}\.{name}"):
        old = getattr(hp, name)
    assert old is new
    assert name not in hp.__all__


def test_from_import_of_an_old_name_and_an_unknown_name():
    with pytest.warns(DeprecationWarning, match="hp.motion|heatpf_jax.motion"):
        from heatpf_jax import ConstantVelocity
    assert ConstantVelocity is hp.motion.ConstantVelocity
    with pytest.raises(AttributeError, match="no attribute 'no_such_name'"):
        hp.no_such_name  # noqa: B018


@pytest.mark.parametrize("old", sorted(OLD_MODULES))
def test_an_old_module_path_keeps_every_name_of_its_all(old):
    if old in MOVED_MODULES:
        sys.modules.pop(old, None)
        with pytest.warns(DeprecationWarning, match=f"{old} moved to"):
            module = importlib.import_module(old)
    else:  # the module became the stage's package, which exports what the module did
        with warnings.catch_warnings():
            warnings.simplefilter("error", DeprecationWarning)
            module = importlib.import_module(old)
    missing = [name for name in OLD_MODULES[old] if not _quietly(lambda n=name: hasattr(module, n))]
    assert not missing, f"{old} lost {missing}"
    if old in MOVED_MODULES:
        name = OLD_MODULES[old][0]
        with pytest.warns(DeprecationWarning, match=rf"{old}\.{name} moved to"):
            obj = getattr(module, name)
        homes = [importlib.import_module(t) for t in MOVED_MODULES[old]]
        assert any(getattr(home, name, None) is obj for home in homes)
    parent_name, short = old.rsplit(".", 1)
    parent = importlib.import_module(parent_name)
    if old in MOVED_MODULES:  # ``hp.motion_velocity`` worked after a bare ``import heatpf_jax``
        parent.__dict__.pop(short, None)  # the import above bound it; a user's process may not have
        with pytest.warns(DeprecationWarning, match=f"{old} moved to"):
            assert getattr(parent, short) is module


def _imports(path: Path) -> set[str]:
    """The ``heatpf_jax`` modules a module imports, anywhere in it (inside functions too)."""
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("heatpf_jax")}
        elif isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("heatpf_jax"):
            for alias in node.names:  # ``from heatpf_jax.io import sequence`` imports a module
                sub = f"{node.module}.{alias.name}"
                out.add(sub if (PACKAGE.parent / sub.replace(".", "/")).with_suffix(".py").exists()
                        or (PACKAGE.parent / sub.replace(".", "/")).is_dir() else node.module)
    return out


def test_no_import_circle_between_modules():
    """Module to module, packages' ``__init__`` re-exports left out: no module imports itself back."""
    graph = {}
    for path in PACKAGE.rglob("*.py"):
        if path.name == "__init__.py" or path.name == "__main__.py":
            continue
        name = ".".join(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        graph[name] = {m for m in _imports(path) if m != name}
    # an import of a package stands for the module of its that holds the name: leave packages out
    graph = {k: {m for m in v if m in graph} for k, v in graph.items()}
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(node):
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                raise AssertionError("import circle: " + " -> ".join(path[path.index(nxt):] + [nxt]))
            if nxt not in state:
                visit(nxt)
        path.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node)


def test_every_subpackage_lists_its_exports():
    for init in PACKAGE.rglob("__init__.py"):
        module = importlib.import_module(".".join(init.parent.relative_to(PACKAGE.parent).parts))
        assert module.__all__, init
        missing = [n for n in module.__all__ if not _quietly(lambda n=n: hasattr(module, n))]
        assert not missing, f"{init}: {missing}"
