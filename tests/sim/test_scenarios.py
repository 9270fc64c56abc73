"""The scenarios after Olufs et al.'s test tours (``two_balls``, ``shot``, ``turning``) and the per-ball info.

Each new scenario is simulated once (300 steps, the default 30 s, on a 50 x 37 heat map) and checked for what
its name promises. Projections use the filter's ``project_points``; the older scenarios are pinned by
arrays taken before the new ones were added (their random streams derive from their index in ``SCENARIOS``),
compared with tolerances, not hashes, so that another CPU's float rounding does not fail them. The checks
were run with every seed 0-29 (change ``SEED`` to re-check).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sim import SCENARIOS, simulate, simulate_with_info
from tests.data.scenario_pins import OLDER as OLDER_PINNED
from tests.data.scenario_pins import pins

DT = 0.1
SEED = 0
SHRINK = 4
NEW = ("two_balls", "shot", "turning")

# The older scenarios (seed 0, 40 steps, shrink 4) as they were before two_balls, shot and turning existed:
# whole small arrays, heat-map row and column sums and three whole maps (tests/data/scenario_pins.py).
PINS = np.load(Path(__file__).parent.parent / "data" / "scenario_pins.npz")
OLDER = OLDER_PINNED
# Far above float32 rounding of trigonometry on another CPU (about 1e-6 here), far below what any change of a
# scenario's draws, blobs or motion makes (a ball moved by one pixel changes row sums by about 0.1).
ATOL = {"ground_truth": 1e-5, "odometry": 1e-5, "cam_to_base": 1e-5, "row_sums": 2e-3, "col_sums": 2e-3,
        "maps": 2e-3}


def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _project(points_xy: np.ndarray, seq: hp.Sequence, t: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Pixels ``[n, 2]`` of ball centres at base ``points_xy`` ``[n, 2]`` (height = radius) and their depths."""
    points = np.c_[points_xy, np.full(len(points_xy), float(seq.ball_radius))]
    uv, depth = hp.camera.project_points(points, seq.intrinsics, seq.cam_to_base[t])
    return np.asarray(uv, np.float64), np.asarray(depth, np.float64)


