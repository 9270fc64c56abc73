"""What the filters read from a colour blob: ``heatmap`` and ``extended`` on synthetic maps, a cone about the ball's
true image centre, against the same filters on the world's detector-like heat maps.

The maps of ``heatpf colour`` are blobs of a few pixels about where the colours say the ball is. This script asks
how the filters' error follows the blob's height, its size and a jitter of its centre from frame to frame, with
everything else perfect: every frame where the ball is in view gets ``peak * max(0, 1 - d / (scale * r))``, ``d``
the pixel's distance from the ball's projected centre (moved by a normal jitter of ``jitter`` pixels per axis),
``r`` the ball's image radius; the sequence carries the colour maps' settings (:data:`heatpf_jax.colour.MAP_SETTINGS`,
every pixel projected). Mean error after step 10 (``colour_user_box.filter_error``), averaged over ``--keys``.

    python benchmarks/colour_blob_sensitivity.py                       # seeds 100-101, the variants below
    python benchmarks/colour_blob_sensitivity.py --seeds 100:104 --cones 1,1,0:0.6,1,0.3
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from colour_user_box import filter_error  # noqa: E402  (beside this script)

from heatpf_jax.cli.settings import parse_seeds  # noqa: E402
from heatpf_jax.colour import MAP_SETTINGS  # noqa: E402
from heatpf_jax.sim.render import project_centre  # noqa: E402
from heatpf_jax.sim.scenarios import simulate_with_info  # noqa: E402

DEFAULT_CONES = "1,1,0:0.6,1,0:0.6,0.5,0:1,2,0:0.6,1,0.1:0.6,1,0.3"


def cone_maps(seq, info, peak: float, scale: float, jitter: float, rng) -> np.ndarray:
    """``float32 [T, H, W]``: a cone about the ball's true image centre in every frame where it is in view."""
    t_steps, h, w = seq.heatmaps.shape
    vv, uu = np.mgrid[0:h, 0:w]
    focal = float(seq.intrinsics[0])
    out = np.zeros((t_steps, h, w), np.float32)
    for t in range(t_steps):
        if not info["visible"][t]:
            continue
        centre = np.array([*seq.ground_truth[t], float(seq.ball_radius)])
        u, v, depth = project_centre(centre, seq.intrinsics, info["true_cam_to_base"][t])
        if depth <= 0:
            continue
        u, v = u + rng.normal(0.0, jitter), v + rng.normal(0.0, jitter)
        radius = focal * float(seq.ball_radius) / depth
        out[t] = peak * np.clip(1.0 - np.hypot(uu - u, vv - v) / (scale * radius), 0.0, 1.0)
    return out


def _cones(text: str) -> list[tuple[float, float, float]]:
    cones = []
    for item in text.split(":"):
        parts = item.split(",")
        if len(parts) != 3:
            raise SystemExit(f"--cones: each cone is PEAK,SCALE,JITTER, got {item!r}")
        peak, scale, jitter = (float(p) for p in parts)
        if not (0.0 < peak <= 1.0 and scale > 0.0 and jitter >= 0.0):
            raise SystemExit(f"--cones: need 0 < PEAK <= 1, SCALE > 0, JITTER >= 0, got {item!r}")
        cones.append((peak, scale, jitter))
    return cones


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100:102")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--keys", type=int, default=1, help="the filters' PRNG keys per run, averaged")
    parser.add_argument("--scenario", default="standard")
    parser.add_argument("--cones", default=DEFAULT_CONES,
                        help="PEAK,SCALE,JITTER[:...]: the cone's height, its radius over the ball's, the centre's "
                        "jitter in pixels (sd per axis)")
    args = parser.parse_args(argv)
    try:
        seeds = parse_seeds(args.seeds, 2)
    except ValueError as err:
        raise SystemExit(str(err)) from None
    cones = _cones(args.cones)
    methods = ("heatmap", "extended")
    names = [f"cone peak {peak:g}, radius {scale:g} r, jitter {jitter:g} px" for peak, scale, jitter in cones]
    rows = {name: {m: [] for m in methods} for name in ["detector-like maps", *names]}
    for seed in seeds:
        seq, info = simulate_with_info(args.scenario, seed, num_steps=args.steps)
        for m in methods:
            rows["detector-like maps"][m].append(filter_error(seq, m, seed, args.keys))
        rng = np.random.default_rng([seed, 31])
        for name, (peak, scale, jitter) in zip(names, cones, strict=True):
            maps = cone_maps(seq, info, peak, scale, jitter, rng)
            cone_seq = seq._replace(heatmaps=maps, settings={**(seq.settings or {}), **MAP_SETTINGS})
            for m in methods:
                rows[name][m].append(filter_error(cone_seq, m, seed, args.keys))
        print(f"seed {seed} done", file=sys.stderr, flush=True)
    print(f"{args.scenario} seeds {args.seeds}, {args.steps} steps, {args.keys} key(s); mean error after step 10 (m)")
    print("| maps | heatmap | extended |\n|---|---|---|")
    for name, by in rows.items():
        print(f"| {name} | {np.mean(by['heatmap']):.4f} | {np.mean(by['extended']):.4f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
