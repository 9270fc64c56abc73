"""Memory hints (Olufs et al. 3.4): particles injected around the tracks the filter has lost.

"We add b additional particles to the particle filter using the positions of the predicted hypothesis of
missing objects. The position of additional particles (per hypothesis) depends on its age [...]. An older
age will result in a larger spread of the additional particles." Here b is ``round(hint_fraction * N)``
per lost track (:func:`heatpf_jax.memory.table.lost_tracks`, ``InjectionContext.memory_lost``), drawn from
``N(predicted position, P_xy + hint_std^2 I)`` with ``P_xy`` the track's predicted position covariance: it grows
with the track's age through the constant-velocity prediction, so the spread follows the age without a second rule. The
hints take the lowest-support slots left by the injectors before them, like explorers and random
particles (:func:`heatpf_jax.injection.explorers.take_slots`). When the ball stays hidden the hints find no
measurement and carry no weight: "in the case of visually gone objects these hints are ignored". The ball's
track (:attr:`heatpf_jax.memory.table.TrackTable.ball`, the one that carried the filter's estimate) gets its hints
first, before tracks observed on more steps.

Re-detection seeds (:class:`RedetectionSeeds`): the memory "allows to re-detect vanished objects and using
their new position as a new initial position for object tracking". Hints come after the step's
weighting, so they act one frame after the ball is seen again; the seeds act on that frame. Before
the particles are weighted, :meth:`heatpf_jax.memory.track_memory.TrackMemory.recall` finds the lost tracks that this
step's measurements re-detect, and ``round(seed_fraction * N)`` of the particles of least support are
moved to ``N(re-detected position, seed_std^2 I)``; the step's weighting then judges them with everything
else. An injector with a ``seed`` method is called at this stage (its ``inject`` does nothing).

Static clutter (:attr:`heatpf_jax.memory.table.TrackTable.static`: a blob that appeared where no track predicted
anything and never moved) is never the ball. Where the memory sees the ball elsewhere (its track re-detected
this step), the particles sitting on static clutter are taken first: the seeds move all of them to the
re-detected ball (at least ``seed_fraction`` of the particles in all), the hints take them before the particles
of least support. The paper's memory re-detects a vanished object "using its new position as a new initial
position": a filter held by a distractor is re-initialised there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from heatpf_jax.injection.explorers import InjectionContext, explorer_count, replace_slots, take_slots
from heatpf_jax.memory.table import complete_tracks
from heatpf_jax.numerics import ranks_of
from heatpf_jax.params import nonnegative, unit_interval

__all__ = ["HintParams", "MemoryHints", "RedetectionSeeds", "SeedParams"]


class HintParams(NamedTuple):
    """Numbers of :class:`MemoryHints`.

    Attributes:
        hint_fraction: share of the particles injected per lost track (Olufs et al.: 50 of 300).
        hint_std: spread added to the track's own position uncertainty, metres.
    """

    hint_fraction: float = 50 / 300
    hint_std: float = 0.05


def _chol2(cov):
    """Cholesky factor of a 2 x 2 covariance (guarded: a zero or tiny matrix gives zeros, not NaN)."""
    a = jnp.maximum(cov[0, 0], 1e-12)
    l00 = jnp.sqrt(a)
    l10 = cov[1, 0] / l00
    l11 = jnp.sqrt(jnp.maximum(cov[1, 1] - l10**2, 1e-12))
    return jnp.array([[l00, 0.0], [l10, l11]], jnp.float32)


@dataclass(frozen=True)
class MemoryHints:
    """Hint particles for the tracks of :class:`~heatpf_jax.memory.track_memory.TrackMemory` that the filter has lost.

    Attributes:
        max_hinted: at most this many lost tracks get hints each step, those observed on most steps
            (1 by default: a filter that follows one ball hints the track it followed longest, not the
            false positives it visited; raise it to follow several objects, as Olufs et al. do).
        name: the injector's name.
    """

    max_hinted: int = 1
    name: str = "hints"

    def validate(self) -> None:
        if not isinstance(self.max_hinted, int) or isinstance(self.max_hinted, bool) or self.max_hinted < 1:
            raise ValueError(f"max_hinted: must be a positive integer, got {self.max_hinted!r}")

    def default_params(self) -> HintParams:
        return HintParams()

    def properties(self) -> HintParams:
        return HintParams(hint_fraction=unit_interval(high_closed=False, trainable=False), hint_std=nonnegative())

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: HintParams) -> InjectionContext:
        tracks = context.memory
        if tracks is None or tracks.valid.shape[0] == 0:
            raise ValueError("injectors: MemoryHints needs a long-term memory (--set memory=tracks)")
        tracks = complete_tracks(tracks)
        chosen = _most_observed(context.memory_lost, tracks.hits, self.max_hinted, tracks.ball)
        # The memory sees the ball (re-detected this step) where the filter is not: hints come from the particles
        # on static clutter first.
        seen_ball = jnp.any(chosen & tracks.ball & (tracks.age <= 0.0))
        context = _demote(context, _on_static(context.particles.xy, tracks, params.hint_std) & seen_ball)
        pos_cov = tracks.cov[:, :2, :2] + params.hint_std**2 * jnp.eye(2, dtype=jnp.float32)[None]
        return _around(key, context, chosen, tracks.mean[:, :2], jax.vmap(_chol2)(pos_cov), params.hint_fraction)


def _most_observed(
    mask: Bool[Array, " m"], hits: Int[Array, " m"], limit: int, ball: Bool[Array, " m"] | None = None
) -> Bool[Array, " m"]:
    """``mask`` restricted to its ``limit`` first tracks: the ball's (``ball``), then those observed on most steps
    (ties: the lower slot)."""
    if limit >= mask.shape[0]:
        return mask
    key = jnp.asarray(hits, jnp.int32)
    if ball is not None:
        key = key + jnp.where(ball, jnp.int32(1 << 24), jnp.int32(0))
    rank = ranks_of(jnp.argsort(-jnp.where(mask, key, -1), stable=True))
    return mask & (rank < limit)


def _on_static(xy: Float[Array, "n 2"], tracks, spread) -> Bool[Array, " n"]:
    """Particles within 3 sigmas (``P_xy + spread^2 I``) of a static-clutter track (``TrackTable.static``)."""
    cov = tracks.cov[:, :2, :2] + spread**2 * jnp.eye(2, dtype=jnp.float32)[None]
    a, b, c = cov[:, 0, 0], cov[:, 0, 1], cov[:, 1, 1]
    det = jnp.maximum(a * c - b * b, 1e-12)
    dx = xy[:, None, 0] - tracks.mean[None, :, 0]
    dy = xy[:, None, 1] - tracks.mean[None, :, 1]
    d2 = (c[None] * dx * dx - 2.0 * b[None] * dx * dy + a[None] * dy * dy) / det[None]
    return jnp.any((tracks.valid & tracks.static)[None, :] & (d2 <= 9.0), axis=1)


def _demote(context: InjectionContext, mask: Bool[Array, " n"]) -> InjectionContext:
    """``context`` with the free slots of ``mask`` ranked below every other free slot (least support: taken first
    by :func:`~heatpf_jax.injection.explorers.take_slots`);
    the order is otherwise kept and taken slots keep their ranks."""
    n = context.rank.shape[0]
    free = context.rank < n - context.used
    key = jnp.where(free, context.rank + jnp.where(mask, n, 0), context.rank + 2 * n)
    return context._replace(rank=ranks_of(jnp.argsort(key, stable=True)))


def _around(key, context: InjectionContext, chosen, centre, chol, fraction, at_least=0) -> InjectionContext:
    """Refills ``round(fraction * N)`` free slots of least support per chosen track (at least ``at_least`` in all)
    with ``N(centre, chol chol^T)``."""
    n = context.log_weights.shape[0]
    per_track = explorer_count(fraction, n)
    some = jnp.sum(chosen.astype(jnp.int32))
    count = jnp.minimum(jnp.maximum(per_track * some, jnp.where(some > 0, at_least, 0)), n - context.used)
    per_track = jnp.maximum(per_track, (count + jnp.maximum(some, 1) - 1) // jnp.maximum(some, 1))
    mask = take_slots(context.rank, context.used, count)
    # The slot of rank r is the (r - first)-th new particle: particle i goes to the (i // b)-th chosen track.
    first = n - context.used - count
    offset = jnp.clip(context.rank - first, 0, jnp.maximum(count - 1, 0))
    chosen_order = jnp.argsort(~chosen, stable=True)  # chosen tracks first, in slot order
    track = chosen_order[jnp.clip(offset // jnp.maximum(per_track, 1), 0, chosen.shape[0] - 1)]
    z = jax.random.normal(key, (n, 2), jnp.float32)
    xy = centre[track] + jnp.einsum("nij,nj->ni", chol[track], z)
    context = replace_slots(jax.random.fold_in(key, 1), context, mask, xy)
    return context._replace(used=context.used + count)


class SeedParams(NamedTuple):
    """Numbers of :class:`RedetectionSeeds`.

    Attributes:
        seed_fraction: share of the particles moved to a re-detected track.
        seed_std: their spread about the re-detected position, metres.
    """

    seed_fraction: float = 0.5
    seed_std: float = 0.05


@dataclass(frozen=True)
class RedetectionSeeds:
    """Particles seeded where the long-term memory re-detects a lost track, before the step's weighting.

    Attributes:
        max_seeded: at most this many re-detected tracks get seeds each step, those observed on most steps.
        name: the injector's name.
    """

    max_seeded: int = 1
    name: str = "seeds"

    def validate(self) -> None:
        if not isinstance(self.max_seeded, int) or isinstance(self.max_seeded, bool) or self.max_seeded < 1:
            raise ValueError(f"max_seeded: must be a positive integer, got {self.max_seeded!r}")

    def default_params(self) -> SeedParams:
        return SeedParams()

    def properties(self) -> SeedParams:
        return SeedParams(seed_fraction=unit_interval(high_closed=False, trainable=False), seed_std=nonnegative())

    def seed(self, key: PRNGKeyArray, context: InjectionContext, params: SeedParams) -> InjectionContext:
        """Moves particles of least support (``context.rank``) to the re-detected tracks of ``context.recall``."""
        recall = context.recall
        if recall is None or recall.redetected.shape[0] == 0:
            raise ValueError("injectors: RedetectionSeeds needs a long-term memory (--set memory=tracks)")
        chosen = _most_observed(recall.redetected, recall.hits, self.max_seeded, recall.ball)
        m = chosen.shape[0]
        chol = jnp.broadcast_to(params.seed_std * jnp.eye(2, dtype=jnp.float32), (m, 2, 2))
        at_least = 0
        if context.memory is not None and recall.ball is not None:
            # The ball reappears where its track predicts it: the particles on static clutter (a blob that never
            # moved and appeared where no track predicted anything) move to it too, whatever their support.
            on_clutter = _on_static(context.particles.xy, complete_tracks(context.memory), params.seed_std)
            on_clutter = on_clutter & jnp.any(chosen & recall.ball)
            context = _demote(context, on_clutter)
            at_least = jnp.sum(on_clutter.astype(jnp.int32))
        return _around(key, context, chosen, recall.xy, chol, params.seed_fraction, at_least)

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: SeedParams) -> InjectionContext:
        """Nothing after resampling: the seeds act before the weighting (:meth:`seed`)."""
        del key, params
        return context
