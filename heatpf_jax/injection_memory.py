"""Memory hints (Olufs et al. 3.4): particles injected around the tracks the filter has lost.

"We add b additional particles to the particle filter using the positions of the predicted hypothesis of
missing objects. The position of additional particles (per hypothesis) depends on its age [...]. An older
age will result in a larger spread of the additional particles." Here b is ``round(hint_fraction * N)``
per lost track (:func:`heatpf_jax.memory.lost_tracks`, ``InjectionContext.memory_lost``), drawn from
``N(predicted position, P_xy + hint_std^2 I)`` with ``P_xy`` the track's predicted position covariance: it grows
with the track's age through the constant-velocity prediction, so the spread follows the age without a second rule. The
hints take the lowest-support slots left by the injectors before them, like explorers and random
particles (:func:`heatpf_jax.injection.take_slots`). When the ball stays hidden the hints find no
measurement and carry no weight: "in the case of visually gone objects these hints are ignored".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import PRNGKeyArray

from heatpf_jax.injection import InjectionContext, explorer_count, replace_slots, take_slots
from heatpf_jax.params import nonnegative, unit_interval

__all__ = ["HintParams", "MemoryHints"]


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
    """Hint particles for the tracks of :class:`~heatpf_jax.memory.TrackMemory` that the filter has lost.

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
        n = context.log_weights.shape[0]
        per_track = explorer_count(params.hint_fraction, n)
        lost = context.memory_lost
        if self.max_hinted < lost.shape[0]:  # only the lost tracks observed most often
            order = jnp.argsort(-jnp.where(lost, tracks.hits, -1), stable=True)
            rank = jnp.zeros_like(order).at[order].set(jnp.arange(order.shape[0], dtype=order.dtype))
            lost = lost & (rank < self.max_hinted)
        num_lost = jnp.sum(lost.astype(jnp.int32))
        count = jnp.minimum(per_track * num_lost, n - context.used)
        mask = take_slots(context.rank, context.used, count)
        # The slot of rank r is the (r - first)-th hint: hint i goes to the (i // b)-th lost track.
        first = n - context.used - count
        offset = jnp.clip(context.rank - first, 0, jnp.maximum(count - 1, 0))
        lost_order = jnp.argsort(~lost, stable=True)  # lost tracks first, in slot order
        track = lost_order[jnp.clip(offset // jnp.maximum(per_track, 1), 0, lost.shape[0] - 1)]
        pos_cov = tracks.cov[:, :2, :2] + params.hint_std**2 * jnp.eye(2, dtype=jnp.float32)[None]
        chol = jax.vmap(_chol2)(pos_cov)
        z = jax.random.normal(key, (n, 2), jnp.float32)
        xy = tracks.mean[track, :2] + jnp.einsum("nij,nj->ni", chol[track], z)
        context = replace_slots(jax.random.fold_in(key, 1), context, mask, xy)
        return context._replace(used=context.used + count)
