"""A ball does not hover: remembered places of flying blobs (NumPy references; spheres drawn by brute force)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.camera import project_pixel
from heatpf_jax.sources.hover import (
    age_hover,
    air_places,
    hovering,
    init_hover,
    place_points,
    remember_hover,
)
from heatpf_jax.sources.lofted import LoftedParams, LoftedSource, LoftedState
from tests.sources.test_lofted import INTRINSICS, PAPER, RADIUS, _inputs, _pose, _sphere_heatmap, _weighted_xy

# One program each for the functions tested directly: run eagerly, each of their operations would compile on its own.
INIT_HOVER = jax.jit(init_hover, static_argnums=(0, 1))
AGE_HOVER = jax.jit(age_hover)
REMEMBER_HOVER = jax.jit(remember_hover)
PLACE_POINTS = jax.jit(place_points)
AIR_PLACES = jax.jit(air_places, static_argnums=3)
HOVERING = jax.jit(hovering)
PROJECT_PIXEL = jax.jit(project_pixel)


def _np_image(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Pixels of homogeneous base-frame points, by the pinhole model written out."""
    cam = (points[:, :3] - points[:, 3:4] * pose[:3, 3][None]) @ pose[:3, :3]
    return np.stack([INTRINSICS[0] * cam[:, 0] / cam[:, 2] + INTRINSICS[2],
                     INTRINSICS[1] * cam[:, 1] / cam[:, 2] + INTRINSICS[3]], -1)


def test_age_hover_moves_points_with_the_robot_and_directions_only_turn():
    rng = np.random.default_rng(3)
    state = INIT_HOVER(4, 3)
    pts = np.concatenate([rng.uniform(-3, 3, (3, 3)), np.array([[1.0], [0.0], [1.0]])], -1).astype(np.float32)
    state = REMEMBER_HOVER(state, pts, np.array([True, True, False]))
    odo = np.array([0.3, -0.1, 0.4], np.float32)
    moved = AGE_HOVER(state, odo, 0.1)
    c, s = np.cos(odo[2]), np.sin(odo[2])
    for p, q in zip(pts, np.asarray(moved.points)[0], strict=True):
        shifted = p[:2] - p[3] * odo[:2]
        expected = np.array([c * shifted[0] + s * shifted[1], -s * shifted[0] + c * shifted[1]])
        np.testing.assert_allclose(q[:2], expected, atol=1e-5)
        assert q[2] == pytest.approx(p[2]) and q[3] == p[3]
    assert float(np.asarray(moved.age)[0]) == pytest.approx(0.1)
    assert np.all(np.isinf(np.asarray(moved.age)[1:]))  # never-filled slots stay infinitely old


def test_place_points_meet_the_plane_or_give_the_direction():
    pose = _pose(0.6, 20.0, yaw=0.2)
    places = np.array([[60.0, 100.0], [100.0, 140.0], [80.0, 5.0]], np.float32)  # the last is above the horizon
    pts = np.asarray(PLACE_POINTS(places, INTRINSICS, pose, RADIUS))
    for uv, p in zip(places[:2], pts[:2], strict=True):
        xy, ok = PROJECT_PIXEL(uv, INTRINSICS, pose, RADIUS)
        assert bool(ok) and p[3] == 1.0 and p[2] == pytest.approx(RADIUS)
        np.testing.assert_allclose(p[:2], np.asarray(xy), atol=1e-4)
    assert pts[2, 3] == 0.0
    np.testing.assert_allclose(_np_image(pts, pose), places, atol=1e-3)  # every place projects back onto itself


def test_air_places_greedy_against_numpy():
    rng = np.random.default_rng(8)
    uv = np.concatenate([rng.normal([30, 40], 0.5, (10, 2)), rng.normal([90, 60], 0.5, (8, 2)),
                         rng.normal([150, 20], 0.5, (6, 2))]).astype(np.float32)
    weight = rng.uniform(0.3, 1.0, len(uv)).astype(np.float32)
    in_air = np.ones(len(uv), bool)
    in_air[18:] = False  # the third blob is on the ground
    got, has, label = AIR_PLACES(uv, weight, in_air, 3, 3.0)
    free, expected, expected_label = in_air.copy(), [], np.full(len(uv), -1)
    while free.any():
        i = int(np.argmax(np.where(free, weight, -np.inf)))
        near = free & (np.sum((uv - uv[i]) ** 2, -1) <= 36.0)
        expected_label[near] = len(expected)
        expected.append(uv[i])
        free &= ~near
    assert np.asarray(has).tolist() == [True, True, False]
    np.testing.assert_allclose(np.asarray(got)[:2], np.array(expected), atol=1e-6)
    np.testing.assert_array_equal(np.asarray(label), expected_label)


def test_hovering_uses_the_age_window_and_the_tolerance():
    pose = _pose(0.6, 20.0)
    state = INIT_HOVER(4, 2)
    place = np.array([[80.0, 100.0], [0.0, 0.0]], np.float32)
    state = REMEMBER_HOVER(state, PLACE_POINTS(place, INTRINSICS, pose, RADIUS), np.array([True, False]))
    query = np.array([[81.0, 101.0], [86.0, 100.0]], np.float32)  # within 3 px, and 6 px away
    check = lambda s: np.asarray(HOVERING(s, query, INTRINSICS, pose, tolerance=3.0, min_age=0.25,  # noqa: E731
                                          max_age=1.0)).tolist()
    assert check(AGE_HOVER(state, np.zeros(3), 0.1)) == [False, False]  # too recent: a ball in flight may pause
    assert check(AGE_HOVER(state, np.zeros(3), 0.5)) == [True, False]
    assert check(AGE_HOVER(state, np.zeros(3), 1.5)) == [False, False]  # forgotten


