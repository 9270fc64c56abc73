"""The ball's mechanics: rolling, bouncing off a robot, pushes, flights and landings, integrated exactly.

A ``_Recorder`` holds the fine samples (``substeps`` per step) and the :class:`MotionEvent` s of a
path and turns them into a :class:`BallMotion` sampled at the steps; ``_still``, ``_roll`` (constant
deceleration, a robot it may meet, a trap once it leaves the region), ``_push`` and ``_fly`` (with
``_air_time``) append to it. The events these make, and when, are :mod:`heatpf_jax.sim.ball_motion`'s
(see its docstring), which re-exports the public names here. NumPy only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from heatpf_jax.sim.ball_region import Region

__all__ = ["GRAVITY", "TRAP_DECEL", "BallMotion", "MotionEvent"]

GRAVITY = 9.81  # m/s^2
TRAP_DECEL = 3.0  # m/s^2 added when a rolling ball leaves the region
_MIN_BOUNCE = np.sqrt(2.0 * GRAVITY * 0.01)  # vertical speed of a 1 cm bounce
_PUSH_ACCEL = 0.5  # m/s^2


# --- Results ------------------------------------------------------------------------------------------------------


class MotionEvent(NamedTuple):
    """One event of a composed path.

    Attributes:
        kind: ``still``, ``kick``, ``bounce`` (a kick at a robot), ``push``, ``loft``, ``hit`` (the ball
            meets the robot), ``trap`` (a rolling ball left the region).
        step: the first step at or after the event.
        time: seconds from step 0.
        speed: the ball's speed just after the event, m/s (the horizontal speed for a loft).
    """

    kind: str
    step: int
    time: float
    speed: float


class BallMotion(NamedTuple):
    """A ball's motion sampled at the steps.

    Attributes:
        positions: ``[T, 2]`` the ground point under the ball (world frame).
        heights: ``[T]`` the ball's lowest point above the ground (0 on the ground).
        velocities: ``[T, 2]`` horizontal velocity, m/s.
        in_air: ``bool [T]`` airborne.
        phase: ``[T]`` what it does: ``still``, ``roll``, ``push``, ``air``.
        events: the events in order.
        obstacles: ``[K, 3]`` the robots it was kicked at: ``(x, y, radius)``.
        obstacle_steps: ``int [K, 2]`` the steps ``[start, stop)`` each robot stands there.
    """

    positions: np.ndarray
    heights: np.ndarray
    velocities: np.ndarray
    in_air: np.ndarray
    phase: np.ndarray
    events: tuple[MotionEvent, ...]
    obstacles: np.ndarray
    obstacle_steps: np.ndarray


# --- Integration --------------------------------------------------------------------------------------------------


class _Recorder:
    """Fine samples at times ``k h``; full once the last step's sample is in."""

    def __init__(self, num_steps: int, dt: float, substeps: int):
        self.num_steps, self.dt, self.substeps = num_steps, dt, substeps
        self.h = dt / substeps
        self.size = (num_steps - 1) * substeps + 1
        self.pos = np.zeros((self.size, 2))
        self.vel = np.zeros((self.size, 2))
        self.z = np.zeros(self.size)
        self.phase = np.empty(self.size, dtype="<U5")
        self.n = 0
        self.events: list[MotionEvent] = []
        self.obstacles: list[tuple[float, float, float]] = []
        self.obstacle_steps: list[list[int]] = []

    @property
    def full(self) -> bool:
        return self.n >= self.size

    @property
    def time(self) -> float:
        return self.n * self.h

    def step_at(self, index: int) -> int:
        return int(-(-index // self.substeps))

    def add(self, pos, vel, z: float, phase: str) -> None:
        if self.n < self.size:
            self.pos[self.n], self.vel[self.n], self.z[self.n], self.phase[self.n] = pos, vel, z, phase
        self.n += 1

    def event(self, kind: str, speed: float) -> None:
        self.events.append(MotionEvent(kind, min(self.step_at(self.n), self.num_steps), self.time, float(speed)))

    def result(self) -> BallMotion:
        every = slice(0, self.size, self.substeps)
        z = self.z[every].copy()
        obstacles = np.array(self.obstacles, np.float64).reshape(-1, 3)
        return BallMotion(
            positions=self.pos[every].copy(),
            heights=z,
            velocities=self.vel[every].copy(),
            in_air=self.phase[every] == "air",
            phase=self.phase[every].copy(),
            events=tuple(self.events),
            obstacles=obstacles,
            obstacle_steps=np.array(self.obstacle_steps, np.int64).reshape(-1, 2),
        )


def _still(rec: _Recorder, pos: np.ndarray, duration: float) -> None:
    for _ in range(int(round(duration / rec.h))):
        if rec.full:
            return
        rec.add(pos, (0.0, 0.0), 0.0, "still")


def _roll(
    rec: _Recorder,
    pos: np.ndarray,
    vel: np.ndarray,
    decel: float,
    *,
    region: Region | None = None,
    obstacle: tuple[float, float, float] | None = None,
    restitution: float = 0.5,
    ball_radius: float = 0.075,
    trap_after: float = np.inf,
    trap_decel: float = TRAP_DECEL,
) -> tuple[np.ndarray, np.ndarray]:
    """Rolls with constant deceleration until the ball stops (trapped after ``trap_after`` s or off the region)."""
    pos, vel = np.array(pos, np.float64), np.array(vel, np.float64)
    h, elapsed, trapped = rec.h, 0.0, False
    speed = float(np.hypot(*vel))
    while speed > 0.0 and not rec.full:
        rec.add(pos, vel, 0.0, "roll")
        if not trapped and elapsed >= trap_after - 1e-9:
            trapped = True
        slow = decel + (trap_decel if trapped else 0.0)
        pos, vel, speed, left = _advance(pos, vel, speed, slow, h, obstacle, ball_radius)
        if left is not None:  # met the robot `left` seconds before the sub-step's end: reflect, roll on
            normal = (pos - np.asarray(obstacle[:2])) / (obstacle[2] + ball_radius)
            vel = vel - (1.0 + restitution) * (vel @ normal) * normal
            speed = float(np.hypot(*vel))
            rec.event("hit", speed)
            if speed > 0.0:
                pos, vel, speed, _ = _advance(pos, vel, speed, slow, left, None, ball_radius)
        elapsed += h
        if region is not None and not trapped and not region.contains(pos):
            trapped = True
            rec.event("trap", speed)
    return pos, np.zeros(2)


def _advance(pos, vel, speed, slow, duration, obstacle, ball_radius):
    """A straight roll at constant deceleration ``slow`` for ``duration`` s, exact; stops at a robot it meets.

    Returns:
        ``(pos, vel, speed, left)``: ``left`` is the time left when the ball met the robot (else ``None``).
    """
    unit = vel / speed
    new = max(speed - slow * duration, 0.0)
    travel = (speed**2 - new**2) / (2.0 * slow)  # exact, also when the ball stops within the duration
    if obstacle is not None:
        gap = pos - np.asarray(obstacle[:2])
        b, c = gap @ unit, gap @ gap - (obstacle[2] + ball_radius) ** 2
        if b < 0.0 and b * b - c >= 0.0:  # approaching, and the line meets the contact circle
            hit = max(-b - np.sqrt(b * b - c), 0.0)
            if hit <= travel:
                at = float(np.sqrt(max(speed**2 - 2.0 * slow * hit, 0.0)))
                return pos + unit * hit, unit * at, at, duration - (speed - at) / slow
    return pos + unit * travel, unit * new, new, None


def _push(rec: _Recorder, pos: np.ndarray, waypoints: list[np.ndarray], speed: float) -> np.ndarray:
    """Moves the ball through ``waypoints`` at up to ``speed`` with accelerations up to 0.5 m/s^2; stops at the last."""
    pos, vel, h = np.array(pos, np.float64), np.zeros(2), rec.h
    for i, target in enumerate(waypoints):
        last = i == len(waypoints) - 1
        for _ in range(int(60.0 / h)):  # a push lasts at most a minute
            if rec.full:
                return pos
            gap = target - pos
            dist = float(np.hypot(*gap))
            if last and dist < 0.003 and np.hypot(*vel) < 0.02:
                return target.copy()
            if not last and dist < 0.1:
                break
            rec.add(pos, vel, 0.0, "push")
            want = gap / max(dist, 1e-12) * (min(speed, np.sqrt(2.0 * _PUSH_ACCEL * dist)) if last else speed)
            change = want - vel
            size = float(np.hypot(*change))
            vel = vel + change * min(1.0, _PUSH_ACCEL * h / max(size, 1e-12))
            pos = pos + vel * h
    return pos


def _air_time(vz: float, restitution: float) -> float:
    """Seconds in the air, bounces included, from a take-off at vertical speed ``vz``."""
    total = 0.0
    while vz >= _MIN_BOUNCE:
        total += 2.0 * vz / GRAVITY
        vz *= restitution
    return total


def _fly(rec: _Recorder, pos: np.ndarray, vel: np.ndarray, vz: float, restitution: float) -> np.ndarray:
    """Flies and bounces (exact landings inside sub-steps) until a bounce would rise less than 1 cm."""
    pos, vel, h, z = np.array(pos, np.float64), np.array(vel, np.float64), rec.h, 0.0
    while not rec.full:
        rec.add(pos, vel, z, "air")
        land = (vz + np.sqrt(vz**2 + 2.0 * GRAVITY * z)) / GRAVITY
        pos = pos + vel * h
        if land <= h:
            up = -restitution * (vz - GRAVITY * land)
            if up < _MIN_BOUNCE:
                return pos
            rest = h - land
            z, vz = up * rest - 0.5 * GRAVITY * rest**2, up - GRAVITY * rest
        else:
            z, vz = z + vz * h - 0.5 * GRAVITY * h**2, vz - GRAVITY * h
    return pos
