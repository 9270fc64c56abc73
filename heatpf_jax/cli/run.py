"""``heatpf run``: the filter on a version-1 sequence file, its estimates as CSV, and on request more outputs.

Writes ``t,x,y,cov_xx,cov_xy,cov_yy`` per step (:func:`write_estimates_csv`) and, with ``--modes`` and
``--tracks``, the particles' modes (:func:`write_modes_csv`) and the long-term memory's tracks
(:func:`write_tracks_csv`); ``--plot`` draws the run (:mod:`heatpf_jax.cli.run_plot`) and ``--bag`` records it as
a ROS 2 bag (:mod:`heatpf_jax.io.rosbag_export`). Every output is checked before the sequence is loaded, none is
another, and an existing one is replaced only with ``--force`` (the input never). The parameters are the
method's defaults, a ``--params`` file's, with ``--set`` on top (:func:`heatpf_jax.cli.options.settings_with_params`).
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np

from heatpf_jax.cli.options import add_burn_in, add_method, add_params, add_set, error_stats, settings_with_params
from heatpf_jax.cli.settings import check_burn_in, method_with_settings, sequence_settings
from heatpf_jax.io.files import check_output, same_file, write_atomic

__all__ = [
    "CSV_HEADER",
    "MODES_HEADER",
    "TRACKS_HEADER",
    "add_parser",
    "cmd_run",
    "write_estimates_csv",
    "write_modes_csv",
    "write_tracks_csv",
]

CSV_HEADER = "t,x,y,cov_xx,cov_xy,cov_yy"
MODES_HEADER = "t,mode,weight,x,y,cov_xx,cov_xy,cov_yy"
TRACKS_HEADER = "t,id,age,x,y,vx,vy"


# ---------------------------------------------------------------------------------------------- CSV files


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


def write_tracks_csv(path: str | os.PathLike, tracks) -> None:
    """Writes the long-term memory's tracks, ``t,id,age,x,y,vx,vy``, one row per valid track per step, atomically.

    Args:
        path: the CSV file.
        tracks: a :class:`~heatpf_jax.memory.table.TrackTable` of NumPy arrays with a leading ``T`` axis.
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
        modes: a :class:`~heatpf_jax.estimate.modes.Modes` of NumPy arrays with a leading ``T`` axis.
    """
    weight, mean, cov, valid = (np.asarray(x) for x in modes)

    def write(fh) -> None:
        fh.write(MODES_HEADER + "\n")
        for t, j in zip(*np.nonzero(valid), strict=True):  # row-major: by step, then by mode
            c = cov[t, j]
            values = (weight[t, j], mean[t, j, 0], mean[t, j, 1], c[0, 0], c[0, 1], c[1, 1])
            fh.write(f"{t},{j}," + ",".join(f"{v:.6f}" for v in values) + "\n")

    write_atomic(Path(path), write)


# --------------------------------------------------------------------------------------------------- run


def _run_filter(seq, args, options, settings):
    import jax

    from heatpf_jax.io.cache import run_estimates

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


def cmd_run(args: argparse.Namespace) -> int:
    """Runs ``heatpf run`` on the parsed ``args``; returns the exit code (0)."""
    from heatpf_jax.io.sequence import load_sequence

    options, settings, _ = settings_with_params(args)
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
    given = {item.partition("=")[0].strip() for item in args.set or []}
    options, settings = sequence_settings(seq, str(args.input), [args.method], options, settings, given,
                                          pinned=args.params is not None)
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


def _extra_output(option: str, path, args, others) -> Path | None:
    """A second output file of ``heatpf run`` (``--modes``, ``--tracks``), checked like ``--output``."""
    if path is None:
        return None
    checked = check_output(option, path, inputs=[args.input], replace=args.force)
    for name, other in others.items():
        if other is not None and (same_file(checked, other) or checked.resolve() == Path(other).resolve()):
            raise ValueError(f"{option}: {path} is also {name}; choose another file")
    return checked


def _bag_output(args, others) -> Path | None:
    """``run --bag``: the bag directory checked before any work
    (:func:`heatpf_jax.io.rosbag_export.check_bag_output`)."""
    if args.bag is None:
        if args.bag_frame is not None or args.bag_start is not None:
            raise ValueError(f"{'--bag-frame' if args.bag_frame is not None else '--bag-start'}: only with --bag")
        return None
    from heatpf_jax.io.rosbag_export import check_bag_output

    if args.bag_frame is not None and not args.bag_frame.strip("/ "):
        raise ValueError(f"--bag-frame: a frame name, got {args.bag_frame!r}")
    if args.bag_start is not None and args.bag_start < 0:
        raise ValueError(f"--bag-start: nanoseconds >= 0, got {args.bag_start}")
    return check_bag_output(args.bag, inputs=others, replace=args.force)


def _bag_run(path: Path, seq, args, options, settings) -> None:
    """``run --bag``: the run as a ROS 2 bag (:mod:`heatpf_jax.io.rosbag_export`), the same run with its states."""
    import jax

    from heatpf_jax.io.rosbag_export import describe_bag, record_run

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
    """``run --plot``: the picture of the run (:mod:`heatpf_jax.cli.run_plot`), its step's state replayed exactly."""
    import jax

    from heatpf_jax.cli.run_plot import default_step, plot_run, state_at

    step = default_step(seq.has_heatmap) if args.plot_step is None else args.plot_step
    model, params = method_with_settings(args.method, options, settings)
    state = state_at(jax.random.key(args.seed), seq, params, model, step)
    plot_run(path, seq, mean, cov, step, state, title=f"{Path(args.input).name}: {args.method}",
             burn_in=args.burn_in)
    print(f"wrote {path} (step {step})")


