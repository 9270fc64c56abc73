"""The heat-map particle filter (Fig. 2) as one fixed pipeline of pieces: ``Filter``, ``init``, ``step``.

One step, in the order of the sequence-file contract::

    ego.ego                 odometry or localisation (Olufs 3.5)      heatpf_jax.motion.ego
    motion.predict          odometry, noise, diffusion (III-D)        heatpf_jax.motion.random_walk
    source.measure          heat map -> Measurements (III-A, IV-B)    heatpf_jax.sources.pixels
    buffer.update           odometry on the buffer, aging (III-C)     heatpf_jax.buffers.aging
    injectors[i].seed       re-detection seeds (Olufs 3.4), if any    heatpf_jax.injection.memory_hints
    observation             log-likelihood per particle (III-B)       heatpf_jax.observation.kernels
    estimator.estimate      output (III-F)                            heatpf_jax.estimate.top_fraction
    resampling.resample     ESS trigger + index resampler (III-E)     heatpf_jax.resampling.resamplers
    memory.update           long-term track memory (Olufs 3.4)        heatpf_jax.memory
    injectors[i].inject     explorers (III-E), hints, ...             heatpf_jax.injection.explorers

Beside the pipeline, ``modes.modes`` reports fixed-size modes of the weighted particles (III-F, V;
Olufs 3.2) in ``StepInfo.modes``: none by default (:class:`~heatpf_jax.estimate.modes.NoModes`).

The particles are sorted by decreasing weight once per step (:func:`heatpf_jax.numerics.order_by_weight`);
the estimator and the resampling strategy share that order. A :class:`Filter` is a ``NamedTuple`` of
frozen, hashable pieces plus ``num_particles``: it is the static argument of ``jit``, and two equal
filters share one compilation. Its numbers are a :class:`FilterParams`, one params ``NamedTuple`` per
piece; ``Filter.properties()`` gives the matching tree of constraints (:mod:`heatpf_jax.params`).
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from heatpf_jax import params as P
from heatpf_jax.buffers.aging import AgingBuffer, AgingParams
from heatpf_jax.estimate.modes import Modes, NoModes
from heatpf_jax.estimate.top_fraction import TopFraction, TopFractionParams
from heatpf_jax.injection.explorers import ExplorerParams, InjectionContext, UniformBox, UniformExplorers
from heatpf_jax.measurements import Measurements, empty_measurements
from heatpf_jax.memory.table import TrackTable
from heatpf_jax.memory.track_memory import NoMemory
from heatpf_jax.motion.ego import OdometryEgo
from heatpf_jax.motion.random_walk import RandomWalk, RandomWalkParams
from heatpf_jax.motion.score import transition_log_weight
from heatpf_jax.numerics import normalise_log, order_by_weight, ranks_of
from heatpf_jax.observation.kernels import InverseDistance, InverseDistanceParams
from heatpf_jax.pieces import StepInputs
from heatpf_jax.resampling.resamplers import ESSParams, ESSResampling
from heatpf_jax.sources.pixels import PixelSource, SourceParams

__all__ = ["Filter", "FilterParams", "FilterState", "StepInfo"]


class FilterParams(NamedTuple):
    """Every number of a :class:`Filter`, one params ``NamedTuple`` per piece.

    The defaults are those of the default :class:`Filter` (the paper's filter). Leaves are Python
    numbers or arrays; a leading batch axis on every leaf makes a batch for ``vmap`` sweeps (see
    :func:`heatpf_jax.stack_params`). Use ``Filter.make_params`` to build params by name.

    Attributes:
        motion: params of ``Filter.motion``.
        source: params of ``Filter.source``.
        buffer: params of ``Filter.buffer``.
        observation: params of ``Filter.observation``.
        estimator: params of ``Filter.estimator``.
        resampling: params of ``Filter.resampling``.
        injectors: ``{injector.name: params}`` for ``Filter.injectors``.
        modes: params of ``Filter.modes``.
        ego: params of ``Filter.ego``.
        memory: params of ``Filter.memory``.
    """

    motion: Any = RandomWalkParams()
    source: Any = SourceParams()
    buffer: Any = AgingParams()
    observation: Any = InverseDistanceParams()
    estimator: Any = TopFractionParams()
    resampling: Any = ESSParams()
    injectors: dict = {"explorers": ExplorerParams()}  # noqa: RUF012 (never mutated)
    modes: Any = NoModes().default_params()
    ego: Any = OdometryEgo().default_params()
    memory: Any = NoMemory().default_params()


class FilterState(NamedTuple):
    """The carried state of the filter.

    Attributes:
        particles: the motion model's particle pytree (``particles.xy``: ``float32 [N, 2]`` positions
            in the current base frame).
        log_weights: ``float32 [N]`` normalised log weights (uniform after resampling).
        buffer: the measurement buffer (the source's size).
        mean: ``float32 [2]`` the last estimate.
        t: ``int32 []`` number of steps taken.
        memory: the long-term memory's tracks (:class:`~heatpf_jax.memory.table.TrackTable`; capacity 0 without).
        source: what the source carries from frame to frame (a source with ``init_state``, e.g. the blob scale
            :class:`~heatpf_jax.sources.lofted.LoftedSource` learns); ``()`` for a source without.
        injection: what the injectors carry, one entry per injector in order (``()`` for one without
            ``init_state``, e.g. the support averages of
            :class:`~heatpf_jax.injection.support_drop.SupportDropExplorers`); ``()`` when none carries anything.
    """

    particles: Any
    log_weights: Float[Array, " n"]
    buffer: Measurements
    mean: Float[Array, "2"]
    t: Int[Array, ""]
    memory: TrackTable
    source: Any = ()
    injection: Any = ()


class StepInfo(NamedTuple):
    """Per-step output and diagnostics (blackjax's ``SMCInfo`` plus the estimate).

    Attributes:
        mean: ``[2]`` the filter's estimate (top-fraction mean).
        cov: ``[2, 2]`` its covariance.
        weighted_mean: ``[2]`` weighted mean of all particles.
        ess: ``[]`` effective sample size before resampling.
        num_valid: ``int32 []`` valid measurements in the buffer.
        resampled: ``bool []`` whether this step resampled.
        log_likelihood: ``[]`` the step's log normalising-constant increment,
            ``log sum_i w_i L_i`` over the previous normalised weights ``w_i`` and this step's
            particle likelihoods ``L_i``: summed over steps, the log marginal likelihood of a
            sequence, the loss of maximum-likelihood tuning. For eq. (1) the ``L_i`` are scores
            (activation / distance), not a normalised density, so the value is defined only up to
            a per-step constant that depends on the heat map: compare it across parameters on the
            same data, not across data sets. ``0`` when the buffer is empty.
        ancestors: ``int32 [N]`` the particle each slot was copied from (its own index without
            resampling); slots refilled by injectors still name the ancestor they replaced.
        modes: :class:`~heatpf_jax.estimate.modes.Modes` of the weighted particles before resampling
            (``K = Filter.modes.num_modes``, 0 by default).
        tracks: the long-term memory's :class:`~heatpf_jax.memory.table.TrackTable` after this step
            (capacity ``Filter.memory.capacity``, 0 by default).
    """

    mean: Float[Array, "2"]
    cov: Float[Array, "2 2"]
    weighted_mean: Float[Array, "2"]
    ess: Float[Array, ""]
    num_valid: Int[Array, ""]
    resampled: Bool[Array, ""]
    log_likelihood: Float[Array, ""]
    ancestors: Int[Array, " n"]
    modes: Modes
    tracks: TrackTable


def _piece_names(injectors) -> list[str]:
    return [inj.name for inj in injectors]


class Filter(NamedTuple):
    """A particle filter: one piece per pipeline stage plus static sizes (hashable; the ``jit`` static argument).

    The defaults are the paper's filter with the team's settings: 500 particles, every pixel a
    measurement, aging buffer, eq. (1), best 95 % as output, systematic resampling, 5 % uniform
    explorers. Presets for the other methods are in :mod:`heatpf_jax.presets`.

    Attributes:
        motion: motion model (:mod:`heatpf_jax.motion.random_walk`).
        source: measurement source (:mod:`heatpf_jax.sources.pixels`).
        buffer: measurement buffer (:mod:`heatpf_jax.buffers.aging`).
        observation: observation model (:mod:`heatpf_jax.observation.kernels`).
        estimator: output (:mod:`heatpf_jax.estimate.top_fraction`).
        resampling: resampling strategy (:mod:`heatpf_jax.resampling.resamplers`).
        injectors: injectors applied in order after resampling (:mod:`heatpf_jax.injection.explorers`); those with
            a ``seed`` method also act before the weighting
            (:class:`~heatpf_jax.injection.memory_hints.RedetectionSeeds`).
            Their ``name`` attributes must differ.
        initial: initial distribution of the particles (a :class:`~heatpf_jax.injection.explorers.UniformBox`).
        num_particles: N.
        modes: multi-modal output (:mod:`heatpf_jax.estimate.modes`), none by default.
        ego: what moves particles, buffer and tracks with the robot (:mod:`heatpf_jax.motion.ego`): odometry
            by default.
        memory: the long-term memory (:mod:`heatpf_jax.memory`), none by default.
    """

    motion: Any = RandomWalk()
    source: Any = PixelSource()
    buffer: Any = AgingBuffer()
    observation: Any = InverseDistance()
    estimator: Any = TopFraction()
    resampling: Any = ESSResampling()
    injectors: tuple = (UniformExplorers(),)
    initial: Any = UniformBox()
    num_particles: int = 500
    modes: Any = NoModes()
    ego: Any = OdometryEgo()
    memory: Any = NoMemory()

    @property
    def requires(self) -> tuple[str, ...]:
        """Optional sequence keys the pieces read (``("robot_pose",)`` for localisation ego-motion)."""
        return tuple(getattr(self.ego, "requires", ()))

    # --- Parameters -------------------------------------------------------------------------------------

    def _per_piece(self, what: str) -> FilterParams:
        def of(piece):
            return getattr(piece, what)()

        return FilterParams(
            motion=of(self.motion),
            source=of(self.source),
            buffer=of(self.buffer),
            observation=of(self.observation),
            estimator=of(self.estimator),
            resampling=of(self.resampling),
            injectors={inj.name: of(inj) for inj in self.injectors},
            modes=of(self.modes),
            ego=of(self.ego),
            memory=of(self.memory),
        )

    def default_params(self) -> FilterParams:
        """Every piece's default params."""
        return self._per_piece("default_params")

    def properties(self) -> FilterParams:
        """The constraint of every parameter, a tree of :class:`~heatpf_jax.params.Param` like :class:`FilterParams`."""
        return self._per_piece("properties")

    def make_params(self, updates: dict[str, Any] | None = None, /, **names: Any) -> FilterParams:
        """Default params with some replaced by name: ``make_params(k=3, diffusion_std=0.1)`` or
        ``make_params({"motion.diffusion_std": 0.1})`` (dotted names, or the last part alone when unambiguous)."""
        return P.make_params(self, updates, **names)

    def validate(self) -> None:
        """Raises ``ValueError`` naming the field if a static choice is unusable."""
        n = self.num_particles
        if not isinstance(n, int) or isinstance(n, bool) or n < 1:
            raise ValueError(f"num_particles: must be a positive integer, got {n!r}")
        if not isinstance(self.injectors, tuple):
            raise ValueError(f"injectors: must be a tuple of injector pieces, got {type(self.injectors).__name__}")
        names = _piece_names(self.injectors)
        if len(set(names)) != len(names):
            raise ValueError(f"injectors: names must differ, got {names}")
        for piece in (self.motion, self.source, self.buffer, self.observation, self.estimator, self.resampling,
                      self.initial, self.modes, self.ego, self.memory, *self.injectors):
            if hasattr(piece, "validate"):
                piece.validate()

    # --- init / step ------------------------------------------------------------------------------------

    def init(self, key: PRNGKeyArray, params: FilterParams) -> FilterState:
        """Draws the initial particles from ``initial`` with uniform weights and an empty buffer (Fig. 2)."""
        n = self.num_particles
        xy = self.initial.sample(key, n)
        particles = self.motion.spawn(jax.random.fold_in(key, 1), xy, params.motion)
        return FilterState(
            particles=particles,
            log_weights=jnp.full((n,), -math.log(n), jnp.float32),
            buffer=empty_measurements(self.source.size),
            mean=jnp.mean(xy, axis=0),
            t=jnp.zeros((), jnp.int32),
            memory=self.memory.init(),
            source=self.source.init_state() if hasattr(self.source, "init_state") else (),
            injection=self._init_injection(),
        )

    def _init_injection(self) -> tuple:
        """The injectors' carried states in order (``()`` for one without ``init_state``); ``()`` if none has one."""
        if not any(hasattr(inj, "init_state") for inj in self.injectors):
            return ()
        return tuple(inj.init_state() if hasattr(inj, "init_state") else () for inj in self.injectors)

    def _seed(
        self, key, state: FilterState, particles, buffer, ego_tracks, inputs: StepInputs, params: FilterParams
    ):
        """Injectors with a ``seed`` method act on the predicted particles before the weighting (re-detection
        seeds); ``(particles, prior log weights)``, unchanged without such injectors."""
        seeders = [inj for inj in self.injectors if hasattr(inj, "seed")]
        if not seeders:
            return particles, state.log_weights
        recall = self.memory.recall(state.memory, buffer, ego_tracks, inputs.dt, params.memory)
        rank = ranks_of(jnp.argsort(-state.log_weights, stable=True))  # rank 0: most support; ties: the lower slot
        context = InjectionContext(
            particles=particles,
            log_weights=state.log_weights,
            rank=rank,
            used=jnp.zeros((), jnp.int32),
            estimate=None,
            motion=self.motion,
            motion_params=params.motion,
            measurements=buffer,
            memory=state.memory,
            recall=recall,
            previous_measurements=state.buffer,
            inputs=inputs,
        )
        k_seed = jax.random.fold_in(key, 11)  # a key of its own: the other stages' keys stay those without seeds
        for i, injector in enumerate(seeders):
            context = injector.seed(jax.random.fold_in(k_seed, i), context, params.injectors[injector.name])
        return context.particles, context.log_weights

    def _measure(self, carried, inputs: StepInputs, params) -> tuple[Measurements, Any]:
        """The source's measurements of this step's heat map (none without one), and what the source carries: a
        source with ``measure_state`` (:class:`~heatpf_jax.pieces.StatefulSource`) updates it on a heat map, and
        through ``carry_state``, where it has one, on a step without."""
        size = self.source.size
        if hasattr(self.source, "measure_state"):
            carry = getattr(self.source, "carry_state", lambda _inputs, _params, c: c)
            return lax.cond(
                inputs.has_heatmap,
                lambda c: self.source.measure_state(inputs, params, c),
                lambda c: (empty_measurements(size), carry(inputs, params, c)),
                carried,
            )
        new = lax.cond(
            inputs.has_heatmap,
            lambda _: self.source.measure(inputs, params),
            lambda _: empty_measurements(size),
            None,
        )
        return new, carried

    def step(
        self, key: PRNGKeyArray, state: FilterState, inputs: StepInputs, params: FilterParams
    ) -> tuple[FilterState, StepInfo]:
        """One filter step: every stage of the pipeline, in order (see the module docstring).

        Args:
            key: PRNG key.
            state: the previous state.
            inputs: this step's heat map, pose and odometry.
            params: :class:`FilterParams` as arrays (traced under ``jit``/``vmap``).

        Returns:
            ``(new_state, info)``.
        """
        k_motion, k_res, k_inject = jax.random.split(key, 3)

        ego = self.ego.ego(inputs, params.ego)
        inputs = inputs._replace(odometry=ego.particles)
        particles = self.motion.predict(k_motion, state.particles, inputs, params.motion)
        new, source_state = self._measure(state.source, inputs, params.source)
        buffer = self.buffer.update(state.buffer, new, inputs, params.buffer)
        particles, prior_log_w = self._seed(key, state, particles, buffer, ego.tracks, inputs, params)

        unnormalised = prior_log_w + self.observation.log_likelihood(particles.xy, buffer, params.observation)
        transition = transition_log_weight(particles)  # score-form motion only (heatpf_jax.motion.score)
        if transition is not None:
            unnormalised = unnormalised + transition
        log_likelihood = jax.nn.logsumexp(unnormalised)
        log_w = normalise_log(unnormalised, log_likelihood)
        weights = jnp.exp(log_w)
        order = order_by_weight(weights)  # one sort, shared by the estimator and the resampling
        particles = self.motion.remember(particles, weights)

        est = self.estimator.estimate(particles, weights, order, params.estimator)
        # A key of its own (folded, so that the other stages' keys stay those of a filter without modes).
        modes = self.modes.modes(jax.random.fold_in(key, 7), particles.xy, weights, params.modes)
        res = self.resampling.resample(k_res, particles.xy, log_w, order, params.resampling)
        particles = jax.tree.map(lambda x: x[res.ancestors], particles)
        tracks = self.memory.update(state.memory, modes, est.mean, buffer, ego.tracks, inputs.dt, params.memory)

        context = InjectionContext(
            particles=particles,
            log_weights=res.log_weights,
            rank=res.rank,
            used=jnp.zeros((), jnp.int32),
            estimate=est,
            motion=self.motion,
            motion_params=params.motion,
            measurements=buffer,
            memory=tracks,
            memory_lost=self.memory.lost(tracks, params.memory),
            has_heatmap=inputs.has_heatmap,
        )
        # One injector takes the step's key itself; several split it.
        keys = (k_inject,) if len(self.injectors) == 1 else tuple(jax.random.split(k_inject, len(self.injectors)))
        carried = list(state.injection) if state.injection else [()] * len(self.injectors)
        for i, (injector, k) in enumerate(zip(self.injectors, keys, strict=True)):
            if hasattr(injector, "inject_state"):  # an injector that carries a state (its init_state)
                context, carried[i] = injector.inject_state(k, context, params.injectors[injector.name], carried[i])
            else:
                context = injector.inject(k, context, params.injectors[injector.name])

        new_state = FilterState(
            particles=context.particles,
            log_weights=normalise_log(context.log_weights),
            buffer=buffer,
            mean=est.mean,
            t=state.t + 1,
            memory=tracks,
            source=source_state,
            injection=tuple(carried) if state.injection else (),
        )
        info = StepInfo(
            mean=est.mean,
            cov=est.cov,
            weighted_mean=est.weighted_mean,
            ess=res.ess,
            num_valid=jnp.sum(buffer.valid).astype(jnp.int32),
            resampled=res.resampled,
            log_likelihood=log_likelihood,
            ancestors=res.ancestors,
            modes=modes,
            tracks=tracks,
        )
        return new_state, info
