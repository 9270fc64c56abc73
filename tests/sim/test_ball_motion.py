"""Ball motion: rolling friction, bounces off robots, lofts, pushes, stills, regions, kicked_hidden.

References: brute-force Euler integration on 0.1 ms steps (rolling, bouncing off a circle, flying with
bounces), the closed forms of a constant deceleration, and ``heatpf_jax.sim.world_paths.fits_in_view``.
"""

from __future__ import annotations

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sim.ball_motion import (
    GRAVITY,
    MOTION_KINDS,
    bounced_path,
    box_region,
    compose_motion,
    kicked_hidden_motion,
    kicked_path,
    lofted_path,
    pushed_path,
    stopped_path,
    view_region,
    wander_path,
)
from heatpf_jax.sim.world_paths import fits_in_view

DT = 0.1
BIG = box_region((0.5, 12.0), 6.0)
INTRINSICS = np.array([143.0, 143.0, 99.5, 74.5])


def _brute_roll(pos, vel, decel, times, *, obstacle=None, restitution=0.0, radius=0.075, h=1e-4):
    """Euler on ``h`` steps from time 0 (a robot ``obstacle = (x, y, r)`` reflects the ball): positions at ``times``."""
    pos, vel = np.array(pos, float), np.array(vel, float)
    marks = np.round(np.asarray(times) / h).astype(int)
    out = []
    for i in range(marks[-1] + 1):
        out += [pos.copy()] * int(np.sum(marks == i))
        speed = np.hypot(*vel)
        if speed > 0:
            vel = vel * max(speed - decel * h, 0.0) / speed
        pos = pos + vel * h
        if obstacle is not None:
            gap = pos - obstacle[:2]
            if np.hypot(*gap) < obstacle[2] + radius and vel @ gap < 0:
                n = gap / np.hypot(*gap)
                vel = vel - (1 + restitution) * (vel @ n) * n
    return np.array(out)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kicked_ball_slows_linearly_at_the_deceleration_until_it_stops(seed):
    rng = np.random.default_rng(seed)
    decel = rng.uniform(0.3, 1.2)
    motion = kicked_path(rng, 80, DT, BIG, decel=decel, kick_speed=(0.5, 3.0))
    kicks = [e for e in motion.events if e.kind == "kick" and e.step < 60]
    assert kicks and not any(e.kind == "trap" for e in motion.events)
    for kick in kicks:
        k, v0, t_kick = kick.step, kick.speed, kick.time
        steps = np.arange(k, min(80, int(np.ceil((t_kick + v0 / decel) / DT)) + 3))  # to a little past the stop
        tau = steps * DT - t_kick
        # The speed decreases linearly at decel from the kick's exact time, and stays 0 once the ball stops...
        np.testing.assert_allclose(np.hypot(*motion.velocities[steps].T), np.maximum(v0 - decel * tau, 0.0),
                                   atol=1e-9)
        # ... and the positions are those of a brute-force integration from the kick (the ball lay still before).
        direction = motion.velocities[k] / np.hypot(*motion.velocities[k])
        ref = _brute_roll(motion.positions[k - 1], direction * v0, decel, tau)
        np.testing.assert_allclose(motion.positions[steps], ref, atol=1e-3)


def test_kicks_stay_in_the_allowed_speeds_and_stop_inside_the_region():
    rng = np.random.default_rng(3)
    region = box_region((1.0, 5.0), 1.5)
    speeds = []
    for _ in range(6):
        motion = kicked_path(rng, 150, DT, region, decel=rng.uniform(0.3, 1.2), kick_speed=(0.5, 2.5))
        speeds += [e.speed for e in motion.events if e.kind == "kick"]
        still = motion.phase == "still"
        assert region.contains(motion.positions[still]).all()
    assert 0.5 <= min(speeds) and max(speeds) <= 2.5 and len(speeds) > 10


