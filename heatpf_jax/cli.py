"""The ``heatpf`` command: ``heatpf demo`` and ``heatpf run``."""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

__all__ = ["apply_overrides", "error_stats", "grid_config", "main", "write_estimates_csv"]

CSV_HEADER = "t,x,y,cov_xx,cov_xy,cov_yy"
METHODS = ("heatmap", "conventional", "kalman")


def apply_overrides(params, config, assignments: list[str]):
    """Applies ``name=value`` overrides to FilterParams or FilterConfig fields.

    Raises:
        ValueError: naming the field when it is unknown or its value does not parse.
    """
    from heatpf_jax.filter import FilterConfig, FilterParams

    p_updates, c_updates = {}, {}
    for item in assignments:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--set: expected name=value, got {item!r}")
        if name in FilterParams._fields:
            default = FilterParams._field_defaults[name]
            p_updates[name] = _parse(name, raw, type(default))
        elif name in FilterConfig._fields:
            default = FilterConfig._field_defaults[name]
            if name == "spawn_box":
                parts = raw.split(",")
                if len(parts) != 4:
                    raise ValueError(f"spawn_box: expected x_min,x_max,y_min,y_max, got {raw!r}")
                c_updates[name] = tuple(_parse(name, p, float) for p in parts)
            else:
                c_updates[name] = _parse(name, raw, type(default))
        else:
            known = ", ".join(FilterParams._fields + FilterConfig._fields)
            raise ValueError(f"{name}: unknown parameter (known: {known})")
    params, config = params._replace(**p_updates), config._replace(**c_updates)
    # k above the default bound raises the bound, unless k_max was given too.
    if "k_max" not in c_updates and isinstance(params.k, int) and params.k > config.k_max:
        config = config._replace(k_max=params.k)
    return params, config


def _k_max_given(assignments: list[str]) -> bool:
    return any(item.partition("=")[0].strip() == "k_max" for item in assignments)


def grid_config(config, grid: dict[str, list], assignments: list[str]):
    """The sweep's config: ``k_max`` raised to the grid's largest k (one compilation covers the
    whole grid), unless ``--set k_max=...`` was given."""
    if "k" in grid and not _k_max_given(assignments):
        config = config._replace(k_max=max(config.k_max, *grid["k"]))
    return config


def _parse(name: str, raw: str, kind: type):
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


