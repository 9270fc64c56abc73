"""The known-answer problem of gradient tuning: a 2-D random walk seen through one exact ground pixel.

The ball does a Gaussian random walk (std ``q`` per step and axis, from the origin); each step's heat map is a
3 x 3 image whose centre pixel alone is lit, seen by a camera 1 m above the noisy measurement
``z_t = x_t + r * N(0, I)`` looking straight down, so the pixel projects exactly onto ``z_t``. A particle
filter with the random-walk motion (diffusion ``q``, no odometry) and the Gaussian observation density on
the single measurement (:class:`~heatpf_jax.observation.kernels.GaussianDensity`, ``k = 1``) is then a bootstrap
filter of a linear-Gaussian model whose exact answers come from a Kalman filter:
:func:`kalman_losses` gives the log-likelihood and the squared error of the posterior mean as functions of
``(log q, log r)``, so ``jax.grad`` of it in float64 is the exact gradient that
:func:`heatpf_jax.tuning.tune`'s estimators must match.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.io.sequence import Sequence, validate_sequence

__all__ = ["kalman_losses", "linear_gaussian_filter", "simulate_linear_gaussian"]


def simulate_linear_gaussian(seed: int, num_steps: int, q: float, r: float) -> Sequence:
    """The random walk and its measurements as a validated sequence (``ground_truth``: the walk).

    The measurement ``z_t`` is the sequence's only lit pixel's ground point (``Sequence.cam_to_base``
    holds it in its translation).
    """
    gen = np.random.default_rng(seed)
    truth = np.cumsum(q * gen.standard_normal((num_steps, 2)), axis=0)
    z = truth + r * gen.standard_normal((num_steps, 2))
    heat = np.zeros((num_steps, 3, 3), np.float32)
    heat[:, 1, 1] = 1.0
    poses = np.stack([camera_pose(height=1.0, pitch=np.pi / 2, x=zt[0], y=zt[1]) for zt in z])
    return validate_sequence(
        Sequence(
            heatmaps=heat,
            has_heatmap=np.ones(num_steps, bool),
            intrinsics=np.array([1.0, 1.0, 1.0, 1.0]),
            cam_to_base=poses,
            odometry=np.zeros((num_steps, 3)),
            ball_radius=np.asarray(0.0),
            dt=np.asarray(0.1),
            ground_truth=truth,
        )
    )


def linear_gaussian_filter(num_particles: int = 1024, spawn_half_width: float = 4.0):
    """The bootstrap particle filter of the problem and its params at ``(q, r) = (0.4, 0.8)``.

    Random walk (diffusion ``q``), one measurement (threshold 0.5, no distance limit: the walk wanders
    far from the origin, no aging), the Gaussian observation density with ``k = 1``, the weighted mean as
    output, systematic resampling when the ESS falls below N / 2 (resampling at every step coalesces the
    genealogy sooner and biases the path-space gradient of the estimate: ``benchmarks/gradients.py``), no
    explorers; the initial particles are uniform over ``[-w, w]^2`` around the walk's start.

    Returns:
        ``(filter, params)``.
    """
    from heatpf_jax.presets import FilterOptions, paper_filter

    w = float(spawn_half_width)
    model = paper_filter(
        FilterOptions(num_particles=num_particles, max_measurements=16, k_max=1, observation="gaussian_density",
                      spawn_box=(-w, w, -w, w))
    )
    params = model.make_params(
        k=1, threshold=0.5, max_distance=float("inf"), obs_std=0.8, resample_threshold=0.5, diffusion_std=0.4,
        explorer_fraction=0.0, top_fraction=1.0, aging=0.0, odom_trans_noise=0.0, odom_rot_noise=0.0,
    )
    return model, params


def kalman_losses(log_qr, z, truth, burn_in: int = 10, prior_var: float = 1e6):
    """Exact ``(mean log-likelihood, mean squared error)`` of the problem, differentiable in ``log_qr``.

    Per axis a scalar Kalman filter (the model is isotropic): predict ``P += q^2``, update with ``r^2``.

    Args:
        log_qr: ``[2]`` ``(log q, log r)``.
        z: ``[T, 2]`` measurements.
        truth: ``[T, 2]`` the walk.
        burn_in: steps left out of both losses (the first step's increment depends on the prior).
        prior_var: the initial variance (diffuse).

    Returns:
        ``(ll, mse)``: the mean over steps ``t >= burn_in`` of the log-likelihood increment
        ``log N(z_t; m_{t|t-1}, (P_{t|t-1} + r^2) I)`` and of ``|m_t - x_t|^2``.
    """
    q2, r2 = jnp.exp(2.0 * log_qr[0]), jnp.exp(2.0 * log_qr[1])
    z = jnp.asarray(z, log_qr.dtype)

    def body(carry, zt):
        m, p = carry
        p = p + q2
        s = p + r2
        innovation = zt - m
        ll = -jnp.log(2.0 * jnp.pi * s) - 0.5 * jnp.sum(innovation**2) / s
        gain = p / s
        m = m + gain * innovation
        return (m, (1.0 - gain) * p), (m, ll)

    init = (jnp.zeros(2, log_qr.dtype), jnp.asarray(prior_var, log_qr.dtype))
    _, (means, lls) = jax.lax.scan(body, init, z)
    err = means - jnp.asarray(truth, log_qr.dtype)
    return jnp.mean(lls[burn_in:]), jnp.mean(jnp.sum(err**2, axis=-1)[burn_in:])
