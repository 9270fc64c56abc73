"""Helpers shared by the benchmark scripts (imported as a sibling module: run the scripts by path)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import jax
import numpy as np

__all__ = ["first_call", "interleaved_times", "parse_sizes", "positive_int", "stats_ms"]


def positive_int(text: str) -> int:
    """argparse type: a positive integer."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def parse_sizes(text: str, max_measurements: int | None = None) -> list[tuple[int, int]]:
    """argparse type: comma-separated ``PxM`` sizes (particles x measurements), e.g. ``500x1024,1000x4096``."""
    sizes = []
    for item in text.split(","):
        try:
            p, m = (int(v) for v in item.lower().split("x"))
        except ValueError as err:
            raise argparse.ArgumentTypeError(f"size {item!r}: expected PxM, e.g. 500x1024") from err
        limit = max_measurements if max_measurements is not None else m
        if p < 1 or m < 1 or m > limit:
            raise argparse.ArgumentTypeError(f"size {item!r}: need P >= 1 and 1 <= M <= {limit}")
        sizes.append((p, m))
    return sizes


def first_call(fn: Callable[[], object]) -> float:
    """Seconds of a first (compiling) call."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn())
    return time.perf_counter() - t0


def interleaved_times(
    calls: dict[str, Callable[[jax.Array], object]], key: jax.Array, repeats: int, warmup: int = 3
) -> dict[str, np.ndarray]:
    """Seconds of each call per round, one call of each per round (so that a noisy machine slows them alike).

    Round ``i`` passes ``keys[i]`` of ``jax.random.split(key, warmup + repeats)`` to every call; the first ``warmup``
    rounds are not timed. Returns ``{name: [repeats] seconds}``.
    """
    keys = jax.random.split(key, warmup + repeats)
    times = {name: [] for name in calls}
    for i in range(warmup + repeats):
        for name, call in calls.items():
            t0 = time.perf_counter()
            jax.block_until_ready(call(keys[i]))
            if i >= warmup:
                times[name].append(time.perf_counter() - t0)
    return {name: np.asarray(t) for name, t in times.items()}


def stats_ms(times: np.ndarray) -> tuple[float, float]:
    """Median and interquartile range of times in seconds, as milliseconds."""
    q1, med, q3 = np.percentile(times, [25, 50, 75])
    return 1e3 * med, 1e3 * (q3 - q1)
