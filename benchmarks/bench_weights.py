"""Benchmark of eq. (1)'s particle weights: blocked exact k-nearest (heatpf_jax.observation.knn)
against top_k, cKDTree and NumPy.

For each ``(particles P, measurements M)`` size (default 500x1024, 1000x4096, 2000x8192; k = 10) and
each measurement layout, on the same inputs:

* ``blocked``: ``heatpf_jax.observation.knn.k_nearest_blocked`` followed by particle_weights' reduction
  (``sum w / max(d, 0.01)``), under ``jax.jit``;
* ``top_k``: ``heatpf_jax.observation.particle_weights(..., method="dense")`` under ``jax.jit`` (dense P x M matrix +
  ``lax.top_k``; the default method, ``"auto"``, would pick the blocked kernel);
* ``cKDTree``: NumPy + ``scipy.spatial.cKDTree`` on the valid positions, build + ``query(k, workers=-1)``
  + the weight sum, in float64;
* ``NumPy brute``: a float32 P x M squared-distance matrix, ``np.argpartition`` for the k smallest,
  then the weight sum in float64.

Layouts (all buffers full: the threshold lets at least M pixels pass, so the strongest M are kept).
``--layout raster`` runs the first two, ``--layout random`` the last two, ``--layout both`` (default) all four:

* ``blob`` / ``2blobs`` (raster): a 200x150 heat map with one or two Gaussian blobs (plus activation
  noise) projected with ``heatpf_jax.measurements.project_heatmap`` (camera ``camera_pose(height=0.6, pitch=0.5)``,
  intrinsics (143, 143, 99.5, 74.5), plane 0.075 m): raster order, as the filter produces them;
  particles: a Gaussian cloud (0.3 m) around the blob centre(s) on the ground plus 5 % uniform explorers
  in a 7 x 8 m box (x in [0, 7], y in [-4, 4]);
* ``uniform`` (random): the same number of positions drawn uniformly in the bounding box of the
  ``blob`` layout, in random order; the ``blob`` layout's particles;
* ``random`` (random): as ``uniform``, with the particles drawn uniformly in the same box too (a
  user's own source, or measurements fused from other robots: no order, no cloud).

The blocked kernel does the same (static) work on every layout; cKDTree's work depends on the layout.

Timing: ``time.perf_counter`` around one call (``block_until_ready`` for JAX), after compilation and a few
warm-up calls, in 4 rounds of blocks: each round runs a block of consecutive calls of every method in
turn (so they share the machine's load; consecutive calls keep each method's allocations warm).
``blocked`` and ``cKDTree`` are timed this way for every case first; ``top_k`` and ``NumPy brute``
afterwards (they allocate up to 66 MB per call, and interleaving them slowed the others down through
page faults and cache pollution). The table gives the median and the interquartile range over
``--repeats`` calls per method; the header and footer print the load average, since other processes on
the machine move these numbers. ``blocked /
cKDTree`` is the ratio of the medians (< 1: blocked is faster). ``max rel`` is the largest relative
difference between the blocked and the top_k weights, ``rel cKD`` between the blocked and the float64
cKDTree weights; ``same sets`` counts particles whose selected
(squared distance, weight, selected) rows from ``k_nearest_blocked`` and the dense
``heatpf_jax.observation.k_nearest(..., method="dense")`` are identical.

Run it from the repository root::

    .venv/bin/python benchmarks/bench_weights.py [--repeats N] [--sizes 500x1024,1000x4096,2000x8192]
        [--k 10] [--layout raster|random|both | --layouts blob,2blobs,uniform,random]
        [--methods blocked,top_k,cKDTree,NumPy brute]

It exits with status 1 if any blocked weight differs from the top_k weight or from the (float64) cKDTree
weight by more than 1e-5 (relative).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable
from functools import partial

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np
import scipy
from _timing import first_call, positive_int, stats_ms  # noqa: E402  (sibling module)
from _timing import parse_sizes as parse_size_list  # noqa: E402
from scipy.spatial import cKDTree

import heatpf_jax as hp
from heatpf_jax.observation.knn import k_nearest_blocked, plan_blocks

HEATMAP_SHAPE = (150, 200)  # rows, columns
INTRINSICS = (143.0, 143.0, 99.5, 74.5)
CAMERA = {"height": 0.6, "pitch": 0.5}
PLANE_HEIGHT = 0.075
MIN_DISTANCE = 0.01
RTOL = 1e-5
WARMUP = 3
BLOCKS = 4  # alternating timing blocks per case
CLOUD_STD = 0.3
EXPLORER_FRACTION = 0.05
EXPLORER_BOX = ((0.0, -4.0), (7.0, 4.0))
# Blobs as (column, row, std in pixels, peak): one broad blob, or two.
BLOBS = {
    "blob": ((99.5, 100.0, 45.0, 0.95),),
    "2blobs": ((55.0, 95.0, 30.0, 0.9), (145.0, 110.0, 32.0, 0.9)),
}
LAYOUTS = ("blob", "2blobs", "uniform", "random")
LAYOUT_GROUPS = {"raster": ("blob", "2blobs"), "random": ("uniform", "random"), "both": LAYOUTS}
METHODS = ("blocked", "top_k", "cKDTree", "NumPy brute")
LIGHT_METHODS = ("blocked", "cKDTree")  # timed side by side, before the dense references


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``PxM`` sizes; M at most the heat map's pixel count (the buffer is filled from its pixels)."""
    return parse_size_list(text, HEATMAP_SHAPE[0] * HEATMAP_SHAPE[1])


