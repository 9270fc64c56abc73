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
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from heatpf_jax.camera import camera_pose
from heatpf_jax.sequence import Sequence, validate_sequence
from heatpf_jax.sim.ball_motion import (
    MOTION_KINDS,
    BallMotion,
    compose_motion,
    kicked_hidden_motion,
    view_region,
    wander_path,
)
from heatpf_jax.sim.detector import (
    DETECTOR_RANGES,
    DetectorFactors,
    Occluder,
    SceneObject,
    clutter_field,
    render_frame,
    sphere_outline,
)
from heatpf_jax.sim.render import BALL_RADIUS, DEFAULT_INTRINSICS, HEATMAP_SHAPE
from heatpf_jax.sim.scenarios import check_run_args
from heatpf_jax.sim.world import (
    bursty_mask,
    compose_pose,
    odometry_from_poses,
    random_windows,
    smooth_signal,
    world_to_base,
)

__all__ = [
    "FAMILY",
    "MAX_FALSE_POSITIVES",
    "Factor",
    "draw_factors",
    "factor_ranges",
    "simulate_family",
    "simulate_family_with_info",
]

# New members go at the end: each member's random streams are seeded with its index here.
FAMILY = (
    "standard",
    "false_positives",
    "split",
    "occlusion",
    "walking",
    "sparse_rate",
    "far",
    "lofted",
    "kicked_hidden",
)
MAX_FALSE_POSITIVES = 5
DEFAULT_NUM_STEPS = 300
_STREAM = 7919  # the family's streams: default_rng([seed, member index, 7919, purpose])


class Factor(NamedTuple):
    """How one factor is drawn.

    Attributes:
        low, high: the range of a uniform (or log-uniform, or inclusive integer) draw; equal for a fixed value.
        choices: the values of a uniform choice (``low``/``high`` unused).
        integer: draw an integer in ``[low, high]``.
        log: draw log-uniformly.
        per_object: one value per false positive (a tuple of ``fp_count`` values).
    """

    low: Any = None
    high: Any = None
    choices: tuple | None = None
    integer: bool = False
    log: bool = False
    per_object: bool = False

    @property
    def fixed(self) -> bool:
        return self.choices is None and self.low == self.high


def _u(lo, hi, **kw) -> Factor:
    return Factor(float(lo), float(hi), **kw)


def _fixed(value) -> Factor:
    return Factor(value, value)


def _base_specs() -> dict[str, Factor]:
    specs = {
        "camera_height_m": _u(0.45, 0.75),
        "camera_pitch_deg": _u(22.0, 38.0),
        "fx_scale": _u(0.85, 1.2),
        "cx_offset_px": _u(-5.0, 5.0),
        "cy_offset_px": _u(-5.0, 5.0),
        "calibration_error_deg": _u(1.0, 3.0),
        "calibration_axis_deg": _u(0.0, 360.0),
        "latency_steps": Factor(0, 2, integer=True),
        "rate_pattern": Factor(choices=("regular", "jittered", "bursty")),
        "drop_rate": _u(0.0, 0.3),
        "drop_burst_steps": _u(2.0, 8.0),
    }
    for name, spec in DETECTOR_RANGES.items():
        specs[name] = Factor(choices=tuple(spec)) if isinstance(spec[0], str) else _u(*spec)
    specs.update({
        "region_near_m": _fixed(0.4),
        "region_far_m": _u(3.0, 6.5),
        "ball_motion": Factor(choices=("mixed", "kicked", "pushed", "bounced")),
        "friction_decel": _u(0.3, 1.2),
        "kick_speed_max": _u(1.5, 3.0),
        "push_speed": _u(0.1, 0.6),
        "stop_s": _u(1.0, 4.0),
        "bounce_restitution": _u(0.3, 0.8),
        "loft_restitution": _fixed(0.0),
        "robot_motion": _fixed("static"),
        "walk_speed_max": _fixed(0.0),
        "turn_rate_max": _fixed(0.0),
        "keep_distance_m": _fixed(0.0),
        "odometry_noise": _fixed(0.0),
        "gait_frequency_hz": _fixed(0.0),
        "gait_roll_deg": _fixed(0.0),
        "gait_pitch_deg": _fixed(0.0),
        "gait_height_m": _fixed(0.0),
        "gait_sway_m": _fixed(0.0),
        "fp_count": Factor(0, 2, integer=True),
        "fp_brightness": _u(0.6, 1.4, per_object=True),
        "fp_moving": Factor(choices=(False, True), per_object=True),
        "fp_radius_m": _u(0.05, 0.3, log=True, per_object=True),
        "fp_on_fraction": _u(0.3, 1.0, per_object=True),
        "fp_burst_s": _u(0.3, 3.0, per_object=True),
        "fp_speed": _u(0.1, 0.8, per_object=True),
        "hide_count": _fixed(0),
        "hide_seconds_max": _fixed(0.0),
        "split_rate": _fixed(0.0),
        "stripe_width": _fixed(0.0),
        "stripe_tilt_deg": _fixed(0.0),
        "distractors": _fixed(0),
        "distractor_brightness": _fixed(0.0),
    })
    return specs


