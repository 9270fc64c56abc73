"""Gradient tuning against a dense grid (issue 11): two noise parameters of a method (default ``paper``).

For each scenario, start from a poor setting (diffusion 5x too large, odometry rotation noise 5x too small),
tune the two by gradient descent (:func:`heatpf_jax.tune`, MSE loss) on training seeds, and compare the mean
error on validation seeds (disjoint) of the start, the tuned point, and the best point of a dense grid over the
same two parameters computed with ``heatpf sweep`` (same validation seeds, same filter seed). Wall times of
tuning and of the grid are printed.

    python benchmarks/tune_vs_grid.py                         # walking and sparse_rate
    python benchmarks/tune_vs_grid.py --scenarios walking --steps 30
"""

from __future__ import annotations

import argparse
import csv
import os
import tempfile
import time

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.cli.parser import main as heatpf
from heatpf_jax.evaluate import DEFAULT_BURN_IN
from heatpf_jax.rollout import stack_params
from heatpf_jax.sim import simulate
from heatpf_jax.sweep import sweep

NAMES = ("motion.diffusion_std", "motion.odom_rot_noise")


def mean_errors(model, params_list, sequences, seed=0, burn_in=DEFAULT_BURN_IN):
    """Mean error (m) after ``burn_in`` over ``sequences`` for each params set, as ``heatpf sweep`` computes it."""
    batch = stack_params(params_list)
    errors = []
    for seq in sequences:
        info = sweep(jax.random.key(seed), seq, batch, model, chunk=len(params_list))
        est = np.asarray(info.mean, np.float64)
        errors.append(np.linalg.norm(est - seq.ground_truth[None], axis=-1)[:, burn_in:])
    return np.concatenate(errors, axis=1).mean(axis=1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="walking,sparse_rate")
    ap.add_argument("--train-seeds", default="100:104")
    ap.add_argument("--val-seeds", default="0:5")
    ap.add_argument("--steps", type=int, default=40, help="gradient steps")
    ap.add_argument("--lr", type=float, default=0.1)
    ap.add_argument("--filter-seeds", type=int, default=2)
    ap.add_argument("--grid-size", type=int, default=8, help="values per parameter in the grid")
    ap.add_argument("--method", default="paper", help="the method tuned (default paper: its random walk's "
                    "diffusion is its motion model)")
    args = ap.parse_args(argv)
    lo, hi = (int(x) for x in args.train_seeds.split(":"))
    train_seeds = list(range(lo, hi))
    lo, hi = (int(x) for x in args.val_seeds.split(":"))
    val_seeds = list(range(lo, hi))
    model, defaults = hp.build(args.method)
    props = model.properties()
    default = dict(zip(P.leaf_names(props), jax.tree.leaves(defaults), strict=True))
    start = {NAMES[0]: 5.0 * float(default[NAMES[0]]), NAMES[1]: float(default[NAMES[1]]) / 5.0}
    init = P.set_by_name(defaults, props, start)
    grid = {
        NAMES[0]: np.geomspace(0.01, 1.0, args.grid_size),
        NAMES[1]: np.geomspace(0.005, 0.5, args.grid_size),
    }
    rows = []
    for scenario in args.scenarios.split(","):
        train = [simulate(scenario, s) for s in train_seeds]
        val = [simulate(scenario, s) for s in val_seeds]
        t0 = time.perf_counter()
        res = hp.tune(jax.random.key(0), train, init, model, names=list(NAMES), steps=args.steps,
                      num_seeds=args.filter_seeds, validation=val, validate_every=10,
                      optimizer=__import__("optax").adam(args.lr))
        tune_s = time.perf_counter() - t0
        tuned = {n: float(res.path[n][-1]) for n in NAMES}
        e_start, e_tuned, e_default = mean_errors(
            model, [init, P.set_by_name(defaults, props, tuned), defaults], val
        )
        with tempfile.TemporaryDirectory() as tmp:
            out = os.path.join(tmp, "grid.csv")
            t0 = time.perf_counter()
            heatpf(["sweep", "--method", args.method, "--scenario", scenario, "--seeds", args.val_seeds,
                    "--output", out, "--top", "0", "--batch-size", str(args.grid_size),
                    *(x for n, vs in grid.items() for x in ("--grid", f"{n}=" + ",".join(f"{v:.6g}" for v in vs)))])
            grid_s = time.perf_counter() - t0
            with open(out) as fh:
                table = list(csv.DictReader(line for line in fh if not line.startswith("#")))
        best = min(table, key=lambda r: float(r["mean_error"]))
        e_best = float(best["mean_error"])
        print(f"\n{scenario}: tuned on seeds {train_seeds}, errors on seeds {val_seeds} (mean error after step "
              f"{DEFAULT_BURN_IN}, m)")
        print(f"  start    {start}: {e_start:.4f}")
        print(f"  tuned    { {n: round(v, 4) for n, v in tuned.items()} }: {e_tuned:.4f}  "
              f"({e_tuned / e_start - 1:+.1%} vs start, {e_tuned / e_best - 1:+.1%} vs grid best)")
        print(f"  grid best { {n: float(best[n]) for n in NAMES} }: {e_best:.4f}   ({len(table)} points)")
        print(f"  defaults {e_default:.4f}")
        print(f"  training loss {res.history[0]:.4f} -> {res.history[-1]:.4f}; validation MSE "
              f"{', '.join(f'{v:.4f}' for v in res.validation)} at steps {list(res.validation_steps)}")
        print(f"  wall time: tuning {tune_s:.0f} s ({args.steps} steps x {len(train)} sequences x "
              f"{args.filter_seeds} seeds), grid {grid_s:.0f} s ({len(table)} sets x {len(val)} sequences)")
        rows.append((scenario, e_start, e_tuned, e_best, tune_s, grid_s))
    print("\n| scenario | start | tuned | grid best | tuned/start | tuned/grid | tuning s | grid s |")
    print("|---|---|---|---|---|---|---|---|")
    for sc, a, b, c, ts, gs in rows:
        print(f"| {sc} | {a:.4f} | {b:.4f} | {c:.4f} | {b / a:.2f} | {b / c:.2f} | {ts:.0f} | {gs:.0f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
