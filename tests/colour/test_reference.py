"""The reference from a user's box (Comaniciu et al. 2003 sec. 6.2, Ning et al. 2012): the weights against the
papers' formulas, the ring and the prior against NumPy, and on frames drawn here with NumPy (not with the
package's renderer): boxes 10-40 % larger than the ball and off-centre, a blurred or differently lit reference
frame, a goal post and a line crossing in view."""

import jax
import numpy as np
import pytest

from heatpf_jax.colour.likelihood import ColourParams, colour_likelihood, window_half_sizes
from heatpf_jax.colour.reference import (
    SCALED_PARAMS,
    ReferenceOptions,
    background_weights,
    box_reference,
    corrected_background_weighted,
    ellipse_prior,
    frames_histogram,
    heaviest_bins,
    locate_object,
    reference_score,
    ring_histogram,
)
from heatpf_jax.colour.space import channel_means, exact_top_bins, histogram, num_bins, patch_histogram, rgi_bins

M = num_bins()
_map = jax.jit(colour_likelihood, static_argnames=("bins", "top_bins", "blob_window"))
# Through `jit`: run eagerly, each of their operations compiles a program of its own (per shape).
_rgi_bins = jax.jit(rgi_bins)
_histogram = jax.jit(histogram, static_argnames="num")
_patch_histogram = jax.jit(patch_histogram, static_argnames="box")
_channel_means = jax.jit(channel_means)
_window_half_sizes = jax.jit(window_half_sizes)

GRASS = np.array([58.0, 128.0, 46.0])


def _pentagon(cx, cy, size, angle, uu, vv):
    inside = np.ones(uu.shape, bool)
    for k in range(5):
        a = angle + 2 * np.pi * k / 5
        inside &= (uu - cx) * np.cos(a) + (vv - cy) * np.sin(a) <= size * np.cos(np.pi / 5)
    return inside


def draw(rng, *, ball=(30.0, 40.0, 6.0), spin=0.0, blur=0.0, post=None, lines=True, gain=1.0, tint=(1.0, 1.0, 1.0),
         shape=(60, 80)):
    """A frame: mown, textured grass, a white line across and one along (crossing), optionally a white post
    (``(column, half-width)``, standing on row 36 and going out of the top), and a white ball ``(row, column,
    radius)`` with dark pentagons, drawn 4 x 4 supersampled; ``blur`` pixels of horizontal motion blur on the
    ball; a light of ``gain`` and ``tint``; noise."""
    h, w = shape
    ss = 4
    vv, uu = (np.mgrid[0:h * ss, 0:w * ss] + 0.5) / ss - 0.5
    stripe = (np.floor(uu / 13.0) % 2 == 0)[..., None]
    img = np.where(stripe, GRASS, GRASS * 0.88) * (1.0 + 0.06 * np.sin(uu * 1.3) * np.cos(vv * 0.7))[..., None]
    if lines:
        line = (np.abs(vv - 0.72 * h) < 0.9) | (np.abs(uu - 0.2 * w - 0.3 * vv) < 0.9)
        img = np.where(line[..., None], np.array([236.0, 238.0, 234.0]), img)
    if post is not None:
        bar = (np.abs(uu - post[0]) <= post[1]) & (vv <= 36.0)
        img = np.where(bar[..., None], np.array([232.0, 232.0, 230.0]), img)
    if ball is not None:
        layers = []
        for shift in np.linspace(-blur / 2, blur / 2, 7 if blur else 1):
            cy, cx, r = ball[0], ball[1] + shift, ball[2]
            disc = (uu - cx) ** 2 + (vv - cy) ** 2 <= r * r
            shade = np.clip(1.05 - 0.35 * (vv - cy + r) / (2 * r), 0.6, 1.0)[..., None]
            colour = np.array([245.0, 245.0, 241.0]) * shade
            for k in range(5):  # a centre patch and four around it
                a = spin + k * 2 * np.pi / 4
                px, py = (cx, cy) if k == 0 else (cx + 0.62 * r * np.cos(a), cy + 0.62 * r * np.sin(a))
                patch = _pentagon(px, py, 0.3 * r, a, uu, vv)[..., None]
                colour = np.where(patch, np.array([30.0, 30.0, 36.0]) * shade, colour)
            layers.append(np.where(disc[..., None], colour, img))
        img = np.mean(layers, axis=0)
    img = img.reshape(h, ss, w, ss, 3).mean(axis=(1, 3)) * gain * np.asarray(tint) + rng.normal(0, 3.0, (h, w, 3))
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def user_box(ball, scale, offset):
    """A box ``scale`` times the ball's diameter, moved by ``offset`` of the box down and to the right."""
    row, col, r = ball
    side = 2 * r * scale
    return (int(round(col - side / 2 + offset * side)), int(round(row - side / 2 + offset * side)),
            int(round(side)), int(round(side)))


