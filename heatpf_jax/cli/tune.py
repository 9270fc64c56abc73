"""``heatpf tune``: a method's continuous parameters tuned by gradient descent (Adam).

Trains on version-1 sequence files (``INPUT.npz``) or on seeds of a simulated ``--scenario``, with the
squared error against ground truth (``--loss mse``) or the heat maps' negative log-likelihood (``--loss
nll``) as the loss (:func:`heatpf_jax.tuning.tune`), optionally measuring a validation loss on other
sequences every ``--validate-every`` steps. Every argument is checked before anything is loaded,
simulated or compiled. The output is a parameter file (:mod:`heatpf_jax.io.params_file`) with every
parameter of the method, the tuning's history and what produced it; ``run``, ``eval`` and ``sweep`` read it
with ``--params``. ``--plot`` draws the training and validation losses per step as a PNG. :func:`add_parser`
registers the subcommand with the options it shares with ``run`` and ``sweep`` (:mod:`heatpf_jax.cli.options`);
:func:`cmd_tune` runs it.
"""

from __future__ import annotations

import argparse
import os
import warnings
from pathlib import Path
from typing import NamedTuple

import numpy as np

from heatpf_jax.cli.options import (
    add_burn_in,
    add_method,
    add_params,
    add_set,
    progress_bar,
    settings_with_params,
    table_lines,
)
from heatpf_jax.cli.settings import (
    check_burn_in,
    method_with_settings,
    parse_seeds,
    scenario_names,
    sequence_settings,
)
from heatpf_jax.io.files import check_input, check_output, same_file, write_atomic

__all__ = ["add_parser", "cmd_tune"]


class _TuneInputs(NamedTuple):
    """What ``heatpf tune`` trains and validates on (files, or seeds of ``scenario``)."""

    files: list[str]  # training files (empty with --scenario)
    validate: list[str]  # validation files
    scenario: str | None
    seeds: range | None  # training seeds of the scenario
    validate_seeds: range | None  # validation seeds of the scenario: right after the training seeds
    length: int | None  # steps per simulated sequence


def _tune_inputs(args) -> _TuneInputs:
    """Checks the training and validation inputs (files readable, seeds, --length) before any work."""
    from heatpf_jax.sim.scenarios import DEFAULT_NUM_STEPS

    if bool(args.inputs) == (args.scenario is not None):
        raise ValueError("tune: give INPUT.npz files or --scenario NAME (one of them)")
    if args.validate and args.validate_seeds is not None:
        raise ValueError("--validate-seeds: give either --validate FILES or --validate-seeds N, not both")
    for path in [*args.inputs, *(args.validate or [])]:
        check_input(path)
        if not os.access(path, os.R_OK):
            raise ValueError(f"{path}: not readable (permission denied)")
    if args.inputs:
        options = (("--seeds", args.seeds), ("--length", args.length), ("--validate-seeds", args.validate_seeds))
        given = [o for o, v in options if v is not None]
        if given:
            raise ValueError(f"{given[0]}: applies to --scenario, not to input files")
        return _TuneInputs(list(args.inputs), list(args.validate or []), None, None, None, None)
    if args.scenario not in scenario_names():
        raise ValueError(f"--scenario: unknown {args.scenario!r} (known: {', '.join(scenario_names())})")
    seeds = parse_seeds(args.seeds, 4)
    length = DEFAULT_NUM_STEPS if args.length is None else args.length
    if length < 1:
        raise ValueError(f"--length: must be >= 1, got {length}")
    val_seeds = None
    if args.validate_seeds is not None:
        if args.validate_seeds < 1:
            raise ValueError(f"--validate-seeds: must be >= 1, got {args.validate_seeds}")
        val_seeds = range(seeds.stop, seeds.stop + args.validate_seeds)
    return _TuneInputs([], list(args.validate or []), args.scenario, seeds, val_seeds, length)


