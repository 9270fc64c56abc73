"""The detector's blob scale learned from the heat maps (NumPy references; spheres drawn by brute force)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sources.blob_scale import (
    blob_scale_estimate,
    blob_scale_spread,
    frame_log_ratio,
    ground_centre,
    ground_spread,
    init_blob_scale,
    update_blob_scale,
)
from heatpf_jax.sources.lofted import LoftedParams, LoftedSource
from tests.sources.test_lofted import MEASURE, PAPER, RADIUS, _inputs, _pose, _sphere_heatmap, _weighted_xy

CALIBRATED = LoftedSource(max_measurements=256, calibration_frames=32)
MEASURE_STATE = jax.jit(CALIBRATED.measure_state)  # one compilation for the tests of a calibrated source
# One program each for the functions tested directly: run eagerly, each of their operations would compile on its own.
INIT_STATE = jax.jit(CALIBRATED.init_state)
INIT_BLOB_SCALE = jax.jit(init_blob_scale, static_argnums=0)
UPDATE = jax.jit(update_blob_scale)
ESTIMATE = jax.jit(blob_scale_estimate)
SPREAD = jax.jit(blob_scale_spread)
FRAME_LOG_RATIO = jax.jit(frame_log_ratio)
GROUND_CENTRE = jax.jit(ground_centre)
GROUND_SPREAD = jax.jit(ground_spread)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> float:
    """The lower weighted median by brute force: the smallest value whose cumulative weight reaches half."""
    order = np.argsort(values, kind="stable")
    cum = np.cumsum(weights[order])
    return float(values[order][np.nonzero(cum >= 0.5 * cum[-1])[0][0]])


def test_frame_log_ratio_is_the_weighted_median():
    rng = np.random.default_rng(21)
    for _ in range(5):
        m = 40
        std = rng.uniform(0.5, 6.0, m).astype(np.float32)
        ground = rng.uniform(1.0, 8.0, m).astype(np.float32)
        weight = rng.uniform(0.3, 1.0, m).astype(np.float32)
        valid = rng.uniform(size=m) > 0.3
        ground[rng.uniform(size=m) < 0.1] = 0.0  # above the horizon: never counted
        ok = valid & (ground > 0)
        got, has = FRAME_LOG_RATIO(std, ground, weight, valid)
        assert bool(has)
        expected = _weighted_median(np.log(std[ok].astype(np.float64) / ground[ok]), weight[ok].astype(np.float64))
        assert float(got) == pytest.approx(expected, abs=1e-5)
    _, has = FRAME_LOG_RATIO(np.ones(4), np.zeros(4), np.ones(4), np.ones(4, bool))
    assert not bool(has)


def test_ring_buffer_and_quantile_against_numpy():
    rng = np.random.default_rng(4)
    state = INIT_BLOB_SCALE(8)
    assert float(ESTIMATE(state, 0.6)) == pytest.approx(0.6)  # the prior before any frame
    kept = []
    for i in range(13):
        value = float(rng.normal(-0.4, 0.3))
        has = i % 4 != 3  # every fourth frame has no blob: nothing is stored
        state = UPDATE(state, value, has)
        if has:
            kept.append(value)
        stored = np.sort(np.asarray(state.log_ratios)[np.asarray(state.filled)])
        np.testing.assert_allclose(stored, np.sort(np.float32(kept[-8:])), rtol=1e-6)
        for q in (0.2, 0.5, 0.9):
            expected = np.exp(np.quantile(np.float32(kept[-8:]), q, method="lower"))
            assert float(ESTIMATE(state, 0.6, q)) == pytest.approx(expected, rel=1e-5)
        recent = np.float32(kept[-8:])
        centre = np.quantile(recent, 0.5, method="lower")
        spread = 1.4826 * np.quantile(np.abs(recent - centre), 0.5, method="lower") if len(recent) > 1 else 0.0
        assert float(SPREAD(state)) == pytest.approx(spread, rel=1e-5, abs=1e-7)


def test_a_detector_with_larger_blobs_is_learned():
    """A detector whose blobs are 1.7 times the simulator's (std 1.0 radii, not 0.6): with the fixed prior a ball
    on the ground reads as a ball in the air and is placed metres nearer the robot; after a few frames of ground
    balls the learned scale is the detector's, a ground ball gives the paper's measurements again, and a ball in
    the air is still placed under it."""
    rng = np.random.default_rng(17)
    params = LoftedParams()
    measure = MEASURE_STATE
    pose = _pose(0.6, 25.0, yaw=0.1)
    state = INIT_STATE()
    ground = np.array([2.4, 0.2])
    heat = _sphere_heatmap(rng, np.array([*ground, RADIUS]), pose, scale=1.0)
    fixed = MEASURE(_inputs(heat, pose), params)  # the fixed prior (no state): what LoftedSource.measure gives
    assert np.linalg.norm(_weighted_xy(fixed) - ground) > 0.5  # the prior 0.6 takes it for a ball 1.7x nearer
    for _ in range(6):
        spot = np.array([rng.uniform(1.5, 4.0), rng.uniform(-1.0, 1.0)])
        heat = _sphere_heatmap(rng, np.array([*spot, RADIUS]), pose, scale=1.0)
        m, state = measure(_inputs(heat, pose), params, state)
    learned = float(ESTIMATE(state.scale, params.blob_scale, params.calibration_quantile))
    assert learned == pytest.approx(1.0, rel=0.12)
    heat = _sphere_heatmap(rng, np.array([*ground, RADIUS]), pose, scale=1.0)
    m, _ = measure(_inputs(heat, pose), params, state)
    paper = PAPER(_inputs(heat, pose), hp.sources.SourceParams())
    np.testing.assert_allclose(np.asarray(m.xy), np.asarray(paper.xy), atol=1e-5)
    assert np.linalg.norm(_weighted_xy(m) - ground) < 0.05 * np.linalg.norm(ground)
    air = np.array([2.8, -0.3])
    heat = _sphere_heatmap(rng, np.array([*air, 0.6]), pose, scale=1.0)
    m, after = measure(_inputs(heat, pose), params, state)
    assert np.linalg.norm(_weighted_xy(m) - air) < 0.1 * np.linalg.norm(air)
    # One flight does not move the estimate: the median of the last frames is still the ground balls'.
    assert float(ESTIMATE(after.scale, params.blob_scale)) == pytest.approx(learned, rel=0.05)


def test_the_filter_carries_the_learned_scale():
    model = hp.build("heatmap").model  # its source: LoftedSource
    # init jitted: one program, where eager ops compile one by one
    assert isinstance(jax.jit(model.init)(jax.random.key(0), model.default_params()).source.scale.log_ratios,
                      jax.Array)
    assert jax.jit(hp.build("paper").model.init)(jax.random.key(0), hp.build("paper").params).source == ()
    assert LoftedSource(calibration_frames=0).init_state() == ()
    assert jax.jit(LoftedSource(calibration_frames=0, hover_frames=4).init_state)().scale == ()
    with pytest.raises(ValueError, match="^calibration_frames:"):
        LoftedSource(calibration_frames=-1).validate()


@pytest.mark.parametrize(
    "ratios",
    [np.full(16, np.log(0.05)),  # speckle's or clutter's ratios: no detector's ball blob
     np.full(16, np.log(3.0)),  # large false blobs'
     np.log(0.6) + np.linspace(-1.0, 1.0, 16)],  # sizes that scatter widely
)
def test_no_credible_blob_scale_gives_the_papers_measurements(ratios):
    """When what the frames show is no detector's ball (a learned scale outside [0.25, 2]) or its sizes scatter too
    widely to tell a flying ball, every pixel is measured where it projects: the paper's measurements, exactly."""
    state = INIT_STATE()  # CALIBRATED's: 16 of its 32 slots filled
    scale = state.scale
    for value in ratios:
        scale = UPDATE(scale, value, True)
    state = state._replace(scale=scale)
    rng = np.random.default_rng(5)
    pose = _pose(0.6, 15.0)
    heat = _sphere_heatmap(rng, np.array([2.5, 0.0, 0.5]), pose)  # a ball in the air, 0.5 m up
    inputs = _inputs(heat, pose)
    paper = PAPER(inputs, hp.sources.SourceParams())
    m, _ = MEASURE_STATE(inputs, LoftedParams(), state)
    valid_rows = lambda x: np.sort(np.asarray(x.xy)[np.asarray(x.valid)], axis=0)  # noqa: E731
    assert int(np.asarray(m.valid).sum()) == int(np.asarray(paper.valid).sum()) > 0
    np.testing.assert_allclose(valid_rows(m), valid_rows(paper), atol=1e-5)
    # A credible scale (the simulator's 0.6, ratios that agree) places the same ball under itself.
    scale = INIT_STATE().scale
    for value in np.log(0.6) + 0.02 * rng.standard_normal(16):
        scale = UPDATE(scale, value, True)
    state = INIT_STATE()._replace(scale=scale)
    placed, _ = MEASURE_STATE(inputs, LoftedParams(), state)
    assert np.linalg.norm(_weighted_xy(placed) - np.array([2.5, 0.0])) < 0.25


