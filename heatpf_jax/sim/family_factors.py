"""The world family's factors: the members, the table of how each factor is drawn, and the drawing.

:data:`FAMILY` names the members; :func:`factor_ranges` gives a member's :class:`Factor` s (the table in
:mod:`heatpf_jax.sim.family`'s docstring) and :func:`draw_factors` draws them for a seed, from a stream of
their own (``default_rng([seed, member index, 7919, 0])``; the planning and rendering streams,
purposes 1-3, come from the same ``_rng``). :mod:`heatpf_jax.sim.family` re-exports every name here.
NumPy only.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from heatpf_jax.sim.detector import DETECTOR_RANGES

__all__ = ["FAMILY", "MAX_FALSE_POSITIVES", "Factor", "draw_factors", "factor_ranges"]

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
