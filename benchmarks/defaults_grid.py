"""Mean error of the heat-map filter over (diffusion_std, aging, k) on every simulated scenario.

The figures behind the README's defaults. Seeds 100-103 by default (not the seeds `heatpf eval`
reports on), 300 steps each, errors after step 10; the baselines are printed for scale.
Run: ``python benchmarks/defaults_grid.py [--seeds 100:104] [--scenarios NAME,...]`` (about 5 minutes
on 2 cores for the defaults).
"""

import argparse
import itertools

import heatpf_jax as hp
from heatpf_jax.evaluate import Variant, evaluate_sequences
from heatpf_jax.sim import SCENARIOS, simulate


def seed_range(text: str) -> range:
    try:
        start, stop = (int(v) for v in text.split(":"))
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"--seeds: expected START:STOP, got {text!r}") from err
    if not 0 <= start < stop:
        raise argparse.ArgumentTypeError(f"--seeds: need 0 <= START < STOP, got {text!r}")
    return range(start, stop)


def scenario_list(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown or not names:
        raise argparse.ArgumentTypeError(f"--scenarios: unknown {unknown}; known: {', '.join(SCENARIOS)}")
    return names


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=seed_range, default=range(100, 104), help="START:STOP (default 100:104)")
    parser.add_argument("--scenarios", type=scenario_list, default=list(SCENARIOS), help="comma-separated names")
    args = parser.parse_args(argv)
    variants = [
        Variant(f"d={d} v={v} k={k}", "heatmap", {"diffusion_std": d, "aging": v, "k": k})
        for d, v, k in itertools.product((0.2, 0.3), (0.05, 0.3), (1, 3))
    ]
    variants += [Variant("conventional", "conventional"), Variant("kalman", "kalman")]
    table: dict[str, dict[str, float]] = {}
    for scenario in args.scenarios:
        seqs = [simulate(scenario, s) for s in args.seeds]
        result = evaluate_sequences(scenario, seqs, options=hp.FilterOptions(), variants=variants)
        for m in result.methods:
            table.setdefault(m.variant.name, {})[scenario] = m.stats(10)["mean"]
    seeds = f"{args.seeds.start}-{args.seeds.stop - 1}"
    print(f"mean error [m], seeds {seeds}; d = diffusion_std, v = aging (l = 0.1), k")
    print(f"{'variant':<22}" + "".join(f"{s[:11]:>12}" for s in args.scenarios))
    for name, row in table.items():
        print(f"{name:<22}" + "".join(f"{row[s]:12.4f}" for s in args.scenarios))


if __name__ == "__main__":
    main()
