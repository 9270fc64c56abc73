"""Memory of a gradient through a whole run (issue 11): with and without ``jax.checkpoint`` around the step.

XLA's compiled memory analysis of ``jax.value_and_grad`` of the MSE loss of one 300-step run of the heatmap
method (500 particles, 1024 measurements, 150 x 200 heat maps) with respect to its trainable parameters:
temporary buffers (the peak working set beyond arguments and outputs) and argument sizes.

    python benchmarks/tune_memory.py [--steps 300] [--particles 500]
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.rollout import prepare_run, run_core
from heatpf_jax.sim import simulate


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--particles", type=int, default=500)
    ap.add_argument("--measurements", type=int, default=1024)
    args = ap.parse_args(argv)
    options = hp.FilterOptions(num_particles=args.particles, max_measurements=args.measurements)
    base, params = hp.build("heatmap", options)
    seq = simulate("walking", 0, num_steps=args.steps)
    truth = jnp.asarray(seq.ground_truth, jnp.float32)
    print(f"gradient of one run: {args.steps} steps, {args.particles} particles, {args.measurements} measurements, "
          f"heat maps {seq.heatmaps.shape[1:]}")
    print(f"{'variant':34s} {'temp MiB':>10s} {'args MiB':>10s} {'out MiB':>9s} {'compile s':>10s} {'run s':>7s}")
    for name, checkpoint in (("checkpointed step (tune's default)", True), ("no checkpoint", False)):
        model = hp.differentiable(base, checkpoint=checkpoint)
        s, p = prepare_run(seq, params, model)
        props = model.properties()
        trainable, frozen = P.partition(p, props)

        def loss(u, key, s=s, model=model, frozen=frozen, props=props):
            pp = P.combine(P.from_unconstrained(u, props), frozen)
            return hp.mse_loss(run_core(key, s, pp, model).info, truth, 10)

        u = P.to_unconstrained(trainable, props)
        t0 = time.perf_counter()
        compiled = jax.jit(jax.value_and_grad(loss)).lower(u, jax.random.key(0)).compile()
        compile_s = time.perf_counter() - t0
        mem = compiled.memory_analysis()
        t0 = time.perf_counter()
        jax.block_until_ready(compiled(u, jax.random.key(1)))
        run_s = time.perf_counter() - t0
        mib = 1 / 2**20
        print(f"{name:34s} {mem.temp_size_in_bytes * mib:10.1f} {mem.argument_size_in_bytes * mib:10.1f} "
              f"{mem.output_size_in_bytes * mib:9.3f} {compile_s:10.1f} {run_s:7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
