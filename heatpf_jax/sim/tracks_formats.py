"""Parsers of the real ball tracks: SkillCorner's and PFF FC's tracking files, each into a :class:`BallTrack`.

The formats are described in :mod:`heatpf_jax.sim.tracks` (which re-exports :func:`load_skillcorner` and
:func:`load_pff`): SkillCorner's version-2 JSON list and version-3 JSON lines, PFF FC's JSON lines, each
with its metadata file beside it; ``.bz2`` and ``.gz`` files are decompressed. NumPy only.
"""

from __future__ import annotations

import bz2
import gzip
import json
import os
from pathlib import Path

import numpy as np

from heatpf_jax.sim.tracks_pieces import BallTrack

__all__ = ["load_pff", "load_skillcorner"]

_SKILLCORNER_RATE = 10.0  # frames per second (the "frame" index counts video frames at 10 fps)
_PFF_FPS = 29.97  # when the metadata gives none


# --- Parsers ------------------------------------------------------------------------------------------------------


def _open_text(path: Path):
    """A text file, transparently decompressed for ``.bz2`` and ``.gz`` names."""
    if path.suffix == ".bz2":
        return bz2.open(path, "rt", encoding="utf-8")
    if path.suffix == ".gz":
        return gzip.open(path, "rt", encoding="utf-8")
    return open(path, encoding="utf-8")


