"""How well each filter keeps both balls of the ``two_balls`` scenario: the share of steps (after the
first ``--burn-in``) at which every ball is within ``--radius`` of a valid mode of the particle set.

Every particle filter reports mean-shift modes (``FilterOptions(modes="meanshift")``, K = 3 slots);
the Kalman filter's one Gaussian is its only mode. Seeds 0-4 by default (those ``heatpf eval`` reports).
Also printed: the single estimate's mean error to the nearer ball, and the share of steps whose
estimate is within the radius of ball A / ball B.

Run: ``python benchmarks/two_balls.py [--seeds 0:5] [--methods extended,heatmap,paper,kalman]``
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.evaluate import _stack, mode_coverage
from heatpf_jax.sim import simulate_with_info


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:5", help="START:STOP (default 0:5)")
    parser.add_argument("--methods", default="extended,heatmap,paper,kalman")
    parser.add_argument("--radius", type=float, default=0.3)
    parser.add_argument("--burn-in", type=int, default=10)
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="a parameter of every method that has it (repeatable)",
    )
    args = parser.parse_args(argv)
    start, stop = (int(v) for v in args.seeds.split(":"))
    runs = [simulate_with_info("two_balls", s) for s in range(start, stop)]
    batch = _stack([r[0] for r in runs])._replace(ground_truth=None)
    balls = np.stack([r[1]["balls_base"] for r in runs])  # [S, T, 2, 2]
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(0), i))(np.arange(len(runs)))
    b = args.burn_in
    settings = {k: float(v) for k, v in (item.split("=", 1) for item in args.set)}
    print(
        f"two_balls, seeds {start}-{stop - 1}, {batch.heatmaps.shape[1]} steps; after step {b}; radius {args.radius} m"
    )
    print(
        f"{'method':<12} {'both covered':>13} {'A covered':>10} {'B covered':>10} {'est. err [m]':>13} "
        f"{'est. near A':>12} {'est. near B':>12} {'time [s]':>9}"
    )
    for name in args.methods.split(","):
        model, params = hp.build(name, hp.FilterOptions(modes="meanshift"))
        params = P.set_by_name(params, model.properties(), settings, skip_unknown=True)
        t0 = time.perf_counter()
        info = jax.vmap(lambda k, s, m=model, p=params: hp.run(k, s, p, m).info)(keys, batch)
        modes = info.modes
        mean, valid = np.asarray(modes.mean), np.asarray(modes.valid)
        both = mode_coverage(mean, valid, balls)[:, b:]
        each = [mode_coverage(mean, valid, balls[:, :, j : j + 1])[:, b:] for j in range(2)]
        est = np.asarray(info.mean)[:, :, None, :]
        dist = np.linalg.norm(est - balls, axis=-1)[:, b:]  # [S, T, 2]
        elapsed = time.perf_counter() - t0
        print(
            f"{name:<12} {both.mean():13.3f} {each[0].mean():10.3f} {each[1].mean():10.3f} "
            f"{dist.min(axis=-1).mean():13.4f} {(dist[..., 0] <= args.radius).mean():12.3f} "
            f"{(dist[..., 1] <= args.radius).mean():12.3f} {elapsed:9.1f}"
        )


if __name__ == "__main__":
    main()
