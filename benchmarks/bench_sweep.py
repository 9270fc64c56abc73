"""Sweep throughput and memory: 64 parameter sets of a 300-step sequence.

Compares, in the same run and on the same sequence, key and parameter sets:

* ``one at a time``: a Python loop of 64 jitted ``run`` calls (compiled once);
* ``sweep``: :func:`heatpf_jax.sweep.sweep` at several chunk sizes (one compilation each), with XLA's
  memory analysis of the compiled program (temporaries grow with the chunk, not the batch);
* the same sweep on 2 devices (``XLA_FLAGS=--xla_force_host_platform_device_count=2``, run in a
  subprocess because the device count is fixed when JAX starts).

Throughput is parameter-set steps per second (sets x steps / wall time), compile excluded (each path is
called once before timing). Run: ``python benchmarks/bench_sweep.py [--sets 64] [--steps 300]``.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax.sim import simulate
from heatpf_jax.sweep import sweep, sweep_memory


def _params(model: hp.Filter, n: int) -> hp.FilterParams:
    rng = np.random.default_rng(0)
    sets = [
        model.make_params(
            k=int(rng.integers(1, 11)),
            threshold=float(rng.uniform(0.2, 0.6)),
            aging=float(rng.uniform(0.0, 0.3)),
            diffusion_std=float(rng.uniform(0.1, 0.3)),
        )
        for _ in range(n)
    ]
    return hp.stack_params(sets)


def _timed(fn) -> float:
    fn()  # compile / warm
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def measure(sets: int, steps: int, chunks: list[int], loop: bool) -> dict:
    seq = simulate("standard", 0, num_steps=steps)
    model = hp.paper_filter(hp.FilterOptions(k_max=10))
    batch = _params(model, sets)
    key = jax.random.key(0)
    out = {"devices": len(jax.devices()), "rows": []}
    if loop:
        singles = [jax.tree.map(lambda v, i=i: v[i], batch) for i in range(sets)]

        def one_at_a_time():
            for p in singles:
                hp.run(key, seq, p, model).info.mean.block_until_ready()

        t = _timed(one_at_a_time)
        out["rows"].append({"what": "one at a time (loop of run)", "seconds": t, "temp_mb": None})
        ref = np.stack([np.asarray(hp.run(key, seq, p, model).info.mean) for p in singles[:4]])
        out["ref"] = ref.tolist()
    for chunk in chunks:
        t = _timed(lambda c=chunk: sweep(key, seq, batch, model, chunk=c).mean.block_until_ready())
        mem = sweep_memory(key, seq, batch, model, chunk=chunk)
        row = {"what": f"sweep, chunk {chunk}", "seconds": t, "temp_mb": mem.temp_bytes / 2**20}
        out["rows"].append(row)
    out["first4"] = np.asarray(sweep(key, seq, batch, model, chunk=chunks[0]).mean[:4]).tolist()
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sets", type=int, default=64)
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--chunks", default="1,8,32")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--no-loop", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    chunks = [int(c) for c in args.chunks.split(",")]
    if args.json:  # child process: one device configuration
        print(json.dumps(measure(args.sets, args.steps, chunks, loop=not args.no_loop)))
        return

    print(
        f"sweep benchmark: {args.sets} parameter sets x {args.steps} steps, 500 particles, 1024-slot buffer, "
        f"200x150 heat maps; jax {jax.__version__}, os.cpu_count() {os.cpu_count()}"
    )
    results = []
    for devices in (1, 2):
        env = dict(os.environ, XLA_FLAGS=f"--xla_force_host_platform_device_count={devices}")
        cmd = [
            sys.executable,
            __file__,
            "--json",
            "--sets",
            str(args.sets),
            "--steps",
            str(args.steps),
            "--chunks",
            args.chunks,
        ] + ([] if devices == 1 else ["--no-loop"])
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
        results.append(json.loads(proc.stdout.strip().splitlines()[-1]))
    base = results[0]["rows"][0]["seconds"]
    total = args.sets * args.steps
    print(f"{'devices':>7}  {'what':<28} {'seconds':>9} {'set-steps/s':>12} {'vs loop':>8} {'XLA temp MiB':>13}")
    for res in results:
        for row in res["rows"]:
            mem = "-" if row["temp_mb"] is None else f"{row['temp_mb']:.1f}"
            print(
                f"{res['devices']:>7}  {row['what']:<28} {row['seconds']:9.2f} {total / row['seconds']:12.0f} "
                f"{base / row['seconds']:8.2f} {mem:>13}"
            )
    ref = np.asarray(results[0]["ref"])
    for res in results:
        diff = np.abs(np.asarray(res["first4"]) - ref).max()
        print(f"max |sweep - single run| over the first 4 sets, {res['devices']} device(s): {diff:.2e} m")
    print("(batched and single programs differ in the last float32 bits; resampling amplifies that over 300 steps")
    print(" into Monte Carlo-sized differences. tests/test_sweep.py checks equality on short sequences.)")


if __name__ == "__main__":
    main()
