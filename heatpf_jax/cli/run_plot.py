"""``heatpf run --plot``: one picture of a run, the estimate over time and one step's particles (Fig. 1c).

Four panels: the estimate's trace on the ground plane in the base frame (with the ground truth where the
sequence has it), the error and the estimate's spread over time, the heat map of one step, and that step
on the ground plane: the buffered measurements coloured by weight, the particles (darker: heavier), the
estimate with its 2-sigma ellipse and the ground truth (the paper's Fig. 1c). The step's particles and
buffer are the state of the same run at that step (:func:`state_at`: a :class:`~heatpf_jax.tracker.Tracker`
with ``run``'s keys fed the sequence up to it), so the picture shows what the estimates in the CSV came from.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from jaxtyping import Float

from heatpf_jax.io.files import write_atomic

__all__ = ["default_step", "plot_run", "state_at"]


def default_step(has_heatmap: np.ndarray) -> int:
    """The last step with a heat map (the last step when there is none)."""
    steps = np.flatnonzero(np.asarray(has_heatmap))
    return int(steps[-1]) if steps.size else len(has_heatmap) - 1


def state_at(key, seq, params, model, step: int):
    """The model's state after ``step`` (0-based) in ``hp.run(key, seq, params, model)``: the same keys, the
    same inputs, one tick at a time (:class:`~heatpf_jax.tracker.Tracker` with ``num_steps = T``)."""
    from heatpf_jax.tracker import Tracker

    tracker = Tracker(key, model, params, heatmap_shape=tuple(seq.heatmaps.shape[1:]), intrinsics=seq.intrinsics,
                      plane_height=float(seq.ball_radius), dt=float(seq.dt), num_steps=seq.num_steps)
    pose = seq.robot_pose is not None and "robot_pose" in getattr(model, "requires", ())
    for t in range(step + 1):
        heat = seq.heatmaps[t] if seq.has_heatmap[t] else None
        extra = {}
        if pose:
            extra = {"robot_pose": seq.robot_pose[t],
                     "pose_confidence": 1.0 if seq.pose_confidence is None else float(seq.pose_confidence[t])}
        tracker.update(heat, seq.cam_to_base[t], seq.odometry[t], **extra)
    return tracker.state


def _ellipse(mean, cov, sigmas: float = 2.0) -> np.ndarray:
    """``[65, 2]`` points of the ``sigmas`` ellipse of a 2-D Gaussian."""
    vals, vecs = np.linalg.eigh(np.asarray(cov, np.float64))
    angle = np.linspace(0.0, 2.0 * np.pi, 65)
    circle = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    return np.asarray(mean, np.float64) + sigmas * (circle * np.sqrt(np.maximum(vals, 0.0))) @ vecs.T


def plot_run(
    path: str | Path,
    seq,
    mean: Float[np.ndarray, "t 2"],
    cov: Float[np.ndarray, "t 2 2"],
    step: int,
    state=None,
    *,
    title: str = "",
    burn_in: int = 10,
) -> Path:
    """Writes the run's picture as a PNG (atomically; see the module docstring).

    Args:
        path: the PNG file.
        seq: the :class:`~heatpf_jax.io.sequence.Sequence` that was run.
        mean, cov: the run's estimates and covariances, per step.
        step: the step whose heat map and particles are drawn.
        state: the model's state after ``step`` (:func:`state_at`); its ``particles.xy``, ``log_weights`` and
            ``buffer`` are drawn where it has them (a Kalman filter has none: only its estimate).
        title: the figure's title.
        burn_in: steps left out of the error statistics (drawn, but shaded).

    Raises:
        RuntimeError: matplotlib is not installed.
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"') from None
    mean, cov = np.asarray(mean, np.float64), np.asarray(cov, np.float64)
    truth = None if seq.ground_truth is None else np.asarray(seq.ground_truth, np.float64)
    time_s = np.arange(seq.num_steps) * float(seq.dt)
    fig, axes = plt.subplots(2, 2, figsize=(12, 9))
    (trace_ax, time_ax), (heat_ax, step_ax) = axes

    # The trace on the ground plane: y to the left, x forward (as a robot's camera sees it).
    if truth is not None:
        trace_ax.plot(truth[:, 1], truth[:, 0], color="tab:green", lw=2, label="ground truth")
    trace_ax.plot(mean[:, 1], mean[:, 0], color="tab:red", lw=1, label="estimate")
    trace_ax.plot(mean[step, 1], mean[step, 0], "o", color="k", ms=5, label=f"step {step}")
    trace_ax.set_xlabel("y [m] (left)")
    trace_ax.set_ylabel("x [m] (forward)")
    trace_ax.invert_xaxis()
    trace_ax.set_aspect("equal", adjustable="datalim")
    trace_ax.set_title("estimate in the base frame")
    trace_ax.legend(fontsize=8)

    # Error and spread over time.
    spread = np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, -1], 0.0))
    if truth is not None:
        error = np.linalg.norm(mean - truth, axis=1)
        time_ax.plot(time_s, error, color="tab:red", lw=1, label="error [m]")
    time_ax.plot(time_s, spread, color="tab:blue", lw=1, label="largest std of the covariance [m]")
    time_ax.axvspan(0.0, burn_in * float(seq.dt), color="0.9", label=f"burn-in ({burn_in} steps)")
    time_ax.axvline(step * float(seq.dt), color="k", lw=0.8)
    missing = np.flatnonzero(~np.asarray(seq.has_heatmap, bool))
    if missing.size:
        time_ax.plot(time_s[missing], np.zeros(missing.size), "|", color="0.5", label="no heat map")
    time_ax.set_xlabel("time [s]")
    time_ax.set_ylabel("metres")
    time_ax.set_title("error and spread over time")
    time_ax.legend(fontsize=8)

    heat_ax.imshow(np.asarray(seq.heatmaps[step]), cmap="magma", vmin=0.0, vmax=1.0, interpolation="nearest")
    heat_ax.set_title(f"heat map, step {step}" + ("" if seq.has_heatmap[step] else " (none arrived: zeros)"))
    heat_ax.set_xlabel("u [px]")
    heat_ax.set_ylabel("v [px]")

    # The step on the ground plane (Fig. 1c).
    buffer = getattr(state, "buffer", None)
    if buffer is not None:
        valid = np.asarray(buffer.valid, bool)
        xy, w = np.asarray(buffer.xy)[valid], np.asarray(buffer.weight)[valid]
        shown = step_ax.scatter(xy[:, 1], xy[:, 0], c=w, cmap="viridis", s=6, vmin=0.0,
                                vmax=max(float(w.max()) if w.size else 1.0, 1e-6), label="measurements")
        fig.colorbar(shown, ax=step_ax, fraction=0.04, pad=0.02, label="measurement weight")
    particles = getattr(getattr(state, "particles", None), "xy", None)
    if particles is not None:
        p = np.asarray(particles)
        lw = np.asarray(state.log_weights, np.float64)
        alpha = np.exp(lw - lw.max())
        colours = np.zeros((p.shape[0], 4))
        colours[:, 3] = 0.15 + 0.85 * alpha
        step_ax.scatter(p[:, 1], p[:, 0], s=4, color=colours, label="particles")
    ellipse = _ellipse(mean[step], cov[step])
    step_ax.plot(ellipse[:, 1], ellipse[:, 0], color="tab:red", lw=1, label="estimate, 2 sigma")
    step_ax.plot(mean[step, 1], mean[step, 0], "+", color="tab:red", ms=10)
    if truth is not None:
        step_ax.plot(truth[step, 1], truth[step, 0], "x", color="tab:green", ms=9, mew=2, label="ground truth")
    # Zoomed on what the estimate came from: the measurements, the estimate's ellipse and the truth (explorer
    # particles far from them are left out of the view, and counted).
    keep = [ellipse]
    if buffer is not None and valid.any():
        keep.append(xy)
    if truth is not None:
        keep.append(truth[step][None])
    lo, hi = np.min(np.concatenate(keep), axis=0) - 0.3, np.max(np.concatenate(keep), axis=0) + 0.3
    centre, half = (lo + hi) / 2.0, np.max(hi - lo) / 2.0  # a square view
    lo, hi = centre - half, centre + half
    step_ax.set_xlim(hi[1], lo[1])  # y to the left
    step_ax.set_ylim(lo[0], hi[0])
    outside = 0 if particles is None else int(np.sum(np.any((p < lo) | (p > hi), axis=1)))
    step_ax.set_xlabel("y [m] (left)")
    step_ax.set_ylabel("x [m] (forward)")
    step_ax.set_aspect("equal", adjustable="box")
    step_ax.set_title(f"step {step}, ground plane" + (f" ({outside} particles out of view)" if outside else ""))
    step_ax.legend(fontsize=8, loc="best")

    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    try:
        write_atomic(path, lambda fh: fig.savefig(fh, format="png", dpi=90), binary=True)
    finally:
        plt.close(fig)
    return path
