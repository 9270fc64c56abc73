"""Benchmark of the observation model (eq. 1) and of one whole filter step, against NumPy + cKDTree.

What it measures, for each ``(particles P, measurements M)`` size (default 500x1024 and 1000x4096):

* ``particle_weights``: the exact blocked kernel (``heatpf_jax.observation.particle_weights(..., method="blocked")``,
  what ``FilterOptions.knn="auto"`` picks at these sizes) and the plain dense ``top_k``, under ``jax.jit``,
  at ``--k`` (default 10);
* ``cKDTree build+query`` / ``cKDTree total``: a NumPy + ``scipy.spatial.cKDTree`` implementation of the
  same model on the same inputs (tree on the valid measurement positions, ``query(particles, k)``; "total"
  adds the masking and the sum of ``weight / max(distance, 0.01)``). Its weights are checked against
  ours (max relative difference, tolerance 1e-5);
* ``step, heat map``: ``Filter.step`` of ``heatpf_jax.heatmap_filter`` under ``jax.jit`` (the model a static
  argument) on a 200x150 heat map whose blob yields more than M pixels above the threshold (projection,
  buffer replacement, weighting, estimate, resampling, explorers), for two parameter choices: the shipped
  defaults (the default params' ``k`` under ``FilterOptions().k_max``, so k stays sweepable) and
  ``k = k_max = --k``;
* ``step, aging``: the same step with ``has_heatmap=False`` (the buffer ages instead);
* ``step, NumPy + cKDTree``: the same step written with NumPy + cKDTree, at the same k.

Every timing is ``time.perf_counter`` around one call (``block_until_ready`` for JAX), after compilation
and a few warm-up calls; the table gives the median and the interquartile range over ``--repeats`` calls
and the first-call (compile) time of the JAX functions. Steps use a fresh PRNG key per call and the same
state (one that already holds a full measurement buffer).

``--threads 1`` runs everything on one core's worth of threads: XLA's CPU thread pool gets one thread
(``PJRT_NPROC=1``, set before JAX starts: XLA's CPU client sizes its pool from it) and cKDTree queries
use ``workers=1``. A robot's filter process runs best that way (or pinned to a core): XLA otherwise
splits larger operations over its pool, and on a small, shared machine the hand-offs cost more than
they save and make step times jittery.

Run it from the repository root::

    .venv/bin/python benchmarks/bench_step.py [--repeats N] [--sizes 500x1024,1000x4096] [--k 10] [--threads 1]
        [--label TEXT]

``--label`` is printed in the header, to tell apart runs of different commits.

It exits with status 1 if the cKDTree weights disagree with ours.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable

if __name__ == "__main__" and "--threads" in sys.argv[1:-1] and sys.argv[sys.argv.index("--threads") + 1] == "1":
    os.environ["PJRT_NPROC"] = "1"  # XLA:CPU sizes its thread pool when JAX starts

import jax
import jax.numpy as jnp
import numpy as np
import scipy
from _timing import first_call, positive_int, stats_ms  # noqa: E402  (sibling module)
from _timing import parse_sizes as parse_size_list  # noqa: E402
from scipy.spatial import cKDTree

import heatpf_jax as hp
from heatpf_jax import params as P

HEATMAP_SHAPE = (150, 200)  # rows, columns: the paper's 200 x 150 heat map
INTRINSICS = (143.0, 143.0, 99.5, 74.5)
CAMERA = {"height": 0.6, "pitch": 0.5}
PLANE_HEIGHT = 0.075  # ball radius, metres
MIN_DISTANCE = 0.01
RTOL = 1e-5
WARMUP = 3
WORKERS = 1 if os.environ.get("PJRT_NPROC") == "1" else -1  # cKDTree query threads (-1: all cores)


def setting(model, params, name: str):
    """The value of the parameter ``name`` (dotted, or its last part when unambiguous) in ``params``."""
    names = P.leaf_names(model.properties())
    full = P.resolve_name(name, names)
    if full is None:
        raise ValueError(f"{name}: unknown parameter (known: {', '.join(names)})")
    return jax.tree.leaves(params)[names.index(full)]


DEFAULT_MODEL = hp.paper_filter()
DEFAULT_PARAMS = DEFAULT_MODEL.default_params()
DEFAULT_K, DEFAULT_K_MAX = setting(DEFAULT_MODEL, DEFAULT_PARAMS, "k"), hp.FilterOptions().k_max


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """``PxM`` sizes; M at most the heat map's pixel count (the buffer is filled from its pixels)."""
    return parse_size_list(text, HEATMAP_SHAPE[0] * HEATMAP_SHAPE[1])