def test_bounce_reflects_off_the_robot_with_restitution():
    rng = np.random.default_rng(4)
    checked = 0
    for _ in range(6):
        decel, e = rng.uniform(0.3, 1.2), rng.uniform(0.3, 0.8)
        motion = bounced_path(rng, 60, DT, BIG, decel=decel, restitution=e)
        kicks = [ev for ev in motion.events if ev.kind == "bounce"]
        hits = [ev for ev in motion.events if ev.kind == "hit"]
        for (x, y, r), (start, stop) in zip(motion.obstacles, motion.obstacle_steps, strict=True):
            kick = next(ev for ev in kicks if ev.step == start)
            if any(ev.step <= start for ev in hits if ev.time >= kick.time) or stop - start < 3:
                continue  # the first sampled step already after the hit: no clean direction
            assert any(kick.time < ev.time for ev in hits)  # every robot kicked at is hit
            traps = [ev.step for ev in motion.events if ev.kind == "trap" and ev.time > kick.time]
            steps = np.arange(start, min([stop, *traps]))  # a ball that leaves the region is trapped
            tau = steps * DT - kick.time
            gap = motion.positions[start] - motion.positions[start - 1]
            ref = _brute_roll(motion.positions[start - 1], gap / np.hypot(*gap) * kick.speed, decel, tau,
                              obstacle=np.array([x, y, r]), restitution=e)
            np.testing.assert_allclose(motion.positions[steps], ref, atol=2e-3)
            checked += 1
    assert checked >= 3


def _flights(heights: np.ndarray) -> list[float]:
    """The apex of each flight of a sampled height trace."""
    apexes, current = [], 0.0
    for z in heights:
        if z > 0:
            current = max(current, z)
        elif current > 0:
            apexes.append(current)
            current = 0.0
    return apexes


def test_loft_flies_on_parabolas_that_shrink_by_the_restitution_squared():
    rng = np.random.default_rng(6)
    dt = 0.005  # fine steps: the sampled apexes are the true ones to a millimetre
    for _ in range(3):
        e = rng.uniform(0.4, 0.6)
        motion = lofted_path(rng, 600, dt, box_region((0.5, 8.0), 4.0), decel=0.5, loft_restitution=e, substeps=4)
        loft = next(ev for ev in motion.events if ev.kind == "loft")
        air = np.flatnonzero(motion.in_air)
        assert air.size and (motion.heights >= 0).all()
        np.testing.assert_array_equal(motion.heights[~motion.in_air], 0.0)
        apexes = _flights(motion.heights[loft.step :])
        assert 0.3 - 1e-3 <= apexes[0] <= 1.4
        ratios = np.array(apexes[1:4]) / np.array(apexes[:3])
        np.testing.assert_allclose(ratios[ratios > 0], e**2, atol=0.02)
        # The first flight is a parabola with g = 9.81 (brute force from its take-off).
        vz = np.sqrt(2 * GRAVITY * apexes[0])
        t = np.arange(loft.step, loft.step + 40) * dt - loft.time
        np.testing.assert_allclose(motion.heights[loft.step : loft.step + 40], vz * t - 0.5 * GRAVITY * t**2,
                                   atol=2e-3)
        # The horizontal velocity is constant in the air.
        vel = motion.velocities[air[: np.argmax(np.diff(air) > 1)] if np.any(np.diff(air) > 1) else air]
        assert np.ptp(vel, axis=0).max() < 1e-9


def test_pushes_are_slow_and_smooth():
    rng = np.random.default_rng(7)
    for push_speed in (0.1, 0.35, 0.6):
        motion = pushed_path(rng, 200, DT, box_region((0.5, 4.0), 1.5), push_speed=push_speed)
        speed = np.hypot(*motion.velocities.T)
        assert speed.max() <= min(0.6, 1.25 * push_speed) + 1e-9
        accel = np.hypot(*np.diff(motion.velocities, axis=0).T) / DT
        assert accel.max() <= 0.5 + 0.2 + 1e-6  # and a stop from below 2 cm/s at the target
        assert any(e.kind == "push" for e in motion.events)


