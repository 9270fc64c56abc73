"""RGB frames of a simulated scenario: the world the heat maps show, as a camera would see it (NumPy).

Every pixel's ray (the true camera pose, the sequence's intrinsics) is cast against the scene and takes
the colour of the nearest surface:

* the ground ``z = 0``: grass in mowing stripes 1 m wide with low-frequency texture, and white field
  lines 5 cm wide painted in the world frame (touchlines at ``y = +-3 m``, lines across at ``x = 3`` and
  ``x = 6.5 m``, a centre circle of 0.75 m radius at ``(6.5, 0)`` and a penalty mark at ``(4.5, 0)``);
* the ball(s) (``info["balls_base"]``; the tracked one only where it is not occluded): white spheres
  with 12 dark patches around the faces of a dodecahedron that roll with the ball, Lambert shading;
* clutter: three robots (dark vertical cylinders of 0.18 m radius, 0.6 m high, with a white band) and two
  white goal posts (0.05 m radius, 0.8 m high) at world places drawn from ``seed``, 1.5 m or more from the
  ball's path, and, in ``false_positives``, a white ball-sized disc on the ground at each spurious place
  while it is on (the things an FCNN mistakes for a ball are white and round);
* above the horizon: a grey-blue wall.

Lighting changes: a smooth global gain in ``[0.8, 1.2]`` over seconds and a slight colour-temperature
shift, then sensor noise (std 3 grey levels); values are clipped to ``uint8``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from heatpf_jax.io.sequence import Sequence
from heatpf_jax.sim.world import world_to_base
from heatpf_jax.sim.world_events import smooth_signal

__all__ = ["render_rgb", "render_rgb_frame"]

_GRASS = np.array([46.0, 120.0, 48.0])
_GRASS_DARK = np.array([38.0, 104.0, 40.0])
_LINE = np.array([225.0, 228.0, 226.0])
_WALL = np.array([120.0, 130.0, 150.0])
_BALL = np.array([235.0, 235.0, 232.0])
_PATCH = np.array([35.0, 35.0, 40.0])
_ROBOT = np.array([45.0, 45.0, 52.0])
_POST = np.array([230.0, 230.0, 230.0])
_LIGHT = np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93])
_LINE_HALF_WIDTH = 0.025


def _dodecahedron_faces() -> np.ndarray:
    """The 12 face normals of a dodecahedron (the icosahedron's vertices)."""
    phi = (1.0 + 5.0**0.5) / 2.0
    v = []
    for a in (-1.0, 1.0):
        for b in (-phi, phi):
            v += [(0.0, a, b), (a, b, 0.0), (b, 0.0, a)]
    v = np.array(v)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


_FACES = _dodecahedron_faces()


def _rays(intrinsics: np.ndarray, cam_to_base: np.ndarray, shape: tuple[int, int]):
    h, w = shape
    fx, fy, cx, cy = intrinsics
    vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
    ray = np.stack([(uu - cx) / fx, (vv - cy) / fy, np.ones_like(uu)], axis=-1)
    direction = ray @ cam_to_base[:3, :3].T  # base frame, per unit optical depth
    return cam_to_base[:3, 3], direction


def _field_lines(xy_world: np.ndarray) -> np.ndarray:
    x, y = xy_world[..., 0], xy_world[..., 1]
    hw = _LINE_HALF_WIDTH
    on = (np.abs(np.abs(y) - 3.0) < hw) & (x > -1.0) & (x < 9.5)
    on |= ((np.abs(x - 3.0) < hw) | (np.abs(x - 6.5) < hw)) & (np.abs(y) <= 3.0)
    on |= np.abs(np.hypot(x - 6.5, y) - 0.75) < hw
    on |= np.hypot(x - 4.5, y) < 0.06
    return on


def _sphere_hits(origin, direction, centre, radius):
    """Optical depth of the nearest hit of each ray with a sphere (inf where none)."""
    oc = origin - centre
    a = np.sum(direction * direction, axis=-1)
    b = 2.0 * direction @ oc
    c = oc @ oc - radius * radius
    disc = b * b - 4.0 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * a)
    return np.where((disc >= 0.0) & (t > 0.05), t, np.inf)


