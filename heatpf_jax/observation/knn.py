"""Exact k-nearest measurements by block minima: eq. (1)'s selection without a top_k over the whole buffer.

:func:`heatpf_jax.observation.kernels.k_nearest` builds the full ``[N, M]`` squared-distance
matrix and calls ``lax.top_k`` on it. On XLA:CPU that ``top_k`` is a per-row
comparator sort and costs most of the time (about 9 ms at N=1000, M=4096).
:func:`k_nearest_blocked` returns the same neighbours (up to distance ties) with
a tournament over blocks of consecutive measurements instead.

Algorithm
---------
The buffer is cut into *leaf blocks* of ``b`` consecutive slots (padded with
invalid slots to a whole number of blocks); ``fanouts = (f_1, ..., f_L)`` then
group ``f_1`` consecutive leaf blocks into a level-1 group, ``f_2`` level-1 groups
into a level-2 group, and so on (:func:`plan_blocks` picks them from ``M`` and
``k_max``). Any buffer order works, at the same cost: see *Buffer order* below.

1. *Block minima* (the only pass over all ``N x M`` pairs): for every particle
   and leaf block, the minimum squared distance to the block's valid members,
   as ``b`` elementwise ``[G, N]`` planes folded with ``minimum`` (no ``[N, M]``
   matrix, no ``[N, M, 2]`` tensor; particles on the minor axis). Group minima at
   the upper levels are minima of their children.
2. *Top-down selection*: at the top level keep the ``kk = min(k_max, M)`` groups
   with the smallest minima; at each lower level keep the ``kk`` smallest among
   the children of the groups kept so far (``kk * f`` candidates); at the leaves
   keep the ``kk`` nearest of the ``kk * b`` member measurements, in increasing
   distance. Each selection takes ``kk`` rounds of (column minimum, first row
   holding it, mask that row) on a ``[candidates, N]`` array, ordering candidates
   by ``(value, position)``; on XLA:CPU this is several times faster than
   ``lax.top_k`` on such short rows. Work per particle: ``M`` distances plus
   ``kk * (G_top + kk * f_L + ... + kk * f_1 + kk * b)`` compare-selects, instead of
   a ``top_k`` over ``M``.

   With a *traced* ``k`` (the filter's case: ``FilterParams.k`` is an array, bounded
   by the static ``k_max``) every selection runs only ``min(k, kk)`` rounds, in a
   ``lax.fori_loop``: the arrays keep their static ``kk``-sized shapes, and the
   ``kk - k`` slots left unfilled hold a *null group* (an extra ``+inf`` row appended
   to each level; its children are the null group of the level below, its slots
   the padding slot). ``k = 3`` under the default ``k_max = 10`` thus pays for 3
   rounds per level, not 10. Under ``vmap`` over ``k`` (sweeps) the batch runs the
   largest ``k`` of the batch as a shared, unbatched loop bound; extra rounds only
   keep more groups and neighbours beyond the ``k``-th, which ``selected`` masks.
3. The outputs are recomputed from the selected slots with the plain formula,
   so values, weights and gradients (through the selected distances and weights;
   the selection itself is discrete and runs on stopped gradients) match
   :func:`~heatpf_jax.observation.kernels.k_nearest`.

Steps 1-2 run over chunks of ``chunk_size`` particles in a ``lax.map``: the
selection's arrays then stay in cache and below the size at which XLA:CPU splits
an operation over threads (the hand-off costs more than these small operations).

Why it is exact
---------------
Give invalid and padding slots the value ``+inf`` (clamped to the largest finite
float), order candidates by ``(value, position)``, and let ``d*`` be the ``kk``-th
smallest squared distance over the whole buffer, ``A`` the slots below ``d*`` (fewer
than ``kk``) and ``E`` those equal to ``d*``. Claim: every candidate set contains all of
``A`` and at least ``kk - |A|`` slots of ``E``. It holds for the whole buffer. Suppose it
holds for a candidate set and we keep the ``kk`` groups that come first by
``(minimum, position)``; let ``m`` be the largest kept minimum. A group holding a slot of
``A`` has minimum ``< d*``; if it were not kept, each of the ``kk`` kept groups would have
a minimum ``< d*``, attained by ``kk`` distinct slots: impossible. If ``m > d*`` every group
with minimum ``<= d*`` is kept, so all of ``A`` and ``E`` stays. If ``m <= d*`` the kept
groups hold ``kk`` distinct slots with values ``<= d*``, so at least ``kk - |A|`` slots of
``E`` stay besides ``A``. With at most ``kk`` groups everything stays. At the leaves the
``kk`` first candidates are therefore ``A`` plus ``kk - |A|`` slots of ``E``: ``kk`` nearest
slots, i.e. the plain ``top_k``'s neighbour set up to the choice among ties at ``d*``
(``top_k`` prefers lower slots, this may not). With fewer than ``kk`` valid measurements
``d*`` is the invalid value, so all valid ones are selected; invalid slots are never
selected (``selected`` is ``valid[slot] & (rank < k)``). No step depends on the layout:
scattered valid slots stay exact, they only make block minima less selective, which
does not change the (static) work.
With a traced ``k`` the same argument holds with ``kk`` replaced by ``min(k, kk)``: each
level keeps the first ``k`` groups, null groups (``+inf``, above every clamped real value)
are only ever picked once fewer than ``k`` real candidates remain, which never happens
(every level offers at least ``k`` real candidates), and the leaves yield the ``k``
nearest slots in increasing distance; ``selected`` masks the rest.

Buffer order
------------
Nothing is pruned at run time: every level keeps ``kk`` groups whatever their minima, so the
work (and the compiled program) is the same for a raster-ordered heat map, a buffer in random
order or measurements fused from several sources; the order changes neither the neighbours nor
the cost. Measured on XLA:CPU (``benchmarks/bench_weights.py --layout both``; 2 cores): the
kernel takes the same time on raster blobs and on random-order buffers with particles spread
over the same area, and sorting the buffer and/or the particles along a Hilbert curve
beforehand (for free, outside the timed call) changed nothing beyond noise. Two exact schemes
that exploit spatial order were prototyped and measured (one XLA thread, k = 10):

* Hilbert-sorted groups chosen by bounding-box lower bounds (branch and bound over gathered
  candidates, with the certificate ``d_k <= smallest discarded bound`` and this kernel as the
  fallback): 1.0-1.9x slower at M = 1024 and 4096, about 15 % faster at M = 8192;
* this tournament with beams narrower than ``kk`` on a Hilbert-sorted buffer (same certificate
  and fallback): about 10 % faster at M = 1024, no faster at M = 4096.

The sort (0.1-0.2 ms for 4096 slots), the per-particle gathers and the fallback cost about what
they save: most of the time goes to the ``kk`` selection rounds per level, which do not depend on
the order.

Everything has static shapes and no data-dependent control flow, so the function
works under ``jit``, ``vmap`` (over ``k``, particles or buffers), ``scan`` and ``grad``.
Squared distances must be finite (coordinates well below 1e19 m).
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from heatpf_jax.measurements import Measurements

__all__ = [
    "DEFAULT_BLOCK_SIZE",
    "DEFAULT_CHUNK_SIZE",
    "BlockPlan",
    "k_nearest_blocked",
    "plan_blocks",
]

DEFAULT_BLOCK_SIZE = 4  # measurements per leaf block: best of 4, 8, 16 on XLA:CPU at M = 1024..8192
DEFAULT_CHUNK_SIZE = 512  # particles per selection chunk (see k_nearest_blocked)

# Plan cost model (see :func:`plan_blocks`), in units of one candidate taking part in the selection rounds.
_LEVEL_COST_PER_K = 2.0  # fixed cost of one extra level (its kk rounds of kernels), per unit of kk
_SLOT_COST_PER_K = 0.25  # one (padded) slot in the block-minimum pass, relative to kk candidates
_FANOUT_CHOICES = (2, 4, 8, 16)
_MAX_UPPER_LEVELS = 3


class BlockPlan(NamedTuple):
    """A static block hierarchy for :func:`k_nearest_blocked`.

    Attributes:
        block_size: ``b``, measurements per leaf block.
        fanouts: ``(f_1, ..., f_L)``: children per group at each level above the leaves, bottom-up.
        num_top: number of groups at the top level.
        padded_size: buffer size after padding, ``num_top * prod(fanouts) * block_size``.
    """

    block_size: int
    fanouts: tuple[int, ...]
    num_top: int
    padded_size: int


def _ceil_div(a: int, b: int) -> int:
    return -(-a // b)


def _plan_cost(num_measurements: int, kk: int, block_size: int, fanouts: tuple[int, ...]) -> float:
    """Estimated per-particle cost of a hierarchy: candidates over all selection levels, plus overheads.

    Calibrated on XLA:CPU (N = 500..2000, M = 1024..8192, k = 10): a selection level of ``R``
    candidates costs about ``0.42 ns * kk * R`` per particle, a distance ``0.11 ns``, and every
    extra level a fixed overhead of about ``20`` candidates at ``kk = 10``.
    """
    group = block_size * int(np.prod(fanouts, dtype=np.int64))
    num_top = _ceil_div(num_measurements, group)
    cost = _SLOT_COST_PER_K * num_top * group / kk + (num_top if num_top > kk else 0)
    kept = min(kk, num_top)
    for f in reversed(fanouts):
        cost += _LEVEL_COST_PER_K * kk + kept * f
        kept = min(kk, kept * f)
    return cost + kept * block_size


def plan_blocks(
    num_measurements: int,
    k_max: int,
    block_size: int = DEFAULT_BLOCK_SIZE,
    fanouts: tuple[int, ...] | None = None,
) -> BlockPlan:
    """Chooses the block hierarchy for a buffer of ``num_measurements`` slots (all static).

    Args:
        num_measurements: buffer size ``M >= 1``.
        k_max: static number of neighbours to select (clipped to ``M``).
        block_size: measurements per leaf block.
        fanouts: children per group at each level above the leaves, bottom-up; by
            default the sequence of up to three values in ``(2, 4, 8, 16)`` (or none)
            with the smallest estimated cost (``(4,)`` for M = 1024, ``(4, 4)`` for M = 4096
            and ``(4, 4, 4)`` for M = 8192 at k_max = 10 and the default block size).

    Returns:
        The :class:`BlockPlan`.
    """
    num_measurements, k_max, block_size = int(num_measurements), int(k_max), int(block_size)
    if num_measurements < 1:
        raise ValueError(f"num_measurements: must be >= 1, got {num_measurements}")
    if k_max < 1:
        raise ValueError(f"k_max: must be >= 1, got {k_max}")
    if block_size < 1:
        raise ValueError(f"block_size: must be >= 1, got {block_size}")
    kk = min(k_max, num_measurements)
    num_leaves = _ceil_div(num_measurements, block_size)
    if fanouts is None:
        options: list[tuple[int, ...]] = [()]
        for depth in range(1, _MAX_UPPER_LEVELS + 1):
            for fans in itertools.product(_FANOUT_CHOICES, repeat=depth):
                if int(np.prod(fans)) < num_leaves:
                    options.append(fans)
        fanouts = min(options, key=lambda fans: _plan_cost(num_measurements, kk, block_size, fans))
    fanouts = tuple(int(f) for f in fanouts)
    if any(f < 1 for f in fanouts):
        raise ValueError(f"fanouts: must be positive, got {fanouts}")
    group = block_size * int(np.prod(fanouts, dtype=np.int64))
    num_top = _ceil_div(num_measurements, group)
    return BlockPlan(block_size, fanouts, num_top, num_top * group)


def _static_k_max(k, k_max: int | None, size: int) -> int:
    if k_max is None:
        try:
            k_max = int(k)
        except TypeError as err:  # includes jax.errors.ConcretizationTypeError
            raise ValueError("k: a traced k needs a static k_max") from err
    if k_max < 1:
        raise ValueError(f"k_max: must be >= 1, got {k_max}")
    return min(int(k_max), size)


def _smallest_rows(
    values: Float[Array, "r n"], count: int, rounds: Int[ArrayLike, ""] | None = None
) -> Int[Array, "c n"]:
    """Row indices of the ``count`` smallest entries of each column, in increasing ``(value, row)``.

    ``count`` rounds of: column minimum, first row holding it, mask that row with ``+inf``.
    ``values`` must be below ``+inf`` on real rows (masked rows are ``+inf``) and have more
    than ``count - 1`` rows.

    With ``rounds`` (a traced integer, at most ``count``) only that many rounds run, in a
    ``lax.fori_loop``; rows ``rounds..count-1`` of the result hold ``r`` (one past the last
    row: the caller's null row).
    """
    rows = values.shape[0]
    row = lax.broadcasted_iota(jnp.int32, values.shape, 0)

    def one_round(values):
        low = jnp.min(values, axis=0)
        return jnp.min(jnp.where(values == low[None, :], row, rows), axis=0)

    if rounds is None:
        picked = []
        for t in range(count):
            first = one_round(values)
            picked.append(first)
            if t + 1 < count:
                values = jnp.where(row == first[None, :], jnp.inf, values)
        return jnp.stack(picked, axis=0)

    def body(t, carry):
        values, out = carry
        first = one_round(values)
        out = lax.dynamic_update_slice(out, first[None, :], (t, jnp.zeros_like(t)))
        return jnp.where(row == first[None, :], jnp.inf, values), out

    out = jnp.full((count, values.shape[1]), rows, jnp.int32)
    num = jnp.clip(_shared_round_count(jnp.asarray(rounds, jnp.int32)), 0, count)
    return lax.fori_loop(jnp.zeros_like(num), num, body, (values, out))[1]


@jax.custom_batching.custom_vmap
def _shared_round_count(k: Int[Array, ""]) -> Int[Array, ""]:
    """The number of selection rounds for a traced ``k``: ``k`` itself, or under ``vmap`` the batch's maximum.

    A batched loop bound would make ``lax.fori_loop`` a while loop that selects its whole carry
    (the ``[candidates, N]`` values of every batch member) after each round. More rounds than
    ``k`` only keep more groups, which leaves the first ``k`` neighbours unchanged, so the batch
    shares one unbatched bound instead.
    """
    return k


@_shared_round_count.def_vmap
def _shared_round_count_vmap(axis_size: int, in_batched: list[bool], k: Int[Array, " b"]):
    del axis_size
    return (jnp.max(k) if in_batched[0] else k), False


def _with_null_row(table: Array, fill) -> Array:
    """``table`` with one more row (the null group) filled with ``fill``."""
    return jnp.concatenate([table, jnp.full((1,) + table.shape[1:], fill, table.dtype)], axis=0)


def _fold_min(planes: list[Float[Array, "g n"]]) -> Float[Array, "g n"]:
    """Elementwise minimum of a list of planes (one loop fusion on XLA:CPU, unlike a reduce)."""
    out = planes[0]
    for plane in planes[1:]:
        out = jnp.minimum(out, plane)
    return out


def _gather_blocks(table: Float[Array, "g b"], blocks: Int[Array, "r n"]) -> Float[Array, "r b n"]:
    """``out[i, j, n] = table[blocks[i, n], j]``: whole rows of ``table`` (contiguous slices)."""
    dnums = lax.GatherDimensionNumbers(offset_dims=(1,), collapsed_slice_dims=(0,), start_index_map=(0,))
    return lax.gather(
        table,
        blocks[:, :, None],
        dnums,
        slice_sizes=(1, table.shape[1]),
        mode=lax.GatherScatterMode.PROMISE_IN_BOUNDS,
    )


def _select_slots(
    px: Float[Array, " n"],
    py: Float[Array, " n"],
    x: Float[Array, " mp"],
    y: Float[Array, " mp"],
    kk: int,
    plan: BlockPlan,
    rounds: Int[Array, ""] | None = None,
) -> Int[Array, "kk n"]:
    """Slots of the ``kk`` nearest points ``(x, y)`` (``+inf`` = invalid) to each particle, nearest first.

    With ``rounds`` (traced ``k``) only the first ``min(k, kk)`` rows are neighbours; the
    others hold the padding slot ``plan.padded_size``.
    """
    n = px.shape[0]
    b = plan.block_size
    big = float(jnp.finfo(x.dtype).max)  # invalid slots: largest finite value; masked rows: +inf
    num_leaves = plan.padded_size // b
    xb = x.reshape(num_leaves, b)
    yb = y.reshape(num_leaves, b)
    pxr, pyr = px[None, :], py[None, :]
    dynamic = rounds is not None

    planes = []
    for j in range(b):
        dx = xb[:, j, None] - pxr
        dy = yb[:, j, None] - pyr
        planes.append(dx * dx + dy * dy)
    minima = [_fold_min(planes)]  # [leaves, N]
    for f in plan.fanouts:
        # A reduce, not a fold: XLA:CPU then materializes each level once instead of re-deriving
        # it inside the consumers of every selection round.
        minima.append(jnp.min(minima[-1].reshape(-1, f, n), axis=1))

    # With a traced k, index G of a level (one past its last group) is its null group.
    top = jnp.minimum(minima[-1], big)
    null = top.shape[0]
    if top.shape[0] > kk:
        groups = _smallest_rows(top, kk, rounds)
    else:
        groups = lax.broadcasted_iota(jnp.int32, top.shape, 0)
    for level in range(len(plan.fanouts) - 1, -1, -1):
        f = plan.fanouts[level]
        r = groups.shape[0]
        children = (groups[:, None, :] * f + jnp.arange(f, dtype=jnp.int32)[None, :, None]).reshape(r * f, n)
        table = jnp.minimum(minima[level], big)
        if dynamic:
            children = jnp.where(jnp.repeat(groups == null, f, axis=0), table.shape[0], children)
            table = _with_null_row(table, jnp.inf)
            null = minima[level].shape[0]
        if r * f > kk:
            values = jnp.take_along_axis(table, children, axis=0)
            picked = _smallest_rows(values, kk, rounds)
            if dynamic:
                children = _with_null_row(children, null)
            groups = jnp.take_along_axis(children, picked, axis=0)
        else:
            groups = children

    r = groups.shape[0]
    if dynamic:
        xb, yb = _with_null_row(xb, jnp.inf), _with_null_row(yb, jnp.inf)
    dx = _gather_blocks(xb, groups) - pxr[None]
    dy = _gather_blocks(yb, groups) - pyr[None]
    sq = jnp.minimum(dx * dx + dy * dy, big)
    slots = groups[:, None, :] * b + jnp.arange(b, dtype=jnp.int32)[None, :, None]
    if dynamic:
        is_null = jnp.broadcast_to((groups == null)[:, None, :], sq.shape)
        sq = jnp.where(is_null, jnp.inf, sq)
        slots = jnp.where(is_null, plan.padded_size, slots)
    sq = sq.reshape(r * b, n)
    slots = slots.reshape(r * b, n)
    picked = _smallest_rows(sq, kk, rounds)
    if dynamic:
        slots = _with_null_row(slots, plan.padded_size)
    return jnp.take_along_axis(slots, picked, axis=0)


def _select_slots_chunked(
    px: Float[Array, " n"],
    py: Float[Array, " n"],
    x: Float[Array, " mp"],
    y: Float[Array, " mp"],
    kk: int,
    plan: BlockPlan,
    chunk_size: int,
    rounds: Int[Array, ""] | None = None,
) -> Int[Array, "n kk"]:
    """:func:`_select_slots` over chunks of ``chunk_size`` particles (``lax.map``), as ``[N, kk]``."""
    n = px.shape[0]
    if n <= chunk_size:
        return _select_slots(px, py, x, y, kk, plan, rounds).T
    num = _ceil_div(n, chunk_size)
    pad = num * chunk_size - n
    pxc = jnp.pad(px, (0, pad)).reshape(num, chunk_size)
    pyc = jnp.pad(py, (0, pad)).reshape(num, chunk_size)
    slots = lax.map(lambda c: _select_slots(c[0], c[1], x, y, kk, plan, rounds), (pxc, pyc))  # [num, kk, chunk]
    return jnp.transpose(slots, (0, 2, 1)).reshape(num * chunk_size, kk)[:n]


def k_nearest_blocked(
    particles: Float[ArrayLike, "n 2"],
    measurements: Measurements,
    k: Int[ArrayLike, ""],
    *,
    k_max: int | None = None,
    block_size: int = DEFAULT_BLOCK_SIZE,
    fanouts: tuple[int, ...] | None = None,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
) -> tuple[Float[Array, "n kmax"], Float[Array, "n kmax"], Bool[Array, "n kmax"]]:
    """Each particle's k nearest valid measurements, by block minima (same contract as ``k_nearest``).

    Returns the same values as :func:`heatpf_jax.observation.kernels.k_nearest` (the same
    neighbour set up to distance ties), without its ``[N, M]`` ``top_k``; see the
    module docstring for the algorithm and why it is exact.

    Args:
        particles: ``[N, 2]`` positions.
        measurements: a buffer of size ``M``, in any order (the work does not depend on it).
        k: number of neighbours, ``1 <= k <= k_max`` (may be traced).
        k_max: static upper bound on ``k``; defaults to ``k`` (then ``k`` must be concrete).
        block_size: static number of consecutive slots per leaf block; ``M`` need not be a multiple.
        fanouts: static groups per level above the leaves (bottom-up); default from :func:`plan_blocks`.
        chunk_size: static number of particles selected per step of a ``lax.map``: keeps the
            selection's arrays small (cache-resident, and below XLA:CPU's threshold for splitting
            an operation over threads, whose hand-offs cost more than these small operations).

    Returns:
        ``(sq_dist, weight, selected)`` each ``[N, min(k_max, M)]``: squared
        distances and weights of the nearest measurements in increasing
        distance, and whether each slot is among the k nearest *valid* ones
        (unselected slots hold ``sq_dist = 1`` and ``weight = 0``).
    """
    particles = jnp.asarray(particles)
    xy = measurements.xy
    size = xy.shape[0]
    kk = _static_k_max(k, k_max, size)
    plan = plan_blocks(size, kk, block_size, fanouts)

    # Selection: discrete, so computed on stopped gradients, in the common float dtype.
    dtype = jnp.promote_types(particles.dtype, xy.dtype)
    pad = plan.padded_size - size
    valid = jnp.pad(measurements.valid, (0, pad))
    xy_sel = jnp.pad(lax.stop_gradient(xy).astype(dtype), ((0, pad), (0, 0)))
    x = jnp.where(valid, xy_sel[:, 0], jnp.inf)
    y = jnp.where(valid, xy_sel[:, 1], jnp.inf)
    p_sel = lax.stop_gradient(particles).astype(dtype)
    if chunk_size < 1:
        raise ValueError(f"chunk_size: must be >= 1, got {chunk_size}")
    # A concrete k runs all kk rounds unrolled; a traced one only min(k, kk) rounds per level.
    rounds = None if isinstance(k, (int, np.integer)) else jnp.asarray(k, jnp.int32)
    slots = _select_slots_chunked(p_sel[:, 0], p_sel[:, 1], x, y, kk, plan, int(chunk_size), rounds)  # [N, kk]

    # Outputs: the plain formulation's expressions at the selected slots (differentiable).
    in_buffer = slots < size  # padding slots are never valid
    slots = jnp.minimum(slots, size - 1)
    selected = in_buffer & measurements.valid[slots] & (jnp.arange(kk, dtype=jnp.int32) < k)[None, :]
    dx = particles[:, 0, None] - xy[slots, 0]
    dy = particles[:, 1, None] - xy[slots, 1]
    sq_sel = jnp.where(selected, dx * dx + dy * dy, 1.0)
    w_sel = jnp.where(selected, measurements.weight[slots], 0.0)
    return sq_sel, w_sel, selected
