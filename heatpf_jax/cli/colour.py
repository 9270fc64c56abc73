"""``heatpf colour``: RGB frames -> colour-likelihood heat maps (Olufs et al. eq. 1-3), a sequence every method runs on.

::

    heatpf colour IN.npz --reference BALL.png [--box x,y,w,h] --output OUT.npz
    heatpf colour IN.npz --box x,y,w,h --frame N --output OUT.npz

The reference comes from a box in frame ``N`` of the input's own ``images``, or from an image of the object
(PNG/JPEG through Pillow, ``pip install 'heatpf-jax[rgb]'``, or a ``.npy`` ``uint8 [h, w, 3]``), in ``--box`` if
given; an image that is a box of one of the input's frames (a PNG cut out of a frame, or a JPEG of it) is taken as
that box in that frame (:func:`heatpf_jax.colour.crop.find_crop`), with a printed line. The box may hold background
(a box around a ball holds grass in its corners, more when drawn loosely or off-centre):
:func:`heatpf_jax.colour.reference.box_reference` finds the object in it and weights down the colours of the
background (the ring around the box, or for an image of the object the input's frames; ``--background``). The maps
are divided by the reference's own score, so that the object as it looks in the reference is at about 1 and the
filters' default threshold applies, and every frame is brought under the reference's light first. ``OUT.npz`` is the
input with ``heatmaps`` replaced by the colour likelihood (:func:`colour_sequence`,
:func:`heatpf_jax.colour.likelihood.colour_heatmaps`). Every argument is checked before any computation; an existing
``OUT.npz`` is replaced only with ``--force``, and never the input.
"""

from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from heatpf_jax.io.files import check_input, check_output

__all__ = ["add_parser", "cmd_colour", "colour_sequence", "read_reference_image"]


_WINDOW_SCALE = 0.8  # colour.reference.SCALED_PARAMS.window_scale (tests/cli/test_colour.py checks they agree)
_LOW_SCORE = 0.2  # below this, a warning: grass-only boxes scored 0.11-0.25, balls 0.26-0.66 (colour_user_box.py)


def _parse_box(text: str) -> tuple[int, int, int, int]:
    parts = text.split(",")
    try:
        box = tuple(int(p) for p in parts)
    except ValueError:
        box = ()
    if len(box) != 4:
        raise ValueError(f"--box: expected x,y,w,h (four integers, pixels), got {text!r}")
    if box[2] < 1 or box[3] < 1:
        raise ValueError(f"--box: width and height must be positive, got {text!r}")
    return box


def _check_box(box, shape: tuple[int, int], where: str) -> None:
    x, y, w, h = box
    if x < 0 or y < 0 or x + w > shape[1] or y + h > shape[0]:
        raise ValueError(f"--box: {x},{y},{w},{h} is not inside {where} ({shape[1]} x {shape[0]} pixels)")


def read_reference_image(path: str | Path) -> np.ndarray:
    """A reference image as ``uint8 [h, w, 3]`` RGB: PNG/JPEG (Pillow) or ``.npy``.

    Raises:
        ValueError: one line naming ``--reference`` and the problem.
    """
    path = check_input(path)
    if path.suffix.lower() == ".npy":
        try:
            image = np.load(path, allow_pickle=False)
        except (ValueError, OSError) as err:
            raise ValueError(f"--reference: {path}: not a readable .npy array ({err})") from None
    else:
        try:
            from PIL import Image, UnidentifiedImageError
        except ImportError:
            raise ValueError("--reference: reading PNG/JPEG needs Pillow (pip install 'heatpf-jax[rgb]'), "
                             "or give a .npy uint8 [h, w, 3]") from None
        try:
            with Image.open(path) as img:
                image = np.asarray(img.convert("RGB"))
        except (UnidentifiedImageError, OSError) as err:
            raise ValueError(f"--reference: {path}: not a readable image ({err})") from None
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3 or min(image.shape[:2]) < 1:
        raise ValueError(f"--reference: {path}: expected uint8 [h, w, 3] RGB, got {image.dtype} {image.shape}")
    return image


