"""Known-answer check of the gradient estimators (issue 11): a 2-D random walk seen through one exact pixel.

For every estimator (stop-gradient resampling with score-form or pathwise motion gradients, soft resampling,
plain detach), the mean over seeds of the estimated gradient of the mean log-likelihood and of the mean
squared error with respect to ``(log q, log r)`` at ``theta0 = truth + (0.5, -0.5)`` is compared with the
exact gradient (``jax.grad`` through a float64 Kalman filter, :func:`heatpf_jax.sim.linear_gaussian.kalman_losses`).
A row passes when both components of both gradients are within 15 % relative and 4 standard errors.

    python benchmarks/gradients.py                     # the issue's size: 64 seeds, N = 1024, T = 300
    python benchmarks/gradients.py --seeds 16 --steps 50
"""

from __future__ import annotations

import argparse
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax import params as P
from heatpf_jax.rollout import prepare_run, run_core
from heatpf_jax.sim.linear_gaussian import kalman_losses, linear_gaussian_filter, simulate_linear_gaussian
from heatpf_jax.tuning import differentiable, mse_loss, nll_loss

Q, R = 0.4, 0.8
VARIANTS = {
    "stop_gradient + score (default)": {"resampling": "stop_gradient", "motion": "score"},
    "stop_gradient + pathwise": {"resampling": "stop_gradient", "motion": "pathwise"},
    "soft (alpha 0.5) + score": {"resampling": "soft", "motion": "score"},
    "detach + score (control)": {"resampling": "detach", "motion": "score"},
    "detach + pathwise (control)": {"resampling": "detach", "motion": "pathwise"},
}


def exact_gradients(seq, theta, burn_in):
    z = np.asarray(seq.cam_to_base[:, :2, 3], np.float64)
    truth = np.asarray(seq.ground_truth, np.float64)
    with jax.enable_x64(True):
        th = jnp.asarray(theta, jnp.float64)
        g_ll = jax.grad(lambda t: kalman_losses(t, z, truth, burn_in)[0])(th)
        g_mse = jax.grad(lambda t: kalman_losses(t, z, truth, burn_in)[1])(th)
        return np.asarray(g_ll), np.asarray(g_mse)


@functools.partial(jax.jit, static_argnames=("model", "burn_in"))
def estimated_gradients(keys, seq, truth, params, theta, model, burn_in):
    """Per key: gradients of (mean log-likelihood, mse) with respect to (log q, log r)."""
    props = model.properties()

    def losses(th, key):
        p = P.set_by_name(params, props, {"diffusion_std": jnp.exp(th[0]), "obs_std": jnp.exp(th[1])})
        info = run_core(key, seq, p, model).info
        return -nll_loss(info, None, burn_in), mse_loss(info, truth, burn_in)

    def one(key):
        return jax.jacrev(losses)(theta, key)

    return jax.vmap(one)(keys)


def check(est, exact, rel=0.15, num_se=4.0):
    mean = est.mean(0)
    se = est.std(0, ddof=1) / np.sqrt(est.shape[0])
    err = np.abs(mean - exact)
    ok = (err <= rel * np.abs(exact)) & (err <= num_se * se)
    return mean, se, ok


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=64)
    ap.add_argument("--particles", type=int, default=1024)
    ap.add_argument("--steps", type=int, default=300)
    ap.add_argument("--burn-in", type=int, default=10)
    ap.add_argument("--data-seed", type=int, default=0)
    ap.add_argument("--variant", action="append", choices=list(VARIANTS))
    ap.add_argument("--resample-threshold", type=float, default=0.5, help="ESS share that triggers resampling")
    args = ap.parse_args(argv)
    seq = simulate_linear_gaussian(args.data_seed, args.steps, Q, R)
    theta = np.log([Q, R]) + np.array([0.5, -0.5])
    g_ll, g_mse = exact_gradients(seq, theta, args.burn_in)
    base, params = linear_gaussian_filter(args.particles)
    params = base.make_params({**dict(zip(P.leaf_names(base.properties()), jax.tree.leaves(params), strict=True)),
                               "resample_threshold": args.resample_threshold})
    print(f"known answer: N={args.particles}, T={args.steps}, {args.seeds} seeds, theta0 = log(q, r) + (0.5, -0.5)")
    print(f"exact d mean-ll / d(log q, log r) = ({g_ll[0]:+.5f}, {g_ll[1]:+.5f}); "
          f"d mse = ({g_mse[0]:+.5f}, {g_mse[1]:+.5f})")
    print(f"{'estimator':34s} {'d ll/d log q':>22s} {'d ll/d log r':>22s} {'d mse/d log q':>22s} "
          f"{'d mse/d log r':>22s}  pass  seconds")
    keys = jax.random.split(jax.random.key(1), args.seeds)
    for name in args.variant or list(VARIANTS):
        model = differentiable(base, **VARIANTS[name])
        s, p = prepare_run(seq, params, model)
        truth = jnp.asarray(seq.ground_truth, jnp.float32)
        t0 = time.perf_counter()
        grads = estimated_gradients(keys, s, truth, p, jnp.asarray(theta, jnp.float32), model, args.burn_in)
        grads = jax.tree.map(lambda x: np.asarray(x, np.float64), grads)
        seconds = time.perf_counter() - t0
        cells, passed = [], True
        for est, exact in ((grads[0], g_ll), (grads[1], g_mse)):
            mean, se, ok = check(est, exact)
            passed &= bool(ok.all())
            cells += [f"{m:+.5f}±{e:.5f}({(m / x - 1):+.0%})" for m, e, x in zip(mean, se, exact, strict=True)]
            if not np.all(np.isfinite(est)):
                passed = False
        sd = np.concatenate([grads[0].std(0), grads[1].std(0)])
        print(f"{name:34s} " + " ".join(f"{c:>22s}" for c in cells) + f"  {'yes' if passed else 'NO':4s}  {seconds:.1f}"
              f"   (per-seed sd: {', '.join(f'{x:.4f}' for x in sd)})")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
