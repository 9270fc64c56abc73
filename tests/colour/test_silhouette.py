"""The ball's outline in a colour map: object probabilities, exact disc means against a NumPy brute force, the
silhouette score's peak and its answer to a post, and the maps that combine it with the histogram's."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from heatpf_jax.colour.likelihood import ColourParams, colour_likelihood
from heatpf_jax.colour.reference import ReferenceOptions, box_reference
from heatpf_jax.colour.silhouette import (
    chromaticity_probability,
    disc_means,
    object_probability,
    reference_silhouette,
    silhouette_prior,
    silhouette_score,
    window_max,
)
from heatpf_jax.colour.space import num_bins, patch_histogram, rgi_bins
from tests.colour.test_likelihood import _scene as scene

_disc_means = jax.jit(disc_means)
_score = jax.jit(silhouette_score, static_argnames=("outer",))
_window_max = jax.jit(window_max, static_argnames=("bound",))
_likelihood = jax.jit(colour_likelihood, static_argnames=("bins", "top_bins", "blob_window"))


def _brute_means(values, radius, outer):
    """Disc and annulus means at every pixel over the image's pixels, by masks."""
    h, w = values.shape
    vv, uu = np.mgrid[:h, :w]
    disc, ring = np.zeros((h, w)), np.zeros((h, w))
    for v in range(h):
        for u in range(w):
            d2 = (vv - v) ** 2 + (uu - u) ** 2
            inside = d2 <= radius[v, u] ** 2
            annulus = (d2 > radius[v, u] ** 2) & (d2 <= outer[v, u] ** 2)
            disc[v, u] = values[inside].mean() if inside.any() else 0.0
            ring[v, u] = values[annulus].mean() if annulus.any() else 0.0
    return disc, ring


def test_object_probability_is_bayes_rule():
    rng = np.random.default_rng(3)
    q = rng.uniform(size=40) * (rng.uniform(size=40) < 0.5)
    o = rng.uniform(size=40) * (rng.uniform(size=40) < 0.7)
    got = object_probability(q, o, 0.2, 300.0)
    qn, on = q / q.sum(), o / o.sum()
    want = 0.2 * qn / (0.2 * qn + 0.8 * (on + 1.0 / 300.0))
    np.testing.assert_allclose(got, want, rtol=1e-6)
    assert np.all(got[q == 0] == 0.0) and got.max() < 1.0
    # No background known: every colour of the object is as likely as one unseen pixel allows.
    np.testing.assert_allclose(object_probability(q, np.zeros(40), 0.2, 300.0)[q > 0],
                               (0.2 * qn / (0.2 * qn + 0.8 / 300.0))[q > 0], rtol=1e-6)
    assert silhouette_prior(2.0) == pytest.approx(np.pi / 16.0)
    with pytest.raises(ValueError, match="prior"):
        object_probability(q, o, 1.0, 300.0)


def test_chromaticity_probability_is_bayes_rule_on_the_chromaticity():
    """The model and the background summed over the intensity bins (the intensity varies fastest in a bin's
    index), Bayes' rule on those sums, every intensity bin of a chromaticity given its value."""
    rng = np.random.default_rng(5)
    bins = (3, 4, 5)
    q = rng.uniform(size=60) * (rng.uniform(size=60) < 0.4)
    o = rng.uniform(size=60) * (rng.uniform(size=60) < 0.6)
    got = chromaticity_probability(q, o, 0.2, 300.0, bins)
    for i_r in range(3):
        for i_g in range(4):
            index = [(i_r * 4 + i_g) * 5 + i_i for i_i in range(5)]
            qc, oc = q[index].sum() / q.sum(), o[index].sum() / o.sum()
            want = 0.2 * qc / (0.2 * qc + 0.8 * (oc + 1.0 / 300.0)) if qc > 0 else 0.0
            np.testing.assert_allclose(got[index], want, rtol=1e-6)


def test_window_max_against_brute_force():
    """Per-pixel squares of every half-size up to the bound (and beyond it, clipped), cut by the borders."""
    rng = np.random.default_rng(6)
    for shape, bound in (((19, 27), 8), ((33, 14), 16)):
        values = rng.uniform(size=shape).astype(np.float32)
        half = rng.uniform(-1.0, bound + 3.0, size=shape).astype(np.float32)
        got = np.asarray(_window_max(values, half, bound=bound))
        want = np.zeros(shape)
        for v in range(shape[0]):
            for u in range(shape[1]):
                r = int(np.clip(np.round(half[v, u]), 0, bound))
                want[v, u] = values[max(v - r, 0):v + r + 1, max(u - r, 0):u + r + 1].max()
        np.testing.assert_array_equal(got, want)


def test_disc_means_against_brute_force():
    rng = np.random.default_rng(0)
    values = rng.uniform(size=(17, 23)).astype(np.float32)
    radius = rng.uniform(0.0, 5.0, size=(17, 23)).astype(np.float32)
    radius[3:6, 4:9] = 0.0  # a disc of the pixel alone, its annulus empty
    outer = (1.5 * radius).astype(np.float32)
    disc, ring = _disc_means(values, radius, outer)
    want_disc, want_ring = _brute_means(values, radius, outer)
    np.testing.assert_allclose(disc, want_disc, atol=2e-5)
    np.testing.assert_allclose(ring, want_ring, atol=2e-5)
    # Only the pixels asked for: the rows summed follow their largest radius, and their means stay exact.
    where = np.zeros((17, 23), bool)
    where[8:12, 2:20] = True
    small = np.where(where, np.minimum(radius, 2.0), radius).astype(np.float32)
    disc, ring = _disc_means(values, small, 1.5 * small, where)
    want_disc, want_ring = _brute_means(values, small, 1.5 * small)
    np.testing.assert_allclose(np.asarray(disc)[where], want_disc[where], atol=2e-5)
    np.testing.assert_allclose(np.asarray(ring)[where], want_ring[where], atol=2e-5)