def _lofted_hover(**kwargs):
    return LoftedSource(max_measurements=256, calibration_frames=0, hover_frames=16, **kwargs)


def test_a_large_thing_on_the_ground_is_measured_as_the_paper_once_it_has_hovered():
    """A ground object twice the ball's size reads as a ball in the air nearer the robot; after it stayed at its
    place for ``hover_min_age`` (the robot turning its head and walking meanwhile) it is measured where it projects,
    exactly as the paper's source measures it."""
    rng = np.random.default_rng(11)
    source = _lofted_hover()
    params = LoftedParams()
    measure = jax.jit(source.measure_state)
    state = jax.jit(source.init_state)()  # one program: eager ops compile one by one
    assert isinstance(state, LoftedState)
    thing = np.array([2.6, 0.3])  # in the base frame of the first step
    step = np.array([0.04, 0.0, 0.02], np.float32)  # the robot walks and turns
    robot = np.zeros(3)
    for t in range(6):
        c, s = np.cos(robot[2]), np.sin(robot[2])
        rel = np.array([[c, s], [-s, c]]) @ (thing - robot[:2])
        pose = _pose(0.6, 20.0, yaw=0.15 * np.sin(t))  # the head turns
        big = RADIUS * 2.0
        heat = _sphere_heatmap(rng, np.array([*rel, big]), pose, scale=0.6 * 2.0)  # a blob twice a ball's there
        inputs = _inputs(heat, pose)._replace(odometry=step if t else np.zeros(3, np.float32))
        m, state = measure(inputs, params, state)
        paper = PAPER(inputs, hp.sources.SourceParams())
        if t < 3:  # ages 0.1 and 0.2 s: still read as a ball in the air, nearer the robot
            assert np.linalg.norm(_weighted_xy(m)) < 0.8 * np.linalg.norm(_weighted_xy(paper))
        else:
            np.testing.assert_allclose(np.asarray(m.xy), np.asarray(paper.xy), atol=1e-4)
        robot = robot + np.array([*(np.array([[np.cos(robot[2]), -np.sin(robot[2])],
                                               [np.sin(robot[2]), np.cos(robot[2])]]) @ step[:2]), step[2]])


def test_a_ball_in_flight_stays_placed_under_itself():
    rng = np.random.default_rng(12)
    source = _lofted_hover()
    measure = jax.jit(source.measure_state)
    state = jax.jit(source.init_state)()  # one program: eager ops compile one by one
    pose = _pose(0.6, 15.0)
    for t in range(8):  # 0.3 m per step across the view, 0.4-0.6 m up
        ground = np.array([2.8 - 0.1 * t, -1.0 + 0.3 * t])
        heat = _sphere_heatmap(rng, np.array([*ground, 0.4 + 0.2 * np.sin(0.4 * t)]), pose)
        m, state = measure(_inputs(heat, pose), LoftedParams(), state)
        assert np.linalg.norm(_weighted_xy(m) - ground) < 0.12 * np.linalg.norm(ground)


def test_places_move_and_age_through_steps_without_a_heat_map():
    source = _lofted_hover()
    state = jax.jit(source.init_state)()  # one program: eager ops compile one by one
    pts = np.array([[2.0, 0.5, RADIUS, 1.0]] * 4, np.float32)
    state = state._replace(hover=REMEMBER_HOVER(state.hover, pts, np.ones(4, bool)))
    inputs = _inputs(np.zeros((8, 8), np.float32), _pose(0.6, 20.0))._replace(
        has_heatmap=np.asarray(False), odometry=np.asarray([0.5, 0.0, 0.0], np.float32))
    after = jax.jit(source.carry_state)(inputs, LoftedParams(), state)
    np.testing.assert_allclose(np.asarray(after.hover.points)[0, 0, :2], [1.5, 0.5], atol=1e-6)
    assert float(np.asarray(after.hover.age)[0]) == pytest.approx(0.1)
    assert jax.jit(LoftedSource().init_state)().hover == ()  # off by default
    with pytest.raises(ValueError, match="^hover_blobs:"):
        LoftedSource(hover_blobs=0).validate()
    with pytest.raises(ValueError, match="^hover_frames:"):
        LoftedSource(hover_frames=-1).validate()


def test_the_filter_ages_the_places_on_steps_without_a_heat_map():
    """``Filter.step`` calls ``carry_state`` on a step without a heat map: remembered places age by its ``dt`` and
    move with its odometry."""
    method = hp.build("heatmap", hp.FilterOptions(hover_frames=4, num_particles=64, max_measurements=64))
    model, params = method.model, method.params
    state = jax.jit(model.init)(jax.random.key(0), params)  # one program: eager ops compile one by one
    pts = np.array([[2.0, 0.5, RADIUS, 1.0]] * 4, np.float32)
    state = state._replace(source=state.source._replace(hover=REMEMBER_HOVER(state.source.hover, pts,
                                                                               np.ones(4, bool))))
    inputs = _inputs(np.zeros((150, 200), np.float32), _pose(0.6, 20.0))._replace(
        has_heatmap=np.asarray(False), odometry=np.asarray([0.25, 0.0, 0.0], np.float32))
    after, _ = jax.jit(model.step)(jax.random.key(1), state, inputs, params)
    assert float(np.asarray(after.source.hover.age)[0]) == pytest.approx(0.1)
    np.testing.assert_allclose(np.asarray(after.source.hover.points)[0, 0, :2], [1.75, 0.5], atol=1e-5)
