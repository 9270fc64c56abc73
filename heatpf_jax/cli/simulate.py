"""``heatpf simulate`` and ``heatpf frame``: an input from the command line, and one frame to read a box off.

    heatpf simulate SCENARIO [--seed N] [--steps N] [--shrink N] [--rgb] --output X.npz
    heatpf simulate MEMBER --family [--seed N] [--steps N] --output X.npz
    heatpf frame X.npz --step N --output frame.png [--heatmap]

``simulate`` writes one simulated world as a sequence file: a scenario of :mod:`heatpf_jax.sim.scenarios`
(with ``--rgb`` its RGB frames too, for ``heatpf colour``), or with ``--family`` a world of the family
(:mod:`heatpf_jax.sim.family`, its nuisance factors drawn from the seed). ``frame`` draws one RGB frame (or,
with ``--heatmap``, the heat map) of a sequence with a pixel grid, labelled in pixels, so that a user can read
off the ``x,y,w,h`` box around the ball that ``heatpf colour --box`` asks for. Both check every argument before
any work and never replace a file without ``--force``.
"""

from __future__ import annotations

import argparse
import importlib.util
from pathlib import Path

import numpy as np

from heatpf_jax.io.files import check_input, check_output, write_atomic

__all__ = ["add_parsers", "cmd_frame", "cmd_simulate", "draw_frame"]

_PLOT_EXTRA = 'needs matplotlib: pip install "heatpf-jax[plot]"'


def _names(family: bool) -> tuple[str, ...]:
    if family:
        from heatpf_jax.sim.family import FAMILY

        return tuple(FAMILY)
    from heatpf_jax.sim.scenarios import SCENARIOS

    return tuple(SCENARIOS)


def cmd_simulate(args: argparse.Namespace) -> int:
    from heatpf_jax.io.sequence import save_sequence

    names = _names(args.family)
    if args.name not in names:
        what = "family member" if args.family else "scenario"
        raise ValueError(f"scenario: unknown {what} {args.name!r}; valid names: {', '.join(names)}")
    if args.family and args.rgb:
        raise ValueError("--rgb: RGB frames are rendered for the fixed scenarios only, not with --family")
    if args.steps is not None and args.steps < 1:
        raise ValueError(f"--steps: must be a positive integer, got {args.steps}")
    if args.seed < 0:
        raise ValueError(f"--seed: must be >= 0, got {args.seed}")
    if args.shrink < 1:
        raise ValueError(f"--shrink: must be a positive integer, got {args.shrink}")
    out = check_output("--output", args.output, replace=args.force)
    if args.family:
        from heatpf_jax.sim.family import simulate_family

        seq = simulate_family(args.name, args.seed, num_steps=args.steps, shrink=args.shrink)
        label = f"family/{args.name}"
    else:
        from heatpf_jax.sim.scenarios import simulate

        seq = simulate(args.name, args.seed, num_steps=args.steps, shrink=args.shrink, rgb=args.rgb)
        label = args.name
    save_sequence(out, seq)
    height, width = seq.heatmaps.shape[1:]
    extra = ", RGB frames" if seq.images is not None else ""
    print(f"{label}, seed {args.seed}: {seq.num_steps} steps of {seq.dt:g} s, heat maps {width} x {height}{extra}, "
          "ground truth")
    print(f"wrote {out}")
    return 0


