"""What a blob's size says of a ball's height, frame by frame, on the replays with heights kept.

For every frame of the replays (static or walking robot, the provider's heights kept) the strongest pixel's blob is
measured as :class:`heatpf_jax.sources.lofted.LoftedSource` measures it (:func:`~heatpf_jax.sources.lofted.blob_sizes`:
its centroid and its std by mass), and its log size ratio ``m = log(s / (b rho_g))`` to a ground ball's at its
centroid, with ``b`` the median ratio over the frames with the ball on the ground. Per bin of the ball's bottom height
over the ground the script prints the median and robust spread of ``m``, the mean error of the blob's centroid
projected on the plane ``z = R`` (the paper's projection) and placed along its ray by its size (``f R / rho``), against
the ground point under the ball; then, for the ground frames, the shares of ``m`` beyond 1-4 robust spreads above the
median and the correlation of ``m`` between frames 1, 3 and 5 steps apart (the size noise's tail and memory, which
:mod:`heatpf_jax.sources.air_prior` models).

    python benchmarks/blob_sizes.py                       # development replays (16 pieces), static robot
    python benchmarks/blob_sizes.py --robot walking --report
    python benchmarks/blob_sizes.py --raw-peak            # the blob's largest pixel as its peak, not subpixel_peaks

Replays need the real tracks (fetched once, see benchmarks/worlds.py).
"""

from __future__ import annotations

import argparse
import sys

import jax
import jax.numpy as jnp
import numpy as np

import heatpf_jax.sources.lofted as lofted
from heatpf_jax.camera import project_pixel

BINS = ((-np.inf, 0.0), (0.0, 0.02), (0.02, 0.05), (0.05, 0.1), (0.1, 0.2), (0.2, np.inf))


def _robust_std(x: np.ndarray) -> float:
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def frames(robot: str, development: bool, count: int, threshold: float = 0.3, min_peak: float = 0.5):
    """Per frame with a blob of peak ``min_peak`` or more: ``(piece, step, bottom height, std_px, ground radius px,
    plane xy or NaN, size xy for the given blob scale, truth)``; the size xy comes later (it needs the scale)."""
    sys.path.insert(0, __file__.rsplit("/", 1)[0])
    from worlds import replay_worlds  # benchmarks/worlds.py, beside this script

    worlds = {name: (seqs, heights) for name, seqs, _, heights in
              replay_worlds(count, 300, "gaussian", ("kept",), development)}
    seqs, heights = worlds[f"replay/{robot}/kept"]

    @jax.jit
    def strongest(heat, intrinsics, pose, radius):
        row, col = jnp.unravel_index(jnp.argmax(heat), heat.shape)
        start = jnp.stack([col, row]).astype(jnp.float32)[None]
        blob = lofted.blob_sizes(heat, start, intrinsics, pose, threshold=threshold, plane_height=radius)
        xy, ok = project_pixel(blob.uv[0], intrinsics, pose, radius, 12.0)
        return blob.uv[0], blob.std_px[0], blob.ground_radius_px[0], xy, ok, jnp.max(heat)

    rows = []
    for i, seq in enumerate(seqs):
        intrinsics = jnp.asarray(seq.intrinsics, jnp.float32)
        radius = jnp.float32(seq.ball_radius)
        for t in range(seq.num_steps):
            if not seq.has_heatmap[t]:
                continue
            pose = jnp.asarray(seq.cam_to_base[t], jnp.float32)
            uv, std, ground, xy, ok, peak = strongest(jnp.asarray(seq.heatmaps[t]), intrinsics, pose, radius)
            if float(peak) < min_peak or float(std) <= 0.0:
                continue
            rows.append(dict(piece=i, t=t, h=float(heights[i, t]), std=float(std), ground=float(ground),
                             uv=np.asarray(uv), plane=np.asarray(xy) if bool(ok) else np.full(2, np.nan),
                             truth=np.asarray(seq.ground_truth[t]), pose=np.asarray(seq.cam_to_base[t]),
                             intrinsics=np.asarray(seq.intrinsics), radius=float(seq.ball_radius)))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--robot", choices=("static", "walking"), default="static")
    parser.add_argument("--report", action="store_true", help="the reported replays (6 pieces of 30 s or more) "
                        "instead of the development ones")
    parser.add_argument("--replays", type=int, default=16, help="development pieces (default 16)")
    parser.add_argument("--raw-peak", action="store_true", help="the blob's largest pixel as its peak (as before "
                        "subpixel_peaks)")
    args = parser.parse_args(argv)
    if args.raw_peak:
        lofted.subpixel_peaks = lambda heat: jnp.asarray(heat, jnp.float32)  # the module-level name blob_sizes calls
    rows = frames(args.robot, not args.report, 6 if args.report else args.replays)
    h = np.array([r["h"] for r in rows])
    ratio = np.array([r["std"] / r["ground"] if r["ground"] > 0 else np.nan for r in rows])
    scale = float(np.nanmedian(ratio[h <= 0.0]))
    m = np.log(ratio / scale)
    plane = np.array([np.linalg.norm(r["plane"] - r["truth"]) for r in rows])
    size = []
    for r in rows:
        points, ok = lofted.air_points(r["uv"][None], np.array([r["std"] / scale], np.float32), r["intrinsics"],
                                       r["pose"], r["radius"])
        size.append(np.linalg.norm(np.asarray(points)[0, :2] - r["truth"]) if bool(ok[0]) else np.nan)
    size = np.array(size)
    print(f"{args.robot} robot, {'reported' if args.report else 'development'} replays, heights kept; "
          f"{len(rows)} frames; blob scale (median over ground frames) {scale:.3f}; peak: "
          f"{'largest pixel' if args.raw_peak else 'subpixel_peaks'}")
    print(f"{'bottom height [m]':<20}{'frames':>8}{'median m':>10}{'robust std':>12}{'plane err':>11}{'size err':>10}")
    for lo, hi in BINS:
        sel = (h > lo) & (h <= hi)
        if not sel.any():
            continue
        finite = sel & np.isfinite(m)
        label = "0" if hi == 0.0 else f"({lo:g}, {hi:g}]"
        print(f"{label:<20}{int(sel.sum()):>8}{np.median(m[finite]):>+10.3f}{_robust_std(m[finite]):>12.3f}"
              f"{np.nanmean(plane[sel]):>11.3f}{np.nanmean(size[sel]):>10.3f}")
    ground = (h <= 0.0) & np.isfinite(m)
    z = (m[ground] - np.median(m[ground])) / _robust_std(m[ground])
    tails = " / ".join(f"{100 * np.mean(z > k):.1f}" for k in (1, 2, 3, 4))
    print(f"ground frames: share of m beyond 1 / 2 / 3 / 4 robust stds above the median [%]: {tails}")
    piece = np.array([r["piece"] for r in rows])
    step = np.array([r["t"] for r in rows])
    for lag in (1, 3, 5):
        a, b = [], []
        for i in range(len(rows)):
            j = np.nonzero((piece == piece[i]) & (step == step[i] + lag))[0]
            if j.size and ground[i] and ground[j[0]]:
                a.append(m[i])
                b.append(m[j[0]])
        print(f"ground frames {lag} step(s) apart: correlation of m {np.corrcoef(a, b)[0, 1]:.2f} ({len(a)} pairs)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
