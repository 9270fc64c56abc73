"""Ball motion in the world frame: pushed, kicked and rolling, bounced off robots, stopped, lofted.

A path is composed of events, each starting from where the last one left the ball:

* **kick**: the ball rolls in a straight line with a constant deceleration ``decel`` (rolling friction,
  0.3-1.2 m/s^2 on artificial turf) until it stops. The kick speed is the one that stops the ball at a
  random target in the region, ``sqrt(2 decel d)``, kept within ``kick_speed`` (0.5-3 m/s after KidSize
  scaling); the direction points at the target.
* **bounce**: a kick at a robot standing in the way: a circle of radius 0.1-0.2 m (a foot) placed at
  35-70 % of the way to the target, offset sideways by up to 0.7 of the contact distance. On contact the
  velocity's normal part is reversed and scaled by the restitution, its tangential part kept. The robot
  stands there until the ball stops (:attr:`BallMotion.obstacles`).
* **push**: pushed by hand or dribbled: slow (0.1-0.6 m/s), smooth (accelerations up to 0.5 m/s^2),
  along a bent line through a waypoint up to 0.3 of the distance to the side, to a target 0.3-1.5 m away.
* **loft**: a chip or lob: the ball flies on a parabola (gravity 9.81 m/s^2, no drag) whose apex (the
  ball's lowest point above the ground) is drawn from ``loft_apex`` (0.3-1.4 m); each landing reverses and
  scales the vertical speed by ``loft_restitution`` (0.4-0.6), the horizontal velocity is kept; once a
  bounce would rise less than 1 cm the ball rolls (as after a kick). The horizontal speed is the one that
  brings the ball to rest at a random target in the region (flights plus roll), within ``kick_speed``.
* **still**: between events the ball lies still for ``stop_s`` times ``U(0.6, 1.4)`` seconds (``stop_s``
  1-4 s); the first still lasts 0.2-1 s.

A rolling ball that leaves the region is trapped by a player: 3 m/s^2 more deceleration until it stops.
The motion is integrated on ``substeps`` sub-steps of each step (exact for a constant deceleration and for
the flights, landings included) and sampled at the steps. :func:`kicked_hidden_motion` makes the
``kicked_hidden`` world: straight rolls that pass behind a robot. Regions live in
:mod:`heatpf_jax.sim.ball_region` and the mechanics (the integration) in :mod:`heatpf_jax.sim.ball_physics`;
this module re-exports their public names. NumPy only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from heatpf_jax.sim.ball_physics import (
    GRAVITY,
    BallMotion,
    MotionEvent,
    _air_time,
    _fly,
    _push,
    _Recorder,
    _roll,
    _still,
)
from heatpf_jax.sim.ball_physics import TRAP_DECEL as TRAP_DECEL  # not in __all__; kept importable here
from heatpf_jax.sim.ball_region import Region, box_region, view_region
from heatpf_jax.sim.world_events import smooth_signal
from heatpf_jax.sim.world_paths import slow_down

__all__ = [
    "EVENT_KINDS",
    "GRAVITY",
    "MOTION_KINDS",
    "BallMotion",
    "HiddenWindow",
    "MotionEvent",
    "Region",
    "bounced_path",
    "box_region",
    "compose_motion",
    "kicked_hidden_motion",
    "kicked_path",
    "lofted_path",
    "pushed_path",
    "stopped_path",
    "view_region",
    "wander_path",
]

EVENT_KINDS = ("kick", "push", "bounce", "loft")
# A motion kind's event weights (``compose_motion(weights=...)``).
MOTION_KINDS: dict[str, dict[str, float]] = {
    "mixed": {"kick": 0.45, "push": 0.35, "bounce": 0.2},
    "kicked": {"kick": 1.0},
    "pushed": {"push": 1.0},
    "bounced": {"bounce": 1.0},
    "lofted": {"loft": 1.0},
}


# --- Results ------------------------------------------------------------------------------------------------------


class HiddenWindow(NamedTuple):
    """One kick of :func:`kicked_hidden_motion` (steps; the ball is hidden on ``[start, stop)``).

    Attributes:
        kick: the step of the kick (the ball rolls from there).
        start: the first hidden step.
        stop: the first step it is seen again.
        after: the end of the 2-3 s after ``stop`` (distractors stay on until then).
        speed: the kick speed, m/s.
        decel: the rolling deceleration, m/s^2.
        distance: how far the ball rolls from ``start`` to ``stop``, metres.
    """

    kick: int
    start: int
    stop: int
    after: int
    speed: float
    decel: float
    distance: float


# --- Choices ------------------------------------------------------------------------------------------------------


def _target(rng: np.random.Generator, pos: np.ndarray, region: Region, lo: float, hi: float) -> np.ndarray:
    """A point of the region ``lo``-``hi`` metres from ``pos`` (the nearest try to that band otherwise)."""
    best, best_miss = region.sample(rng), np.inf
    for _ in range(200):
        cand = region.sample(rng)
        d = float(np.hypot(*(cand - pos)))
        miss = max(lo - d, d - hi, 0.0)
        if miss == 0.0:
            return cand
        if miss < best_miss:
            best, best_miss = cand, miss
    return best


def _kick_velocity(
    rng: np.random.Generator, pos: np.ndarray, region: Region, decel: float, kick_speed: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """A kick that stops the ball at a target in the region: ``(velocity [2], target [2])``."""
    lo_d = max(kick_speed[0] ** 2 / (2.0 * decel), 0.3)
    hi_d = max(kick_speed[1] ** 2 / (2.0 * decel), lo_d)
    target = _target(rng, pos, region, lo_d, hi_d)
    gap = target - pos
    dist = max(float(np.hypot(*gap)), 1e-9)
    speed = float(np.clip(np.sqrt(2.0 * decel * dist), *kick_speed))
    return gap / dist * speed, target


def _loft_velocity(
    rng: np.random.Generator,
    pos: np.ndarray,
    region: Region,
    decel: float,
    kick_speed: tuple[float, float],
    air: float,
) -> np.ndarray:
    """The horizontal velocity of a loft that comes to rest at a target in the region (``air`` s aloft)."""

    def reach(v: float) -> float:
        return v * air + v**2 / (2.0 * decel)

    target = _target(rng, pos, region, max(reach(kick_speed[0]), 0.3), max(reach(kick_speed[1]), 0.3))
    gap = target - pos
    dist = max(float(np.hypot(*gap)), 1e-9)
    speed = decel * (-air + np.sqrt(air**2 + 2.0 * dist / decel))
    return gap / dist * float(np.clip(speed, *kick_speed))


# --- Composition --------------------------------------------------------------------------------------------------


def compose_motion(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    region: Region,
    *,
    weights: dict[str, float],
    decel: float,
    kick_speed: tuple[float, float] = (0.5, 3.0),
    push_speed: float = 0.3,
    stop_s: float = 2.0,
    restitution: float = 0.5,
    loft_apex: tuple[float, float] = (0.3, 1.4),
    loft_restitution: float = 0.5,
    obstacle_radius: tuple[float, float] = (0.1, 0.2),
    ball_radius: float = 0.075,
    start: np.ndarray | None = None,
    substeps: int = 20,
) -> BallMotion:
    """A path of random events (see the module docstring), each drawn with ``weights``, stills in between.

    Args:
        rng: the source of every draw.
        num_steps: T.
        dt: step, seconds.
        region: where the ball is kept (targets are drawn in it; a ball rolling out is trapped).
        weights: ``event kind -> weight`` over :data:`EVENT_KINDS` (e.g. a value of :data:`MOTION_KINDS`).
        decel: rolling deceleration, m/s^2.
        kick_speed: the kick speeds allowed, m/s.
        push_speed: the typical push speed, m/s (each push ``U(0.75, 1.25)`` times it, within 0.1-0.6).
        stop_s: the typical still time between events, seconds.
        restitution: of a ball bouncing off a robot.
        loft_apex: the range of a loft's apex, metres.
        loft_restitution: of a landing ball (vertical).
        obstacle_radius: the range of the radius of a robot the ball is kicked at.
        ball_radius: metres (for the contact with a robot).
        start: ``[2]`` the ball's place at step 0 (default: drawn in the region).
        substeps: integration sub-steps per step.

    Returns:
        The :class:`BallMotion`.
    """
    unknown = set(weights) - set(EVENT_KINDS)
    if unknown:
        raise ValueError(f"weights: unknown event kinds {sorted(unknown)}; valid: {', '.join(EVENT_KINDS)}")
    kinds = list(weights)
    p = np.array([weights[k] for k in kinds], np.float64)
    p = p / p.sum()
    rec = _Recorder(num_steps, dt, substeps)
    pos = region.sample(rng) if start is None else np.array(start, np.float64)
    rec.event("still", 0.0)
    _still(rec, pos, rng.uniform(0.2, 1.0))
    while not rec.full:
        kind = kinds[int(rng.choice(len(kinds), p=p))]
        if kind in ("kick", "bounce"):
            vel, target = _kick_velocity(rng, pos, region, decel, kick_speed)
            obstacle = None
            if kind == "bounce":
                r_obs = rng.uniform(*obstacle_radius)
                frac, side = rng.uniform(0.35, 0.7), rng.uniform(-0.7, 0.7)
                gap = target - pos
                dist = float(np.hypot(*gap))
                contact = r_obs + ball_radius
                if frac * dist - contact > 0.1:
                    unit = gap / max(dist, 1e-12)
                    centre = pos + frac * gap + side * contact * np.array([-unit[1], unit[0]])
                    obstacle = (float(centre[0]), float(centre[1]), float(r_obs))
                else:
                    kind = "kick"
            rec.event(kind, float(np.hypot(*vel)))
            first = rec.n
            pos, _ = _roll(rec, pos, vel, decel, region=region, obstacle=obstacle, restitution=restitution,
                           ball_radius=ball_radius)
            if obstacle is not None:
                rec.obstacles.append(obstacle)
                rec.obstacle_steps.append([rec.step_at(first), min(rec.step_at(rec.n), num_steps)])
        elif kind == "push":
            speed = float(np.clip(push_speed * rng.uniform(0.75, 1.25), 0.1, 0.6))
            target = _target(rng, pos, region, 0.3, 1.5)
            gap = target - pos
            via = pos + 0.5 * gap + rng.uniform(-0.3, 0.3) * np.array([-gap[1], gap[0]])
            if not region.contains(via):
                via = pos + 0.5 * gap
            rec.event("push", speed)
            pos = _push(rec, pos, [via, target], speed)
        else:  # loft
            apex = rng.uniform(*loft_apex)
            vz = float(np.sqrt(2.0 * GRAVITY * apex))
            vel = _loft_velocity(rng, pos, region, decel, kick_speed, _air_time(vz, loft_restitution))
            rec.event("loft", float(np.hypot(*vel)))
            pos = _fly(rec, pos, vel, vz, loft_restitution)
            pos, _ = _roll(rec, pos, vel, decel, region=region)
        if rec.full:
            break
        rec.event("still", 0.0)
        _still(rec, pos, stop_s * rng.uniform(0.6, 1.4))
    return rec.result()


def kicked_path(rng, num_steps, dt, region, *, decel, **kwargs) -> BallMotion:
    """Kicks only: the ball rolls with deceleration ``decel`` to a stop, lies still, is kicked again."""
    return compose_motion(rng, num_steps, dt, region, weights=MOTION_KINDS["kicked"], decel=decel, **kwargs)


def pushed_path(rng, num_steps, dt, region, *, push_speed=0.3, decel=0.6, **kwargs) -> BallMotion:
    """Pushes only: slow, smooth moves from target to target with stills in between."""
    return compose_motion(rng, num_steps, dt, region, weights=MOTION_KINDS["pushed"], decel=decel,
                          push_speed=push_speed, **kwargs)


def bounced_path(rng, num_steps, dt, region, *, decel, restitution=0.5, **kwargs) -> BallMotion:
    """Kicks at robots standing in the way: each roll bounces off one (:attr:`BallMotion.obstacles`)."""
    return compose_motion(rng, num_steps, dt, region, weights=MOTION_KINDS["bounced"], decel=decel,
                          restitution=restitution, **kwargs)


def lofted_path(rng, num_steps, dt, region, *, decel, loft_apex=(0.3, 1.4), loft_restitution=0.5,
                **kwargs) -> BallMotion:
    """Lofts only: flights up to ``loft_apex``, bounces with ``loft_restitution``, rolls, stills."""
    return compose_motion(rng, num_steps, dt, region, weights=MOTION_KINDS["lofted"], decel=decel,
                          loft_apex=loft_apex, loft_restitution=loft_restitution, **kwargs)


def stopped_path(rng, num_steps, dt, region, *, start=None) -> BallMotion:
    """A ball lying still all the time (at ``start`` or a point drawn in the region)."""
    rec = _Recorder(num_steps, dt, 1)
    pos = region.sample(rng) if start is None else np.array(start, np.float64)
    rec.event("still", 0.0)
    _still(rec, pos, num_steps * dt)
    return rec.result()


def wander_path(
    rng: np.random.Generator, num_steps: int, dt: float, region: Region, *, max_speed: float, fill: float = 0.9
) -> np.ndarray:
    """A smooth random path in the region (as :func:`heatpf_jax.sim.world_paths.view_path`), at most ``max_speed``.

    Returns:
        ``float64 [T, 2]``.
    """
    a = smooth_signal(rng, num_steps, dt)
    b = smooth_signal(rng, num_steps, dt)
    x = region.x[0] + 0.5 * (a + 1.0) * (region.x[-1] - region.x[0])
    half = np.minimum(np.interp(x, region.x, region.half_width), np.sqrt(np.maximum(region.max_distance**2 - x**2, 0)))
    return slow_down(np.stack([x, fill * b * half], axis=-1), dt, max_speed)


# --- kicked_hidden ------------------------------------------------------------------------------------------------


def _straight_roll_length(speed: float, decel: float, free: float, trap: float) -> float:
    """How far a ball kicked at ``speed`` rolls: ``decel`` for ``free`` s, then ``decel + trap`` until it stops."""
    t1 = min(free, speed / decel)
    left = max(speed - decel * t1, 0.0)
    return speed * t1 - 0.5 * decel * t1**2 + left**2 / (2.0 * (decel + trap))


def kicked_hidden_motion(
    rng: np.random.Generator,
    num_steps: int,
    dt: float,
    region: Region,
    *,
    speed: tuple[float, float] = (0.4, 1.0),
    seen: tuple[float, float] = (1.0, 1.5),
    hidden: tuple[float, float] = (1.5, 2.0),
    hidden_distance: tuple[float, float] = (0.6, 1.1),
    after: tuple[float, float] = (2.0, 3.0),
    trap_decel: tuple[float, float] = (1.5, 2.5),
    decel: tuple[float, float] = (0.02, 0.5),
    push_speed: tuple[float, float] = (0.3, 0.6),
    wait: tuple[float, float] = (1.0, 2.0),
    substeps: int = 20,
) -> tuple[BallMotion, list[HiddenWindow]]:
    """Straight rolls that pass behind a robot: kick, seen, hidden, seen again, trapped; then the next kick.

    Each kick rolls the ball in a straight line at ``speed`` (m/s); it is seen for ``seen`` s, hidden for
    ``hidden`` s while it rolls ``hidden_distance`` metres, seen again for ``after`` s, then trapped
    (``trap_decel`` m/s^2 more) to a stop. Kicks come on steps and ``seen`` and ``hidden`` are rounded to
    whole steps, so the windows are exact in steps. The deceleration follows from the draws,
    ``(v0 H - D) / (S H + H^2 / 2)`` (kick speed ``v0``, seen ``S``, hidden ``H`` and distance ``D``), and is
    redrawn until it lies in ``decel`` and the ball still rolls when it reappears. The start and direction
    are drawn so that the whole roll lies in the region; the ball lies there 0.2-0.5 s before the first
    kick, and is pushed (``push_speed``) to the next start, where it waits ``wait`` s.

    Returns:
        ``(motion, windows)``: the :class:`BallMotion` and a :class:`HiddenWindow` per kick that starts
        within the run (``stop`` and ``after`` cut at T).
    """
    rec = _Recorder(num_steps, dt, substeps)
    h = rec.h
    pos, windows = None, []
    while not rec.full:
        for _ in range(10_000):
            v0, s, hide, dist = (rng.uniform(*speed), rng.uniform(*seen), rng.uniform(*hidden),
                                 rng.uniform(*hidden_distance))
            s, hide = round(s / dt) * dt, round(hide / dt) * dt  # on the step grid
            a = (v0 * hide - dist) / (s * hide + 0.5 * hide**2)
            if decel[0] <= a <= decel[1] and v0 - a * (s + hide) > 0.05:
                break
        extra, trap = rng.uniform(*after), rng.uniform(*trap_decel)
        length = _straight_roll_length(v0, a, s + hide + extra, trap)
        along = np.linspace(0.0, length, max(2, int(length / 0.1) + 2))
        for _ in range(500):
            start = region.sample(rng)
            angle = rng.uniform(0.0, 2.0 * np.pi)
            unit = np.array([np.cos(angle), np.sin(angle)])
            if region.contains(start + along[:, None] * unit).all():
                break
        if pos is None:
            pos = start
            rec.event("still", 0.0)
            _still(rec, pos, rng.uniform(0.2, 0.5))
        else:
            speed_push = float(rng.uniform(*push_speed))
            rec.event("push", speed_push)
            pos = _push(rec, pos, [start], speed_push)
            rec.event("still", 0.0)
            _still(rec, pos, rng.uniform(*wait))
        _still(rec, pos, ((-rec.n) % substeps) * h)  # the kick comes on a step
        if rec.full:
            break
        kick = rec.n
        rec.event("kick", v0)
        pos, _ = _roll(rec, pos, unit * v0, a, trap_after=s + hide + extra, trap_decel=trap)
        first, last = kick + round(s / h), kick + round((s + hide) / h)
        start_step, stop_step = rec.step_at(first), rec.step_at(last)
        travelled = v0 * (s + hide) - 0.5 * a * (s + hide) ** 2 - (v0 * s - 0.5 * a * s**2)
        windows.append(HiddenWindow(
            kick=rec.step_at(kick), start=min(start_step, num_steps), stop=min(stop_step, num_steps),
            after=min(rec.step_at(kick + round((s + hide + extra) / h)), num_steps), speed=float(v0),
            decel=float(a), distance=float(travelled)))
    windows = [w for w in windows if w.kick < num_steps]
    return rec.result(), windows
