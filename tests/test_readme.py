"""The Python code blocks of README.md and of the documentation (docs/**/*.md) run as tests, so a renamed or
changed public name fails here, not for a user.

Every ```` ```python ```` fenced block of README.md is one test, ``test_readme_block[bN-LM-<first line>]``
(N: the block's index from 0, M: the README line of its opening fence), and every one of a documentation
page one ``test_docs_block[docs/PAGE.md-bN-LM-<first line>]``, executed as written with ``exec``; a
traceback names ``FILE:M block N`` and the line within the block (line 1: the line after the fence). The
``heatpf`` command lines of their ```` ```bash ```` blocks are parsed by the command's own parser
(``test_cli_lines_parse``), so a renamed option fails here too. Each Python block runs on its own:

* in a fresh temporary working directory that holds ``recording.npz``, 20 steps of the standard scenario on
  a 50 x 37 heat map (the ``small_sequence`` fixture of ``tests/conftest.py``, ``hp.save_sequence``);
* in a fresh namespace that holds ``robot``, a stand-in for a robot's interfaces (:class:`Robot`: ``ok()``
  is True for 3 ticks, ``new_heatmap()`` gives a frame of the shape the block's ``heatmap_shape=(H, W)``
  asks for, or None every other tick, ``cam_to_base()``, ``odometry_since_last_tick()``,
  ``publish_ball(mean, cov)`` records what it got), and ``SMALL_OPTIONS`` (conftest's small
  ``hp.FilterOptions``, for the directives below; filters built with it share compilations with the
  other tests).

After a block, what it left is checked: every ``hp.RunResult`` in its namespace has a finite ``info.mean
[..., T, 2]`` and ``info.cov [..., T, 2, 2]`` (``T = seq.num_steps`` where the block defines ``seq``),
every ``hp.TuneResult`` a finite, non-empty ``history``, and a block that uses ``robot`` must have
published at least one finite ``mean [2]`` and ``cov [2, 2]`` and run until ``robot.ok()`` said False.

Directives: HTML comments on the lines directly above a block's opening fence (no blank line between),
one per line, each ``<!-- test: ... -->``; GitHub does not render them.

* ``<!-- test: replace OLD NEW [OLD NEW ...] -->``: before the block runs, every occurrence of the text
  OLD is replaced by NEW, pair after pair, in order. The strings are shell-quoted (``shlex``: 'single' or
  "double" quotes), e.g. ``<!-- test: replace "num_steps=300" "num_steps=20" -->``. Use it only to
  substitute tiny sizes for heavy ones (particles, steps, sequences), never to repair a block. OLD must
  occur in the block, so a directive gone stale with an edit of the block fails.
* ``<!-- test: skip (reason) -->``: the block cannot run here (e.g. it needs rclpy); its test is
  reported as skipped with the reason, and ``test_skipped_blocks`` fails if more than one block of a file
  is skipped.

Any other ``<!-- test`` comment, or one that is not directly above a Python block, fails
``test_directives``; ``test_readme_has_python_blocks`` fails if README.md has no Python block.
"""

from __future__ import annotations

import linecache
import re
import shlex
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pytest

import heatpf_jax as hp
from tests.conftest import SMALL_OPTIONS

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
DOCS = sorted((ROOT / "docs").rglob("*.md"))
DIRECTIVE = re.compile(r"<!--\s*test:(?P<body>.*?)-->\s*$")
SKIP = re.compile(r"skip\s*\((?P<reason>.+)\)\s*$", re.DOTALL)
ROBOT_TICKS = 3


class Block(NamedTuple):
    index: int
    line: int  # 1-based line of the opening fence in its file
    source: str  # the block as written
    replacements: tuple[tuple[str, str], ...]
    skip: str | None  # the reason, or None
    file: str = "README.md"  # relative to the repository root

    @property
    def id(self) -> str:
        first = next((s.strip() for s in self.source.splitlines() if s.strip()), "")
        prefix = "" if self.file == "README.md" else f"{self.file}-"
        return f"{prefix}b{self.index}-L{self.line}-{first[:40]}"


def _parse_directive(body: str) -> tuple[tuple[tuple[str, str], ...], str | None]:
    """``replace ...`` or ``skip (...)`` -> (replacements, skip reason); ValueError if neither."""
    body = body.strip()
    skip = SKIP.fullmatch(body)
    if skip:
        return (), skip.group("reason").strip()
    words = shlex.split(body)
    if not words or words[0] != "replace" or len(words) < 3 or len(words) % 2 == 0:
        raise ValueError(f"expected 'replace OLD NEW [OLD NEW ...]' or 'skip (reason)', got {body!r}")
    pairs = words[1:]
    return tuple(zip(pairs[0::2], pairs[1::2], strict=True)), None


