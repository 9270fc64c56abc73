"""The long-term memory's pieces (Olufs et al. 3.4): :class:`TrackMemory`, and :class:`NoMemory` (the default).

A filter holds one of them as its ``memory``: :meth:`TrackMemory.update` runs a step of the memory
(:func:`~heatpf_jax.memory.update.update_tracks`), :meth:`TrackMemory.lost` names the tracks that get hint
particles and :meth:`TrackMemory.recall` the lost tracks this step's buffer shows again (:class:`Recall`). The
memory's step is described in :mod:`heatpf_jax.memory`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.measurements import Measurements
from heatpf_jax.memory.blobs import find_blobs, redetect
from heatpf_jax.memory.candidates import blob_under, candidates_from, observed_support
from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.predict import predict_tracks
from heatpf_jax.memory.table import TrackTable, complete_tracks, empty_tracks, lost_tracks
from heatpf_jax.memory.update import update_tracks
from heatpf_jax.params import NoParams, integer, nonnegative, positive, unit_interval

__all__ = [
    "NoMemory",
    "Recall",
    "TrackMemory",
]


class Recall(NamedTuple):
    """The lost tracks the memory re-detects in this step's buffer, before the filter weighs its particles.

    Attributes:
        redetected: ``bool [M]`` tracks that nothing observed last step (lost by the filter and not
            re-detected by the memory either) and that this step's measurements re-detect: a reappearance.
        xy: ``float32 [M, 2]`` where: the re-detecting measurements' weighted centroid.
        hits: ``int32 [M]`` the tracks' observation counts (how established each is).
        ball: ``bool [M]`` the ball's track (``TrackTable.ball``; ``None``: none known).
    """

    redetected: Bool[Array, " m"]
    xy: Float[Array, "m 2"]
    hits: Int[Array, " m"]
    ball: Bool[Array, " m"] | None = None


@dataclass(frozen=True)
class NoMemory:
    """No long-term memory (the default): a track table of capacity 0."""

    capacity: int = 0

    def default_params(self) -> NoParams:
        return NoParams()

    def properties(self) -> NoParams:
        return NoParams()

    def validate(self) -> None:
        pass

    def init(self) -> TrackTable:
        return empty_tracks(0)

    def update(self, tracks, modes, estimate_mean, buffer, ego, dt, params) -> TrackTable:
        return tracks

    def lost(self, tracks: TrackTable, params) -> Bool[Array, " m"]:
        return tracks.valid

    def recall(self, tracks, buffer, ego, dt, params) -> Recall:
        return Recall(jnp.zeros((0,), bool), jnp.zeros((0, 2), jnp.float32), jnp.zeros((0,), jnp.int32),
                      jnp.zeros((0,), bool))


@dataclass(frozen=True)
class TrackMemory:
    """The long-term memory of Olufs et al. (3.4) with ``capacity`` track slots (see :mod:`heatpf_jax.memory`).

    Attributes:
        capacity: track slots.
        max_births: blobs no track explains that may open a track each step (0: tracks come from the filter's
            candidates only).
        max_blobs: blobs the memory looks for in each buffer (:func:`~heatpf_jax.memory.blobs.find_blobs`), strongest
            first.
    """

    capacity: int = 16
    max_births: int = 1
    max_blobs: int = 8

    def default_params(self) -> MemoryParams:
        return MemoryParams()

    def properties(self) -> MemoryParams:
        return MemoryParams(
            memory_forget=positive(),
            memory_gate=positive(),
            memory_accel_std=positive(),
            memory_obs_std=positive(),
            memory_spawn_speed_std=positive(),
            memory_min_support=positive(trainable=False),
            memory_support_radius=positive(trainable=False),
            memory_confirm=integer(1, 1000),
            memory_redetect_sigmas=positive(trainable=False),
            memory_friction=nonnegative(),
            memory_static_speed=positive(trainable=False),
            memory_birth_support=positive(trainable=False),
            memory_blob_radius=positive(trainable=False),
            memory_lost_accel_std=positive(),
            memory_redetect_share=unit_interval(trainable=False),
            memory_lost_turn=positive(trainable=False),
        )

    def validate(self) -> None:
        c = self.capacity
        if not isinstance(c, int) or isinstance(c, bool) or c < 1:
            raise ValueError(f"max_tracks: must be a positive integer, got {c!r}")
        for name in ("max_births", "max_blobs"):
            b = getattr(self, name)
            if not isinstance(b, int) or isinstance(b, bool) or b < 0:
                raise ValueError(f"{name}: must be a non-negative integer, got {b!r}")

    def init(self) -> TrackTable:
        return empty_tracks(self.capacity)

    def update(
        self,
        tracks: TrackTable,
        modes,
        estimate_mean: Float[Array, "2"],
        buffer: Measurements,
        ego: Float[Array, "3"],
        dt,
        params: MemoryParams,
    ) -> TrackTable:
        """One step of the memory from this step's modes (or estimate), buffer and ego-motion."""
        cand_xy, cand_valid = candidates_from(modes, estimate_mean)
        support = observed_support(cand_xy, buffer, params.memory_support_radius)
        observed = cand_valid & (support >= params.memory_min_support)
        # What the memory observes is a blob under a candidate, not the particles' mean: a cloud on its way
        # from a vanished ball to a distractor is on the distractor's blob, on the ball's, or on none.
        blobs = find_blobs(buffer, params, self.max_blobs)
        centre = blob_under(cand_xy, buffer, blobs.member, blobs.xy, params.memory_support_radius)
        cand_xy = jnp.where(observed[:, None], centre, cand_xy)
        return update_tracks(tracks, cand_xy, observed, jnp.asarray(dt, jnp.float32), ego, params, buffer,
                             estimate=estimate_mean, max_births=self.max_births, max_blobs=self.max_blobs)

    def lost(self, tracks: TrackTable, params: MemoryParams) -> Bool[Array, " m"]:
        """The tracks the filter has lost this step (they get hints)."""
        return lost_tracks(tracks, params.memory_confirm)

    def recall(
        self, tracks: TrackTable, buffer: Measurements, ego: Float[Array, "3"], dt, params: MemoryParams
    ) -> Recall:
        """The tracks lost at the end of the previous step (``tracks``), predicted by ``dt`` and ``ego``, that
        :func:`~heatpf_jax.memory.blobs.redetect` finds in this step's ``buffer`` (the state is not changed:
        :meth:`update` does that)."""
        tracks = complete_tracks(tracks)
        lost = lost_tracks(tracks, params.memory_confirm) & (tracks.age > 0)  # unseen last step, by anyone
        predicted = predict_tracks(tracks, jnp.asarray(dt, jnp.float32), ego, params.memory_accel_std,
                                   params.memory_friction, params.memory_lost_accel_std)
        again, centroid = redetect(predicted, lost, buffer, params, self.max_blobs, dt=jnp.asarray(dt, jnp.float32))
        return Recall(redetected=again, xy=centroid, hits=tracks.hits, ball=tracks.ball)
