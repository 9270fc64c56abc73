"""The ``heatpf`` command: ``run``, ``eval``, ``sweep``, ``tune``, ``demo`` and ``params``.

A user's files come first: every check (settings, paths, burn-in, seeds) runs before anything is
loaded, simulated or compiled; an existing output is replaced only with ``--force`` (the input never);
a sweep resumes a CSV only when the CSV's own record of what produced it matches the command. ``tune``
(:mod:`heatpf_jax.cli_tune`) writes a parameter file (:mod:`heatpf_jax.params_file`) that ``run``, ``eval``
and ``sweep`` read with ``--params`` (the file's values first, ``--set`` on top, then ``--grid`` in a
sweep). JAX's persistent compilation cache (:mod:`heatpf_jax.cache`) makes a second run of the same
shapes start fast.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from heatpf_jax.evaluate import DEFAULT_BURN_IN
from heatpf_jax.files import check_input, check_output, check_output_dir, same_file, write_atomic
from heatpf_jax.settings import (
    LIST_PARAMS,
    check_burn_in,
    checked_settings,
    format_value,
    full_name,
    grid_config,
    layered_settings,
    method_names,
    method_with_settings,
    option_alternatives,
    parse_grid,
    parse_seeds,
    parse_settings,
    scenario_names,
    unused_options,
)
from heatpf_jax.sweep_record import RECORD_INTRO, grid_key, read_done, sweep_record

__all__ = [
    "CSV_HEADER",
    "DEFAULT_BURN_IN",
    "MODES_HEADER",
    "describe_method",
    "error_stats",
    "grid_config",
    "main",
    "parse_grid",
    "parse_seeds",
    "parse_settings",
    "write_estimates_csv",
    "write_modes_csv",
]

CSV_HEADER = "t,x,y,cov_xx,cov_xy,cov_yy"
MODES_HEADER = "t,mode,weight,x,y,cov_xx,cov_xy,cov_yy"
_INTERRUPTED = 130  # the shell's code for a command stopped by Ctrl-C (128 + SIGINT)


# --------------------------------------------------------------------------------------------- names


# --------------------------------------------------------------------------------------------- paths


# ------------------------------------------------------------------------------------------- results


def error_stats(estimates: np.ndarray, truth: np.ndarray, burn_in: int = 0) -> dict[str, float]:
    """Mean, max and std of the Euclidean error after the first ``burn_in`` steps, metres (Table I's columns).

    The same definition as ``heatpf eval`` and ``heatpf demo`` (:meth:`heatpf_jax.evaluate.MethodResult.stats`).
    """
    err = np.linalg.norm(np.asarray(estimates, np.float64) - np.asarray(truth, np.float64), axis=1)[burn_in:]
    if err.size == 0:
        raise ValueError(f"burn_in: {burn_in} leaves no step of the {len(estimates)} steps")
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


TRACKS_HEADER = "t,id,age,x,y,vx,vy"


def write_tracks_csv(path: str | os.PathLike, tracks) -> None:
    """Writes the long-term memory's tracks, ``t,id,age,x,y,vx,vy``, one row per valid track per step, atomically.

    Args:
        path: the CSV file.
        tracks: a :class:`~heatpf_jax.memory.TrackTable` of NumPy arrays with a leading ``T`` axis.
    """
    ids, valid, mean, age = (np.asarray(x) for x in (tracks.id, tracks.valid, tracks.mean, tracks.age))

    def write(fh) -> None:
        fh.write(TRACKS_HEADER + "\n")
        for t, j in zip(*np.nonzero(valid), strict=True):  # by step, then by slot
            x, y, vx, vy = mean[t, j]
            fh.write(f"{t},{ids[t, j]},{age[t, j]:.3f},{x:.6f},{y:.6f},{vx:.6f},{vy:.6f}\n")

    write_atomic(Path(path), write)


def write_modes_csv(path: str | os.PathLike, modes) -> None:
    """Writes ``t,mode,weight,x,y,cov_xx,cov_xy,cov_yy``, one row per valid mode per step, atomically.

    Args:
        path: the CSV file.
        modes: a :class:`~heatpf_jax.modes.Modes` of NumPy arrays with a leading ``T`` axis.
    """
    weight, mean, cov, valid = (np.asarray(x) for x in modes)

    def write(fh) -> None:
        fh.write(MODES_HEADER + "\n")
        for t, j in zip(*np.nonzero(valid), strict=True):  # row-major: by step, then by mode
            c = cov[t, j]
            values = (weight[t, j], mean[t, j, 0], mean[t, j, 1], c[0, 0], c[0, 1], c[1, 1])
            fh.write(f"{t},{j}," + ",".join(f"{v:.6f}" for v in values) + "\n")

    write_atomic(Path(path), write)


# ------------------------------------------------------------------------------------------- --params


def _params_file(args):
    """The checked ``--params`` file (``None`` without one), every error naming ``--params`` and the file."""
    from heatpf_jax.params_file import load_params_file

    if getattr(args, "params", None) is None:
        return None
    try:
        check_input(args.params)
        return load_params_file(args.params)
    except ValueError as err:
        raise ValueError(f"--params: {err}") from None


def _settings_with_params(args):
    """``(options, settings, set_settings)`` of run, sweep and tune: the ``--params`` file beneath ``--set``.

    ``args.method`` becomes the file's method when not given (heatpf's ``heatmap`` without a file); a
    different one is refused. ``settings`` are by dotted name, the file's values with ``--set``'s on top;
    ``set_settings`` are ``--set``'s alone. Everything is checked (ranges included) before any work.
    """
    from heatpf_jax.rollout import validate_params

    loaded = _params_file(args)
    if loaded is not None and args.method not in (None, loaded.method):
        raise ValueError(f"--params: {args.params} holds parameters of method {loaded.method}, not {args.method}; "
                         f"pass --method {loaded.method} or leave --method out")
    if args.method is None:
        args.method = "heatmap" if loaded is None else loaded.method
    options, set_settings = checked_settings(args, [args.method], None if loaded is None else loaded.options)
    if loaded is None:
        return options, set_settings, set_settings
    settings = layered_settings(args.method, options, loaded.params, set_settings)
    model, params = method_with_settings(args.method, options, settings)
    validate_params(params, model)
    return options, settings, set_settings


# ---------------------------------------------------------------------------------------------- run


def _run_filter(seq, args, options, settings):
    import jax

    from heatpf_jax.cache import run_estimates

    model, params = method_with_settings(args.method, options, settings)
    start = time.perf_counter()
    # With the cache on, the traced run is kept as an exported program too: a warm start skips tracing.
    mean, cov, modes, tracks = run_estimates(
        jax.random.key(args.seed), seq, params, model, getattr(args, "cache_dir", None)
    )
    elapsed = time.perf_counter() - start
    if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(cov))):
        bad = int(np.flatnonzero(~np.all(np.isfinite(mean), axis=1) | ~np.all(np.isfinite(cov), axis=(1, 2)))[0])
        raise RuntimeError(f"the filter produced a non-finite estimate at step {bad}; please report this")
    return mean, cov, modes, tracks, elapsed


def _report(name: str, seq, mean, elapsed: float, burn_in: int) -> None:
    print(
        f"{name}: {seq.num_steps} steps, {int(np.sum(seq.has_heatmap))} heat maps, "
        f"{elapsed:.2f} s (including compilation)"
    )
    if seq.ground_truth is None:
        print(f"no ground_truth in {name}: no error statistics")
        return
    stats = error_stats(mean, seq.ground_truth, burn_in)
    print(
        f"error [m] after step {burn_in}: mean {stats['mean']:.4f}  max {stats['max']:.4f}  std {stats['std']:.4f}"
    )


def _cmd_run(args) -> int:
    from heatpf_jax.sequence import load_sequence

    options, settings, _ = _settings_with_params(args)
    if args.modes is not None and options.modes == "none":
        options = options._replace(modes="meanshift")  # --modes without a choice: mean-shift modes
    check_burn_in(args.burn_in)
    out = check_output("--output", args.output, inputs=[args.input], replace=args.force)
    modes_out = _extra_output("--modes", args.modes, args, {"--output": out})
    tracks_out = _extra_output("--tracks", args.tracks, args, {"--output": out, "--modes": modes_out})
    if tracks_out is not None and options.memory == "none":
        raise ValueError("--tracks: the filter has no long-term memory; add --set memory=tracks")
    plot_out = _extra_output("--plot", args.plot, args, {"--output": out, "--modes": modes_out,
                                                          "--tracks": tracks_out})
    if plot_out is not None:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"')
    elif args.plot_step is not None:
        raise ValueError("--plot-step: only with --plot")
    bag_out = _bag_output(args, [args.input, out, modes_out, tracks_out, plot_out])
    seq = load_sequence(args.input)
    if seq.ground_truth is not None:
        check_burn_in(args.burn_in, seq.num_steps)
    if args.plot_step is not None and not 0 <= args.plot_step < seq.num_steps:
        raise ValueError(f"--plot-step: must be in [0, {seq.num_steps - 1}], got {args.plot_step}")
    mean, cov, modes, tracks, elapsed = _run_filter(seq, args, options, settings)
    write_estimates_csv(out, mean, cov)
    if modes_out is not None:
        write_modes_csv(modes_out, modes)
    if tracks_out is not None:
        write_tracks_csv(tracks_out, tracks)
    _report(str(args.input), seq, mean, elapsed, args.burn_in)
    print(f"wrote {out}")
    if modes_out is not None:
        print(f"wrote {modes_out} ({int(np.sum(modes.valid))} modes over {seq.num_steps} steps)")
    if tracks_out is not None:
        print(f"wrote {tracks_out} ({len(np.unique(tracks.id[tracks.valid]))} tracks, "
              f"{int(np.sum(tracks.valid))} rows over {seq.num_steps} steps)")
    if plot_out is not None:
        _plot_run(plot_out, seq, mean, cov, args, options, settings)
    if bag_out is not None:
        _bag_run(bag_out, seq, args, options, settings)
    return 0


def _bag_output(args, others) -> Path | None:
    """``run --bag``: the bag directory checked before any work (:func:`heatpf_jax.rosbag_export.check_bag_output`)."""
    if args.bag is None:
        if args.bag_frame is not None or args.bag_start is not None:
            raise ValueError(f"{'--bag-frame' if args.bag_frame is not None else '--bag-start'}: only with --bag")
        return None
    from heatpf_jax.rosbag_export import check_bag_output

    if args.bag_frame is not None and not args.bag_frame.strip("/ "):
        raise ValueError(f"--bag-frame: a frame name, got {args.bag_frame!r}")
    if args.bag_start is not None and args.bag_start < 0:
        raise ValueError(f"--bag-start: nanoseconds >= 0, got {args.bag_start}")
    return check_bag_output(args.bag, inputs=others, replace=args.force)


def _bag_run(path: Path, seq, args, options, settings) -> None:
    """``run --bag``: the run as a ROS 2 bag (:mod:`heatpf_jax.rosbag_export`), the same run with its states."""
    import jax

    from heatpf_jax.rosbag_export import describe_bag, record_run

    model, params = method_with_settings(args.method, options, settings)
    summary = record_run(path, jax.random.key(args.seed), seq, params, model,
                         frame_id=(args.bag_frame or "base_footprint").strip("/ "), start_ns=args.bag_start)
    print(describe_bag(path, summary))
    if args.bag_start is None and seq.stamps is not None:
        print(f"{path}: stamped with the sequence's clock (its stamps, from {int(seq.stamps[0])} ns)")
    elif args.bag_start is None:
        print(f"{path}: stamps from 0 s every {float(seq.dt):g} s (the sequence has no stamps; --bag-start sets "
              "step 0's stamp)")


def _plot_run(path: Path, seq, mean, cov, args, options, settings) -> None:
    """``run --plot``: the picture of the run (:mod:`heatpf_jax.run_plot`), its step's state replayed exactly."""
    import jax

    from heatpf_jax.run_plot import default_step, plot_run, state_at

    step = default_step(seq.has_heatmap) if args.plot_step is None else args.plot_step
    model, params = method_with_settings(args.method, options, settings)
    state = state_at(jax.random.key(args.seed), seq, params, model, step)
    plot_run(path, seq, mean, cov, step, state, title=f"{Path(args.input).name}: {args.method}",
             burn_in=args.burn_in)
    print(f"wrote {path} (step {step})")


