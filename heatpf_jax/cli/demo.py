"""``heatpf demo``: the short version of ``heatpf eval``, on one simulated sequence of the ``standard`` scenario.

Compares the first four of :data:`heatpf_jax.evaluate.DEFAULT_VARIANTS` on a static robot with a heat map every
step and prints the table of ``heatpf eval``; ``--output`` also writes the heat-map filter's estimates as the CSV
of ``heatpf run`` (:func:`heatpf_jax.cli.run.write_estimates_csv`, with zero covariances). Every argument is
checked before anything is simulated.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from heatpf_jax.cli.options import add_burn_in, add_set
from heatpf_jax.cli.run import write_estimates_csv
from heatpf_jax.cli.settings import check_burn_in, checked_settings
from heatpf_jax.io.files import check_output

__all__ = ["add_parser", "cmd_demo"]


def cmd_demo(args: argparse.Namespace) -> int:
    """Runs ``heatpf demo`` on the parsed ``args``; returns the exit code (0)."""
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


def add_parser(sub, parents: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    """Registers ``demo`` on ``sub`` (the ``heatpf`` sub-parsers) with the ``parents`` parsers; returns its parser."""
    p = sub.add_parser("demo", parents=parents, help="a short evaluation on a built-in simulated sequence")
    p.add_argument("--steps", type=int, default=300, help="number of filter steps (default 300)")
    add_burn_in(p)
    p.add_argument("--output", "-o", help="optional CSV of the estimates (not replaced if it exists, unless "
                   "--force)")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    p.add_argument("--seed", type=int, default=0, help="PRNG seed (default 0)")
    add_set(p, "a parameter of any method")
    p.set_defaults(func=cmd_demo)
    return p
