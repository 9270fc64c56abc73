"""``heatpf colour``: RGB frames -> colour-likelihood heat maps (Olufs et al. eq. 1-3), a sequence every method runs on.

::

    heatpf colour IN.npz --reference BALL.png [--box x,y,w,h] --output OUT.npz
    heatpf colour IN.npz --box x,y,w,h --frame N --output OUT.npz

The reference histogram comes from an image of the object (PNG/JPEG through Pillow, ``pip install
'heatpf-jax[rgb]'``, or a ``.npy`` ``uint8 [h, w, 3]``), cropped to ``--box`` if given, or from a box in
frame ``N`` of the input's own ``images``. ``OUT.npz`` is the input with ``heatmaps`` replaced by the
colour likelihood (:func:`heatpf_jax.colour_likelihood.colour_heatmaps`). Every argument is checked before
any computation; an existing ``OUT.npz`` is replaced only with ``--force``, and never the input.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from heatpf_jax.files import check_input, check_output

__all__ = ["add_parser", "cmd_colour", "read_reference_image"]


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


def cmd_colour(args: argparse.Namespace) -> int:
    from heatpf_jax.colour_likelihood import ColourParams, colour_heatmaps
    from heatpf_jax.colour_space import exact_top_bins, patch_histogram, smooth_chromaticity, smooth_intensity
    from heatpf_jax.sequence import load_sequence, save_sequence

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
        q = patch_histogram(seq.images[args.frame], box)
    else:
        q = patch_histogram(reference_image, box)
    q = smooth_chromaticity(smooth_intensity(q, weight=args.smoothing), weight=args.chroma_smoothing)
    params = ColourParams(theta=args.theta, window_scale=args.window_scale)
    start = time.perf_counter()
    heat = colour_heatmaps(seq.images, q, seq.intrinsics, seq.cam_to_base, seq.ball_radius, params,
                           top_bins=exact_top_bins(q))  # exact, and no more bins than the reference fills
    heat = np.asarray(heat)
    elapsed = time.perf_counter() - start
    if not np.all(np.isfinite(heat)):
        raise RuntimeError("the colour likelihood produced a non-finite value; please report this")
    save_sequence(out, seq._replace(heatmaps=np.clip(heat, 0.0, 1.0).astype(np.float32)))
    print(f"{args.input}: {seq.num_steps} frames of {seq.images.shape[2]} x {seq.images.shape[1]}, colour likelihood "
          f"in {elapsed:.2f} s (including compilation); activation mean {heat.mean():.4f}, max {heat.max():.3f}")
    print(f"wrote {out}")
    return 0


def add_parser(sub, parent: list[argparse.ArgumentParser]) -> argparse.ArgumentParser:
    p = sub.add_parser(
        "colour", parents=parent,
        help="turn a sequence's RGB frames into colour-likelihood heat maps (Olufs et al. eq. 1-3)",
        epilog="Then run any method on the output, e.g. heatpf run OUT.npz --output est.csv "
               "--set threshold=0.1 (a colour map's activations are lower than a detector's).",
    )
    p.add_argument("input", help="sequence file (.npz, version 1) with images (uint8 [T, H, W, 3])")
    p.add_argument("--reference", metavar="REF.png", help="image of the object (PNG/JPEG, or .npy uint8 [h, w, 3])")
    p.add_argument("--box", metavar="x,y,w,h", help="the object's box, pixels: in --reference, or in --frame")
    p.add_argument("--frame", type=int, help="take the reference from --box in this frame of the input")
    p.add_argument("--output", "-o", required=True, help="the new sequence (not replaced if it exists, unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    p.add_argument("--theta", type=float, default=0.2, help="eq. 3's lower limit (default 0.2)")
    p.add_argument("--window-scale", type=float, default=0.9, help="object window half-size over the expected "
                   "ball radius in pixels (default 0.9)")
    p.add_argument("--smoothing", type=float, default=0.25, help="reference smoothing along the intensity bins, "
                   "for lighting changes (default 0.25)")
    p.add_argument("--chroma-smoothing", type=float, default=0.25, help="reference smoothing along the r' and g' "
                   "bins, for a colour cast of the light on a white or grey object (default 0.25; 0: none)")
    p.set_defaults(func=cmd_colour)
    return p
