"""``heatpf eval``: the paper's comparison of the methods (Table I, Fig. 4, Fig. 6), per scenario.

Runs every method of :data:`heatpf_jax.evaluate.DEFAULT_VARIANTS` (or those of ``--method``) on seeds of the
simulated scenarios, of the world family (``--family``, with a per-factor breakdown of the errors) or on one
recording (``--input``), and prints a table per scenario (:func:`heatpf_jax.evaluate.evaluate_sequences`);
``--plot`` writes Fig. 4 and Fig. 6 per scenario as PNG. A ``--params`` file sets the parameters of its own
method's rows, ``--set`` on top. Every argument is checked before any sequence is simulated or loaded.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from heatpf_jax.cli.options import add_burn_in, add_set, checked_params_file, progress_bar
from heatpf_jax.cli.settings import (
    check_burn_in,
    checked_settings,
    layered_settings,
    method_names,
    method_with_settings,
    parse_seeds,
    scenario_names,
    sequence_settings,
)
from heatpf_jax.io.files import check_input, check_output_dir

__all__ = ["add_parser", "cmd_eval"]


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


def cmd_eval(args: argparse.Namespace) -> int:
    """Runs ``heatpf eval`` on the parsed ``args``; returns the exit code (0)."""
    from heatpf_jax.evaluate import DEFAULT_VARIANTS, evaluate_sequences, factor_breakdown, format_table, plot_scenario
    from heatpf_jax.io.sequence import load_sequence
    from heatpf_jax.sim import simulate_family_with_info, simulate_with_info

    loaded = checked_params_file(args)
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
    bar = progress_bar(total)
    written = []
    try:
        for name, scenario in jobs:
            targets = None  # several balls (two_balls): the error is to the nearest
            if scenario is None:
                sequences = [load_sequence(args.input)]
                check_burn_in(args.burn_in, sequences[0].num_steps)
                given = {item.partition("=")[0].strip() for item in args.set or []}
                methods = sorted({v.method for v in variants})
                options, settings = sequence_settings(sequences[0], str(args.input), methods, options, settings,
                                                      given, pinned=loaded is not None)
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


def add_parser(sub, parents: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Registers ``eval`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser."""
    scenarios = ", ".join(scenario_names())
    p = sub.add_parser(
        "eval", parents=parents, help="the paper's comparison (Table I, Fig. 4, Fig. 6) on every scenario",
        epilog=f"Scenarios: {scenarios}.",
    )
    p.add_argument("--scenario", action="append", help=f"a scenario, repeatable (default: all): {scenarios}; "
                   "with --family, a family member")
    p.add_argument("--family", action="store_true", help="the world family instead of the fixed scenarios: "
                   "each scenario type with its nuisance factors drawn per seed (heatpf_jax.sim.family), "
                   "with a per-factor breakdown of the errors")
    p.add_argument("--input", help="evaluate a recording (.npz with ground_truth) instead of the scenarios")
    p.add_argument("--seeds", metavar="N|START:STOP", help="sequences per scenario: N (seeds 0..N-1, "
                   "default 5) or START:STOP (e.g. 200:216)")
    p.add_argument("--steps", type=int, default=None, help="steps per sequence (default: the scenario's, 300)")
    add_burn_in(p)
    p.add_argument("--plot", metavar="DIR", help="write Fig. 4 and Fig. 6 per scenario as PNG into DIR "
                   "(created if missing; PNGs of the same names there are replaced)")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed of the filters (default 0)")
    p.add_argument("--method", action="append", choices=method_names(),
                   help="a method to compare, repeatable (default: all, with the paper's aging ablations)")
    add_set(p, "a parameter of any method")
    p.add_argument(
        "--params", metavar="TUNED.json", help="a parameter file (`heatpf tune --output`) for the rows of its "
        "method (--set on top); its static options apply to every method, as --set's do",
    )
    p.set_defaults(func=cmd_eval)
    return p