def colour_sequence(
    seq,
    *,
    box: tuple[int, int, int, int] | None = None,
    frame: int | None = None,
    reference_image: np.ndarray | None = None,
    background: str = "auto",
    options=None,
    params=None,
    timings: dict[str, float] | None = None,
    silhouette: bool = True,
):
    """``heatpf colour`` as a function: the sequence with its ``heatmaps`` replaced by colour maps.

    The reference is the object in ``box`` of frame ``frame`` of ``seq.images``, or in ``reference_image``
    (in ``box`` of it, or the whole of it), taken by :func:`heatpf_jax.colour.reference.box_reference`; the maps
    (:func:`heatpf_jax.colour.likelihood.colour_heatmaps`) are divided by the reference's own score.

    Args:
        seq: a :class:`~heatpf_jax.io.sequence.Sequence` with ``images``.
        box: ``(x, y, width, height)``, pixels.
        frame: the frame of ``seq.images`` holding ``box`` (then no ``reference_image``).
        reference_image: ``uint8 [h, w, 3]`` an image of the object.
        background: where the background histogram comes from: ``"ring"`` (around the box, in the image it is
            in), ``"frames"`` (:func:`~heatpf_jax.colour.reference.frames_histogram` of ``seq.images``),
            ``"none"`` (no background weighting), ``"auto"``: the ring for a box in a frame, the frames for
            a reference image (it has no known surroundings).
        options: :class:`~heatpf_jax.colour.reference.ReferenceOptions` (default: its defaults).
        params: :class:`~heatpf_jax.colour.likelihood.ColourParams` (its ``reference_score`` is replaced;
            default :data:`~heatpf_jax.colour.reference.SCALED_PARAMS`).
        timings: a dict that receives the seconds of ``"reference"`` (taking it), ``"compile"`` (compiling the
            maps' program, or loading it from JAX's persistent cache) and ``"maps"`` (computing them).
        silhouette: shape the histogram maps by the ball's outline (:mod:`heatpf_jax.colour.silhouette`, the
            reference's ``silhouette`` and ``silhouette_score``; the default, as ``heatpf colour``'s); ``False``
            keeps the histogram maps alone (``heatpf colour --no-silhouette``). A reference with no silhouette
            score (0) keeps them alone too.

    Returns:
        ``(sequence, reference)``: the new sequence (activations in ``[0, 1]``) and the
        :class:`~heatpf_jax.colour.reference.Reference` it was made with. The sequence's ``settings`` carry
        :data:`~heatpf_jax.colour.likelihood.MAP_SETTINGS` (``source=pixels``: a colour blob's size is the window's,
        not the ball's), which ``heatpf run`` applies; in Python pass them on yourself
        (:func:`heatpf_jax.cli.settings.parse_settings` turns them into options).
    """
    from heatpf_jax.colour.likelihood import MAP_SETTINGS, colour_heatmaps
    from heatpf_jax.colour.reference import SCALED_PARAMS, ReferenceOptions, box_reference, frames_histogram
    from heatpf_jax.colour.space import channel_means, exact_top_bins

    options = ReferenceOptions() if options is None else options
    params = SCALED_PARAMS if params is None else params
    if (reference_image is None) == (frame is None):
        raise ValueError("--reference: give a reference image, or --box x,y,w,h with --frame N (a box in a frame)")
    image = seq.images[frame] if reference_image is None else reference_image
    box = (0, 0, image.shape[1], image.shape[0]) if box is None else tuple(int(v) for v in box)
    if background == "auto":
        background = "ring" if reference_image is None else "frames"
    if background not in ("ring", "frames", "none"):
        raise ValueError(f"--background: expected auto, ring, frames or none, got {background!r}")
    options = options._replace(background=background != "none")
    if background == "frames":
        # Thousands of times more pixels than a ring: the paper's o* (the rarest colour seen) would weigh every
        # colour seen anywhere (a ball's white in the field lines) down to nothing beside the colours never
        # seen. A ring's resolution instead, one pixel in a ring three times the box's area.
        options = options._replace(floor=max(options.floor, 1.0 / ((options.ring**2 - 1.0) * box[2] * box[3])))
    timings = {} if timings is None else timings
    start = time.perf_counter()
    histogram = frames_histogram(seq.images) if background == "frames" else None
    ref = box_reference(image, box, options, params, background=histogram)
    if not ref.score > 0.0:
        raise ValueError(f"{'--box' if reference_image is None else '--reference'}: the object's colours do not stand "
                         "out from the background around it (its own score is 0); take the box around the object")
    params = params._replace(reference_score=ref.score)
    outline = None
    if silhouette and ref.silhouette is not None and ref.silhouette_score > 0.0:
        params = params._replace(silhouette_score=ref.silhouette_score)
        outline = ref.silhouette
    # The reference's light: its frame's, or for an image of the object (whose own means are the object's) the
    # input's; every frame is brought under it.
    white = channel_means(image if reference_image is None else seq.images[_spread(seq.num_steps)])
    # One program for any number of frames: _CHUNK_FRAMES frames to a call (lax.map inside), the last call's chunk
    # padded with its last frame. Compiled ahead so that its time is known apart; JAX's persistent cache then serves
    # it to every later file of these image and reference sizes, whatever its length.
    chunks = _chunks(seq.num_steps, _CHUNK_FRAMES)
    top_bins = exact_top_bins(ref.histogram)  # exact: every bin the reference fills
    timings["reference"] = time.perf_counter() - start
    start = time.perf_counter()
    first = _chunk_args(seq, chunks[0], ref.histogram, params)
    program = colour_heatmaps.lower(*first, top_bins=top_bins, white=white, object_probability=outline).compile()
    timings["compile"] = time.perf_counter() - start
    start = time.perf_counter()
    heat = np.concatenate([
        np.asarray(program(*_chunk_args(seq, frames, ref.histogram, params), white=white, object_probability=outline))
        for frames in chunks])[:seq.num_steps]
    timings["maps"] = time.perf_counter() - start
    if not np.all(np.isfinite(heat)):
        raise RuntimeError("the colour likelihood produced a non-finite value; please report this")
    return seq._replace(heatmaps=np.clip(heat, 0.0, 1.0).astype(np.float32),
                        settings={**(seq.settings or {}), **MAP_SETTINGS}), ref


