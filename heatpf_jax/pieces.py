"""What each stage of the filter pipeline provides, and what a step reads.

A filter step runs, always in this order (:func:`heatpf_jax.filter.Filter.step`)::

    motion.predict -> source.measure -> buffer.update -> observation.log_likelihood
        -> estimator.estimate -> resampling.resample -> injectors[i].inject

Each stage is a *piece*: a small frozen, hashable object that holds only static choices (sizes,
a resampler function, a box) and whose numbers live in its own params ``NamedTuple``. Every piece
has ``default_params()`` and ``properties()`` (a tree of :class:`heatpf_jax.params.Param` of the
params' structure). The protocols below document the other methods; a new capability is a new
class that satisfies one of them, never a flag inside the step.

Particles are a pytree (a ``NamedTuple``) whose leaves all have the particle axis first and that
has the field ``xy`` (``[N, 2]`` positions): the motion model decides what else they carry.
"""

from __future__ import annotations

from typing import Any, NamedTuple, Protocol, runtime_checkable

from jaxtyping import Array, Bool, Float, Int, PRNGKeyArray

from heatpf_jax.measurements import Measurements

__all__ = [
    "Buffer",
    "Estimator",
    "Injector",
    "MeasurementSource",
    "ModelWrapper",
    "MotionModel",
    "ObservationModel",
    "ResamplingStrategy",
    "StatefulSource",
    "StepInputs",
]


class StepInputs(NamedTuple):
    """What one filter step receives.

    Attributes:
        heatmap: ``float32 [H, W]`` activations (ignored unless ``has_heatmap``).
        has_heatmap: ``bool []``.
        cam_to_base: ``float32 [4, 4]`` camera pose at this step.
        odometry: ``float32 [3]`` motion since the previous step, ``(dx, dy, dtheta)``.
        intrinsics: ``float32 [4]`` ``(fx, fy, cx, cy)``.
        plane_height: ``float32 []`` the ball radius.
        dt: ``float32 []`` the filter period, seconds.
        pose_delta: ``float32 [3]`` the self-localisation's motion since the previous step in the previous
            base frame (:func:`heatpf_jax.motion.ego.pose_deltas`); zeros when the sequence has no ``robot_pose``.
        pose_confidence: ``float32 []`` its confidence (:func:`heatpf_jax.motion.ego.pose_confidences`).
    """

    heatmap: Float[Array, "h w"]
    has_heatmap: Bool[Array, ""]
    cam_to_base: Float[Array, "4 4"]
    odometry: Float[Array, "3"]
    intrinsics: Float[Array, "4"]
    plane_height: Float[Array, ""]
    dt: Float[Array, ""]
    pose_delta: Float[Array, "3"] | None = None
    pose_confidence: Float[Array, ""] | None = None


class _Piece(Protocol):
    def default_params(self) -> NamedTuple: ...

    def properties(self) -> NamedTuple: ...


@runtime_checkable
class MotionModel(_Piece, Protocol):
    """Predicts particles one step ahead (III-D) and makes particles from positions."""

    def spawn(self, key: PRNGKeyArray, xy: Float[Array, "n 2"], params: Any) -> Any:
        """Particles (this model's pytree) at the given positions, e.g. with zero velocity."""

    def predict(self, key: PRNGKeyArray, particles: Any, inputs: StepInputs, params: Any) -> Any: ...

    def remember(self, particles: Any, weights: Float[Array, " n"]) -> Any:
        """Particles after the update, given their normalised weights (before resampling, so that
        copies inherit what is stored): the identity for most models; the mass-inertia model keeps
        each particle's weight to scale its next spread."""


@runtime_checkable
class MeasurementSource(_Piece, Protocol):
    """Turns a heat map into a fixed-size :class:`Measurements` of ``size`` slots."""

    size: int

    def measure(self, inputs: StepInputs, params: Any) -> Measurements: ...


@runtime_checkable
class StatefulSource(MeasurementSource, Protocol):
    """A source that carries something from frame to frame (``FilterState.source``), e.g. what it has learned
    of the detector (:class:`~heatpf_jax.sources.lofted.LoftedSource`'s blob scale). The filter calls
    ``measure_state`` instead of ``measure``, only on steps with a heat map; on a step without, it calls the
    source's ``carry_state(inputs, params, state)`` where the source has one (e.g. to move what it remembers with
    the robot), and keeps the state unchanged otherwise."""

    def init_state(self) -> Any:
        """The carried state before the first frame (a pytree of fixed shape)."""

    def measure_state(self, inputs: StepInputs, params: Any, state: Any) -> tuple[Measurements, Any]: ...


@runtime_checkable
class Buffer(_Piece, Protocol):
    """Keeps measurements between heat maps (III-C): moves, ages or replaces them."""

    def update(
        self, buffer: Measurements, new: Measurements, inputs: StepInputs, params: Any
    ) -> Measurements: ...


@runtime_checkable
class ObservationModel(_Piece, Protocol):
    """Unnormalised log-likelihood of every particle given the buffer (III-B)."""

    def log_likelihood(
        self, xy: Float[Array, "n 2"], buffer: Measurements, params: Any
    ) -> Float[Array, " n"]: ...


@runtime_checkable
class Estimator(_Piece, Protocol):
    """The filter's output (III-F) from particles, their weights and their order by weight."""

    def estimate(
        self, particles: Any, weights: Float[Array, " n"], order: Int[Array, " n"], params: Any
    ) -> Any: ...


@runtime_checkable
class ResamplingStrategy(_Piece, Protocol):
    """Decides whether and how to resample (III-E); see :class:`heatpf_jax.resampling.resamplers.Resampled`."""

    def resample(
        self,
        key: PRNGKeyArray,
        xy: Float[Array, "n 2"],
        log_weights: Float[Array, " n"],
        order: Int[Array, " n"],
        params: Any,
    ) -> Any:
        """Ancestors and new weights from the particles' positions (cluster-wise resampling uses
        them; plain resampling ignores them), normalised log weights and their order by weight."""


@runtime_checkable
class Injector(_Piece, Protocol):
    """Replaces some particles by new ones (explorers, random particles, hints)."""

    name: str

    def inject(self, key: PRNGKeyArray, context: Any, params: Any) -> Any: ...


class ModelWrapper:
    """A model around another (``self.model``) that changes only its ``step``: ``init``, ``default_params``,
    ``properties``, ``validate`` and ``requires`` (the optional inputs it reads, e.g. ``robot_pose``) are the wrapped
    model's. A subclass is a frozen dataclass (hashable: models are static arguments of ``jax.jit``) with a
    ``model`` field and its own ``step``."""

    model: Any

    def init(self, key: PRNGKeyArray, params):
        return self.model.init(key, params)

    def default_params(self):
        return self.model.default_params()

    def properties(self):
        return self.model.properties()

    def validate(self) -> None:
        self.model.validate()

    @property
    def requires(self) -> tuple[str, ...]:
        return tuple(getattr(self.model, "requires", ()))
