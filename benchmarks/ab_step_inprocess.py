"""A method's step on an earlier commit against the working tree's, interleaved call by call in one process.

    python benchmarks/ab_step_inprocess.py --base ef322f8 [--methods heatmap,paper] [--repeats 200] [--threads 1]

``ab_commits.py`` runs each commit's ``bench_step.py`` in its own process, alternately; on a shared machine the load
moves between the processes by 20-30 %. Here the base commit's package is checked out into a temporary git worktree,
copied under another name (``heatpf_base``, its own imports renamed) and imported beside the working tree's
``heatpf_jax``, so that both steps run in one process, one call of each per round. Each method is built with
``FilterOptions(num_particles, max_measurements)`` and stepped with ``Filter.step`` under ``jax.jit`` on
``bench_step``'s 200 x 150 heat map (the threshold that gives ``max_measurements`` pixels), from the state after one
step (a full buffer). The base commit must have the same entry points (``build``, ``FilterOptions``, ``StepInputs``,
``Filter.step``, ``params.set_by_name`` / ``as_arrays``; ef322f8, the commit the world-family issue was filed
against, has them). The table gives each step's median and interquartile range per call and its ratio to the base's
step of the same method. ``--extra heatmap:source=pixels`` adds the working tree's variants (``FilterOptions``
fields).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

if __name__ == "__main__" and "--threads" in sys.argv[1:-1] and sys.argv[sys.argv.index("--threads") + 1] == "1":
    os.environ["PJRT_NPROC"] = "1"

import numpy as np
from _timing import interleaved_times, positive_int, stats_ms

ROOT = Path(__file__).resolve().parent.parent
BASE_NAME = "heatpf_base"


def _base_package(commit: str, dest: Path) -> None:
    """``commit``'s ``heatpf_jax`` as ``dest / heatpf_base``, every ``heatpf_jax`` in its sources renamed."""
    tree = dest / "tree"
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", "-f", str(tree), commit], check=True,
                   capture_output=True)
    try:
        shutil.copytree(tree / "heatpf_jax", dest / BASE_NAME)
    finally:
        subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=True,
                       capture_output=True)
    for path in (dest / BASE_NAME).rglob("*.py"):
        path.write_text(path.read_text().replace("heatpf_jax", BASE_NAME))


def _stepper(lib, method: str, options: dict, heatmap, threshold: float):
    import jax
    import jax.numpy as jnp
    from bench_step import CAMERA, INTRINSICS, PLANE_HEIGHT

    inputs = lib.StepInputs(
        heatmap=jnp.asarray(heatmap), has_heatmap=jnp.asarray(True),
        cam_to_base=jnp.asarray(lib.camera.camera_pose(**CAMERA), jnp.float32),
        odometry=jnp.zeros((3,), jnp.float32), intrinsics=jnp.asarray(INTRINSICS, jnp.float32),
        plane_height=jnp.asarray(PLANE_HEIGHT, jnp.float32), dt=jnp.asarray(0.1, jnp.float32),
    )
    model, params = lib.build(method, lib.FilterOptions(**options))
    props = model.properties()
    params = lib.params.as_arrays(lib.params.set_by_name(params, props, {"threshold": threshold}), props)
    step = jax.jit(lib.Filter.step, static_argnums=0)
    k0, k1 = jax.random.split(jax.random.key(0))
    state, _ = step(model, k1, model.init(k0, params), inputs, params)  # a full buffer
    jax.block_until_ready(step(model, k1, state, inputs, params))  # compiled
    return lambda key: step(model, key, state, inputs, params)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--base", required=True, help="the earlier commit")
    parser.add_argument("--methods", default="heatmap,paper", help="methods run on both (default heatmap,paper)")
    parser.add_argument("--extra", default="", help="the working tree's variants, METHOD:FIELD=VALUE[+...], "
                        "comma-separated (e.g. heatmap:source=pixels)")
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--measurements", type=int, default=1024)
    parser.add_argument("--repeats", type=positive_int, default=200, help="interleaved rounds (default 200)")
    parser.add_argument("--threads", type=positive_int, default=None, help="1: one XLA thread (PJRT_NPROC=1)")
    args = parser.parse_args(argv)
    known = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{args.base}^{{commit}}"],
                           capture_output=True)
    if known.returncode != 0:
        parser.error(f"--base: {args.base!r} is no commit of this repository")
    import jax
    from bench_step import make_heatmap, pick_threshold

    import heatpf_jax as head

    heatmap = make_heatmap()
    threshold = pick_threshold(heatmap, args.measurements, 0.1)
    options = {"num_particles": args.particles, "max_measurements": args.measurements}
    with tempfile.TemporaryDirectory() as tmp:
        _base_package(args.base, Path(tmp))
        sys.path.insert(0, tmp)
        base = __import__(BASE_NAME)
        runs = {}
        for method in args.methods.split(","):
            runs[f"{method} @ {args.base}"] = _stepper(base, method, options, heatmap, threshold)
            runs[f"{method} @ working tree"] = _stepper(head, method, options, heatmap, threshold)
        for spec in filter(None, args.extra.split(",")):
            method, _, fields = spec.partition(":")
            extra = dict(item.split("=", 1) for item in fields.split("+")) if fields else {}
            runs[f"{spec} @ working tree"] = _stepper(head, method, {**options, **extra}, heatmap, threshold)
        times = interleaved_times(runs, jax.random.key(1), args.repeats, warmup=5)
    print(f"jax {jax.__version__}, PJRT_NPROC={os.environ.get('PJRT_NPROC', '-')}; {args.particles} particles x "
          f"{args.measurements} measurements; {args.repeats} interleaved rounds")
    print(f"{'step':<44} {'median [ms]':>12} {'IQR [ms]':>9} {'/ base':>7}")
    for name, t in times.items():
        med, iqr = stats_ms(t)
        base_t = times.get(f"{name.split(':')[0].split(' @ ')[0]} @ {args.base}")
        ratio = np.median(t) / np.median(base_t) if base_t is not None else float("nan")
        print(f"{name:<44} {med:12.3f} {iqr:9.3f} {ratio:7.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
