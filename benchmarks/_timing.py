"""Helpers shared by the benchmark scripts (imported as a sibling module: run the scripts by path)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import jax
import numpy as np

__all__ = ["first_call", "parse_sizes", "positive_int", "stats_ms"]


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


def stats_ms(times: np.ndarray) -> tuple[float, float]:
    """Median and interquartile range of times in seconds, as milliseconds."""
    q1, med, q3 = np.percentile(times, [25, 50, 75])
    return 1e3 * med, 1e3 * (q3 - q1)
