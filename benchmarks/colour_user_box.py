"""Colour heat maps from a user's box: the filter on colour maps at its default threshold against the same
filter on the detector-like heat maps of the same frames.

A user takes the reference as a box around the ball in one frame: here boxes 10 %, 25 % and 40 % larger than
the ball, centred on it and off-centre by a quarter of the box (down and right), in the first frame where
the ball is visible. The colour maps are what ``heatpf colour IN.npz --box x,y,w,h --frame N`` writes
(:func:`heatpf_jax.cli.colour.colour_sequence`); ``heatmap`` and ``extended`` run on them with their default
parameters (threshold 0.3) and on the sequence's own ``heatmaps``; mean error after step 10, and the ratio.

Two renderers draw the frames of one simulated world (its camera, its ball path):

* ``ours``: the package's renderer (:func:`heatpf_jax.sim.render_rgb.render_rgb`, ray-cast);
* ``numpy``: an independent one written here, in image space: mown grass in stripes along the other axis
  with per-pixel texture, its own field lines (a line across, a touchline, a circle), a white goal post near
  the ball's path, a ball drawn as a disc with five to seven dark pentagons that turn as it rolls,
  2 x 2 supersampled edges, motion blur over a 20 ms exposure, a light that drifts darker and warmer
  (yellowish) over the sequence, and sensor noise.

    python benchmarks/colour_user_box.py                         # seeds 0-2, 200 steps, both renderers
    python benchmarks/colour_user_box.py --seeds 100:103 --renderers numpy --scales 1.25
    python benchmarks/colour_user_box.py --methods heatmap,heatmap:threshold=0.5   # METHOD:NAME=VALUE[+...]
    python benchmarks/colour_user_box.py --maps histogram        # the histograms alone (--no-silhouette)

``--speed``: the time of ``heatpf colour`` on 200 frames (``standard`` seed 0, a box 25 % larger than the ball)
from a cold and from a warm compilation cache (a fresh ``HEATPF_CACHE_DIR``, the command run twice in new
processes), against the time of one map (a jitted call on one frame, median of ``--repeats``). ``--before DIR``
also runs the command of another checkout of the package (``DIR`` holds its ``heatpf_jax``) on the same input.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

import heatpf_jax as hp
from heatpf_jax.cli.settings import parse_seeds
from heatpf_jax.sim.render import project_centre
from heatpf_jax.sim.scenarios import simulate_with_info

# --- An independent renderer ---------------------------------------------------------------------------------

_GRASS = np.array([62.0, 132.0, 44.0])
_GRASS_ALT = np.array([52.0, 118.0, 40.0])
_WHITE = np.array([238.0, 240.0, 236.0])
_BALL = np.array([244.0, 244.0, 240.0])
_PATCH = np.array([28.0, 30.0, 34.0])
_SKY = np.array([150.0, 160.0, 175.0])
_SS = 2  # supersampling per axis


def _pentagon(cx, cy, radius, angle, uu, vv) -> np.ndarray:
    """Pixels (supersampled grid ``uu, vv``) inside a regular pentagon."""
    inside = np.ones(uu.shape, bool)
    for k in range(5):
        a = angle + 2 * np.pi * k / 5
        nx, ny = np.cos(a), np.sin(a)  # outward normal of one side
        inside &= (uu - cx) * nx + (vv - cy) * ny <= radius * np.cos(np.pi / 5)
    return inside


def _patch_directions(rng) -> np.ndarray:
    """Unit vectors of a ball's dark patches in its own frame: 12 dodecahedron-like places, jittered."""
    phi = (1 + 5**0.5) / 2
    v = np.array([(0, a, b * phi) for a in (-1, 1) for b in (-1, 1)]
                 + [(a, b * phi, 0) for a in (-1, 1) for b in (-1, 1)]
                 + [(b * phi, 0, a) for a in (-1, 1) for b in (-1, 1)], float)
    v += rng.normal(0, 0.05, v.shape)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def render_numpy(seq, info, seed: int) -> np.ndarray:
    """RGB frames ``uint8 [T, H, W, 3]`` of a simulated sequence, drawn in image space (module docstring)."""
    rng = np.random.default_rng([seed, 7177])
    t_steps = seq.num_steps
    h, w = seq.heatmaps.shape[1:]
    fx, fy, cx, cy = (float(v) for v in seq.intrinsics)
    radius = float(seq.ball_radius)
    cams = info["true_cam_to_base"]
    poses = info["robot_pose"]
    balls = info["balls_base"]
    visible = info["balls_visible"]
    hs, ws = h * _SS, w * _SS
    vv, uu = (np.mgrid[0:hs, 0:ws] + 0.5) / _SS - 0.5  # pixel coordinates of the subsamples
    texture = rng.normal(0.0, 1.0, (64, 64))
    dirs = _patch_directions(rng)
    ball_world = info["ball_world"]
    post_world = _post_place(ball_world, poses[0], rng)
    gain = 1.0 - 0.2 * (0.5 - 0.5 * np.cos(np.linspace(0, 2 * np.pi, t_steps)))  # 1 -> 0.8 -> 1
    warm = 0.5 - 0.5 * np.cos(np.linspace(0, 3 * np.pi, t_steps))  # 0 -> 1 -> 0 -> 1
    rotation = np.eye(3)
    frames = np.empty((t_steps, h, w, 3), np.uint8)
    background_cache: dict[bytes, np.ndarray] = {}
    for t in range(t_steps):
        cam = cams[t]
        key = np.round(np.concatenate([cam.ravel(), poses[t]]), 9).tobytes()
        if key not in background_cache:
            background_cache.clear()
            background_cache[key] = _background(cam, poses[t], (hs, ws), uu, vv, (fx, fy, cx, cy), texture,
                                                post_world)
        img = background_cache[key].copy()
        step = balls[t, 0] - balls[t - 1, 0] if t else np.zeros(2)
        dist = float(np.linalg.norm(step))
        if dist > 1e-9:
            axis = np.array([-step[1], step[0], 0.0]) / dist
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            a = dist / radius
            rotation = (np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k) @ rotation
        for b in range(balls.shape[1]):
            if not visible[t, b]:
                continue
            velocity = (balls[t, b] - balls[t - 1, b]) / float(seq.dt) if t else np.zeros(2)
            layers = []
            for s in np.linspace(-0.5, 0.5, 5):  # a 20 ms exposure
                centre = np.array([*(balls[t, b] + s * 0.02 * velocity), radius])
                layers.append(_ball_layer(img, centre, rotation, dirs, cam, (fx, fy, cx, cy), uu, vv))
            img = np.mean(layers, axis=0)
        img = img.reshape(h, _SS, w, _SS, 3).mean(axis=(1, 3))
        tint = np.array([1.0 + 0.08 * warm[t], 1.0 + 0.02 * warm[t], 1.0 - 0.18 * warm[t]])
        img = img * gain[t] * tint + rng.normal(0.0, 4.0, img.shape)
        frames[t] = np.clip(np.round(img), 0, 255).astype(np.uint8)
    return frames


