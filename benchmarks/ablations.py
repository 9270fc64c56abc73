"""Mean error of filters composed from pieces, per scenario: the figures behind the heatmap and extended
defaults and the issue-10 ablations (one change at a time).

A variant is a spec string: a method name (``heatmap``, ``paper``, ``extended``, ``bitbots2018``,
``kalman``) optionally followed by ``;name=value`` settings, or the paper's filter with pieces replaced::

    motion=rw|cv|mi            RandomWalk (the paper's), ConstantVelocity, MassInertia
    obs=id|g|range             eq. (1), GaussianKernel (k_max 10), FootprintTemplate (range-aware)
    meas=1                     add explorers drawn at the measurements
    NAME=VALUE                 any parameter by name (k=10, obs_std=0.05, accel_std=5, aging=0.6, ...)

Run: ``python benchmarks/ablations.py --seeds 0:5 --scenarios far,standard "motion=rw" "motion=cv;obs=range" heatmap``
(the issue-10 note's commands). Errors are the mean over seeds of the error after step 10, with keys
``fold_in(key(0), i)`` as ``heatpf eval``; ``two_balls`` errors are to ball A only here (``heatpf eval``
takes the nearer ball).
"""

from __future__ import annotations

import argparse
import sys
import time

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.evaluate import _stack
from heatpf_jax.sim import SCENARIOS, simulate

MOTIONS = {"rw": hp.motion.RandomWalk, "cv": hp.motion.ConstantVelocity, "mi": hp.motion.MassInertia}
OBSERVATIONS = {"id": None, "g": hp.observation.GaussianKernel, "range": hp.observation.FootprintTemplate}


def build(spec: str):
    head, _, rest = spec.partition(";")
    if head in ("heatmap", "paper", "extended", "bitbots2018", "kalman"):
        model, params = hp.build(head)
        settings = dict(x.split("=", 1) for x in rest.split(";") if x)
    else:
        settings = dict(x.split("=", 1) for x in spec.split(";") if x)
        model = hp.paper_filter()._replace(motion=MOTIONS[settings.pop("motion", "rw")]())
        obs = OBSERVATIONS[settings.pop("obs", "id")]
        if obs is not None:
            model = model._replace(observation=obs(k_max=10))
        if settings.pop("meas", None):
            model = model._replace(injectors=(*model.injectors, hp.injection.MeasurementExplorers()))
        params = model.default_params()
    return model, P.set_by_name(params, model.properties(), {k: float(v) for k, v in settings.items()})


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="100:104", help="START:STOP (default 100:104, the tuning seeds)")
    parser.add_argument("--scenarios", default="all", help="comma-separated names, or all")
    parser.add_argument("variants", nargs="+")
    args = parser.parse_args(argv)
    start, stop = (int(v) for v in args.seeds.split(":"))
    names = list(SCENARIOS) if args.scenarios == "all" else args.scenarios.split(",")
    table: dict[str, dict[str, float]] = {}
    for scenario in names:
        seqs = [simulate(scenario, s) for s in range(start, stop)]
        batch = _stack(seqs)
        truth = np.asarray(batch.ground_truth)
        batch = batch._replace(ground_truth=None)
        keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(0), i))(np.arange(len(seqs)))
        for spec in args.variants:
            model, params = build(spec)
            t0 = time.perf_counter()
            est = np.asarray(jax.vmap(lambda k, s, m=model, p=params: hp.run(k, s, p, m).info.mean)(keys, batch))
            err = np.linalg.norm(est - truth, axis=-1)[:, 10:].mean()
            table.setdefault(spec, {})[scenario] = err
            print(f"  {scenario} {spec}: {err:.4f} ({time.perf_counter() - t0:.1f} s)", file=sys.stderr, flush=True)
    print(f"seeds {start}-{stop - 1}: mean error after step 10 [m]")
    print(f"{'variant':<50}" + "".join(f"{s[:11]:>12}" for s in names))
    for spec, row in table.items():
        print(f"{spec:<50}" + "".join(f"{row[s]:12.4f}" for s in names))


if __name__ == "__main__":
    main()
