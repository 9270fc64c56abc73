"""The paper's comparison (Table I, Fig. 4, Fig. 6) on simulated scenarios or a user's recording.

Every method is a named preset (:mod:`heatpf_jax.presets`) run through the same
:func:`heatpf_jax.run` on the same sequences; settings given by name apply to every
method that has a parameter of that name. Seeds of one scenario share shapes, so
each method runs all seeds in one ``vmap`` and compiles once.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path

import jax
import numpy as np

from heatpf_jax import params as P
from heatpf_jax.io.files import write_atomic
from heatpf_jax.io.sequence import Sequence
from heatpf_jax.presets import FilterOptions, build
from heatpf_jax.rollout import run

__all__ = [
    "DEFAULT_BURN_IN",
    "DEFAULT_VARIANTS",
    "MethodResult",
    "ScenarioResult",
    "Variant",
    "evaluate_sequences",
    "factor_breakdown",
    "format_table",
    "mode_coverage",
    "plot_scenario",
    "radial_lateral",
]


@dataclass(frozen=True)
class Variant:
    """A named way to run a method (a name in ``heatpf_jax.presets.METHODS``) with parameter changes by name."""

    name: str
    method: str
    overrides: dict = field(default_factory=dict)


DEFAULT_BURN_IN = 10  # steps left out of every error statistic (the filter converging from its prior)

DEFAULT_VARIANTS = (
    Variant("heatmap", "heatmap"),
    Variant("conventional", "conventional"),
    Variant("kalman", "kalman"),
    Variant("bitbots2018", "bitbots2018"),
    Variant("paper", "paper"),
    Variant("extended", "extended"),
    # Aging ablations of the paper's filter (III-C): measurements that never age, and that die at once.
    Variant("paper, no aging (v=0, l=0)", "paper", {"aging": 0.0, "min_weight": 0.0}),
    Variant("paper, v=1 (no memory)", "paper", {"aging": 1.0}),
)


@dataclass
class MethodResult:
    """Estimates and errors of one variant on every sequence of a scenario."""

    variant: Variant
    estimates: np.ndarray  # [S, T, 2]
    errors: np.ndarray  # [S, T] Euclidean error, metres
    radial: np.ndarray | None = None  # [S, T] signed error along the ray from the robot to the object, metres
    lateral: np.ndarray | None = None  # [S, T] signed error across that ray (to the left), metres

    def stats(self, burn_in: int, end_steps: int = 30) -> dict[str, float]:
        """Mean, max, std of the error after ``burn_in``; ``end``: mean error of the last ``end_steps``
        steps of each sequence (a filter that diverged for good shows it there); ``radial`` and ``lateral``:
        the root-mean-square of the error's parts along and across the ray from the robot (when known)."""
        e = self.errors[:, burn_in:].ravel()
        end = self.errors[:, -min(end_steps, self.errors.shape[1]) :]
        out = {"mean": float(e.mean()), "max": float(e.max()), "std": float(e.std()), "end": float(end.mean())}
        if self.radial is not None and self.lateral is not None:
            out["radial"] = float(np.sqrt(np.mean(np.square(self.radial[:, burn_in:]))))
            out["lateral"] = float(np.sqrt(np.mean(np.square(self.lateral[:, burn_in:]))))
        return out


@dataclass
class ScenarioResult:
    name: str
    truth: np.ndarray  # [S, T, 2]
    methods: list[MethodResult]
    burn_in: int
    num_objects: int = 1  # errors are to the nearest of this many objects (two_balls: 2)

    def by_name(self, name: str) -> MethodResult | None:
        return next((m for m in self.methods if m.variant.name == name), None)


def _stack(sequences: list[Sequence]) -> Sequence:
    shapes = {s.heatmaps.shape for s in sequences}
    if len(shapes) != 1:
        raise ValueError(f"sequences: seeds of one scenario must share shapes, got {sorted(shapes)}")
    fields = {}
    for name in Sequence._fields:
        values = [getattr(s, name) for s in sequences]
        if name == "settings":  # not an array: kept where every sequence has the same
            fields[name] = values[0] if all(v == values[0] for v in values) else None
            continue
        fields[name] = None if any(v is None for v in values) else np.stack(values)
    return Sequence(**fields)