def error_stats(estimates: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Mean, max and std of the Euclidean error, metres (the paper's Table I columns)."""
    err = np.linalg.norm(np.asarray(estimates, np.float64) - np.asarray(truth, np.float64), axis=1)
    return {"mean": float(err.mean()), "max": float(err.max()), "std": float(err.std())}


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_estimates_csv(path: str | os.PathLike, mean: np.ndarray, cov: np.ndarray) -> None:
    """Writes ``t,x,y,cov_xx,cov_xy,cov_yy`` atomically (temporary file renamed into place)."""
    path = Path(path)
    t = np.arange(mean.shape[0])
    table = np.column_stack([t, mean[:, 0], mean[:, 1], cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]])
    fd, tmp = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", suffix=".csv.tmp")
    try:
        with os.fdopen(fd, "w") as fh:
            fh.write(CSV_HEADER + "\n")
            for row in table:
                fh.write(f"{int(row[0])}," + ",".join(f"{v:.6f}" for v in row[1:]) + "\n")
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _settings(args):
    """Parses and checks --set before any data is loaded or simulated."""
    from heatpf_jax.filter import FilterConfig, FilterParams, validate_config, validate_params

    params, config = apply_overrides(FilterParams(), FilterConfig(), args.set or [])
    validate_config(config)
    validate_params(params, config)
    return params, config


def _run_filter(seq, args, params, config):
    import jax

    from heatpf_jax.filter import run

    config = config._replace(method=args.method)
    start = time.perf_counter()
    result = run(jax.random.key(args.seed), seq, params, config)
    mean = np.asarray(result.info.mean)
    cov = np.asarray(result.info.cov)
    elapsed = time.perf_counter() - start
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        bad = int(np.flatnonzero(~np.all(np.isfinite(mean), axis=1) | ~np.all(np.isfinite(cov), axis=(1, 2)))[0])
        raise RuntimeError(f"the filter produced a non-finite estimate at step {bad}; please report this")
    return mean, cov, elapsed


def _report(name: str, seq, mean, cov, elapsed: float) -> None:
    print(
        f"{name}: {seq.num_steps} steps, {int(np.sum(seq.has_heatmap))} heat maps, "
        f"{elapsed:.2f} s (including compilation)"
    )
    if seq.ground_truth is not None:
        stats = error_stats(mean, seq.ground_truth)
        print(f"error [m]: mean {stats['mean']:.4f}  max {stats['max']:.4f}  std {stats['std']:.4f}")


def _cmd_run(args) -> int:
    from heatpf_jax.sequence import load_sequence

    params, config = _settings(args)
    seq = load_sequence(args.input)
    mean, cov, elapsed = _run_filter(seq, args, params, config)
    write_estimates_csv(args.output, mean, cov)
    _report(str(args.input), seq, mean, cov, elapsed)
    print(f"wrote {args.output}")
    return 0


def _cmd_demo(args) -> int:
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, format_table
    from heatpf_jax.sim import simulate

    params, config = _settings(args)
    if args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    print("heatpf demo: simulated 'standard' scenario (static robot, 200x150 heat map every step, 10 Hz);")
    print("the short version of `heatpf eval` (one scenario, one sequence)")
    start = time.perf_counter()
    seq = simulate("standard", args.seed, num_steps=args.steps)
    variants = DEFAULT_VARIANTS[:3]
    result = evaluate_sequences(
        "standard",
        [seq],
        params=params,
        config=config,
        variants=variants,
        seed=args.seed,
        burn_in=min(10, args.steps - 1),
    )
    print(format_table(result))
    print(f"({time.perf_counter() - start:.1f} s including compilation)")
    if args.output:
        write_estimates_csv(args.output, result.methods[0].estimates[0], np.zeros((args.steps, 2, 2)))
        print(f"wrote {args.output} (heatmap estimates; covariances are in `heatpf run`)")
    return 0


def _cmd_eval(args) -> int:
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, format_table, plot_scenario
    from heatpf_jax.sequence import load_sequence
    from heatpf_jax.sim import SCENARIOS, simulate

    params, config = _settings(args)
    if args.input:
        jobs = [(Path(args.input).stem, None)]
    else:
        names = args.scenario or list(SCENARIOS)
        unknown = [n for n in names if n not in SCENARIOS]
        if unknown:
            raise ValueError(f"--scenario: unknown {unknown[0]!r} (known: {', '.join(SCENARIOS)})")
        jobs = [(n, n) for n in names]
    if args.seeds < 1:
        raise ValueError(f"--seeds: must be >= 1, got {args.seeds}")
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    if args.plot:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"')

    seqs_per_job = 1 if args.input else args.seeds
    total = len(jobs) * (seqs_per_job + len(DEFAULT_VARIANTS))
    bar = _progress(total)
    tables, written = [], []
    try:
        for name, scenario in jobs:
            if scenario is None:
                sequences = [load_sequence(args.input)]
                bar.update(1)
            else:
                sequences = []
                for seed in range(args.seeds):
                    bar.set_description(f"{name} seed {seed}")
                    sequences.append(simulate(scenario, seed, num_steps=args.steps))
                    bar.update(1)

            def tick(label: str) -> None:
                bar.set_description(label)
                bar.update(1)

            result = evaluate_sequences(
                name, sequences, params=params, config=config, seed=args.seed, burn_in=args.burn_in, progress=tick
            )
            tables.append(format_table(result))
            bar.write(tables[-1] + "\n")
            if args.plot:
                written += plot_scenario(result, args.plot)
    finally:
        bar.close()
    for path in written:
        print(f"wrote {path}")
    return 0


def parse_grid(items: list[str]) -> dict[str, list]:
    """Parses ``--grid name=v1,v2,...`` into ``{name: [values]}`` (FilterParams fields only).

    Raises:
        ValueError: naming the field when it is unknown, static, repeated or a value does not parse.
    """
    from heatpf_jax.filter import FilterConfig, FilterParams

    grid: dict[str, list] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep or not name or not raw.strip():
            raise ValueError(f"--grid: expected name=v1,v2,..., got {item!r}")
        if name in FilterConfig._fields:
            raise ValueError(f"{name}: a static FilterConfig field cannot be swept in one compilation; use --set")
        if name not in FilterParams._fields:
            raise ValueError(f"{name}: unknown parameter (known: {', '.join(FilterParams._fields)})")
        if name in grid:
            raise ValueError(f"{name}: given twice in --grid")
        kind = type(FilterParams._field_defaults[name])
        grid[name] = [_parse(name, v, kind) for v in raw.split(",")]
    if not grid:
        raise ValueError("--grid: give at least one name=v1,v2,...")
    return grid


def _grid_key(values) -> tuple[str, ...]:
    return tuple(f"{float(v):.9g}" for v in values)


def _read_done(path: Path, columns: list[str]) -> dict[tuple[str, ...], list[str]]:
    """Rows already in a sweep CSV, keyed by their parameter values; checks the header."""
    if not path.exists() or path.stat().st_size == 0:
        return {}
    lines = path.read_text().splitlines()
    header = lines[0].split(",") if lines else []
    if header != columns:
        raise ValueError(
            f"--output: {path} exists with columns {header}, this sweep writes {columns}; "
            "use another file to start a different sweep"
        )
    done = {}
    n_params = len(columns) - 4
    for line in lines[1:]:
        cells = line.split(",")
        if len(cells) != len(columns):
            continue  # a row cut short by an interruption: recompute it
        done[_grid_key(cells[1 : 1 + n_params])] = cells
    return done


def _cmd_sweep(args) -> int:
    import itertools

    import jax

    from heatpf_jax.filter import stack_params
    from heatpf_jax.sequence import load_sequence
    from heatpf_jax.sim import SCENARIOS, simulate
    from heatpf_jax.sweep import sweep

    params, config = _settings(args)
    config = config._replace(method=args.method)
    grid = parse_grid(args.grid or [])
    config = grid_config(config, grid, args.set or [])
    if (args.input is None) == (args.scenario is None):
        raise ValueError("sweep: give either INPUT.npz or --scenario NAME")
    if args.scenario is not None and args.scenario not in SCENARIOS:
        raise ValueError(f"--scenario: unknown {args.scenario!r} (known: {', '.join(SCENARIOS)})")
    if args.seeds < 1 or args.batch_size < 1:
        raise ValueError("--seeds and --batch-size: must be >= 1")
    names = list(grid)
    combos = list(itertools.product(*grid.values()))
    sets = [params._replace(**dict(zip(names, c, strict=True))) for c in combos]
    # Check every set before any work.
    from heatpf_jax.filter import validate_params

    for p in sets:
        validate_params(p, config)

    if args.input is not None:
        sequences = [load_sequence(args.input)]
    else:
        sequences = [simulate(args.scenario, seed, num_steps=args.steps) for seed in range(args.seeds)]
    if any(s.ground_truth is None for s in sequences):
        raise ValueError("ground_truth: the sweep ranks parameter sets by error and needs ground truth")
    burn_in = min(args.burn_in, sequences[0].num_steps - 1)

    out = Path(args.output)
    columns = ["index", *names, "mean_error", "max_error", "std_error"]
    done = _read_done(out, columns)
    todo = [i for i, c in enumerate(combos) if _grid_key(c) not in done]
    # Start (or restart) the file with its header and the complete rows only: a row cut short by an
    # interruption is dropped and recomputed. Written atomically, so the finished rows are never at risk.
    _write_atomic(out, "".join(",".join(r) + "\n" for r in [columns, *done.values()]))
    n_dev = len(jax.local_devices())
    per_call = args.batch_size * n_dev
    print(
        f"sweep: {len(combos)} parameter sets ({len(combos) - len(todo)} already in {out}), "
        f"{len(sequences)} sequence(s) x {sequences[0].num_steps} steps, {n_dev} device(s), "
        f"{per_call} sets per call"
    )
    bar = _progress(len(todo))
    key = jax.random.key(args.seed)
    try:
        for start in range(0, len(todo), per_call):
            ids = todo[start : start + per_call]
            padded = ids + [ids[-1]] * (per_call - len(ids))  # same shape every call: one compilation
            batch = stack_params([sets[i] for i in padded])
            errors = []
            for seq in sequences:
                info = sweep(key, seq, batch, config, chunk=args.batch_size)
                est = np.asarray(info.mean, np.float64)[: len(ids)]
                errors.append(np.linalg.norm(est - seq.ground_truth[None], axis=-1)[:, burn_in:])
            err = np.concatenate(errors, axis=1)
            if not np.all(np.isfinite(err)):
                raise RuntimeError("the filter produced a non-finite estimate; please report this")
            with out.open("a") as fh:
                for row, i in enumerate(ids):
                    e = err[row]
                    values = ",".join(f"{v:.9g}" for v in combos[i])
                    fh.write(f"{i},{values},{e.mean():.6f},{e.max():.6f},{e.std():.6f}\n")
                fh.flush()
            bar.update(len(ids))
    finally:
        bar.close()

    rows = list(_read_done(out, columns).values())
    rows.sort(key=lambda r: float(r[-3]))
    print(f"best of {len(rows)} by mean error (errors after step {burn_in}, metres):")
    print("  " + "  ".join(f"{c:>12}" for c in columns[1:]))
    for r in rows[: args.top]:
        print("  " + "  ".join(f"{c:>12}" for c in r[1:]))
    print(f"all results: {out}")
    return 0


def _progress(total: int):
    from tqdm import tqdm

    # disable=None: a live bar on a terminal, silence in logs and CI.
    return tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=False, mininterval=0.5, disable=None)