def test_background_weights_and_the_corrected_model_against_the_papers_formulas(rng):
    o = rng.uniform(size=M) * (rng.uniform(size=M) < 0.3)
    o /= o.sum()
    o_star = o[o > 0].min()
    want = np.where(o > 0, np.minimum(o_star / np.where(o > 0, o, 1.0), 1.0), 1.0)  # Comaniciu et al. sec. 6.2
    np.testing.assert_allclose(background_weights(o), want, rtol=1e-5)
    floor = 0.01
    want_floor = np.where(o > 0, np.minimum(max(o_star, floor) / np.where(o > 0, o, 1.0), 1.0), 1.0)
    np.testing.assert_allclose(background_weights(o, floor), want_floor, rtol=1e-5)
    np.testing.assert_array_equal(background_weights(np.zeros(M)), np.ones(M))  # no background: unweighted
    q = rng.uniform(size=M) * (rng.uniform(size=M) < 0.2)
    q /= q.sum()
    got = np.asarray(corrected_background_weighted(q, o))  # Ning et al.: only the target model is weighted
    np.testing.assert_allclose(got, want * q / np.sum(want * q), rtol=1e-5, atol=1e-9)
    assert np.isclose(got.sum(), 1.0)


def test_ellipse_prior_and_ring_against_numpy(rng):
    prior = np.asarray(ellipse_prior(9, 13, 0.9))
    v = (np.arange(9) + 0.5 - 4.5) / (0.9 * 4.5)
    u = (np.arange(13) + 0.5 - 6.5) / (0.9 * 6.5)
    np.testing.assert_allclose(prior, np.maximum(1 - v[:, None] ** 2 - u[None, :] ** 2, 0), rtol=1e-6, atol=1e-7)
    assert prior[0, 0] == 0 and prior[4, 6] == prior.max()
    image = rng.integers(0, 256, (30, 40, 3), dtype=np.uint8)
    for box in [(10, 8, 6, 5), (0, 0, 7, 9), (35, 26, 5, 4)]:  # inside, and at two corners (the ring clipped)
        got, pixels = ring_histogram(image, box, 2.0)
        x, y, w, h = box
        mask = np.zeros((30, 40), bool)
        grow_y, grow_x = h // 2 + h % 2, w // 2 + w % 2  # half the box each side, rounded outwards
        mask[max(y - grow_y, 0):y + h + grow_y, max(x - grow_x, 0):x + w + grow_x] = True
        mask[y:y + h, x:x + w] = False
        idx = np.asarray(_rgi_bins(image))[mask]
        assert pixels == mask.sum()
        np.testing.assert_allclose(got, np.bincount(idx, minlength=M) / idx.size, rtol=1e-6)


