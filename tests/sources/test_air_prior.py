"""The posterior placement of a blob along its ray (SciPy numerical integration as the reference)."""

from __future__ import annotations

import jax
import numpy as np
import pytest
from scipy import integrate, stats

from heatpf_jax.sources.air_prior import GROUND_DF, air_log_ratio, air_probability, predict_flight

# Through `jit`, every number traced: run eagerly, each of their operations compiles a program of its own.
_air_probability = jax.jit(air_probability)
_air_log_ratio = jax.jit(air_log_ratio)
_predict_flight = jax.jit(predict_flight)


def _posterior(m: float, sigma: float, share: float, scale: float) -> tuple[float, float]:
    """``(P(air | m), E[x | m])`` by quadrature over the prior (1 - a) delta(x) + a exp(-x / lam) / lam."""
    air = lambda x: share / scale * np.exp(-x / scale) * stats.norm.pdf(m - x, 0.0, sigma)  # noqa: E731
    upper = max(m, 0.0) + 12.0 * sigma + 40.0 * scale
    points = [p for p in (m,) if 0.0 < p < upper]
    z_air = integrate.quad(air, 0.0, upper, points=points, limit=200)[0]
    moment = integrate.quad(lambda x: x * air(x), 0.0, upper, points=points, limit=200)[0]
    evidence = (1.0 - share) * stats.t.pdf(m, GROUND_DF, 0.0, sigma) + z_air
    return z_air / evidence, moment / evidence


@pytest.mark.parametrize(("sigma", "share", "scale"), [(0.03, 0.01, 0.1), (0.02, 0.3, 0.3), (0.08, 0.05, 0.5)])
def test_posterior_matches_quadrature(sigma, share, scale):
    for m in (-0.2, -0.02, 0.0, 0.01, 0.05, 0.1, 0.2, 0.6):
        p_air, mean = _posterior(m, sigma, share, scale)
        assert float(_air_probability(m, sigma, share, scale)) == pytest.approx(p_air, rel=2e-3, abs=1e-6)
        assert float(_air_log_ratio(m, sigma, share, scale)) == pytest.approx(mean, rel=2e-3, abs=1e-6)


def test_posterior_limits():
    """Far below the noise: on the ground (no move); far above: the measured ratio less sigma^2 / lam."""
    m = np.array([-1.0, 0.3])
    out = np.asarray(_air_log_ratio(m, 0.03, 0.5, 0.2))
    assert out[0] == pytest.approx(0.0, abs=1e-6)
    assert out[1] == pytest.approx(0.3 - 0.03**2 / 0.2, rel=1e-2)
    assert np.all(np.isfinite(np.asarray(_air_log_ratio(np.linspace(-5, 50, 101), 0.02, 1e-6, 0.1))))
    # The more a ball is expected in the air, the farther a blob of the same size moves.
    moves = [float(_air_log_ratio(0.08, 0.03, a, 0.1)) for a in (0.001, 0.05, 0.9)]
    assert moves[0] < moves[1] < moves[2]


def test_predict_flight_is_the_two_state_chain():
    dt, rate, flight = 0.1, 0.2, 1.5
    launch, stay = 1.0 - np.exp(-rate * dt), np.exp(-dt / flight)
    transition = np.array([[stay, 1.0 - stay], [launch, 1.0 - launch]])  # rows: from air, from ground
    p = 0.3
    for _ in range(5):
        expected = np.array([p, 1.0 - p]) @ transition
        p = float(_predict_flight(p, dt, rate, flight))
        assert p == pytest.approx(expected[0], rel=1e-5)
    stationary = launch / (launch + 1.0 - stay)
    assert float(_predict_flight(stationary, dt, rate, flight)) == pytest.approx(stationary, rel=1e-5)
