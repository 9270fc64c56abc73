"""Measurement sources: each piece against the projection / clustering function it wraps, by hand."""

from __future__ import annotations

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.image_components import strongest_cluster_centre
from tests.conftest import step_inputs


def test_pixel_source_is_every_pixel_above_threshold(small_sequence):
    inputs = step_inputs(small_sequence, 2, has_heatmap=True)
    source = hp.PixelSource(max_measurements=256)
    out = source.measure(inputs, hp.SourceParams(threshold=0.4, max_distance=12.0))
    assert source.size == 256 and out.xy.shape == (256, 2)
    heat = np.asarray(small_sequence.heatmaps[2])
    assert int(np.sum(out.valid)) == int(np.sum(heat >= 0.4))  # all pixels fit and every ray hits the ground
    np.testing.assert_allclose(np.sort(np.asarray(out.weight)[np.asarray(out.valid)]), np.sort(heat[heat >= 0.4]))
    # Each measurement is its pixel's ray on the ball plane (NumPy, in float64), in raster order.
    v, u = np.nonzero(heat >= 0.4)
    fx, fy, cx, cy = np.asarray(small_sequence.intrinsics, np.float64)
    pose = np.asarray(small_sequence.cam_to_base[2], np.float64)
    rays = pose[:3, :3] @ np.stack([(u - cx) / fx, (v - cy) / fy, np.ones(len(u))])
    scale = (float(small_sequence.ball_radius) - pose[2, 3]) / rays[2]
    xy = pose[:2, 3, None] + scale * rays[:2]
    np.testing.assert_allclose(np.asarray(out.xy)[np.asarray(out.valid)], xy.T, atol=1e-4)


def test_cluster_centre_source_is_one_projected_centroid(small_sequence):
    inputs = step_inputs(small_sequence, 2, has_heatmap=True)
    source = hp.ClusterCentreSource()
    out = source.measure(inputs, hp.SourceParams(threshold=0.3, max_distance=12.0))
    assert source.size == 1 and bool(out.valid[0])
    uv, peak, found = strongest_cluster_centre(inputs.heatmap, 0.3)
    xy, ok = hp.project_pixel(uv, inputs.intrinsics, inputs.cam_to_base, inputs.plane_height)
    np.testing.assert_allclose(np.asarray(out.xy[0]), np.asarray(xy), atol=1e-6)
    assert float(out.weight[0]) == pytest.approx(float(peak))
    # Beyond max_distance nothing is measured.
    near = source.measure(inputs, hp.SourceParams(threshold=0.3, max_distance=0.5))
    assert not bool(near.valid[0])


def test_source_validation_names_the_field():
    with pytest.raises(ValueError, match="^max_measurements:"):
        hp.PixelSource(max_measurements=0).validate()
    with pytest.raises(ValueError, match="^downscale:"):
        hp.PixelSource(downscale=1.5).validate()
