"""Per-tick cost of :class:`heatpf_jax.Tracker` next to the bare jitted ``model.step``, at the defaults.

The default model (``heatpf_jax.heatmap_filter()``: 500 particles, 1024 measurements) and its default
params, on the simulated ``standard`` scenario (200 x 150 heat maps, a heat map every step). Rows:

* ``jit(model.step), device inputs``: the bare step, ``StepInputs`` already on the device, keys split
  beforehand, the state carried: the floor a loop around ``model.step`` can reach;
* ``jit(model.step), NumPy heat map``: the same with the heat map handed over from the host each call;
* ``Tracker.update, NumPy heat map``: what a robot's loop calls (NumPy heat map, pose and odometry);
* ``Tracker.update, device heat map``: the same with the heat map already on the device;
* ``Tracker.update(None)``: a tick without a heat map (the buffer ages);
* ``Tracker.update returns``: the time until ``update`` returns, before the step has finished
  (JAX dispatches asynchronously; reading the estimate waits).

Every row is ``time.perf_counter`` around one call and ``jax.block_until_ready`` of its result (the
estimate, or the bare step's state and info), after ``--warmup`` untimed calls; the table gives the
median and the interquartile range over ``--repeats`` calls (default 300), each call on the next step of
the sequence. The machine's load average is printed before and after: on a shared machine, compare runs
only at similar load.

Run it from the repository root::

    .venv/bin/python benchmarks/bench_tracker.py [--repeats 300] [--warmup 10] [--label TEXT]
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from collections.abc import Callable

import jax
import jax.numpy as jnp
import numpy as np
from _timing import positive_int, stats_ms  # sibling module: run the script by path

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.sim import simulate


def time_calls(call: Callable[[int], object], warmup: int, repeats: int, *, wait_inside: bool = True) -> np.ndarray:
    """Seconds per ``call(i)``; ``wait_inside=False`` stops the clock when the call returns, then waits."""
    for i in range(warmup):
        jax.block_until_ready(call(i))
    times = np.empty(repeats)
    for j in range(repeats):
        t0 = time.perf_counter()
        out = call(warmup + j)
        if wait_inside:
            jax.block_until_ready(out)
            times[j] = time.perf_counter() - t0
        else:
            times[j] = time.perf_counter() - t0
            jax.block_until_ready(out)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=positive_int, default=300, help="timed calls per row (default 300)")
    parser.add_argument("--warmup", type=positive_int, default=10, help="untimed calls per row (default 10)")
    parser.add_argument("--label", default="", metavar="TEXT", help="printed in the header (default none)")
    args = parser.parse_args(argv)

    n = args.warmup + args.repeats
    seq = simulate("standard", 0, num_steps=n)
    model = hp.paper_filter()
    params_py = model.default_params()
    dev = jax.devices()[0]
    load_before = os.getloadavg()
    print("heatpf_jax benchmark: Tracker.update against the bare jitted model.step")
    print(f"label: {args.label or '-'}")
    print(f"python {platform.python_version()}  jax {jax.__version__}  numpy {np.__version__}  "
          f"heatpf_jax {hp.__version__}")
    print(f"device: {dev.platform} / {dev.device_kind}  os.cpu_count(): {os.cpu_count()}  "
          f"load average (1, 5, 15 min) before: {', '.join(f'{x:.2f}' for x in load_before)}")
    print(f"model: heatmap_filter() defaults, {model.num_particles} particles, {model.source.size} measurements; "
          f"heat map {seq.heatmaps.shape[2]}x{seq.heatmaps.shape[1]} ('standard', seed 0)")
    print(f"repeats = {args.repeats} (+{args.warmup} warm-up); times in ms: median, IQR (q3 - q1)")
    print()

    heat_np = [np.ascontiguousarray(h) for h in seq.heatmaps]
    cams = [np.asarray(c, np.float32) for c in seq.cam_to_base]
    odos = [np.asarray(o, np.float32) for o in seq.odometry]
    key = jax.random.key(0)

    # Tracker: construction compiles and warms up.
    t0 = time.perf_counter()
    tracker = hp.Tracker(key, model, params_py, heatmap_shape=seq.heatmaps.shape[1:], intrinsics=seq.intrinsics,
                         plane_height=seq.ball_radius, dt=seq.dt)
    t_build = time.perf_counter() - t0

    # The bare step: everything prepared beforehand.
    params = P.as_arrays(params_py, model.properties())
    k_init, k_steps = jax.random.split(key)
    keys = jax.random.split(k_steps, n)
    step = jax.jit(model.step)
    const = {
        "intrinsics": jnp.asarray(seq.intrinsics, jnp.float32),
        "plane_height": jnp.asarray(seq.ball_radius, jnp.float32),
        "dt": jnp.asarray(seq.dt, jnp.float32),
    }
    has = jnp.asarray(True)

    def inputs(t: int, heatmap) -> hp.StepInputs:
        return hp.StepInputs(heatmap=heatmap, has_heatmap=has, cam_to_base=jnp.asarray(cams[t]),
                             odometry=jnp.asarray(odos[t] if t else np.zeros(3, np.float32)), **const)

    on_device = [inputs(t, jnp.asarray(heat_np[t])) for t in range(n)]
    from_host = [inputs(t, heat_np[t]) for t in range(n)]
    keys_list = list(keys)
    heat_dev = [x.heatmap for x in on_device]
    jax.block_until_ready((on_device, keys_list))

    def bare(batch):
        state = [model.init(k_init, params)]

        def call(i: int):
            state[0], info = step(keys_list[i], state[0], batch[i], params)
            return state[0], info

        return call

    t0 = time.perf_counter()
    jax.block_until_ready(step(keys_list[0], model.init(k_init, params), on_device[0], params))
    t_compile_bare = time.perf_counter() - t0

    def tracked(heats):
        tracker.reset(key)
        return lambda i: tracker.update(heats[i] if heats is not None else None, cams[i], odos[i])

    rows = [
        ("jit(model.step), device inputs", time_calls(bare(on_device), args.warmup, args.repeats)),
        ("jit(model.step), NumPy heat map", time_calls(bare(from_host), args.warmup, args.repeats)),
        ("Tracker.update, NumPy heat map", time_calls(tracked(heat_np), args.warmup, args.repeats)),
        ("Tracker.update, device heat map", time_calls(tracked(heat_dev), args.warmup, args.repeats)),
        ("Tracker.update(None)", time_calls(tracked(None), args.warmup, args.repeats)),
        ("Tracker.update returns (NumPy, no wait)",
         time_calls(tracked(heat_np), args.warmup, args.repeats, wait_inside=False)),
    ]
    floor = stats_ms(rows[0][1])[0]

    header = f"{'what':<42} {'median ms':>10} {'IQR ms':>9} {'/ bare step':>11}"
    header += f"  [{args.label}]" if args.label else ""
    print(header)
    print("-" * len(header))
    for name, times in rows:
        med, iqr = stats_ms(times)
        print(f"{name:<42} {med:10.3f} {iqr:9.3f} {med / floor:11.2f}")
    print()
    print(f"Tracker construction (compile + 2 warm-up ticks): {t_build:.2f} s; bare step first call: "
          f"{t_compile_bare:.2f} s")
    print(f"load average (1, 5, 15 min) after: {', '.join(f'{x:.2f}' for x in os.getloadavg())}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
