"""A simulated world for evaluation: a humanoid's head camera watching a ball, as FCNN-like heat maps.

NumPy only (it makes data; it is not part of the filter). Conventions follow the sequence-file
contract, so ``project_heatmap`` of a rendered frame lands on the ball.

* :mod:`heatpf_jax.sim.world`: ball paths, robot poses and odometry, random events;
* :mod:`heatpf_jax.sim.render`: heat-map rendering;
* :mod:`heatpf_jax.sim.scenarios`: :func:`simulate` and the named scenarios (:data:`SCENARIOS`).
"""

from heatpf_jax.sim.render import BALL_RADIUS, DEFAULT_INTRINSICS, HEATMAP_SHAPE, render_heatmap, scaled_camera
from heatpf_jax.sim.scenarios import SCENARIOS, simulate, simulate_standard, simulate_with_info
from heatpf_jax.sim.world import ball_path, integrate_odometry, odometry_from_poses, world_to_base

__all__ = [
    "BALL_RADIUS",
    "DEFAULT_INTRINSICS",
    "HEATMAP_SHAPE",
    "SCENARIOS",
    "ball_path",
    "integrate_odometry",
    "odometry_from_poses",
    "render_heatmap",
    "scaled_camera",
    "simulate",
    "simulate_standard",
    "simulate_with_info",
    "world_to_base",
]