def parse_readme(text: str, file: str = "README.md") -> tuple[list[Block], list[str]]:
    """The Python blocks of ``text`` (the Markdown file ``file``) with their directives, and the problems found
    (never raises)."""
    lines = text.splitlines()
    blocks: list[Block] = []
    problems: list[str] = []
    used: set[int] = set()  # lines of directives attached to a python block
    i = 0
    while i < len(lines):
        fence = lines[i].strip()
        if not fence.startswith("```"):
            i += 1
            continue
        info = fence[3:].strip()
        end = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == "```"), None)
        if end is None:
            problems.append(f"{file}:{i + 1}: unclosed code fence")
            break
        if info.split(" ")[0] == "python":
            replacements: list[tuple[str, str]] = []
            skip = None
            j = i - 1
            while j >= 0 and lines[j].lstrip().startswith("<!--"):
                match = DIRECTIVE.match(lines[j].strip())
                if match:
                    used.add(j)
                    try:
                        pairs, reason = _parse_directive(match.group("body"))
                    except ValueError as error:
                        problems.append(f"{file}:{j + 1}: {error}")
                    else:
                        replacements[:0] = pairs  # directives apply top to bottom
                        skip = reason or skip
                j -= 1
            source = "\n".join(lines[i + 1:end]) + "\n"
            blocks.append(Block(len(blocks), i + 1, source, tuple(replacements), skip, file))
        i = end + 1
    for n, line in enumerate(lines):
        if re.match(r"\s*<!--\s*test", line) and n not in used:
            problems.append(f"{file}:{n + 1}: a test directive not directly above a ```python block "
                            f"(or not one line '<!-- test: ... -->'): {line.strip()!r}")
    return blocks, problems


BLOCKS, PROBLEMS = parse_readme(README.read_text(encoding="utf-8"))
DOC_BLOCKS: list[Block] = []
for _page in DOCS:
    _blocks, _problems = parse_readme(_page.read_text(encoding="utf-8"), _page.relative_to(ROOT).as_posix())
    DOC_BLOCKS += _blocks
    PROBLEMS += _problems


def runnable_source(block: Block) -> str:
    """The block with its replacements applied; fails if an OLD text does not occur in it."""
    source = block.source
    for old, new in block.replacements:
        if old not in source:
            pytest.fail(f"{block.file}:{block.line}: replace directive's {old!r} does not occur in the block")
        source = source.replace(old, new)
    return source


class Robot:
    """A robot's interfaces as the README's loop uses them, fed from a simulated sequence."""

    def __init__(self, seq: hp.Sequence, heatmap_shape: tuple[int, int], ticks: int = ROBOT_TICKS) -> None:
        self.seq, self.shape, self.ticks = seq, heatmap_shape, ticks
        self.tick = 0  # ok() calls that said True
        self.ok_calls = 0
        self.published: list[tuple[np.ndarray, np.ndarray]] = []

    def ok(self) -> bool:
        self.ok_calls += 1
        if self.tick >= self.ticks:
            return False
        self.tick += 1
        return True

    def _t(self) -> int:
        return (self.tick - 1) % self.seq.num_steps

    def new_heatmap(self) -> np.ndarray | None:
        """The sequence's frame resampled (nearest pixel) to the asked shape; None on every second tick."""
        if self.tick % 2 == 0:
            return None
        frame = np.asarray(self.seq.heatmaps[self._t()], np.float32)
        h, w = self.shape
        rows = np.arange(h) * frame.shape[0] // h
        cols = np.arange(w) * frame.shape[1] // w
        return np.ascontiguousarray(frame[np.ix_(rows, cols)])

    def cam_to_base(self) -> np.ndarray:
        return np.asarray(self.seq.cam_to_base[self._t()], np.float32)

    def odometry_since_last_tick(self) -> tuple[float, float, float]:
        return (0.0, 0.0, 0.0)

    def publish_ball(self, mean, cov) -> None:
        self.published.append((np.array(mean), np.array(cov)))


def _heatmap_shape(source: str, default: tuple[int, int]) -> tuple[int, int]:
    match = re.search(r"heatmap_shape\s*=\s*\(\s*(\d+)\s*,\s*(\d+)\s*\)", source)
    return (int(match.group(1)), int(match.group(2))) if match else default


