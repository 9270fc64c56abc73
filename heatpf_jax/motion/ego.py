"""Ego-motion: what moves the particles, the buffer and the memory's tracks each step (Olufs et al. 3.5).

The first stage of a step. The heat-map paper (III-D) moves particles and buffered measurements by the
robot's odometry; Olufs et al. use the robot's self-localisation instead: the motion between the
previous and the current pose, *weighted by the localisation's confidence* ("which prevents artificial
motion caused by non explicit poses, like for example during the global localisation"), rotates the
particles (they are "only rotated") and shifts and rotates the long-term memory's tracks.

Each piece returns an :class:`EgoMotion`: the motion ``(dx, dy, dtheta)`` in the previous base frame
applied to the particles and the buffer (the step passes it on as ``inputs.odometry``) and the one
applied to the memory's tracks (:mod:`heatpf_jax.memory`):

* :class:`OdometryEgo` (default): the sequence's odometry for both, as the heat-map paper does;
* :class:`NoEgo`: no compensation (the robot's motion is left to the diffusion);
* :class:`LocalisationEgo`: the pose delta from ``robot_pose``, times ``pose_confidence`` (``weighted``),
  rotation only for the particles (the paper) or rotation and translation (``translate``), rotation and
  translation for the tracks. It needs the sequence keys ``robot_pose`` (and ``pose_confidence``, 1
  where absent): :func:`heatpf_jax.rollout.prepare_run` refuses a sequence without them.

The pose delta itself is computed on the host, in float64, by :func:`pose_deltas` where the poses are
concrete: poses in a world frame can be large numbers, and their difference loses nothing there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from heatpf_jax.params import NoParams

__all__ = ["EGO_MOTIONS", "EgoMotion", "LocalisationEgo", "NoEgo", "OdometryEgo", "pose_confidences", "pose_deltas"]


class EgoMotion(NamedTuple):
    """The step's ego-motion, ``(dx, dy, dtheta)`` from the previous base frame to the current one.

    Attributes:
        particles: ``float32 [3]`` applied to the particles and the measurement buffer.
        tracks: ``float32 [3]`` applied to the long-term memory's tracks.
    """

    particles: Float[Array, "3"]
    tracks: Float[Array, "3"]


def pose_deltas(robot_pose, xp=np):
    """The motion between successive poses in the previous base frame, like odometry (row 0 zero).

    Args:
        robot_pose: ``[T, 3]`` the base's ``(x, y, theta)`` in a world frame.
        xp: ``numpy`` (default: float64 on the host, exact for poses far from the world origin) or
            ``jax.numpy`` (traced poses, e.g. sequences under ``vmap``; in float32).

    Returns:
        ``[T, 3]``: ``(R(theta_{t-1})^T (p_t - p_{t-1}), wrap(theta_t - theta_{t-1}))``.
    """
    pose = xp.asarray(robot_pose, xp.float64 if xp is np else xp.float32)
    d = pose[1:, :2] - pose[:-1, :2]
    c, s = xp.cos(pose[:-1, 2]), xp.sin(pose[:-1, 2])
    dth = pose[1:, 2] - pose[:-1, 2]
    rows = xp.stack(
        [c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1], xp.arctan2(xp.sin(dth), xp.cos(dth))], axis=1
    )
    return xp.concatenate([xp.zeros((1, 3), rows.dtype), rows], axis=0)


def pose_confidences(confidence, num_steps: int, xp=np):
    """The confidence of each step's pose delta: the lower of its two poses' (1 without confidences).

    A delta is only as trustworthy as the worse of the poses it is taken between: a localisation that
    jumps away and back is distrusted on both jumps.
    """
    if confidence is None:
        return xp.ones(num_steps, xp.float64 if xp is np else xp.float32)
    conf = xp.asarray(confidence)
    return xp.concatenate([conf[:1], xp.minimum(conf[1:], conf[:-1])])


@dataclass(frozen=True)
class OdometryEgo:
    """The sequence's odometry moves particles, buffer and tracks (the heat-map paper, III-D)."""

    requires: tuple[str, ...] = ()

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def ego(self, inputs, params) -> EgoMotion:
        odometry = jnp.asarray(inputs.odometry, jnp.float32)
        return EgoMotion(particles=odometry, tracks=odometry)


@dataclass(frozen=True)
class NoEgo:
    """No ego-motion compensation: nothing is moved with the robot."""

    requires: tuple[str, ...] = ()

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def ego(self, inputs, params) -> EgoMotion:
        zero = jnp.zeros((3,), jnp.float32)
        return EgoMotion(particles=zero, tracks=zero)


@dataclass(frozen=True)
class LocalisationEgo:
    """Ego-motion from self-localisation weighted by its confidence (Olufs et al. 3.5).

    ``motion = c * delta`` with ``delta`` the step's pose delta (:func:`pose_deltas`) and ``c`` its
    confidence (:func:`pose_confidences`; 1 when not ``weighted``). The particles and the buffer get the
    rotation only (``(0, 0, c * dtheta)``, as the paper does) or, with ``translate``, all of it; the
    memory's tracks always get all of it.

    Attributes:
        translate: also shift the particles and the buffer (default: rotate only, as the paper).
        weighted: scale by the confidence (default); ``False`` applies the raw delta, jumps included.
    """

    translate: bool = False
    weighted: bool = True
    requires: tuple[str, ...] = ("robot_pose",)

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def ego(self, inputs, params) -> EgoMotion:
        if inputs.pose_delta is None:
            raise ValueError("robot_pose: LocalisationEgo needs the sequence's robot_pose (ego=pose...)")
        delta = jnp.asarray(inputs.pose_delta, jnp.float32)
        confidence = jnp.asarray(inputs.pose_confidence, jnp.float32) if self.weighted else jnp.float32(1.0)
        full = confidence * delta
        particles = full if self.translate else full * jnp.array([0.0, 0.0, 1.0], jnp.float32)
        return EgoMotion(particles=particles, tracks=full)


EGO_MOTIONS = {
    "odometry": OdometryEgo(),
    "none": NoEgo(),
    "pose": LocalisationEgo(),
    "pose_full": LocalisationEgo(translate=True),
    "pose_unweighted": LocalisationEgo(weighted=False),
    "pose_full_unweighted": LocalisationEgo(translate=True, weighted=False),
}