def _tune_names(items: list[str] | None, method: str, model) -> list[str] | None:
    """``--tune``'s dotted names (``None``: every trainable parameter), each a trainable parameter of ``model``."""
    from heatpf_jax import params as P
    from heatpf_jax.cli.settings import ALIASES
    from heatpf_jax.tuning import differentiable, trainable_names

    try:
        differentiable(model)
    except (AttributeError, ValueError):
        raise ValueError(f"--method: {method} is no particle filter; `heatpf tune` tunes particle filters") from None
    trainable = trainable_names(model)
    if not trainable:
        raise ValueError(f"--method: {method} has no parameter that gradients can tune; use `heatpf sweep`")
    if not items:
        return None
    names = P.leaf_names(model.properties())
    chosen: list[str] = []
    for item in items:
        for typed in (n.strip() for n in item.split(",")):
            if not typed:
                raise ValueError(f"--tune: expected NAME,NAME,..., got {item!r}")
            try:
                full = P.resolve_name(ALIASES.get(typed, typed), names)
            except ValueError as err:
                raise ValueError(f"--tune: {err}") from None
            if full is None:
                raise ValueError(f"--tune: {typed}: not a parameter of method {method} "
                                 f"(trainable: {', '.join(trainable)})")
            if full not in trainable:
                raise ValueError(f"--tune: {full}: frozen (discrete, or acts only through a count or a mask), so "
                                 f"gradients cannot tune it; sweep it: heatpf sweep --grid {typed}=V1,V2,...")
            if full not in chosen:
                chosen.append(full)
    return chosen


def _check_tune_numbers(args) -> None:
    for option, value in (("--steps", args.steps), ("--filter-seeds", args.filter_seeds),
                          ("--validate-every", args.validate_every)):
        if value < 1:
            raise ValueError(f"{option}: must be >= 1, got {value}")
    if not (np.isfinite(args.lr) and args.lr > 0):
        raise ValueError(f"--lr: must be a positive number, got {args.lr}")


def _tune_sequences(files: list[str], scenario, seeds, length, loss: str, burn_in: int, what: str) -> list:
    """Loads (or simulates) sequences and checks them: one shape, ground truth for ``mse``, room after burn-in."""
    from heatpf_jax.io.sequence import load_sequence
    from heatpf_jax.sim import simulate

    if files:
        labels, sequences = files, [load_sequence(f) for f in files]
    else:
        labels = [f"--scenario {scenario} seed {s}" for s in seeds]
        sequences = [simulate(scenario, s, num_steps=length) for s in seeds]
    first = sequences[0].heatmaps.shape
    for label, seq in zip(labels, sequences, strict=True):
        if seq.heatmaps.shape != first:
            shape = seq.heatmaps.shape
            raise ValueError(f"{label}: {shape[0]} steps of {shape[2]}x{shape[1]} heat maps, but {labels[0]} has "
                             f"{first[0]} of {first[2]}x{first[1]}; {what} sequences must share one shape")
        if loss == "mse" and seq.ground_truth is None:
            raise ValueError(f"{label}: no ground_truth, which --loss mse needs (--loss nll does not)")
    check_burn_in(burn_in, first[0])
    return sequences