# Frames per call of the colour maps' program in colour_sequence: one compiled program serves inputs of any length (the
# last call pads at most 7 frames: 7 maps of 15-37 ms each on the 2-core development machine).
_CHUNK_FRAMES = 8


def _chunks(num: int, size: int) -> list[np.ndarray]:
    """The frame indices of each call, ``size`` to a call, the last one padded with its last frame."""
    return [np.minimum(np.arange(begin, begin + size), num - 1) for begin in range(0, num, size)]


def _chunk_args(seq, frames: np.ndarray, histogram, params):
    """:func:`~heatpf_jax.colour.likelihood.colour_heatmaps`' arguments for the frames ``frames`` of ``seq``."""
    return (seq.images[frames], histogram, seq.intrinsics, np.asarray(seq.cam_to_base)[frames], seq.ball_radius,
            params)


def _spread(num: int, count: int = 8) -> np.ndarray:
    """``count`` frame indices spread evenly over ``num`` frames."""
    return np.unique(np.linspace(0, num - 1, max(min(count, num), 1)).round().astype(int))


def cmd_colour(args: argparse.Namespace) -> int:
    from heatpf_jax.colour.crop import find_crop, frame_box
    from heatpf_jax.colour.likelihood import MAP_SETTINGS
    from heatpf_jax.colour.reference import SCALED_PARAMS, ReferenceOptions
    from heatpf_jax.io.sequence import load_sequence, save_sequence

    check_input(args.input)
    out = check_output("--output", args.output, inputs=[args.input], replace=args.force)
    box = None if args.box is None else _parse_box(args.box)
    if args.reference is None and (box is None or args.frame is None):
        raise ValueError("--reference: give a reference image, or --box x,y,w,h with --frame N (a box in a frame)")
    if args.reference is not None and args.frame is not None:
        raise ValueError("--frame: applies to a box in the input's frames, not to --reference")
    if not 0.0 <= args.theta < 1.0:
        raise ValueError(f"--theta: must lie in [0, 1), got {args.theta}")
    if not args.window_scale > 0.0:
        raise ValueError(f"--window-scale: must be positive, got {args.window_scale}")
    if not 0.0 <= args.window_waist <= 1.0:
        raise ValueError(f"--window-waist: must lie in [0, 1], got {args.window_waist}")
    if not 0.0 <= args.smoothing < 0.5:
        raise ValueError(f"--smoothing: must lie in [0, 0.5), got {args.smoothing}")
    if not 0.0 <= args.chroma_smoothing < 0.5:
        raise ValueError(f"--chroma-smoothing: must lie in [0, 0.5), got {args.chroma_smoothing}")
    reference_image = None if args.reference is None else read_reference_image(args.reference)
    if reference_image is not None and box is not None:
        _check_box(box, reference_image.shape[:2], f"the reference image {args.reference}")
    seq = load_sequence(args.input)
    if seq.images is None:
        raise ValueError(f"{args.input}: images: missing; heatpf colour needs RGB frames (key images, "
                         "uint8 [T, H, W, 3])")
    if reference_image is None:
        if not 0 <= args.frame < seq.num_steps:
            raise ValueError(f"--frame: must be in [0, {seq.num_steps - 1}], got {args.frame}")
        _check_box(box, seq.images.shape[1:3], f"frame {args.frame}")
    options = ReferenceOptions(intensity_smoothing=args.smoothing, chroma_smoothing=args.chroma_smoothing)
    params = SCALED_PARAMS._replace(theta=args.theta, window_scale=args.window_scale, window_waist=args.window_waist)
    frame = args.frame
    crop = None if reference_image is None else find_crop(seq.images, reference_image)
    if crop is not None:  # the image is a box of one of the frames: the reference is that box's, in its frame
        h, w = reference_image.shape[:2]
        box, frame, reference_image = frame_box(crop, (0, 0, w, h) if box is None else box), crop.frame, None
        how = "pixel for pixel" if crop.rms == 0.0 else f"to within {crop.rms:.1f} grey levels RMS (a lossy copy)"
        print(f"--reference: {args.reference} is the box {crop.x},{crop.y},{w},{h} of frame {crop.frame}, {how}: the "
              "reference is taken there, as with --box and --frame")
    timings: dict[str, float] = {}
    colour, ref = colour_sequence(seq, box=box, frame=frame, reference_image=reference_image,
                                  background=args.background, options=options, params=params, timings=timings,
                                  silhouette=args.silhouette)
    save_sequence(out, colour)
    heat = colour.heatmaps
    where = f"frame {frame}" if reference_image is None else str(args.reference)
    source = {"ring": f"the ring around it in {where}", "frames": "the input's frames",
              "none": "none (not weighted)"}[_background_kind(args.background, reference_image)]
    print(f"reference: the object's box {','.join(map(str, ref.box))} in {where} (from the box "
          f"{','.join(map(str, box)) if box else 'the whole image'}); background: {source}; "
          f"{int(np.count_nonzero(np.asarray(ref.histogram)))} bins; its own score {ref.score:.3f} (activation 1)")
    if not args.silhouette:
        print("maps: the colour histograms alone (--no-silhouette)")
    elif ref.silhouette_score > 0.0:
        print(f"maps: the colour histograms shaped by the ball's outline (the reference's own silhouette score "
              f"{ref.silhouette_score:.3f}; --no-silhouette: the histograms alone)")
    else:
        print("maps: the colour histograms alone (the object's outline does not stand out from the background around "
              "it in the reference: its silhouette score is 0)")
    if ref.score < _LOW_SCORE:
        option = "--box" if reference_image is None else "--reference"
        warnings.warn(f"{option}: the reference's own score is low ({ref.score:.3f}; a ball in its box scores about "
                      "0.3-0.7): the box may not hold the object, or the object's colours are the background's")
    elapsed = timings["reference"] + timings["compile"] + timings["maps"]
    print(f"{args.input}: {seq.num_steps} frames of {seq.images.shape[2]} x {seq.images.shape[1]}, colour likelihood "
          f"in {elapsed:.2f} s (including compilation): reference {timings['reference']:.2f} s, compilation "
          f"{timings['compile']:.2f} s, maps {timings['maps']:.2f} s ({1000 * timings['maps'] / seq.num_steps:.1f} ms "
          f"a frame); activation mean {heat.mean():.4f}, max {heat.max():.3f}")
    carried = ", ".join(f"{k}={v}" for k, v in MAP_SETTINGS.items())
    print(f"wrote {out}, with the settings {carried} (a colour blob is as large as the window that made it, not as "
          "the ball: none is placed in the air by its size); heatpf run applies them")
    return 0


