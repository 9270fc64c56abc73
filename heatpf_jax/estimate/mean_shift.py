"""Weighted mean shift with fixed sizes (Comaniciu & Meer 2002), and the seeds it starts from.

``S`` seeds (:func:`seed_points`: cell centroids of a grid in Z order, :func:`grid_cells`), not all N
particles, climb the weighted kernel density; converged modes closer than a merge radius are merged
greedily in order of density (sklearn's rule); at most ``M`` modes are kept (the heaviest) behind a
``valid`` mask (:class:`Clusters`). Centres and labels carry no gradient; the cluster weights keep that
of the input weights. The shared helpers are in :mod:`heatpf_jax.estimate.clustering`.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from heatpf_jax.estimate.clustering import _check_count, _nearest, squared_distances, usable_weights

__all__ = [
    "KERNELS",
    "Clusters",
    "grid_cells",
    "mean_shift",
    "seed_points",
]

KERNELS = ("gaussian", "flat")


class Clusters(NamedTuple):
    """What :func:`mean_shift` returns: ``M = max_clusters`` slots, the valid ones first.

    Attributes:
        labels: ``int32 [N]`` each point's cluster, in ``[0, M)``; always a valid cluster.
        centres: ``float32 [M, 2]`` the modes (the converged seeds kept by the merge); zero where invalid.
        weights: ``float32 [M]`` the sum of the member weights (their total is the input's total);
            zero where invalid. Valid clusters come in order of decreasing estimated mass (seeds in
            their basin, see :func:`mean_shift`), which is nearly always decreasing weight.
        valid: ``bool [M]`` which slots hold a mode (fewer than ``M`` distinct modes leave some empty).
    """

    labels: Int[Array, " n"]
    centres: Float[Array, "m 2"]
    weights: Float[Array, " m"]
    valid: Bool[Array, " m"]


_GRID_BITS = 4  # seeding grid: 16 x 16 cells over the points' bounding square
_GRID_CELLS = 4**_GRID_BITS


def _spread_bits(v):
    """Bits ``b3..b0`` of ``uint32 v`` moved to the even positions ``b3 0 b2 0 b1 0 b0``."""
    v = (v | (v << 2)) & jnp.uint32(0x33)
    return (v | (v << 1)) & jnp.uint32(0x55)


def grid_cells(points: Float[ArrayLike, "n 2"]) -> Int[Array, " n"]:
    """Each point's cell of a 16 x 16 grid over the points' bounding square, numbered in Z (Morton) order.

    Cell ``(i, j)`` (column i along x, row j along y) gets the number whose even bits are those of ``i``
    and odd bits those of ``j``, so neighbouring cells mostly have neighbouring numbers.
    """
    points = lax.stop_gradient(jnp.asarray(points))
    low = jnp.min(points, axis=0)
    span = jnp.max(jnp.max(points, axis=0) - low)
    scale = (2**_GRID_BITS) / jnp.where(span > 0, span, 1.0)
    cells = jnp.clip(jnp.floor((points - low[None, :]) * scale), 0, 2**_GRID_BITS - 1).astype(jnp.uint32)
    return (_spread_bits(cells[:, 0]) | (_spread_bits(cells[:, 1]) << 1)).astype(jnp.int32)


def seed_points(
    points: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], num_seeds: int
) -> Float[Array, "s 2"]:
    """``num_seeds`` starting points spread over the weight mass and over the plane, without a sort.

    The points are binned into the cells of :func:`grid_cells`; systematic positions ``(i + 1/2) / S``
    in the weight CDF taken over the cells in Z order pick cells, and a seed is its cell's weighted
    centroid. Each seed stands for an equal share ``1/S`` of the weight and a compact cluster covers a
    few consecutive cells, so it gets about ``S`` times its share of the seeds: every mode holding well
    over ``1/S`` of the weight is seeded, deterministically. Seeding at points in their own order
    (random in space) would miss a mode of share ``m`` with probability about ``(1 - m)^S``; the ``S``
    highest-weight points would all sit on the main peak. All-zero weights count as uniform.
    """
    points = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    sums = jax.ops.segment_sum(
        jnp.stack([w, w * points[:, 0], w * points[:, 1]], axis=1), grid_cells(points), num_segments=_GRID_CELLS
    )
    cdf = jnp.cumsum(sums[:, 0])
    positions = (jnp.arange(num_seeds, dtype=w.dtype) + 0.5) * (cdf[-1] / num_seeds)
    cell = jnp.clip(jnp.searchsorted(cdf, positions, side="right", method="compare_all"), 0, _GRID_CELLS - 1)
    picked = sums[cell]
    # A picked cell has weight (up to float rounding at a cell boundary: then guard the division).
    mass = jnp.where(picked[:, 0] > 0, picked[:, 0], 1.0)
    return picked[:, 1:] / mass[:, None]


def _kernel_weights(d2, w, bandwidth, kernel: str):
    if kernel == "gaussian":
        k = jnp.exp(d2 * (-0.5 / (bandwidth * bandwidth)))
    else:
        k = (d2 <= bandwidth * bandwidth).astype(w.dtype)
    return k * w[None, :]


def _greedy_merge(centres, density, radius) -> Bool[Array, " s"]:
    """Greedy non-maximum suppression without a sort: in order of decreasing density (ties by index),
    a centre with positive density survives unless a survivor lies within ``radius`` (inclusive).

    ``keep_i = alive_i and not any_j (j before i, |c_i - c_j| <= radius, keep_j)`` has the greedy
    answer as its only fixed point; iterating it from ``alive`` fixes one more centre of the order each
    round (at most ``S`` rounds), and stops as soon as nothing changes (usually two or three rounds).
    """
    s = centres.shape[0]
    slots = jnp.arange(s, dtype=jnp.int32)
    alive = density > 0
    denser = density[None, :] > density[:, None]
    tie_first = (density[None, :] == density[:, None]) & (slots[None, :] < slots[:, None])
    suppressors = (denser | tie_first) & (squared_distances(centres, centres) <= radius * radius)

    def changed(state):
        _, moved, rounds = state
        return moved & (rounds < s)

    def round_(state):
        keep, _, rounds = state
        new = alive & ~jnp.any(suppressors & keep[None, :], axis=1)
        return new, jnp.any(new != keep), rounds + 1

    keep, _, _ = lax.while_loop(changed, round_, (alive, jnp.array(True), jnp.int32(0)))
    return keep


def mean_shift(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    *,
    bandwidth: Float[ArrayLike, ""],
    num_seeds: int,
    max_clusters: int,
    num_iters: int,
    merge_radius: Float[ArrayLike, ""] | None = None,
    kernel: str = "gaussian",
) -> Clusters:
    """Weighted mean shift from ``S`` seeds, with a fixed number of iterations and output slots.

    1. Seeds: :func:`seed_points`, ``S`` cell centroids spread over the weight mass (an equal share
       each) and over the plane.
    2. ``num_iters`` mean-shift steps of every seed against all N points (Comaniciu & Meer eq. 17)::

           x <- sum_j K(x - p_j) w_j p_j / sum_j K(x - p_j) w_j

       with ``K(d) = exp(-|d|^2 / 2h^2)`` (``"gaussian"``) or ``|d| <= h`` (``"flat"``); a seed whose
       denominator is zero stays where it is and is dropped (as sklearn drops a seed with an empty
       window; only a flat kernel can leave every seed so, and then no cluster is valid).
    3. Merge: in order of decreasing density ``sum_j K w_j`` (of the last step's window, as sklearn's
       "intensity"), a mode is dropped if a kept mode lies within ``merge_radius`` (sklearn's
       ``MeanShift`` rule, and its radius ``h`` as the default: distinct modes of a Gaussian-smoothed
       density are more than ``2h`` apart, and seeds still on their way after ``num_iters`` steps are
       absorbed).
    4. Keep the ``max_clusters`` heaviest modes: a mode's mass is estimated by the seeds whose nearest
       mode it is (each seed is ``1/S`` of the weight: a stratified estimate of the mass of its basin
       of attraction), ties by density; they fill the slots in that order. Every point goes to its
       nearest kept mode, and a cluster's weight is the sum of its members' weights.

    Cost: ``O(num_iters S N + S^2 + M N)``; the N points are never iterated themselves.

    Args:
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        bandwidth: the kernel scale ``h`` (may be traced).
        num_seeds: ``S``, static.
        max_clusters: ``M``, static, in ``[1, S]``.
        num_iters: mean-shift steps, static.
        merge_radius: modes this close (inclusive) are merged; ``bandwidth`` if ``None``. May be traced.
        kernel: ``"gaussian"`` or ``"flat"``, static.

    Returns:
        :class:`Clusters`. Centres and labels carry no gradient; ``weights`` carries that of ``weights``.
    """
    _check_count("num_seeds", num_seeds, 1)
    _check_count("max_clusters", max_clusters, 1)
    _check_count("num_iters", num_iters, 0)
    if max_clusters > num_seeds:
        raise ValueError(f"max_clusters: must be at most num_seeds ({num_seeds}), got {max_clusters}")
    if kernel not in KERNELS:
        raise ValueError(f"kernel: must be one of {', '.join(KERNELS)}, got {kernel!r}")
    weights = jnp.asarray(weights)
    pts = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    bandwidth = lax.stop_gradient(jnp.asarray(bandwidth, pts.dtype))
    radius = bandwidth if merge_radius is None else lax.stop_gradient(jnp.asarray(merge_radius, pts.dtype))
    px, py = pts[:, 0], pts[:, 1]

    def kernel_sums(x, y):
        kw = _kernel_weights(squared_distances(jnp.stack([x, y], axis=1), pts), w, bandwidth, kernel)
        return jnp.sum(kw, axis=1), jnp.sum(kw * px[None, :], axis=1), jnp.sum(kw * py[None, :], axis=1)

    def shift(_, state):
        x, y, _ = state
        den, num_x, num_y = kernel_sums(x, y)
        ok = den > 0
        safe = jnp.where(ok, den, 1.0)
        return jnp.where(ok, num_x / safe, x), jnp.where(ok, num_y / safe, y), den

    seeds = seed_points(pts, w, num_seeds)
    x, y = seeds[:, 0], seeds[:, 1]
    if num_iters == 0:
        density = kernel_sums(x, y)[0]
    else:
        # The density of the last window (as sklearn's "intensity"): no extra kernel evaluation.
        x, y, density = lax.fori_loop(0, num_iters, shift, (x, y, jnp.zeros_like(x)))
    modes = jnp.stack([x, y], axis=1)
    distinct = _greedy_merge(modes, density, radius)

    owner = _nearest(modes, modes, distinct)
    seed_count = jax.ops.segment_sum(jnp.ones_like(density), owner, num_segments=num_seeds)
    top_density = jnp.max(density)
    tie_break = 0.5 * density / jnp.where(top_density > 0, top_density, 1.0)
    _, top = lax.top_k(jnp.where(distinct, seed_count + tie_break, -1.0), max_clusters)
    valid = distinct[top]
    centres = jnp.where(valid[:, None], modes[top], 0.0)
    labels = _nearest(pts, centres, valid)
    cluster_weights = jax.ops.segment_sum(weights, labels, num_segments=max_clusters)
    return Clusters(labels=labels, centres=centres, weights=jnp.where(valid, cluster_weights, 0.0), valid=valid)
