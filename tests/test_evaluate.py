"""Error statistics: the radial / lateral split by hand, and as the comparison table reports it."""

from __future__ import annotations

import numpy as np

from heatpf_jax.evaluate import MethodResult, ScenarioResult, Variant, factor_breakdown, format_table, radial_lateral


def test_radial_lateral_by_hand(rng):
    truth = np.array([[2.0, 0.0], [0.0, 3.0], [0.0, 0.0]])
    est = np.array([[2.5, 0.1], [0.2, 2.9], [0.3, -0.4]])
    radial, lateral = radial_lateral(est, truth)
    # Beyond the ball along the ray is positive; left of the ray is positive; at the origin the ray is x.
    np.testing.assert_allclose(radial, [0.5, -0.1, 0.3])
    np.testing.assert_allclose(lateral, [0.1, -0.2, -0.4])
    truth, est = rng.normal(size=(5, 7, 2)) * 3, rng.normal(size=(5, 7, 2)) * 3
    radial, lateral = radial_lateral(est, truth)
    np.testing.assert_allclose(radial**2 + lateral**2, np.sum((est - truth) ** 2, -1), rtol=1e-12)


def test_table_reports_the_split_as_root_mean_squares(rng):
    truth = rng.uniform(1, 4, size=(2, 20, 2))
    est = truth + rng.normal(scale=0.1, size=truth.shape)
    radial, lateral = radial_lateral(est, truth)
    m = MethodResult(Variant("x", "paper"), est, np.linalg.norm(est - truth, axis=-1), radial, lateral)
    st = m.stats(5)
    assert st["radial"] == np.sqrt(np.mean(radial[:, 5:] ** 2))
    assert st["lateral"] == np.sqrt(np.mean(lateral[:, 5:] ** 2))
    table = format_table(ScenarioResult("s", truth, [m], 5), reference="x")
    assert "radial rms" in table and f"{st['radial']:11.4f}" in table.splitlines()[-1]


def test_factor_breakdown_splits_each_numeric_factor_at_its_median():
    truth = np.zeros((4, 12, 2)) + [2.0, 0.0]
    errors = np.array([[0.1] * 12, [0.2] * 12, [0.5] * 12, [0.9] * 12])
    m = MethodResult(Variant("x", "paper"), truth, errors)
    factors = [{"noise": 0.01, "shape": "disc", "count": 3}, {"noise": 0.02, "shape": "gaussian", "count": 3},
               {"noise": 0.05, "shape": "disc", "count": 3}, {"noise": 0.06, "shape": "disc", "count": 3}]
    text = factor_breakdown(ScenarioResult("family/standard", truth, [m], 2), factors)
    lines = text.splitlines()
    assert len(lines) == 2  # only "noise" is numeric and varies
    assert lines[1].split()[:3] == ["noise", "<=", "0.035"] and "x 0.150/0.700" in lines[1]
    empty = factor_breakdown(ScenarioResult("s", truth, [m], 2), [{}] * 4)
    assert empty == "s: no factor varies over these sequences"
