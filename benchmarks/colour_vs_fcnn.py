"""The same filter on a tour's simulated FCNN heat maps and on the colour heat maps of its rendered RGB frames.

For each seed: the scenario rendered in RGB (`simulate(..., rgb=True)`), the reference histogram from a box
(0.7 ball radii) around the ball in the first frame where it is visible (smoothed along the intensity
bins), the colour heat maps (`heatpf colour`'s defaults), and each method run on both (the colour maps
with ``threshold = 0.1``, the FCNN maps with the method's defaults). Mean error after step 10 over the
seeds, and the ratio colour / FCNN.

    python benchmarks/colour_vs_fcnn.py                          # standard, seeds 0-4
    python benchmarks/colour_vs_fcnn.py --scenario turning --seeds 100:103
"""

from __future__ import annotations

import argparse

import jax
import numpy as np
from table1_rgb import THRESHOLD, reference_box

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.colour_likelihood import ColourParams, colour_heatmaps
from heatpf_jax.colour_space import exact_top_bins, patch_histogram, smooth_intensity
from heatpf_jax.settings import parse_seeds
from heatpf_jax.sim.scenarios import simulate_with_info


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="standard")
    parser.add_argument("--seeds", default="0:5")
    parser.add_argument("--methods", default="heatmap,extended")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds, 5)
    errors = {(m, kind): [] for m in args.methods.split(",") for kind in ("fcnn", "colour")}
    for seed in seeds:
        seq, info = simulate_with_info(args.scenario, seed, rgb=True)
        t0, box, _, _ = reference_box(seq, info)
        q = smooth_intensity(patch_histogram(seq.images[t0], box))
        heat = np.asarray(colour_heatmaps(seq.images, q, seq.intrinsics, seq.cam_to_base, seq.ball_radius,
                                          ColourParams(), top_bins=exact_top_bins(q)))
        for method in args.methods.split(","):
            model, params = hp.build(method)
            colour_params = P.set_by_name(params, model.properties(), {"threshold": THRESHOLD})
            for kind, data, p in (("fcnn", seq, params), ("colour", seq._replace(heatmaps=heat), colour_params)):
                est = np.asarray(hp.run(jax.random.key(seed), data._replace(images=None), p, model).info.mean)
                errors[(method, kind)].append(np.linalg.norm(est - seq.ground_truth, axis=1)[10:].mean())
    print(f"{args.scenario}, seeds {seeds.start}-{seeds.stop - 1}: mean error after step 10 [m]")
    print(f"{'method':10s} {'FCNN maps':>10s} {'colour maps':>12s} {'ratio':>6s}   per seed (colour / FCNN)")
    for method in args.methods.split(","):
        f, c = np.array(errors[(method, "fcnn")]), np.array(errors[(method, "colour")])
        per_seed = " ".join(f"{r:.2f}" for r in c / f)
        print(f"{method:10s} {f.mean():10.4f} {c.mean():12.4f} {c.mean() / f.mean():6.2f}   {per_seed}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
