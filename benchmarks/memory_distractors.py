"""The long-term memory among distractors (Olufs et al. 3.4): ``kicked_hidden`` worlds, with and without memory.

Each seed is world ``seed`` of the family's ``kicked_hidden`` member (a static robot; straight rolls at
0.4-1 m/s, each hidden behind a robot for 1.5-2 s while it rolls 0.6-1.1 m), rendered three times with
0, 1 and 2 distractor blobs (``overrides={"distractors": d}``: ball-like blobs near where the ball
vanished and where it comes back, on during the hiding and 2-3 s after it). Per hiding:

* **hidden steps**: the heat maps that show the world while the ball is hidden (``info["hidden"]``
  shifted by the world's latency);
* **steps to re-acquire**: from the first heat map that shows the ball again (1: that step) until the
  estimate is first within 0.3 m of the ball; ``window + 1`` when not within ``--window`` steps. Hidings
  whose reappearance leaves fewer than ``--window`` steps in the run are left out;
* **ball track within 0.5 m**: the share of the hidden steps on which the memory's ball track
  (``TrackTable.ball``) lies within 0.5 m of the hidden ball; **any track**: on which some track does (the
  issue's "the memory's tracks are within 0.5 m of the hidden ball"). For a table without ``ball`` (an older
  memory) the ball track is the valid track observed on most steps, where its hints went.

"The ball" is where the heat map shows it (:func:`apparent_ball`): the family's cameras are miscalibrated by
1-3 degrees, which alone moves a ball at 3-6 m by up to a metre, so every filter is measured against it.

The table gives, per distractor count and filter, the median and the mean steps over every hiding of
every seed and filter key, the hidings never re-acquired, both track shares, and the mean error over
the 2-3 s after the reappearance (the distractors still on).

    python benchmarks/memory_distractors.py                    # seeds 0-19, 2 filter keys (the report)
    python benchmarks/memory_distractors.py --seeds 100:120    # the development seeds the memory was set on
    python benchmarks/memory_distractors.py --memories tracks --set memory_lost_accel_std=1   # a variant

Worlds take about 8 s each to render; ``--cache DIR`` (default ``~/.cache/heatpf_jax/memory_distractors``,
``--cache none`` to switch it off) keeps them as .npz files.
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import jax
import numpy as np

from heatpf_jax.cli.settings import parse_seeds
from heatpf_jax.io.sequence import Sequence, load_sequence, save_sequence
from heatpf_jax.presets import FilterOptions, build
from heatpf_jax.rollout import run

NUM_STEPS = 300
MEMBER = "kicked_hidden"
_INFO_KEYS = ("hidden", "visible", "render_step", "distractor_world", "distractor_on")


def world(seed: int, distractors: int, cache: Path | None, num_steps: int = NUM_STEPS):
    """``(sequence, info)`` of ``kicked_hidden`` world ``seed`` with ``distractors`` blobs per hiding.

    ``info`` holds ``hidden``, ``visible``, ``render_step``, ``distractor_world``, ``distractor_on`` and
    ``latency`` (the rest of :func:`~heatpf_jax.sim.family.simulate_family_with_info`'s info is dropped).
    """
    stem = f"{MEMBER}_{seed}_d{distractors}_{num_steps}"
    if cache is not None and (cache / f"{stem}.npz").is_file() and (cache / f"{stem}_info.npz").is_file():
        with np.load(cache / f"{stem}_info.npz") as f:
            return load_sequence(cache / f"{stem}.npz"), {k: f[k] for k in f.files}
    from heatpf_jax.sim.family import simulate_family_with_info

    seq, full = simulate_family_with_info(MEMBER, seed, num_steps=num_steps, overrides={"distractors": distractors})
    info = {k: np.asarray(full[k]) for k in _INFO_KEYS}
    info["apparent"] = apparent_ball(seq, full)
    info["latency"] = np.asarray(int(full["factors"]["latency_steps"]))
    info["after"] = np.array([w.after for w in full["hidden_kicks"]], np.int64)
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
        save_sequence(cache / f"{stem}.npz", seq)
        np.savez(cache / f"{stem}_info.npz", **info)
    return seq, info


def apparent_ball(seq: Sequence, info) -> np.ndarray:
    """``[T, 2]`` where heat map t shows the ball (base frame): the true ball of the rendered step
    (``render_step``, the latency) seen by the true camera, and its ray cast onto the plane
    ``z = ball_radius`` by the sequence's (miscalibrated) camera, as the filter casts it. A tracker that is on
    the ball's blob is on this point; the calibration error (1-3 degrees) alone moves it up to about 1 m from
    the ball at 3-6 m, so re-acquiring means coming within 0.3 m of it, not of the ball. Where the ball is
    hidden it is where the ball would be seen. (``kicked_hidden`` has a static robot: every base frame is one.)
    """
    s = np.asarray(info["render_step"])
    radius = float(seq.ball_radius)
    centre = np.concatenate([np.asarray(info["balls_base"])[s, 0], radius + np.asarray(info["ball_height"])[s, None]],
                            axis=1)
    true_cam = np.asarray(info["true_cam_to_base"])[s]
    given = np.asarray(seq.cam_to_base)
    ray_cam = np.einsum("tji,tj->ti", true_cam[:, :3, :3], centre - true_cam[:, :3, 3])  # R^T (p - o)
    ray = np.einsum("tij,tj->ti", given[:, :3, :3], ray_cam)
    origin = given[:, :3, 3]
    scale = (radius - origin[:, 2]) / np.where(np.abs(ray[:, 2]) > 1e-9, ray[:, 2], -1e-9)
    return origin[:, :2] + scale[:, None] * ray[:, :2]


def hidings(info, num_steps: int, window: int):
    """``[(hidden_steps, reappear, after_stop)]`` per hiding that leaves ``window`` steps after its reappearance."""
    lat = int(info["latency"])
    visible = np.asarray(info["visible"])
    out = []
    for (start, stop), after in zip(np.asarray(info["hidden"]).reshape(-1, 2), info["after"], strict=True):
        first, last = min(start + lat, num_steps), min(stop + lat, num_steps)
        seen = np.flatnonzero(visible[last:]) + last
        if last <= first or seen.size == 0 or seen[0] + window > num_steps:
            continue
        out.append((np.arange(first, last), int(seen[0]), int(min(max(after + lat, seen[0] + 1), num_steps))))
    return out


def ball_track_xy(tracks) -> np.ndarray:
    """``[T, 2]`` the ball track's position (NaN where there is none): ``TrackTable.ball``, or, for a table without
    it, the valid track observed on most steps (where the hints of :class:`~heatpf_jax.injection.MemoryHints` go)."""
    valid = np.asarray(tracks.valid)
    mean = np.asarray(tracks.mean)[..., :2]
    if getattr(tracks, "ball", None) is not None:
        flag = np.asarray(tracks.ball) & valid
    else:
        hits = np.where(valid, np.asarray(tracks.hits), -1)
        flag = (np.arange(valid.shape[-1])[None] == np.argmax(hits, axis=-1)[:, None]) & valid
    out = np.full((valid.shape[0], 2), np.nan)
    t, m = np.nonzero(flag)
    out[t] = mean[t, m]
    return out


def score(mean, tracks, truth, info, window: int, radius: float = 0.3):
    """Per hiding ``(steps, ball_share, any_share, error_after)`` of one run (``tracks`` None without memory),
    against ``truth`` ``[T, 2]`` (:func:`apparent_ball`)."""
    rows = []
    err = np.linalg.norm(mean - truth, axis=-1)
    ball_xy = None if tracks is None else ball_track_xy(tracks)
    for hidden, back, after in hidings(info, truth.shape[0], window):
        hit = np.flatnonzero(err[back : back + window] < radius)
        steps = hit[0] + 1 if hit.size else window + 1
        if tracks is None:
            ball_share = any_share = np.nan
        else:
            ball_share = np.mean(np.linalg.norm(ball_xy[hidden] - truth[hidden], axis=-1) < 0.5)  # NaN: False
            d = np.linalg.norm(np.asarray(tracks.mean)[hidden, :, :2] - truth[hidden, None], axis=-1)
            any_share = np.mean(np.any(np.asarray(tracks.valid)[hidden] & (d < 0.5), axis=-1))
        rows.append((steps, ball_share, any_share, err[back:after].mean()))
    return rows


def evaluate(sequences, infos, method: str, memory: str, keys: int, window: int, settings=None, max_tracks=None):
    """Rows of :func:`score` over every sequence and filter key, and the seconds it took."""
    options = FilterOptions(memory=memory)
    if max_tracks is not None:
        options = options._replace(max_tracks=max_tracks)
    model, params = build(method, options)
    if settings:
        params = _set(model, params, settings)
    batch = jax.tree.map(lambda *x: np.stack(x), *[s._replace(ground_truth=None) for s in sequences])

    @jax.jit
    def runs(key):
        ks = jax.random.split(key, len(sequences))
        info = jax.vmap(lambda k, s: run(k, s, params, model).info)(ks, batch)
        return info.mean, info.tracks

    rows, start = [], time.perf_counter()
    for k in range(keys):
        mean, tracks = jax.device_get(runs(jax.random.key(k)))
        for i, (seq, info) in enumerate(zip(sequences, infos, strict=True)):
            one = None if memory == "none" else jax.tree.map(lambda x, i=i: x[i], tracks)
            rows += score(np.asarray(mean[i], np.float64), one, np.asarray(info["apparent"]), info, window)
    return np.array(rows, np.float64).reshape(-1, 4), time.perf_counter() - start


def _set(model, params, settings):
    from heatpf_jax import params as P

    return P.set_by_name(params, model.properties(), settings, skip_unknown=True)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0:20", help="START:STOP or N (default 0:20, the report's seeds)")
    parser.add_argument("--distractors", default="0,1,2", help="comma-separated blob counts (default 0,1,2)")
    parser.add_argument("--method", default="heatmap")
    parser.add_argument("--keys", type=int, default=2, help="filter keys per world (default 2)")
    parser.add_argument("--window", type=int, default=30, help="steps watched after reappearance (default 30)")
    parser.add_argument("--cache", default=str(Path.home() / ".cache" / "heatpf_jax" / "memory_distractors"),
                        help="directory for rendered worlds ('none': render every time)")
    parser.add_argument("--max-tracks", type=int, default=None, help="the memory's capacity (default: the preset's)")
    parser.add_argument("--memories", default="none,tracks", help="comma-separated: none, tracks (default both)")
    parser.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a parameter for the filter with memory (development)")
    args = parser.parse_args(argv)
    seeds = parse_seeds(args.seeds, 20)
    cache = None if args.cache == "none" else Path(os.path.expanduser(args.cache))
    settings = {k: float(v) for k, v in (s.split("=", 1) for s in args.set)}
    print(f"{MEMBER}, seeds {seeds.start}-{seeds.stop - 1}, {NUM_STEPS} steps, method {args.method}, "
          f"{args.keys} filter keys, window {args.window}" + (f", memory settings {settings}" if settings else ""))
    print(f"{'distractors':>11s} {'memory':7s} {'hidings':>7s} {'median steps':>12s} {'mean steps':>10s} "
          f"{'not found':>9s} {'ball track <0.5 m':>17s} {'any track <0.5 m':>16s} {'error after [m]':>15s} "
          f"{'time [s]':>8s}")
    for d in (int(x) for x in args.distractors.split(",")):
        worlds = [world(s, d, cache) for s in seeds]
        sequences, infos = [w[0] for w in worlds], [w[1] for w in worlds]
        medians = {}
        for memory in args.memories.split(","):
            rows, secs = evaluate(sequences, infos, args.method, memory, args.keys, args.window,
                                  settings if memory == "tracks" else None, args.max_tracks)
            steps = rows[:, 0]
            medians[memory] = np.median(steps)
            shares = ("-", "-") if memory == "none" else (f"{100 * np.mean(rows[:, 1]):.1f} %",
                                                        f"{100 * np.mean(rows[:, 2]):.1f} %")
            print(f"{d:11d} {memory:7s} {len(rows):7d} {np.median(steps):12.1f} {steps.mean():10.2f} "
                  f"{int(np.sum(steps > args.window)):9d} {shares[0]:>17s} {shares[1]:>16s} "
                  f"{np.mean(rows[:, 3]):15.4f} {secs:8.1f}", flush=True)
        if len(medians) == 2:
            print(f"{'':11s} ratio of medians (memory / none): {medians['tracks'] / medians['none']:.2f}")
        jax.clear_caches()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
