"""The world family: every scenario type with its nuisance factors drawn per seed from wide ranges.

:func:`simulate_family` makes member ``member``'s world number ``seed``: a version-1 :class:`~heatpf_jax.Sequence`
with ground truth. Its factors (camera, calibration, latency, timing, detector, background, false
positives, ball motion, robot) are a deterministic function of ``(member, seed)``, drawn from a stream of
their own (:func:`draw_factors`), independent of other members and of ``num_steps`` and ``shrink``; the
world (paths, poses, events) is planned in the full-size camera, so it is the same at every ``shrink``.
:func:`simulate_family_with_info` also returns ``info["factors"]`` (the flat dict of every factor) and the
per-step facts :func:`heatpf_jax.sim.simulate_with_info` documents. With ``fixed=True`` a member is
today's scenario of the same name (:data:`heatpf_jax.sim.SCENARIOS`), unchanged, for comparison.

Members (:data:`FAMILY`): ``standard`` (a static robot, the ball's events in view), ``false_positives``
(2-5 spurious blobs, at least one brighter than the ball), ``split`` (a close ball, 0.45-1.3 m, whose blob
a stripe cuts on 50-90 % of the frames), ``occlusion`` (the ball hidden in 2-4 windows per 30 s of
0.5-2.5 s), ``walking`` (the robot walks after the ball: gait sway, noisy odometry), ``sparse_rate`` (heat
maps dropped in bursts, 40-75 % of the steps), ``far`` (the ball 4-7 m away, weaker and patchier),
``lofted`` (chips and lobs: flights up to 0.3-1.4 m, bounces, rolls; the camera looks up more) and
``kicked_hidden`` (straight rolls at 0.4-1 m/s, hidden behind a robot for 1.5-2 s while rolling 0.6-1.1 m,
with 0-2 distractor blobs during the hiding and 2-3 s after).

Factors (uniform unless said; ``a/b/c``: a uniform choice; per FP: a tuple, one value per false positive;
k.h.: kicked_hidden):

| factor                 | default range            | members that differ                                   |
|------------------------|--------------------------|-------------------------------------------------------|
| camera_height_m        | 0.45-0.75                |                                                       |
| camera_pitch_deg       | 22-38 (down)             | split 30-42, far 16-24, lofted 12-22, k.h. 22-35      |
| fx_scale               | 0.85-1.2 (fx = fy = 143 fx_scale at 200 x 150)     |                                  |
| cx_offset_px           | -5-5 (principal point, px of 200 x 150)            |                                  |
| cy_offset_px           | -5-5                     |                                                       |
| calibration_error_deg  | 1-3: the angle between the sequence's cam_to_base and the true one |                  |
| calibration_axis_deg   | 0-360: the error's axis in the optical x-z plane (0: pitch, 90: roll) |               |
| latency_steps          | 0/1/2: heat map t shows the world of step t - latency |                          |
| rate_pattern           | regular/jittered/bursty  | sparse_rate bursty                                    |
| drop_rate              | 0-0.3 (share of steps without a heat map) | sparse_rate 0.4-0.75                 |
| drop_burst_steps       | 2-8 (mean burst of drops, bursty)    |                                           |
| blob_shape ... line_strength | :data:`heatpf_jax.sim.detector.DETECTOR_RANGES` | far: peak 0.4-0.8, dropout 0.05-0.3 |
| region_near_m          | 0.4 m (the view may cut it) | split 0.45, far 4, lofted 1.5, kicked_hidden 1, walking 0.9 |
| region_far_m           | 3-6.5 m                  | split 1-1.3, far 7, lofted 4.5-6.5, walking 3-4.5, k.h. 4-6 |
| ball_motion            | mixed/kicked/pushed/bounced | split pushed/mixed; lofted, kicked_hidden: their own  |
| friction_decel         | 0.3-1.2 m/s^2            | k.h. 0 (its own per kick: info hidden_kicks)          |
| kick_speed_max         | 1.5-3 m/s (kicks 0.5 m/s up to it) | split 0.8-1.5, k.h. 0 (0.4-1 per kick)      |
| push_speed             | 0.1-0.6 m/s              | lofted 0 (no pushes), k.h. 0 (0.3-0.6 per push)       |
| stop_s                 | 1-4 s (stills of ``U(0.6, 1.4)`` times it between events) | k.h. 0 (1-2 s)       |
| bounce_restitution     | 0.3-0.8 (off robots)     | lofted 0, k.h. 0 (no robots in the way)               |
| loft_restitution       | 0 (no lofts)             | lofted 0.4-0.6 (landings; apexes 0.3-1.4 m per loft)  |
| robot_motion           | static                   | walking follow                                        |
| walk_speed_max         | 0                        | walking 0.1-0.3 m/s                                   |
| turn_rate_max          | 0                        | walking 0.3-0.7 rad/s                                 |
| keep_distance_m        | 0                        | walking 0.8-1.6 (the robot walks up to this far)      |
| odometry_noise         | 0                        | walking 0.05-0.1 (multiplicative std)                 |
| gait_frequency_hz      | 0                        | walking 1.6-2 (steps a second; sway at half of it)    |
| gait_roll_deg          | 0                        | walking 0.5-2 (head roll at the stride frequency)     |
| gait_pitch_deg         | 0                        | walking 0.3-1 (head pitch at the step frequency)      |
| gait_height_m          | 0                        | walking 0.005-0.015 (bob at the step frequency)       |
| gait_sway_m            | 0                        | walking 0.01-0.02 (sideways at the stride frequency)  |
| fp_count               | 0-2 (integers)           | false_positives 2-5, kicked_hidden 0                  |
| fp_brightness          | per FP 0.6-1.4 times the ball's peak (capped at 1); false_positives: one at least 1.05 | |
| fp_moving              | per FP False/True (static or on a smooth path; 0.4-6.5 m ahead, in view) |       |
| fp_radius_m            | per FP 0.05-0.3, log-uniform (ball-sized up to 0.12, large above) |              |
| fp_on_fraction         | per FP 0.3-1 (share of frames it is on) |                                        |
| fp_burst_s             | per FP 0.3-3 s (mean length of an on burst: flicker) |                           |
| fp_speed               | per FP 0.1-0.8 m/s (moving ones) |                                               |
| hide_count             | 0                        | occlusion 2-4 windows per 30 s                        |
| hide_seconds_max       | 0                        | occlusion 1-2.5 (each window 0.5 s up to it)          |
| split_rate             | 0                        | split 0.5-0.9 (share of frames cut, in 2 s bursts)    |
| stripe_width           | 0                        | split 0.2-0.5 (ball radii)                            |
| stripe_tilt_deg        | 0                        | split 0-40 (the stripe's largest tilt from vertical)  |
| distractors            | 0                        | kicked_hidden 0/1/2 (blobs per hiding)                |
| distractor_brightness  | 0                        | kicked_hidden 0.7-1.1 times the ball's peak           |

``occlusion_rate`` (a detector factor) hides part of the ball (a band or a half plane, one per 1 s burst)
on that share of the frames in every member. :func:`factor_ranges` gives the ranges of a member and the
tests check every draw against them. NumPy only.

The factors are drawn in :mod:`heatpf_jax.sim.family_factors` (whose public names this module re-exports),
the world planned in :mod:`heatpf_jax.sim.family_plan` and rendered in :mod:`heatpf_jax.sim.family_render`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from heatpf_jax.io.sequence import Sequence
from heatpf_jax.sim.family_factors import (
    FAMILY,
    MAX_FALSE_POSITIVES,
    Factor,
    _check_member,
    draw_factors,
    factor_ranges,
)
from heatpf_jax.sim.family_plan import _plan
from heatpf_jax.sim.family_render import _render
from heatpf_jax.sim.scenarios import check_run_args

__all__ = [
    "FAMILY",
    "MAX_FALSE_POSITIVES",
    "Factor",
    "draw_factors",
    "factor_ranges",
    "simulate_family",
    "simulate_family_with_info",
]

DEFAULT_NUM_STEPS = 300


# --- Public entry points ------------------------------------------------------------------------------------------


_check_args = check_run_args


def simulate_family_with_info(
    member: str,
    seed: int,
    *,
    num_steps: int | None = None,
    dt: float = 0.1,
    shrink: int = 1,
    overrides: Mapping[str, Any] | None = None,
    fixed: bool = False,
) -> tuple[Sequence, dict[str, Any]]:
    """Simulates world ``seed`` of ``member`` and reports its factors and what was rendered.

    Args:
        member: one of :data:`FAMILY`.
        seed: non-negative integer; the same arguments give identical arrays.
        num_steps: T (default 300: 30 s at 10 Hz).
        dt: filter period, seconds.
        shrink: integer divisor of the 200 x 150 heat map (same field of view; the same world).
        overrides: factors to pin (see :func:`draw_factors`).
        fixed: today's scenario of the same name instead (:func:`heatpf_jax.sim.simulate_with_info`;
            ``lofted`` and ``kicked_hidden`` have none); its ``info["factors"]`` is empty.

    Returns:
        ``(sequence, info)``: a validated version-1 sequence with ground truth (the ground point under the
        ball, also in the air), and a dict with ``member``, ``seed``, ``fixed``, ``factors`` (the flat
        dict of :func:`draw_factors`) and the keys of :func:`heatpf_jax.sim.simulate_with_info`
        (``robot_pose``, ``ball_world``, ``true_odometry``, ``true_cam_to_base`` (the true camera at step
        t; the sequence's ``cam_to_base`` is it rotated by the calibration error), ``in_view``,
        ``occluded``, ``visible``, ``ball_peak``, ``split``, ``false_positive_world`` (``[K, 2]`` at step
        0), ``false_positive_radius``, ``false_positive_on``, ``false_positive_peak``,
        ``false_positive_count``, ``balls_base``, ``balls_visible``), where the per-frame ones describe
        heat map t, which shows the world of step ``render_step[t] = max(t - latency, 0)``; and

        * ``ball_height`` ``[T]``: the ball's lowest point above the ground; ``in_air`` ``bool [T]``;
        * ``ball_speed`` ``[T]``: its horizontal speed, m/s; ``ball_events``: its
          :class:`~heatpf_jax.sim.ball_physics.MotionEvent` s; ``obstacles`` ``[K, 3]`` and ``obstacle_steps``
          ``int [K, 2]``: the robots it bounced off;
        * ``render_step`` ``int [T]``; ``partly_occluded`` ``bool [T]``: a band or half plane hides part of
          the ball in heat map t;
        * ``false_positive_path`` ``[T, K, 2]``: every false positive's world place at each step
          (distractors included);
        * in ``occlusion`` and ``kicked_hidden``: ``hidden`` ``int [W, 2]``, the world steps ``[start, stop)``
          in which the ball is hidden;
        * in ``kicked_hidden``: ``hidden_kicks``, a :class:`~heatpf_jax.sim.ball_motion.HiddenWindow` per
          window (the kick's step and speed, the deceleration, the distance rolled while hidden, the end of
          the 2-3 s after it); ``distractor_world`` ``[M, 2]`` and ``distractor_on`` ``bool [T, M]`` (world
          steps; the last ``M`` columns of the false-positive arrays, ``distractors`` per window in order).

    Raises:
        ValueError: an unknown member (the message lists the valid names), factor or bad argument.
    """
    _check_member(member)
    num_steps = _check_args(seed, num_steps, dt, shrink)
    dt = float(dt)
    if fixed:
        from heatpf_jax.sim.scenarios import SCENARIOS, simulate_with_info

        if member not in SCENARIOS:
            raise ValueError(f"fixed: {member!r} has no fixed scenario; those with one: "
                             f"{', '.join(m for m in FAMILY if m in SCENARIOS)}")
        if overrides:
            raise ValueError("overrides: a fixed scenario has no factors to pin")
        seq, info = simulate_with_info(member, int(seed), num_steps=num_steps, dt=dt, shrink=int(shrink))
        return seq, {**info, "member": member, "fixed": True, "factors": {}}
    factors = draw_factors(member, int(seed), overrides=overrides)
    world = _plan(member, int(seed), factors, num_steps, dt)
    seq, info = _render(world, factors, int(seed), member, num_steps, dt, int(shrink))
    return seq, {"scenario": member, "member": member, "seed": int(seed), "fixed": False, "factors": factors, **info}


def simulate_family(
    member: str,
    seed: int,
    *,
    num_steps: int | None = None,
    dt: float = 0.1,
    shrink: int = 1,
    overrides: Mapping[str, Any] | None = None,
    fixed: bool = False,
) -> Sequence:
    """World ``seed`` of ``member`` as a validated version-1 sequence (see :func:`simulate_family_with_info`)."""
    return simulate_family_with_info(member, seed, num_steps=num_steps, dt=dt, shrink=shrink, overrides=overrides,
                                     fixed=fixed)[0]