def check_namespace(namespace: dict, robot: Robot, source: str) -> int:
    """Asserts on what the block left (module docstring); returns how many things were checked."""
    checked = 0
    seq = namespace.get("seq")
    steps = seq.num_steps if isinstance(seq, hp.Sequence) else None
    for name, value in namespace.items():
        if isinstance(value, hp.RunResult):
            mean, cov = np.asarray(value.info.mean), np.asarray(value.info.cov)
            assert mean.ndim >= 2 and mean.shape[-1] == 2, f"{name}.info.mean: shape {mean.shape}, expected [..., T, 2]"
            assert cov.shape == (*mean.shape, 2), f"{name}.info.cov: shape {cov.shape} for mean {mean.shape}"
            if steps is not None:
                assert mean.shape[-2] == steps, f"{name}.info.mean: {mean.shape[-2]} steps, seq has {steps}"
            assert np.isfinite(mean).all(), f"{name}.info.mean is not finite"
            assert np.isfinite(cov).all(), f"{name}.info.cov is not finite"
            checked += 1
        elif isinstance(value, hp.TuneResult):
            history = np.asarray(value.history)
            assert history.size > 0 and np.isfinite(history).all(), f"{name}.history: {history}"
            checked += 1
    if re.search(r"\brobot\.", source):
        assert robot.published, "the loop published nothing"
        assert robot.ok_calls == robot.ticks + 1, f"robot.ok() called {robot.ok_calls} times, not {robot.ticks + 1}"
        for mean, cov in robot.published:
            assert mean.shape == (2,) and np.isfinite(mean).all(), f"published mean {mean!r}"
            assert cov.shape == (2, 2) and np.isfinite(cov).all(), f"published cov {cov!r}"
        checked += 1
    return checked


def test_readme_has_python_blocks():
    assert BLOCKS, "README.md has no ```python block"


def test_directives():
    assert not PROBLEMS, "\n".join(PROBLEMS)


def test_docs_are_found():
    """The documentation pages are where this test looks for them (a moved docs/ would test nothing)."""
    assert DOCS and any(b.file.startswith("docs/") for b in DOC_BLOCKS), "no docs/**/*.md with a ```python block"


def test_skipped_blocks():
    every = BLOCKS + DOC_BLOCKS
    for file in sorted({b.file for b in every}):
        skipped = [f"{b.file}:{b.line} ({b.skip})" for b in every if b.file == file and b.skip is not None]
        assert len(skipped) <= 1, f"more than one block of {file} is skipped: " + "; ".join(skipped)


def run_block(block: Block, tmp_path, monkeypatch, small_sequence) -> None:
    """Runs one block as the module docstring says (skips it if it is marked skip)."""
    if block.skip is not None:
        pytest.skip(f"{block.file}:{block.line} is marked skip: {block.skip}")
    source = runnable_source(block)
    monkeypatch.chdir(tmp_path)
    hp.save_sequence("recording.npz", small_sequence)
    robot = Robot(small_sequence, _heatmap_shape(source, small_sequence.heatmaps.shape[1:]))
    namespace = {"__name__": f"readme_block_{block.index}", "robot": robot, "SMALL_OPTIONS": SMALL_OPTIONS}
    # A traceback shows the (substituted) block's lines: linecache serves them under this name.
    filename = f"{block.file}:{block.line} block {block.index}"
    linecache.cache[filename] = (len(source), None, source.splitlines(keepends=True), filename)
    code = compile(source, filename, "exec")
    exec(code, namespace)
    check_namespace(namespace, robot, source)


@pytest.mark.parametrize("block", BLOCKS, ids=[b.id for b in BLOCKS])
def test_readme_block(block: Block, tmp_path, monkeypatch, small_sequence):
    run_block(block, tmp_path, monkeypatch, small_sequence)


@pytest.mark.parametrize("block", DOC_BLOCKS, ids=[b.id for b in DOC_BLOCKS])
def test_docs_block(block: Block, tmp_path, monkeypatch, small_sequence):
    run_block(block, tmp_path, monkeypatch, small_sequence)


def cli_lines(text: str, file: str) -> list[tuple[str, str]]:
    """``(where, line)`` for every ``heatpf ...`` command of the ```` ```bash ```` blocks of ``text``: comments
    dropped, backslash continuations joined, commands after ``&&`` split off. Lines written as a synopsis
    (``[optional]``, ``a|b``, ``...``) are left out: they are not meant to run as written."""
    found = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() != "```bash":
            i += 1
            continue
        j = i + 1
        command = ""
        while j < len(lines) and lines[j].strip() != "```":
            part = lines[j].split(" #", 1)[0].rstrip()
            command += part[:-1] + " " if part.endswith("\\") else part
            if not part.endswith("\\"):
                for piece in command.split("&&"):
                    piece = piece.strip()
                    if piece.startswith("heatpf ") and not any(c in piece for c in "[|") and "..." not in piece:
                        found.append((f"{file}:{j + 1}", piece))
                command = ""
            j += 1
        i = j + 1
    return found


CLI_LINES = [found for page in [README, *DOCS]
             for found in cli_lines(page.read_text(encoding="utf-8"), page.relative_to(ROOT).as_posix())]