def make_heatmap(seed: int = 0) -> np.ndarray:
    """A broad blob in the lower half of the image plus a little activation noise, in [0, 1]."""
    rng = np.random.default_rng(seed)
    h, w = HEATMAP_SHAPE
    vv, uu = np.mgrid[0:h, 0:w]
    heat = 0.95 * np.exp(-0.5 * ((uu - 99.5) ** 2 + (vv - 100.0) ** 2) / 45.0**2)
    heat = heat + 0.02 * rng.standard_normal(HEATMAP_SHAPE)
    return np.clip(heat, 0.0, 1.0).astype(np.float32)


def pick_threshold(heatmap: np.ndarray, m: int, min_weight: float) -> float:
    """An activation threshold that about 10 % more than ``m`` pixels pass (so the buffer fills up)."""
    ranked = np.sort(heatmap.ravel())[::-1]
    idx = min(ranked.size - 1, int(1.1 * m))
    return float(max(ranked[idx], min_weight))


def ckdtree_weights(
    particles: np.ndarray, xy: np.ndarray, weight: np.ndarray, valid: np.ndarray, k: int
) -> tuple[np.ndarray, float]:
    """Eq. (1) with a k-d tree. Returns the weights and the seconds spent in build + query."""
    t0 = time.perf_counter()
    pts = xy[valid]
    if pts.shape[0] == 0:
        return np.ones(particles.shape[0]), time.perf_counter() - t0
    tree = cKDTree(pts)
    dist, idx = tree.query(particles, k=k, workers=WORKERS)
    t_tree = time.perf_counter() - t0
    dist = dist.reshape(particles.shape[0], k)
    idx = idx.reshape(particles.shape[0], k)
    w = np.append(weight[valid], 0.0)  # fewer than k points: idx == n, dist == inf
    found = np.isfinite(dist)
    contrib = np.where(found, w[idx] / np.maximum(np.where(found, dist, 1.0), MIN_DISTANCE), 0.0)
    return contrib.sum(axis=1), t_tree


