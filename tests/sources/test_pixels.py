"""Measurement sources: each piece against the projection / clustering function it wraps, by hand."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sources.image_centroids import blob_centres
from heatpf_jax.sources.image_components import strongest_cluster_centre

# The sources and functions tested, one program each (shared by the tests): run eagerly, each of their operations
# would compile on its own.
PIXELS = jax.jit(hp.sources.PixelSource(max_measurements=256).measure)
CLUSTER_CENTRE = jax.jit(hp.sources.ClusterCentreSource().measure)
CENTROIDS = jax.jit(hp.sources.CentroidSource(max_measurements=256).measure)
BLOB_CENTRES = jax.jit(blob_centres)


@jax.jit
def _cluster_centre_xy(heatmap, threshold, intrinsics, cam_to_base, plane_height):
    """:func:`strongest_cluster_centre` projected by :func:`hp.camera.project_pixel`, and its peak: one program."""
    uv, peak, found = strongest_cluster_centre(heatmap, threshold)
    xy, ok = hp.camera.project_pixel(uv, intrinsics, cam_to_base, plane_height)
    return xy, peak


def _inputs(seq: hp.Sequence, t: int) -> hp.StepInputs:
    """``tests.conftest.step_inputs(seq, t, has_heatmap=True)`` in NumPy: its `jnp` conversions would each compile a
    program of their own."""
    return hp.StepInputs(
        heatmap=np.asarray(seq.heatmaps[t], np.float32), has_heatmap=np.asarray(True),
        cam_to_base=np.asarray(seq.cam_to_base[t], np.float32), odometry=np.zeros(3, np.float32),
        intrinsics=np.asarray(seq.intrinsics, np.float32), plane_height=np.asarray(seq.ball_radius, np.float32),
        dt=np.asarray(seq.dt, np.float32))


def test_pixel_source_is_every_pixel_above_threshold(small_sequence):
    inputs = _inputs(small_sequence, 2)
    source = hp.sources.PixelSource(max_measurements=256)
    out = jax.tree.map(np.asarray, PIXELS(inputs, hp.sources.SourceParams(threshold=0.4, max_distance=12.0)))
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
    inputs = _inputs(small_sequence, 2)
    source = hp.sources.ClusterCentreSource()
    out = jax.tree.map(np.asarray, CLUSTER_CENTRE(inputs, hp.sources.SourceParams(threshold=0.3, max_distance=12.0)))
    assert source.size == 1 and bool(out.valid[0])
    xy, peak = _cluster_centre_xy(inputs.heatmap, 0.3, inputs.intrinsics, inputs.cam_to_base, inputs.plane_height)
    np.testing.assert_allclose(np.asarray(out.xy[0]), np.asarray(xy), atol=1e-6)
    assert float(out.weight[0]) == pytest.approx(float(peak))
    # Beyond max_distance nothing is measured.
    near = CLUSTER_CENTRE(inputs, hp.sources.SourceParams(threshold=0.3, max_distance=0.5))
    assert not bool(np.asarray(near.valid)[0])


def test_source_validation_names_the_field():
    with pytest.raises(ValueError, match="^max_measurements:"):
        hp.sources.PixelSource(max_measurements=0).validate()
    with pytest.raises(ValueError, match="^downscale:"):
        hp.sources.PixelSource(downscale=1.5).validate()


def test_centroid_source_projects_each_pixels_blob_centre(small_sequence):
    inputs = _inputs(small_sequence, 2)
    params = hp.sources.CentroidParams(threshold=0.4)
    out = jax.tree.map(np.asarray, CENTROIDS(inputs, params))
    heat = np.asarray(small_sequence.heatmaps[2])
    v, u = np.nonzero(heat >= 0.4)
    assert int(np.sum(out.valid)) == len(u)
    np.testing.assert_allclose(np.asarray(out.weight)[np.asarray(out.valid)], heat[v, u])  # raster order
    centres = BLOB_CENTRES(heat, np.stack([u, v], 1).astype(np.float32), inputs.intrinsics, inputs.cam_to_base,
                           threshold=0.4, plane_height=inputs.plane_height)
    uv = np.asarray(centres.uv, np.float64)
    fx, fy, cx, cy = np.asarray(small_sequence.intrinsics, np.float64)
    pose = np.asarray(small_sequence.cam_to_base[2], np.float64)
    rays = pose[:3, :3] @ np.stack([(uv[:, 0] - cx) / fx, (uv[:, 1] - cy) / fy, np.ones(len(uv))])
    xy = pose[:2, 3, None] + (float(small_sequence.ball_radius) - pose[2, 3]) / rays[2] * rays[:2]
    np.testing.assert_allclose(np.asarray(out.xy)[np.asarray(out.valid)], xy.T, atol=1e-4)
    # A ball's pixels all end near the ball (the sequence's ground truth), closer than the pixels themselves.
    raw = PIXELS(inputs, hp.sources.SourceParams(threshold=0.4))
    truth = np.asarray(small_sequence.ground_truth[2])
    spread = lambda m: np.abs(np.asarray(m.xy)[np.asarray(m.valid)] - truth).max()  # noqa: E731
    assert spread(out) < spread(raw)
    # A blob that spills out of its window more than max_spill is dropped: with max_spill below 1, every one.
    assert not np.any(np.asarray(CENTROIDS(inputs, params._replace(max_spill=0.99)).valid))
    assert np.array_equal(np.asarray(CENTROIDS(inputs, params._replace(max_spill=3.0)).valid),
                          np.asarray(out.valid))