def test_cli_lines_parse():
    """Every runnable ``heatpf`` line of the README and the documentation is accepted by the command's parser
    (options, choices, required arguments); it is parsed, not run."""
    import contextlib
    import io

    from heatpf_jax.cli.parser import _build_parser

    assert CLI_LINES, "no heatpf command lines found"
    failed = []
    for where, line in CLI_LINES:
        err = io.StringIO()
        try:
            with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
                _build_parser().parse_args(shlex.split(line)[1:])
        except SystemExit as exit_:
            if exit_.code:
                failed.append(f"{where}: {line}\n    {err.getvalue().strip()}")
    assert not failed, "\n".join(failed)


def _generated_parts(text: str) -> dict[str, tuple[list[str], list[str]]]:
    """Per ``## `heatpf NAME``` section of the command-line page: its usage words and its option table rows."""
    from tests.data.cli_docs import _HEADING

    parts, name, lines = {}, None, text.splitlines()
    for i, line in enumerate(lines):
        match = _HEADING.match(line)
        if match:
            name = match.group(1)
            block = lines[i + 1:]
            start = block.index("```text")
            usage = block[start + 1 : block.index("```", start + 1)]
            table = []
            for r in block[block.index("| option | meaning |"):]:
                if not r.startswith("|"):
                    break
                table.append(r)
            parts[name] = (" ".join(usage).split(), table)
    return parts


def test_cli_page_matches_the_parser():
    """``docs/cli.md`` shows every subcommand's options as the parser has them (forms, metavars, help texts) and
    its usage; regenerate the page's usage blocks and tables with ``python -m tests.data.cli_docs``. Usage lines
    are compared word by word (their wrapping is argparse's)."""
    from tests.data import cli_docs

    page = cli_docs.PAGE.read_text(encoding="utf-8")
    assert cli_docs.missing_sections(page) == [], "add a section for these subcommands to docs/cli.md"
    have, want = _generated_parts(page), _generated_parts(cli_docs.render(page))
    stale = sorted(name for name in want if have.get(name) != want[name])
    assert not stale, f"docs/cli.md is out of date for {stale}: run python -m tests.data.cli_docs"


def test_api_pages_and_module_table_match_the_package():
    """Every module is on an API page and in the module-to-stage table, as ``python -m tests.data.api_docs``
    writes them, so a module added to a stage cannot go undocumented."""
    from tests.data import api_docs

    stale = [file for file, text in api_docs.pages().items() if (api_docs.API / file).read_text() != text]
    assert not stale, f"docs/api/{stale} out of date: run python -m tests.data.api_docs"
    listed = {line.split("::: ")[1].strip() for text in api_docs.pages().values()
              for line in text.splitlines() if line.startswith("::: ")}
    missing = [m for m in api_docs.all_modules() if m not in listed]
    assert not missing, f"modules on no API page: {missing}"
    page = api_docs.TABLE_PAGE.read_text()
    assert api_docs.table_page(page) == page, "the module table is out of date: run python -m tests.data.api_docs"


def test_sphinx_roles_become_links_to_the_api_pages(tmp_path):
    """docs/hooks/sphinx_roles.py on a two-page site: a full path, a package's re-export (linked where it is
    defined), a short name (same page first), ``~`` showing the last part, and an unknown target as plain code."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("sphinx_roles", ROOT / "docs" / "hooks" / "sphinx_roles.py")
    roles = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(roles)
    motion, sources = tmp_path / "api" / "motion" / "index.html", tmp_path / "api" / "sources" / "index.html"
    motion.parent.mkdir(parents=True)
    sources.parent.mkdir(parents=True)
    motion.write_text('<h2 id="heatpf_jax.motion.constant_velocity.ConstantVelocity"></h2>'
                      '<h2 id="heatpf_jax.motion.random_walk.RandomWalk"></h2>')
    sources.write_text('<h2 id="heatpf_jax.sources.pixels.PixelSource"></h2>'
                       "<p>:class:<code>~heatpf_jax.motion.ConstantVelocity</code>, :func:<code>PixelSource</code>, "
                       ":mod:<code>heatpf_jax.motion.random_walk.RandomWalk</code>, :data:<code>NOWHERE</code></p>")
    roles.on_post_build({"site_dir": str(tmp_path)})
    text = sources.read_text()
    assert ('<a class="autorefs" href="../motion/index.html#heatpf_jax.motion.constant_velocity.ConstantVelocity">'
            "<code>ConstantVelocity</code></a>") in text
    assert ('<a class="autorefs" href="index.html#heatpf_jax.sources.pixels.PixelSource">'
            "<code>PixelSource</code></a>") in text
    assert "<code>heatpf_jax.motion.random_walk.RandomWalk</code></a>" in text
    assert text.endswith(", <code>NOWHERE</code></p>") and ":class:" not in text and ":data:" not in text