def numpy_step(rng: np.random.Generator, particles: np.ndarray, heatmap: np.ndarray, pose: np.ndarray,
               threshold: float, m: int, k: int, n_explorers: int, box=(0.0, 7.0, -4.0, 4.0)) -> np.ndarray:
    """The same filter step in NumPy + cKDTree (static robot): diffusion, projection of every pixel at or
    above the threshold (strongest m kept), eq. (1) by cKDTree, systematic resampling, explorers, and
    the top-95 % estimate. Returns the estimate."""
    n = particles.shape[0]
    particles = particles + 0.2 * rng.standard_normal(particles.shape)
    h, w = heatmap.shape
    fx, fy, cx, cy = INTRINSICS
    act = heatmap.ravel()
    idx = np.flatnonzero(act >= threshold)
    if idx.size > m:
        idx = np.sort(idx[np.argpartition(act[idx], -m)[-m:]])
    u, v = (idx % w).astype(np.float64), (idx // w).astype(np.float64)
    rays = np.stack([(u - cx) / fx, (v - cy) / fy, np.ones_like(u)]) .T @ pose[:3, :3].T
    scale = (PLANE_HEIGHT - pose[2, 3]) / rays[:, 2]
    ok = scale > 0
    xy = pose[:2, 3] + scale[ok, None] * rays[ok, :2]
    tree = cKDTree(xy)
    d, j = tree.query(particles, k=min(k, len(xy)), workers=WORKERS)
    d, j = d.reshape(n, -1), j.reshape(n, -1)
    weights = (act[idx][ok][j] / np.maximum(d, MIN_DISTANCE)).sum(axis=1)
    weights = weights / weights.sum()
    order = np.argsort(-weights)
    top = order[: int(np.ceil(0.95 * n))]
    estimate = np.average(particles[top], axis=0, weights=weights[top])
    positions = (np.arange(n) + rng.random()) / n
    chosen = np.minimum(np.searchsorted(np.cumsum(weights), positions), n - 1)
    support = weights[chosen]
    particles = particles[chosen]
    low = np.argsort(support, kind="stable")[:n_explorers]
    particles[low] = rng.uniform((box[0], box[2]), (box[1], box[3]), (n_explorers, 2))
    return estimate


def time_calls(call: Callable[[int], object], repeats: int) -> np.ndarray:
    """Seconds per call of ``call(i)`` for i in range(repeats), after WARMUP untimed calls."""
    for i in range(WARMUP):
        call(i)
    times = np.empty(repeats)
    for i in range(repeats):
        t0 = time.perf_counter()
        call(WARMUP + i)
        times[i] = time.perf_counter() - t0
    return times


def bench_size(num_particles: int, max_measurements: int, k: int, repeats: int) -> dict:
    heatmap = make_heatmap()
    threshold = pick_threshold(heatmap, max_measurements, setting(DEFAULT_MODEL, DEFAULT_PARAMS, "min_weight"))
    cam = jnp.asarray(hp.camera.camera_pose(**CAMERA), jnp.float32)
    intr = jnp.asarray(INTRINSICS, jnp.float32)

    def inputs(has_heatmap: bool) -> hp.StepInputs:
        return hp.StepInputs(
            heatmap=jnp.asarray(heatmap),
            has_heatmap=jnp.asarray(has_heatmap),
            cam_to_base=cam,
            odometry=jnp.zeros((3,), jnp.float32),
            intrinsics=intr,
            plane_height=jnp.asarray(PLANE_HEIGHT, jnp.float32),
            dt=jnp.asarray(0.1, jnp.float32),
        )

    with_map, without_map = inputs(True), inputs(False)
    step = jax.jit(hp.Filter.step, static_argnums=0)  # step(model, key, state, inputs, params); model static
    rows = []
    rng = np.random.default_rng(0)
    pose_np = np.asarray(hp.camera.camera_pose(**CAMERA))
    n_exp = round(setting(DEFAULT_MODEL, DEFAULT_PARAMS, "explorer_fraction") * num_particles)
    state_for_weights = None
    compiled: set[hp.Filter] = set()
    # The shipped defaults (k under k_max) and k = k_max = --k.
    choices = ((f"defaults k={DEFAULT_K}/{DEFAULT_K_MAX}", DEFAULT_K, DEFAULT_K_MAX), (f"k={k}", k, k))
    for label, step_k, k_max in choices:
        options = hp.FilterOptions(num_particles=num_particles, max_measurements=max_measurements, k_max=k_max)
        model = hp.paper_filter(options)
        params_py = model.make_params(k=step_k, threshold=threshold)
        model.validate()
        hp.validate_params(params_py, model)
        params = P.as_arrays(params_py, model.properties())
        key_init, key_first, key_steps = jax.random.split(jax.random.key(0), 3)
        state0 = model.init(key_init, params)
        # Compile (timed once; "-" when an earlier choice had the same model, so the program is cached)
        # and one step with a heat map: its state holds a full buffer for both timings.
        t_compile = first_call(lambda: step(model, key_first, state0, with_map, params))
        t_compile = None if model in compiled else t_compile
        compiled.add(model)
        state, info0 = step(model, key_first, state0, with_map, params)
        jax.block_until_ready(state)
        n_keys = WARMUP + repeats
        keys = list(jax.random.split(key_steps, 2 * n_keys))
        keys_map, keys_age = keys[:n_keys], keys[n_keys:]
        _, info_map = step(model, keys_map[0], state, with_map, params)
        _, info_age = step(model, keys_age[0], state, without_map, params)
        t_map = time_calls(lambda i: jax.block_until_ready(step(model, keys_map[i], state, with_map, params)),
                           repeats)
        t_age = time_calls(lambda i: jax.block_until_ready(step(model, keys_age[i], state, without_map, params)),
                           repeats)
        t_np = time_calls(lambda i: numpy_step(rng, np.asarray(state.particles.xy, np.float64), heatmap, pose_np,
                                               threshold, max_measurements, step_k, n_exp), repeats)
        rows += [
            (f"step, heat map ({label})", t_map, t_compile, int(info_map.num_valid)),
            (f"step, aging ({label})", t_age, None, int(info_age.num_valid)),
            (f"step, NumPy+cKDTree (k={step_k})", t_np, None, int(info0.num_valid)),
        ]
        state_for_weights = state

    # The observation model on the step's inputs: the state's particles and this heat map's buffer.
    project = jax.jit(hp.measurements.project_heatmap, static_argnames="max_measurements")

    def default(name: str):
        return setting(DEFAULT_MODEL, DEFAULT_PARAMS, name)

    buffer = project(heatmap, intr, cam, threshold=jnp.float32(threshold), plane_height=PLANE_HEIGHT,
                     max_measurements=max_measurements, max_distance=default("max_distance"))
    buffer = hp.measurements.update_buffer(hp.measurements.empty_measurements(max_measurements), buffer, True,
                                           default("aging"), default("min_weight"))
    particles = state_for_weights.particles.xy
    jax.block_until_ready((buffer, particles))
    weights_fn = jax.jit(lambda p, m: hp.observation.particle_weights(p, m, k, method="blocked"))
    t_compile_pw = first_call(lambda: weights_fn(particles, buffer))
    t_pw = time_calls(lambda i: weights_fn(particles, buffer).block_until_ready(), repeats)
    ours = np.asarray(weights_fn(particles, buffer), np.float64)
    dense_fn = jax.jit(lambda p, m: hp.observation.particle_weights(p, m, k, method="dense"))
    t_compile_dense = first_call(lambda: dense_fn(particles, buffer))
    t_dense = time_calls(lambda i: dense_fn(particles, buffer).block_until_ready(), repeats)
    dense_rel = np.abs(np.asarray(dense_fn(particles, buffer), np.float64) - ours) / np.abs(ours)

    # NumPy + cKDTree on the same (float32) inputs, in float64.
    p_np = np.asarray(particles, np.float64)
    xy_np = np.asarray(buffer.xy, np.float64)
    w_np = np.asarray(buffer.weight, np.float64)
    v_np = np.asarray(buffer.valid)
    tree_times = []

    def ckd(_i: int) -> None:
        _, t_tree = ckdtree_weights(p_np, xy_np, w_np, v_np, k)
        tree_times.append(t_tree)

    t_ckd = time_calls(ckd, repeats)
    t_tree = np.asarray(tree_times[WARMUP:])
    ref, _ = ckdtree_weights(p_np, xy_np, w_np, v_np, k)
    rel = np.abs(ours - ref) / np.maximum(np.abs(ref), np.finfo(np.float64).tiny)
    n_valid = int(np.sum(v_np))
    return {
        "P": num_particles,
        "M": max_measurements,
        "threshold": threshold,
        "rows": [
            (f"particle_weights k={k} (blocked)", t_pw, t_compile_pw, n_valid),
            (f"particle_weights k={k}, dense", t_dense, t_compile_dense, n_valid),
            ("cKDTree build+query", t_tree, None, n_valid),
            ("cKDTree total (numpy+scipy)", t_ckd, None, n_valid),
            *rows,
        ],
        "max_rel": float(max(rel.max(), dense_rel.max())),
        "ok": bool(np.all(rel <= RTOL) and np.all(dense_rel <= RTOL)),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=positive_int, default=100, help="timed calls per row (default 100)")
    parser.add_argument("--sizes", type=parse_sizes, default=parse_sizes("500x1024,1000x4096"),
                        help="comma-separated PARTICLESxMEASUREMENTS (default 500x1024,1000x4096)")
    parser.add_argument("--k", type=positive_int, default=10, help="neighbours per particle (default 10)")
    parser.add_argument("--threads", choices=("all", "1"), default="all",
                        help="1: XLA thread pool of one thread (PJRT_NPROC=1) and cKDTree workers=1 (default all)")
    parser.add_argument("--label", default="", metavar="TEXT",
                        help="printed in the header, e.g. the commit measured (default none)")
    args = parser.parse_args(argv)
    if (args.threads == "1") != (os.environ.get("PJRT_NPROC") == "1"):
        parser.error("--threads 1 must be given on the command line (PJRT_NPROC is read when JAX starts)")

    dev = jax.devices()[0]
    print("heatpf_jax benchmark: observation model (eq. 1) and one filter step")
    print(f"label: {args.label or '-'}")
    print(f"python {platform.python_version()}  jax {jax.__version__}  numpy {np.__version__}  "
          f"scipy {scipy.__version__}  heatpf_jax {hp.__version__}")
    print(f"device: {dev.platform} / {dev.device_kind} ({len(jax.devices())} device(s))  os.cpu_count(): "
          f"{os.cpu_count()}  machine: {platform.machine()}  load average: {os.getloadavg()[0]:.2f}")
    one = "XLA pool of 1 (PJRT_NPROC=1), cKDTree workers=1"
    print(f"threads: {one if args.threads == '1' else 'all (XLA default pool, cKDTree workers=-1)'}")
    print(f"k = {args.k}, repeats = {args.repeats} (+{WARMUP} warm-up), "
          f"heat map {HEATMAP_SHAPE[1]}x{HEATMAP_SHAPE[0]}, min_distance = {MIN_DISTANCE}")
    print("times in ms: median, IQR (q3 - q1); compile = first call, s")
    print()

    results = [bench_size(p, m, args.k, args.repeats) for p, m in args.sizes]

    header = f"{'P':>5} {'M':>5}  {'what':<40} {'median ms':>10} {'IQR ms':>9} {'compile s':>9} {'n_valid':>7}"
    header += f"  [{args.label}]" if args.label else ""
    print(header)
    print("-" * len(header))
    for res in results:
        for name, times, compile_s, n_valid in res["rows"]:
            med, iqr = stats_ms(times)
            comp = f"{compile_s:9.2f}" if compile_s is not None else f"{'-':>9}"
            print(f"{res['P']:>5} {res['M']:>5}  {name:<40} {med:10.3f} {iqr:9.3f} {comp} {n_valid:>7}")
    print()

    header = (f"{'P':>5} {'M':>5}  {'threshold':>9} {'pw / cKDTree':>12} {'step / NumPy step':>17} "
              f"{'(defaults)':>10} {'max rel diff':>12} {'agree':>5}")
    print(header)
    print("-" * len(header))
    for res in results:
        med = {name: stats_ms(times)[0] for name, times, _, _ in res["rows"]}
        pw = med[f"particle_weights k={args.k} (blocked)"] / med["cKDTree total (numpy+scipy)"]
        step_k = med[f"step, heat map (k={args.k})"] / med[f"step, NumPy+cKDTree (k={args.k})"]
        step_d = (med[f"step, heat map (defaults k={DEFAULT_K}/{DEFAULT_K_MAX})"]
                  / med[f"step, NumPy+cKDTree (k={DEFAULT_K})"])
        print(f"{res['P']:>5} {res['M']:>5}  {res['threshold']:9.4f} {pw:12.2f} {step_k:17.2f} {step_d:10.2f} "
              f"{res['max_rel']:12.2e} {'yes' if res['ok'] else 'NO':>5}")
    print()
    print("ratios: median ours / median peer; < 1 means ours is faster. pw: the blocked kernel against")
    print("cKDTree total (build + query + sum). step: our jitted step with a heat map against the same step")
    print(f"in NumPy + cKDTree at the same k (k = {args.k}, and the defaults k = {DEFAULT_K}).")
    print(f"agree: every particle's weight within relative {RTOL:g} of the cKDTree weight.")
    return 0 if all(res["ok"] for res in results) else 1


if __name__ == "__main__":
    sys.exit(main())
