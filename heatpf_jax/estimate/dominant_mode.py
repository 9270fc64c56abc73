"""Output of a multi-modal particle set: the dominant mode (Olufs et al. sec. 3.2, 3.4).

With two visually identical objects, or a ball and a bright false positive, the particle cloud has
several modes and the paper's top-fraction mean (III-F) lands between them. Olufs et al. obtain
"multiple states from one particle set by applying the MC estimation methods separately on each
cluster" and output "the most dominant observation": here the weighted mean and covariance of the
heaviest mean-shift mode (:class:`heatpf_jax.estimate.modes.MeanShiftModes`). With one mode this is the
weighted mean of that mode's particles.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from heatpf_jax.estimate.modes import MeanShiftModes, MeanShiftParams
from heatpf_jax.estimate.top_fraction import Estimate, weighted_mean_cov

__all__ = ["DominantMode"]


@dataclass(frozen=True)
class DominantMode:
    """The heaviest mean-shift mode's weighted mean and covariance as the filter's output.

    Attributes:
        finder: the mean-shift mode finder (deterministic: its seeds are the heaviest particles).
    """

    finder: MeanShiftModes = field(default_factory=MeanShiftModes)

    def default_params(self) -> MeanShiftParams:
        return self.finder.default_params()

    def properties(self) -> MeanShiftParams:
        return self.finder.properties()

    def validate(self) -> None:
        self.finder.validate()

    def estimate(self, particles, weights: Float[Array, " n"], order: Int[Array, " n"], params) -> Estimate:
        del order
        xy = particles.xy
        # Mean shift ignores the key; the modes are sorted by weight, the valid ones first.
        modes = self.finder.modes(jax.random.key(0), xy, weights, params)
        weighted_mean, cov_all = weighted_mean_cov(xy, weights)
        ok = modes.valid[0]
        return Estimate(
            mean=jnp.where(ok, modes.mean[0], weighted_mean),
            cov=jnp.where(ok, modes.cov[0], cov_all),
            weighted_mean=weighted_mean,
        )