def _cylinder_hits(origin, direction, centre_xy, radius, height):
    """Optical depth of the nearest hit with a vertical cylinder (side or top) standing on the ground."""
    d, o = direction[..., :2], origin[:2] - centre_xy
    a = np.sum(d * d, axis=-1)
    b = 2.0 * d @ o
    c = o @ o - radius * radius
    disc = b * b - 4.0 * a * c
    t = (-b - np.sqrt(np.maximum(disc, 0.0))) / (2.0 * np.maximum(a, 1e-12))
    z = origin[2] + t * direction[..., 2]
    side = (disc >= 0.0) & (t > 0.05) & (z >= 0.0) & (z <= height)
    t_top = (height - origin[2]) / np.where(np.abs(direction[..., 2]) > 1e-9, direction[..., 2], 1e-9)
    top_xy = origin[:2] + t_top[..., None] * d
    top = (t_top > 0.05) & (np.sum((top_xy - centre_xy) ** 2, axis=-1) <= radius * radius)
    return np.where(side, t, np.where(top, t_top, np.inf)), z


def _ball_rotations(balls_base: np.ndarray, robot_pose: np.ndarray, radius: float) -> np.ndarray:
    """Each ball's orientation per step ``[T, B, 3, 3]`` (ball frame -> world), rolling without slipping."""
    num_steps, num_balls = balls_base.shape[:2]
    c, s = np.cos(robot_pose[:, 2]), np.sin(robot_pose[:, 2])
    world = np.stack([robot_pose[:, None, 0] + c[:, None] * balls_base[..., 0] - s[:, None] * balls_base[..., 1],
                      robot_pose[:, None, 1] + s[:, None] * balls_base[..., 0] + c[:, None] * balls_base[..., 1]],
                     axis=-1)
    rot = np.tile(np.eye(3), (num_steps, num_balls, 1, 1))
    for t in range(1, num_steps):
        for b in range(num_balls):
            step = world[t, b] - world[t - 1, b]
            dist = np.linalg.norm(step)
            r = rot[t - 1, b]
            if dist > 1e-9:
                axis = np.array([-step[1], step[0], 0.0]) / dist  # z x direction of motion
                angle = dist / radius
                k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
                r = (np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k) @ r
            rot[t, b] = r
    return rot


def render_rgb_frame(
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    robot_pose: np.ndarray,
    balls: list[tuple[np.ndarray, np.ndarray]],
    ball_radius: float,
    clutter: dict[str, np.ndarray],
    discs: np.ndarray,
    disc_radius: np.ndarray,
) -> np.ndarray:
    """One noise-free frame ``float64 [H, W, 3]`` before lighting (see the module docstring).

    Args:
        intrinsics: the camera's ``(fx, fy, cx, cy)``.
        cam_to_base: the camera's pose in the base frame.
        shape: the frame's ``(H, W)``.
        robot_pose: ``(x, y, theta)`` of the base in the world.
        balls: ``(centre_xy_base [2], rotation ball->world [3, 3])`` of every ball drawn.
        ball_radius: metres.
        clutter: ``robots`` ``[R, 2]`` and ``posts`` ``[P, 2]`` world positions.
        discs: ``[D, 2]`` base-frame centres of white ground discs; ``disc_radius`` ``[D]``.
    """
    origin, direction = _rays(intrinsics, cam_to_base, shape)
    depth = np.full(shape, np.inf)
    colour = np.broadcast_to(_WALL * (0.9 + 0.1 * np.linspace(0, 1, shape[0]))[:, None, None], (*shape, 3)).copy()
    # Ground.
    dz = direction[..., 2]
    t_ground = np.where(dz < -1e-9, -origin[2] / np.where(dz < -1e-9, dz, -1.0), np.inf)
    ground = np.isfinite(t_ground)
    hit = origin[:2] + np.where(ground, t_ground, 0.0)[..., None] * direction[..., :2]
    c, s = np.cos(robot_pose[2]), np.sin(robot_pose[2])
    world = np.stack([robot_pose[0] + c * hit[..., 0] - s * hit[..., 1],
                      robot_pose[1] + s * hit[..., 0] + c * hit[..., 1]], axis=-1)
    stripe = (np.floor(world[..., 0]) % 2 == 0)[..., None]
    texture = 1.0 + 0.06 * np.sin(1.7 * world[..., 0] + 0.5) * np.sin(2.3 * world[..., 1] + 1.1)
    grass = np.where(stripe, _GRASS, _GRASS_DARK) * texture[..., None]
    white = _field_lines(world)
    for k in range(len(discs)):
        white |= np.sum((hit - discs[k]) ** 2, axis=-1) <= disc_radius[k] ** 2
    ground_colour = np.where(white[..., None], _LINE, grass)
    colour = np.where(ground[..., None], ground_colour, colour)
    depth = np.where(ground, t_ground, depth)
    # Robots and goal posts (world -> base).
    for kind, radius, height, base_colour in (("robots", 0.18, 0.6, _ROBOT), ("posts", 0.05, 0.8, _POST)):
        places = clutter.get(kind, np.zeros((0, 2)))
        if len(places) == 0:
            continue
        for centre in world_to_base(robot_pose, places):
            t, z = _cylinder_hits(origin, direction, centre, radius, height)
            closer = t < depth
            col = np.broadcast_to(base_colour, (*shape, 3))
            if kind == "robots":
                band = ((z > 0.35) & (z < 0.42))[..., None]
                col = np.where(band, _POST, col)
            colour = np.where(closer[..., None], col, colour)
            depth = np.where(closer, t, depth)
    # Balls.
    for centre_xy, rot in balls:
        centre = np.array([centre_xy[0], centre_xy[1], ball_radius])
        t = _sphere_hits(origin, direction, centre, ball_radius)
        closer = t < depth
        if not np.any(closer):
            continue
        point = origin + np.where(closer, t, 0.0)[..., None] * direction
        normal = (point - centre) / ball_radius
        shade = 0.55 + 0.45 * np.clip(normal @ _LIGHT, 0.0, 1.0)
        # The normal in the ball's own frame: base -> world -> ball.
        r_base = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        n_ball = normal @ r_base.T @ rot
        patch = np.max(n_ball @ _FACES.T, axis=-1) > np.cos(np.deg2rad(21.0))
        col = np.where(patch[..., None], _PATCH, _BALL) * shade[..., None]
        colour = np.where(closer[..., None], col, colour)
        depth = np.where(closer, t, depth)
    return colour


