"""Mean error of the heat-map filter over (diffusion_std, aging, k) on every simulated scenario.

The figures behind the README's defaults. Seeds 100-103 (not the seeds `heatpf eval` reports on),
300 steps each, errors after step 10; the baselines are printed for scale.
Run: ``python benchmarks/defaults_grid.py`` (about 5-10 minutes on 2 cores).
"""

import itertools

import heatpf_jax as hp
from heatpf_jax.evaluate import Variant, evaluate_sequences
from heatpf_jax.sim import SCENARIOS, simulate

SEEDS = range(100, 104)


def main() -> None:
    variants = [
        Variant(f"d={d} v={v} k={k}", "heatmap", {"diffusion_std": d, "aging": v, "k": k})
        for d, v, k in itertools.product((0.2, 0.3), (0.05, 0.3), (1, 3))
    ]
    variants += [Variant("conventional", "conventional"), Variant("kalman", "kalman")]
    table: dict[str, dict[str, float]] = {}
    for scenario in SCENARIOS:
        seqs = [simulate(scenario, s) for s in SEEDS]
        result = evaluate_sequences(
            scenario, seqs, params=hp.FilterParams(), config=hp.FilterConfig(), variants=variants
        )
        for m in result.methods:
            table.setdefault(m.variant.name, {})[scenario] = m.stats(10)["mean"]
    print("mean error [m], seeds 100-103; d = diffusion_std, v = aging (l = 0.1), k")
    print(f"{'variant':<22}" + "".join(f"{s[:11]:>12}" for s in SCENARIOS))
    for name, row in table.items():
        print(f"{name:<22}" + "".join(f"{row[s]:12.4f}" for s in SCENARIOS))


if __name__ == "__main__":
    main()