def _extra_output(option: str, path, args, others) -> Path | None:
    """A second output file of ``heatpf run`` (``--modes``, ``--tracks``), checked like ``--output``."""
    if path is None:
        return None
    checked = check_output(option, path, inputs=[args.input], replace=args.force)
    for name, other in others.items():
        if other is not None and (same_file(checked, other) or checked.resolve() == Path(other).resolve()):
            raise ValueError(f"{option}: {path} is also {name}; choose another file")
    return checked


def _cmd_demo(args) -> int:
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, format_table
    from heatpf_jax.sim import simulate

    variants = DEFAULT_VARIANTS[:4]
    options, settings = checked_settings(args, [v.method for v in variants])
    if args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    check_burn_in(args.burn_in, args.steps)
    out = None if args.output is None else check_output("--output", args.output, replace=args.force)
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
        burn_in=args.burn_in,
    )
    print(format_table(result))
    print(f"({time.perf_counter() - start:.1f} s including compilation)")
    if out is not None:
        write_estimates_csv(out, result.methods[0].estimates[0], np.zeros((args.steps, 2, 2)))
        print(f"wrote {out} (heatmap estimates; covariances are in `heatpf run`)")
    return 0


# --------------------------------------------------------------------------------------------- eval


def _eval_jobs(args) -> tuple[list[tuple[str, str | None]], range, int | None]:
    """``[(name, scenario or None for --input)]``, the seeds and the steps per sequence (None: the file's)."""
    from heatpf_jax.sim.scenarios import DEFAULT_NUM_STEPS

    if args.input:
        options = (("--scenario", args.scenario), ("--seeds", args.seeds), ("--steps", args.steps),
                   ("--family", args.family or None))
        given = [o for o, v in options if v is not None]
        if given:
            raise ValueError(f"{given[0]}: applies to the simulated scenarios, not to --input")
        check_input(args.input)
        return [(Path(args.input).stem, None)], range(1), None
    known = _family_members() if args.family else scenario_names()
    names = args.scenario or list(known)
    unknown = [n for n in names if n not in known]
    if unknown:
        what = "family member" if args.family else "scenario"
        raise ValueError(f"--scenario: unknown {what} {unknown[0]!r} (known: {', '.join(known)})")
    seeds = parse_seeds(args.seeds, 5)
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps: must be >= 1, got {args.steps}")
    label = "family/{}" if args.family else "{}"
    return [(label.format(n), n) for n in names], seeds, DEFAULT_NUM_STEPS if args.steps is None else args.steps