def _heat_at(heat: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The heat at the nearest pixel of each ``uv`` ``[n, 2]``."""
    cols = np.clip(np.round(uv[:, 0]).astype(int), 0, heat.shape[-1] - 1)
    rows = np.clip(np.round(uv[:, 1]).astype(int), 0, heat.shape[-2] - 1)
    return heat[rows, cols]


@functools.cache
def _old(scenario: str) -> tuple[hp.Sequence, dict]:
    """40 steps of an older scenario, seed 0 (the fingerprints' seed)."""
    return simulate_with_info(scenario, 0, num_steps=40, shrink=SHRINK)


@pytest.fixture(scope="module")
def two_balls() -> tuple[hp.Sequence, dict]:
    return simulate_with_info("two_balls", SEED, shrink=SHRINK)


@pytest.fixture(scope="module")
def shot() -> tuple[hp.Sequence, dict]:
    return simulate_with_info("shot", SEED, shrink=SHRINK)


@pytest.fixture(scope="module")
def turning() -> tuple[hp.Sequence, dict]:
    return simulate_with_info("turning", SEED, shrink=SHRINK)


# --- The older scenarios ------------------------------------------------------------------------------------------


def test_new_scenarios_come_last():
    assert SCENARIOS[: len(OLDER)] == OLDER and SCENARIOS[len(OLDER) :][: len(NEW)] == NEW


@pytest.mark.parametrize("scenario", OLDER)
def test_older_scenarios_are_unchanged(scenario):
    seq, _ = _old(scenario)
    for key, value in pins(seq).items():
        pinned = PINS[f"{scenario}/{key}"]
        assert value.shape == pinned.shape and value.dtype == pinned.dtype, key
        if value.dtype == bool:
            np.testing.assert_array_equal(value, pinned, err_msg=key)
        else:
            np.testing.assert_allclose(value.astype(np.float64), pinned.astype(np.float64), rtol=0,
                                       atol=ATOL[key], err_msg=f"{scenario}: {key}")


@pytest.mark.parametrize("scenario", OLDER)
def test_one_ball_scenarios_report_their_ball(scenario):
    seq, info = _old(scenario)
    assert info["balls_base"].shape == (40, 1, 2) and info["balls_base"].dtype == np.float64
    np.testing.assert_array_equal(info["balls_base"][:, 0], seq.ground_truth)
    assert info["balls_visible"].shape == (40, 1) and info["balls_visible"].dtype == bool
    np.testing.assert_array_equal(info["balls_visible"][:, 0], info["visible"])


# --- Every new scenario -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("scenario", NEW)
def test_new_scenarios_reproduce_and_vary(scenario):
    seq, info = simulate_with_info(scenario, 3, num_steps=60, shrink=SHRINK)
    again, info_again = simulate_with_info(scenario, 3, num_steps=60, shrink=SHRINK)
    for key in hp.Sequence._fields:
        np.testing.assert_array_equal(getattr(again, key), getattr(seq, key), err_msg=key)
    assert info.keys() == info_again.keys()
    for key, value in info.items():
        np.testing.assert_array_equal(info_again[key], value, err_msg=key)
    other, other_info = simulate_with_info(scenario, 4, num_steps=60, shrink=SHRINK)
    assert not np.allclose(other_info["balls_base"], info["balls_base"])
    assert not np.array_equal(other.heatmaps, seq.heatmaps)
    assert hp.validate_sequence(seq) is not None and seq.heatmaps.shape == (60, 37, 50)


@pytest.mark.parametrize("scenario", NEW)
def test_new_worlds_do_not_depend_on_shrink(scenario, request):
    seq, info = request.getfixturevalue(scenario)
    small, small_info = simulate_with_info(scenario, SEED, shrink=10)
    for key in ("ball_world", "robot_pose", "balls_base", "true_cam_to_base"):
        np.testing.assert_array_equal(small_info[key], info[key], err_msg=key)
    np.testing.assert_array_equal(small.odometry, seq.odometry)


@pytest.mark.parametrize("scenario", NEW)
def test_ground_truth_is_the_first_ball_in_the_robots_frame(scenario, request):
    seq, info = request.getfixturevalue(scenario)
    pose, ball = info["robot_pose"], info["ball_world"]
    truth = np.stack([_rot(pose[t, 2]).T @ (ball[t] - pose[t, :2]) for t in range(seq.num_steps)])
    np.testing.assert_allclose(seq.ground_truth, truth, atol=1e-9)
    np.testing.assert_array_equal(info["balls_base"][:, 0], seq.ground_truth)
    np.testing.assert_array_equal(info["balls_visible"][:, 0], info["visible"])
    assert seq.num_steps == 300 and info["balls_base"].shape == (300, 2 if scenario == "two_balls" else 1, 2)


# --- two_balls ----------------------------------------------------------------------------------------------------


def test_two_balls_share_the_standard_world_plus_a_second_blob(two_balls):
    seq, info = two_balls
    std = simulate("standard", SEED, shrink=SHRINK)
    np.testing.assert_array_equal(seq.ground_truth, std.ground_truth)
    np.testing.assert_array_equal(seq.cam_to_base, std.cam_to_base)
    np.testing.assert_array_equal(seq.odometry, 0.0)
    # The heat maps differ from the standard ones only around the second ball (a blob of std
    # max(0.6 * apparent radius, 0.7) pixels), rendered at the same size and peak as the first.
    uv_b, depth_b = _project(info["balls_base"][:, 1], seq)
    sigma = np.maximum(0.6 * seq.intrinsics[0] * float(seq.ball_radius) / depth_b, 0.7)
    rows, cols = np.mgrid[0 : seq.heatmaps.shape[1], 0 : seq.heatmaps.shape[2]]
    for t in range(seq.num_steps):
        changed = np.abs(seq.heatmaps[t] - std.heatmaps[t]) > 1e-6
        dist = np.hypot(cols[changed] - uv_b[t, 0], rows[changed] - uv_b[t, 1])
        assert np.all(dist < 6 * sigma[t] + 1.0), t
    both = info["balls_visible"].all(axis=1)
    assert both.mean() > 0.9
    uv_a, _ = _project(info["balls_base"][:, 0], seq)
    for t in np.flatnonzero(both):
        heat = seq.heatmaps[t]
        assert _heat_at(heat, uv_a[t : t + 1])[0] > 0.4 and _heat_at(heat, uv_b[t : t + 1])[0] > 0.4, t
        if np.linalg.norm(uv_a[t] - uv_b[t]) > 6 * sigma[t] + 2:  # far from the first ball, only the second lights
            assert _heat_at(std.heatmaps[t], uv_b[t : t + 1])[0] < 0.2, t


def test_two_balls_meet_without_overlapping_and_move_independently(two_balls):
    seq, info = two_balls
    a, b = info["balls_base"][:, 0], info["balls_base"][:, 1]
    gap = np.linalg.norm(a - b, axis=1)
    meetings = info["meeting_steps"]
    assert len(meetings) == 3 and np.all(gap[meetings] < 0.3) and gap.min() < 0.3
    assert gap.min() >= 0.16 - 1e-9  # two balls of radius 0.075 m cannot overlap
    # Separate meetings about 10 s apart: the balls come within 0.3 m in three separate stretches.
    near = np.flatnonzero(gap < 0.3)
    assert np.sum(np.diff(near) > 20) + 1 >= 3
    # Independent paths: not copies, not offset copies, not moving together.
    assert np.all((b - a).std(axis=0) > 0.2) and np.ptp(gap) > 1.0
    va, vb = np.diff(a, axis=0) / DT, np.diff(b, axis=0) / DT
    for axis in range(2):
        assert abs(np.corrcoef(va[:, axis], vb[:, axis])[0, 1]) < 0.7
    speed_b = np.linalg.norm(vb, axis=1)
    assert speed_b.max() <= 3.0 and speed_b.mean() > 0.2
    assert info["balls_visible"][:, 1].mean() > 0.9


# --- shot ---------------------------------------------------------------------------------------------------------


def test_shot_three_kicks_bounce_off_the_goal_and_come_back(shot):
    seq, info = shot
    ball, speed, kicks, goal_x = info["ball_world"], info["ball_speed"], info["shot_steps"], info["goal_x"]
    np.testing.assert_array_equal(seq.odometry, 0.0)
    assert np.all(seq.cam_to_base == seq.cam_to_base[0])
    assert kicks.dtype.kind == "i" and len(kicks) == 3 and 5.0 <= goal_x <= 6.0
    vel = np.diff(ball, axis=0) / DT
    ends = np.r_[kicks[1:], seq.num_steps]
    for k, end in zip(kicks, ends, strict=True):
        # At rest at the start spot, 1.5-2.6 m ahead, then kicked at 5-8 m/s, away from the robot.
        assert np.all(speed[k - 5 : k] == 0.0) and 1.45 <= ball[k, 0] <= 2.55
        assert 5.0 <= speed[k] <= 8.0
        assert vel[k, 0] > 0.9 * np.linalg.norm(vel[k]) and np.linalg.norm(vel[k]) > 4.5
        # Rolling friction: 0.5-1 m/s^2 (no bounce within 0.2 s: the goal is 2.4 m away or more, 0.3 s at 8 m/s).
        assert 0.5 - 1e-9 <= (speed[k] - speed[k + 2]) / (2 * DT) <= 1.0 + 1e-9
        # The bounce: the x velocity reverses at the goal line, slower (restitution 0.4-0.7, and 0.3 s of
        # friction), the y velocity kept. The step of the bounce (turn - 1 or turn) is left out.
        turn = k + int(np.argmax(vel[k:end, 0] < 0.0))
        assert vel[turn, 0] < 0.0 and goal_x - 1.0 < ball[turn - 1 : turn + 2, 0].max() <= goal_x
        before, after = vel[turn - 2], vel[turn + 1]
        assert 0.3 < -after[0] / before[0] < 0.75 and abs(after[1] - before[1]) < 0.2
        # Back: stopped (trapped) short of the robot, then dribbled at up to 1.2 m/s to the next start spot.
        stopped = turn + int(np.argmax(speed[turn:end] == 0.0))
        assert speed[stopped] == 0.0 and stopped < end - 10
        assert 0.2 < speed[stopped:end].max() <= 1.2 + 1e-9 and ball[stopped:end, 0].min() > 1.0
    assert np.all(speed[: kicks[0]] <= 1.2 + 1e-9)
    assert np.linalg.norm(vel, axis=1).max() <= 8.0
    assert info["visible"].mean() > 0.9 and ball[:, 0].max() <= goal_x


def test_shot_speed_matches_the_path(shot):
    seq, info = shot
    ball, speed = info["ball_world"], info["ball_speed"]
    assert speed.shape == (seq.num_steps,) and np.all(speed >= 0.0)
    moved = np.linalg.norm(np.diff(ball, axis=0), axis=1) / DT
    mean = 0.5 * (speed[1:] + speed[:-1])
    error = np.abs(moved - mean)
    # Exact for straight motion at constant deceleration; off only at kicks, bounces, stops and turns.
    assert np.mean(error < 0.02) > 0.9 and np.percentile(error, 98) < 1.0, np.sort(error)[-10:]
    for k in info["shot_steps"]:  # the step after a kick moves at the kick's speed less friction
        assert abs(moved[k] - speed[k]) < 0.1


# --- turning ------------------------------------------------------------------------------------------------------


def test_turning_robot_turns_in_place_left_and_right(turning):
    seq, info = turning
    pose = info["robot_pose"]
    np.testing.assert_array_equal(pose[:, :2], 0.0)
    np.testing.assert_array_equal(pose[0], 0.0)
    omega = np.diff(pose[:, 2]) / DT
    assert 0.7 <= np.abs(omega).max() <= 1.0
    signs = np.sign(omega[np.abs(omega) > 0.05])
    assert np.sum(signs[1:] != signs[:-1]) >= 6  # several left and right turns in 30 s
    assert 0.3 <= np.abs(omega).mean() <= 0.8 and np.abs(np.diff(omega)).max() / DT < 3.0  # smooth
    assert 0.8 < np.ptp(pose[:, 2]) < 1.8  # an oscillation of bounded amplitude, not a spin
    # The camera pose is exact and fixed on the robot.
    np.testing.assert_array_equal(seq.cam_to_base, info["true_cam_to_base"])
    assert np.all(seq.cam_to_base == seq.cam_to_base[0])
    # The turn adds to the ball's motion: it moves faster in the robot's frame than in the world.
    world_motion = np.linalg.norm(np.diff(info["ball_world"], axis=0), axis=1)
    base_motion = np.linalg.norm(np.diff(seq.ground_truth, axis=0), axis=1)
    assert base_motion.mean() > 1.1 * world_motion.mean() and world_motion.max() / DT <= 3.0


def test_turning_odometry_is_noisy_but_close(turning):
    seq, info = turning
    true_odom, odom = info["true_odometry"], seq.odometry
    np.testing.assert_array_equal(odom[0], 0.0)
    np.testing.assert_allclose(true_odom[1:, 2], np.diff(info["robot_pose"][:, 2]), atol=1e-12)
    assert not np.array_equal(odom, true_odom)
    assert np.abs(odom[:, :2]).max() < 0.01  # no translation beyond a few millimetres of noise
    moving = np.abs(true_odom[:, 2]) > 0.02
    rel = (odom[moving, 2] - true_odom[moving, 2]) / true_odom[moving, 2]
    assert 0.03 < rel.std() < 0.15
    heading_error = np.cumsum(odom[:, 2] - true_odom[:, 2])
    assert np.abs(heading_error).max() < 0.25


def test_turning_keeps_the_ball_in_view_a_good_part_of_the_time(turning):
    seq, info = turning
    assert 0.5 <= info["in_view"].mean() < 1.0  # the turn takes the ball out of view now and then
    visible = np.flatnonzero(info["visible"])
    uv, depth = _project(seq.ground_truth[visible], seq)
    assert np.all(depth > 0)
    peaks = np.array([_heat_at(seq.heatmaps[t], uv[i : i + 1])[0] for i, t in enumerate(visible)])
    assert np.mean(peaks > 0.4) > 0.95