def _half_sample_mode_reference(values: np.ndarray, min_window: int = 8) -> float:
    """The half-sample mode by brute force: the shortest window of half the values (of equally short ones, the one
    nearest the middle), then of half of those, down to a quarter of all values (at least ``min_window``); the last
    window's median."""
    v = np.sort(np.float64(values))
    smallest = max(len(v) // 4, min_window)
    while True:
        k = min(max((len(v) + 1) // 2, smallest), len(v))
        if k == len(v):
            return float(np.median(v))
        lengths = np.array([v[i + k - 1] - v[i] for i in range(len(v) - k + 1)])
        ties = np.flatnonzero(lengths <= lengths.min() + 1e-6 * (1.0 + abs(lengths.min())))
        i = int(ties[np.argmin(np.abs(ties - 0.5 * (len(v) - k)))])
        v = v[i:i + k]


def _ground_spread_reference(values: np.ndarray) -> float:
    """The half-sample mode, then 1.4826 times the lower median of the distances below it."""
    v = np.float64(values)
    centre = _half_sample_mode_reference(v)
    below = centre - v[v < centre]
    return 1.4826 * float(np.quantile(below, 0.5, method="lower"))


def test_ground_spread_ignores_balls_in_the_air():
    """Ground balls' sizes N(log 0.6, 0.03^2) and a third of the frames in flights (only ever larger): the spread
    below the half-sample mode is the ground balls', the median absolute deviation about the median is not."""
    rng = np.random.default_rng(8)
    ground = np.log(0.6) + 0.03 * rng.standard_normal(170)
    air = np.log(0.6) + rng.exponential(0.4, 86)
    values = rng.permutation(np.concatenate([ground, air]))
    state = INIT_BLOB_SCALE(256)
    for value in values:
        state = UPDATE(state, value, True)
    spread = float(GROUND_SPREAD(state))
    assert spread == pytest.approx(_ground_spread_reference(np.float32(values)), rel=1e-4)
    assert spread == pytest.approx(0.03, rel=0.2)
    assert float(SPREAD(state)) > 1.3 * spread
    few = INIT_BLOB_SCALE(16)
    for value in values[:7]:
        few = UPDATE(few, value, True)
    assert float(GROUND_SPREAD(few)) == 0.0  # fewer than 8 values: no spread yet
    # The ground balls' centre: the half-sample mode, on log 0.6 where the median of all frames lies above it.
    centre, has = GROUND_CENTRE(state)
    assert bool(has)
    assert float(centre) == pytest.approx(_half_sample_mode_reference(np.float32(values)), abs=1e-5)
    assert float(centre) == pytest.approx(np.log(0.6), abs=0.01)
    assert float(np.log(ESTIMATE(state, 0.6))) > float(centre) + 0.02
    assert not bool(GROUND_CENTRE(few)[1])


def test_ground_centre_holds_when_most_frames_are_in_flight():
    """A run that starts in a long flight: 13 ground balls' sizes N(log 0.6, 0.026^2) and 27 frames in the air. The
    shortest half of the 40 values holds flights' values and lies above the ground balls; the half-sample mode stays
    on them, and the spread below it is theirs (checked against the NumPy brute force)."""
    rng = np.random.default_rng(15)
    ground = np.log(0.6) + 0.026 * rng.standard_normal(13)
    air = np.log(0.6) + rng.exponential(0.5, 27)
    values = np.float32(rng.permutation(np.concatenate([ground, air])))
    state = INIT_BLOB_SCALE(256)
    for value in values:
        state = UPDATE(state, value, True)
    centre, has = GROUND_CENTRE(state)
    assert bool(has)
    assert float(centre) == pytest.approx(_half_sample_mode_reference(values), abs=1e-5)
    assert float(centre) == pytest.approx(np.log(0.6), abs=0.03)
    v = np.sort(np.float64(values))
    shorth = min((v[i + 20] - v[i], 0.5 * (v[i] + v[i + 20])) for i in range(20))[1]
    assert shorth > np.log(0.6) + 0.04  # the shortest half alone is pulled up by the flights
    assert float(GROUND_SPREAD(state)) == pytest.approx(_ground_spread_reference(values), rel=1e-4)
    assert float(GROUND_SPREAD(state)) < 0.06


def test_a_run_that_starts_in_a_flight_still_places_a_flying_ball():
    """22 of the 32 stored frames in a flight (a run that starts with a long one) and 10 ground balls: all values
    scatter widely about their median, the ground balls' do not about their mode. A ball 0.5 m up is placed by its
    size; read against the median and its spread, it was left on the plane, 8 m too far."""
    rng = np.random.default_rng(16)
    values = np.concatenate([np.log(0.6) + 0.026 * rng.standard_normal(10), np.log(0.6) + rng.exponential(1.0, 22)])
    scale = INIT_STATE().scale
    for value in rng.permutation(values):
        scale = UPDATE(scale, value, True)
    assert float(SPREAD(scale)) > LoftedParams().calibration_max_spread  # the median's view
    assert float(GROUND_SPREAD(scale)) < 0.06
    state = INIT_STATE()._replace(scale=scale)
    pose = _pose(0.6, 15.0)
    truth = np.array([2.5, 0.0])
    inputs = _inputs(_sphere_heatmap(rng, np.array([*truth, 0.5]), pose), pose)
    placed, _ = MEASURE_STATE(inputs, LoftedParams(), state)
    paper = PAPER(inputs, hp.sources.SourceParams())
    assert np.linalg.norm(_weighted_xy(paper) - truth) > 1.0
    assert np.linalg.norm(_weighted_xy(placed) - truth) < 0.1 * np.linalg.norm(truth)


def test_a_low_ball_after_a_flight_is_placed_by_its_size():
    """A ball 0.06 m up (its blob 1.13 times a ground ball's there, below ``min_ratio``) just after a flight: the
    flight state says the ball is in the air, and its size places it far nearer the truth than the plane, which puts
    it 13 % of its range too far. Ground balls long after any flight keep the paper's measurements."""
    rng = np.random.default_rng(4)
    params = LoftedParams()
    measure = MEASURE_STATE
    pose = _pose(0.6, 25.0, yaw=0.1)
    state = INIT_STATE()
    for _ in range(20):  # ground balls: the detector's scale and spread are learned, the flight state stays low
        spot = np.array([rng.uniform(1.5, 3.5), rng.uniform(-0.8, 0.8)])
        m, state = measure(_inputs(_sphere_heatmap(rng, np.array([*spot, RADIUS]), pose), pose), params, state)
    assert float(state.flight) < 0.05
    ground = np.array([2.4, 0.2])
    inputs = _inputs(_sphere_heatmap(rng, np.array([*ground, RADIUS]), pose), pose)
    m, _ = measure(inputs, params, state)
    paper = PAPER(inputs, hp.sources.SourceParams())
    np.testing.assert_allclose(np.asarray(m.xy), np.asarray(paper.xy), atol=1e-5)
    for height in (0.5, 0.35, 0.2):  # the flight's end
        m, state = measure(_inputs(_sphere_heatmap(rng, np.array([*ground, height + RADIUS]), pose), pose), params,
                           state)
    assert float(state.flight) > 0.9
    inputs = _inputs(_sphere_heatmap(rng, np.array([*ground, 0.06 + RADIUS]), pose), pose)
    m, _ = measure(inputs, params, state)
    paper = PAPER(inputs, hp.sources.SourceParams())
    plane_error = np.linalg.norm(_weighted_xy(paper) - ground)
    assert plane_error > 0.25
    assert np.linalg.norm(_weighted_xy(m) - ground) < 0.4 * plane_error


def test_a_flying_ball_is_sized_against_the_ground_balls_not_the_flights():
    """Frames in flights pull the median of all frames' ratios up (3 % here, 14 flights among 31): a ball in
    the air read against it would look that much smaller and lie that much farther along its ray. It is read against
    the ground balls' centre (``ground_centre``) instead: placed as with the ground balls' scale known."""
    rng = np.random.default_rng(12)
    values = np.concatenate([np.log(0.6) + 0.02 * rng.standard_normal(17), np.log(0.6) + rng.exponential(0.4, 14)])
    state = INIT_STATE()
    scale = state.scale
    for value in rng.permutation(values):
        scale = UPDATE(scale, value, True)
    state = state._replace(scale=scale)
    pose = _pose(0.6, 15.0)
    inputs = _inputs(_sphere_heatmap(rng, np.array([2.5, 0.0, 0.5]), pose), pose)  # a ball 0.5 m up
    learned, _ = MEASURE_STATE(inputs, LoftedParams(), state)
    known = MEASURE(inputs, LoftedParams(blob_scale=0.6))  # the ground balls' scale, fixed
    median = float(np.exp(np.quantile(np.float32(values), 0.5, method="lower")))
    assert median > 1.03 * 0.6
    by_median = MEASURE(inputs, LoftedParams(blob_scale=median))
    truth = np.array([2.5, 0.0])
    assert np.linalg.norm(_weighted_xy(known) - truth) < 0.15
    shift = np.linalg.norm(_weighted_xy(by_median) - _weighted_xy(known))
    assert shift > 0.05
    assert np.linalg.norm(_weighted_xy(learned) - _weighted_xy(known)) < 0.2 * shift