def _post_place(ball_world, pose, rng) -> np.ndarray:
    """A goal post's world place in view of the first pose, 0.3-0.6 m from the ball's path (it shares
    windows with the ball now and then)."""
    c, s = np.cos(pose[2]), np.sin(pose[2])
    for _ in range(1000):
        x, y = rng.uniform(1.2, 3.5), rng.uniform(-0.4, 0.4) * 1.2
        place = pose[:2] + np.array([c * x - s * y, s * x + c * y])
        gap = np.min(np.linalg.norm(ball_world - place, axis=1))
        if 0.3 <= gap <= 0.6:
            return place
    return pose[:2] + np.array([c * 3.0, s * 3.0])


def _background(cam, pose, shape, uu, vv, intr, texture, post_world) -> np.ndarray:
    fx, fy, cx, cy = intr
    ray = np.stack([(uu - cx) / fx, (vv - cy) / fy, np.ones_like(uu)], axis=-1) @ cam[:3, :3].T
    origin = cam[:3, 3]
    dz = ray[..., 2]
    ground = dz < -1e-9
    depth = np.where(ground, -origin[2] / np.where(ground, dz, -1.0), 0.0)
    bx, by = origin[0] + depth * ray[..., 0], origin[1] + depth * ray[..., 1]
    c, s = np.cos(pose[2]), np.sin(pose[2])
    x, y = pose[0] + c * bx - s * by, pose[1] + s * bx + c * by
    stripe = (np.floor(y / 0.7) % 2 == 0)[..., None]
    tex = texture[(np.floor(x / 0.02) % 64).astype(int), (np.floor(y / 0.02) % 64).astype(int)]
    grass = np.where(stripe, _GRASS, _GRASS_ALT) * (1.0 + 0.07 * tex)[..., None]
    half = 0.03
    line = (np.abs(x - 2.5) < half) | ((np.abs(y - 1.8) < half) & (x > 0.0))
    line |= np.abs(np.hypot(x - 5.0, y + 1.0) - 0.6) < half
    img = np.where(ground[..., None], np.where(line[..., None], _WHITE, grass), _SKY)
    # The goal post: a white vertical bar 5 cm in radius, 0.8 m high, drawn between its projected foot and top.
    base_to_cam = np.linalg.inv(cam)
    c_w, s_w = np.cos(-pose[2]), np.sin(-pose[2])
    rel = post_world - pose[:2]
    p_base = np.array([c_w * rel[0] - s_w * rel[1], s_w * rel[0] + c_w * rel[1]])
    foot = base_to_cam @ np.array([*p_base, 0.0, 1.0])
    top = base_to_cam @ np.array([*p_base, 0.8, 1.0])
    if foot[2] > 0.1 and top[2] > 0.1:
        (u0, v0), (u1, v1) = [(fx * p[0] / p[2] + cx, fy * p[1] / p[2] + cy) for p in (foot, top)]
        half_w = fx * 0.05 / foot[2]
        frac = np.clip((vv - v0) / (v1 - v0 if abs(v1 - v0) > 1e-6 else 1e-6), 0.0, 1.0)
        u_axis = u0 + frac * (u1 - u0)
        on = (np.abs(uu - u_axis) <= half_w) & (vv <= v0) & (vv >= v1)
        img = np.where(on[..., None], _WHITE * 0.97, img)
    return img


