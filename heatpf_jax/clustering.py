"""Clustering of weighted 2-D particles with fixed sizes: mean shift, k-means and Gaussian-mixture EM.

The multi-modal output (III-F; Olufs et al. 2006, sec. 3.2, the "extended particle filter") needs
the modes of the particle set every filter step, so everything here is jittable with static sizes,
works under ``vmap`` and costs O(S N) or O(K N) per iteration:

* :func:`mean_shift` (Comaniciu & Meer 2002): ``S`` seeds, not all N particles, climb the weighted
  kernel density; converged modes closer than a merge radius are merged greedily in order of
  density (sklearn's rule); at most ``M`` modes are kept (the heaviest) behind a ``valid`` mask.
* :func:`kmeans_plus_plus` and :func:`kmeans`: weighted k-means++ seeding and Lloyd iterations.
* :func:`gmm_em`: EM (:func:`responsibilities`, :func:`m_step`) for a weighted mixture of
  full-covariance Gaussians, in log space.

Mean shift and k-means are discrete decisions: their centres, labels and the choices inside are
computed on ``stop_gradient`` inputs, so ``jax.grad`` through them is finite (zero). Sums over the
members (:attr:`Clusters.weights`, :attr:`KMeans.weights`, :func:`weighted_stats`) keep the gradient
of the inputs, and EM is smooth throughout. All-zero weights are treated as uniform; nothing returns
NaN. The pieces that turn these into the filter's modes are in :mod:`heatpf_jax.modes`.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

__all__ = [
    "KERNELS",
    "Clusters",
    "KMeans",
    "Mixture",
    "gmm_em",
    "grid_cells",
    "kmeans",
    "kmeans_plus_plus",
    "m_step",
    "mean_shift",
    "mixture_from_labels",
    "mixture_log_prob",
    "responsibilities",
    "seed_points",
    "squared_distances",
    "usable_weights",
    "weighted_stats",
]

KERNELS = ("gaussian", "flat")
_LOG_2PI = math.log(2.0 * math.pi)


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


class KMeans(NamedTuple):
    """What :func:`kmeans` returns.

    Attributes:
        centres: ``float32 [K, 2]`` the centres after the last Lloyd update.
        labels: ``int32 [N]`` each point's nearest centre.
        weights: ``float32 [K]`` the sum of the member weights.
    """

    centres: Float[Array, "k 2"]
    labels: Int[Array, " n"]
    weights: Float[Array, " k"]


class Mixture(NamedTuple):
    """A mixture of ``K`` Gaussians in the plane.

    Attributes:
        weight: ``float32 [K]`` mixing weights, summing to 1.
        mean: ``float32 [K, 2]``.
        cov: ``float32 [K, 2, 2]`` full covariances.
    """

    weight: Float[Array, " k"]
    mean: Float[Array, "k 2"]
    cov: Float[Array, "k 2 2"]


def _check_count(name: str, value, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"{name}: must be an integer >= {low}, got {value!r}")


def usable_weights(weights: Float[ArrayLike, " n"]) -> Float[Array, " n"]:
    """``weights``, or all ones when they sum to zero (no information: treat the points alike)."""
    weights = jnp.asarray(weights)
    return jnp.where(jnp.sum(weights) > 0, weights, jnp.ones_like(weights))


def squared_distances(a: Float[ArrayLike, "m 2"], b: Float[ArrayLike, "n 2"]) -> Float[Array, "m n"]:
    """``|a_i - b_j|^2`` from the coordinate differences (exact at zero, unlike the dot-product form).

    Written per coordinate: XLA's CPU backend vectorises ``[m, n]`` planes far better than a reduction
    over a trailing axis of size 2.
    """
    a = jnp.asarray(a)
    b = jnp.asarray(b)
    dx = a[:, 0][:, None] - b[:, 0][None, :]
    dy = a[:, 1][:, None] - b[:, 1][None, :]
    return dx * dx + dy * dy


def weighted_stats(
    points: Float[ArrayLike, "n 2"], member_weights: Float[ArrayLike, "n k"], fallback: Float[ArrayLike, "k 2"]
) -> tuple[Float[Array, " k"], Float[Array, "k 2"], Float[Array, "k 2 2"]]:
    """Mass, weighted mean and biased weighted covariance of ``K`` (soft or hard) groups of points.

    Args:
        points: ``[N, 2]``.
        member_weights: ``[N, K]`` weight of point i in group k (``w_i r_ik``, or ``w_i`` one-hot).
        fallback: ``[K, 2]`` the mean of a group without mass (its covariance is then zero).

    Returns:
        ``(mass [K], mean [K, 2], cov [K, 2, 2])``.
    """
    points = jnp.asarray(points)
    member_weights = jnp.asarray(member_weights)
    mass = jnp.sum(member_weights, axis=0)
    has_mass = mass > 0
    safe_mass = jnp.where(has_mass, mass, 1.0)
    # Elementwise products and sums, no dot: K and 2 are tiny, and XLA compiles these much faster.
    px, py = points[:, 0][:, None], points[:, 1][:, None]
    mean_x = jnp.sum(member_weights * px, axis=0) / safe_mass
    mean_y = jnp.sum(member_weights * py, axis=0) / safe_mass
    mean = jnp.where(has_mass[:, None], jnp.stack([mean_x, mean_y], axis=1), jnp.asarray(fallback))
    dx = px - mean[:, 0][None, :]
    dy = py - mean[:, 1][None, :]
    cxx = jnp.sum(member_weights * dx * dx, axis=0) / safe_mass
    cxy = jnp.sum(member_weights * dx * dy, axis=0) / safe_mass
    cyy = jnp.sum(member_weights * dy * dy, axis=0) / safe_mass
    cov = jnp.stack([jnp.stack([cxx, cxy], axis=1), jnp.stack([cxy, cyy], axis=1)], axis=1)
    return mass, mean, cov


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


def _nearest(points, centres, allowed) -> Int[Array, " n"]:
    """Index of the nearest allowed centre (the first of equals), as two plain ``min`` reductions:
    XLA's CPU backend runs those far faster than ``argmin``'s value-index reduction."""
    k = centres.shape[0]
    d2 = jnp.where(allowed[None, :], squared_distances(points, centres), jnp.inf)
    best = jnp.min(d2, axis=1, keepdims=True)
    return jnp.min(jnp.where(d2 == best, jnp.arange(k, dtype=jnp.int32)[None, :], k), axis=1)


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


def kmeans_plus_plus(
    key: PRNGKeyArray, points: Float[ArrayLike, "n 2"], weights: Float[ArrayLike, " n"], num_clusters: int
) -> Float[Array, "k 2"]:
    """Weighted greedy k-means++ seeding (Arthur & Vassilvitskii 2007; sklearn's variant).

    The first centre is drawn with probability proportional to ``w_i``. For each next one,
    ``2 + floor(ln K)`` candidates are drawn proportional to ``w_i D_i^2`` (``D_i``: distance to the
    nearest centre so far) and the one that leaves the smallest potential ``sum_i w_i D_i^2`` is kept;
    if every point with weight already coincides with a centre, candidates are drawn proportional to
    ``w_i``. No gradient.

    Args:
        key: PRNG key.
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        num_clusters: ``K``, static.

    Returns:
        ``[K, 2]`` initial centres (points of the set).
    """
    _check_count("num_clusters", num_clusters, 1)
    pts = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    n = w.shape[0]
    trials = 2 + int(math.log(num_clusters))
    # Uniforms turned into indices by inverse-CDF search: cheaper to run and to compile than
    # categorical draws over all N points.
    u = jax.random.uniform(key, (num_clusters, trials), w.dtype)

    def draw(p, u_k):
        cdf = jnp.cumsum(p)
        return jnp.clip(jnp.searchsorted(cdf, u_k * cdf[-1], side="right", method="compare_all"), 0, n - 1)

    first = draw(w, u[0, :1])[0]
    centres = jnp.zeros((num_clusters, 2), pts.dtype).at[0].set(pts[first])
    d2 = squared_distances(pts[first][None, :], pts)[0]

    def add_centre(k, state):
        centres, d2 = state
        p = w * d2
        candidates = draw(jnp.where(jnp.sum(p) > 0, p, w), u[k])
        d2_new = jnp.minimum(d2[None, :], squared_distances(pts[candidates], pts))  # [trials, N]
        best = jnp.argmin(jnp.sum(d2_new * w[None, :], axis=1))
        return centres.at[k].set(pts[candidates[best]]), d2_new[best]

    centres, _ = lax.fori_loop(1, num_clusters, add_centre, (centres, d2))
    return centres


def kmeans(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    centres: Float[ArrayLike, "k 2"],
    *,
    num_iters: int,
) -> KMeans:
    """Weighted Lloyd iterations from ``centres``: assign to the nearest centre, move centres to the
    weighted means of their members. A centre without member weight stays where it is.

    Args:
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        centres: ``[K, 2]`` initial centres (e.g. :func:`kmeans_plus_plus`).
        num_iters: Lloyd iterations, static.

    Returns:
        :class:`KMeans`: the centres after the last update, the labels of those centres (as sklearn's
        ``KMeans``) and the member weight sums (of ``weights``, which keep their gradient).
    """
    _check_count("num_iters", num_iters, 0)
    weights = jnp.asarray(weights)
    pts = lax.stop_gradient(jnp.asarray(points))
    w = lax.stop_gradient(usable_weights(weights))
    centres = lax.stop_gradient(jnp.asarray(centres, pts.dtype))
    k = centres.shape[0]
    everyone = jnp.ones((k,), bool)

    def update(_, c):
        member = jax.nn.one_hot(_nearest(pts, c, everyone), k, dtype=w.dtype) * w[:, None]
        mass = jnp.sum(member, axis=0)
        moved = (member.T @ pts) / jnp.where(mass > 0, mass, 1.0)[:, None]
        return jnp.where((mass > 0)[:, None], moved, c)

    centres = lax.fori_loop(0, num_iters, update, centres)
    labels = _nearest(pts, centres, everyone)
    return KMeans(centres=centres, labels=labels, weights=weights @ jax.nn.one_hot(labels, k, dtype=weights.dtype))


def _regularised(cov, reg_covar):
    return cov + reg_covar * jnp.eye(2, dtype=cov.dtype)[None, :, :]


def mixture_from_labels(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    labels: Int[ArrayLike, " n"],
    centres: Float[ArrayLike, "k 2"],
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """The mixture of hard clusters (EM's initialisation from k-means): weight shares, member means,
    member covariances plus ``reg_covar I``. A cluster without weight keeps its centre and gets
    ``reg_covar I`` and weight 0."""
    points = jnp.asarray(points)
    w = usable_weights(weights)
    k = jnp.asarray(centres).shape[0]
    member = jax.nn.one_hot(jnp.asarray(labels), k, dtype=w.dtype) * w[:, None]
    mass, mean, cov = weighted_stats(points, member, centres)
    return Mixture(weight=mass / jnp.sum(mass), mean=mean, cov=_regularised(cov, reg_covar))


def mixture_log_prob(points: Float[ArrayLike, "n 2"], mixture: Mixture) -> Float[Array, "n k"]:
    """``log(pi_k N(x_i | mu_k, Sigma_k))`` for every point and component (``-inf`` where ``pi_k = 0``).

    The 2 x 2 inverse and determinant are written out: ``Sigma = [[a, b], [b, c]]``,
    ``(x - mu)^T Sigma^{-1} (x - mu) = (c dx^2 - 2 b dx dy + a dy^2) / (a c - b^2)``.
    """
    points = jnp.asarray(points)
    a = mixture.cov[:, 0, 0]
    b = 0.5 * (mixture.cov[:, 0, 1] + mixture.cov[:, 1, 0])
    c = mixture.cov[:, 1, 1]
    det = a * c - b * b
    d = points[:, None, :] - mixture.mean[None, :, :]  # [N, K, 2]
    dx, dy = d[..., 0], d[..., 1]
    maha = (c[None, :] * dx * dx - 2.0 * b[None, :] * dx * dy + a[None, :] * dy * dy) / det[None, :]
    positive = mixture.weight > 0
    log_pi = jnp.where(positive, jnp.log(jnp.where(positive, mixture.weight, 1.0)), -jnp.inf)
    return (log_pi - 0.5 * jnp.log(det) - _LOG_2PI)[None, :] - 0.5 * maha


def responsibilities(points: Float[ArrayLike, "n 2"], mixture: Mixture) -> Float[Array, "n k"]:
    """E-step: ``r_ik = pi_k N(x_i | k) / sum_l pi_l N(x_i | l)``, normalised in log space."""
    log_p = mixture_log_prob(points, mixture)
    return jnp.exp(log_p - jax.nn.logsumexp(log_p, axis=1, keepdims=True))


def m_step(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    resp: Float[ArrayLike, "n k"],
    previous: Mixture,
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """M-step with point weights ``w_i`` (equivalent to repeating point i ``w_i`` times)::

        N_k = sum_i w_i r_ik,  pi_k = N_k / sum_k N_k,  mu_k = sum_i w_i r_ik x_i / N_k,
        Sigma_k = sum_i w_i r_ik (x_i - mu_k)(x_i - mu_k)^T / N_k + reg_covar I

    A component whose ``N_k`` is zero keeps ``previous``'s mean and covariance, with weight 0. All-zero
    weights count as uniform.
    """
    w = usable_weights(weights)
    mass, mean, cov = weighted_stats(points, jnp.asarray(resp) * w[:, None], previous.mean)
    cov = jnp.where((mass > 0)[:, None, None], _regularised(cov, reg_covar), previous.cov)
    return Mixture(weight=mass / jnp.sum(mass), mean=mean, cov=cov)


def gmm_em(
    points: Float[ArrayLike, "n 2"],
    weights: Float[ArrayLike, " n"],
    init: Mixture,
    *,
    num_iters: int,
    reg_covar: Float[ArrayLike, ""],
) -> Mixture:
    """EM for a weighted mixture of full-covariance Gaussians: ``num_iters`` steps of
    :func:`responsibilities` (log space) then :func:`m_step`, from ``init``.

    Args:
        points: ``[N, 2]``.
        weights: ``[N]`` non-negative; all zero counts as uniform.
        init: the starting :class:`Mixture` (``K`` components).
        num_iters: EM steps, static.
        reg_covar: added to the diagonal of every covariance.

    Returns:
        The fitted :class:`Mixture`. Every operation is smooth, so ``jax.grad`` flows through all the
        steps (compiling that is costly: :class:`heatpf_jax.modes.GaussianMixtureModes` differentiates
        only the last M-step).
    """
    _check_count("num_iters", num_iters, 0)
    points = jnp.asarray(points)

    def step(_, mix: Mixture) -> Mixture:
        return m_step(points, weights, responsibilities(points, mix), mix, reg_covar)

    init = Mixture(*(jnp.asarray(x, points.dtype) for x in init))
    return lax.fori_loop(0, num_iters, step, init)