def test_heaviest_bins():
    q = np.zeros(M)
    q[:6] = [0.4, 0.3, 0.15, 0.1, 0.03, 0.02]
    np.testing.assert_allclose(heaviest_bins(q, 0.95)[:6], np.array([0.4, 0.3, 0.15, 0.1, 0, 0]) / 0.95, rtol=1e-6)
    np.testing.assert_allclose(heaviest_bins(q, 0.99, max_bins=2)[:6], [0.4 / 0.7, 0.3 / 0.7, 0, 0, 0, 0], rtol=1e-6)
    np.testing.assert_allclose(heaviest_bins(q, 1.0), q, rtol=1e-6)


def _canvas_coefficient(q, patch, background, s, params):
    """NumPy brute force of :func:`locate_object`'s canvas: the coefficient of every window centred in the patch,
    the pixels outside it each holding the background histogram."""
    idx = np.asarray(_rgi_bins(patch))
    h, w = idx.shape
    outer = int(_window_half_sizes(float(s), params._replace(window_scale=1.0))[1])
    out = np.zeros((h, w))
    for v in range(h):
        for u in range(w):
            counts = {}
            b = int(min(max(np.round(np.float32(params.window_waist) * np.float32(s)), 0), s))
            n = {}
            for name, half, arm in (("in", s, b), ("out", outer, outer)):
                c = np.zeros(M)
                rows, cols = np.mgrid[v - half:v + half + 1, u - half:u + half + 1]
                window = (np.abs(rows - v) <= arm) | (np.abs(cols - u) <= arm)  # the cross (a square for the ring)
                inside = (rows >= 0) & (rows < h) & (cols >= 0) & (cols < w)
                np.add.at(c, idx[rows[inside & window], cols[inside & window]], 1.0)
                counts[name] = c + (~inside & window).sum() * background
                n[name] = window.sum()
            n_in, n_out = n["in"], n["out"]
            p_obj = counts["in"] / n_in
            p_bck = (counts["out"] - counts["in"]) / (n_out - n_in)
            out[v, u] = np.sum(np.sqrt(q) * np.maximum(np.sqrt(p_obj) - np.sqrt(np.maximum(p_bck, 0)), 0))
    return out


@pytest.mark.parametrize("waist", [1.0, 0.618])
def test_locate_object_against_brute_force(rng, waist):
    ball = (9.0, 12.0, 4.0)
    frame = draw(rng, ball=ball, shape=(20, 26), lines=False)
    box = (6, 3, 12, 12)  # larger than the ball and off-centre
    background, _ = ring_histogram(frame, box)
    patch = frame[3:15, 6:18]
    q = np.asarray(corrected_background_weighted(_histogram(_rgi_bins(patch), M), background))
    q = q * (q >= np.sort(q)[-exact_top_bins(q)])  # the bins locate_object's tables hold
    q /= q.sum()
    params = ColourParams(window_waist=waist)
    fit = locate_object(q, patch, background, params)
    best = max(((s, _canvas_coefficient(q, patch, np.asarray(background), s, params)) for s in range(1, 7)),
               key=lambda sr: sr[1].max())
    assert fit.score == pytest.approx(best[1].max(), rel=1e-4)
    assert (fit.row, fit.col) == np.unravel_index(np.argmax(best[1]), best[1].shape)
    assert fit.radius == pytest.approx(best[0] / params.window_scale)
    assert abs(fit.row + 3 - ball[0]) <= 1 and abs(fit.col + 6 - ball[1]) <= 1  # at the ball
    assert reference_score(q, patch, background, params) == fit.score


