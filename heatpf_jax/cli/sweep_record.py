"""What a sweep CSV records about the question it answers, so that a resume never reuses another's rows.

A sweep CSV begins with ``# name = value`` lines: the package version, the method, the input's sha256
(or scenario, seeds and steps), seed, burn-in, every static option and every parameter outside the
grid. :func:`read_done` returns the finished rows only when that record matches this command's.
"""

from __future__ import annotations

from pathlib import Path

from heatpf_jax.cli.settings import format_value
from heatpf_jax.io.files import sha256_of

__all__ = ["RECORD_INTRO", "grid_key", "read_done", "sweep_record"]

RECORD_INTRO = "# heatpf sweep results. The same command resumes this file; it refuses when a line below differs."


def grid_key(values) -> tuple[str, ...]:
    return tuple(f"{float(v):.9g}" for v in values)


def sweep_record(args, seeds: range, steps: int | None, options, model, params, grid_names) -> list[tuple[str, str]]:
    """What defines a sweep's rows besides their grid values: ``[(name, value)]``, written atop the CSV."""
    import jax

    from heatpf_jax import __version__
    from heatpf_jax import params as P

    record = [("heatpf_jax", __version__), ("method", args.method)]
    if args.input is not None:
        record.append(("input_sha256", sha256_of(Path(args.input))))
    else:
        record += [("scenario", args.scenario), ("seeds", f"{seeds.start}:{seeds.stop}"), ("steps", str(steps))]
    record += [("seed", str(args.seed)), ("burn_in", str(args.burn_in))]
    record += [(f"option.{name}", format_value(value)) for name, value in options._asdict().items()]
    names = P.leaf_names(model.properties())
    leaves = jax.tree.leaves(params)
    record += [(f"param.{n}", format_value(v)) for n, v in zip(names, leaves, strict=True) if n not in grid_names]
    return record


def _record_of(lines: list[str]) -> dict[str, str]:
    """The ``# name = value`` lines of a sweep CSV."""
    found = {}
    for line in lines:
        if line.startswith("#"):
            name, sep, value = line[1:].strip().partition(" = ")
            if sep:
                found[name] = value
    return found


def _short(value: str | None) -> str:
    if value is None:
        return "none"
    return value if len(value) <= 24 else value[:12] + "..."


def _record_diff(found: dict[str, str], record: list[tuple[str, str]]) -> str:
    """What differs between a CSV's record and this command's, in words (empty when nothing does)."""
    wanted = dict(record)
    names = [n for n, _ in record] + [n for n in found if n not in wanted]
    diffs = [
        f"{n}: {_short(found.get(n))} in the file, {_short(wanted.get(n))} now"
        for n in names
        if found.get(n) != wanted.get(n)
    ]
    more = f"; and {len(diffs) - 4} more" if len(diffs) > 4 else ""
    return "; ".join(diffs[:4]) + more


def read_done(path: Path, record: list[tuple[str, str]], columns: list[str]) -> dict[tuple[str, ...], list[str]]:
    """Rows already in a sweep CSV, keyed by their grid values, after checking that the CSV answers this sweep.

    Raises:
        ValueError: the file is not a sweep CSV, or its record or columns differ from this sweep's.
    """
    if not path.exists() or path.stat().st_size == 0:
        return {}
    fresh = "use another --output to start a new file"
    try:
        lines = path.read_text().splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"--output: {path} is not a sweep CSV (not text); {fresh}") from None
    found = _record_of(lines)
    if not found:
        raise ValueError(
            f"--output: {path} exists and holds no record of the sweep that wrote it (another kind of file, or "
            f"one from an earlier heatpf); {fresh}"
        )
    diff = _record_diff(found, record)
    if diff:
        raise ValueError(f"--output: {path} holds the results of another sweep ({diff}); {fresh}")
    body = [line for line in lines if not line.startswith("#")]
    header = body[0].split(",") if body else []
    if header != columns:
        raise ValueError(f"--output: {path} has the columns {header}, this sweep writes {columns}; {fresh}")
    done = {}
    n_params = len(columns) - 4
    for line in body[1:]:
        cells = line.split(",")
        if len(cells) != len(columns):
            continue  # a row cut short by an interruption: recompute it
        done[grid_key(cells[1 : 1 + n_params])] = cells
    return done
