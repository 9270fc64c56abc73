"""The detector's blob size, learned from the heat maps themselves: the mode of recent frames' blob sizes.

:class:`~heatpf_jax.sources.lofted.LoftedSource` tells a ball in the air from one on the ground by comparing a blob's
apparent radius with a ground ball's there. The apparent radius comes from the blob's std, ``rho = s / b``, and
``b`` (the detector's blob std per apparent ball radius) is a property of the detector, not of the world: 0.6 for
the package's simulator, anything from 0.3 to 1.5 for a real network (its blob's softness, size, saturation and
blur all scale it). A wrong ``b`` reads every ground ball as flying (``b`` too small) or no flying ball as one.

Most of the time the ball is on the ground, so the detector's own ``b`` is what most blobs show: each frame with a
blob gives the activation-weighted median, over its above-threshold pixels, of

    l = log(s / rho_g)            (rho_g: a ground ball's radius at the blob's centroid, pixels)

which is ``log b`` for a ball on the ground (plus the noise of ``s``) and larger for a ball in the air. The last
``frames`` such values are kept (a ring buffer, :class:`BlobScaleState`). Their ``quantile``
(:func:`blob_scale_estimate`; a median over 256 frames, 8.5 s at 30 Hz) stays on the ground balls' value through
flights of up to half of that; their half-sample mode (:func:`ground_centre`) and the spread below it
(:func:`ground_spread`) stay on it through flights that fill most of the recent frames, as at the start of a run.
Before the first blob the prior ``blob_scale`` is used.

This is the way a camera's exposure or a detector's threshold is set from the data it sees: no calibration
constant of the detector is needed. Every function here is pure and jittable.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float, Int

__all__ = [
    "BlobScaleState",
    "blob_scale_estimate",
    "blob_scale_spread",
    "frame_log_ratio",
    "ground_centre",
    "ground_spread",
    "init_blob_scale",
    "update_blob_scale",
]


class BlobScaleState(NamedTuple):
    """The recent frames' blob-size ratios (a ring buffer).

    Attributes:
        log_ratios: ``float32 [F]`` each frame's ``l`` (:func:`frame_log_ratio`), oldest overwritten first.
        filled: ``bool [F]`` which slots hold a frame's value.
        next: ``int32 []`` the slot the next value goes to.
    """

    log_ratios: Float[Array, " f"]
    filled: Bool[Array, " f"]
    next: Int[Array, ""]


def init_blob_scale(frames: int) -> BlobScaleState:
    """An empty buffer of ``frames`` slots (at least one)."""
    f = max(int(frames), 1)
    return BlobScaleState(jnp.zeros((f,), jnp.float32), jnp.zeros((f,), bool), jnp.zeros((), jnp.int32))


def frame_log_ratio(
    std_px: Float[ArrayLike, " m"],
    ground_radius_px: Float[ArrayLike, " m"],
    weight: Float[ArrayLike, " m"],
    valid: Bool[ArrayLike, " m"],
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """One frame's ``l``: the ``weight``-weighted median of ``log(std_px / ground_radius_px)``.

    Pixels count where ``valid``, their blob has a positive std and a ground ball there has a positive radius
    (below the horizon).

    Args:
        std_px: ``[M]`` each pixel's blob std, pixels (:attr:`~heatpf_jax.sources.lofted.BlobSizes.std_px`).
        ground_radius_px: ``[M]`` a ground ball's radius at each blob's centroid, pixels.
        weight: ``[M]`` each pixel's activation.
        valid: ``[M]`` which pixels are measured.

    Returns:
        ``(l, has)``: the weighted median (the lower one at a tie), and whether any pixel counted.
    """
    std = jnp.asarray(std_px, jnp.float32)
    ground = jnp.asarray(ground_radius_px, jnp.float32)
    ok = jnp.asarray(valid, bool) & (std > 0.0) & (ground > 0.0) & jnp.isfinite(std) & jnp.isfinite(ground)
    ratio = jnp.log(jnp.where(ok, std, 1.0)) - jnp.log(jnp.where(ok, ground, 1.0))
    w = jnp.where(ok, jnp.asarray(weight, jnp.float32), 0.0)
    order = jnp.argsort(jnp.where(ok, ratio, jnp.inf))
    cum = jnp.cumsum(w[order])
    total = cum[-1]
    i = jnp.clip(jnp.searchsorted(cum, 0.5 * total, side="left"), 0, ratio.shape[0] - 1)
    has = total > 0.0
    return jnp.where(has, ratio[order][i], 0.0), has


def update_blob_scale(
    state: BlobScaleState, log_ratio: Float[ArrayLike, ""], has: Bool[ArrayLike, ""]
) -> BlobScaleState:
    """``state`` with ``log_ratio`` stored in the next slot when ``has`` (unchanged otherwise)."""
    has = jnp.asarray(has, bool)
    f = state.log_ratios.shape[0]
    slot = state.next % f
    return BlobScaleState(
        log_ratios=jnp.where(has, state.log_ratios.at[slot].set(jnp.asarray(log_ratio, jnp.float32)),
                             state.log_ratios),
        filled=jnp.where(has, state.filled.at[slot].set(True), state.filled),
        next=jnp.where(has, (slot + 1) % f, state.next).astype(jnp.int32),
    )


def blob_scale_estimate(
    state: BlobScaleState, prior: Float[ArrayLike, ""], quantile: Float[ArrayLike, ""] = 0.5
) -> Float[Array, ""]:
    """The detector's blob std per apparent radius: ``exp`` of the ``quantile`` of the stored values (NumPy's
    ``quantile(..., method="lower")``), or ``prior`` while none is stored."""
    count = jnp.sum(state.filled)
    values = jnp.sort(jnp.where(state.filled, state.log_ratios, jnp.inf))  # stored values first
    rank = jnp.clip(jnp.floor(jnp.asarray(quantile, jnp.float32) * (count - 1).astype(jnp.float32)), 0, None)
    i = jnp.clip(rank.astype(jnp.int32), 0, state.log_ratios.shape[0] - 1)
    return jnp.where(count > 0, jnp.exp(values[i]), jnp.asarray(prior, jnp.float32))


def blob_scale_spread(state: BlobScaleState) -> Float[Array, ""]:
    """The robust spread of the stored values about their median: ``1.4826`` times their median absolute deviation
    (the std of normal values; 0 while fewer than two are stored). Medians as NumPy's ``method="lower"``."""
    count = jnp.sum(state.filled)
    f = state.log_ratios.shape[0]

    def lower_median(x):
        values = jnp.sort(jnp.where(state.filled, x, jnp.inf))
        return values[jnp.clip((count - 1) // 2, 0, f - 1)]

    centre = lower_median(state.log_ratios)
    mad = lower_median(jnp.abs(state.log_ratios - centre))
    return jnp.where(count > 1, 1.4826 * mad, 0.0)


def _half_sample_mode(state: BlobScaleState, min_window: int = 8) -> Float[Array, ""]:
    """The stored values' mode, robust to a minority or a majority of larger values: the half-sample mode (Bickel
    and Fruehwirth, 2006). The shortest interval holding half of the values, then the shortest holding half of those,
    and so on down to a quarter of the values (at least ``min_window``), whose median it returns (``inf`` with none
    stored). Ground balls' sizes are one tight cluster and flights' are spread over a decade, so the nested
    intervals close on the ground balls' values even where most recent frames are in flight (the shortest half alone
    would hold some of the flights' and lie above them). Of intervals as short as the shortest (to float rounding),
    the one nearest the middle is taken: values without a denser part give their middle, not their lowest part.
    """
    f = state.log_ratios.shape[0]
    count = jnp.sum(state.filled).astype(jnp.int32)
    values = jnp.sort(jnp.where(state.filled, state.log_ratios, jnp.inf))
    idx = jnp.arange(f)
    smallest = jnp.maximum(count // 4, min_window)

    def halve(_, window):
        lo, n = window
        k = jnp.minimum(jnp.maximum((n + 1) // 2, smallest), n)
        starts = (idx >= lo) & (idx + k <= lo + n)
        length = jnp.where(starts, values[jnp.clip(idx + k - 1, 0, f - 1)] - values, jnp.inf)
        shortest = jnp.min(length)
        tie = starts & (length <= shortest + 1e-6 * (1.0 + jnp.abs(shortest)))
        middle = lo.astype(jnp.float32) + 0.5 * (n - k).astype(jnp.float32)
        best = jnp.argmin(jnp.where(tie, jnp.abs(idx.astype(jnp.float32) - middle), jnp.inf)).astype(jnp.int32)
        return jnp.where(jnp.any(starts), best, lo), jnp.maximum(k, 1)

    # Each pass halves the window: log2(F) passes reach any size (one loop body: a small program to compile).
    lo, n = lax.fori_loop(0, max(int(f).bit_length(), 1), halve, (jnp.zeros((), jnp.int32), count))
    return 0.5 * (values[jnp.clip(lo + (n - 1) // 2, 0, f - 1)] + values[jnp.clip(lo + n // 2, 0, f - 1)])


def ground_centre(state: BlobScaleState, min_count: int = 8) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """``(centre, has)``: the ground balls' ``log b``, robust to balls in the air (:func:`ground_spread`'s centre,
    the stored values' half-sample mode), and whether ``min_count`` values are stored. The median of all frames
    (:func:`blob_scale_estimate`) lies above it by a share of the flights' sizes (up to 0.026 on the development
    replays with heights kept, 0.006 on average over the pieces, against the shortest half's midpoint; far more where
    most recent frames are in flight): a ball read against the median reads that much too small."""
    count = jnp.sum(state.filled)
    has = count >= min_count
    return jnp.where(has, _half_sample_mode(state), 0.0), has


def ground_spread(state: BlobScaleState, min_count: int = 8) -> Float[Array, ""]:
    """The spread of ground balls' values, robust to balls in the air: they only ever make a blob larger.

    The ground balls' centre is the stored values' half-sample mode (nested shortest halves, down to a quarter of the
    values: it lies on the ground balls' tight cluster wherever the larger, widely spread values of balls in the air
    lie, even where those are most of the recent frames, as at the start of a run in a long flight), and their spread
    ``1.4826`` times the median distance below it of the values below it (a half-normal's median is ``0.6745``
    stds). A median absolute deviation about the median, as :func:`blob_scale_spread` takes, grows with the share of
    frames in the air (0.055 against 0.040 on a development replay with a third of its frames in flights). 0 while
    fewer than ``min_count`` values are stored.
    """
    f = state.log_ratios.shape[0]
    count = jnp.sum(state.filled)
    centre = _half_sample_mode(state)
    below = state.filled & (state.log_ratios < centre)
    n_below = jnp.sum(below)
    dist = jnp.sort(jnp.where(below, centre - state.log_ratios, jnp.inf))
    spread = 1.4826 * dist[jnp.clip((n_below - 1) // 2, 0, f - 1)]
    return jnp.where((count >= min_count) & (n_below > 0), spread, 0.0)
