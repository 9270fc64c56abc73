"""The ball-track type and its pieces: :class:`BallTrack`, :func:`segments` and :func:`resample_track`.

A :class:`BallTrack` is a ball's track as a provider gives it (pitch frame, the source's clock);
:func:`segments` cuts it into the pieces where the ball is known and :func:`resample_track` puts a piece on
the filter's period. :mod:`heatpf_jax.sim.tracks` (the sources, their fetching and parsing) re-exports
every name here. NumPy only.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

__all__ = ["BallTrack", "resample_track", "segments"]


class BallTrack(NamedTuple):
    """A ball's track as a provider gives it (or a piece of one).

    Positions are in the pitch frame: metres, origin at the centre spot, x along the long side,
    y along the short side, z up (the height the provider reports; 0 where it reports none).
    """

    t: np.ndarray  # float64 [T]: seconds on the source's clock, increasing
    xyz: np.ndarray  # float64 [T, 3]: ball position, metres; zeros where not visible
    visible: np.ndarray  # bool [T]: the ball's position is known
    source: str  # e.g. "skillcorner:2417", "pff:10517"
    rate: float  # nominal frames per second
    height_known: np.ndarray | None = None  # bool [T]: the provider gave a height (z)

    @property
    def num_frames(self) -> int:
        return int(np.shape(self.t)[0])

    def slice(self, start: int, stop: int) -> BallTrack:
        """Frames ``start:stop`` of the track."""
        known = None if self.height_known is None else self.height_known[start:stop]
        return self._replace(t=self.t[start:stop], xyz=self.xyz[start:stop], visible=self.visible[start:stop],
                             height_known=known)


# --- Pieces and resampling ----------------------------------------------------------------------------------------


def segments(
    track: BallTrack, max_gap_s: float = 0.5, *, min_length_s: float = 0.0, max_speed: float | None = None
) -> Iterator[BallTrack]:
    """The contiguous pieces of a track where the ball is known.

    A piece runs from a known frame to a known frame; consecutive known frames in it are at most
    ``max_gap_s`` apart (frames between them stay in the piece, marked not visible). A longer gap
    (a replay, a close-up, the half-time break, a new snippet) starts a new piece, and so does a
    jump faster than ``max_speed`` (a tracking glitch: broadcast tracking has a few jumps of
    50-150 m/s).

    Args:
        track: the whole track.
        max_gap_s: the longest gap, seconds, bridged inside a piece.
        min_length_s: pieces shorter than this (last minus first time) are left out.
        max_speed: the fastest horizontal speed, m/s in the track's units, between consecutive known
            frames inside a piece (default: no limit).

    Yields:
        :class:`BallTrack` pieces in time order.
    """
    known = np.flatnonzero(track.visible)
    if known.size == 0:
        return
    gaps = np.diff(track.t[known])
    split = gaps > max_gap_s + 1e-9
    if max_speed is not None:
        step = np.linalg.norm(np.diff(track.xyz[known, :2], axis=0), axis=1)
        split |= step > max_speed * np.maximum(gaps, 1e-9)
    breaks = np.flatnonzero(split)
    starts = np.concatenate([known[:1], known[breaks + 1]])
    stops = np.concatenate([known[breaks], known[-1:]])
    for start, stop in zip(starts, stops, strict=True):
        if track.t[stop] - track.t[start] >= min_length_s - 1e-9:
            yield track.slice(int(start), int(stop) + 1)


def resample_track(track: BallTrack, dt: float, *, max_gap_s: float = 0.5) -> BallTrack:
    """The track at times ``t0 + k dt`` by linear interpolation between known frames.

    ``t0`` is the first known frame's time; the last sample is at or before the last known frame.
    Every sample has a position (interpolated between the known frames around it); it is
    ``visible`` only where those frames are at most ``max_gap_s`` apart (or it falls on a known
    frame), and ``height_known`` only where both are.

    Args:
        track: a track (typically a piece from :func:`segments`).
        dt: the new period, seconds.
        max_gap_s: the longest gap, seconds, bridged by interpolation as known.

    Returns:
        A :class:`BallTrack` with ``rate = 1 / dt``.

    Raises:
        ValueError: the track has no known frame, or ``dt`` is not positive.
    """
    if not (np.isfinite(dt) and dt > 0):
        raise ValueError(f"dt: must be a positive number of seconds, got {dt!r}")
    known = np.flatnonzero(track.visible)
    if known.size == 0:
        raise ValueError(f"track {track.source!r}: the ball is never known")
    tk, xyz = track.t[known], track.xyz[known]
    has_z = np.ones(known.size, bool) if track.height_known is None else track.height_known[known]
    count = int(np.floor((tk[-1] - tk[0]) / dt + 1e-9)) + 1
    t_new = tk[0] + dt * np.arange(count)
    left = np.clip(np.searchsorted(tk, t_new, side="right") - 1, 0, known.size - 1)
    right = np.minimum(left + 1, known.size - 1)
    on_sample = np.abs(t_new - tk[left]) <= 1e-9
    right = np.where(on_sample, left, right)
    gap = tk[right] - tk[left]
    out = np.stack([np.interp(t_new, tk, xyz[:, k]) for k in range(3)], axis=-1)
    return BallTrack(
        t=t_new,
        xyz=out,
        visible=gap <= max_gap_s + 1e-9,
        source=track.source,
        rate=1.0 / dt,
        height_known=has_z[left] & has_z[right],
    )
