"""Step time of the methods with a velocity state and cluster-wise (mean-shift) resampling against the
paper's plain step, in the same run (issue 10's speed check).

Every method's ``Filter.step`` under ``jax.jit`` (the model static) at (P particles, M measurements),
on ``bench_step``'s 200 x 150 heat map whose blob gives more than M pixels above the threshold, from a
state whose buffer is already full. The methods' calls are interleaved round by round (one call of
each per round, ``--repeats`` rounds) so that a noisy machine slows them alike; the table gives the
median and interquartile range per call and the ratio of medians to ``paper``:

* ``paper``: the 2019 filter (static position, eq. 1, systematic resampling, explorers);
* ``paper + velocity``: the same with the constant-velocity motion model;
* ``velocity + mean-shift resampling``: that with :class:`heatpf_jax.resampling.ClusterResampling`;
* ``heatmap``: the product's defaults (velocity, range-aware template over k = 10, the lofted source with its
  blob scale learned);
* ``heatmap (pixel source)``: the same with the paper's source, every pixel where it projects (``--set
  source=pixels``, the ``heatmap`` before the lofted source);
* ``heatmap (centroid source)``: the same with every pixel at its blob's centroid (``--set source=centroids``);
* ``heatmap (fixed share)``: the defaults with :class:`heatpf_jax.injection.MeasurementExplorers` (``--set
  resetting=fixed``) instead of the re-acquisition seeds (:class:`heatpf_jax.injection.ReacquisitionSeeds`, the
  default since they were measured here as ``heatmap (re-acquisition seeds)``);
* ``extended``: Olufs et al.'s combination (mass inertia, cluster-wise resampling, random and
  measurement particles, the dominant mode as output);
* ``paper / heatmap / extended + memory``: each with the long-term memory (``--set memory=tracks``:
  16 track slots, re-detection, hint particles and re-detection seeds; issue 12's speed check), and
  ``heatmap + memory, 8 slots`` and ``4 slots``: the memory's earlier capacities.

Run: ``.venv/bin/python benchmarks/bench_extended.py [--sizes 500x1024] [--repeats 200] [--threads 1]``
"""

from __future__ import annotations

import argparse
import os
import sys

if __name__ == "__main__" and "--threads" in sys.argv[1:-1] and sys.argv[sys.argv.index("--threads") + 1] == "1":
    os.environ["PJRT_NPROC"] = "1"


import jax
import jax.numpy as jnp
import numpy as np
from _timing import first_call, interleaved_times, positive_int, stats_ms
from bench_step import CAMERA, INTRINSICS, PLANE_HEIGHT, make_heatmap, parse_sizes, pick_threshold

import heatpf_jax as hp
from heatpf_jax import params as P


def models(options: hp.FilterOptions) -> dict[str, tuple[hp.Filter, hp.FilterParams]]:
    paper, paper_params = hp.build("paper", options)
    velocity = paper._replace(motion=hp.motion.ConstantVelocity())
    clustered = velocity._replace(resampling=hp.resampling.ClusterResampling())
    out = {
        "paper": (paper, paper_params),
        "paper + velocity": (velocity, velocity.default_params()),
        "velocity + mean-shift resampling": (clustered, clustered.default_params()),
    }
    for name in ("heatmap", "extended"):
        out[name] = tuple(hp.build(name, options))
    # heatmap with every pixel at its blob's centroid (--set source=centroids).
    out["heatmap (centroid source)"] = tuple(hp.build("heatmap", options._replace(source="centroids")))
    out["heatmap (pixel source)"] = tuple(hp.build("heatmap", options._replace(source="pixels")))
    out["heatmap (fixed share)"] = tuple(hp.build("heatmap", options._replace(resetting="fixed")))
    with_memory = options._replace(memory="tracks")
    for name in ("paper", "heatmap", "extended"):
        out[f"{name} + memory"] = tuple(hp.build(name, with_memory))
    # The memory's earlier capacities, for their cost in the same run.
    for slots in (8, 4):
        out[f"heatmap + memory, {slots} slots"] = tuple(hp.build("heatmap", with_memory._replace(max_tracks=slots)))
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=parse_sizes, default=parse_sizes("500x1024"))
    parser.add_argument("--repeats", type=positive_int, default=200)
    parser.add_argument("--threads", type=positive_int, default=None, help="1: one XLA thread (PJRT_NPROC=1)")
    args = parser.parse_args(argv)
    heatmap = make_heatmap()
    inputs = hp.StepInputs(
        heatmap=jnp.asarray(heatmap),
        has_heatmap=jnp.asarray(True),
        cam_to_base=jnp.asarray(hp.camera.camera_pose(**CAMERA), jnp.float32),
        odometry=jnp.zeros((3,), jnp.float32),
        intrinsics=jnp.asarray(INTRINSICS, jnp.float32),
        plane_height=jnp.asarray(PLANE_HEIGHT, jnp.float32),
        dt=jnp.asarray(0.1, jnp.float32),
    )
    step = jax.jit(hp.Filter.step, static_argnums=0)
    print(
        f"jax {jax.__version__}, {jax.devices()[0].platform}, PJRT_NPROC={os.environ.get('PJRT_NPROC', '-')}; "
        f"{args.repeats} interleaved rounds"
    )
    for num_particles, max_measurements in args.sizes:
        options = hp.FilterOptions(num_particles=num_particles, max_measurements=max_measurements)
        prepared = {}
        for name, (model, params) in models(options).items():
            threshold = pick_threshold(heatmap, max_measurements, 0.1)
            params = P.as_arrays(
                P.set_by_name(params, model.properties(), {"threshold": threshold}), model.properties()
            )
            k0, k1 = jax.random.split(jax.random.key(0))
            state = model.init(k0, params)
            compile_s = first_call(lambda m=model, s=state, p=params: step(m, k1, s, inputs, p))
            state, info = step(model, k1, state, inputs, params)  # a full buffer
            prepared[name] = (model, params, state, compile_s, int(info.num_valid))
        calls = {name: (lambda k, m=model, p=params, s=state: step(m, k, s, inputs, p))
                 for name, (model, params, state, _, _) in prepared.items()}
        times = interleaved_times(calls, jax.random.key(1), args.repeats)
        base = np.median(times["paper"])
        print(f"\n{num_particles} particles x {max_measurements} measurements")
        print(f"{'step':<36} {'median [ms]':>12} {'IQR [ms]':>9} {'/ paper':>8} {'compile [s]':>12} {'valid':>6}")
        for name, (_, _, _, compile_s, valid) in prepared.items():
            med, iqr = stats_ms(np.asarray(times[name]))
            ratio = np.median(times[name]) / base
            print(f"{name:<36} {med:12.3f} {iqr:9.3f} {ratio:8.2f} {compile_s:12.2f} {valid:6d}")


if __name__ == "__main__":
    main()
