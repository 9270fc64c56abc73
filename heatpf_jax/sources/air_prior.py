"""How far up a blob's ball is, given its size: the posterior mean under a prior that balls mostly roll.

:class:`~heatpf_jax.sources.lofted.LoftedSource` reads a blob's size as ``m = log(rho / rho_g)``, the log ratio of its
apparent radius to a ground ball's at the point where its ray meets the ground. The ball's true ratio ``x = log q``
is 0 on the ground and positive in the air (``q = d_g / d``, the ground point's optical depth over the ball's); the
measured one is ``m = x + e``, ``e ~ N(0, sigma^2)``, ``sigma`` the spread of ground balls' sizes that the source
learns from the heat maps (:func:`~heatpf_jax.sources.blob_scale.blob_scale_spread`).

A hard rule (in the air when ``m`` exceeds a threshold) measures every ball below the threshold on the plane ``z = R``,
which for a ball 0.05-0.1 m up puts it 15-20 % of its range too far along the ray (0.55 m at 3.4 m on the development
replays), and every ground ball whose size noise crosses it that far too near. The error-minimising placement along
the ray is the posterior mean of ``x`` under the prior

    p(x) = (1 - a) delta(x) + a exp(-x / lam) / lam      (x >= 0)

(``a`` the share of blobs that are balls in the air, ``lam`` the mean log ratio of such a ball), which is

    E[x | m] = P(air | m) E[x | m, air],
    E[x | m, air] = mu + sigma phi(mu / sigma) / Phi(mu / sigma),  mu = m - sigma^2 / lam,
    P(air | m) = a f_1(m) / ((1 - a) f_0(m) + a f_1(m)),

with ``f_1(m) = exp(sigma^2 / 2 lam^2 - m / lam) Phi(mu / sigma) / lam`` (an exponentially modified Gaussian) and
``f_0`` a Student t of ``GROUND_DF = 5`` degrees of freedom and scale ``sigma``: ground balls' sizes have a heavier
upper tail than a normal's (on the development replays 5.8 % beyond 2 robust stds and 1.3 % beyond 3, a t of 5
degrees has 5.1 % and 1.5 %, a normal 2.3 % and 0.1 %), and a normal would take every such blob for a low flight.
The mean is 0 for ``m`` well below ``sigma`` and about ``m - sigma^2 / lam`` above it (where the air is likely), and
moves a blob smoothly in between. Far beyond, the t's polynomial tail outgrows the exponential prior's and the
posterior turns back to the ground: :class:`~heatpf_jax.sources.lofted.LoftedSource` uses it only below its hard test,
beyond which a blob is placed by its measured size. The tail shares quoted are those measured before the sub-pixel
peak (:func:`~heatpf_jax.sources.lofted.subpixel_peaks`), which halved them (3.0 % and 0.3 %). Every function here
is pure and jittable.
"""

from __future__ import annotations

import jax.numpy as jnp
from jax.scipy.stats import norm, t
from jaxtyping import Array, ArrayLike, Float

GROUND_DF = 5.0  # degrees of freedom of the ground balls' size noise (a Student t: see the module docstring)

__all__ = ["air_log_ratio", "air_posterior", "air_probability", "predict_flight"]


def air_posterior(
    log_ratio: Float[ArrayLike, "*b"], sigma: Float[ArrayLike, "*b"], share: Float[ArrayLike, ""],
    scale: Float[ArrayLike, ""],
) -> tuple[Float[Array, "*b"], Float[Array, "*b"]]:
    """``(P(air | m), E[x | m])``: the posterior probability that a blob of measured log size ratio ``m`` is a ball in
    the air, and the posterior mean of the ball's true log size ratio (0 on the ground); see the module docstring.

    Args:
        log_ratio: ``m``, finite.
        sigma: the ground balls' log-size spread, positive (a scalar, or one per entry of ``log_ratio``).
        share: ``a``, the prior share of balls in the air, in ``(0, 1)``.
        scale: ``lam``, the mean log ratio of a ball in the air, positive.

    Returns:
        Probabilities and non-negative posterior means, each the shape of ``log_ratio``.
    """
    m = jnp.asarray(log_ratio, jnp.float32)
    mu = m - jnp.square(sigma) / scale
    z = mu / sigma
    ground = jnp.log1p(-share) + t.logpdf(m, GROUND_DF, 0.0, sigma)
    air = jnp.log(share) - jnp.log(scale) + jnp.square(sigma) / (2.0 * jnp.square(scale)) - m / scale + norm.logcdf(z)
    p_air = jnp.exp(air - jnp.logaddexp(ground, air))
    mills = jnp.exp(norm.logpdf(z) - norm.logcdf(z))  # phi(z) / Phi(z), stable far into the lower tail
    return p_air, p_air * jnp.maximum(mu + sigma * mills, 0.0)


def air_probability(
    log_ratio: Float[ArrayLike, "*b"], sigma: Float[ArrayLike, ""], share: Float[ArrayLike, ""],
    scale: Float[ArrayLike, ""],
) -> Float[Array, "*b"]:
    """``P(air | m)`` alone (:func:`air_posterior`)."""
    return air_posterior(log_ratio, sigma, share, scale)[0]


def air_log_ratio(
    log_ratio: Float[ArrayLike, "*b"], sigma: Float[ArrayLike, ""], share: Float[ArrayLike, ""],
    scale: Float[ArrayLike, ""],
) -> Float[Array, "*b"]:
    """``E[x | m]`` alone (:func:`air_posterior`)."""
    return air_posterior(log_ratio, sigma, share, scale)[1]


def predict_flight(
    p_air: Float[ArrayLike, ""], dt: Float[ArrayLike, ""], launch_rate: Float[ArrayLike, ""],
    flight_time: Float[ArrayLike, ""],
) -> Float[Array, ""]:
    """The probability that the ball is in the air one step of ``dt`` seconds later (a two-state Markov chain).

    A ball on the ground is launched at ``launch_rate`` per second; a flight lasts ``flight_time`` seconds on
    average (bounces included):

        p' = p exp(-dt / flight_time) + (1 - p) (1 - exp(-launch_rate dt)).
    """
    p = jnp.asarray(p_air, jnp.float32)
    stay = jnp.exp(-jnp.asarray(dt, jnp.float32) / flight_time)
    launch = -jnp.expm1(-jnp.asarray(launch_rate, jnp.float32) * dt)
    return p * stay + (1.0 - p) * launch