def parse_layouts(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    for name in names:
        if name not in LAYOUTS:
            raise argparse.ArgumentTypeError(f"layout {name!r}: choose from {', '.join(LAYOUTS)}")
    return names


def parse_methods(text: str) -> list[str]:
    names = [t.strip() for t in text.split(",") if t.strip()]
    for name in names:
        if name not in METHODS:
            raise argparse.ArgumentTypeError(f"method {name!r}: choose from {', '.join(METHODS)}")
    if "blocked" not in names:
        raise argparse.ArgumentTypeError("methods: 'blocked' is required")
    return [m for m in METHODS if m in names]


# --------------------------------------------------------------------------- inputs


def make_heatmap(blobs, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h, w = HEATMAP_SHAPE
    vv, uu = np.mgrid[0:h, 0:w]
    heat = np.zeros(HEATMAP_SHAPE)
    for cu, cv, std, peak in blobs:
        heat = heat + peak * np.exp(-0.5 * ((uu - cu) ** 2 + (vv - cv) ** 2) / std**2)
    heat = heat + 0.02 * rng.standard_normal(HEATMAP_SHAPE)
    return np.clip(heat, 0.0, 1.0).astype(np.float32)


def blob_buffer(blobs, m: int) -> tuple[hp.Measurements, np.ndarray]:
    """The projected heat map (threshold: about 10 % more than ``m`` pixels pass) and the blobs' ground centres."""
    heat = make_heatmap(blobs)
    ranked = np.sort(heat.ravel())[::-1]
    threshold = float(ranked[min(ranked.size - 1, int(1.1 * m))])
    cam = jnp.asarray(hp.camera.camera_pose(**CAMERA), jnp.float32)
    intr = jnp.asarray(INTRINSICS, jnp.float32)
    project = jax.jit(hp.measurements.project_heatmap, static_argnames="max_measurements")
    meas = project(jnp.asarray(heat), intr, cam, threshold=jnp.float32(threshold),
                   plane_height=jnp.float32(PLANE_HEIGHT), max_measurements=m)
    centres = [np.asarray(hp.camera.project_pixel(jnp.asarray((cu, cv), jnp.float32), intr, cam, PLANE_HEIGHT)[0])
               for cu, cv, _, _ in blobs]
    return jax.block_until_ready(meas), np.asarray(centres, np.float64)


def uniform_buffer(like: hp.Measurements, seed: int = 1) -> hp.Measurements:
    """As many positions as ``like`` has valid ones, uniform in its bounding box, random order, all valid."""
    rng = np.random.default_rng(seed)
    xy = np.asarray(like.xy)[np.asarray(like.valid)]
    lo, hi = xy.min(axis=0), xy.max(axis=0)
    m = like.xy.shape[0]
    pts = rng.uniform(lo, hi, (m, 2)).astype(np.float32)
    weight = rng.uniform(0.3, 1.0, m).astype(np.float32)
    return hp.Measurements(jnp.asarray(pts), jnp.asarray(weight), jnp.ones(m, bool), jnp.zeros((m, 2, 2), jnp.float32))


def uniform_particles(n: int, like: hp.Measurements, seed: int = 3) -> jax.Array:
    """``n`` particles uniform in the bounding box of ``like``'s valid positions."""
    rng = np.random.default_rng(seed)
    xy = np.asarray(like.xy)[np.asarray(like.valid)]
    return jnp.asarray(rng.uniform(xy.min(axis=0), xy.max(axis=0), (n, 2)), jnp.float32)


def make_particles(n: int, centres: np.ndarray, seed: int = 2) -> jax.Array:
    rng = np.random.default_rng(seed)
    n_exp = int(round(EXPLORER_FRACTION * n))
    which = rng.integers(0, len(centres), n - n_exp)
    cloud = centres[which] + CLOUD_STD * rng.standard_normal((n - n_exp, 2))
    explorers = rng.uniform(EXPLORER_BOX[0], EXPLORER_BOX[1], (n_exp, 2))
    p = np.concatenate([cloud, explorers])[rng.permutation(n)]
    return jnp.asarray(p, jnp.float32)


# --------------------------------------------------------------------------- the four implementations


def blocked_weights(particles, measurements, k: int):
    """particle_weights' reduction on top of the blocked selection."""
    sq, w, _ = k_nearest_blocked(particles, measurements, k, k_max=k)
    dist = jnp.sqrt(jnp.maximum(sq, MIN_DISTANCE**2))
    out = jnp.sum(w / dist, axis=-1)
    return jnp.where(jnp.any(measurements.valid), out, jnp.ones_like(out))


def ckdtree_weights(p: np.ndarray, xy: np.ndarray, weight: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    pts = xy[valid]
    if pts.shape[0] == 0:
        return np.ones(p.shape[0])
    dist, idx = cKDTree(pts).query(p, k=k, workers=-1)
    dist = dist.reshape(p.shape[0], k)
    idx = idx.reshape(p.shape[0], k)
    w = np.append(weight[valid], 0.0)  # fewer than k points: idx == n, dist == inf
    found = np.isfinite(dist)
    return np.where(found, w[idx] / np.maximum(np.where(found, dist, 1.0), MIN_DISTANCE), 0.0).sum(axis=1)


def brute_weights(p32: np.ndarray, xy32: np.ndarray, weight: np.ndarray, valid: np.ndarray, k: int) -> np.ndarray:
    pts = xy32[valid]
    if pts.shape[0] == 0:
        return np.ones(p32.shape[0])
    w = weight[valid]
    dx = p32[:, 0, None] - pts[None, :, 0]
    dy = p32[:, 1, None] - pts[None, :, 1]
    sq = dx * dx + dy * dy
    kk = min(k, pts.shape[0])
    idx = np.argpartition(sq, kk - 1, axis=1)[:, :kk] if kk < pts.shape[0] else np.broadcast_to(
        np.arange(pts.shape[0]), sq.shape)
    d = np.sqrt(np.take_along_axis(sq, idx, axis=1).astype(np.float64))
    return (w[idx] / np.maximum(d, MIN_DISTANCE)).sum(axis=1)


# --------------------------------------------------------------------------- timing


def time_blocks(calls: list[Callable[[], object]], repeats: int, blocks: int = BLOCKS) -> list[np.ndarray]:
    """Seconds per call for each callable: ``blocks`` rounds in which each callable runs a block of calls.

    Consecutive calls of one function keep its allocations warm (interleaving single calls of four
    implementations mostly measures allocator and cache churn); alternating blocks lets all of them
    share the machine's load over the whole run. One untimed call opens every block.
    """
    for call in calls:
        for _ in range(WARMUP):
            call()
    sizes = [repeats // blocks + (1 if b < repeats % blocks else 0) for b in range(blocks)]
    times: list[list[float]] = [[] for _ in calls]
    for size in sizes:
        for j, call in enumerate(calls):
            call()
            for _ in range(size):
                t0 = time.perf_counter()
                call()
                times[j].append(time.perf_counter() - t0)
    return [np.asarray(t) for t in times]


def rel_diff(a: np.ndarray, b: np.ndarray) -> float:
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), np.finfo(np.float64).tiny)))