def _ball_layer(img, centre, rotation, dirs, cam, intr, uu, vv) -> np.ndarray:
    fx, fy, cx, cy = intr
    u, v, depth = project_centre(centre, np.array(intr), cam)
    if depth <= 0.05:
        return img
    r = fx * float(centre[2]) / depth
    d2 = ((uu - u) ** 2 + (vv - v) ** 2) / (r * r)
    disc = d2 <= 1.0
    out = img.copy()
    shade = 0.65 + 0.35 * np.clip(1.0 - (vv - (v - 0.6 * r)) / (2.2 * r), 0.0, 1.0)  # lit from above
    colour = np.broadcast_to(_BALL, img.shape) * shade[..., None]
    # Patches: the ball's patch directions in the camera frame; those facing the camera drawn as pentagons.
    base_to_cam = np.linalg.inv(cam)[:3, :3]
    for d in dirs @ rotation.T @ base_to_cam.T:
        if d[2] > -0.2:  # facing away from the camera (optical z points into the scene)
            continue
        pu, pv = u + r * d[0], v + r * d[1]
        size = 0.36 * r * np.sqrt(max(-d[2], 0.05))
        colour = np.where(_pentagon(pu, pv, size, np.arctan2(d[1], d[0]), uu, vv)[..., None],
                          _PATCH * shade[..., None], colour)
    return np.where(disc[..., None], colour, out)


# --- The benchmark -------------------------------------------------------------------------------------------