def _family_members() -> tuple[str, ...]:
    from heatpf_jax.sim.family import FAMILY

    return FAMILY


def _variants_with_params(variants, loaded, options, settings):
    """The variants of the file's method with its parameters beneath ``--set`` and the variant's own changes.

    Checked here (ranges included), before any sequence is simulated or loaded.
    """
    import dataclasses

    from heatpf_jax import params as P
    from heatpf_jax.rollout import validate_params

    method = loaded.method
    own = layered_settings(method, options, loaded.params, settings, skip_unknown=True)
    out = []
    for v in variants:
        if v.method == method:
            v = dataclasses.replace(v, overrides={**own, **v.overrides})
            model, params = method_with_settings(method, options, {})
            validate_params(P.set_by_name(params, model.properties(), v.overrides), model)
        out.append(v)
    return out


def _cmd_eval(args) -> int:
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, factor_breakdown, format_table, plot_scenario
    from heatpf_jax.sequence import load_sequence
    from heatpf_jax.sim import simulate_family_with_info, simulate_with_info

    loaded = _params_file(args)
    if loaded is not None and args.method and loaded.method not in args.method:
        raise ValueError(f"--params: {args.params} holds parameters of method {loaded.method}, which --method "
                         f"leaves out; add --method {loaded.method}")
    variants = [v for v in DEFAULT_VARIANTS if not args.method or v.method in args.method]
    options, settings = checked_settings(
        args, sorted({v.method for v in variants}), None if loaded is None else loaded.options
    )
    if loaded is not None:
        variants = _variants_with_params(variants, loaded, options, settings)
    jobs, seeds, steps = _eval_jobs(args)
    check_burn_in(args.burn_in, steps)
    if args.plot:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"')
        check_output_dir(args.plot)

    if loaded is not None:
        print(f"{loaded.method}: the parameters of {args.params} (--set on top)")
    total = len(jobs) * (len(seeds) + len(variants))
    bar = _progress(total)
    written = []
    try:
        for name, scenario in jobs:
            targets = None  # several balls (two_balls): the error is to the nearest
            if scenario is None:
                sequences = [load_sequence(args.input)]
                check_burn_in(args.burn_in, sequences[0].num_steps)
                bar.update(1)
            else:
                sequences, targets, factors = [], [], []
                for seed in seeds:
                    bar.set_description(f"{name} seed {seed}")
                    simulate = simulate_family_with_info if args.family else simulate_with_info
                    seq, info = simulate(scenario, seed, num_steps=steps)
                    sequences.append(seq)
                    targets.append(info["balls_base"])
                    factors.append(info.get("factors", {}))
                    bar.update(1)

            def tick(label: str) -> None:
                bar.set_description(label)
                bar.update(1)

            result = evaluate_sequences(
                name, sequences, options=options, settings=settings, seed=args.seed, burn_in=args.burn_in,
                progress=tick, targets=targets, variants=variants,
            )
            bar.write(format_table(result) + "\n")
            if args.family and scenario is not None:
                bar.write(factor_breakdown(result, factors) + "\n")
            if args.plot:
                written += plot_scenario(result, args.plot)
    finally:
        bar.close()
    for path in written:
        print(f"wrote {path}")
    return 0