def _plot_tuning(path: Path, result, loss: str) -> None:
    """The training loss per gradient step and the validation loss at its steps, as a PNG (atomically)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"') from None
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(np.arange(len(result.history)), result.history, label="training (fresh filter seeds each step)")
    if len(result.validation):
        ax.plot(result.validation_steps, result.validation, "o-", label="validation (fixed filter seeds)")
    ax.xaxis.set_major_locator(matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("gradient step")
    ax.set_ylabel({"mse": "mean squared error [m$^2$]", "nll": "negative log-likelihood per step"}[loss])
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    write_atomic(path, lambda fh: fig.savefig(fh, format="png", dpi=100), binary=True)
    plt.close(fig)


def _tune_summary(result, start: dict, method: str, loss: str) -> None:
    h = result.history
    print(f"tuned {len(result.names)} parameter(s) of {method} by {len(h)} gradient steps on loss {loss} "
          f"in {result.seconds:.1f} s (compilation included):")
    rows = [("name", "start", "final")]
    rows += [(n, f"{start[n]:.6g}", f"{v[-1]:.6g}") for n, v in result.path.items()]
    print("\n".join(table_lines(rows)))
    print(f"training loss: {h[0]:.6g} at step 0, {h[-1]:.6g} at step {len(h) - 1}")
    for name, values in result.path.items():
        values = np.asarray(values, np.float64)
        if len(h) > 1 and np.all(values == values.flat[0]):
            warnings.warn(f"--tune: {name} kept its start value {start[name]:.6g} through {len(h)} gradient steps: "
                          "the loss has no gradient in it on these sequences (e.g. an odometry noise on a robot "
                          "that does not move); leave it out of --tune or tune on sequences that exercise it")
    if len(result.validation):
        pairs = zip(result.validation_steps, result.validation, strict=True)
        print("validation loss: " + ", ".join(f"{v:.6g} (step {int(s)})" for s, v in pairs))


def _tune_record(args, data: _TuneInputs) -> dict:
    """What produced a tuned file, for its ``training`` key."""
    if data.files:
        record = {"inputs": data.files}
    else:
        record = {"scenario": data.scenario, "seeds": f"{data.seeds.start}:{data.seeds.stop}", "length": data.length}
    if data.validate:
        record["validate"] = data.validate
    if data.validate_seeds is not None:
        record["validate_seeds"] = f"{data.validate_seeds.start}:{data.validate_seeds.stop}"
    record.update(steps=args.steps, lr=args.lr, filter_seeds=args.filter_seeds, burn_in=args.burn_in,
                  validate_every=args.validate_every, seed=args.seed, params=args.params, set=args.set or [])
    return record


def cmd_tune(args: argparse.Namespace) -> int:
    """Runs ``heatpf tune`` on the parsed ``args``; returns the exit code (0).

    Every check runs before any sequence is loaded or simulated; bad input raises :class:`ValueError` or
    :class:`RuntimeError` with one line, which :func:`heatpf_jax.cli.main` prints.
    """
    import jax
    import optax

    from heatpf_jax.io.params_file import json_floats, params_by_name, save_params_file
    from heatpf_jax.tuning import tune

    options, settings, _ = settings_with_params(args)
    model, params = method_with_settings(args.method, options, settings)
    names = _tune_names(args.tune, args.method, model)
    _check_tune_numbers(args)
    data = _tune_inputs(args)
    check_burn_in(args.burn_in, data.length)
    inputs = [*data.files, *data.validate, args.params]
    out = check_output("--output", args.output, inputs=inputs, replace=args.force)
    plot = None
    if args.plot:
        import importlib.util

        if importlib.util.find_spec("matplotlib") is None:
            raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"')
        plot = check_output("--plot", args.plot, inputs=inputs, replace=args.force)
        if same_file(plot, out) or plot.resolve() == out.resolve():
            raise ValueError(f"--plot: {args.plot} is also --output; choose another file")

    train = _tune_sequences(data.files, data.scenario, data.seeds, data.length, args.loss, args.burn_in, "training")
    validation = None
    if data.validate or data.validate_seeds is not None:
        validation = _tune_sequences(data.validate, data.scenario, data.validate_seeds, data.length, args.loss,
                                     args.burn_in, "validation")
    if data.files:  # what every file asks alike, beneath --set
        loaded = train + (validation or [])
        shared = {k: v for k, v in (loaded[0].settings or {}).items()
                  if all((s.settings or {}).get(k, None) == v for s in loaded)}
        label = data.files[0] if len(loaded) == 1 else "the sequence files"
        given = {item.partition("=")[0].strip() for item in args.set or []}
        advised = sequence_settings(loaded[0]._replace(settings=shared or None), label, [args.method], options,
                                    settings, given, pinned=args.params is not None)
        if advised != (options, settings):
            options, settings = advised
            model, params = method_with_settings(args.method, options, settings)
            names = _tune_names(args.tune, args.method, model)
    print(f"tune {args.method}: {len(train)} training sequence(s) x {train[0].num_steps} steps, "
          f"{args.filter_seeds} filter seed(s) each, {args.steps} gradient steps (the first compiles)")
    bar = progress_bar(args.steps)
    bar.set_description("tune")

    def tick(step: int, value: float) -> None:
        bar.set_postfix_str(f"loss {value:.4g}", refresh=False)
        bar.update(1)

    try:
        result = tune(
            jax.random.key(args.seed), train, params, model, names=names, optimizer=optax.adam(args.lr),
            steps=args.steps, loss=args.loss, num_seeds=args.filter_seeds, burn_in=args.burn_in,
            validation=validation, validate_every=args.validate_every, callback=tick,
        )
    except FloatingPointError as err:
        raise RuntimeError(f"{err}; try a smaller --lr") from None
    finally:
        bar.close()
    start = {n: v for n, v in params_by_name(params, model).items() if n in result.names}
    save_params_file(
        out, args.method, options, result.params,
        tuned=list(result.names),
        start=start,
        loss=args.loss,
        history=json_floats(result.history),
        validation=json_floats(result.validation),
        validation_steps=[int(s) for s in result.validation_steps],
        path={n: json_floats(v) for n, v in result.path.items()},
        seconds=round(float(result.seconds), 3),
        training=_tune_record(args, data),
    )
    if plot is not None:
        _plot_tuning(plot, result, args.loss)
    _tune_summary(result, start, args.method, args.loss)
    print(f"wrote {out}")
    if plot is not None:
        print(f"wrote {plot}")
    return 0


def add_parser(sub, parents: list[argparse.ArgumentParser], scenarios: str | None = None) -> argparse.ArgumentParser:
    """Registers ``tune`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser.

    ``scenarios`` lists the scenario names for the help text (default: every scenario). The parser's default
    ``func`` is :func:`cmd_tune`.
    """
    scenarios = ", ".join(scenario_names()) if scenarios is None else scenarios
    p = sub.add_parser(
        "tune", parents=parents, help="tune a method's continuous parameters by gradient descent (Adam)",
        epilog=f"Scenarios: {scenarios}. Trainable parameters: heatpf params --method NAME. The output JSON "
        "holds every parameter; run, eval and sweep read it with --params.",
    )
    p.add_argument("inputs", nargs="*", metavar="INPUT.npz", help="training sequences of one shape (with "
                   "ground_truth for --loss mse); or use --scenario")
    p.add_argument("--scenario", help=f"train on a simulated scenario instead: {scenarios}")
    p.add_argument("--seeds", metavar="N|START:STOP", help="training sequences of --scenario: N (seeds 0..N-1, "
                   "default 4) or START:STOP")
    p.add_argument("--length", type=int, help="steps per simulated sequence (default: the scenario's, 300)")
    p.add_argument("--validate", nargs="+", action="extend", metavar="VAL.npz", help="validation sequences "
                   "(one shape), their loss measured every --validate-every steps with fixed filter seeds")
    p.add_argument("--validate-seeds", type=int, metavar="N", help="N validation sequences of --scenario, on the "
                   "seeds right after the training seeds")
    p.add_argument("--validate-every", type=int, default=10, help="gradient steps between validation losses "
                   "(default 10)")
    p.add_argument("--loss", choices=("mse", "nll"), default="mse", help="mse: squared error of the estimate "
                   "against ground_truth (default); nll: minus the log-likelihood of the heat maps per step")
    p.add_argument("--tune", action="append", metavar="NAME,NAME", help="parameters to tune (dotted or short "
                   "names, repeatable; default: every trainable parameter of the method)")
    add_set(p, "the starting value of a parameter")
    add_params(p)
    add_method(p, "tune", params_file=True)
    p.add_argument("--steps", type=int, default=50, help="gradient steps (default 50)")
    p.add_argument("--lr", type=float, default=0.05, help="Adam's learning rate, on the unconstrained "
                   "coordinates (log or logit of each parameter; default 0.05)")
    p.add_argument("--filter-seeds", type=int, default=2, help="filter seeds per sequence and gradient step "
                   "(default 2)")
    add_burn_in(p)
    p.add_argument("--output", "-o", required=True, metavar="TUNED.json", help="the parameter file (every "
                   "parameter; not replaced if it exists, unless --force)")
    p.add_argument("--force", action="store_true", help="replace existing --output and --plot files")
    p.add_argument("--plot", metavar="LOSS.png", help="write the training and validation loss per step as a PNG")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the filter seeds (default 0)")
    p.set_defaults(func=cmd_tune)
    return p
