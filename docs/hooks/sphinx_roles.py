"""MkDocs hook: the docstrings' Sphinx roles (``:class:`~heatpf_jax.motion.ConstantVelocity```) as links.

The docstrings name objects the Sphinx way; mkdocstrings renders the role literally (``:class:`` before a code
span). After the build, every ``:role:<code>target</code>`` in the site becomes the target as code, linked to
where the API reference documents it: the target's full path (``heatpf_jax.motion.constant_velocity.X``), the
module that defines an object a package re-exports (``heatpf_jax.motion.X``), or a short name (``X``,
``X.attr``) that one documented object ends with (on the same page first). A leading ``~`` shows the last
part only, as Sphinx does. A target found nowhere stays plain code. ``mkdocs.yml`` names this file under ``hooks``.
"""

from __future__ import annotations

import html
import importlib
import os
import re
from pathlib import Path

ROLE = re.compile(r":(?:class|func|meth|attr|mod|data|obj|exc):<code>(~?)([\w.]+)</code>")
ANCHOR = re.compile(r'id="(heatpf_jax(?:\.\w+)*)"')


def documented(site: Path) -> dict[str, Path]:
    """Every documented object's full path -> the page that holds its anchor."""
    out: dict[str, Path] = {}
    for page in sorted(site.rglob("*.html")):
        for name in ANCHOR.findall(page.read_text(encoding="utf-8")):
            out.setdefault(name, page)
    return out


def _defined_at(target: str) -> str | None:
    """``heatpf_jax.motion.X`` -> ``heatpf_jax.motion.constant_velocity.X``, where ``X`` is defined."""
    module_name, _, name = target.rpartition(".")
    try:
        obj = getattr(importlib.import_module(module_name), name)
    except (ImportError, AttributeError, ValueError):
        return None
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{module}.{qualname}" if module and qualname else None


def resolve(target: str, anchors: dict[str, Path], page: Path | None = None) -> str | None:
    """The documented full path a role's target names, or ``None``.

    A short name that several documented objects end with means the one on the same ``page`` (a docstring
    names its own module's objects that way), and of those the one with the shortest path (a module that
    re-exports a name documents it again, further down)."""
    if target in anchors:
        return target
    if target.startswith("heatpf_jax."):
        defined = _defined_at(target)
        return defined if defined in anchors else None
    ends = [name for name in anchors if name.endswith("." + target)]
    if len(ends) > 1 and page is not None:
        ends = [name for name in ends if anchors[name] == page] or ends
    if len(ends) > 1 and len({anchors[name] for name in ends}) == 1:
        ends = [min(ends, key=lambda name: (name.count("."), len(name)))]
    return ends[0] if len(ends) == 1 else None


def rewrite(text: str, page: Path, anchors: dict[str, Path]) -> str:
    """``text`` (one page's HTML) with every role replaced by its target's code span, linked where documented."""

    def one(match: re.Match) -> str:
        short, target = match[1] == "~", match[2]
        shown = html.escape(target.rsplit(".", 1)[-1] if short else target)
        full = resolve(target, anchors, page)
        if full is None:
            return f"<code>{shown}</code>"
        href = os.path.relpath(anchors[full], page.parent).replace(os.sep, "/")
        return f'<a class="autorefs" href="{href}#{full}"><code>{shown}</code></a>'

    return ROLE.sub(one, text)


def on_post_build(config, **kwargs) -> None:
    site = Path(config["site_dir"])
    anchors = documented(site)
    for page in site.rglob("*.html"):
        text = page.read_text(encoding="utf-8")
        new = rewrite(text, page, anchors)
        if new != text:
            page.write_text(new, encoding="utf-8")