def _clutter(rng: np.random.Generator, ball_world: np.ndarray) -> dict[str, np.ndarray]:
    """Robot and goal-post places, 1.5 m or more from every point of the ball's path."""

    def far(p):
        return np.min(np.linalg.norm(ball_world - p, axis=1)) >= 1.5

    robots = []
    for _ in range(200):
        p = np.array([rng.uniform(1.5, 7.0), rng.uniform(-3.5, 3.5)])
        if far(p) and all(np.linalg.norm(p - q) > 1.0 for q in robots):
            robots.append(p)
        if len(robots) == 3:
            break
    goal_x = rng.uniform(7.5, 8.5)
    posts = np.array([[goal_x, -1.3], [goal_x, 1.3]])
    posts = np.array([p for p in posts if far(p)]).reshape(-1, 2)
    return {"robots": np.array(robots).reshape(-1, 2), "posts": posts}


def render_rgb(seq: Sequence, info: dict[str, Any], *, seed: int) -> np.ndarray:
    """RGB frames ``uint8 [T, H, W, 3]`` of a simulated sequence (``simulate_with_info``'s outputs).

    Deterministic in ``seed`` (clutter places, lighting, noise), independent of the simulator's own
    random streams: the heat maps and the frames show one world.
    """
    rng = np.random.default_rng([int(seed), 0x52474])
    num_steps = seq.num_steps
    shape = seq.heatmaps.shape[1:]
    intrinsics = np.asarray(seq.intrinsics, np.float64)
    radius = float(seq.ball_radius)
    cams = info["true_cam_to_base"]
    poses = info["robot_pose"]
    balls_base = info["balls_base"]
    occluded = info["occluded"]
    clutter = _clutter(rng, info["ball_world"])
    rotations = _ball_rotations(balls_base, poses, radius)
    gain = 1.0 + 0.2 * smooth_signal(rng, num_steps, float(seq.dt), freqs=(0.03, 0.15))
    warmth = 0.05 * smooth_signal(rng, num_steps, float(seq.dt), freqs=(0.02, 0.1))
    fp_world = info.get("false_positive_world", np.zeros((0, 2)))
    fp_on = info.get("false_positive_on", np.zeros((num_steps, 0), bool))
    fp_radius = info.get("false_positive_radius", np.zeros(0))
    frames = np.empty((num_steps, *shape, 3), np.uint8)
    for t in range(num_steps):
        balls = [(balls_base[t, b], rotations[t, b]) for b in range(balls_base.shape[1])
                 if not (b == 0 and occluded[t])]
        on = np.flatnonzero(fp_on[t]) if fp_on.shape[1] else np.zeros(0, int)
        discs = world_to_base(poses[t], fp_world[on]) if len(on) else np.zeros((0, 2))
        frame = render_rgb_frame(intrinsics, cams[t], shape, poses[t], balls, radius, clutter, discs,
                                 np.maximum(fp_radius[on], radius) if len(on) else np.zeros(0))
        tint = np.array([1.0 + warmth[t], 1.0, 1.0 - warmth[t]])
        frame = frame * gain[t] * tint + 3.0 * rng.standard_normal(frame.shape)
        frames[t] = np.clip(np.round(frame), 0, 255).astype(np.uint8)
    return frames