_MEMBER_SPECS: dict[str, dict[str, Factor]] = {
    "standard": {},
    "false_positives": {"fp_count": Factor(2, 5, integer=True)},
    "split": {
        "camera_pitch_deg": _u(30.0, 42.0),
        "region_near_m": _fixed(0.45),
        "region_far_m": _u(1.0, 1.3),
        "ball_motion": Factor(choices=("pushed", "mixed")),
        "kick_speed_max": _u(0.8, 1.5),
        "split_rate": _u(0.5, 0.9),
        "stripe_width": _u(0.2, 0.5),
        "stripe_tilt_deg": _u(0.0, 40.0),
    },
    "occlusion": {"hide_count": Factor(2, 4, integer=True), "hide_seconds_max": _u(1.0, 2.5)},
    "walking": {
        "region_near_m": _fixed(0.9),
        "region_far_m": _u(3.0, 4.5),
        "robot_motion": _fixed("follow"),
        "walk_speed_max": _u(0.1, 0.3),
        "turn_rate_max": _u(0.3, 0.7),
        "keep_distance_m": _u(0.8, 1.6),
        "odometry_noise": _u(0.05, 0.1),
        "gait_frequency_hz": _u(1.6, 2.0),
        "gait_roll_deg": _u(0.5, 2.0),
        "gait_pitch_deg": _u(0.3, 1.0),
        "gait_height_m": _u(0.005, 0.015),
        "gait_sway_m": _u(0.01, 0.02),
    },
    "sparse_rate": {"rate_pattern": _fixed("bursty"), "drop_rate": _u(0.4, 0.75)},
    "far": {
        "camera_pitch_deg": _u(16.0, 24.0),
        "peak": _u(0.4, 0.8),
        "dropout": _u(0.05, 0.3),
        "region_near_m": _fixed(4.0),
        "region_far_m": _fixed(7.0),
    },
    "lofted": {
        "camera_pitch_deg": _u(12.0, 22.0),
        "region_near_m": _fixed(1.5),
        "region_far_m": _u(4.5, 6.5),
        "ball_motion": _fixed("lofted"),
        "push_speed": _fixed(0.0),
        "bounce_restitution": _fixed(0.0),
        "loft_restitution": _u(0.4, 0.6),
    },
    "kicked_hidden": {
        "camera_pitch_deg": _u(22.0, 35.0),
        "region_near_m": _fixed(1.0),
        "region_far_m": _u(4.0, 6.0),
        "ball_motion": _fixed("kicked_hidden"),
        **{name: _fixed(0.0) for name in ("friction_decel", "kick_speed_max", "push_speed", "stop_s",
                                          "bounce_restitution")},
        "fp_count": _fixed(0),
        "distractors": Factor(0, 2, integer=True),
        "distractor_brightness": _u(0.7, 1.1),
    },
}


def _check_member(member: str) -> int:
    if member not in FAMILY:
        raise ValueError(f"member: unknown member {member!r}; valid names: {', '.join(FAMILY)}")
    return FAMILY.index(member)


