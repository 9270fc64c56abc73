"""Gradient estimators through resampling, as wrappers of a resampling strategy (III-E).

Resampling copies particles by a discrete draw, so a plain filter's gradient stops there: the copies get
constant weights and forget how their parameters shaped their ancestors' weights. The wrappers below keep
the wrapped strategy's draw (the ancestors, the ranks and the *values* of the weights are the strategy's
own) and change what flows backwards:

* :class:`StopGradientResampling` (the default for tuning): Scibior and Wood (2021), "Differentiable
  particle filtering without modifying the forward pass". Each slot's new log weight gains
  ``lw[a] - stop_gradient(lw[a])`` of its ancestor ``a``: zero in value, the ancestor's log-weight
  gradient in gradient. Gradients of the log-likelihood and of posterior expectations (the estimate)
  are then consistent; with score-form motion (:mod:`heatpf_jax.motion.score`) they are Fisher's
  identity on the particles' genealogy.
* :class:`SoftResampling` (Karkus et al. 2018, PF-net): ancestors from the mixture ``q = alpha w +
  (1 - alpha) / N``, new weights ``w[a] / q[a]`` (normalised), which carry the gradient of ``w[a]``. The
  forward pass changes (non-uniform weights after resampling); ``alpha = 1`` is plain resampling without
  gradient, ``alpha = 0`` keeps all weights and gradients but stops resampling.
* :class:`DetachResampling`: the control. Gradients stop at resampling (every weight after it is a
  constant, as in the plain strategy); the known-answer test shows its gradients are wrong.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, Int, PRNGKeyArray

from heatpf_jax.numerics import normalise_log
from heatpf_jax.params import unit_interval
from heatpf_jax.resampling.resamplers import (
    ESSParams,
    Resampled,
    check_resampler,
    ess_trigger,
    sorted_resampled,
    systematic,
)

__all__ = ["DetachResampling", "SoftResampling", "StopGradientResampling"]


class _Wrapper:
    """Delegates params, properties and validation to the wrapped strategy ``self.resampling``."""

    def default_params(self):
        return self.resampling.default_params()

    def properties(self):
        return self.resampling.properties()

    def validate(self) -> None:
        if hasattr(self.resampling, "validate"):
            self.resampling.validate()


@dataclass(frozen=True)
class StopGradientResampling(_Wrapper):
    """The wrapped strategy with Scibior and Wood's stop-gradient correction of the new weights.

    Values (ancestors, ranks, weights) are exactly the wrapped strategy's; where it resampled, slot i's
    log weight gains ``lw[a_i] - stop_gradient(lw[a_i])`` (where it did not, ``a_i = i`` and the weight
    keeps its own gradient). Params and properties are the wrapped strategy's.

    Attributes:
        resampling: a resampling strategy (:class:`~heatpf_jax.resampling.resamplers.ESSResampling`,
            :class:`~heatpf_jax.resampling.clustered.ClusterResampling`).
    """

    resampling: Any

    def resample(
        self,
        key: PRNGKeyArray,
        xy: Float[Array, "n 2"],
        log_weights: Float[Array, " n"],
        order: Int[Array, " n"],
        params: Any,
    ) -> Resampled:
        res = self.resampling.resample(key, xy, log_weights, order, params)
        inherited = log_weights[res.ancestors]
        # A zero weight (log -inf, possible where nothing was resampled) inherits no gradient and no NaN.
        finite = jnp.isfinite(inherited)
        inherited = jnp.where(finite, inherited, 0.0)
        new = lax.stop_gradient(res.log_weights) + (inherited - lax.stop_gradient(inherited))
        return res._replace(log_weights=new)


@dataclass(frozen=True)
class DetachResampling(_Wrapper):
    """The wrapped strategy with every gradient through the weights stopped at resampling (the control).

    Where the strategy resampled, the new weights are constants; where it did not, they keep their
    gradient (as the plain strategy). Exists to show that the known-answer test has power.

    Attributes:
        resampling: a resampling strategy.
    """

    resampling: Any

    def resample(self, key, xy, log_weights, order, params) -> Resampled:
        res = self.resampling.resample(key, xy, log_weights, order, params)
        return res._replace(log_weights=jnp.where(res.resampled, lax.stop_gradient(res.log_weights), res.log_weights))


@dataclass(frozen=True)
class SoftResampling:
    """Soft resampling (Karkus et al. 2018): ancestors from ``q = alpha w + (1 - alpha) / N``, weights ``w / q``.

    The particles are drawn in the step's order of decreasing weight (``q`` has the same order), so
    slot i has support rank i as with :class:`~heatpf_jax.resampling.resamplers.ESSResampling`.

    Its params are :class:`~heatpf_jax.resampling.resamplers.ESSParams` (it replaces an ``ESSResampling`` without
    changing the filter's params); ``alpha`` is a static choice of the gradient estimator.

    Attributes:
        resampler: an index resampler ``(key, weights, num_samples) -> indices``.
        alpha: share of the weights in the proposal ``q = alpha w + (1 - alpha) / N`` (PF-net's 0.5).
    """

    resampler: Callable[[PRNGKeyArray, Array, int], Array] = systematic
    alpha: float = 0.5

    def default_params(self) -> ESSParams:
        return ESSParams()

    def properties(self) -> ESSParams:
        return ESSParams(resample_threshold=unit_interval(trainable=False))

    def validate(self) -> None:
        check_resampler(self.resampler)
        if not (isinstance(self.alpha, (int, float)) and 0.0 <= self.alpha <= 1.0):
            raise ValueError(f"alpha: must be in [0, 1], got {self.alpha!r}")

    def resample(
        self,
        key: PRNGKeyArray,
        xy: Float[Array, "n 2"],
        log_weights: Float[Array, " n"],
        order: Int[Array, " n"],
        params: ESSParams,
    ) -> Resampled:
        del xy
        n = log_weights.shape[0]
        weights = jnp.exp(log_weights)
        ess, resampled = ess_trigger(weights, params.resample_threshold)
        alpha = self.alpha
        q = alpha * lax.stop_gradient(weights) + (1.0 - alpha) / n
        idx = order[self.resampler(key, q[order], n)]
        new = normalise_log(log_weights[idx] - jnp.log(q[idx]))
        return sorted_resampled(resampled, idx, new, log_weights, order, ess)

