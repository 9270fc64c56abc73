"""The same filter on a tour's simulated FCNN heat maps and on the colour heat maps of its rendered RGB frames.

For each seed: the scenario rendered in RGB (`simulate(..., rgb=True)`), the reference histogram from a box
(0.7 ball radii) around the ball in the first frame where it is visible (smoothed along the intensity
bins), the colour heat maps (`heatpf colour`'s defaults), and each method run on both (the colour maps
with ``threshold = 0.1``, the FCNN maps with the method's defaults). Mean error after step 10 over the
seeds, and the ratio colour / FCNN.

    python benchmarks/colour_vs_fcnn.py                          # standard, seeds 0-4
    python benchmarks/colour_vs_fcnn.py --scenario turning --seeds 100:103

``--windows blob,pixel`` compares the colour map's window at each response's centroid (the default) with the
window at each pixel (``blob_window=False``, the single pass of sessions 6-7).

``--centroids`` also prints what limits the colour maps: per frame where the ball is visible, the
weighted centroid of each map's pixels above the filter's threshold within 15 px of the ball's true
image position, against that position (bias and spread in pixels, and the pixels used).
"""

from __future__ import annotations

import argparse

import jax
import numpy as np
from table1_rgb import THRESHOLD, reference_box, to_image

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.cli.settings import parse_seeds
from heatpf_jax.colour.likelihood import ColourParams, colour_heatmaps
from heatpf_jax.colour.space import exact_top_bins, patch_histogram, smooth_chromaticity, smooth_intensity
from heatpf_jax.sim.scenarios import simulate_with_info


def centroid_offsets(maps: np.ndarray, threshold: float, truth_px: np.ndarray, visible: np.ndarray,
                     radius: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    """Per visible frame, ``(centroid - truth [n, 2], pixels used [n])`` of the map's pixels above
    ``threshold`` within ``radius`` px of the ball's true image position (frames without any: skipped)."""
    vv, uu = np.mgrid[0:maps.shape[1], 0:maps.shape[2]]
    offsets, counts = [], []
    for t in np.flatnonzero(visible):
        u, v = truth_px[t]
        sel = (maps[t] > threshold) & ((uu - u) ** 2 + (vv - v) ** 2 < radius**2)
        if sel.any():
            w = maps[t][sel]
            offsets.append([w @ uu[sel] / w.sum() - u, w @ vv[sel] / w.sum() - v])
            counts.append(sel.sum())
    return np.asarray(offsets), np.asarray(counts)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", default="standard")
    parser.add_argument("--seeds", default="0:5")
    parser.add_argument("--methods", default="heatmap,extended")
    parser.add_argument("--centroids", action="store_true", help="also the maps' centroid bias and spread [px]")
    parser.add_argument("--chroma", type=float, default=0.25, help="reference smoothing along r' and g' (0: none)")
    parser.add_argument("--windows", default="blob", help="colour map windows: blob (default), pixel, or both")
    args = parser.parse_args(argv)
    windows = args.windows.split(",")
    kinds = ["fcnn", *(f"colour/{w}" for w in windows)]
    offsets = {kind: [] for kind in kinds}
    seeds = parse_seeds(args.seeds, 5)
    errors = {(m, kind): [] for m in args.methods.split(",") for kind in kinds}
    for seed in seeds:
        seq, info = simulate_with_info(args.scenario, seed, rgb=True)
        t0, box, _, _ = reference_box(seq, info)
        q = smooth_chromaticity(smooth_intensity(patch_histogram(seq.images[t0], box)), weight=args.chroma)
        heats = {f"colour/{w}": np.asarray(colour_heatmaps(seq.images, q, seq.intrinsics, seq.cam_to_base,
                                                         seq.ball_radius, ColourParams(), top_bins=exact_top_bins(q),
                                                         blob_window=w == "blob"))
                 for w in windows}
        if args.centroids:
            truth_px = to_image(seq.ground_truth, seq, info["true_cam_to_base"])
            visible = info["visible"].copy()
            visible[:10] = False
            fcnn_threshold = float(hp.build(args.methods.split(",")[0])[1].source.threshold)
            for kind in kinds:
                maps, thr = (seq.heatmaps, fcnn_threshold) if kind == "fcnn" else (heats[kind], THRESHOLD)
                offsets[kind].append(centroid_offsets(np.asarray(maps), thr, truth_px, visible))
        for method in args.methods.split(","):
            model, params = hp.build(method)
            colour_params = P.set_by_name(params, model.properties(), {"threshold": THRESHOLD})
            for kind in kinds:
                data, p = (seq, params) if kind == "fcnn" else (seq._replace(heatmaps=heats[kind]), colour_params)
                est = np.asarray(hp.run(jax.random.key(seed), data._replace(images=None), p, model).info.mean)
                errors[(method, kind)].append(np.linalg.norm(est - seq.ground_truth, axis=1)[10:].mean())
    print(f"{args.scenario}, seeds {seeds.start}-{seeds.stop - 1}: mean error after step 10 [m]")
    print(f"{'method':10s} {'maps':13s} {'error':>8s} {'ratio':>6s}   per seed (colour / FCNN)")
    for method in args.methods.split(","):
        f = np.array(errors[(method, "fcnn")])
        print(f"{method:10s} {'fcnn':13s} {f.mean():8.4f}")
        for kind in kinds[1:]:
            c = np.array(errors[(method, kind)])
            per_seed = " ".join(f"{r:.2f}" for r in c / f)
            print(f"{method:10s} {kind:13s} {c.mean():8.4f} {c.mean() / f.mean():6.2f}   {per_seed}")
    if args.centroids:
        print("map centroids near the ball against its true image position [px] (u: column, v: row, down)")
        print(f"{'maps':13s} {'frames':>6s} {'bias u':>7s} {'bias v':>7s} {'std u':>6s} {'std v':>6s} {'pixels':>7s}")
        for kind, parts in offsets.items():
            d = np.concatenate([o for o, _ in parts])
            n = np.concatenate([c for _, c in parts])
            print(f"{kind:13s} {len(d):6d} {d[:, 0].mean():7.3f} {d[:, 1].mean():7.3f} {d[:, 0].std():6.3f} "
                  f"{d[:, 1].std():6.3f} {np.median(n):7.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
