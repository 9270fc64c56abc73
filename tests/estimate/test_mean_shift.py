"""``heatpf_jax.estimate.mean_shift`` against independent references.

* flat-kernel mean shift: sklearn's ``MeanShift`` with the same seeds, on points repeated by integer weights;
* Gaussian mean shift: a float64 NumPy brute force written here.

The sklearn comparison skips where scikit-learn is not installed.

Compiling is most of the cost here, so each kernel is compiled once for the whole file: the
Gaussian mean shift batched over two data sets and differentiated (every batch element is checked
against the reference, which shows that ``vmap`` and ``grad`` work).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from heatpf_jax.estimate.mean_shift import mean_shift, seed_points
from tests.estimate.clustering_data import CENTRES, N, blobs

SEEDS = 16
ITERS = 50  # enough for the seeds of one mode to agree to float32 precision
KEEP = 2  # max_clusters of the Gaussian runs (fewer than the blobs: the heaviest are kept)


@jax.jit
def _flat(points, weights, bandwidth):
    """The seeds, and the flat-kernel mean shift keeping every mode (``max_clusters = num_seeds``)."""
    clusters = mean_shift(
        points, weights, bandwidth=bandwidth, num_seeds=SEEDS, max_clusters=SEEDS, num_iters=ITERS, kernel="flat"
    )
    return seed_points(points, weights, SEEDS), clusters


def _gaussian_loss(points, weights, bandwidth, radius):
    out = mean_shift(
        points, weights, bandwidth=bandwidth, num_seeds=SEEDS, max_clusters=KEEP, num_iters=ITERS, merge_radius=radius
    )
    return jnp.sum(out.centres) + jnp.sum(out.weights * jnp.arange(KEEP, dtype=jnp.float32)), out


_gaussian_batch = jax.jit(jax.vmap(jax.value_and_grad(_gaussian_loss, argnums=(0, 1), has_aux=True)))


def _gaussian(points, weights, bandwidths, radii):
    """Gaussian mean shift of a batch of data sets: ``(clusters, d loss / d points, d loss / d weights)``."""
    f32 = lambda x: jnp.asarray(np.asarray(x), jnp.float32)  # noqa: E731
    (_, out), (g_points, g_weights) = _gaussian_batch(f32(points), f32(weights), f32(bandwidths), f32(radii))
    return jax.tree.map(np.asarray, out), np.asarray(g_points), np.asarray(g_weights)


def _match(ours: np.ndarray, theirs: np.ndarray, atol: float) -> np.ndarray:
    """``perm`` with ``ours[i] ~ theirs[perm[i]]``; asserts the two sets of centres agree."""
    assert ours.shape == theirs.shape, (ours, theirs)
    d = np.linalg.norm(ours[:, None, :] - theirs[None, :, :], axis=-1)
    perm = np.argmin(d, axis=1)
    assert sorted(perm.tolist()) == list(range(len(theirs))), (ours, theirs)
    np.testing.assert_allclose(ours, theirs[perm], atol=atol)
    return perm


# --- references --------------------------------------------------------------------------------


def _cell_reference(points: np.ndarray) -> np.ndarray:
    """Cells of a 16 x 16 grid over the bounding square in Z order, bits interleaved one by one (x even, y odd)."""
    low = points.min(axis=0)
    span = np.float32((points.max(axis=0) - low).max())
    cells = np.clip(np.floor((points - low) * (np.float32(16) / span)), 0, 15).astype(np.int64)
    return sum((((cells[:, 0] >> b) & 1) << (2 * b)) | (((cells[:, 1] >> b) & 1) << (2 * b + 1)) for b in range(4))


def _seed_reference(points: np.ndarray, weights: np.ndarray, num_seeds: int) -> np.ndarray:
    """Weighted centroids of the cells at the systematic positions of the weight CDF over cells in Z order."""
    cells = _cell_reference(points)
    w = weights.astype(np.float64)
    mass = np.bincount(cells, weights=w, minlength=256)
    cdf = np.cumsum(mass)
    picked = np.searchsorted(cdf, (np.arange(num_seeds) + 0.5) * cdf[-1] / num_seeds, side="right")
    centroids = np.stack([np.bincount(cells, weights=w * points[:, d], minlength=256) for d in range(2)], axis=1)
    return centroids[picked] / mass[picked, None]


def _gaussian_mean_shift_reference(points, weights, bandwidth, num_seeds, max_clusters, num_iters, radius):
    """Float64 brute force of the documented algorithm: seeds, steps, greedy merge, heaviest basins, labels."""
    p = points.astype(np.float64)
    w = weights.astype(np.float64)
    x = _seed_reference(points, weights, num_seeds)
    for _ in range(num_iters):
        k = np.exp(-0.5 * np.sum((x[:, None, :] - p[None, :, :]) ** 2, axis=-1) / bandwidth**2) * w[None, :]
        density = k.sum(axis=1)
        x = (k @ p) / density[:, None]
    order = sorted(range(num_seeds), key=lambda i: (-density[i], i))
    kept: list[int] = []
    for i in order:
        if all(np.linalg.norm(x[i] - x[j]) > radius for j in kept):
            kept.append(i)
    owner = [min(kept, key=lambda j: (np.linalg.norm(x[i] - x[j]), j)) for i in range(num_seeds)]
    score = {j: owner.count(j) + 0.5 * density[j] / density.max() for j in kept}
    top = sorted(kept, key=lambda j: (-score[j], j))[:max_clusters]
    centres = x[top]
    labels = np.argmin(np.sum((p[:, None, :] - centres[None, :, :]) ** 2, axis=-1), axis=1)
    return centres, labels, np.bincount(labels, weights=w, minlength=len(top))


# --- mean shift ----------------------------------------------------------------------------------


def test_seeds_are_cell_centroids_spread_over_the_weight(rng):
    points, which = blobs(rng)
    weights = rng.gamma(0.5, size=N).astype(np.float32)
    weights[::7] = 0.0
    seeds = np.asarray(_flat(jnp.asarray(points), jnp.asarray(weights), jnp.float32(0.5))[0])
    np.testing.assert_allclose(seeds, _seed_reference(points, weights, SEEDS), atol=1e-5)
    # Each blob covers consecutive cells in Z order, so it gets about SEEDS times its share of the weight.
    shares = np.bincount(which, weights=weights) / weights.sum()
    nearest_blob = np.argmin(np.linalg.norm(seeds[:, None, :] - CENTRES[None], axis=-1), axis=1)
    assert np.all(np.abs(np.bincount(nearest_blob, minlength=3) - SEEDS * shares) <= 2)


@pytest.mark.parametrize("data_seed", [0, 1])
def test_flat_kernel_matches_sklearn_mean_shift(data_seed):
    sklearn_cluster = pytest.importorskip("sklearn.cluster")
    rng = np.random.default_rng(data_seed)
    points, _ = blobs(rng)
    counts = rng.integers(1, 4, size=N)
    bandwidth = 0.6  # smaller than the blobs: seeds stop at several local modes that the merge joins
    _, ours = _flat(jnp.asarray(points), jnp.asarray(counts, jnp.float32), jnp.float32(bandwidth))

    seeds = _seed_reference(points, counts.astype(np.float32), SEEDS)
    repeated = np.repeat(points.astype(np.float64), counts, axis=0)
    ref = sklearn_cluster.MeanShift(bandwidth=bandwidth, seeds=seeds, cluster_all=True).fit(repeated)

    valid = np.asarray(ours.valid)
    assert valid.sum() == len(ref.cluster_centers_) >= 3
    assert np.all(valid[: valid.sum()])  # valid slots first
    assert np.all(np.asarray(ours.centres)[~valid] == 0) and np.all(np.asarray(ours.weights)[~valid] == 0)
    perm = _match(np.asarray(ours.centres)[valid], ref.cluster_centers_, atol=1e-4)
    # Labels: the same partition (the repeats of a point share its label).
    first = np.cumsum(counts) - counts
    np.testing.assert_array_equal(perm[np.asarray(ours.labels)], ref.labels_[first])
    np.testing.assert_allclose(
        np.asarray(ours.weights)[valid], np.bincount(ref.labels_, minlength=len(perm))[perm], rtol=1e-6
    )


def test_gaussian_kernel_matches_numpy_reference_under_vmap_and_grad(rng):
    data = [blobs(rng)[0] for _ in range(2)]
    weights = rng.gamma(1.0, size=(2, N)).astype(np.float32)
    bandwidths, radii = np.array([0.3, 0.35], np.float32), np.array([0.4, 0.5], np.float32)
    out, g_points, g_weights = _gaussian(np.stack(data), weights, bandwidths, radii)
    for i in range(2):
        centres, labels, cluster_weights = _gaussian_mean_shift_reference(
            data[i], weights[i], bandwidths[i], SEEDS, KEEP, ITERS, radii[i]
        )
        assert len(centres) == KEEP and np.all(out.valid[i])
        np.testing.assert_allclose(out.centres[i], centres, atol=1e-4)
        np.testing.assert_array_equal(out.labels[i], labels)
        np.testing.assert_allclose(out.weights[i], cluster_weights, rtol=1e-5)
    # Centres carry no gradient; a cluster's weight is the sum of its members' weights, so
    # d loss / d w_i is the index of point i's cluster.
    np.testing.assert_array_equal(g_points, 0.0)
    np.testing.assert_array_equal(g_weights, out.labels.astype(np.float32))


def test_mean_shift_keeps_the_heaviest_blobs(rng):
    data = [blobs(rng, std=0.3) for _ in range(2)]
    weights = rng.gamma(2.0, size=(2, N)).astype(np.float32)
    out, _, _ = _gaussian(np.stack([d[0] for d in data]), weights, [0.5, 0.5], [0.5, 0.5])
    assert out.labels.shape == (2, N) and out.centres.shape == (2, KEEP, 2) and out.weights.shape == (2, KEEP)
    for i, (_, which) in enumerate(data):
        heaviest = np.argsort(-np.bincount(which, weights=weights[i]))[:KEEP]
        np.testing.assert_allclose(out.centres[i], CENTRES[heaviest], atol=0.25)
        # Every point belongs to a kept cluster; the weights add up to the total.
        np.testing.assert_allclose(out.weights[i].sum(), weights[i].sum(), rtol=1e-5)


def test_mean_shift_zero_weights_count_as_uniform(rng):
    points, _ = blobs(rng)
    weights = np.stack([np.zeros(N, np.float32), np.ones(N, np.float32)])
    out, g_points, g_weights = _gaussian(np.stack([points, points]), weights, [0.5, 0.5], [0.5, 0.5])
    assert np.all(np.isfinite(out.centres)) and np.all(np.isfinite(g_points)) and np.all(np.isfinite(g_weights))
    np.testing.assert_array_equal(out.labels[0], out.labels[1])
    np.testing.assert_allclose(out.centres[0], out.centres[1])
    np.testing.assert_array_equal(out.weights[0], 0.0)
    np.testing.assert_allclose(out.weights[1], np.bincount(out.labels[1], minlength=KEEP))


def test_mean_shift_rejects_bad_sizes():
    p, w = jnp.zeros((4, 2)), jnp.ones(4)
    with pytest.raises(ValueError, match="^max_clusters:"):
        mean_shift(p, w, bandwidth=1.0, num_seeds=2, max_clusters=3, num_iters=1)
    with pytest.raises(ValueError, match="^kernel:"):
        mean_shift(p, w, bandwidth=1.0, num_seeds=2, max_clusters=1, num_iters=1, kernel="box")
    with pytest.raises(ValueError, match="^num_seeds:"):
        mean_shift(p, w, bandwidth=1.0, num_seeds=0, max_clusters=1, num_iters=1)
