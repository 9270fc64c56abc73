"""Named methods: what each preset is made of, and the 2018 node's settings as the issue lists them."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax import presets


def test_every_method_builds_and_validates():
    for name in presets.METHODS:
        method = hp.build(name)
        method.model.validate()
        hp.validate_params(method.params, method.model)
    with pytest.raises(ValueError, match="^method: must be one of"):
        hp.build("particle")
    # `heatpf eval` compares every method.
    from heatpf_jax.evaluate import DEFAULT_VARIANTS

    assert {v.method for v in DEFAULT_VARIANTS} == set(presets.METHODS)


def test_conventional_is_the_particle_filter_with_the_cluster_source():
    heat, conv = hp.build("paper").model, hp.build("conventional").model
    assert isinstance(conv.source, hp.sources.ClusterCentreSource) and isinstance(heat.source, hp.sources.PixelSource)
    assert conv._replace(source=heat.source) == heat  # every other piece is the same
    assert hash(hp.paper_filter()) == hash(hp.paper_filter())  # equal filters share a compilation


def test_paper_heatmap_and_extended_are_what_their_names_say():
    paper, heat, ext = (hp.build(name) for name in ("paper", "heatmap", "extended"))
    # paper: the 2019 filter as the default Filter of pieces (static position, eq. 1, plain resampling).
    assert paper.model == hp.Filter() and paper.params == hp.Filter().default_params()
    # heatmap: the same pipeline with the lofted source (its blob scale learned), a velocity state and the
    # range-aware observation.
    assert heat.model.source == hp.sources.LoftedSource() and heat.params.source == hp.sources.LoftedParams()
    assert isinstance(heat.model.motion, hp.motion.ConstantVelocity)
    assert isinstance(heat.model.observation, hp.observation.FootprintTemplate)
    assert [type(i) for i in heat.model.injectors] == [hp.injection.UniformExplorers, hp.injection.ReacquisitionSeeds]
    assert heat.model._replace(
        source=paper.model.source, motion=paper.model.motion, observation=paper.model.observation,
        injectors=paper.model.injectors,
    ) == paper.model
    assert heat.params.observation.k == 10
    # source=centroids: each pixel at its blob's centroid, heatmap's spill gate 1.5 (paper's: none).
    centroids = hp.build("heatmap", hp.FilterOptions(source="centroids"))
    assert centroids.model == heat.model._replace(source=hp.sources.CentroidSource())
    assert centroids.params.source == hp.sources.CentroidParams(max_spill=1.5)
    pixels = hp.build("heatmap", hp.FilterOptions(source="pixels"))
    assert pixels.model == heat.model._replace(source=hp.sources.PixelSource())
    assert pixels.params.source == hp.sources.SourceParams()
    assert hp.build("heatmap", hp.FilterOptions(source="lofted")) == heat
    assert hp.build("heatmap", hp.FilterOptions(hover_frames=16)).model.source.hover_frames == 16  # opt-in
    assert hp.build("paper", hp.FilterOptions(source="centroids")).params.source == hp.sources.CentroidParams()
    gauss = hp.build("heatmap", hp.FilterOptions(observation="gaussian"))
    assert gauss.params.observation.k == 10 and gauss.params.observation.obs_std == 0.05
    # extended: mass inertia, cluster-wise resampling, random and measurement particles, dominant mode.
    assert isinstance(ext.model.motion, hp.motion.MassInertia) and isinstance(
        ext.model.resampling, hp.resampling.ClusterResampling
    )
    assert [type(i) for i in ext.model.injectors] == [
        hp.injection.UniformExplorers, hp.injection.RandomParticles, hp.injection.MeasurementExplorers
    ]
    assert not ext.model.resampling.correct and ext.params.resampling.bandwidth == 0.1
    assert isinstance(ext.model.estimator, hp.estimate.DominantMode)
    # motion=NAME swaps only the motion model; heatmap's large white-noise acceleration is for the constant
    # velocity: the rolling ball keeps its own (its kicks change its speed) and heatmap's speed of new particles.
    for name, piece in [("random_walk", hp.motion.RandomWalk), ("rolling_ball", hp.motion.RollingBall),
                        ("constant_velocity", hp.motion.ConstantVelocity), ("mass_inertia", hp.motion.MassInertia)]:
        swapped = hp.build("heatmap", hp.FilterOptions(motion=name))
        assert swapped.model == heat.model._replace(motion=piece())
        assert hp.build("paper", hp.FilterOptions(motion=name)).model == paper.model._replace(motion=piece())
    rolling = hp.build("heatmap", hp.FilterOptions(motion="rolling_ball")).params.motion
    assert rolling == hp.motion.RollingBallParams(spawn_speed_std=3.0)
    assert hp.build("heatmap", hp.FilterOptions(motion="constant_velocity")) == heat
    # The observation option still applies to every particle filter.
    forced = hp.build("heatmap", hp.FilterOptions(observation="inverse_distance")).model
    assert isinstance(forced.observation, hp.observation.InverseDistance)


def test_bitbots2018_settings():
    model, params = hp.build("bitbots2018")
    assert model.num_particles == 2000
    assert isinstance(model.motion, hp.motion.DiffusionOnly) and params.motion.diffusion_std == 0.1
    assert isinstance(model.buffer, hp.buffers.LatestOnly)
    assert isinstance(model.observation, hp.observation.Floored) and params.observation.weight_floor == 0.001
    assert params.observation.base.k == 1
    assert params.estimator.top_fraction == 0.5
    assert model.resampling.resampler is hp.resampling.systematic and params.resampling.resample_threshold == 1.0
    (explorers,) = model.injectors
    assert explorers.box == (-18.0, 18.0, -18.0, 18.0) and params.injectors["explorers"].explorer_fraction == 0.2
    assert model.initial.box == (-18.0, 18.0, -18.0, 18.0)


def test_bitbots2018_weight_floor_and_no_odometry(small_sequence):
    """A step without a heat map weights every particle equally; odometry moves nothing."""
    model = presets.bitbots2018(hp.FilterOptions(max_measurements=128, k_max=1))
    model = model._replace(num_particles=256)
    params = presets.bitbots2018_params()
    seq = small_sequence._replace(has_heatmap=np.arange(small_sequence.num_steps) < 10,
                                  odometry=np.tile([0.2, 0.0, 0.1], (small_sequence.num_steps, 1)))
    res = hp.run(jax.random.key(0), seq, params, model)
    ess = np.asarray(res.info.ess)
    np.testing.assert_allclose(ess[10:], 256, rtol=1e-4)  # no heat map: uniform weights
    assert np.all(ess[1:10] < 256)
    # Floor: every particle keeps a weight of at least 0.001 / (sum of weights) on heat-map steps.
    lik = model.observation.log_likelihood(
        np.array([[50.0, 50.0]], np.float32),
        hp.Measurements(
            xy=np.zeros((1, 2), np.float32),
            weight=np.ones(1, np.float32),
            valid=np.ones(1, bool),
            footprint=np.zeros((1, 2, 2), np.float32),
        ),
        params.observation,
    )
    assert float(lik[0]) == pytest.approx(np.log(1 / np.hypot(50, 50)) if 1 / np.hypot(50, 50) > 0.001
                                          else np.log(0.001), rel=1e-5)


def test_options_validation_names_the_field():
    for change, field in [({"resampler": "bogus"}, "resampler"), ({"spawn": "normal"}, "spawn"),
                          ({"observation": "cauchy"}, "observation"), ({"num_particles": 0}, "num_particles"),
                          ({"k_max": 1.5}, "k_max"), ({"spawn_box": (1.0, 0.0, -1.0, 1.0)}, "spawn_box"),
                          ({"knn": "kdtree"}, "knn"), ({"motion": "brownian"}, "motion"),
                          ({"hover_frames": -1}, "hover_frames")]:
        with pytest.raises(ValueError, match=rf"^{field}:"):
            hp.paper_filter(hp.FilterOptions(**change))