def evaluate_sequences(
    name: str,
    sequences: list[Sequence],
    *,
    options: FilterOptions = FilterOptions(),
    settings: dict | None = None,
    variants: Iterable[Variant] = DEFAULT_VARIANTS,
    seed: int = 0,
    burn_in: int = DEFAULT_BURN_IN,
    progress: Callable[[str], None] | None = None,
    targets: list[np.ndarray] | None = None,
) -> ScenarioResult:
    """Runs every variant on every sequence (with ground truth) of one scenario.

    Args:
        name: scenario name, for the table.
        sequences: sequences of equal shapes, each with ``ground_truth``.
        options: the static choices shared by every method (each preset takes those that apply).
        settings: ``{name: value}`` parameters shared by every method that has them; each
            variant applies its own overrides on top.
        variants: what to run.
        seed: PRNG seed; sequence i uses key ``fold_in(key(seed), i)`` for every variant.
        burn_in: steps excluded from the statistics (convergence from the initial prior).
        progress: called with a label after each variant.
        targets: per sequence ``[T, B, 2]``, every object the tracker may follow (``two_balls``: both
            balls, ``simulate_with_info``'s ``balls_base``): the error is then the distance to the
            nearest of them. Default: ``ground_truth`` alone.

    Returns:
        :class:`ScenarioResult`.
    """
    for i, s in enumerate(sequences):
        if s.ground_truth is None:
            raise ValueError(f"ground_truth: sequence {i} of {name!r} has none; the comparison needs it")
    if burn_in >= sequences[0].num_steps:
        raise ValueError(f"burn_in: {burn_in} leaves no step of the {sequences[0].num_steps}-step sequences")
    batch = _stack(sequences)
    truth = np.asarray(batch.ground_truth, np.float64)
    objects = truth[:, :, None, :] if targets is None else np.stack([np.asarray(t, np.float64) for t in targets])
    if objects.shape[:2] != truth.shape[:2] or objects.shape[-1] != 2:
        raise ValueError(f"targets: expected [T, B, 2] per sequence, got {objects.shape[1:]}")
    batch = batch._replace(ground_truth=None, stamps=None, settings=None)
    keys = jax.vmap(lambda i: jax.random.fold_in(jax.random.key(seed), i))(np.arange(len(sequences)))
    results = []
    for variant in variants:
        model, p = build(variant.method, options)
        p = P.set_by_name(p, model.properties(), settings or {}, skip_unknown=True)
        p = P.set_by_name(p, model.properties(), variant.overrides)
        out = jax.vmap(lambda k, s, p=p, m=model: run(k, s, p, m).info.mean)(keys, batch)
        est = np.asarray(out, np.float64)
        if not np.all(np.isfinite(est)):
            raise RuntimeError(f"{variant.name}: non-finite estimate on scenario {name!r}; please report this")
        distances = np.linalg.norm(est[:, :, None, :] - objects, axis=-1)
        nearest = np.take_along_axis(objects, np.argmin(distances, axis=-1)[:, :, None, None], axis=2)[:, :, 0]
        radial, lateral = radial_lateral(est, nearest)
        results.append(MethodResult(variant, est, np.min(distances, axis=-1), radial, lateral))
        if progress is not None:
            progress(f"{name}: {variant.name}")
    return ScenarioResult(name=name, truth=truth, methods=results, burn_in=burn_in, num_objects=objects.shape[2])


