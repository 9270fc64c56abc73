"""A ball does not hover: a blob that reads as a ball in the air at the same place for a while lies on the ground.

:class:`~heatpf_jax.sources.lofted.LoftedSource` reads a blob larger than a ground ball there as a ball in the air
and places it, compact and ball-sized, under the ball its size implies, nearer the robot. Anything on the ground
that the detector sees larger than the ball (a goal post's foot, a penalty mark, a robot's foot, a false blob twice
the ball's size) is read that way too, and placed by its size it looks exactly like a ball: it captures the filter,
where the paper's projection spread its pixels thinly over the ground far behind it. What tells the two apart is
time. A ball in the air is in flight: it was kicked, so its blob crosses the image from frame to frame (its ground
point moves at the flight's horizontal speed and its height changes). A thing on the ground stays where it is in the
world while it is seen.

:class:`HoverState` keeps, for each of the last ``F`` frames, the places of up to ``K`` blobs read as flying, as
homogeneous base-frame points ``(x, y, z, w)``: where the ray through the blob's centroid meets the plane
``z = R`` (``w = 1``), or, above the horizon, the ray's direction (``w = 0``). Odometry moves them every step (the
robot's own motion, as it moves particles and buffered measurements; a turning head needs nothing, the points are
in the base frame) and their ages grow by the step's ``dt``. A blob read as flying now whose centroid lies within
``tolerance`` pixels of where such a point projects in the current image, stored between ``min_age`` and
``max_age`` seconds ago, has hovered there: it is not a ball in flight, and is measured where it projects, as the
paper's source does.

A ball on the ground that its blob's noise reads as flying is corrected the same way, once it has been read so at
one place for ``min_age``. A flight along the ray near its apex can pause for a frame or two in the image; ``min_age``
of 0.25 s lets it pass. Every function here is pure and jittable.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from heatpf_jax.camera import pixel_ray, project_pixel, project_points
from heatpf_jax.frames import apply_odometry

__all__ = [
    "HoverState",
    "age_hover",
    "air_places",
    "hovering",
    "init_hover",
    "place_points",
    "remember_hover",
]


class HoverState(NamedTuple):
    """The recent frames' places of blobs read as flying (a ring buffer of frames).

    Attributes:
        points: ``float32 [F, K, 4]`` homogeneous base-frame points: ``(x, y, R, 1)`` where the ray through a
            blob's centroid met the plane ``z = R``, or ``(dx, dy, dz, 0)`` its direction above the horizon.
        valid: ``bool [F, K]`` which hold a place.
        age: ``float32 [F]`` seconds since each frame.
        next: ``int32 []`` the frame slot the next frame's places go to.
    """

    points: Float[Array, "f k 4"]
    valid: Bool[Array, "f k"]
    age: Float[Array, " f"]
    next: Int[Array, ""]


def init_hover(frames: int, blobs: int) -> HoverState:
    """An empty buffer of ``frames`` frames of ``blobs`` places each (at least one of each)."""
    f, k = max(int(frames), 1), max(int(blobs), 1)
    return HoverState(jnp.zeros((f, k, 4), jnp.float32), jnp.zeros((f, k), bool),
                      jnp.full((f,), jnp.inf, jnp.float32), jnp.zeros((), jnp.int32))


def age_hover(state: HoverState, odometry: Float[ArrayLike, "3"], dt: Float[ArrayLike, ""]) -> HoverState:
    """The places in the base frame after the robot moved by ``odometry`` ``(dx, dy, dtheta)``, ``dt`` older.

    A point moves as :func:`~heatpf_jax.frames.apply_odometry` moves points, ``R(dtheta)^T (p - w (dx, dy))``; a
    direction (``w = 0``) only turns.
    """
    odometry = jnp.asarray(odometry, jnp.float32)
    f, k, _ = state.points.shape
    p = state.points.reshape(f * k, 4)
    w = p[:, 3]
    per_point = jnp.stack([w * odometry[0], w * odometry[1], jnp.broadcast_to(odometry[2], w.shape)], axis=-1)
    xy = apply_odometry(p[:, :2], per_point)
    moved = jnp.concatenate([xy, p[:, 2:]], axis=-1).reshape(f, k, 4)
    return state._replace(points=moved, age=state.age + jnp.asarray(dt, jnp.float32))


def air_places(
    uv: Float[ArrayLike, "m 2"],
    weight: Float[ArrayLike, " m"],
    in_air: Bool[ArrayLike, " m"],
    blobs: int,
    tolerance: Float[ArrayLike, ""],
) -> tuple[Float[Array, "k 2"], Bool[Array, " k"], Int[Array, " m"]]:
    """Up to ``blobs`` distinct blob centroids among the pixels read as flying, strongest first.

    Greedy: the strongest flying pixel's centroid is a place; every flying pixel whose centroid lies within
    ``2 tolerance`` pixels of it belongs to it; repeat.

    Args:
        uv: ``[M, 2]`` each pixel's blob centroid (column, row).
        weight: ``[M]`` each pixel's activation.
        in_air: ``[M]`` which pixels are read as flying.
        blobs: static number of places.
        tolerance: pixels.

    Returns:
        ``(places [K, 2], valid [K], label [M])``: ``label`` is the place each pixel belongs to, ``-1`` for a pixel
        not read as flying or beyond the ``K`` places.
    """
    uv = jnp.asarray(uv, jnp.float32)
    weight = jnp.asarray(weight, jnp.float32)
    free = jnp.asarray(in_air, bool)
    label = jnp.full(free.shape, -1, jnp.int32)
    places, valid = [], []
    for k in range(max(int(blobs), 1)):
        i = jnp.argmax(jnp.where(free, weight, -jnp.inf))
        has = free[i]
        place = uv[i]
        near = free & (jnp.sum(jnp.square(uv - place[None, :]), axis=-1) <= jnp.square(2.0 * tolerance))
        label = jnp.where(near, k, label)
        free = free & ~near
        places.append(jnp.where(has, place, 0.0))
        valid.append(has)
    return jnp.stack(places), jnp.stack(valid), label


def place_points(
    places: Float[ArrayLike, "k 2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    plane_height: Float[ArrayLike, ""],
) -> Float[Array, "k 4"]:
    """Homogeneous base-frame points of image places: the ray's meeting with ``z = plane_height`` (``w = 1``),
    or its direction where it meets no ground in front of the camera (``w = 0``)."""
    pose = jnp.asarray(cam_to_base, jnp.float32)
    places = jnp.asarray(places, jnp.float32)
    xy, hits = jax.vmap(project_pixel, in_axes=(0, None, None, None))(places, intrinsics, pose, plane_height)
    rays = jax.vmap(pixel_ray, in_axes=(0, None))(places, intrinsics) @ pose[:3, :3].T
    height = jnp.broadcast_to(jnp.asarray(plane_height, jnp.float32), hits.shape)
    ground = jnp.concatenate([xy, height[:, None], jnp.ones_like(height)[:, None]], axis=-1)
    direction = jnp.concatenate([rays, jnp.zeros_like(height)[:, None]], axis=-1)
    return jnp.where(hits[:, None], ground, direction)


def remember_hover(state: HoverState, points: Float[ArrayLike, "k 4"], valid: Bool[ArrayLike, " k"]) -> HoverState:
    """``state`` with this frame's places in the next slot (age 0), the oldest frame's overwritten."""
    f = state.points.shape[0]
    slot = state.next % f
    return HoverState(
        points=state.points.at[slot].set(jnp.asarray(points, jnp.float32)),
        valid=state.valid.at[slot].set(jnp.asarray(valid, bool)),
        age=state.age.at[slot].set(0.0),
        next=((slot + 1) % f).astype(jnp.int32),
    )


def _image_of(points: Float[Array, "n 4"], intrinsics: Float[Array, "4"], pose: Float[Array, "4 4"]):
    """Pixels ``[n, 2]`` of homogeneous base-frame points, and whether each lies in front of the camera: a
    direction (``w = 0``) projects where the point one unit along it from the camera does."""
    origin = pose[:3, 3]
    uv, depth = project_points(points[:, :3] + (1.0 - points[:, 3:4]) * origin[None, :], intrinsics, pose)
    return uv, depth > 1e-6


def hovering(
    state: HoverState,
    uv: Float[ArrayLike, "m 2"],
    intrinsics: Float[ArrayLike, "4"],
    cam_to_base: Float[ArrayLike, "4 4"],
    *,
    tolerance: Float[ArrayLike, ""],
    min_age: Float[ArrayLike, ""],
    max_age: Float[ArrayLike, ""],
) -> Bool[Array, " m"]:
    """Whether a place stored between ``min_age`` and ``max_age`` seconds ago projects within ``tolerance``
    pixels of each centroid ``uv``.

    Args:
        state: the stored places, moved into this step's base frame (:func:`age_hover`).
        uv: ``[M, 2]`` blob centroids (column, row) in this step's image.
        intrinsics: ``(fx, fy, cx, cy)``.
        cam_to_base: ``[4, 4]`` this step's camera pose.
        tolerance: pixels.
        min_age: seconds.
        max_age: seconds.

    Returns:
        ``bool [M]``.
    """
    f, k = state.valid.shape
    intrinsics = jnp.asarray(intrinsics, jnp.float32)
    pose = jnp.asarray(cam_to_base, jnp.float32)
    stored, front = _image_of(state.points.reshape(f * k, 4), intrinsics, pose)
    in_window = (state.age >= min_age) & (state.age <= max_age)
    usable = state.valid.reshape(-1) & front & jnp.repeat(in_window, k)
    d2 = jnp.sum(jnp.square(jnp.asarray(uv, jnp.float32)[:, None, :] - stored[None, :, :]), axis=-1)
    return jnp.any(usable[None, :] & (d2 <= jnp.square(tolerance)), axis=-1)