@pytest.mark.parametrize("scale, offset", [(1.1, 0.0), (1.25, 0.25), (1.4, 0.0), (1.4, 0.25)])
def test_the_background_loses_weight_whatever_the_box_holds(rng, scale, offset):
    ball = (30.0, 40.0, 6.0)
    frame = draw(rng, ball=ball, post=(57.0, 2.5))
    box = user_box(ball, scale, offset)
    plain = np.asarray(_patch_histogram(frame, box))
    grass = np.asarray(_rgi_bins(frame[3:12, 3:12])).ravel()  # grass only, away from lines, post and ball
    grass_bins = np.unique(grass)
    ref = box_reference(frame, box, ReferenceOptions(intensity_smoothing=0.0, chroma_smoothing=0.0))
    model = np.asarray(ref.histogram)
    assert plain[grass_bins].sum() > 0.15  # the box holds grass ...
    assert model[grass_bins].sum() < 0.02  # ... the reference does not
    x, y, w, h = ref.box  # the object's box: the ball's, within a pixel
    assert abs(x + w / 2 - 0.5 - ball[1]) <= 1.0 and abs(y + h / 2 - 0.5 - ball[0]) <= 1.0
    assert abs(w / 2 - ball[2]) <= 0.25 * ball[2] + 0.5


@pytest.mark.parametrize("reference", ["tight", "larger", "off-centre", "blurred", "yellow light"])
def test_maps_are_near_one_at_the_ball_and_low_elsewhere(rng, reference):
    """The reference taken the way a user takes it; another frame with the ball elsewhere, turned, under a
    darker and yellower light, beside a goal post and a line crossing: the map at the ball near 1, the post,
    the lines and a frame without the ball below the filter's threshold (0.3)."""
    ball = (30.0, 40.0, 6.0)
    kwargs = {"tight": {}, "larger": {"scale": 1.4}, "off-centre": {"scale": 1.25, "offset": 0.25},
              "blurred": {"blur": 4.0}, "yellow light": {"gain": 0.85, "tint": (1.05, 1.0, 0.8)}}[reference]
    scale, offset = kwargs.pop("scale", 1.1), kwargs.pop("offset", 0.0)
    frame0 = draw(rng, ball=ball, post=(70.0, 2.5), **kwargs)
    params = SCALED_PARAMS
    ref = box_reference(frame0, user_box(ball, scale, offset), params=params)
    params = params._replace(reference_score=ref.score)
    white = _channel_means(frame0)
    half = np.full((60, 80), ball[2], np.float32)

    def heat(image):
        return np.asarray(_map(image, ref.histogram, half, params, top_bins=exact_top_bins(ref.histogram),
                               white=white))

    own = heat(frame0)
    assert own.max() > 0.9  # the reference's own frame: its object at about 1
    other = (44.0, 18.0, 6.0)
    frame = draw(rng, ball=other, spin=0.5, post=(30.0, 2.5), gain=0.8, tint=(1.06, 1.0, 0.85))
    got = heat(frame)
    vv, uu = np.mgrid[0:60, 0:80]
    near = (vv - other[0]) ** 2 + (uu - other[1]) ** 2 <= (1.5 * other[2]) ** 2
    assert got[near].max() > 0.6, got[near].max()
    assert got[~near].max() < 0.3, got[~near].max()  # the post (a white bar as wide as the ball) and the lines
    peak = np.unravel_index(np.argmax(np.where(near, got, 0)), got.shape)
    assert abs(peak[0] - other[0]) <= 1.5 and abs(peak[1] - other[1]) <= 1.5
    empty = draw(rng, ball=None, post=(30.0, 2.5), gain=0.9)
    assert heat(empty).max() < 0.3


def test_a_box_in_a_frame_and_that_box_as_an_image_agree(rng):
    """With the same background and the object inside the box, a box in a frame and the box saved as an image
    give the same reference (the same model, the same own score)."""
    ball = (30.0, 40.0, 6.0)
    frame = draw(rng, ball=ball)
    box = user_box(ball, 1.6, 0.0)
    background = frames_histogram(frame[None])
    a = box_reference(frame, box, background=background)
    x, y, w, h = box
    b = box_reference(frame[y:y + h, x:x + w], (0, 0, w, h), background=background)
    np.testing.assert_allclose(a.histogram, b.histogram, atol=1e-7)
    assert a.score == pytest.approx(b.score, rel=1e-6)
    assert (a.box[0] - x, a.box[1] - y, *a.box[2:]) == b.box