# -------------------------------------------------------------------------------------------- sweep

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


def _cmd_sweep(args) -> int:
    import itertools

    from heatpf_jax import params as P
    from heatpf_jax.rollout import validate_params
    from heatpf_jax.sequence import load_sequence
    from heatpf_jax.sim import simulate

    options, settings, set_settings = _settings_with_params(args)  # --grid goes on top of both
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
    names = list(grid)
    combos = list(itertools.product(*grid.values()))
    sets = [P.set_by_name(params, model.properties(), dict(zip(names, c, strict=True))) for c in combos]
    for p in sets:  # every set checked before any work
        validate_params(p, model)
    grid_names = {full_name(n, args.method, options) for n in names}
    record = sweep_record(args, seeds, steps, options, model, params, grid_names)
    columns = ["index", *names, "mean_error", "max_error", "std_error"]
    done = read_done(out, record, columns)

    if args.input is not None:
        sequences = [load_sequence(args.input)]
        check_burn_in(args.burn_in, sequences[0].num_steps)
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
        return _INTERRUPTED
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


# ------------------------------------------------------------------------------------------- params


def _option_choices() -> dict[str, str]:
    from heatpf_jax.ego import EGO_MOTIONS
    from heatpf_jax.observation import KNN_METHODS
    from heatpf_jax.presets import MEMORIES, MODE_FINDERS, OBSERVATIONS, RESAMPLERS, SOURCES, SPAWNS

    return {
        "resampler": "one of " + ", ".join(sorted(RESAMPLERS)),
        "spawn": "one of " + ", ".join(SPAWNS),
        "spawn_box": "x_min,x_max,y_min,y_max (metres)",
        "observation": "one of auto, " + ", ".join(OBSERVATIONS),
        "modes": "one of " + ", ".join(MODE_FINDERS),
        "knn": "one of " + ", ".join(KNN_METHODS),
        "ego": "one of " + ", ".join(EGO_MOTIONS),
        "memory": "one of " + ", ".join(MEMORIES),
        "source": "one of auto, " + ", ".join(SOURCES),
    }