def test_stills_last_their_time_and_a_stopped_ball_never_moves():
    rng = np.random.default_rng(8)
    motion = compose_motion(rng, 300, DT, box_region((0.5, 5.0), 2.0), weights=MOTION_KINDS["mixed"], decel=0.8,
                            stop_s=2.0)
    stills = [(a, b) for a, b in zip(motion.events[:-1], motion.events[1:], strict=True) if a.kind == "still"]
    assert len(stills) >= 3
    for a, b in stills[1:]:
        assert 2.0 * 0.6 - DT <= b.time - a.time <= 2.0 * 1.4 + DT
        assert np.ptp(motion.positions[a.step : b.step], axis=0).max() < 1e-12 if b.step > a.step else True
    still = stopped_path(rng, 50, DT, BIG)
    assert np.ptp(still.positions, axis=0).max() == 0.0 and not still.velocities.any()


def test_view_region_is_in_view_and_paths_stay_in_it():
    rng = np.random.default_rng(9)
    cam = hp.camera.camera_pose(height=0.6, pitch=np.deg2rad(30.0))
    region = view_region(INTRINSICS, cam, (150, 200), x_range=(0.2, 6.5), radius=0.075, fill=1.0)
    assert region.x[0] > 0.4  # the near end is cut where the ball does not fit
    points = [region.sample(rng) for _ in range(200)]
    assert all(fits_in_view(p, INTRINSICS, cam, (150, 200), radius=0.075, margin_px=1.0) for p in points)
    for kind in ("mixed", "pushed", "bounced"):
        motion = compose_motion(rng, 300, DT, region, weights=MOTION_KINDS[kind], decel=0.6)
        assert region.contains(motion.positions).mean() > 0.95
    wander = wander_path(rng, 300, DT, region, max_speed=0.5)
    assert region.contains(wander).all()
    assert np.hypot(*np.diff(wander, axis=0).T).max() / DT <= 0.5 + 1e-9


def test_same_generator_same_motion():
    a = compose_motion(np.random.default_rng(10), 100, DT, BIG, weights=MOTION_KINDS["mixed"], decel=0.6)
    b = compose_motion(np.random.default_rng(10), 100, DT, BIG, weights=MOTION_KINDS["mixed"], decel=0.6)
    np.testing.assert_array_equal(a.positions, b.positions)
    assert a.events == b.events
    with pytest.raises(ValueError, match="unknown event kinds"):
        compose_motion(np.random.default_rng(0), 10, DT, BIG, weights={"dribble": 1.0}, decel=0.6)


@pytest.mark.parametrize("seed", [0, 1])
def test_kicked_hidden_rolls_straight_through_its_windows(seed):
    region = box_region((1.0, 6.0), 2.5)
    motion, windows = kicked_hidden_motion(np.random.default_rng(seed), 300, DT, region)
    assert len(windows) >= 2
    for w in windows:
        assert 0.4 <= w.speed <= 1.0 and 0.02 <= w.decel <= 0.5
        assert 1.0 - 1e-9 <= (w.start - w.kick) * DT <= 1.5 + 1e-9
        assert 1.5 - 1e-9 <= (w.stop - w.start) * DT <= 2.0 + 1e-9
        assert 2.0 <= (w.after - w.stop) * DT <= 3.0 + DT or w.after == 300
        rolled = np.hypot(*(motion.positions[w.stop] - motion.positions[w.start]))
        assert rolled == pytest.approx(w.distance, abs=1e-6) and 0.6 <= rolled <= 1.1
        # Constant deceleration from the kick: v(t) = v0 - a t, on a straight line.
        t = (np.arange(w.kick, w.after) - w.kick) * DT
        t = t[w.speed - w.decel * t > 0]  # it may stop before `after` (and be pushed to the next start)
        steps = w.kick + np.arange(len(t))
        np.testing.assert_allclose(np.hypot(*motion.velocities[steps].T), w.speed - w.decel * t, atol=1e-9)
        d = motion.positions[steps] - motion.positions[w.kick]
        u = motion.velocities[w.kick] / w.speed
        np.testing.assert_allclose(d[:, 0] * u[1] - d[:, 1] * u[0], 0.0, atol=1e-9)
    assert region.contains(motion.positions).all()