def ball_box(seq, info, t: int, scale: float, offset: float) -> tuple[int, int, int, int]:
    """A user's box around the ball in frame ``t``: ``scale`` times the ball's diameter, its centre moved by
    ``offset`` of the box down and to the right."""
    centre = np.array([*seq.ground_truth[t], float(seq.ball_radius)])
    u, v, depth = project_centre(centre, seq.intrinsics, info["true_cam_to_base"][t])
    side = 2.0 * float(seq.intrinsics[0]) * float(seq.ball_radius) / depth * scale
    x0 = u - side / 2 + offset * side
    y0 = v - side / 2 + offset * side
    h, w = seq.heatmaps.shape[1:]
    x, y, s = int(round(x0)), int(round(y0)), max(int(round(side)), 2)
    x, y = min(max(x, 0), w - s), min(max(y, 0), h - s)
    return x, y, s, s


def _plain(seq, t0: int, box):
    """The previous release's ``heatpf colour``: the whole box's histogram, smoothed, on the coefficient's own
    scale (``theta`` 0.2, no background weighting, no white balance)."""
    from heatpf_jax.colour.likelihood import ColourParams, colour_heatmaps
    from heatpf_jax.colour.space import exact_top_bins, patch_histogram, smooth_chromaticity, smooth_intensity

    q = smooth_chromaticity(smooth_intensity(patch_histogram(seq.images[t0], box)))
    heat = colour_heatmaps(seq.images, q, seq.intrinsics, seq.cam_to_base, seq.ball_radius, ColourParams(),
                           top_bins=exact_top_bins(q))
    return seq._replace(heatmaps=np.clip(np.asarray(heat), 0.0, 1.0).astype(np.float32))


def _image_reference(seq, image: np.ndarray, params, jpeg: bool, silhouette: bool = True):
    """``heatpf colour --reference``: an image found in the frames (a PNG cut out of one, or a JPEG of it) is taken
    as its box in its frame, as the command does (:func:`heatpf_jax.colour.crop.find_crop`), else by itself; with
    ``jpeg`` the image goes through a JPEG file first (quality 90, Pillow)."""
    from heatpf_jax.cli.colour import colour_sequence
    from heatpf_jax.colour.crop import find_crop, frame_box

    if jpeg:
        import io

        from PIL import Image

        buffer = io.BytesIO()
        Image.fromarray(image).save(buffer, format="JPEG", quality=90)
        image = np.asarray(Image.open(io.BytesIO(buffer.getvalue())).convert("RGB"))
    crop = find_crop(seq.images, image)
    if crop is None:
        return colour_sequence(seq, reference_image=image, params=params, silhouette=silhouette)
    h, w = image.shape[:2]
    return colour_sequence(seq, box=frame_box(crop, (0, 0, w, h)), frame=crop.frame, params=params,
                           silhouette=silhouette)


def reference_frames(seq, info) -> dict[str, int]:
    """Frames a user might take the reference in: the first where the ball is visible (``first``), the one
    where it moves fastest in the image (``blur``: the most motion blur), and the one whose light is the most
    different from the first's (``light``: the largest change of the channel means' ratios), each with the
    ball visible and at least 10 px inside the image. In ``main``'s ``--frames``, ``NAME-image`` is that frame's
    box saved as an image and given as ``--reference`` (found in the frames, pixel for pixel: the box's reference),
    ``NAME-jpeg`` the same saved as a JPEG (found within the tolerance of :func:`heatpf_jax.colour.crop.find_crop`,
    or taken by itself with the input's frames as its background), ``NAME-plain``
    the previous release's reference from it (:func:`_plain`)."""
    h, w = seq.heatmaps.shape[1:]
    uv = np.array([project_centre(np.array([*g, float(seq.ball_radius)]), seq.intrinsics, c)[:2]
                   for g, c in zip(seq.ground_truth, info["true_cam_to_base"], strict=True)])
    ok = info["visible"] & (uv[:, 0] > 10) & (uv[:, 0] < w - 10) & (uv[:, 1] > 10) & (uv[:, 1] < h - 10)
    frames = np.flatnonzero(ok)
    speed = np.r_[0.0, np.linalg.norm(np.diff(uv, axis=0), axis=1)]
    means = seq.images.reshape(seq.num_steps, -1, 3).mean(axis=1)
    ratios = np.log(means[:, [0, 2]] / means[:, [1]])  # r/g and b/g
    first = int(frames[0])
    level = np.abs(np.log(means.mean(1) / means[first].mean()))
    light = np.linalg.norm(ratios - ratios[first], axis=1) + 0.2 * level
    return {"first": first, "blur": int(frames[np.argmax(speed[frames])]),
            "light": int(frames[np.argmax(light[frames])])}