# ------------------------------------------------------------------------------------------------ parser


def add_parser(sub, parents: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Registers ``run`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser."""
    p = sub.add_parser(
        "run", parents=parents, help="run the filter on a version-1 sequence file",
        epilog="Parameter names, defaults and ranges: heatpf params --method NAME.",
    )
    p.add_argument("input", help="sequence file (.npz, version 1)")
    p.add_argument("--output", "-o", required=True, help="CSV with t,x,y,cov_xx,cov_xy,cov_yy (not replaced "
                   "if it exists, unless --force)")
    p.add_argument("--modes", metavar="MODES.csv", help="also write the modes of the particles per step: "
                   "t,mode,weight,x,y,cov_xx,cov_xy,cov_yy, one row per valid mode (by --set modes=meanshift|"
                   "kmeans|gmm, default meanshift; --set max_modes=K)")
    p.add_argument("--tracks", metavar="TRACKS.csv", help="also write the long-term memory's tracks per step: "
                   "t,id,age,x,y,vx,vy, one row per track (needs --set memory=tracks)")
    p.add_argument("--plot", metavar="RUN.png", help="also draw the run: the estimate against the ground truth, "
                   "the error and spread over time, and one step's heat map, measurements and particles (needs "
                   "matplotlib: pip install 'heatpf-jax[plot]')")
    p.add_argument("--plot-step", type=int, default=None, metavar="N", help="the step --plot draws (default: the "
                   "last step with a heat map)")
    p.add_argument("--force", action="store_true", help="replace existing --output, --modes, --tracks and "
                   "--plot files")
    p.add_argument("--bag", metavar="DIR", help="also write the run as a ROS 2 bag (rosbag2, MCAP) for Foxglove or "
                   "ros2 bag play: estimate, particles, measurements, modes, tracks, camera tf under /heatpf "
                   "(needs rosbags: pip install 'heatpf-jax[ros]'; an existing bag is replaced only with --force)")
    p.add_argument("--bag-frame", metavar="FRAME", help="the bag's frame_id, the robot's base frame (default "
                   "base_footprint)")
    p.add_argument("--bag-start", type=int, metavar="NS", help="the stamp of step 0 in the bag, nanoseconds, "
                   "the others dt apart (default: the sequence's own stamps, which import-rosbag keeps, else 0)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    add_burn_in(p)
    add_set(p)
    add_params(p)
    add_method(p, params_file=True)
    p.set_defaults(func=cmd_run)
    return p
