"""Writes the API reference pages (``docs/api/*.md``): one page per stage of the pipeline, from the package.

Each page lists its package (its docstring says what the stage holds) and then every module in it, so a
module added to a stage is documented without editing a page: ``python -m tests.data.api_docs``.
``tests/test_readme.py`` checks that the pages are what this writes and that every module of the library
is on one of them.
"""

from __future__ import annotations

import pkgutil
from pathlib import Path

import heatpf_jax

API = Path(__file__).resolve().parents[2] / "docs" / "api"

# (file, title, introduction, the modules of the page: a package means the package and all its modules)
PAGES = (
    ("running.md", "Running and tuning",
     "Building a filter from a named method, running it over a sequence or tick by tick, sweeping and tuning its "
     "parameters: the trunk of the package. The names are importable from `heatpf_jax` directly (`hp.run`, "
     "`hp.build`, `hp.Tracker`, `hp.tune`).",
     ("heatpf_jax.presets", "heatpf_jax.filter", "heatpf_jax.pieces", "heatpf_jax.rollout", "heatpf_jax.tracker",
      "heatpf_jax.params", "heatpf_jax.tuning", "heatpf_jax.sweep", "heatpf_jax.evaluate", "heatpf_jax.numerics")),
    ("camera.md", "Camera and measurements",
     "The camera geometry that projects heat-map pixels onto the ground (Fig. 3), the measurement arrays every "
     "source fills and every buffer keeps, and the change of base frame that odometry makes.",
     ("heatpf_jax.camera", "heatpf_jax.measurements", "heatpf_jax.frames")),
    ("motion.md", "Motion", "How particles move between heat maps, and the robot's own motion.",
     ("heatpf_jax.motion",)),
    ("sources.md", "Sources", "What a heat map's pixels become.", ("heatpf_jax.sources",)),
    ("buffers.md", "Buffers", "What is kept between heat maps, and how it ages.", ("heatpf_jax.buffers",)),
    ("observation.md", "Observation", "A particle's weight from the buffered measurements.",
     ("heatpf_jax.observation",)),
    ("estimate.md", "Estimate", "What the filter reports: the estimate, modes and the clustering they use.",
     ("heatpf_jax.estimate",)),
    ("resampling.md", "Resampling", "Resamplers, the ESS trigger, cluster-wise resampling, gradient estimators.",
     ("heatpf_jax.resampling",)),
    ("injection.md", "Injection", "New particles among the resampled ones.", ("heatpf_jax.injection",)),
    ("memory.md", "Memory", "The long-term memory: tracks of every object seen. See "
     "[Memory and ego-motion](../memory-and-ego-motion.md).", ("heatpf_jax.memory",)),
    ("colour.md", "Colour", "Colour-likelihood heat maps from RGB frames (Olufs et al.), and the reference "
     "histogram from a user's box. See [Colour heat maps](../colour.md).", ("heatpf_jax.colour",)),
    ("io.md", "Files, cache and ROS bags", "The sequence file, parameter files, atomic writes, the compilation "
     "cache, and ROS 2 bags in and out with the conversions between ROS messages and the filter's inputs and "
     "outputs. See [Sequence file format](../file-format.md) and [ROS bags](../ros.md).", ("heatpf_jax.io",)),
    ("baselines.md", "Baselines", "Baselines beside the filter: the constant-velocity Kalman filter (the `kalman` "
     "method) and the image-space colour trackers of Olufs et al.'s Table 1.", ("heatpf_jax.baselines",)),
    ("sim.md", "Simulation", "The simulated worlds: the named scenarios, the world family and replays of real "
     "ball tracks. NumPy only. See [Worlds](../worlds.md).", ("heatpf_jax.sim",)),
)
UNDOCUMENTED = ("heatpf_jax.cli", "heatpf_jax._moved")  # the command line has its own page (docs/cli.md)


def modules_of(name: str) -> list[str]:
    """``name`` and, for a package, every module in it (sorted)."""
    module = __import__(name, fromlist=["_"])
    if not hasattr(module, "__path__"):
        return [name]
    return [name] + sorted(f"{name}.{m.name}" for m in pkgutil.iter_modules(module.__path__)
                           if not m.name.startswith("_"))


def page_text(title: str, intro: str, names: tuple[str, ...]) -> str:
    blocks = []
    for name in names:
        for module in modules_of(name):
            package = module == name and len(modules_of(name)) > 1
            blocks.append(f"::: {module}" + ("\n    options:\n      members: false" if package else ""))
    return f"# {title}\n\n{intro}\n\n" + "\n\n".join(blocks) + "\n"


def pages() -> dict[str, str]:
    return {file: page_text(title, intro, names) for file, title, intro, names in PAGES}


def all_modules() -> list[str]:
    """Every module of the library but the command line's (which docs/cli.md documents)."""
    root = Path(heatpf_jax.__file__).parent
    out = []
    for path in root.rglob("*.py"):
        parts = path.relative_to(root.parent).with_suffix("").parts
        if parts[-1] in ("__init__", "__main__"):
            parts = parts[:-1]
        name = ".".join(parts)
        if name != "heatpf_jax" and not name.startswith(UNDOCUMENTED):
            out.append(name)
    return sorted(out)


STAGES = {  # the table's first column, by the module's place
    "motion": "motion", "sources": "source", "buffers": "buffer", "observation": "observation",
    "estimate": "estimate", "resampling": "resampling", "injection": "injection", "memory": "memory",
    "colour": "colour maps", "baselines": "baselines", "sim": "simulation", "io": "files", "cli": "command line",
}
TABLE_PAGE = API.parent / "methods-and-pieces.md"
TABLE_START = "<!-- the module table: python -m tests.data.api_docs -->"
TABLE_END = "<!-- end of the module table -->"


def _summary(path: Path) -> str:
    """The first sentence of a module's docstring, as one table cell."""
    import ast

    doc = ast.get_docstring(ast.parse(path.read_text())) or ""
    first = " ".join(doc.split("\n\n")[0].split())
    return first.replace("|", "\\|")


def module_table() -> str:
    """``| stage | module | what it holds |`` for every module of the library, the trunk first."""
    root = Path(heatpf_jax.__file__).parent
    rows = []
    for path in sorted(root.rglob("*.py"), key=lambda p: (len(p.relative_to(root).parts) > 1, str(p))):
        rel = path.relative_to(root)
        if path.name in ("__init__.py", "__main__.py") or rel.parts[0].startswith("_"):
            continue
        stage = STAGES.get(rel.parts[0], "trunk") if len(rel.parts) > 1 else "trunk"
        rows.append(f"| {stage} | `{rel}` | {_summary(path)} |")
    return "\n".join(["| stage | module | what it holds |", "|---|---|---|", *rows])


def table_page(text: str) -> str:
    """``text`` (methods-and-pieces.md) with the module table between its markers rewritten."""
    start, end = text.index(TABLE_START) + len(TABLE_START), text.index(TABLE_END)
    return text[:start] + "\n" + module_table() + "\n" + text[end:]


def main() -> None:
    for file, text in pages().items():
        (API / file).write_text(text)
    TABLE_PAGE.write_text(table_page(TABLE_PAGE.read_text()))
    print(f"wrote {len(PAGES)} pages in {API} and the module table in {TABLE_PAGE}")


if __name__ == "__main__":
    main()
