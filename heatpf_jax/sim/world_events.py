"""Random signals and on/off events for the simulated worlds.

:func:`smooth_signal` (a smooth random signal in ``[-1, 1]``) shapes paths, poses and effects;
:func:`bursty_mask` (bursts of on and off) and :func:`random_windows` (non-overlapping windows) decide when
something is on or happens. :mod:`heatpf_jax.sim.world` re-exports them. NumPy only.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bursty_mask", "random_windows", "smooth_signal"]


def smooth_signal(
    rng: np.random.Generator, num_steps: int, dt: float, *, freqs=(0.05, 0.35), terms: int = 3
) -> np.ndarray:
    """A smooth random signal in ``[-1, 1]``: ``terms`` sinusoids with weights summing to 1.

    Returns:
        ``float64 [num_steps]``.
    """
    t = np.arange(num_steps) * dt
    amps = rng.uniform(0.2, 1.0, terms)
    amps = amps / amps.sum()
    f = rng.uniform(freqs[0], freqs[1], terms)
    phases = rng.uniform(0, 2 * np.pi, terms)
    return (amps[:, None] * np.sin(2 * np.pi * f[:, None] * t + phases[:, None])).sum(0)


# --- Random events ------------------------------------------------------------------------------------------------


def bursty_mask(rng: np.random.Generator, num_steps: int, on_fraction: float, mean_on_steps: float) -> np.ndarray:
    """A two-state Markov chain: on for bursts of mean length ``mean_on_steps``, on ``on_fraction`` of the time.

    The chain starts from its stationary distribution.

    Returns:
        ``bool [num_steps]``.
    """
    on_fraction = float(np.clip(on_fraction, 1e-3, 1 - 1e-3))
    p_off = 1.0 / max(mean_on_steps, 1.0)  # on -> off
    p_on = min(p_off * on_fraction / (1.0 - on_fraction), 1.0)  # off -> on
    u = rng.uniform(size=num_steps)
    out = np.zeros(num_steps, bool)
    state = u[0] < on_fraction
    for t in range(num_steps):
        if t > 0:
            state = (u[t] >= p_off) if state else (u[t] < p_on)
        out[t] = state
    return out


def random_windows(
    rng: np.random.Generator,
    num_steps: int,
    count: int,
    length_range: tuple[int, int],
    *,
    min_gap: int,
    start_after: int,
) -> list[tuple[int, int]]:
    """Non-overlapping windows ``[start, stop)`` of random integer lengths in ``length_range`` (inclusive).

    Windows start at or after ``start_after``, are separated by at least ``min_gap`` steps and end by
    ``num_steps``; windows that do not fit are dropped (the last ones first).
    """
    lengths = list(rng.integers(length_range[0], length_range[1] + 1, size=count))
    while lengths and start_after + sum(lengths) + min_gap * (len(lengths) - 1) > num_steps:
        lengths.pop()
    if not lengths:
        return []
    slack = num_steps - start_after - sum(lengths) - min_gap * (len(lengths) - 1)
    # Spread the slack at random over the len + 1 gaps (before, between, after).
    cuts = np.sort(rng.integers(0, slack + 1, size=len(lengths)))
    windows, pos, used = [], start_after, 0
    for i, (length, cut) in enumerate(zip(lengths, cuts, strict=True)):
        pos += int(cut) - used + (min_gap if i else 0)
        used = int(cut)
        windows.append((pos, pos + int(length)))
        pos += int(length)
    return windows
