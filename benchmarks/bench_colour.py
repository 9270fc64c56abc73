"""Time of the colour likelihood (Olufs et al. eq. 1-3) of one 200 x 150 RGB frame, and of the image trackers'
steps, against the heat-map filter's step on the same frame's colour map.

The frame is a rendered `standard` frame (`simulate(..., rgb=True)`); default bins (12 x 12 x 4), the
window from the camera geometry (:func:`heatpf_jax.colour.likelihood.expected_radius_px`, computed once
per camera pose and included in ``colour map + window``), the reference's 64 heaviest bins. Every call is
timed with ``block_until_ready`` after compilation and warm-up; the table gives the median and the
interquartile range over ``--repeats`` calls (interleaved, so that a noisy machine slows all alike).

    python benchmarks/bench_colour.py [--repeats 100] [--threads 1]
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

import heatpf_jax as hp
from heatpf_jax import params as P
from heatpf_jax.baselines.colour_particles import ColourParticleTracker
from heatpf_jax.baselines.image_window import Window
from heatpf_jax.baselines.kalman_mean_shift import KalmanMeanShiftTracker
from heatpf_jax.baselines.mean_shift import MeanShiftTracker
from heatpf_jax.colour.likelihood import ColourParams, colour_likelihood, expected_radius_px
from heatpf_jax.colour.silhouette import chromaticity_probability, silhouette_prior
from heatpf_jax.colour.space import DEFAULT_BINS, exact_top_bins, patch_histogram, smooth_chromaticity, smooth_intensity
from heatpf_jax.sim.scenarios import simulate_with_info


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=positive_int, default=100)
    parser.add_argument("--threads", type=positive_int, default=None, help="1: one XLA thread (PJRT_NPROC=1)")
    args = parser.parse_args(argv)
    seq, info = simulate_with_info("standard", 0, num_steps=12, rgb=True)
    t = int(np.flatnonzero(info["visible"])[0])
    frame = jnp.asarray(seq.images[t])
    q = smooth_chromaticity(smooth_intensity(patch_histogram(seq.images[t], (90, 60, 9, 9))))
    pose = jnp.asarray(seq.cam_to_base[t], jnp.float32)
    intr = jnp.asarray(seq.intrinsics, jnp.float32)
    params = ColourParams(window_scale=0.9)
    shape = frame.shape[:2]
    radius = jax.jit(expected_radius_px, static_argnums=3)(intr, pose, 0.075, shape)
    likelihood = jax.jit(colour_likelihood)
    likelihood_k = jax.jit(colour_likelihood, static_argnames=("top_bins", "blob_window"))
    exact = exact_top_bins(q)  # what `heatpf colour` uses: the reference's non-empty bins, rounded up to 2^n
    # The ball's outline as heatpf colour adds it: its object probabilities against the frame's own colours.
    probability = chromaticity_probability(q, patch_histogram(seq.images[t]), silhouette_prior(), 3.0 * 81,
                                           DEFAULT_BINS)
    outlined = params._replace(silhouette_score=0.5)
    full = jax.jit(lambda f, p: colour_likelihood(f, q, expected_radius_px(intr, p, 0.075, shape), params))
    heat = likelihood(frame, q, radius, params)
    model, fparams = hp.build("heatmap")
    fparams = P.as_arrays(P.set_by_name(fparams, model.properties(), {"threshold": 0.1}), model.properties())
    inputs = hp.StepInputs(heatmap=heat, has_heatmap=jnp.asarray(True), cam_to_base=pose,
                           odometry=jnp.zeros((3,), jnp.float32), intrinsics=intr,
                           plane_height=jnp.float32(0.075), dt=jnp.float32(0.1))
    step = jax.jit(hp.Filter.step, static_argnums=0)
    state = model.init(jax.random.key(0), fparams)
    state, _ = step(model, jax.random.key(1), state, inputs, fparams)
    start_uv = jnp.asarray([94.0, 64.0], jnp.float32)
    calls = {
        "colour map (window given)": lambda k: likelihood(frame, q, radius, params),
        "colour map + window": lambda k: full(frame, pose),
        f"colour map, top_bins {exact} (exact)": lambda k: likelihood_k(frame, q, radius, params, top_bins=exact),
        f"  one pass, top_bins {exact}": lambda k: likelihood_k(frame, q, radius, params, top_bins=exact,
                                                               blob_window=False),
        f"  and the outline, top_bins {exact}": lambda k: likelihood_k(frame, q, radius, outlined, top_bins=exact,
                                                                      object_probability=probability),
        "heatmap step on the colour map": lambda k: step(model, k, state, inputs, fparams),
    }
    for name, tracker in (("mean shift step", MeanShiftTracker()), ("mean shift + KF step", KalmanMeanShiftTracker()),
                          ("MC tracker step (150)", ColourParticleTracker())):
        p = tracker.default_params()
        s0 = tracker.init(jax.random.key(0), Window(start_uv, jnp.full((2,), 4.0, jnp.float32), q), p)
        fn = jax.jit(lambda k, s, f, tr=tracker, p=p: tr.step(k, s, f, p))
        calls[name] = lambda k, fn=fn, s0=s0: fn(k, s0, frame)
    compile_s = {name: first_call(lambda c=call: c(jax.random.key(2))) for name, call in calls.items()}
    times = interleaved_times(calls, jax.random.key(3), args.repeats)
    print(f"jax {jax.__version__}, {jax.devices()[0].platform}, PJRT_NPROC={os.environ.get('PJRT_NPROC', '-')}; "
          f"{shape[1]} x {shape[0]} frame, {args.repeats} interleaved rounds")
    print(f"{'call':<34} {'median [ms]':>12} {'IQR [ms]':>9} {'compile [s]':>12}")
    for name in calls:
        med, iqr = stats_ms(np.asarray(times[name]))
        print(f"{name:<34} {med:12.3f} {iqr:9.3f} {compile_s[name]:12.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