def _table(rows: list[tuple[str, ...]]) -> list[str]:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return ["  " + "  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)).rstrip() for r in rows]


def describe_method(method: str, options=None, settings: dict | None = None) -> str:
    """Every parameter of ``method`` (dotted name, value, allowed range, trainable or frozen) and the static options.

    Args:
        method: a name in ``heatpf_jax.presets.METHODS``.
        options: the static options (default :class:`~heatpf_jax.presets.FilterOptions()`).
        settings: ``{name: value}`` applied to the defaults first.

    Returns:
        The text ``heatpf params`` prints.
    """
    import jax

    from heatpf_jax import params as P
    from heatpf_jax.presets import FilterOptions

    options = FilterOptions() if options is None else options
    model, params = method_with_settings(method, options, settings or {})
    props = model.properties()
    rows = [("name", "value", "allowed", "tuning")]
    for name, value, prop in zip(
        P.leaf_names(props), jax.tree.leaves(params), jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, P.Param)),
        strict=True,
    ):
        rows.append((name, format_value(value), prop.describe(), "trainable" if prop.trainable else "frozen"))
    unused = {
        f for f in FilterOptions._fields
        if f in unused_options(FilterOptions()._replace(**{f: option_alternatives(f)[0]}), [method])
    }
    choices = _option_choices()
    o_rows = [("name", "value", "allowed")]
    for name, value in options._asdict().items():
        note = choices.get(name, "a positive integer")
        o_rows.append((name, format_value(value), note + (f" (not used by {method})" if name in unused else "")))
    first, value = rows[1][0], rows[1][1]
    return "\n".join([
        f"parameters of {method} (--set NAME=VALUE, or --grid NAME=V1,V2 in `heatpf sweep`; the last part of a",
        f"name is enough where it is unambiguous: --set {first.rsplit('.', 1)[-1]}={value} sets {first}):",
        *_table(rows),
        "static options (--set NAME=VALUE; each value compiles its own program, so they cannot be swept):",
        *_table(o_rows),
    ])


