"""``heatpf sweep``: the cartesian product of parameter grids on one sequence file or a simulated scenario, ranked.

Every set of the ``--grid`` product (on top of a ``--params`` file and ``--set``) is checked first, then run
``--batch-size`` sets at a time, vmapped (:func:`heatpf_jax.sweep.sweep`); each finished batch is appended to the
CSV, which starts with a record of what produced it (:mod:`heatpf_jax.cli.sweep_record`), so that the same
command resumes an interrupted sweep and another one is refused. At the end the best sets are printed by mean
error, with a warning for each grid axis along which nothing changed (:func:`idle_axes`).
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

from heatpf_jax.cli.options import (
    INTERRUPTED,
    add_burn_in,
    add_method,
    add_params,
    add_set,
    progress_bar,
    settings_with_params,
)
from heatpf_jax.cli.settings import (
    check_burn_in,
    full_name,
    grid_config,
    method_with_settings,
    parse_grid,
    parse_seeds,
    scenario_names,
    sequence_settings,
)
from heatpf_jax.cli.sweep_record import RECORD_INTRO, grid_key, read_done, sweep_record
from heatpf_jax.io.files import check_input, check_output, write_atomic

__all__ = ["add_parser", "cmd_sweep", "idle_axes"]


def _sweep_inputs(args) -> tuple[range, int | None]:
    """Checks --input/--scenario/--seeds/--steps; the seeds and steps of the scenario (None for a file)."""
    from heatpf_jax.sim.scenarios import DEFAULT_NUM_STEPS

    if (args.input is None) == (args.scenario is None):
        raise ValueError("sweep: give either INPUT.npz or --scenario NAME")
    if args.input is not None:
        given = [o for o, v in (("--seeds", args.seeds), ("--steps", args.steps)) if v is not None]
        if given:
            raise ValueError(f"{given[0]}: applies to --scenario, not to an input file")
        check_input(args.input)
        return range(1), None
    if args.scenario not in scenario_names():
        raise ValueError(f"--scenario: unknown {args.scenario!r} (known: {', '.join(scenario_names())})")
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    return parse_seeds(args.seeds, 1), DEFAULT_NUM_STEPS if args.steps is None else args.steps


def _check_grid_against_settings(grid: dict, settings: dict, method: str, options) -> None:
    in_grid = {full_name(n, method, options) for n in grid}
    both = [n for n in settings if full_name(n, method, options) in in_grid]
    if both:
        raise ValueError(f"{both[0]}: given in both --set and --grid; keep one")


def cmd_sweep(args: argparse.Namespace) -> int:
    """Runs ``heatpf sweep`` on the parsed ``args``; returns the exit code (0, or 130 when interrupted)."""
    import itertools

    from heatpf_jax import params as P
    from heatpf_jax.io.sequence import load_sequence
    from heatpf_jax.rollout import validate_params
    from heatpf_jax.sim import simulate

    options, settings, set_settings = settings_with_params(args)  # --grid goes on top of both
    grid = parse_grid(args.grid or [], args.method)
    _check_grid_against_settings(grid, set_settings, args.method, options)
    options = grid_config(options, grid, args.set or [])
    model, params = method_with_settings(args.method, options, settings)
    seeds, steps = _sweep_inputs(args)
    if args.batch_size < 1:
        raise ValueError(f"--batch-size: must be >= 1, got {args.batch_size}")
    if args.top < 0:
        raise ValueError(f"--top: must be >= 0, got {args.top}")
    check_burn_in(args.burn_in, steps)
    out = check_output("--output", args.output, inputs=[args.input], replace=True)
    recording = None
    if args.input is not None:
        recording = load_sequence(args.input)
        check_burn_in(args.burn_in, recording.num_steps)
        given = {item.partition("=")[0].strip() for item in args.set or []} | set(grid)
        advised = sequence_settings(recording, str(args.input), [args.method], options, settings, given,
                                    pinned=args.params is not None)
        if advised != (options, settings):
            options, settings = advised
            model, params = method_with_settings(args.method, options, settings)
    names = list(grid)
    combos = list(itertools.product(*grid.values()))
    sets = [P.set_by_name(params, model.properties(), dict(zip(names, c, strict=True))) for c in combos]
    for p in sets:  # every set checked before any work
        validate_params(p, model)
    grid_names = {full_name(n, args.method, options) for n in names}
    record = sweep_record(args, seeds, steps, options, model, params, grid_names)
    columns = ["index", *names, "mean_error", "max_error", "std_error"]
    done = read_done(out, record, columns)

    if recording is not None:
        sequences = [recording]
    else:
        sequences = [simulate(args.scenario, seed, num_steps=steps) for seed in seeds]
    if any(s.ground_truth is None for s in sequences):
        raise ValueError("ground_truth: the sweep ranks parameter sets by error and needs ground truth")

    # Start (or restart) the file with its record, its header and the complete rows only: a row cut short
    # by an interruption is dropped and recomputed. Written atomically, so the finished rows are never at risk.
    lines = [RECORD_INTRO, *(f"# {n} = {v}" for n, v in record), ",".join(columns)]
    text = "".join(line + "\n" for line in lines + [",".join(r) for r in done.values()])
    write_atomic(out, lambda fh: fh.write(text))
    todo = [i for i, c in enumerate(combos) if grid_key(c) not in done]
    try:
        _sweep_rows(args, out, model, sets, combos, todo, sequences, len(done))
    except _Interrupted as stop:
        print(f"interrupted: {stop.saved} rows saved in {out}; run the same command to resume", file=sys.stderr)
        return INTERRUPTED
    _print_best(out, record, columns, args.top, args.burn_in)
    return 0


class _Interrupted(Exception):
    """Ctrl-C during a sweep, after ``saved`` rows were safely in the file."""

    def __init__(self, saved: int):
        super().__init__(saved)
        self.saved = saved


def _sweep_rows(args, out: Path, model, sets, combos, todo: list[int], sequences, saved: int) -> None:
    """Computes the rows ``todo`` a batch at a time, appending each batch to ``out`` as it completes."""
    import jax

    from heatpf_jax.rollout import stack_params
    from heatpf_jax.sweep import sweep

    n_dev = len(jax.local_devices())
    per_call = args.batch_size * n_dev
    print(
        f"sweep: {len(combos)} parameter sets ({len(combos) - len(todo)} already in {out}), "
        f"{len(sequences)} sequence(s) x {sequences[0].num_steps} steps, {n_dev} device(s), "
        f"{per_call} sets per call"
    )
    bar = progress_bar(len(todo))
    key = jax.random.key(args.seed)
    try:
        for start in range(0, len(todo), per_call):
            ids = todo[start : start + per_call]
            padded = ids + [ids[-1]] * (per_call - len(ids))  # same shape every call: one compilation
            batch = stack_params([sets[i] for i in padded])
            errors = []
            for seq in sequences:
                info = sweep(key, seq, batch, model, chunk=args.batch_size)
                est = np.asarray(info.mean, np.float64)[: len(ids)]
                errors.append(np.linalg.norm(est - seq.ground_truth[None], axis=-1)[:, args.burn_in :])
            err = np.concatenate(errors, axis=1)
            if not np.all(np.isfinite(err)):
                raise RuntimeError("the filter produced a non-finite estimate; please report this")
            with out.open("a") as fh:
                for row, i in enumerate(ids):
                    e = err[row]
                    values = ",".join(f"{v:.9g}" for v in combos[i])
                    fh.write(f"{i},{values},{e.mean():.6f},{e.max():.6f},{e.std():.6f}\n")
            saved += len(ids)
            bar.update(len(ids))
    except KeyboardInterrupt:
        raise _Interrupted(saved) from None
    finally:
        bar.close()


def _print_best(out: Path, record, columns: list[str], top: int, burn_in: int) -> None:
    rows = list(read_done(out, record, columns).values())
    rows.sort(key=lambda r: float(r[-3]))
    print(f"best of {len(rows)} by mean error (errors after step {burn_in}, metres):")
    print("  " + "  ".join(f"{c:>12}" for c in columns[1:]))
    for r in rows[:top]:
        print("  " + "  ".join(f"{c:>12}" for c in r[1:]))
    print(f"all results: {out}")
    for name in idle_axes(columns[1:-3], [r[1:-3] for r in rows], [[float(v) for v in r[-3:]] for r in rows]):
        warnings.warn(f"--grid {name}: its values gave the same errors in every row; the setting changes nothing "
                      "here (a piece this method does not use, or an effect these sequences never show)")


def idle_axes(names: list[str], values: list[list[str]], errors: list[list[float]]) -> list[str]:
    """The grid axes (``names``) along which nothing changes: with two values or more, and every group of rows
    that differ only in that axis with the same errors (relative tolerance 1e-9).

    Args:
        names: the axes' names.
        values: per row, its value on each axis (as written).
        errors: per row, its error statistics.
    """
    idle = []
    for i, name in enumerate(names):
        if len({v[i] for v in values}) < 2:
            continue
        groups: dict[tuple, list[list[float]]] = {}
        for v, e in zip(values, errors, strict=True):
            groups.setdefault(tuple(v[:i] + v[i + 1 :]), []).append(e)
        compared = [g for g in groups.values() if len(g) > 1]
        if compared and all(np.allclose(g, g[0], rtol=1e-9, atol=0.0) for g in compared):
            idle.append(name)
    return idle


def add_parser(sub, parents: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Registers ``sweep`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser."""
    scenarios = ", ".join(scenario_names())
    p = sub.add_parser(
        "sweep", parents=parents, help="run the cartesian product of parameter grids, ranked by error",
        epilog=f"Scenarios: {scenarios}. The CSV records what produced its rows (# lines); the same command "
        "resumes it, another one is refused.",
    )
    p.add_argument("input", nargs="?", help="sequence file (.npz with ground_truth); or use --scenario")
    p.add_argument("--scenario", help=f"a simulated scenario instead of a file: {scenarios}")
    p.add_argument("--grid", action="append", metavar="NAME=V1,V2,...", help="a parameter grid (repeatable)")
    p.add_argument("--output", "-o", default="sweep.csv", help="results CSV (default sweep.csv); an existing "
                   "one is resumed when it holds this sweep, refused otherwise")
    p.add_argument("--seeds", metavar="N|START:STOP", help="scenario sequences per set: N (seeds 0..N-1, "
                   "default 1) or START:STOP")
    p.add_argument("--steps", type=int, default=None, help="steps per scenario sequence (default 300)")
    p.add_argument("--batch-size", type=int, default=16, help="sets vmapped together per device (default 16)")
    add_burn_in(p)
    p.add_argument("--top", type=int, default=5, help="best sets printed (default 5)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    add_set(p, "a fixed parameter")
    add_params(p)
    add_method(p, "sweep", params_file=True)
    p.set_defaults(func=cmd_sweep)
    return p
