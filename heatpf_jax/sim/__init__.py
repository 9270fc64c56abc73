"""A simulated world for evaluation: a humanoid's head camera watching a ball, as FCNN-like heat maps.

NumPy only (it makes data; it is not part of the filter). Conventions follow the sequence-file
contract, so ``project_heatmap`` of a rendered frame lands on the ball.

* :mod:`heatpf_jax.sim.world`: ball paths, robot poses and odometry, random events;
* :mod:`heatpf_jax.sim.render`: heat-map rendering;
* :mod:`heatpf_jax.sim.scenarios`: :func:`simulate` and the named scenarios (:data:`SCENARIOS`);
* :mod:`heatpf_jax.sim.family`: the world family (:data:`FAMILY`), each scenario type with its nuisance
  factors (detector blob, clutter, camera and its calibration, timing, ball motion) drawn per seed
  (:func:`simulate_family`), with :mod:`heatpf_jax.sim.detector` and :mod:`heatpf_jax.sim.ball_motion`;
* :mod:`heatpf_jax.sim.tracks` and :mod:`heatpf_jax.sim.replay`: real ball tracks from professional matches
  (fetched at first use, never stored in the repository), replayed at KidSize scale (:func:`replay_world`).
"""

from heatpf_jax.sim.family import FAMILY, draw_factors, simulate_family, simulate_family_with_info
from heatpf_jax.sim.render import BALL_RADIUS, DEFAULT_INTRINSICS, HEATMAP_SHAPE, render_heatmap, scaled_camera
from heatpf_jax.sim.replay import replay_segments, replay_world
from heatpf_jax.sim.scenarios import SCENARIOS, simulate, simulate_standard, simulate_with_info
from heatpf_jax.sim.tracks import BallTrack, fetch_kloppy_files, load_pff, load_skillcorner, resample_track, segments
from heatpf_jax.sim.world import ball_path, integrate_odometry, odometry_from_poses, world_to_base

__all__ = [
    "BALL_RADIUS",
    "BallTrack",
    "DEFAULT_INTRINSICS",
    "FAMILY",
    "HEATMAP_SHAPE",
    "SCENARIOS",
    "ball_path",
    "draw_factors",
    "fetch_kloppy_files",
    "integrate_odometry",
    "load_pff",
    "load_skillcorner",
    "odometry_from_poses",
    "render_heatmap",
    "replay_segments",
    "replay_world",
    "resample_track",
    "scaled_camera",
    "segments",
    "simulate",
    "simulate_family",
    "simulate_family_with_info",
    "simulate_standard",
    "simulate_with_info",
    "world_to_base",
]
