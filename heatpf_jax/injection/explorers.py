"""Injection: particles replaced by new ones after resampling (III-E), and where new particles come from.

Explorers (III-E): a configurable fraction of the particles with the lowest support is drawn anew,
so that a second region of high activation (a true positive next to a false one, Fig. 5) can still
attract particles after the cloud has converged.

Each injector is a piece (:class:`UniformExplorers`, :class:`GaussianExplorers`; random particles and
memory hints come next) with ``inject(key, context, params) -> context``. The
:class:`InjectionContext` carries the particles and the slots already taken: an injector takes the
next ``count`` slots by lowest support (:func:`take_slots`), so several injectors never refill the
same slot and none depends on how the resampler laid the particles out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from heatpf_jax.numerics import ranks_of
from heatpf_jax.params import positive, unit_interval

__all__ = [
    "ExplorerParams",
    "GaussianExplorerParams",
    "GaussianExplorers",
    "InjectionContext",
    "RandomParams",
    "RandomParticles",
    "UniformBox",
    "UniformExplorers",
    "explorer_count",
    "explorer_mask",
    "explorer_slots",
    "refill",
    "replace_slots",
    "spawn_gaussian",
    "spawn_uniform",
    "take_slots",
]


def spawn_uniform(key: PRNGKeyArray, num: int, box: tuple[float, float, float, float]) -> Float[Array, "num 2"]:
    """``num`` points uniform over ``box = (x_min, x_max, y_min, y_max)`` in the base frame."""
    x_min, x_max, y_min, y_max = box
    low = jnp.array([x_min, y_min], jnp.float32)
    high = jnp.array([x_max, y_max], jnp.float32)
    return jax.random.uniform(key, (num, 2), jnp.float32, low, high)


def spawn_gaussian(
    key: PRNGKeyArray, num: int, mean: Float[ArrayLike, "2"], std: Float[ArrayLike, ""]
) -> Float[Array, "num 2"]:
    """``num`` points from ``N(mean, std^2 I)``."""
    return jnp.asarray(mean, jnp.float32)[None, :] + std * jax.random.normal(key, (num, 2), jnp.float32)


def explorer_mask(support: Float[ArrayLike, " n"], fraction: Float[ArrayLike, ""]) -> Bool[Array, " n"]:
    """Marks the ``round(fraction * n)`` particles with the lowest support (ties by index).

    ``fraction`` may be traced: the count is a traced integer and the mask is
    built from ranks, so shapes stay static.
    """
    support = jnp.asarray(support)
    n = support.shape[0]
    count = explorer_count(fraction, n)
    return ranks_of(jnp.argsort(support, stable=True)) < count


def explorer_count(fraction: Float[ArrayLike, ""], num: int) -> Array:
    """``round(fraction * num)`` as a (possibly traced) ``int32``: how many particles respawn."""
    return jnp.round(fraction * num).astype(jnp.int32)


def explorer_slots(num: int, fraction: Float[ArrayLike, ""]) -> Bool[Array, " num"]:
    """Marks the last ``round(fraction * num)`` of ``num`` slots.

    After resampling particles sorted by decreasing weight (every resampler returns
    non-decreasing indices), the last slots hold the copies with the lowest support:
    this is :func:`explorer_mask` of their support (ties broken by the sort) without a
    second sort.
    """
    return jnp.arange(num, dtype=jnp.int32) >= num - explorer_count(fraction, num)


def _check_box(box) -> None:
    box = tuple(box)
    if len(box) != 4 or not all(math.isfinite(b) for b in box) or box[0] >= box[1] or box[2] >= box[3]:
        raise ValueError(f"spawn_box: must be finite (x_min, x_max, y_min, y_max) with min < max, got {box!r}")


@dataclass(frozen=True)
class UniformBox:
    """The initial distribution (Fig. 2): uniform over ``box = (x_min, x_max, y_min, y_max)`` in the base frame."""

    box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)

    def validate(self) -> None:
        _check_box(self.box)

    def sample(self, key: PRNGKeyArray, num: int) -> Float[Array, "num 2"]:
        return spawn_uniform(key, num, self.box)


class InjectionContext(NamedTuple):
    """What injectors read and update, in order.

    Attributes:
        particles: the resampled particles (the motion model's pytree).
        log_weights: ``float32 [N]`` their log weights (normalised by the step after the last injector).
        rank: ``int32 [N]`` each slot's support rank (0: the most support).
        used: ``int32 []`` slots already refilled (those of the highest ranks).
        estimate: this step's estimate (``mean`` ``[2]``).
        motion: the filter's motion model (static), which makes particles from positions.
        motion_params: its params.
        measurements: this step's measurement buffer (:class:`~heatpf_jax.measurements.Measurements`),
            for injectors that draw from the measurements; ``None`` where there is none.
        memory: the long-term memory's tracks after this step (:class:`~heatpf_jax.memory.table.TrackTable`).
        memory_lost: ``bool [M]`` the tracks the filter has lost (:func:`heatpf_jax.memory.table.lost_tracks`).
        recall: before the weighting only (injectors' ``seed``), the lost tracks this step's measurements
            re-detect (:class:`heatpf_jax.memory.track_memory.Recall`).
        has_heatmap: ``bool []`` whether this step brought a new heat map (``None`` where unknown).
        previous_measurements: before the weighting only (injectors' ``seed``), the previous step's measurement buffer
            (``None`` where unknown).
        inputs: before the weighting only (injectors' ``seed``), this step's
            :class:`~heatpf_jax.pieces.StepInputs` (its camera and heat map: what the camera can see; ``None`` where
            unknown).
    """

    particles: Any
    log_weights: Float[Array, " n"]
    rank: Int[Array, " n"]
    used: Int[Array, ""]
    estimate: Any
    motion: Any
    motion_params: Any
    measurements: Any = None
    memory: Any = None
    memory_lost: Any = None
    recall: Any = None
    has_heatmap: Any = None
    previous_measurements: Any = None
    inputs: Any = None


def take_slots(rank: Int[ArrayLike, " n"], used: Int[ArrayLike, ""], count: Int[ArrayLike, ""]) -> Bool[Array, " n"]:
    """The ``count`` slots of lowest support not yet taken: ranks in ``[n - used - count, n - used)``."""
    rank = jnp.asarray(rank)
    n = rank.shape[0]
    return (rank >= n - used - count) & (rank < n - used)


def replace_slots(key: PRNGKeyArray, context: InjectionContext, mask: Bool[Array, " n"], xy: Float[Array, "n 2"]):
    """``context`` with the particles of ``mask`` replaced by new ones at ``xy`` (weight 1/N each)."""
    n = mask.shape[0]
    new = context.motion.spawn(key, xy, context.motion_params)
    particles = jax.tree.map(
        lambda a, b: jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b), new, context.particles
    )
    log_w = jnp.where(mask, -math.log(n), context.log_weights)
    return context._replace(particles=particles, log_weights=log_w)


def refill(key: PRNGKeyArray, context: InjectionContext, fraction, draw) -> InjectionContext:
    """Refills the next ``round(fraction * N)`` free slots of lowest support with positions from ``draw``.

    Args:
        key: PRNG key (``draw`` gets it; the motion model's ``spawn`` a key folded from it).
        context: the injection context.
        fraction: share of the particles to refill (may be traced).
        draw: ``(key, n) -> [n, 2]`` positions (all ``n`` drawn; the refilled slots take theirs).

    Returns:
        The context with those slots replaced (weight 1/N each) and ``used`` advanced.
    """
    n = context.log_weights.shape[0]
    count = explorer_count(fraction, n)
    mask = take_slots(context.rank, context.used, count)
    context = replace_slots(jax.random.fold_in(key, 1), context, mask, draw(key, n))
    return context._replace(used=context.used + count)


class ExplorerParams(NamedTuple):
    """Numbers of :class:`UniformExplorers`.

    Attributes:
        explorer_fraction: share of lowest-support particles respawned (III-E); 5 % in the paper.
    """

    explorer_fraction: float = 0.05


@dataclass(frozen=True)
class UniformExplorers:
    """Explorers (III-E) drawn uniformly over ``box`` (the spawn box of the initial distribution)."""

    box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)
    name: str = "explorers"

    def default_params(self) -> ExplorerParams:
        return ExplorerParams()

    def properties(self) -> ExplorerParams:
        # A count of particles: frozen.
        return ExplorerParams(explorer_fraction=unit_interval(high_closed=False, trainable=False))

    def validate(self) -> None:
        _check_box(self.box)

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: ExplorerParams) -> InjectionContext:
        return refill(key, context, params.explorer_fraction, lambda k, n: spawn_uniform(k, n, self.box))


class GaussianExplorerParams(NamedTuple):
    """Numbers of :class:`GaussianExplorers`.

    Attributes:
        explorer_fraction: share of lowest-support particles respawned (III-E).
        explorer_std: std of the spawn distribution around the current estimate, metres.
    """

    explorer_fraction: float = 0.05
    explorer_std: float = 0.5


@dataclass(frozen=True)
class GaussianExplorers:
    """Explorers (III-E) drawn from ``N(estimate, explorer_std^2 I)``."""

    name: str = "explorers"

    def default_params(self) -> GaussianExplorerParams:
        return GaussianExplorerParams()

    def properties(self) -> GaussianExplorerParams:
        return GaussianExplorerParams(
            explorer_fraction=unit_interval(high_closed=False, trainable=False), explorer_std=positive()
        )

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: GaussianExplorerParams) -> InjectionContext:
        return refill(
            key, context, params.explorer_fraction,
            lambda k, n: spawn_gaussian(k, n, context.estimate.mean, params.explorer_std),
        )


class RandomParams(NamedTuple):
    """Numbers of :class:`RandomParticles`.

    Attributes:
        random_fraction: share of the particles redrawn uniformly each step (Olufs et al. 3.2: 50 of 300).
    """

    random_fraction: float = 50 / 300


@dataclass(frozen=True)
class RandomParticles:
    """Random particles (Olufs et al., section 3.2): a fixed share drawn uniformly over ``box`` every step.

    Unlike the explorers (III-E), which the paper ties to the weakest particles, these are Olufs's
    "random particles" that keep the filter able to find an object anywhere in the spawn area. They
    take the lowest-support slots left after the injectors before them (:func:`take_slots`); their
    other state (a velocity) comes from the motion model's ``spawn``.
    """

    box: tuple[float, float, float, float] = (0.0, 7.0, -4.0, 4.0)
    name: str = "random"

    def default_params(self) -> RandomParams:
        return RandomParams()

    def properties(self) -> RandomParams:
        return RandomParams(random_fraction=unit_interval(high_closed=False, trainable=False))

    def validate(self) -> None:
        _check_box(self.box)

    def inject(self, key: PRNGKeyArray, context: InjectionContext, params: RandomParams) -> InjectionContext:
        return refill(key, context, params.random_fraction, lambda k, n: spawn_uniform(k, n, self.box))