def _number(value) -> float | None:
    """A finite float, or ``None`` for null, text or non-finite values."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        out = float(value)
    except (TypeError, ValueError):
        return None
    return out if np.isfinite(out) else None


def _build(frames: list[tuple[float, float | None, float | None, float | None]], source: str, rate: float,
           path: Path) -> BallTrack:
    """A track from ``(t, x, y, z)`` rows (``None`` where unknown): sorted by time, duplicate times dropped."""
    if not frames:
        raise ValueError(f"{path}: no frames")
    t = np.array([f[0] for f in frames], np.float64)
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.ones(t.shape[0], bool)
    keep[1:] = np.diff(t) > 0.0
    rows = [frames[i] for i in order[keep]]
    visible = np.array([r[1] is not None and r[2] is not None for r in rows], bool)
    height_known = np.array([v and r[3] is not None for v, r in zip(visible, rows, strict=True)], bool)
    xyz = np.zeros((len(rows), 3))
    for i, (_, x, y, z) in enumerate(rows):
        if visible[i]:
            xyz[i] = (x, y, 0.0 if z is None else z)
    return BallTrack(t=t[keep], xyz=xyz, visible=visible, source=source, rate=float(rate), height_known=height_known)


def _sibling_metadata(path: Path, old: str, new: str) -> Path | None:
    """The metadata file beside ``path``: its name with ``old`` replaced by ``new`` (suffixes -> .json)."""
    stem = path.name.split(".")[0]
    if old in stem:
        candidate = path.with_name(stem.replace(old, new) + ".json")
        if candidate.is_file():
            return candidate
    return None


def _load_json(path: Path, what: str):
    try:
        with _open_text(path) as fh:
            return json.load(fh)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (json.JSONDecodeError, UnicodeDecodeError, OSError, EOFError) as err:
        raise ValueError(f"{path}: not a readable {what} ({type(err).__name__}: {err})") from None


def _json_lines(path: Path, what: str) -> list[dict]:
    rows = []
    try:
        with _open_text(path) as fh:
            for number, line in enumerate(fh, start=1):
                if not line.strip():
                    continue
                try:
                    row = json.loads(line)
                except json.JSONDecodeError as err:
                    raise ValueError(f"{path}: line {number} is not JSON ({err.msg}); not a {what}") from None
                if not isinstance(row, dict):
                    raise ValueError(f"{path}: line {number} is not a JSON object; not a {what}")
                rows.append(row)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (UnicodeDecodeError, OSError, EOFError) as err:
        raise ValueError(f"{path}: not a readable {what} ({type(err).__name__}: {err})") from None
    return rows


def load_skillcorner(
    path: str | os.PathLike, *, meta_path: str | os.PathLike | None = None, ball_id: int | None = None
) -> BallTrack:
    """The ball's track from a SkillCorner tracking file (version 2 JSON list, or version 3 JSON lines).

    Time is ``frame / 10`` (SkillCorner counts video frames at 10 fps), continuous across the halves
    (the break's frames have no ball). The ball is known where its record has ``x`` and ``y`` and the
    frame's ``period`` is not null; ``z`` is kept where given (``height_known``), else 0.

    Args:
        path: ``structured_data.json`` (version 2: a JSON list of frames) or a ``.jsonl`` of
            version-3 frames (``ball_data``); ``.bz2``/``.gz`` are decompressed.
        meta_path: the match file giving the match ``id`` and ``ball.trackable_object``. Default: the
            file beside ``path`` with ``structured_data`` in its name replaced by ``match_data`` (or
            ``v3_raw_data``/``raw_data`` by ``meta_data``), else ``match_data.json`` in the same folder.
        ball_id: the ball's ``trackable_object``, overriding the match file. Without either, the
            object that carries a ``z`` most often is the ball (only the ball has one).

    Returns:
        A :class:`BallTrack` at 10 Hz, source ``"skillcorner:<match id>"`` (``"skillcorner"`` without one).

    Raises:
        ValueError: one line naming the file: missing, unreadable, or not in either format.
    """
    path = Path(path)
    with _open_text_checked(path) as fh:
        head = fh.read(4096).lstrip()
    if head.startswith("["):
        frames = _load_json(path, "SkillCorner file (a JSON list of frames)")
        if not all(isinstance(f, dict) and "frame" in f for f in frames):
            raise ValueError(f"{path}: not a SkillCorner file (a JSON list of objects with 'frame')")
        meta = _skillcorner_meta(path, meta_path)
        match = meta.get("id")
        if ball_id is None:
            ball_id = (meta.get("ball") or {}).get("trackable_object")
        if ball_id is None:
            ball_id = _guess_ball_id(frames)
        rows = []
        for f in frames:
            x = y = z = None
            if f.get("period") is not None:
                for rec in f.get("data") or ():
                    if not isinstance(rec, dict):
                        continue
                    if (ball_id is not None and rec.get("trackable_object") == ball_id) or \
                            rec.get("group_name") in ("ball", "balls"):
                        x, y, z = _number(rec.get("x")), _number(rec.get("y")), _number(rec.get("z"))
                        break
            rows.append((_frame_time(f, path), x, y, z))
    elif head.startswith("{"):
        lines = _json_lines(path, "SkillCorner version-3 file (JSON lines)")
        if not all("frame" in f and isinstance(f.get("ball_data"), dict) for f in lines):
            raise ValueError(f"{path}: not a SkillCorner version-3 file (every line needs 'frame' and 'ball_data')")
        meta = _skillcorner_meta(path, meta_path)
        match = meta.get("id")
        rows = []
        for f in lines:
            ball = f["ball_data"]
            known = f.get("period") is not None
            rows.append((_frame_time(f, path), _number(ball.get("x")) if known else None,
                         _number(ball.get("y")) if known else None, _number(ball.get("z"))))
    else:
        raise ValueError(f"{path}: not a SkillCorner file (neither a JSON list nor JSON lines)")
    source = "skillcorner" if match is None else f"skillcorner:{match}"
    return _build(rows, source, _SKILLCORNER_RATE, path)


def _open_text_checked(path: Path):
    try:
        return _open_text(path)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: a directory, not a tracking file") from None
    except OSError as err:
        raise ValueError(f"{path}: cannot be opened ({err.strerror})") from None


def _frame_time(frame: dict, path: Path) -> float:
    value = _number(frame.get("frame"))
    if value is None:
        raise ValueError(f"{path}: a frame without a frame number ({str(frame)[:80]})")
    return value / _SKILLCORNER_RATE


def _skillcorner_meta(path: Path, meta_path) -> dict:
    if meta_path is None:
        for old, new in (("structured_data", "match_data"), ("v3_raw_data", "meta_data"), ("raw_data", "meta_data")):
            meta_path = meta_path or _sibling_metadata(path, old, new)
        if meta_path is None and (path.parent / "match_data.json").is_file():
            meta_path = path.parent / "match_data.json"
    if meta_path is None:
        return {}
    meta = _load_json(Path(meta_path), "SkillCorner match file")
    if not isinstance(meta, dict):
        raise ValueError(f"{meta_path}: not a SkillCorner match file (a JSON object)")
    return meta


def _guess_ball_id(frames: list[dict]):
    counts: dict = {}
    for f in frames:
        for rec in f.get("data") or ():
            if isinstance(rec, dict) and "z" in rec and rec.get("trackable_object") is not None:
                counts[rec["trackable_object"]] = counts.get(rec["trackable_object"], 0) + 1
    return max(counts, key=counts.get) if counts else None


def load_pff(path: str | os.PathLike, *, meta_path: str | os.PathLike | None = None) -> BallTrack:
    """The ball's track from a PFF FC tracking file (JSON lines, one frame a line).

    Position: ``ballsSmoothed`` (as kloppy reads it); frames where it is null, or has no ``x``/``y``,
    or whose ``period`` is null, have no ball. Time: ``videoTimeMs / 1000`` (continuous over the
    match), else ``frameNum / fps``.

    Args:
        path: ``pff_<game>.jsonl`` (``.bz2``/``.gz`` decompressed).
        meta_path: ``pff_metadata_<game>.json`` (a list holding one object with ``fps``); default:
            the file of that name beside ``path``, if any.

    Returns:
        A :class:`BallTrack` at the metadata's fps (29.97 without one), source ``"pff:<game>"``.

    Raises:
        ValueError: one line naming the file: missing, unreadable, or not PFF's format.
    """
    path = Path(path)
    lines = _json_lines(path, "PFF tracking file (JSON lines)")
    if not lines or not all("frameNum" in f and "period" in f for f in lines):
        raise ValueError(f"{path}: not a PFF tracking file (every line needs 'frameNum' and 'period')")
    if meta_path is None:
        meta_path = _sibling_metadata(path, "pff_", "pff_metadata_")
    fps = _PFF_FPS
    if meta_path is not None:
        meta = _load_json(Path(meta_path), "PFF metadata file")
        meta = meta[0] if isinstance(meta, list) and meta else meta
        if isinstance(meta, dict) and _number(meta.get("fps")):
            fps = float(meta["fps"])
    rows = []
    for f in lines:
        ms = _number(f.get("videoTimeMs"))
        if ms is not None:
            t = ms / 1000.0
        else:
            number = _number(f.get("frameNum"))
            if number is None:
                raise ValueError(f"{path}: a frame without videoTimeMs or frameNum ({str(f)[:80]})")
            t = number / fps
        ball = f.get("ballsSmoothed")
        x = y = z = None
        if isinstance(ball, dict) and f.get("period") is not None:
            x, y, z = _number(ball.get("x")), _number(ball.get("y")), _number(ball.get("z"))
        rows.append((t, x, y, z))
    game = _number(lines[0].get("gameRefId"))
    if game is None:
        stem = path.name.split(".")[0]
        game_text = stem.removeprefix("pff_")
    else:
        game_text = str(int(game))
    return _build(rows, f"pff:{game_text}", fps, path)