def factor_ranges(member: str) -> dict[str, Factor]:
    """Every factor of ``member`` and how it is drawn, in drawing order (see the module docstring's table)."""
    _check_member(member)
    return {**_base_specs(), **_MEMBER_SPECS[member]}


def _rng(seed: int, member: str, purpose: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), FAMILY.index(member), _STREAM, purpose])


def _draw(rng: np.random.Generator, spec: Factor):
    """One draw (``MAX_FALSE_POSITIVES`` for a per-object factor); a fixed factor draws nothing."""
    size = MAX_FALSE_POSITIVES if spec.per_object else None
    if spec.choices is not None:
        idx = rng.integers(len(spec.choices), size=size)
        return tuple(spec.choices[int(i)] for i in idx) if size else spec.choices[int(idx)]
    if spec.fixed:
        return (spec.low,) * MAX_FALSE_POSITIVES if size else spec.low
    if spec.integer:
        value = rng.integers(spec.low, spec.high + 1, size=size)
        return tuple(int(v) for v in value) if size else int(value)
    if spec.log:
        value = np.exp(rng.uniform(np.log(spec.low), np.log(spec.high), size=size))
    else:
        value = rng.uniform(spec.low, spec.high, size=size)
    return tuple(float(v) for v in value) if size else float(value)