def prepare_case(n: int, m: int, k: int, layout: str) -> dict:
    """Inputs, compiled functions and the four callables of one case."""
    if layout in ("uniform", "random"):
        like, centres = blob_buffer(BLOBS["blob"], m)
        meas = uniform_buffer(like)
    else:
        meas, centres = blob_buffer(BLOBS[layout], m)
    particles = uniform_particles(n, meas) if layout == "random" else make_particles(n, centres)

    ours = jax.jit(partial(blocked_weights, k=k))
    plain = jax.jit(partial(hp.observation.particle_weights, k=k, method="dense"))
    compile_ours = first_call(lambda: ours(particles, meas))
    compile_plain = first_call(lambda: plain(particles, meas))

    p64 = np.asarray(particles, np.float64)
    p32 = np.asarray(particles)
    xy64 = np.asarray(meas.xy, np.float64)
    xy32 = np.asarray(meas.xy)
    w64 = np.asarray(meas.weight, np.float64)
    valid = np.asarray(meas.valid)

    got = np.asarray(ours(particles, meas))
    want = np.asarray(plain(particles, meas))
    tree = ckdtree_weights(p64, xy64, w64, valid, k)
    brute = brute_weights(p32, xy32, w64, valid, k)
    sel_ours = [np.asarray(a) for a in jax.jit(partial(k_nearest_blocked, k=k, k_max=k))(particles, meas)]
    sel_plain = [
        np.asarray(a)
        for a in jax.jit(partial(hp.observation.k_nearest, k=k, k_max=k, method="dense"))(particles, meas)
    ]
    same = np.all([np.all(a == b, axis=1) for a, b in zip(sel_ours, sel_plain, strict=True)], axis=0)

    return {
        "P": n, "M": m, "layout": layout, "n_valid": int(valid.sum()),
        "plan": plan_blocks(m, k).fanouts,
        "calls": {
            "blocked": lambda: ours(particles, meas).block_until_ready(),
            "top_k": lambda: plain(particles, meas).block_until_ready(),
            "cKDTree": lambda: ckdtree_weights(p64, xy64, w64, valid, k),
            "NumPy brute": lambda: brute_weights(p32, xy32, w64, valid, k),
        },
        "times": {},
        "compile": (compile_ours, compile_plain),
        "rel_plain": rel_diff(got, want),
        "rel_blocked_tree": rel_diff(got, tree),
        "rel_tree": rel_diff(tree, want),
        "rel_brute": rel_diff(brute, want),
        "same_sets": int(same.sum()),
    }


