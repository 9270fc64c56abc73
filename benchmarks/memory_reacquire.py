"""Re-acquisition after a 2 s occlusion, with and without the long-term memory (Olufs et al. 3.4).

Each seed is the `standard` world (a ball rolling at up to 3 m/s in front of a standing robot) with the
ball hidden for ``--occlusion`` seconds from a step drawn per seed, chosen where the ball is in view
just before and just after. Re-acquisition: the number of steps after the ball reappears until the
estimate is first within 0.3 m of it (1: on the first step it is seen again). The table gives the
median and the mean over seeds (and over ``--filter-seeds`` filter keys per seed), and how many runs
had not re-acquired within ``--window`` steps (counted as ``window + 1`` in the median and mean).

    python benchmarks/memory_reacquire.py                    # seeds 0-11
    python benchmarks/memory_reacquire.py --seeds 100:112    # the seeds the memory's defaults were set on
"""

from __future__ import annotations

import argparse
import time

import jax
import numpy as np

from heatpf_jax.cli.settings import parse_seeds
from heatpf_jax.evaluate import Variant, evaluate_sequences
from heatpf_jax.presets import FilterOptions
from heatpf_jax.sim.scenarios import simulate_with_info

NUM_STEPS = 200


def occluded_sequences(scenario: str, seeds, seconds: float, dt: float = 0.1):
    """``(sequences, reappear_steps)``: each seed's world of ``scenario`` with a ``seconds`` occlusion."""
    length = int(round(seconds / dt))
    sequences, reappear = [], []
    for seed in seeds:
        _, info = simulate_with_info(scenario, seed, num_steps=NUM_STEPS, dt=dt)
        rng = np.random.default_rng([seed, 7])
        starts = [t for t in rng.permutation(np.arange(60, NUM_STEPS - length - 40))
                  if info["in_view"][t - 1] and info["in_view"][t + length: t + length + 5].all()]
        start = int(starts[0])
        seq, _ = simulate_with_info(scenario, seed, num_steps=NUM_STEPS, dt=dt, occlude=(start, start + length))
        sequences.append(seq)
        reappear.append(start + length)
    return sequences, np.array(reappear)


def steps_to_reacquire(errors: np.ndarray, reappear: np.ndarray, window: int, radius: float = 0.3) -> np.ndarray:
    """Per run, the steps from reappearance until the error is first below ``radius`` (``window + 1``: never)."""
    out = np.full(len(reappear), window + 1)
    for i, t0 in enumerate(reappear):
        hit = np.flatnonzero(errors[i, t0 : t0 + window] < radius)
        if hit.size:
            out[i] = hit[0] + 1
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:12", help="START:STOP or N (default 0:12)")
    parser.add_argument("--scenario", default="standard", help="the world (default standard; false_positives "
                        "adds distractors the filter can drift to while the ball is hidden)")
    parser.add_argument("--occlusion", type=float, default=2.0, help="seconds hidden (default 2)")
    parser.add_argument("--window", type=int, default=30, help="steps watched after reappearance (default 30)")
    parser.add_argument("--filter-seeds", type=int, default=3, help="filter keys per sequence (default 3)")
    parser.add_argument("--methods", default="paper,heatmap,extended", help="comma-separated")
    parser.add_argument("--max-tracks", type=int, default=FilterOptions().max_tracks,
                        help=f"the memory's capacity (default {FilterOptions().max_tracks})")
    parser.add_argument("--modes", default="none", help="the filters' modes, the memory's candidates "
                        "(default none: the estimate; meanshift: every cluster)")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds, 12)
    sequences, reappear = occluded_sequences(args.scenario, seeds, args.occlusion)
    print(f"{args.scenario} with a {args.occlusion:g} s occlusion, seeds {seeds.start}-{seeds.stop - 1}, "
          f"{args.filter_seeds} filter keys each; reappearance at steps {reappear.tolist()}")
    print(f"{'method':10s} {'memory':7s} {'median steps':>12s} {'mean steps':>11s} {'not found':>10s} "
          f"{'error after [m]':>16s} {'mean error [m]':>15s} {'time [s]':>9s}")
    for method in args.methods.split(","):
        for memory in ("none", "tracks"):
            start = time.perf_counter()
            steps, after, overall = [], [], []
            for key in range(args.filter_seeds):
                result = evaluate_sequences(
                    args.scenario, sequences,
                    options=FilterOptions(memory=memory, modes=args.modes, max_tracks=args.max_tracks),
                    variants=[Variant(memory, method)], seed=key,
                )
                errors = result.methods[0].errors
                steps.append(steps_to_reacquire(errors, reappear, args.window))
                after.append(np.mean([errors[i, t0 : t0 + 10].mean() for i, t0 in enumerate(reappear)]))
                overall.append(errors[:, 10:].mean())
            steps = np.concatenate(steps)
            print(f"{method:10s} {memory:7s} {np.median(steps):12.1f} {steps.mean():11.2f} "
                  f"{int(np.sum(steps > args.window)):10d} {np.mean(after):16.4f} {np.mean(overall):15.4f} "
                  f"{time.perf_counter() - start:9.1f}")
    jax.clear_caches()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