def filter_error(seq, method: str, seed: int, keys: int = 1) -> float:
    """``METHOD`` or ``METHOD:NAME=VALUE[+...]``: static options and parameters by name, as ``benchmarks/worlds.py``
    takes them (``heatmap:source=pixels+threshold=0.5``), on top of the sequence's own settings as ``heatpf run``
    applies them (``heatpf colour``'s ``source=pixels``). With ``keys`` > 1 the mean over the filter's PRNG keys
    ``key(seed)`` and ``fold_in(key(seed), j)``, ``j = 1 .. keys - 1`` (the filter's own randomness)."""
    import contextlib
    import io

    from worlds import variant_options  # benchmarks/worlds.py, beside this script

    from heatpf_jax import params as P
    from heatpf_jax.cli.settings import sequence_settings

    name, _, spec = method.partition(":")
    options, overrides = variant_options(spec)
    given = {item.partition("=")[0] for item in spec.split("+")} if "=" in spec else ({"source"} if spec else set())
    with contextlib.redirect_stdout(io.StringIO()):  # as heatpf run: the sequence's settings beneath the spec's
        options, overrides = sequence_settings(seq, "colour", [name], options, overrides, given)
    model, params = hp.build(name, options)
    if overrides:
        params = P.set_by_name(params, model.properties(), overrides)
    errors = []
    for j in range(keys):
        key = jax.random.key(seed) if j == 0 else jax.random.fold_in(jax.random.key(seed), j)
        mean = np.asarray(hp.run(key, seq, params, model).info.mean, np.float64)
        err = np.linalg.norm(mean - seq.ground_truth, axis=1)[10:]
        errors.append(np.mean(np.where(np.isfinite(err), err, 10.0)))
    return float(np.mean(errors))


def _command(args: list[str], cache: Path, pythonpath: str | None = None) -> tuple[float, str]:
    """``heatpf ARGS`` in a new process with the compilation cache in ``cache``, in ``cache``'s parent (not in
    a checkout, whose package ``python -m`` would put first): ``(wall seconds, stdout)``."""
    env = dict(os.environ, HEATPF_CACHE_DIR=str(cache))
    env.pop("HEATPF_NO_CACHE", None)
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "heatpf_jax.cli", *args], env=env, capture_output=True, text=True,
                          check=True, cwd=cache.parent)
    return time.perf_counter() - start, done.stdout