def draw_frame(image: np.ndarray, *, title: str = "", grid: int | None = None):
    """A matplotlib figure of one frame (``[H, W, 3]`` uint8 RGB, or ``[H, W]`` activations in ``[0, 1]``)
    in pixel coordinates: one figure pixel per image pixel scaled up, a grid line every ``grid`` pixels
    (default: about twenty across the width, a multiple of 5), labelled ticks on both axes, and each pixel's centre
    at its integer coordinates (``x`` the column, ``y`` the row), as ``--box x,y,w,h`` counts them.

    Raises:
        RuntimeError: matplotlib is not installed.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError(f"frame {_PLOT_EXTRA}") from None
    height, width = image.shape[:2]
    if grid is None:
        grid = max(5, int(round(width / 20 / 5)) * 5)
    scale = max(1.0, 900.0 / width) / 100.0  # about 900 pixels across
    fig, ax = plt.subplots(figsize=(width * scale + 1.2, height * scale + 0.9), dpi=100)
    if image.ndim == 2:
        shown = ax.imshow(image, cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest")
        fig.colorbar(shown, ax=ax, fraction=0.03, pad=0.02, label="activation")
    else:
        ax.imshow(image, interpolation="nearest")
    ticks = np.arange(0, max(width, height) + 1, grid)
    ax.set_xticks(ticks[ticks < width])
    ax.set_yticks(ticks[ticks < height])
    ax.set_xticks(np.arange(0, width, 1), minor=True)
    ax.set_yticks(np.arange(0, height, 1), minor=True)
    ax.grid(which="major", color="cyan", linewidth=0.6, alpha=0.7)
    ax.tick_params(which="minor", length=2)
    ax.tick_params(top=True, labeltop=True, right=True, labelright=True, labelsize=7)
    ax.set_xlim(-0.5, width - 0.5)
    ax.set_ylim(height - 0.5, -0.5)
    ax.set_xlabel("x (column, pixels)")
    ax.set_ylabel("y (row, pixels)")
    if title:
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    return fig


def cmd_frame(args: argparse.Namespace) -> int:
    from heatpf_jax.io.sequence import load_sequence

    check_input(args.input)
    out = check_output("--output", args.output, inputs=(args.input,), replace=args.force)
    if importlib.util.find_spec("matplotlib") is None:
        raise RuntimeError(f"frame {_PLOT_EXTRA}")
    if args.grid is not None and args.grid < 1:
        raise ValueError(f"--grid: must be a positive integer, got {args.grid}")
    seq = load_sequence(args.input)
    if not 0 <= args.step < seq.num_steps:
        raise ValueError(f"--step: must be in [0, {seq.num_steps - 1}], got {args.step}")
    if args.heatmap:
        image = np.asarray(seq.heatmaps[args.step], np.float32)
        what = "heat map" + ("" if seq.has_heatmap[args.step] else " (none arrived at this step: zeros)")
    else:
        if seq.images is None:
            raise ValueError(f"--step: {args.input} holds no RGB frames (images); pass --heatmap for its heat maps")
        image = np.asarray(seq.images[args.step])
        what = "RGB frame"
    height, width = image.shape[:2]
    fig = draw_frame(image, title=f"{Path(args.input).name}, step {args.step}: {what}", grid=args.grid)
    import matplotlib.pyplot as plt

    try:
        write_atomic(out, lambda fh: fig.savefig(fh, format="png"), binary=True)
    finally:
        plt.close(fig)
    print(f"{args.input}, step {args.step}: {what}, {width} x {height} pixels (x: column, y: row; a box is "
          "x,y,w,h with x,y its top-left pixel)")
    print(f"wrote {out}")
    return 0


def add_parsers(sub, parent: list[argparse.ArgumentParser]) -> None:
    """Adds ``simulate`` and ``frame`` to the ``heatpf`` command's subparsers."""
    p = sub.add_parser(
        "simulate", parents=parent, help="write a simulated world as a sequence file (a scenario, or a family world)",
        epilog="Then e.g. heatpf run X.npz --output est.csv, or with --rgb: heatpf frame X.npz --step 0 --output "
               "f.png to find the ball's box, and heatpf colour X.npz --box x,y,w,h --frame 0 --output colour.npz.",
    )
    p.add_argument("name", metavar="SCENARIO", help="a scenario (standard, false_positives, split, occlusion, "
                   "walking, sparse_rate, far, two_balls, shot, turning), or with --family a family member")
    p.add_argument("--family", action="store_true", help="a world of the family (heatpf_jax.sim.family): the "
                   "scenario type with its nuisance factors drawn from the seed (also lofted, kicked_hidden)")
    p.add_argument("--seed", type=int, default=0, help="the world's seed (default 0)")
    p.add_argument("--steps", type=int, default=None, help="filter steps (default: the scenario's, 300)")
    p.add_argument("--shrink", type=int, default=1, help="divide the heat map's size by this (default 1)")
    p.add_argument("--rgb", action="store_true", help="also render RGB frames (images), for heatpf colour")
    p.add_argument("--output", "-o", required=True, help="the sequence file (not replaced unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser(
        "frame", parents=parent, help="draw one RGB frame or heat map of a sequence with a pixel grid (PNG)",
        epilog="Read the ball's box x,y,w,h off the grid for heatpf colour --box x,y,w,h --frame N.",
    )
    p.add_argument("input", help="sequence file (.npz, version 1)")
    p.add_argument("--step", type=int, required=True, help="the step (frame) to draw")
    p.add_argument("--heatmap", action="store_true", help="draw the heat map instead of the RGB frame")
    p.add_argument("--grid", type=int, default=None, help="grid spacing, pixels (default: about 20 lines across)")
    p.add_argument("--output", "-o", required=True, help="the PNG file (not replaced unless --force)")
    p.add_argument("--force", action="store_true", help="replace an existing --output")
    p.set_defaults(func=cmd_frame)