def _background_kind(background: str, reference_image) -> str:
    if background != "auto":
        return background
    return "ring" if reference_image is None else "frames"


def add_parser(sub, parent: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "colour", parents=parent,
        help="turn a sequence's RGB frames into colour-likelihood heat maps (Olufs et al. eq. 1-3)",
        epilog="Then run any method on the output at its default threshold, e.g. heatpf run OUT.npz --output "
               "est.csv (the maps are divided by the reference's own score: the object is at about 1).",
    )
    p.add_argument("input", help="sequence file (.npz, version 1) with images (uint8 [T, H, W, 3])")
    p.add_argument("--reference", metavar="REF.png", help="image of the object (PNG/JPEG, or .npy uint8 [h, w, 3]); "
                   "one cut out of a frame of the input (pixel for pixel, or a JPEG of it) is taken as that box in "
                   "that frame")
    p.add_argument("--box", metavar="x,y,w,h", help="the object's box, pixels: in --reference, or in --frame")
    p.add_argument("--frame", type=int, help="take the reference from --box in this frame of the input")
    p.add_argument("--background", default="auto", choices=("auto", "ring", "frames", "none"),
                   help="the colours the reference weights down (Comaniciu et al.'s background-weighted "
                   "histogram): the ring around the box (in the image the box is in), the input's frames, or none; "
                   "auto (default): the ring for --frame (and for a --reference found in a frame), the frames for "
                   "--reference")
    p.add_argument("--output", "-o", required=True, help="the new sequence (not replaced if it exists, unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    p.add_argument("--theta", type=float, default=0.35, help="eq. 3's lower limit, a share of the reference's own "
                   "score (default 0.35)")
    p.add_argument("--window-scale", type=float, default=_WINDOW_SCALE, help="object window half-size over the "
                   f"expected ball radius in pixels (default {_WINDOW_SCALE}, the library's SCALED_PARAMS)")
    p.add_argument("--window-waist", type=float, default=1.0, help="the object window's arm width over its length, "
                   "in [0, 1] (default 1: a square; 0.618 with --window-scale 0.851: the largest cross of two "
                   "rectangles inside a round ball)")
    p.add_argument("--silhouette", action=argparse.BooleanOptionalAction, default=True,
                   help="shape the colour histograms' maps by the ball's outline (the object probability's disc "
                   "against its annulus; the default); --no-silhouette: the histograms alone")
    p.add_argument("--smoothing", type=float, default=0.25, help="reference smoothing along the intensity bins, "
                   "for lighting changes (default 0.25)")
    p.add_argument("--chroma-smoothing", type=float, default=0.25, help="reference smoothing along the r' and g' "
                   "bins, for a colour cast of the light on a white or grey object (default 0.25; 0: none)")
    p.set_defaults(func=cmd_colour)
    return p