def radial_lateral(estimates: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The error ``estimates - truth`` ``[..., 2]`` split along and across the ray from the robot (the base
    frame's origin) to the truth: ``(radial, lateral)``, each ``[...]``, signed (radial: beyond the object is
    positive; lateral: to the left of the ray is positive). At the origin itself the ray is taken along x."""
    estimates, truth = np.asarray(estimates, np.float64), np.asarray(truth, np.float64)
    norm = np.linalg.norm(truth, axis=-1, keepdims=True)
    ray = np.where(norm > 1e-9, truth / np.where(norm > 1e-9, norm, 1.0), np.array([1.0, 0.0]))
    d = estimates - truth
    return np.sum(d * ray, axis=-1), ray[..., 0] * d[..., 1] - ray[..., 1] * d[..., 0]


def mode_coverage(
    mode_mean: np.ndarray, mode_valid: np.ndarray, objects: np.ndarray, radius: float = 0.3
) -> np.ndarray:
    """Per step, whether every object is within ``radius`` of a valid mode.

    Args:
        mode_mean: ``[..., T, K, 2]`` mode means (``StepInfo.modes.mean``).
        mode_valid: ``bool [..., T, K]``.
        objects: ``[..., T, B, 2]`` the objects (``balls_base``).
        radius: metres.

    Returns:
        ``bool [..., T]``.
    """
    d = np.linalg.norm(np.asarray(objects)[..., :, None, :] - np.asarray(mode_mean)[..., None, :, :], axis=-1)
    d = np.where(np.asarray(mode_valid)[..., None, :], d, np.inf)  # [..., T, B, K]
    return np.all(np.min(d, axis=-1) <= radius, axis=-1)


def factor_breakdown(result: ScenarioResult, factors: list[dict]) -> str:
    """Each method's mean error on the sequences whose factor is low against those where it is high.

    Args:
        result: the comparison on ``S`` sequences of one family member.
        factors: per sequence, its drawn nuisance factors (``info["factors"]`` of
            :func:`~heatpf_jax.sim.family.simulate_family_with_info`).

    Returns:
        One line per numeric factor that varies over the sequences: the factor's median, and per method the
        mean error (after the burn-in) on the sequences at or below it and on those above it. A factor that
        splits a method's error far apart is one the method is sensitive to. Empty without factors.
    """
    per_seq = {m.variant.name: m.errors[:, result.burn_in :].mean(axis=1) for m in result.methods}
    names = [n for n in (factors[0] if factors else {}) if all(n in f for f in factors)]
    lines = []
    for name in names:
        values = [factors[i][name] for i in range(len(factors))]
        if not all(isinstance(v, int | float | np.number) and not isinstance(v, bool) for v in values):
            continue
        values = np.asarray(values, np.float64)
        median = float(np.median(values))
        low, high = values <= median, values > median
        if not low.any() or not high.any():
            continue
        cells = "  ".join(f"{m} {e[low].mean():.3f}/{e[high].mean():.3f}" for m, e in per_seq.items())
        lines.append(f"  {name:<24} <= {median:<9.4g} {cells}")
    if not lines:
        return f"{result.name}: no factor varies over these sequences"
    return f"{result.name}: mean error [m] with the factor at or below / above its median\n" + "\n".join(lines)


def format_table(result: ScenarioResult, reference: str = "conventional") -> str:
    """The paper's Table I for one scenario, with ratios to ``reference``."""
    ref = result.by_name(reference)
    ref_stats = ref.stats(result.burn_in) if ref is not None else None
    s, t = result.truth.shape[:2]
    lines = [
        f"scenario {result.name}: {s} sequence(s) x {t} steps, errors after step {result.burn_in}"
        + (f" (to the nearest of {result.num_objects} balls)" if result.num_objects > 1 else ""),
        f"{'method':<30} {'mean [m]':>9} {'max [m]':>9} {'std [m]':>9} {'mean/' + reference:>18} {'last 30 [m]':>13}"
        f" {'radial rms':>11} {'lateral rms':>12}",
    ]
    for m in result.methods:
        st = m.stats(result.burn_in)
        ratio = f"{st['mean'] / ref_stats['mean']:.3f}" if ref_stats else "-"
        split = f" {st['radial']:11.4f} {st['lateral']:12.4f}" if "radial" in st else f" {'-':>11} {'-':>12}"
        lines.append(
            f"{m.variant.name:<30} {st['mean']:9.4f} {st['max']:9.3f} {st['std']:9.4f} {ratio:>18} {st['end']:13.4f}"
            + split
        )
    return "\n".join(lines)


def plot_scenario(result: ScenarioResult, directory: str | Path) -> list[Path]:
    """Writes Fig. 4 (error histograms per method) and Fig. 6 (traces of the first sequence) as PNG.

    Raises:
        RuntimeError: matplotlib is not installed (``pip install "heatpf-jax[plot]"``).
    """
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        raise RuntimeError('--plot needs matplotlib: pip install "heatpf-jax[plot]"') from None
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    colours = {"heatmap": "tab:red", "conventional": "tab:blue", "kalman": "tab:purple", "bitbots2018": "tab:orange"}
    # The four methods of the paper's figures when they were run; otherwise every method that was.
    shown = [m for m in result.methods if m.variant.name in colours] or list(result.methods)
    others = iter(["tab:brown", "tab:pink", "tab:gray", "tab:olive", "tab:cyan"] * 4)
    for m in shown:
        colours.setdefault(m.variant.name, next(others))
    b = result.burn_in

    fig, ax = plt.subplots(figsize=(6, 4))
    top = max(float(np.percentile(m.errors[:, b:], 99.5)) for m in shown)
    bins = np.linspace(0.0, max(top, 1e-3), 40)
    for m in shown:
        ax.hist(m.errors[:, b:].ravel(), bins=bins, alpha=0.5, label=m.variant.name, color=colours[m.variant.name])
    ax.set_xlabel("error [m]")
    ax.set_ylabel("steps")
    ax.set_title(f"{result.name}: error distribution (Fig. 4)")
    ax.legend()
    hist_path = directory / f"{result.name}_errors.png"
    fig.tight_layout()
    write_atomic(hist_path, lambda fh: fig.savefig(fh, format="png", dpi=100), binary=True)
    plt.close(fig)

    fig, ax = plt.subplots(figsize=(6, 5))
    ax.plot(result.truth[0, b:, 1], result.truth[0, b:, 0], color="tab:green", label="ground truth", lw=2)
    for m in shown:
        ax.plot(m.estimates[0, b:, 1], m.estimates[0, b:, 0], color=colours[m.variant.name], label=m.variant.name, lw=1)
    ax.set_xlabel("y [m] (left)")
    ax.set_ylabel("x [m] (forward)")
    ax.invert_xaxis()
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_title(f"{result.name}: traces in the base frame (Fig. 6)")
    ax.legend()
    trace_path = directory / f"{result.name}_traces.png"
    fig.tight_layout()
    write_atomic(trace_path, lambda fh: fig.savefig(fh, format="png", dpi=100), binary=True)
    plt.close(fig)
    return [hist_path, trace_path]
