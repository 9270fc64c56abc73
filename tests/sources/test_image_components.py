"""Conventional measurement: JAX connected components and cluster centre against scipy.ndimage."""

import jax
import numpy as np
import pytest
from scipy import ndimage

import heatpf_jax as hp
from heatpf_jax.sources.image_components import cluster_measurement, connected_components, strongest_cluster_centre

EIGHT = np.ones((3, 3), int)
_components = jax.jit(connected_components)
_centre = jax.jit(strongest_cluster_centre)
# One program per buffer size: run eagerly, each of its operations would compile on its own.
_cluster_measurement = jax.jit(cluster_measurement, static_argnames="size")
# Inputs are NumPy: eager `jnp` conversions compile a program each.


def _blobs(rng, shape=(30, 40), sigma=2.0):
    return ndimage.gaussian_filter(rng.random(shape), sigma)


@pytest.mark.parametrize("seed", range(4))
def test_components_partition_equals_scipy(seed):
    rng = np.random.default_rng(seed)
    field = _blobs(rng)
    mask = field > np.quantile(field, 0.6)
    labels = np.asarray(_components(mask))
    ref, count = ndimage.label(mask, structure=EIGHT)
    assert count >= 2
    assert np.all(labels[~mask] == mask.size)
    # Same partition: one JAX label per scipy component, and distinct components get distinct labels.
    per_component = [set(labels[ref == i].tolist()) for i in range(1, count + 1)]
    assert all(len(c) == 1 for c in per_component)
    assert len({next(iter(c)) for c in per_component}) == count
    # The label is the smallest raster index of the component.
    flat_ref = ref.ravel()
    for i in range(1, count + 1):
        assert next(iter(per_component[i - 1])) == int(np.flatnonzero(flat_ref == i)[0])


def test_long_snake_component_converges():
    mask = np.zeros((21, 21), bool)
    mask[::2, :] = True
    mask[1::4, -1] = True
    mask[3::4, 0] = True  # one serpentine component of ~230 pixels
    labels = np.asarray(_components(mask))
    assert ndimage.label(mask, structure=EIGHT)[1] == 1
    assert set(labels[mask].tolist()) == {0}


def _numpy_centre(heat, threshold):
    mask = heat >= threshold
    ref, _ = ndimage.label(mask, structure=EIGHT)
    best = np.unravel_index(np.argmax(np.where(mask, heat, -1.0)), heat.shape)
    member = ref == ref[best]
    w = np.where(member, heat, 0.0)
    rows, cols = np.mgrid[: heat.shape[0], : heat.shape[1]]
    return np.array([(w * cols).sum(), (w * rows).sum()]) / w.sum(), heat[best]


@pytest.mark.parametrize("threshold", [0.45, 0.55])
def test_strongest_cluster_centre_matches_numpy(threshold):
    rng = np.random.default_rng(7)
    heat = _blobs(rng, sigma=1.5)
    heat = (heat - heat.min()) / (heat.max() - heat.min())
    uv, peak, found = _centre(np.asarray(heat, np.float32), np.float32(threshold))
    ref_uv, ref_peak = _numpy_centre(heat.astype(np.float32), threshold)
    assert bool(found)
    np.testing.assert_allclose(np.asarray(uv), ref_uv, rtol=1e-5, atol=1e-4)
    assert float(peak) == pytest.approx(float(ref_peak), rel=1e-6)


def test_split_blob_gives_the_centre_of_one_half():
    # Two halves of one ball separated by an occluding stripe: the conventional detection is one half's centre.
    heat = np.zeros((20, 30), np.float32)
    heat[8:12, 5:12] = 0.9
    heat[8:12, 14:21] = 0.8
    uv, peak, found = _centre(heat, np.float32(0.5))
    assert bool(found) and float(peak) == pytest.approx(0.9)
    np.testing.assert_allclose(np.asarray(uv), [8.0, 9.5], atol=1e-5)


def test_nothing_above_threshold():
    heat = np.full((10, 12), 0.2, np.float32)
    _, _, found = _centre(heat, np.float32(0.5))
    assert not bool(found)
    m = _cluster_measurement(heat, np.array([20.0, 20.0, 6.0, 5.0], np.float32),
                             np.asarray(hp.camera.camera_pose(height=0.6, pitch=0.6), np.float32),
                             threshold=0.5, plane_height=0.075)
    assert not bool(np.asarray(m.valid)[0])


def test_cluster_measurement_projects_the_centre():
    intr = np.array([20.0, 20.0, 6.0, 5.0])
    pose = hp.camera.camera_pose(height=0.6, pitch=0.6)
    heat = np.zeros((10, 12), np.float32)
    heat[6:8, 3:5] = [[0.6, 0.9], [0.7, 0.8]]
    m = jax.tree.map(np.asarray, _cluster_measurement(heat, np.asarray(intr, np.float32), np.asarray(pose, np.float32),
                                                      threshold=np.float32(0.5), plane_height=0.075, size=3))
    uv = np.array([(0.6 * 3 + 0.9 * 4 + 0.7 * 3 + 0.8 * 4) / 3.0, (0.6 * 6 + 0.9 * 6 + 0.7 * 7 + 0.8 * 7) / 3.0])
    # Closed-form ray/plane intersection in NumPy.
    ray = pose[:3, :3] @ np.array([(uv[0] - intr[2]) / intr[0], (uv[1] - intr[3]) / intr[1], 1.0])
    s = (0.075 - pose[2, 3]) / ray[2]
    expected = pose[:2, 3] + s * ray[:2]
    assert np.asarray(m.valid).tolist() == [True, False, False]
    np.testing.assert_allclose(np.asarray(m.xy[0]), expected, rtol=1e-5)
    assert float(m.weight[0]) == pytest.approx(0.9)