def _cmd_params(args) -> int:
    options, settings, _ = _settings_with_params(args)
    print(describe_method(args.method, options, settings))
    return 0


# -------------------------------------------------------------------------------------------- parser


def _progress(total: int):
    from tqdm import tqdm

    # disable=None: a live bar on a terminal, silence in logs and CI.
    return tqdm(total=total, file=sys.stderr, dynamic_ncols=True, leave=False, mininterval=0.5, disable=None)


def _add_set(p, what: str = "a parameter") -> None:
    p.add_argument(
        "--set",
        action="append",
        metavar="NAME=VALUE",
        help=f"{what} (dotted, e.g. motion.diffusion_std, or its last part: diffusion_std) or a static option "
        f"(num_particles, resampler, ...), repeatable, e.g. --set k=3; {LIST_PARAMS}",
    )


def _add_burn_in(p) -> None:
    p.add_argument(
        "--burn-in",
        type=int,
        default=DEFAULT_BURN_IN,
        help=f"first steps left out of the error statistics (default {DEFAULT_BURN_IN}, as in every command)",
    )


def _add_method(p, verb: str = "run", params_file: bool = False) -> None:
    default = "the --params file's method, else heatmap" if params_file else "heatmap"
    p.add_argument(
        "--method", choices=method_names(), default=None if params_file else "heatmap",
        help=f"filter method to {verb} (default {default})",
    )


def _add_params(p) -> None:
    p.add_argument(
        "--params", metavar="TUNED.json", help="start from a parameter file (`heatpf tune --output`): its "
        "parameters and static options; --set goes on top",
    )


def _global_options() -> argparse.ArgumentParser:
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument(
        "--no-cache",
        action="store_true",
        help="do not use the compilation cache (~/.cache/heatpf_jax/jax, or $HEATPF_CACHE_DIR; "
        "HEATPF_NO_CACHE=1 does the same)",
    )
    return parent