def time_phase(cases: list[dict], methods: list[str], repeats: int) -> None:
    """Times ``methods`` of every case (alternating blocks within a case), storing into ``case['times']``."""
    if not methods:
        return
    for case in cases:
        times = time_blocks([case["calls"][name] for name in methods], repeats)
        case["times"].update(zip(methods, times, strict=True))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=positive_int, default=40, help="timed repetitions per case (default 40)")
    parser.add_argument("--sizes", type=parse_sizes, default=parse_sizes("500x1024,1000x4096,2000x8192"),
                        help="comma-separated PARTICLESxMEASUREMENTS (default 500x1024,1000x4096,2000x8192)")
    parser.add_argument("--k", type=positive_int, default=10, help="neighbours per particle (default 10)")
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--layout", choices=tuple(LAYOUT_GROUPS), default="both",
                       help="raster: blob,2blobs; random: uniform,random; both (default): all four")
    which.add_argument("--layouts", type=parse_layouts, default=None,
                       help=f"comma-separated measurement layouts, instead of --layout (from {','.join(LAYOUTS)})")
    parser.add_argument("--methods", type=parse_methods, default=list(METHODS),
                        help=f"comma-separated methods to time (default {','.join(METHODS)}; blocked is required)")
    args = parser.parse_args(argv)
    layouts = args.layouts if args.layouts is not None else list(LAYOUT_GROUPS[args.layout])

    dev = jax.devices()[0]
    print("heatpf_jax benchmark: eq. (1) particle weights, blocked exact k-nearest vs top_k / cKDTree / NumPy")
    print(f"python {platform.python_version()}  jax {jax.__version__}  jaxlib {jaxlib.__version__}  "
          f"numpy {np.__version__}  scipy {scipy.__version__}  heatpf_jax {hp.__version__}")
    print(f"device: {dev.platform} / {dev.device_kind} ({len(jax.devices())} device(s))  "
          f"os.cpu_count(): {os.cpu_count()}  machine: {platform.machine()}  "
          f"XLA_FLAGS: {os.environ.get('XLA_FLAGS', '(unset)')}")
    print(f"load average at start: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(f"k = {args.k}, repeats = {args.repeats} (+{WARMUP} warm-up; {BLOCKS} alternating blocks), "
          f"heat map {HEATMAP_SHAPE[1]}x{HEATMAP_SHAPE[0]}, min_distance = {MIN_DISTANCE}")
    print("times in ms: median (IQR = q3 - q1); compile = first call of the jitted function, s")
    print()

    t_start = time.perf_counter()
    results = [prepare_case(p, m, args.k, layout) for p, m in args.sizes for layout in layouts]
    # The compared methods first, for all cases; then the dense references. The dense ones allocate
    # 2-66 MB per call, and interleaving them slowed the others (blocked 3.2 instead of 1.6 ms at
    # 1000 x 4096) through page faults and cache pollution.
    time_phase(results, [name for name in args.methods if name in LIGHT_METHODS], args.repeats)
    time_phase(results, [name for name in args.methods if name not in LIGHT_METHODS], args.repeats)

    methods = args.methods
    header = (f"{'P':>5} {'M':>5} {'layout':<8} {'valid':>5} "
              + " ".join(f"{name:>17}" for name in methods)
              + f" {'blocked/cKDTree':>15} {'max rel':>8} {'rel cKD':>8} {'same sets':>10}")
    print(header)
    print("-" * len(header))
    for res in results:
        cells = []
        for name in methods:
            med, iqr = stats_ms(res["times"][name])
            cells.append(f"{med:8.3f} ({iqr:6.3f})")
        if "cKDTree" in methods:
            ratio = f"{stats_ms(res['times']['blocked'])[0] / stats_ms(res['times']['cKDTree'])[0]:15.2f}"
        else:
            ratio = f"{'-':>15}"
        print(f"{res['P']:>5} {res['M']:>5} {res['layout']:<8} {res['n_valid']:>5} " + " ".join(cells)
              + f" {ratio} {res['rel_plain']:8.1e} {res['rel_blocked_tree']:8.1e} {res['same_sets']:>5}/{res['P']:<4}")
    print()
    print("plans, compile times and the other implementations' agreement with top_k (max relative difference):")
    for res in results:
        print(f"  {res['P']:>5} x {res['M']:>5} {res['layout']:<8} fanouts {str(res['plan']):<8} "
              f"compile blocked {res['compile'][0]:5.2f} s, top_k {res['compile'][1]:5.2f} s;  "
              f"cKDTree {res['rel_tree']:.1e}, NumPy brute {res['rel_brute']:.1e}")
    print()
    print("blocked/cKDTree: ratio of medians (< 1: blocked is faster). max rel: blocked vs top_k weights; "
          "rel cKD: blocked vs the float64 cKDTree weights.")
    print(f"same sets: particles whose (sq_dist, weight, selected) rows equal the dense k_nearest's exactly. "
          f"Total {time.perf_counter() - t_start:.0f} s; load average at end: "
          f"{' '.join(f'{v:.2f}' for v in os.getloadavg())}.")
    return 0 if all(max(res["rel_plain"], res["rel_blocked_tree"]) <= RTOL for res in results) else 1


if __name__ == "__main__":
    sys.exit(main())
