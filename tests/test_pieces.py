"""Every shipped piece satisfies its stage's protocol, is hashable by value, and its properties
tree has the structure of its params."""

from __future__ import annotations

import jax
import pytest

import heatpf_jax as hp
from heatpf_jax import pieces
from heatpf_jax.params import Param, validate

PIECES = [
    (pieces.MotionModel, [hp.motion.RandomWalk(), hp.motion.DiffusionOnly()]),
    (pieces.MeasurementSource, [hp.sources.PixelSource(), hp.sources.ClusterCentreSource()]),
    (pieces.Buffer, [hp.buffers.AgingBuffer(), hp.buffers.LatestOnly()]),
    (pieces.ObservationModel, [hp.observation.InverseDistance(), hp.observation.GaussianKernel(),
                               hp.observation.Floored(hp.observation.InverseDistance())]),
    (pieces.Estimator, [hp.estimate.TopFraction()]),
    (pieces.ResamplingStrategy, [hp.resampling.ESSResampling(r) for r in hp.resampling.RESAMPLERS.values()]),
    (pieces.Injector, [hp.injection.UniformExplorers(), hp.injection.GaussianExplorers(),
                       hp.injection.RandomParticles()]),
]


@pytest.mark.parametrize("protocol, instances", PIECES, ids=[p.__name__ for p, _ in PIECES])
def test_pieces_satisfy_their_protocol(protocol, instances):
    for piece in instances:
        assert isinstance(piece, protocol), piece
        assert hash(piece) == hash(type(piece)(*piece.__dict__.values()))  # by value, so jit caches hit
        params, props = piece.default_params(), piece.properties()
        assert jax.tree.structure(params) == jax.tree.structure(props, is_leaf=lambda x: isinstance(x, Param))
        for leaf in jax.tree.leaves(props, is_leaf=lambda x: isinstance(x, Param)):
            assert isinstance(leaf, Param)
        validate(params, props)  # the defaults satisfy their own constraints
