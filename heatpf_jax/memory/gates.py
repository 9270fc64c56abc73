"""The long-term memory's gates (Olufs et al. 3.4): where a track may be moved, and the most likely pairs.

:func:`gate_costs` is the cost of explaining each point by each track, infinite outside the track's gate; points
(the filter's candidates, the memory's blobs) and tracks are paired most likely first by a greedy assignment.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from heatpf_jax.memory.params import MemoryParams
from heatpf_jax.memory.table import TrackTable

__all__ = ["gate_costs"]


def gate_costs(tracks: TrackTable, xy: Float[Array, "p 2"], params: "MemoryParams") -> Float[Array, "p m"]:
    """The cost of explaining each point by each track: its negative log-likelihood under the track's predicted
    position, ``d^2 / 2 + log det(S) / 2`` with ``d`` the Mahalanobis distance for ``S = P_xy + memory_obs_std^2 I``;
    ``inf`` outside the track's **gate** (farther than ``memory_redetect_sigmas`` sigmas or ``memory_gate`` metres)
    and for empty slots. The gate is where a track may be moved; the cost picks the most likely track among those
    whose gates overlap (a tight static track explains its own blob better than a wide lost one).
    """
    cov = tracks.cov[:, :2, :2] + params.memory_obs_std**2 * jnp.eye(2, dtype=jnp.float32)[None]
    a, b, c = cov[None, :, 0, 0], cov[None, :, 0, 1], cov[None, :, 1, 1]
    det = jnp.maximum(a * c - b * b, 1e-12)
    dx = xy[:, None, 0] - tracks.mean[None, :, 0]
    dy = xy[:, None, 1] - tracks.mean[None, :, 1]
    d2 = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det
    inside = (
        tracks.valid[None, :]
        & (d2 <= params.memory_redetect_sigmas**2)
        & (dx * dx + dy * dy <= params.memory_gate**2)
    )
    return jnp.where(inside, 0.5 * d2 + 0.5 * jnp.log(det), jnp.inf)


def _associate(costs: Float[Array, "k m"], cand_ok: Bool[Array, " k"]) -> Int[Array, " k"]:
    """Greedy assignment by increasing cost (finite: inside the gate): ``track_of[k]`` (-1: none) per candidate."""
    d = jnp.where(cand_ok[:, None], costs, jnp.inf)
    k_count, m = d.shape
    track_of = jnp.full((k_count,), -1, jnp.int32)
    for _ in range(min(k_count, m)):  # static and small
        flat = jnp.argmin(d)
        best = d.reshape(-1)[flat]
        i, j = flat // m, flat % m
        ok = jnp.isfinite(best)
        track_of = jnp.where(ok, track_of.at[i].set(j.astype(jnp.int32)), track_of)
        d = jnp.where(ok, d.at[i, :].set(jnp.inf).at[:, j].set(jnp.inf), d)
    return track_of