def draw_factors(member: str, seed: int, *, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The factors of world ``seed`` of ``member``: a flat dict ``name -> value`` (drawn, then ``overrides``).

    Cheap (no paths, no rendering): the same dict :func:`simulate_family_with_info` records. Per-object
    factors are tuples of ``fp_count`` values.

    Args:
        member: one of :data:`FAMILY`.
        seed: non-negative integer.
        overrides: ``name -> value`` pinning some factors (e.g. ``{"distractors": 0}``: the same world without
            distractors); the other draws do not change. A per-object factor takes a tuple (of at least
            ``fp_count`` values) or one value for every object.

    Raises:
        ValueError: an unknown member or factor name.
    """
    specs = factor_ranges(member)
    rng = _rng(seed, member, 0)
    values = {name: _draw(rng, spec) for name, spec in specs.items()}
    if member == "false_positives":
        # At least one place outshines the ball: the brightest of the first fp_count, raised if needed.
        lift = float(rng.uniform(1.05, 1.4))
        bright = list(values["fp_brightness"])
        k = int(np.argmax(bright[: values["fp_count"]]))
        if bright[k] < 1.05:
            bright[k] = lift
        values["fp_brightness"] = tuple(bright)
    for name, value in (overrides or {}).items():
        if name not in specs:
            raise ValueError(f"overrides: unknown factor {name!r} of {member!r}")
        if specs[name].per_object and not isinstance(value, tuple | list):
            value = (value,) * MAX_FALSE_POSITIVES
        values[name] = tuple(value) if specs[name].per_object else value
    count = int(values["fp_count"])
    if not 0 <= count <= MAX_FALSE_POSITIVES:
        raise ValueError(f"overrides: fp_count must lie in [0, {MAX_FALSE_POSITIVES}], got {count}")
    for name, spec in specs.items():
        if spec.per_object:
            if len(values[name]) < count:
                raise ValueError(f"overrides: {name} needs {count} values, got {len(values[name])}")
            values[name] = tuple(values[name][:count])
    return values


# --- The world ----------------------------------------------------------------------------------------------------


class _World(NamedTuple):
    """A planned world; per-step arrays have a leading axis T."""

    motion: BallMotion
    robot_pose: np.ndarray  # [T, 3]
    true_cam: np.ndarray  # [T, 4, 4] the camera at step t
    given_cam: np.ndarray  # [T, 4, 4] what the sequence says
    given_odometry: np.ndarray  # [T, 3]
    has_heatmap: np.ndarray  # [T] bool
    ball_on: np.ndarray  # [T] bool: not hidden (world steps)
    occluder: list  # [T] Occluder or None (world steps)
    split: np.ndarray  # [T] bool: the occluder is the split stripe
    ball_peak: np.ndarray  # [T]
    fp_path: np.ndarray  # [T, K, 2] world
    fp_radius: np.ndarray  # [K]
    fp_peak: np.ndarray  # [T, K], 0 where off (world steps)
    extra_info: dict


def _full_camera(f: Mapping[str, Any]) -> np.ndarray:
    """The intrinsics of the 200 x 150 heat map for the drawn camera."""
    fx = DEFAULT_INTRINSICS[0] * f["fx_scale"]
    return np.array([fx, fx, DEFAULT_INTRINSICS[2] + f["cx_offset_px"], DEFAULT_INTRINSICS[3] + f["cy_offset_px"]])


def _shrunk(intrinsics: np.ndarray, shrink: int) -> tuple[np.ndarray, tuple[int, int]]:
    """As :func:`heatpf_jax.sim.render.scaled_camera`, for any full-size intrinsics."""
    offset = (shrink - 1) / 2.0
    fx, fy, cx, cy = intrinsics
    return (np.array([fx / shrink, fy / shrink, (cx - offset) / shrink, (cy - offset) / shrink]),
            (HEATMAP_SHAPE[0] // shrink, HEATMAP_SHAPE[1] // shrink))


def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def _calibration_rotation(f: Mapping[str, Any]) -> np.ndarray:
    """The calibration error as a rotation of the optical frame: ``R_given = R_true @ E``."""
    phi = np.deg2rad(f["calibration_axis_deg"])
    return _axis_rotation(np.array([np.cos(phi), 0.0, np.sin(phi)]), np.deg2rad(f["calibration_error_deg"]))


def _cameras(f: Mapping[str, Any], num_steps: int, dt: float, rng: np.random.Generator):
    """True and given camera poses ``[T, 4, 4]``: gait sway (walking) and the calibration error."""
    t = np.arange(num_steps) * dt
    height, pitch = f["camera_height_m"], np.deg2rad(f["camera_pitch_deg"])
    stride = np.pi * f["gait_frequency_hz"] * t + rng.uniform(0.0, 2.0 * np.pi)  # half the step frequency
    roll = np.deg2rad(f["gait_roll_deg"]) * np.sin(stride)
    sway = f["gait_sway_m"] * np.sin(stride)
    bob_pitch = np.deg2rad(f["gait_pitch_deg"]) * np.sin(2.0 * stride)
    bob_height = f["gait_height_m"] * np.sin(2.0 * stride + 0.5)
    true = np.stack([camera_pose(height=height + bob_height[i], pitch=pitch + bob_pitch[i], roll=roll[i], y=sway[i])
                     for i in range(num_steps)])
    given = true.copy()
    given[:, :3, :3] = true[:, :3, :3] @ _calibration_rotation(f)
    return true, given


def _has_heatmap(f: Mapping[str, Any], num_steps: int, rng: np.random.Generator) -> np.ndarray:
    drop = float(f["drop_rate"])
    if f["rate_pattern"] == "regular":
        has = rng.uniform(size=num_steps) >= drop
    elif f["rate_pattern"] == "jittered":  # gaps of 1-3 steps: 1 + Binomial(2, p), a share `drop` of steps dropped
        p = drop / (2.0 * (1.0 - drop))
        has, t = np.zeros(num_steps, bool), int(rng.integers(0, 2))
        while t < num_steps:
            has[t] = True
            t += 1 + int(rng.binomial(2, p))
    else:
        has = ~bursty_mask(rng, num_steps, drop, f["drop_burst_steps"]) if drop > 0 else np.ones(num_steps, bool)
    if not has.any():
        has[0] = True
    return has


def _follow_poses(rng, ball: np.ndarray, dt: float, f: Mapping[str, Any]) -> np.ndarray:
    """A robot walking after the ball: it turns towards where it saw the ball 0.3 s ago and walks up to it."""
    num_steps = ball.shape[0]
    lag = max(1, int(round(0.3 / dt)))
    sideways = 0.03 * smooth_signal(rng, num_steps, dt, freqs=(0.02, 0.1))
    poses = np.zeros((num_steps, 3))
    for t in range(1, num_steps):
        rel = world_to_base(poses[t - 1], ball[max(t - 1 - lag, 0)])
        bearing, dist = float(np.arctan2(rel[1], rel[0])), float(np.hypot(*rel))
        turn = np.clip(1.5 * bearing, -f["turn_rate_max"], f["turn_rate_max"])
        speed = np.clip(0.6 * (dist - f["keep_distance_m"]), 0.0, f["walk_speed_max"]) * max(np.cos(bearing), 0.0)
        poses[t] = compose_pose(poses[t - 1], np.array([speed * dt, sideways[t] * dt, turn * dt]))
    return poses


def _occluders(rng, num_steps: int, dt: float, rate: float) -> list:
    """Partial occlusion: on a share ``rate`` of the steps (1 s bursts) a band or half plane, one per burst."""
    out = [None] * num_steps
    if rate <= 0.0:
        return out
    on = bursty_mask(rng, num_steps, rate, 1.0 / dt)
    edges = np.diff(np.r_[0, on.astype(int), 0])
    for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        if rng.uniform() < 0.5:
            occ = Occluder(rng.uniform(0.0, 2.0 * np.pi), rng.uniform(-0.3, 0.6), np.inf)
        else:
            occ = Occluder(rng.uniform(-0.5, 0.5) * np.pi, rng.uniform(-0.5, 0.5), rng.uniform(0.3, 0.8))
        out[start:stop] = [occ] * (stop - start)
    return out


def _plan(member: str, seed: int, f: Mapping[str, Any], num_steps: int, dt: float) -> _World:
    world, fx = _rng(seed, member, 1), _rng(seed, member, 3)
    full = _full_camera(f)
    true_cam, given_cam = _cameras(f, num_steps, dt, fx)
    nominal = camera_pose(height=f["camera_height_m"], pitch=np.deg2rad(f["camera_pitch_deg"]))
    region = view_region(full, nominal, HEATMAP_SHAPE, x_range=(f["region_near_m"], f["region_far_m"]),
                         radius=BALL_RADIUS, max_distance=f["region_far_m"] if member == "far" else np.inf)
    # False positives may be anywhere a ball could be seen (not only where this member keeps its ball).
    fp_region = view_region(full, nominal, HEATMAP_SHAPE, x_range=(0.4, 6.5), radius=BALL_RADIUS)
    extra: dict[str, Any] = {}
    ball_on = np.ones(num_steps, bool)
    if f["ball_motion"] == "kicked_hidden":
        motion, windows = kicked_hidden_motion(world, num_steps, dt, region)
        for w in windows:
            ball_on[w.start : w.stop] = False
        extra["hidden"] = np.array([(w.start, w.stop) for w in windows], np.int64).reshape(-1, 2)
        extra["hidden_kicks"] = windows
    else:
        motion = compose_motion(
            world, num_steps, dt, region, weights=MOTION_KINDS[f["ball_motion"]], decel=f["friction_decel"],
            kick_speed=(0.5, f["kick_speed_max"]), push_speed=f["push_speed"], stop_s=f["stop_s"],
            restitution=f["bounce_restitution"], loft_restitution=f["loft_restitution"])
    if f["robot_motion"] == "follow":
        poses = _follow_poses(world, motion.positions, dt, f)
        true_odom = odometry_from_poses(poses)
        noisy = true_odom * (1.0 + f["odometry_noise"] * fx.standard_normal(true_odom.shape))
        noisy += np.array([0.001, 0.001, 0.002]) * fx.standard_normal(true_odom.shape)
        noisy[0] = 0.0
    else:
        poses = np.zeros((num_steps, 3))
        noisy = np.zeros((num_steps, 3))
    if f["hide_count"] > 0:
        count = max(1, int(round(f["hide_count"] * num_steps * dt / 30.0)))
        lengths = (max(1, int(round(0.5 / dt))), max(1, int(round(f["hide_seconds_max"] / dt))))
        windows = random_windows(fx, num_steps, count, lengths, min_gap=max(1, int(round(1.0 / dt))),
                                 start_after=max(1, int(round(1.5 / dt))))
        for start, stop in windows:
            ball_on[start:stop] = False
        extra["hidden"] = np.array(windows, np.int64).reshape(-1, 2)
    occluder = _occluders(fx, num_steps, dt, f["occlusion_rate"])
    split = np.zeros(num_steps, bool)
    if f["split_rate"] > 0.0:
        split = bursty_mask(fx, num_steps, f["split_rate"], 2.0 / dt)
        tilt = np.deg2rad(f["stripe_tilt_deg"]) * smooth_signal(fx, num_steps, dt, freqs=(0.05, 0.2))
        offset = 0.2 * smooth_signal(fx, num_steps, dt, freqs=(0.1, 0.4))
        for t in np.flatnonzero(split):
            occluder[t] = Occluder(float(tilt[t]), float(offset[t]), float(f["stripe_width"]))
    peak = np.clip(f["peak"] + f["peak_jitter"] * fx.standard_normal(num_steps), 0.2, 1.0)
    # False positives: static places or smooth paths in the region, flickering in bursts.
    count = int(f["fp_count"])
    paths, radii, peaks = [], [], []
    for k in range(count):
        if f["fp_moving"][k]:
            paths.append(wander_path(world, num_steps, dt, fp_region, max_speed=f["fp_speed"][k]))
        else:
            paths.append(np.repeat(fp_region.sample(world)[None], num_steps, axis=0))
        radii.append(f["fp_radius_m"][k])
        on = bursty_mask(fx, num_steps, f["fp_on_fraction"][k], f["fp_burst_s"][k] / dt)
        level = np.clip(f["fp_brightness"][k] * f["peak"] + 0.03 * fx.standard_normal(num_steps), 0.2, 1.0)
        peaks.append(np.where(on, level, 0.0))
    # kicked_hidden's distractors: ball-like blobs near where the ball vanished and where it comes back.
    distractors, distractor_on = [], []
    for w in extra.get("hidden_kicks", []) if f["distractors"] > 0 else []:
        for j in range(int(f["distractors"])):
            anchor = motion.positions[min(w.start if j == 0 else w.stop, num_steps - 1)]
            place = anchor
            for _ in range(100):
                angle, dist = world.uniform(0.0, 2.0 * np.pi), world.uniform(0.3, 0.9)
                place = anchor + dist * np.array([np.cos(angle), np.sin(angle)])
                if region.contains(place):
                    break
            on = (np.arange(num_steps) >= w.start) & (np.arange(num_steps) < w.after)
            level = np.clip(f["distractor_brightness"] * f["peak"] + 0.03 * fx.standard_normal(num_steps), 0.2, 1.0)
            paths.append(np.repeat(place[None], num_steps, axis=0))
            radii.append(BALL_RADIUS)
            peaks.append(np.where(on, level, 0.0))
            distractors.append(place)
            distractor_on.append(on)
    if f["ball_motion"] == "kicked_hidden":
        extra["distractor_world"] = np.array(distractors, np.float64).reshape(-1, 2)
        extra["distractor_on"] = np.array(distractor_on, bool).reshape(-1, num_steps).T
    k_all = len(paths)
    return _World(
        motion=motion,
        robot_pose=poses,
        true_cam=true_cam,
        given_cam=given_cam,
        given_odometry=noisy,
        has_heatmap=_has_heatmap(f, num_steps, fx),
        ball_on=ball_on,
        occluder=occluder,
        split=split,
        ball_peak=peak,
        fp_path=np.stack(paths, axis=1) if k_all else np.zeros((num_steps, 0, 2)),
        fp_radius=np.array(radii, np.float64),
        fp_peak=np.stack(peaks, axis=1) if k_all else np.zeros((num_steps, 0)),
        extra_info=extra,
    )


# --- Rendering ----------------------------------------------------------------------------------------------------


def _in_image(centre: np.ndarray, radius: float, intrinsics, cam, shape) -> bool:
    outline = sphere_outline(centre, radius, intrinsics, cam)
    if outline is None:
        return False
    u, v = outline[0]
    return 0.0 <= u <= shape[1] - 1 and 0.0 <= v <= shape[0] - 1


def _render(w: _World, f: Mapping[str, Any], seed: int, member: str, num_steps: int, dt: float, shrink: int):
    intrinsics, shape = _shrunk(_full_camera(f), shrink)
    det = DetectorFactors(**{name: f[name] for name in DetectorFactors._fields})
    noise = _rng(seed, member, 2)
    latency = int(f["latency_steps"])
    render_step = np.maximum(np.arange(num_steps) - latency, 0)
    pose = w.robot_pose
    truth = np.stack([world_to_base(pose[t], w.motion.positions[t]) for t in range(num_steps)])
    heatmaps = np.zeros((num_steps, *shape), np.float32)
    in_view = np.zeros(num_steps, bool)
    k_all = w.fp_radius.shape[0]
    fp_on = np.zeros((num_steps, k_all), bool)
    fp_peak = np.zeros((num_steps, k_all))
    length = det.clutter_length_px * shape[1] / HEATMAP_SHAPE[1]
    rho = det.clutter_persistence
    field = clutter_field(noise, shape, length) if det.clutter_strength > 0 else None
    for t in range(num_steps):
        if field is not None and t > 0:
            field = rho * field + np.sqrt(1.0 - rho**2) * clutter_field(noise, shape, length)
        s = render_step[t]
        cam = w.true_cam[s]
        ball = np.r_[truth[s], BALL_RADIUS + w.motion.heights[s]]
        in_view[t] = _in_image(ball, BALL_RADIUS, intrinsics, cam, shape)
        if not w.has_heatmap[t]:
            continue
        objects = []
        if w.ball_on[s]:
            objects.append(SceneObject(ball, BALL_RADIUS, float(w.ball_peak[s]), "ball", w.occluder[s]))
        if k_all:
            places = world_to_base(pose[s], w.fp_path[s])
            for k in np.flatnonzero(w.fp_peak[s] > 0):
                centre = np.r_[places[k], w.fp_radius[k]]
                objects.append(SceneObject(centre, float(w.fp_radius[k]), float(w.fp_peak[s, k]), "false_positive"))
                fp_on[t, k] = _in_image(centre, w.fp_radius[k], intrinsics, cam, shape)
                fp_peak[t, k] = w.fp_peak[s, k] if fp_on[t, k] else 0.0
        heatmaps[t] = render_frame(noise, objects, intrinsics, cam, shape, det, clutter=field)
    has = w.has_heatmap
    ball_on = w.ball_on[render_step]
    visible = has & ball_on & in_view
    true_odom = odometry_from_poses(pose)
    seq = Sequence(
        heatmaps=heatmaps,
        has_heatmap=has.copy(),
        intrinsics=intrinsics,
        cam_to_base=w.given_cam.copy(),
        odometry=w.given_odometry.copy(),
        ball_radius=np.asarray(BALL_RADIUS),
        dt=np.asarray(float(dt)),
        ground_truth=truth,
    )
    occluded_part = np.array([w.occluder[s] is not None for s in render_step]) & visible
    info = {
        "robot_pose": pose.copy(),
        "ball_world": w.motion.positions.copy(),
        "ball_height": w.motion.heights.copy(),
        "in_air": w.motion.in_air.copy(),
        "ball_speed": np.hypot(w.motion.velocities[:, 0], w.motion.velocities[:, 1]),
        "ball_events": w.motion.events,
        "obstacles": w.motion.obstacles.copy(),
        "obstacle_steps": w.motion.obstacle_steps.copy(),
        "true_odometry": true_odom,
        "true_cam_to_base": w.true_cam.copy(),
        "render_step": render_step,
        "in_view": in_view,
        "occluded": ~ball_on,
        "visible": visible,
        "ball_peak": np.where(visible, w.ball_peak[render_step], 0.0),
        "split": visible & w.split[render_step],
        "partly_occluded": occluded_part & ~w.split[render_step],
        "false_positive_world": w.fp_path[0].copy(),
        "false_positive_path": w.fp_path.copy(),
        "false_positive_radius": w.fp_radius.copy(),
        "false_positive_on": fp_on,
        "false_positive_peak": fp_peak,
        "false_positive_count": fp_on.sum(axis=1).astype(np.int64),
        "balls_base": truth[:, None].copy(),
        "balls_visible": visible[:, None].copy(),
        **w.extra_info,
    }
    return validate_sequence(seq), info


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
          :class:`~heatpf_jax.sim.ball_motion.MotionEvent` s; ``obstacles`` ``[K, 3]`` and ``obstacle_steps``
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
