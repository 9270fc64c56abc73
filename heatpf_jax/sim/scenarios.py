"""Simulated evaluation scenarios: the paper's standard setting (Table I) and its edge cases (IV-D).

:func:`simulate` returns a version-1 :class:`~heatpf_jax.Sequence` with ground truth;
:func:`simulate_with_info` also returns per-step facts about what was rendered (for tests and
evaluation). Every scenario is a deterministic function of ``(scenario, seed, num_steps, dt, shrink)``.

The world frame is the robot's base frame at step 0. A humanoid's head camera (0.45-0.7 m high,
pitched down 25-35 degrees) sees a 200 x 150 heat map (``shrink`` divides it); the ball (radius
0.075 m) rolls on smooth random paths at up to 3 m/s (kicked at 5-8 m/s in ``shot``). ``standard``,
``false_positives``, ``occlusion``, ``sparse_rate`` and ``two_balls`` share the standard world of a seed
(camera 0.6 m, 30 degrees, the same ball path and activation noise), so their differences are the
scenario's effect alone.
``two_balls`` adds a second ball; ``shot`` and ``turning`` follow Olufs et al.'s test tours B (a ball
shot at a goal) and C (a robot turning in place).

The worlds are planned in :mod:`heatpf_jax.sim.scenarios_plan` (which holds :data:`SCENARIOS`, re-exported
here) and rendered in :mod:`heatpf_jax.sim.scenarios_render`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from heatpf_jax.io.sequence import Sequence
from heatpf_jax.sim.render import scaled_camera
from heatpf_jax.sim.scenarios_plan import _BUILDERS, SCENARIOS
from heatpf_jax.sim.scenarios_plan import BALL_PEAK as BALL_PEAK  # not in __all__; kept importable here
from heatpf_jax.sim.scenarios_plan import MAX_BALL_SPEED as MAX_BALL_SPEED  # not in __all__; kept importable here
from heatpf_jax.sim.scenarios_plan import NOISE as NOISE  # not in __all__; kept importable here
from heatpf_jax.sim.scenarios_render import _render

__all__ = ["SCENARIOS", "simulate", "simulate_standard", "simulate_with_info"]

DEFAULT_NUM_STEPS = 300


# --- Public entry points ------------------------------------------------------------------------------------------


def _check_args(scenario, seed, num_steps, dt, shrink) -> int:
    if scenario not in SCENARIOS:
        raise ValueError(f"scenario: unknown scenario {scenario!r}; valid names: {', '.join(SCENARIOS)}")
    return check_run_args(seed, num_steps, dt, shrink)


def check_run_args(seed, num_steps, dt, shrink) -> int:
    """Checks a simulation's seed, steps, period and shrink (one line naming the field); the number of steps."""
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    num_steps = DEFAULT_NUM_STEPS if num_steps is None else num_steps
    if isinstance(num_steps, bool) or not isinstance(num_steps, int | np.integer) or num_steps < 1:
        raise ValueError(f"num_steps: must be a positive integer, got {num_steps!r}")
    if not (isinstance(dt, int | float | np.floating) and np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
    if isinstance(shrink, bool) or not isinstance(shrink, int | np.integer) or not 1 <= shrink <= 50:
        raise ValueError(f"shrink: must be an integer in [1, 50], got {shrink!r}")
    return int(num_steps)


def simulate_with_info(
    scenario: str,
    seed: int,
    *,
    num_steps: int | None = None,
    dt: float = 0.1,
    shrink: int = 1,
    occlude: tuple[int, int] | None = None,
    rgb: bool = False,
) -> tuple[Sequence, dict[str, Any]]:
    """Simulates one scenario and reports what was rendered.

    Args:
        scenario: one of :data:`SCENARIOS`.
        seed: non-negative integer; the same arguments give identical arrays.
        num_steps: T (default 300: 30 s at 10 Hz).
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view), for quick tests.
        occlude: optional steps ``(start, stop)`` on which the ball is hidden as well (an occlusion of
            ``stop - start`` steps, e.g. for the long-term memory's re-acquisition test); the world is
            the scenario's own, unchanged.
        rgb: also render RGB frames of the same world into the sequence's ``images``
            (:func:`heatpf_jax.sim.render_rgb.render_rgb`; about 25 ms a 200 x 150 frame).

    Returns:
        ``(sequence, info)``: a validated version-1 sequence with ground truth, and a dict of

        * ``robot_pose`` ``[T, 3]``: (x, y, theta) in the world (the base frame of step 0);
        * ``ball_world`` ``[T, 2]``: ball centre in the world;
        * ``true_odometry`` ``[T, 3]``: the exact motion (the sequence's odometry is noisy in ``walking``);
        * ``true_cam_to_base`` ``[T, 4, 4]``: the pose the heat maps were rendered with (the sequence's
          ``cam_to_base`` is off by 1-2 degrees of pitch in ``walking``);
        * ``in_view`` ``bool [T]``: the ball centre projects inside the image;
        * ``occluded`` ``bool [T]``: the ball is hidden (``occlusion`` windows);
        * ``visible`` ``bool [T]``: the ball is rendered in ``heatmaps[t]`` (a heat map arrives, the ball
          is in view and not occluded);
        * ``ball_peak`` ``[T]``: the ball blob's peak activation (0 where not rendered);
        * ``split`` ``bool [T]``: an occluding stripe cuts the ball blob in two (``split``);
        * ``false_positive_world`` ``[K, 2]``, ``false_positive_radius`` ``[K]``: the spurious places;
        * ``false_positive_on`` ``bool [T, K]``, ``false_positive_peak`` ``[T, K]``: which are rendered, how
          bright; ``false_positive_count`` ``int [T]``: how many are rendered in ``heatmaps[t]``;
        * ``balls_base`` ``[T, B, 2]``: every ball's centre in the base frame of step t, the tracked one
          (``ground_truth``) first: ``B = 2`` in ``two_balls``, 1 elsewhere;
        * ``balls_visible`` ``bool [T, B]``: which balls are rendered in ``heatmaps[t]`` (column 0 is
          ``visible``; other balls are never occluded);

        and in ``two_balls``: ``meeting_steps`` ``int [M]``, the steps where the balls were made to meet
        (centres 0.18-0.26 m apart); in ``shot``: ``ball_speed`` ``[T]``, the ball's world speed
        (m/s, just after the kick at a kick step), ``shot_steps`` ``int [K]``, the steps of the kicks, and
        ``goal_x``, the x of the wall the ball bounces off; in ``turning``: ``localisation_lost`` ``bool [T]``,
        the steps on which the self-localisation (the sequence's ``robot_pose``) has jumped away.

    Raises:
        ValueError: an unknown ``scenario`` (the message lists the valid names) or a bad argument
            (the message names it).
    """
    num_steps = _check_args(scenario, seed, num_steps, dt, shrink)
    dt = float(dt)
    intrinsics, shape = scaled_camera(int(shrink))
    plan = _BUILDERS[scenario](int(seed), num_steps, dt, intrinsics, shape)
    if occlude is not None:
        start, stop = (int(v) for v in occlude)
        if not 0 <= start < stop <= num_steps:
            raise ValueError(f"occlude: must be (start, stop) with 0 <= start < stop <= {num_steps}, got {occlude}")
        hidden = (np.arange(num_steps) >= start) & (np.arange(num_steps) < stop)
        plan.ball_on = (np.ones(num_steps, bool) if plan.ball_on is None else plan.ball_on) & ~hidden
    seq, info = _render(plan, num_steps, dt, intrinsics, shape)
    if rgb:
        from heatpf_jax.sim.render_rgb import render_rgb

        seq = seq._replace(images=render_rgb(seq, info, seed=int(seed)))
    return seq, {"scenario": scenario, "seed": int(seed), **info}


def simulate(
    scenario: str, seed: int, *, num_steps: int | None = None, dt: float = 0.1, shrink: int = 1, rgb: bool = False
) -> Sequence:
    """Simulates one scenario as a validated version-1 sequence with ground truth.

    Scenarios (:data:`SCENARIOS`, 300 steps at 10 Hz by default):

    * ``standard``: static robot, a heat map every step (the paper's Table I setting).
    * ``false_positives``: standard plus 3-5 spurious blobs at fixed world places (goal-post feet, the
      penalty mark, white objects at the field border), each on 30-60 % of the frames in bursts, at least
      one brighter than the ball (Fig. 5).
    * ``split``: a close ball (0.45-1.2 m) whose blob an occluding stripe cuts into two clusters on about
      80 % of the frames (Fig. 7a).
    * ``far``: a distant ball (4.2-6.9 m): a few weak pixels with gaps (Fig. 7b).
    * ``occlusion``: standard, but the ball vanishes for 0.5-2 s windows (2-3 per 30 s) while it moves on.
    * ``walking``: the robot walks (0.1-0.3 m/s) and turns (up to 0.2-0.5 rad/s); noisy odometry, a
      camera pose off by 1-2 degrees of pitch, head sway; the heat maps use the true camera pose.
    * ``sparse_rate``: standard, but heat maps arrive on about a third of the steps, after gaps of 1-6 steps.
    * ``two_balls``: standard plus a second, identical ball (same size and activation) on its own smooth
      path in view, bent so that the balls pass each other (centres 0.18-0.26 m apart) about every 10 s
      and never overlap (centres at least 0.16 m apart). The ground truth is the standard ball.
    * ``shot``: static robot; a ball dribbled to a start spot 1.6-2.4 m ahead is shot at 5-8 m/s, 3-10
      degrees off straight ahead, towards a wall (a goal) 5-6 m ahead; it rolls with a deceleration of
      0.5-1 m/s^2, bounces back (restitution 0.4-0.7), is trapped by a player and dribbled back at about
      1 m/s; a shot about every 10 s (Olufs et al.'s tour B).
    * ``turning``: the robot turns in place, left and right: its yaw swings +-0.5-0.7 rad with a period of
      4-7 s, at up to 0.75-0.95 rad/s; the ball moves on a path like the standard one ahead of the
      middle of the swing and is in view about 80 % of the time. Noisy odometry as in ``walking``; the
      camera pose is exact (Olufs et al.'s tour C). The sequence also holds a self-localisation
      (``robot_pose``, ``pose_confidence``): off by about 2 cm and 0.5 degrees with confidence 0.85-0.98,
      except about 4 times a minute, when it jumps 0.3-1 m and 10-30 degrees away for 1-2.5 s with
      confidence 0.02-0.15 (:func:`~heatpf_jax.sim.world.localisation_poses`).

    ``two_balls``, ``shot`` and ``turning`` make the same world (paths, poses) at every ``shrink``.
    See :func:`simulate_with_info` for the arguments.
    """
    return simulate_with_info(scenario, seed, num_steps=num_steps, dt=dt, shrink=shrink, rgb=rgb)[0]


def simulate_standard(seed: int, num_steps: int = 300, dt: float = 0.1, *, shrink: int = 1) -> Sequence:
    """The paper's Table I setting: a static robot, a heat map every filter step.

    Camera 0.6 m high, pitched down 30 degrees; a ball rolling on a smooth random path in front of it
    at up to 3 m/s. Same as ``simulate("standard", seed, ...)``.

    Args:
        seed: seed of the path and the activation noise.
        num_steps: T.
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view), for quick tests.
    """
    return simulate("standard", seed, num_steps=num_steps, dt=dt, shrink=shrink)