def speed(repeats: int, before: str | None) -> int:
    from heatpf_jax.cli.colour import colour_sequence
    from heatpf_jax.colour.likelihood import colour_likelihood, expected_radius_px
    from heatpf_jax.colour.reference import SCALED_PARAMS
    from heatpf_jax.colour.space import channel_means, exact_top_bins
    from heatpf_jax.io.sequence import save_sequence

    seq, info = simulate_with_info("standard", 0, num_steps=200, rgb=True)
    box = ball_box(seq, info, 0, 1.25, 0.0)
    _, ref = colour_sequence(seq.head(2), box=box, frame=0)
    params = SCALED_PARAMS._replace(reference_score=ref.score)
    white = channel_means(seq.images[0])
    k = exact_top_bins(ref.histogram)
    params = params._replace(silhouette_score=ref.silhouette_score)  # the outline, as heatpf colour's default
    one = jax.jit(lambda image, pose: colour_likelihood(
        image, ref.histogram, expected_radius_px(seq.intrinsics, pose, seq.ball_radius, seq.heatmaps.shape[1:]),
        params, top_bins=k, white=white, object_probability=ref.silhouette))
    frames = [(jax.numpy.asarray(seq.images[t]), jax.numpy.asarray(seq.cam_to_base[t], np.float32))
              for t in range(0, 200, 200 // 10)]
    jax.block_until_ready(one(*frames[0]))
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(one(*frames[i % len(frames)]))
        times.append(time.perf_counter() - start)
    per_map = float(np.median(times))
    print(f"one map (200 x 150, {k} bins, two passes and the outline, jitted, median of {repeats}): "
          f"{1000 * per_map:.1f} ms "
          f"(IQR {1000 * np.subtract(*np.percentile(times, [75, 25])):.1f} ms); 200 maps: {200 * per_map:.2f} s")
    pattern = re.compile(r"in ([\d.]+) s \(including compilation\)(?:: reference ([\d.]+) s, compilation ([\d.]+) s, "
                         r"maps ([\d.]+) s)?")
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rgb.npz"
        save_sequence(path, seq)
        runs = [("this checkout", None)] + ([("--before", before)] if before else [])
        for name, pythonpath in runs:
            cache = Path(tmp) / f"cache-{len(name)}"
            for state in ("cold", "warm"):
                wall, out = _command(["colour", str(path), "--box", ",".join(map(str, box)), "--frame", "0",
                                      "-o", str(Path(tmp) / "out.npz"), "--force"], cache, pythonpath)
                found = pattern.search(out)
                parts = "" if found is None or found.group(2) is None else (
                    f" (reference {found.group(2)} s, compilation {found.group(3)} s, maps {found.group(4)} s)")
                total = "?" if found is None else found.group(1)
                print(f"{name:14s} {state} cache: heatpf colour {total} s{parts}; the process {wall:.1f} s")
                if found is not None and found.group(4) is not None:
                    ratio = float(found.group(4)) / (200 * per_map)
                    print(f"{'':14s} maps / (200 x one map) = {ratio:.2f} (at most 3 asked)")
    return 0


def main(argv=None) -> int:
    from heatpf_jax.cli.colour import colour_sequence
    from heatpf_jax.colour.reference import SCALED_PARAMS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:3")
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--keys", type=int, default=1, help="the filters' PRNG keys per run, averaged")
    parser.add_argument("--scenario", default="standard")
    parser.add_argument("--renderers", default="ours,numpy")
    parser.add_argument("--methods", default="heatmap,extended")
    parser.add_argument("--scales", default="1.1,1.25,1.4")
    parser.add_argument("--offsets", default="0,0.25")
    parser.add_argument("--frames", default="first,blur,light,first-image,first-plain",
                        help="reference frames (reference_frames); NAME-image: that frame's box as an image "
                        "(NAME-jpeg: as a JPEG); NAME-plain: the previous release's reference")
    parser.add_argument("--theta", type=float, default=None, help="eq. 3's theta (default: heatpf colour's)")
    parser.add_argument("--window-scale", type=float, default=None,
                        help="the object window's half-size over the ball's radius (default: heatpf colour's)")
    parser.add_argument("--maps", default="outline", choices=("histogram", "outline"),
                        help="heatpf colour's maps (outline, the default: the histograms shaped by the ball's outline) "
                        "or the histograms alone (histogram: heatpf colour --no-silhouette)")
    parser.add_argument("--speed", action="store_true", help="time heatpf colour on 200 frames instead")
    parser.add_argument("--repeats", type=int, default=30, help="--speed: calls of one map timed")
    parser.add_argument("--before", default=None, help="--speed: a directory holding another heatpf_jax to time")
    args = parser.parse_args(argv)
    if args.speed:
        return speed(args.repeats, args.before)
    seeds = parse_seeds(args.seeds, 3)
    methods = args.methods.split(",")
    scales = [float(s) for s in args.scales.split(",")]
    offsets = [float(s) for s in args.offsets.split(",")]
    params = SCALED_PARAMS if args.theta is None else SCALED_PARAMS._replace(theta=args.theta)
    if args.window_scale is not None:
        params = params._replace(window_scale=args.window_scale)
    outline = args.maps == "outline"
    rows = []
    start = time.perf_counter()
    for renderer in args.renderers.split(","):
        for seed in seeds:
            seq, info = simulate_with_info(args.scenario, seed, num_steps=args.steps, rgb=renderer == "ours")
            if renderer == "numpy":
                seq = seq._replace(images=render_numpy(seq, info, seed))
            picks = reference_frames(seq, info)
            detector = {m: filter_error(seq, m, seed, args.keys) for m in methods}
            for which in args.frames.split(","):
                t0 = picks[which.removesuffix("-image").removesuffix("-jpeg").removesuffix("-plain")]
                for scale in scales:
                    for offset in offsets:
                        box = ball_box(seq, info, t0, scale, offset)
                        if which.endswith("-plain"):  # the previous release: the whole box, the coefficient's scale
                            colour, ref = _plain(seq, t0, box), None
                        elif which.endswith(("-image", "-jpeg")):  # the box saved: --reference BOX.png / .jpg
                            x, y, w, h = box
                            colour, ref = _image_reference(seq, seq.images[t0, y:y + h, x:x + w], params,
                                                           jpeg=which.endswith("-jpeg"), silhouette=outline)
                        else:
                            colour, ref = colour_sequence(seq, box=box, frame=t0, params=params,
                                                          silhouette=outline)
                        errs = {m: filter_error(colour, m, seed, args.keys) for m in methods}
                        rows.append((renderer, seed, which, scale, offset, detector, errs))
                        got = "" if ref is None else f"-> {ref.box} score {ref.score:.3f} "
                        print(f"{renderer:5s} seed {seed:3d} {which:5s} frame {t0:3d} box x{scale:.2f} "
                              f"off {offset:.2f} {box} {got}| "
                              + "  ".join(f"{m} {errs[m]:.4f}/{detector[m]:.4f} = {errs[m] / detector[m]:.2f}x"
                                          for m in methods), flush=True)
    print(f"\n{args.scenario}, seeds {seeds.start}-{seeds.stop - 1}, {args.steps} steps, default thresholds, theta "
          f"{params.theta} ({time.perf_counter() - start:.0f} s). Mean error after step 10 [m], colour / detector "
          "(ratio of the means; worst: the largest ratio of one seed):")
    print(f"{'renderer':8s} {'frame':11s} {'box':>5s} {'offset':>6s} "
          + " ".join(f"{m + ' colour':>16s} {m + ' det.':>14s} {'ratio':>6s} {'worst':>6s}" for m in methods))
    order = args.frames.split(",")
    keys = sorted({(r[0], r[2], r[3], r[4]) for r in rows}, key=lambda k: (k[0], order.index(k[1]), k[2], k[3]))
    for renderer, which, scale, offset in keys:
        sel = [r for r in rows if (r[0], r[2], r[3], r[4]) == (renderer, which, scale, offset)]
        line = f"{renderer:8s} {which:11s} {scale:5.2f} {offset:6.2f} "
        for m in methods:
            col = np.mean([r[6][m] for r in sel])
            det = np.mean([r[5][m] for r in sel])
            worst = max(r[6][m] / r[5][m] for r in sel)
            line += f"{col:16.4f} {det:14.4f} {col / det:6.2f} {worst:6.2f} "
        print(line)
    for renderer in args.renderers.split(","):
        sel = [r for r in rows if r[0] == renderer and not r[2].endswith("-plain")]
        if not sel:
            continue
        print(f"{renderer}: over every box and reference frame (not -plain), " + ", ".join(
            f"{m} {np.mean([r[6][m] for r in sel]):.4f} / {np.mean([r[5][m] for r in sel]):.4f} = "
            f"{np.mean([r[6][m] for r in sel]) / np.mean([r[5][m] for r in sel]):.2f}x" for m in methods))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
