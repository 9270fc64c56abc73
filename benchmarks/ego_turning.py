"""Ego-motion compensation in `turning` (Olufs et al. 3.5): odometry, none, and the self-localisation with and
without its confidence, rotation only (the paper) or rotation and translation.

The `turning` sequences carry a self-localisation (``robot_pose``, ``pose_confidence``) that jumps 0.3-1 m
and 10-30 degrees away about 4 times a minute for 1-2.5 s, with its confidence at 0.02-0.15 meanwhile. The
table gives the mean error after the burn-in over every step, and over the steps from a jump's start to
2 s after its end (when a wrongly applied jump still shows).

    python benchmarks/ego_turning.py                      # seeds 0-4, heatmap and paper
    python benchmarks/ego_turning.py --seeds 100:104      # the seeds the defaults were chosen on
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from heatpf_jax.cli.settings import parse_seeds
from heatpf_jax.evaluate import DEFAULT_BURN_IN, Variant, evaluate_sequences
from heatpf_jax.presets import FilterOptions
from heatpf_jax.sim.scenarios import simulate_with_info

EGOS = ("none", "odometry", "pose", "pose_full", "pose_unweighted", "pose_full_unweighted")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:5", help="START:STOP or N (default 0:5)")
    parser.add_argument("--methods", default="heatmap,paper", help="comma-separated (default heatmap,paper)")
    parser.add_argument("--after", type=float, default=2.0, help="seconds after a jump still counted (default 2)")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds, 5)
    runs = [simulate_with_info("turning", s) for s in seeds]
    sequences = [r[0] for r in runs]
    dt = float(sequences[0].dt)
    after = int(round(args.after / dt))
    jump = np.stack([r[1]["localisation_lost"] for r in runs])
    near_jump = jump.copy()
    for k in range(1, after + 1):
        near_jump[:, k:] |= jump[:, :-k]
    near_jump[:, :DEFAULT_BURN_IN] = False
    print(f"turning, seeds {seeds.start}-{seeds.stop - 1}: {jump.sum()} of {jump.size} steps with the localisation "
          f"jumped away; {near_jump.sum()} steps within {args.after:g} s of a jump")
    print(f"{'method':10s} {'ego':22s} {'mean error [m]':>15s} {'near jumps [m]':>15s} {'time [s]':>9s}")
    for method in args.methods.split(","):
        for ego in EGOS:
            start = time.perf_counter()
            result = evaluate_sequences(
                "turning", sequences, options=FilterOptions(ego=ego), variants=[Variant(ego, method)]
            )
            errors = result.methods[0].errors
            overall = errors[:, DEFAULT_BURN_IN:].mean()
            print(f"{method:10s} {ego:22s} {overall:15.4f} {errors[near_jump].mean():15.4f} "
                  f"{time.perf_counter() - start:9.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