class _Parser(argparse.ArgumentParser):
    """An ``ArgumentParser`` whose usage errors are one line (``heatpf run: error: ...``), not a usage block."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _build_parser() -> argparse.ArgumentParser:
    from heatpf_jax import __version__

    parser = _Parser(
        prog="heatpf",
        description="Heat-map particle filter in Cartesian space (JAX).",
        epilog="Compiled programs are cached on disk (~/.cache/heatpf_jax/jax; $HEATPF_CACHE_DIR moves it), so a "
        "second run of the same shapes starts fast; --no-cache or HEATPF_NO_CACHE=1 turns that off.",
    )
    parser.add_argument(
        "--no-cache", dest="no_cache_global", action="store_true", help="as the subcommands' --no-cache"
    )
    parser.add_argument("--version", action="version", version=f"heatpf {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    parent = [_global_options()]
    scenarios = ", ".join(scenario_names())

    p_run = sub.add_parser(
        "run", parents=parent, help="run the filter on a version-1 sequence file",
        epilog="Parameter names, defaults and ranges: heatpf params --method NAME.",
    )
    p_run.add_argument("input", help="sequence file (.npz, version 1)")
    p_run.add_argument("--output", "-o", required=True, help="CSV with t,x,y,cov_xx,cov_xy,cov_yy (not replaced "
                       "if it exists, unless --force)")
    p_run.add_argument("--modes", metavar="MODES.csv", help="also write the modes of the particles per step: "
                       "t,mode,weight,x,y,cov_xx,cov_xy,cov_yy, one row per valid mode (by --set modes=meanshift|"
                       "kmeans|gmm, default meanshift; --set max_modes=K)")
    p_run.add_argument("--tracks", metavar="TRACKS.csv", help="also write the long-term memory's tracks per step: "
                       "t,id,age,x,y,vx,vy, one row per track (needs --set memory=tracks)")
    p_run.add_argument("--plot", metavar="RUN.png", help="also draw the run: the estimate against the ground truth, "
                       "the error and spread over time, and one step's heat map, measurements and particles (needs "
                       "matplotlib: pip install 'heatpf-jax[plot]')")
    p_run.add_argument("--plot-step", type=int, default=None, metavar="N", help="the step --plot draws (default: the "
                       "last step with a heat map)")
    p_run.add_argument("--force", action="store_true", help="replace existing --output, --modes, --tracks and "
                       "--plot files")
    p_run.add_argument("--bag", metavar="DIR", help="also write the run as a ROS 2 bag (rosbag2, MCAP) for Foxglove or "
                       "ros2 bag play: estimate, particles, measurements, modes, tracks, camera tf under /heatpf "
                       "(needs rosbags: pip install 'heatpf-jax[ros]'; an existing bag is replaced only with --force)")
    p_run.add_argument("--bag-frame", metavar="FRAME", help="the bag's frame_id, the robot's base frame (default "
                       "base_footprint)")
    p_run.add_argument("--bag-start", type=int, metavar="NS", help="the stamp of step 0 in the bag, nanoseconds, "
                       "the others dt apart (default: the sequence's own stamps, which import-rosbag keeps, else 0)")
    p_run.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    _add_burn_in(p_run)
    _add_set(p_run)
    _add_params(p_run)
    _add_method(p_run, params_file=True)
    p_run.set_defaults(func=_cmd_run)

    p_eval = sub.add_parser(
        "eval", parents=parent, help="the paper's comparison (Table I, Fig. 4, Fig. 6) on every scenario",
        epilog=f"Scenarios: {scenarios}.",
    )
    p_eval.add_argument("--scenario", action="append", help=f"a scenario, repeatable (default: all): {scenarios}; "
                        "with --family, a family member")
    p_eval.add_argument("--family", action="store_true", help="the world family instead of the fixed scenarios: "
                        "each scenario type with its nuisance factors drawn per seed (heatpf_jax.sim.family), "
                        "with a per-factor breakdown of the errors")
    p_eval.add_argument("--input", help="evaluate a recording (.npz with ground_truth) instead of the scenarios")
    p_eval.add_argument("--seeds", metavar="N|START:STOP", help="sequences per scenario: N (seeds 0..N-1, "
                        "default 5) or START:STOP (e.g. 200:216)")
    p_eval.add_argument("--steps", type=int, default=None, help="steps per sequence (default: the scenario's, 300)")
    _add_burn_in(p_eval)
    p_eval.add_argument("--plot", metavar="DIR", help="write Fig. 4 and Fig. 6 per scenario as PNG into DIR "
                        "(created if missing; PNGs of the same names there are replaced)")
    p_eval.add_argument("--seed", type=int, default=0, help="PRNG seed of the filters (default 0)")
    p_eval.add_argument("--method", action="append", choices=method_names(),
                        help="a method to compare, repeatable (default: all, with the paper's aging ablations)")
    _add_set(p_eval, "a parameter of any method")
    p_eval.add_argument(
        "--params", metavar="TUNED.json", help="a parameter file (`heatpf tune --output`) for the rows of its "
        "method (--set on top); its static options apply to every method, as --set's do",
    )
    p_eval.set_defaults(func=_cmd_eval)

    p_sweep = sub.add_parser(
        "sweep", parents=parent, help="run the cartesian product of parameter grids, ranked by error",
        epilog=f"Scenarios: {scenarios}. The CSV records what produced its rows (# lines); the same command "
        "resumes it, another one is refused.",
    )
    p_sweep.add_argument("input", nargs="?", help="sequence file (.npz with ground_truth); or use --scenario")
    p_sweep.add_argument("--scenario", help=f"a simulated scenario instead of a file: {scenarios}")
    p_sweep.add_argument("--grid", action="append", metavar="NAME=V1,V2,...", help="a parameter grid (repeatable)")
    p_sweep.add_argument("--output", "-o", default="sweep.csv", help="results CSV (default sweep.csv); an existing "
                         "one is resumed when it holds this sweep, refused otherwise")
    p_sweep.add_argument("--seeds", metavar="N|START:STOP", help="scenario sequences per set: N (seeds 0..N-1, "
                         "default 1) or START:STOP")
    p_sweep.add_argument("--steps", type=int, default=None, help="steps per scenario sequence (default 300)")
    p_sweep.add_argument("--batch-size", type=int, default=16, help="sets vmapped together per device (default 16)")
    _add_burn_in(p_sweep)
    p_sweep.add_argument("--top", type=int, default=5, help="best sets printed (default 5)")
    p_sweep.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    _add_set(p_sweep, "a fixed parameter")
    _add_params(p_sweep)
    _add_method(p_sweep, "sweep", params_file=True)
    p_sweep.set_defaults(func=_cmd_sweep)
    from heatpf_jax import cli_tune

    cli_tune.add_parser(sub, parent, scenarios)

    p_demo = sub.add_parser("demo", parents=parent, help="a short evaluation on a built-in simulated sequence")
    p_demo.add_argument("--steps", type=int, default=300, help="number of filter steps (default 300)")
    _add_burn_in(p_demo)
    p_demo.add_argument("--output", "-o", help="optional CSV of the estimates (not replaced if it exists, unless "
                        "--force)")
    p_demo.add_argument("--force", action="store_true", help="replace an existing --output")
    p_demo.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    _add_set(p_demo, "a parameter of any method")
    p_demo.set_defaults(func=_cmd_demo)

    p_params = sub.add_parser(
        "params", parents=parent, help="list a method's parameters (names, defaults, ranges) and the static options"
    )
    _add_method(p_params, "describe", params_file=True)
    p_params.add_argument("--set", action="append", metavar="NAME=VALUE",
                          help="show the values with these settings (e.g. --set observation=gaussian)")
    p_params.add_argument("--params", metavar="TUNED.json", help="show the values of a parameter file "
                          "(`heatpf tune --output`), --set on top")
    p_params.set_defaults(func=_cmd_params)

    from heatpf_jax import cli_rgb, cli_simulate, rosbag_import

    cli_rgb.add_parser(sub, parent)
    rosbag_import.add_parser(sub, parent)
    cli_simulate.add_parsers(sub, parent)
    return parser


def _os_error_text(err: OSError) -> str:
    where = f"{err.filename}: " if err.filename else ""
    return f"{where}{err.strerror or err}"


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Shows a warning as one ``heatpf: warning: ...`` line on stderr (no source file, no line of code)."""
    print(f"heatpf: warning: {message}", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``heatpf`` console script.

    Returns:
        0 on success; 2 after a one-line ``heatpf: error: ...`` on stderr; 130 when interrupted (Ctrl-C).
    """
    from heatpf_jax.cache import compilation_cache
    from heatpf_jax.sequence import SequenceError

    args = _build_parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.showwarning = _one_line_warning
            no_cache = getattr(args, "no_cache", False) or args.no_cache_global
            with compilation_cache(enabled=not no_cache) as cache_dir:
                args.cache_dir = cache_dir
                return args.func(args)
    except KeyboardInterrupt:
        print("heatpf: interrupted", file=sys.stderr)
        return _INTERRUPTED
    except (SequenceError, ValueError, TypeError, RuntimeError) as err:
        print(f"heatpf: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `heatpf params | head`: the reader left; say nothing more
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    except OSError as err:
        print(f"heatpf: error: {_os_error_text(err)}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