def test_the_score_peaks_at_the_ball_and_a_post_scores_less():
    """A disc of object pixels scores highest at its centre and falls off with the distance (a cone, not a
    plateau); a bar as wide as the ball and cut by the image's top border scores well below it."""
    h, w, r = 40, 60, 5.0
    vv, uu = np.mgrid[:h, :w]
    p = np.zeros((h, w), np.float32)
    p[(vv - 24) ** 2 + (uu - 18) ** 2 <= r * r] = 0.95
    p[0:14, 40:51] = 0.95  # a post, 11 px wide, from the top border down
    s = np.asarray(_score(p, np.full((h, w), r, np.float32)))
    assert np.unravel_index(np.argmax(s[:, :32]), (h, 32)) == (24, 18)
    profile = s[24, 18:24]
    assert np.all(np.diff(profile) < 0)  # every pixel off the centre costs
    assert s[:, 34:].max() < 0.75 * s[24, 18]


def test_reference_silhouette_is_the_best_score_of_its_canvas():
    """The reference's own score (NumPy masks on a canvas) against the maps' score (row prefix sums) of that
    canvas, at the box's pixels."""
    rng = np.random.default_rng(1)
    box = rng.uniform(0.0, 1.0, size=(9, 9))
    box[(np.mgrid[:9, :9][0] - 4) ** 2 + (np.mgrid[:9, :9][1] - 4) ** 2 <= 16] = 0.9
    pad = 8
    canvas = np.full((9 + 2 * pad, 9 + 2 * pad), 0.05, np.float32)
    canvas[pad:pad + 9, pad:pad + 9] = box
    s = np.asarray(_score(canvas, np.full(canvas.shape, 4.0, np.float32)))
    got = reference_silhouette(box, 0.05, 4.0)
    assert got == pytest.approx(float(s[pad:pad + 9, pad:pad + 9].max()), abs=1e-5)
    assert got > 0.5


def _scene(rng, centre=(20, 22)):
    return scene(rng, h=40, w=48, centre=centre, radius=5.0)


def _brute_shape(score, half, s_ref):
    """``1 - c + c S+ / S_max``, ``c = min(S_max / S_ref, 1)``: ``S_max`` the largest ``S+`` over the square of
    half-size ``half`` (masks)."""
    h, w = score.shape
    s = np.maximum(score, 0.0)
    r = half.astype(int)
    best = np.array([[s[max(v - r[v, u], 0):v + r[v, u] + 1, max(u - r[v, u], 0):u + r[v, u] + 1].max()
                      for u in range(w)] for v in range(h)])
    clear = np.clip(best / s_ref, 0.0, 1.0)
    return 1.0 - clear + clear * s / np.maximum(best, 1e-6)


def test_maps_with_the_outline_against_their_parts():
    """``H * (1 - c + c S+ / S_max)``, ``c = min(S_max / S_ref, 1)``: the histogram map without the outline, a
    brute-force silhouette score of the chromaticity's object probabilities and a brute-force window maximum (one
    window size: every response's centroid has the same radius), with the reference's own score, with one below the
    frame's (the outline as clear as the reference's: its cone alone) and with one far above it (a faint outline
    hardly reshapes the histogram's map)."""
    rng = np.random.default_rng(2)
    image = _scene(rng)
    ref = box_reference(image, (16, 14, 13, 13), ReferenceOptions(), ColourParams(window_scale=0.8))
    assert ref.silhouette is not None and ref.silhouette.shape == (num_bins(),) and ref.silhouette_score > 0.3
    idx = np.asarray(rgi_bins(image))
    assert ref.silhouette[idx[20, 22]] > 0.8 and ref.silhouette[idx[3, 3]] < 0.05  # the ball's white; grass
    half = np.full(image.shape[:2], 5.0, np.float32)
    q = jnp.asarray(ref.histogram)
    disc, ring = _brute_means(ref.silhouette[idx].astype(np.float64), half, 1.5 * half)
    for s_ref in (ref.silhouette_score, 4.0 * ref.silhouette_score, 0.5 * ref.silhouette_score):
        params = ColourParams(window_scale=0.8, reference_score=ref.score, silhouette_score=s_ref)
        plain = np.asarray(_likelihood(image, q, half, params))
        got = np.asarray(_likelihood(image, q, half, params, object_probability=ref.silhouette))
        want = plain * _brute_shape(disc - ring, half, s_ref)
        np.testing.assert_allclose(got, want, atol=2e-5)
        assert np.unravel_index(np.argmax(got), got.shape) == (20, 22) and got.max() > 0.6
        assert np.all(got <= plain + 1e-6)  # the outline never raises the histogram's value
        # The outline's best point keeps the histogram's value.
        assert got[20, 22] == pytest.approx(plain[20, 22], abs=1e-6)
    assert (disc - ring).max() > s_ref  # the last case: the frame's outline clearer than the reference's
    # A frame without the ball: nothing.
    empty = np.asarray(_likelihood(_scene(rng, centre=(-30, -30)), q, half, params,
                                   object_probability=ref.silhouette))
    assert empty.max() < 0.1


def test_a_reference_image_of_the_ball_alone_scores_its_outline():
    """A box cut to the ball (its corners grass) and taken by itself, with a background histogram given."""
    rng = np.random.default_rng(4)
    image = _scene(rng)
    patch = image[14:27, 16:29]
    grass = np.asarray(patch_histogram(image, (0, 0, 10, 10)))
    ref = box_reference(patch, (0, 0, 13, 13), ReferenceOptions(), ColourParams(window_scale=0.8), background=grass)
    assert ref.silhouette_score > 0.3
