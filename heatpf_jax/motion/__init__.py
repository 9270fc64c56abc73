"""Motion models: how particles move between heat maps (III-D; Olufs 3.3), and the robot's own motion (Olufs 3.5).

* :mod:`~heatpf_jax.motion.random_walk`: the paper's odometry plus diffusion, the particle type;
* :mod:`~heatpf_jax.motion.constant_velocity`: a velocity state;
* :mod:`~heatpf_jax.motion.mass_inertia`: Olufs's mass inertia;
* :mod:`~heatpf_jax.motion.rolling_ball`: a real ball (friction, kicks);
* :mod:`~heatpf_jax.motion.score`: the score form of a Gaussian motion model (for gradients);
* :mod:`~heatpf_jax.motion.ego`: ego-motion from odometry or self-localisation.
"""

from heatpf_jax.motion.constant_velocity import (
    ConstantVelocity,
    ConstantVelocityParams,
    VelocityParticles,
    move_with_odometry,
)
from heatpf_jax.motion.ego import (
    EGO_MOTIONS,
    EgoMotion,
    LocalisationEgo,
    NoEgo,
    OdometryEgo,
    pose_confidences,
    pose_deltas,
)
from heatpf_jax.motion.mass_inertia import (
    InertiaParticles,
    MassInertia,
    MassInertiaParams,
    normalised_score,
)
from heatpf_jax.motion.random_walk import (
    DiffusionOnly,
    DiffusionParams,
    Particles,
    RandomWalk,
    RandomWalkParams,
    apply_odometry,
    diffuse,
    move_and_diffuse,
    move_particles,
)
from heatpf_jax.motion.rolling_ball import (
    RollingBall,
    RollingBallParams,
    roll,
)
from heatpf_jax.motion.score import (
    ScoredParticles,
    ScoreMotion,
    gaussian_log_score,
    transition_log_weight,
)

__all__ = [
    "ConstantVelocity",
    "ConstantVelocityParams",
    "DiffusionOnly",
    "DiffusionParams",
    "EGO_MOTIONS",
    "EgoMotion",
    "InertiaParticles",
    "LocalisationEgo",
    "MassInertia",
    "MassInertiaParams",
    "NoEgo",
    "OdometryEgo",
    "Particles",
    "RandomWalk",
    "RandomWalkParams",
    "RollingBall",
    "RollingBallParams",
    "ScoreMotion",
    "ScoredParticles",
    "VelocityParticles",
    "apply_odometry",
    "diffuse",
    "gaussian_log_score",
    "move_and_diffuse",
    "move_particles",
    "move_with_odometry",
    "normalised_score",
    "pose_confidences",
    "pose_deltas",
    "roll",
    "transition_log_weight",
]
