"""Are the estimates the same? Every method and piece on every scenario, saved or compared bit for bit.

    python benchmarks/same_estimates.py --output before.npz             # on the old checkout
    python benchmarks/same_estimates.py --output after.npz              # on the new one
    python benchmarks/same_estimates.py --compare before.npz after.npz  # the table

For a change that must not change behaviour (a restructure, a rename): each named method with its
defaults, and ``heatmap`` with every static option that swaps a piece (source, observation, modes, memory,
spawn, ego, resampler), runs ``--steps`` steps of every scenario and every member of the world family
(seed ``--seed``), through the public ``build`` and ``run`` alone, so the script runs on both layouts.
``--compare`` prints, per run, whether the estimates are equal bit for bit and the largest difference.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

PIECES = (
    ("source", ("centroids", "lofted")),
    ("observation", ("inverse_distance", "gaussian", "gaussian_density")),
    ("modes", ("meanshift", "kmeans", "gmm")),
    ("memory", ("tracks",)),
    ("spawn", ("gaussian",)),
    ("ego", ("none", "pose", "pose_full")),
    ("resampler", ("multinomial", "stratified", "residual")),
)


def _runs(steps: int, seed: int) -> dict[str, np.ndarray]:
    import jax

    from heatpf_jax.presets import METHODS, FilterOptions, build
    from heatpf_jax.rollout import run
    from heatpf_jax.sim import FAMILY, SCENARIOS, simulate, simulate_family

    worlds = {f"scenario:{name}": simulate(name, seed, num_steps=steps) for name in SCENARIOS}
    worlds |= {f"family:{name}": simulate_family(name, seed, num_steps=steps) for name in FAMILY}
    models = [(method, FilterOptions()) for method in METHODS]
    models += [("heatmap", FilterOptions()._replace(**{field: value})) for field, values in PIECES for value in values]
    out = {}
    key = jax.random.key(seed)
    for method, options in models:
        model, params = build(method, options)
        step = jax.jit(lambda k, s, p, m=model: run(k, s, p, m).info.mean)
        label = method + "".join(f",{f}={getattr(options, f)}" for f in options._fields
                                 if getattr(options, f) != getattr(FilterOptions(), f))
        for world, seq in worlds.items():
            if options.ego.startswith("pose") and seq.robot_pose is None:
                continue  # a world without self-localisation: the pose ego-motion refuses it
            out[f"{label}|{world}"] = np.asarray(step(key, seq, params))
        print(label, file=sys.stderr)
    return out


def _compare(before_path: str, after_path: str) -> int:
    before, after = np.load(before_path), np.load(after_path)
    missing = sorted(set(before.files) ^ set(after.files))
    equal = 0
    worst = (0.0, "")
    for name in sorted(set(before.files) & set(after.files)):
        a, b = before[name], after[name]
        same = a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
        equal += same
        diff = float(np.nanmax(np.abs(a - b))) if a.shape == b.shape else float("inf")
        if not same:
            print(f"differs: {name} (largest difference {diff:.3g} m)")
        worst = max(worst, (diff, name))
    total = len(set(before.files) & set(after.files))
    print(f"{equal} of {total} runs equal bit for bit; largest difference {worst[0]:.3g} m"
          + (f" ({worst[1]})" if worst[0] else ""))
    for name in missing:
        print(f"only in one file: {name}")
    return 0 if equal == total and not missing else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--output", help="write every run's estimates here (.npz)")
    parser.add_argument("--compare", nargs=2, metavar=("BEFORE", "AFTER"), help="compare two such files")
    parser.add_argument("--steps", type=int, default=60, help="steps per world (default 60)")
    parser.add_argument("--seed", type=int, default=0, help="the worlds' and the filters' seed (default 0)")
    args = parser.parse_args()
    if args.compare:
        return _compare(*args.compare)
    if not args.output:
        parser.error("give --output FILE or --compare BEFORE AFTER")
    runs = _runs(args.steps, args.seed)
    np.savez(args.output, **runs)
    print(f"wrote {len(runs)} runs to {args.output}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
