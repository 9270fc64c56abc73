"""The ``heatpf`` command: ``heatpf demo`` and ``heatpf run``."""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from heatpf_jax.files import write_atomic

__all__ = ["error_stats", "grid_config", "main", "parse_settings", "write_estimates_csv"]

CSV_HEADER = "t,x,y,cov_xx,cov_xy,cov_yy"
# Names of earlier versions, still accepted by --set and --grid.
_ALIASES = {"kalman_accel_std": "accel_std", "kalman_meas_std": "meas_std"}


def _method_names() -> list[str]:
    from heatpf_jax.presets import METHODS

    return list(METHODS)


def _param_of(name: str, methods, options, typed: str | None = None):
    """The :class:`~heatpf_jax.params.Param` that ``name`` refers to in the first of ``methods`` that has it.

    ``typed`` is the name as the user wrote it (a legacy alias), for the error message.
    """
    import jax

    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    known = []
    for method in methods:
        props = build(method, options).model.properties()
        names = P.leaf_names(props)
        full = P.resolve_name(name, names)
        if full is not None:
            return jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param))[names.index(full)]
        known += [n for n in names if n not in known]
    where = f"method {methods[0]}" if len(methods) == 1 else "any method"
    raise ValueError(f"{typed or name}: not a parameter of {where} (known: {', '.join(known)}; static options: "
                     f"{', '.join(_options_fields())})")


def _options_fields() -> tuple[str, ...]:
    from heatpf_jax.presets import FilterOptions

    return FilterOptions._fields


def parse_settings(assignments: list[str], methods=("heatmap",)):
    """Parses ``--set name=value`` items into static options and parameter settings.

    A name is a :class:`~heatpf_jax.presets.FilterOptions` field (``num_particles``, ``resampler``,
    ...) or a parameter of one of ``methods``, dotted (``motion.diffusion_std``) or by its last
    part where that is unambiguous (``diffusion_std``). A ``k`` above the default ``k_max`` raises
    ``k_max``, unless ``k_max`` was given too.

    Returns:
        ``(options, settings)``: a :class:`~heatpf_jax.presets.FilterOptions` and ``{name: value}``.

    Raises:
        ValueError: naming the field when it is unknown or its value does not parse.
    """
    from heatpf_jax.presets import FilterOptions, validate_options

    o_updates, raw = {}, {}
    for item in assignments:
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--set: expected name=value, got {item!r}")
        if name in FilterOptions._fields:
            default = FilterOptions._field_defaults[name]
            if name == "spawn_box":
                parts = value.split(",")
                if len(parts) != 4:
                    raise ValueError(f"spawn_box: expected x_min,x_max,y_min,y_max, got {value!r}")
                o_updates[name] = tuple(_parse(name, p, float) for p in parts)
            else:
                o_updates[name] = _parse(name, value, type(default))
        else:
            raw[name] = value
    options = FilterOptions()._replace(**o_updates)
    validate_options(options)
    settings = {}
    for typed, value in raw.items():
        name = _ALIASES.get(typed, typed)
        prop = _param_of(name, list(methods), options, typed)
        settings[name] = _parse(typed, value, int if prop.integer else float)
    k = settings.get("k")
    if "k_max" not in o_updates and isinstance(k, int) and k > options.k_max:
        options = options._replace(k_max=k)
    return options, settings


def grid_config(options, grid: dict[str, list], assignments: list[str]):
    """The sweep's options: ``k_max`` raised to the grid's largest k (one compilation covers the
    whole grid), unless ``--set k_max=...`` was given."""
    if "k" in grid and not any(item.partition("=")[0].strip() == "k_max" for item in assignments):
        options = options._replace(k_max=max(options.k_max, *grid["k"]))
    return options


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


def write_estimates_csv(path: str | os.PathLike, mean: np.ndarray, cov: np.ndarray) -> None:
    """Writes ``t,x,y,cov_xx,cov_xy,cov_yy`` atomically (temporary file renamed into place)."""
    path = Path(path)
    t = np.arange(mean.shape[0])
    table = np.column_stack([t, mean[:, 0], mean[:, 1], cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]])

    def write(fh) -> None:
        fh.write(CSV_HEADER + "\n")
        for row in table:
            fh.write(f"{int(row[0])}," + ",".join(f"{v:.6f}" for v in row[1:]) + "\n")

    write_atomic(path, write)


def _settings(args, methods):
    """Parses and checks --set for every method before any data is loaded or simulated."""
    from heatpf_jax import params as P
    from heatpf_jax.presets import build
    from heatpf_jax.rollout import validate_params

    options, settings = parse_settings(args.set or [], methods)
    for method in methods:
        model, params = build(method, options)
        validate_params(P.set_by_name(params, model.properties(), settings, skip_unknown=True), model)
    return options, settings


def _method(method: str, options, settings):
    """The model of ``method`` and its params with every setting applied (each must be one of its parameters)."""
    from heatpf_jax import params as P
    from heatpf_jax.presets import build

    model, params = build(method, options)
    return model, P.set_by_name(params, model.properties(), settings)


