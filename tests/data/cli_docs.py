"""Writes the usage block and the option table of every subcommand in ``docs/cli.md`` from the ``heatpf`` parser.

Each ``## `heatpf NAME``` section of the page starts with the subcommand's usage (a ``text`` block) and a table of
its options (each option's forms and its help text); the prose after the table is the page's own and is kept.
``tests/test_readme.py::test_cli_page_matches_the_parser`` fails when an option, a metavar or a help text
changed without the page: regenerate with ``python -m tests.data.cli_docs``.
"""

from __future__ import annotations

import argparse
import os
import re
from pathlib import Path
from unittest import mock

PAGE = Path(__file__).resolve().parents[2] / "docs" / "cli.md"
_HEADING = re.compile(r"^## `heatpf ([a-z-]+)`$")
_WIDTH = 72


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    from heatpf_jax.cli.parser import _build_parser

    actions = [a for a in _build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices)


def _usage(parser: argparse.ArgumentParser) -> list[str]:
    with mock.patch.dict(os.environ, {"COLUMNS": str(_WIDTH)}):
        text = parser.format_usage()
    lines = [line.strip() for line in text.removeprefix("usage: ").rstrip().splitlines()]
    return [lines[0]] + ["    " + line for line in lines[1:]]


def _forms(action: argparse.Action) -> str:
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    metavar = ""
    if action.nargs != 0:
        metavar = action.metavar or (
            "{" + ",".join(map(str, action.choices)) + "}" if action.choices else action.dest.upper()
        )
    strings = sorted(action.option_strings, key=lambda s: (not s.startswith("--"), s))
    return ", ".join(f"`{s} {metavar}`" if metavar else f"`{s}`" for s in strings)


def section(parser: argparse.ArgumentParser) -> list[str]:
    """The generated part of a subcommand's section: its usage block and its option table."""
    rows = ["| option | meaning |", "|---|---|"]
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
            continue
        meaning = " ".join((action.help or "").split()).replace("|", "\\|")
        rows.append(f"| {_forms(action)} | {meaning} |")
    return ["", "```text", *_usage(parser), "```", "", *rows]


def render(text: str) -> str:
    """``text`` (the page) with every subcommand's usage block and table regenerated."""
    parsers = _subparsers()
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    while i < len(lines):
        out.append(lines[i])
        match = _HEADING.match(lines[i])
        i += 1
        if not match or match.group(1) not in parsers:
            continue
        # Skip the old generated part: up to the end of the first table after the heading.
        while i < len(lines) and not lines[i].startswith("|"):
            i += 1
        while i < len(lines) and lines[i].startswith("|"):
            i += 1
        out.extend(section(parsers[match.group(1)]))
    return "\n".join(out) + "\n"


def missing_sections(text: str) -> list[str]:
    """The subcommands that have no ``## `heatpf NAME``` section on the page."""
    found = {m.group(1) for m in map(_HEADING.match, text.splitlines()) if m}
    return sorted(set(_subparsers()) - found)


if __name__ == "__main__":
    PAGE.write_text(render(PAGE.read_text()))
    print(f"wrote {PAGE}")
