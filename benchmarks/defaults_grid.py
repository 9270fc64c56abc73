"""Mean error of the heat-map filter over a (diffusion_std, k) grid on the simulated standard scenario.

The figures behind the README's choice of the default ``k`` and ``diffusion_std``.
Run: ``python benchmarks/defaults_grid.py`` (about a minute on 2 cores).
"""

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax.sim import simulate_standard

SEEDS = (1, 2, 3)
KS = (1, 3, 5, 10)
DIFFUSIONS = (0.1, 0.15, 0.2, 0.3)


def main() -> None:
    seqs = [simulate_standard(s, 300) for s in SEEDS]
    config = hp.FilterConfig()
    print(f"mean error [m] after step 5, averaged over seeds {SEEDS}; other parameters at their defaults")
    print("diffusion_std " + "".join(f"{'k=' + str(k):>9}" for k in KS))
    for d in DIFFUSIONS:
        row = []
        for k in KS:
            errs = []
            for s in seqs:
                r = hp.run(jax.random.key(0), s, hp.FilterParams(k=k, diffusion_std=d), config)
                errs.append(np.linalg.norm(np.asarray(r.info.mean) - s.ground_truth, axis=1)[5:].mean())
            row.append(np.mean(errs))
        print(f"{d:13.2f} " + "".join(f"{v:9.4f}" for v in row))


if __name__ == "__main__":
    main()