def _build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="heatpf", description="Heat-map particle filter in Cartesian space (JAX).")
    sub = parser.add_subparsers(dest="command", required=True)

    def common(p):
        p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
        p.add_argument(
            "--set",
            action="append",
            metavar="NAME=VALUE",
            help="override a FilterParams or FilterConfig field (repeatable), e.g. --set k=3",
        )
        p.add_argument("--method", choices=METHODS, default="heatmap", help="filter method (default heatmap)")

    p_run = sub.add_parser("run", help="run the filter on a version-1 sequence file")
    p_run.add_argument("input", help="sequence file (.npz, version 1)")
    p_run.add_argument("--output", "-o", required=True, help="CSV with t,x,y,cov_xx,cov_xy,cov_yy")
    common(p_run)
    p_run.set_defaults(func=_cmd_run)

    p_eval = sub.add_parser("eval", help="the paper's comparison (Table I, Fig. 4, Fig. 6) on every scenario")
    p_eval.add_argument("--scenario", action="append", help="a scenario (repeatable; default: all)")
    p_eval.add_argument("--input", help="evaluate a recording (.npz with ground_truth) instead of the scenarios")
    p_eval.add_argument("--seeds", type=int, default=5, help="sequences per scenario (default 5)")
    p_eval.add_argument("--steps", type=int, default=None, help="steps per sequence (default: the scenario's, 300)")
    p_eval.add_argument("--burn-in", type=int, default=10, help="first steps left out of the statistics (default 10)")
    p_eval.add_argument("--plot", metavar="DIR", help="write Fig. 4 and Fig. 6 per scenario as PNG into DIR")
    p_eval.add_argument("--seed", type=int, default=0, help="PRNG seed of the filters (default 0)")
    p_eval.add_argument("--set", action="append", metavar="NAME=VALUE", help="override a parameter (repeatable)")
    p_eval.set_defaults(func=_cmd_eval)

    p_sweep = sub.add_parser("sweep", help="run the cartesian product of parameter grids, ranked by error")
    p_sweep.add_argument("input", nargs="?", help="sequence file (.npz with ground_truth); or use --scenario")
    p_sweep.add_argument("--scenario", help="a simulated scenario instead of a file")
    p_sweep.add_argument("--grid", action="append", metavar="NAME=V1,V2,...", help="a FilterParams grid (repeatable)")
    p_sweep.add_argument("--output", "-o", default="sweep.csv", help="results CSV; an existing one is resumed")
    p_sweep.add_argument("--seeds", type=int, default=1, help="scenario sequences per set (default 1)")
    p_sweep.add_argument("--steps", type=int, default=None, help="steps per scenario sequence (default 300)")
    p_sweep.add_argument("--batch-size", type=int, default=16, help="sets vmapped together per device (default 16)")
    p_sweep.add_argument("--burn-in", type=int, default=10, help="first steps left out of the errors (default 10)")
    p_sweep.add_argument("--top", type=int, default=5, help="best sets printed (default 5)")
    common(p_sweep)
    p_sweep.set_defaults(func=_cmd_sweep)

    p_demo = sub.add_parser("demo", help="a short evaluation on a built-in simulated sequence")
    p_demo.add_argument("--steps", type=int, default=300, help="number of filter steps (default 300)")
    p_demo.add_argument("--output", "-o", help="optional CSV of the estimates")
    common(p_demo)
    p_demo.set_defaults(func=_cmd_demo)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``heatpf`` console script."""
    from heatpf_jax.sequence import SequenceError

    args = _build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (SequenceError, ValueError, TypeError, RuntimeError) as err:
        print(f"heatpf: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