def _run_filter(seq, args, options, settings):
    import jax

    from heatpf_jax.rollout import run

    model, params = _method(args.method, options, settings)
    start = time.perf_counter()
    result = run(jax.random.key(args.seed), seq, params, model)
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

    options, settings = _settings(args, [args.method])
    seq = load_sequence(args.input)
    mean, cov, elapsed = _run_filter(seq, args, options, settings)
    write_estimates_csv(args.output, mean, cov)
    _report(str(args.input), seq, mean, cov, elapsed)
    print(f"wrote {args.output}")
    return 0


def _cmd_demo(args) -> int:
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, format_table
    from heatpf_jax.sim import simulate

    variants = DEFAULT_VARIANTS[:4]
    options, settings = _settings(args, [v.method for v in variants])
    if args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    print("heatpf demo: simulated 'standard' scenario (static robot, 200x150 heat map every step, 10 Hz);")
    print("the short version of `heatpf eval` (one scenario, one sequence)")
    start = time.perf_counter()
    seq = simulate("standard", args.seed, num_steps=args.steps)
    result = evaluate_sequences(
        "standard",
        [seq],
        options=options,
        settings=settings,
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

    options, settings = _settings(args, sorted({v.method for v in DEFAULT_VARIANTS}))
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
                name, sequences, options=options, settings=settings, seed=args.seed, burn_in=args.burn_in,
                progress=tick
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


def parse_grid(items: list[str], method: str = "heatmap") -> dict[str, list]:
    """Parses ``--grid name=v1,v2,...`` into ``{name: [values]}`` (parameters of ``method`` only).

    Raises:
        ValueError: naming the field when it is unknown, static, repeated or a value does not parse.
    """
    from heatpf_jax.presets import FilterOptions

    grid: dict[str, list] = {}
    for item in items:
        name, sep, raw = item.partition("=")
        name = name.strip()
        if not sep or not name or not raw.strip():
            raise ValueError(f"--grid: expected name=v1,v2,..., got {item!r}")
        if name in FilterOptions._fields:
            raise ValueError(f"{name}: a static option cannot be swept in one compilation; use --set")
        typed, name = name, _ALIASES.get(name, name)
        prop = _param_of(name, [method], FilterOptions(), typed)
        if name in grid:
            raise ValueError(f"{name}: given twice in --grid")
        grid[name] = [_parse(name, v, int if prop.integer else float) for v in raw.split(",")]
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

    from heatpf_jax import params as P
    from heatpf_jax.rollout import stack_params, validate_params
    from heatpf_jax.sequence import load_sequence
    from heatpf_jax.sim import SCENARIOS, simulate
    from heatpf_jax.sweep import sweep

    options, settings = _settings(args, [args.method])
    grid = parse_grid(args.grid or [], args.method)
    options = grid_config(options, grid, args.set or [])
    model, params = _method(args.method, options, settings)
    if (args.input is None) == (args.scenario is None):
        raise ValueError("sweep: give either INPUT.npz or --scenario NAME")
    if args.scenario is not None and args.scenario not in SCENARIOS:
        raise ValueError(f"--scenario: unknown {args.scenario!r} (known: {', '.join(SCENARIOS)})")
    if args.seeds < 1 or args.batch_size < 1:
        raise ValueError("--seeds and --batch-size: must be >= 1")
    names = list(grid)
    combos = list(itertools.product(*grid.values()))
    props = model.properties()
    sets = [P.set_by_name(params, props, dict(zip(names, c, strict=True))) for c in combos]
    # Check every set before any work.
    for p in sets:
        validate_params(p, model)

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
    text = "".join(",".join(r) + "\n" for r in [columns, *done.values()])
    write_atomic(out, lambda fh: fh.write(text))
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
                info = sweep(key, seq, batch, model, chunk=args.batch_size)
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
            help="a parameter (dotted, e.g. motion.diffusion_std, or its last part: diffusion_std) or a static "
            "option (num_particles, resampler, ...), repeatable, e.g. --set k=3",
        )

    def method(p):
        p.add_argument("--method", choices=_method_names(), default="heatmap", help="filter method (default heatmap)")

    p_run = sub.add_parser("run", help="run the filter on a version-1 sequence file")
    p_run.add_argument("input", help="sequence file (.npz, version 1)")
    p_run.add_argument("--output", "-o", required=True, help="CSV with t,x,y,cov_xx,cov_xy,cov_yy")
    common(p_run)
    method(p_run)
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
    p_sweep.add_argument("--grid", action="append", metavar="NAME=V1,V2,...", help="a parameter grid (repeatable)")
    p_sweep.add_argument("--output", "-o", default="sweep.csv", help="results CSV; an existing one is resumed")
    p_sweep.add_argument("--seeds", type=int, default=1, help="scenario sequences per set (default 1)")
    p_sweep.add_argument("--steps", type=int, default=None, help="steps per scenario sequence (default 300)")
    p_sweep.add_argument("--batch-size", type=int, default=16, help="sets vmapped together per device (default 16)")
    p_sweep.add_argument("--burn-in", type=int, default=10, help="first steps left out of the errors (default 10)")
    p_sweep.add_argument("--top", type=int, default=5, help="best sets printed (default 5)")
    common(p_sweep)
    method(p_sweep)
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
