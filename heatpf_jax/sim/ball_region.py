"""Regions: where a simulated ball may be, on the ground in front of the robot.

A :class:`Region` is a band of forward distances with a half-width at each (and a largest distance from
the origin): :func:`box_region` makes a rectangle, :func:`view_region` the ground a forward-looking
camera sees a whole ball on. :mod:`heatpf_jax.sim.ball_motion` draws targets in one and re-exports every
name here. NumPy only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from heatpf_jax.sim.world_paths import lateral_limit

__all__ = ["Region", "box_region", "view_region"]


class Region(NamedTuple):
    """Where a ball may be: ``x[0] <= x <= x[-1]``, ``|y| <= half_width(x)`` (linear in between) and
    ``|(x, y)| <= max_distance``.

    Attributes:
        x: ``[G]`` increasing forward distances, metres.
        half_width: ``[G]`` the largest ``|y|`` at each ``x``.
        max_distance: the largest distance from the origin.
    """

    x: np.ndarray
    half_width: np.ndarray
    max_distance: float = np.inf

    def contains(self, xy: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether points ``[..., 2]`` lie in the region, at least ``margin`` metres inside its sides."""
        xy = np.asarray(xy, np.float64)
        x, y = xy[..., 0], xy[..., 1]
        half = np.interp(x, self.x, self.half_width) - margin
        inside = (x >= self.x[0] + margin) & (x <= self.x[-1] - margin) & (np.abs(y) <= half)
        return inside & (np.hypot(x, y) <= self.max_distance - margin)

    def sample(self, rng: np.random.Generator, margin: float = 0.0) -> np.ndarray:
        """A point ``[2]`` uniform over the region (rejection from its bounding box)."""
        top = float(self.half_width.max())
        for _ in range(10_000):
            point = np.array([rng.uniform(self.x[0], self.x[-1]), rng.uniform(-top, top)])
            if self.contains(point, margin):
                return point
        return np.array([0.5 * (self.x[0] + self.x[-1]), 0.0])


def box_region(x_range: tuple[float, float], half_width: float, *, max_distance: float = np.inf) -> Region:
    """A rectangle ``x_range`` by ``+-half_width``."""
    return Region(np.array([float(x_range[0]), float(x_range[1])]), np.full(2, float(half_width)), max_distance)


def view_region(
    intrinsics: np.ndarray,
    cam_to_base: np.ndarray,
    shape: tuple[int, int],
    *,
    x_range: tuple[float, float],
    radius: float,
    fill: float = 0.85,
    max_distance: float = np.inf,
    points: int = 25,
) -> Region:
    """The ground in front of a forward-looking camera where a ball of ``radius`` is wholly in view.

    ``fill`` times the half-width that keeps the ball in the image (``heatpf_jax.sim.world_paths.lateral_limit``)
    at each of ``points`` distances in ``x_range``, cut to ``max_distance``; the ends where the ball does
    not fit at all (too close or too far to see) are cut off.

    Raises:
        ValueError: when the ball fits nowhere in ``x_range``.
    """
    grid = np.linspace(x_range[0], x_range[1], points)
    half = fill * lateral_limit(grid, intrinsics, cam_to_base, shape, radius=radius)
    half = np.minimum(half, np.sqrt(np.maximum(max_distance**2 - grid**2, 0.0)))
    ok = np.flatnonzero(half > 0.05)
    if ok.size < 2:
        raise ValueError(f"x_range: a ball is in view nowhere in {x_range}")
    keep = slice(ok[0], ok[-1] + 1)
    return Region(grid[keep], half[keep], float(max_distance))
