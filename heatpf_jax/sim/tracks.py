"""Real ball tracks: fetched from kloppy's source distribution, parsed into one small type.

Two open sources ship as test files inside the source distribution of `kloppy
<https://github.com/PySport/kloppy>`_ 3.19.1 (``pip download --no-deps --no-binary :all: kloppy==3.19.1``):

* **SkillCorner open data** (``skillcorner_structured_data.json`` with ``skillcorner_match_data.json``):
  broadcast tracking of FC Bayern München - Borussia Dortmund, Bundesliga, 2019-11-09 (SkillCorner match
  2417), 10 Hz, both halves; the ball is known on about 30 900 frames (51 minutes), with a height ``z`` on
  about half of them. Format (version 2): a JSON list with one object per video frame, ``{"frame": int,
  "period": 1 | 2 | null, "time": "m:ss.ff" | null, "possession": {...}, "data": [record, ...]}``; a record
  is ``{"x", "y", ["z"], "track_id", "trackable_object" | "group_name"}`` in metres, pitch centre origin, x
  along the long side. The ball is the record whose ``trackable_object`` is ``match_data["ball"]
  ["trackable_object"]`` (or whose ``group_name`` is ``"ball"``/``"balls"``); frames without one, and
  frames with ``period`` null (before the match, half time), have no ball. The variant
  ``skillcorner_structured_data_timestamp.json`` (first half only, ``"timestamp"`` for ``"time"``) and the
  version-3 JSON lines ``skillcorner_v3_raw_data.jsonl`` (``"ball_data": {"x", "y", "z", "is_detected"}``
  per line) are read too.
* **PFF FC's FIFA World Cup 2022 sample** (``pff_10517.jsonl``, Argentina - France; ``pff_3812.jsonl``,
  Senegal - Netherlands; with ``pff_metadata_<game>.json``): broadcast tracking at 29.97 Hz with the
  ball's height. JSON lines, one frame each: ``{"frameNum", "period", "videoTimeMs",
  "periodElapsedTime", "ballsSmoothed": {"x", "y", "z", "visibility"} | null, "balls": [...], ...}``
  in metres, pitch centre origin. The sample is short: snippets of 50 frames (1.7 s) around kick-offs,
  six in all, one of them without any ball.

The Hawk-Eye files of the same distribution are reserved for independent evaluation: nothing here
reads, extracts or names them.

:func:`fetch_kloppy_files` downloads the distribution once (``pip download``), keeps only the files
above, with ``SOURCE.txt`` (package, version, sha256, files, licences) and kloppy's licence, in
``$HEATPF_TRACKS_DIR`` (else ``~/.cache/heatpf_jax/tracks``), and reuses them afterwards. Nothing
is vendored in the repository; tests use tiny synthetic files of the same formats
(``tests/data/tiny_tracks``).

Licences: kloppy is BSD-3-Clause (Copyright (c) 2020, PySport). SkillCorner's open data
(https://github.com/SkillCorner/opendata) is released under the MIT License (Copyright (c) 2020
SkillCorner), and SkillCorner asks that users credit it. PFF FC released its World Cup 2022 data on
request (https://www.blog.fc.pff.com/blog/pff-fc-release-2022-world-cup-data); kloppy's distribution
states no separate licence for the sample: use it for research, and do not redistribute it.
"""

from __future__ import annotations

import bz2
import gzip
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import numpy as np

__all__ = [
    "KLOPPY_FILES",
    "KLOPPY_VERSION",
    "TRACKS_DIR_ENV",
    "BallTrack",
    "fetch_kloppy_files",
    "load_pff",
    "load_skillcorner",
    "resample_track",
    "segments",
    "tracks_directory",
]

KLOPPY_VERSION = "3.19.1"
TRACKS_DIR_ENV = "HEATPF_TRACKS_DIR"
# The test files taken from the distribution (under kloppy-<version>/kloppy/tests/files/), never Hawk-Eye's. (Its
# SkillCorner version-3 sample, 44 frames of another match, is left out: too short to replay, of unstated origin.)
KLOPPY_FILES = (
    "skillcorner_structured_data.json",
    "skillcorner_match_data.json",
    "pff_10517.jsonl",
    "pff_metadata_10517.json",
    "pff_3812.jsonl",
    "pff_metadata_3812.json",
)
# sha256 of kloppy-3.19.1.tar.gz as published on PyPI.
_SDIST_SHA256 = "c2e592f8728a0bbe07566f048938b84edb0352064864996a150973a5d7c0ac0a"
_SKILLCORNER_RATE = 10.0  # frames per second (the "frame" index counts video frames at 10 fps)
_PFF_FPS = 29.97  # when the metadata gives none


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


# --- The cache ----------------------------------------------------------------------------------------------------


def tracks_directory(cache_dir: str | os.PathLike | None = None) -> Path:
    """The folder of fetched tracks: ``cache_dir``, else ``$HEATPF_TRACKS_DIR``, else ``~/.cache/heatpf_jax/tracks``."""
    if cache_dir is not None:
        return Path(cache_dir).expanduser()
    if os.environ.get(TRACKS_DIR_ENV):
        return Path(os.environ[TRACKS_DIR_ENV]).expanduser()
    return Path.home() / ".cache" / "heatpf_jax" / "tracks"


def fetch_kloppy_files(cache_dir: str | os.PathLike | None = None) -> Path:
    """The folder with kloppy's SkillCorner and PFF test files, downloaded and extracted at first use.

    The first call runs ``python -m pip download --no-deps --no-binary :all: kloppy==3.19.1`` (about
    40 MB), checks the archive's sha256, and extracts :data:`KLOPPY_FILES`, kloppy's ``LICENSE`` (as
    ``LICENSE-kloppy.txt``) and a ``SOURCE.txt`` (package, version, sha256, files with their sizes and
    sha256, licences) into a temporary folder beside the cache, renamed to ``<cache>/kloppy-3.19.1``
    when complete: an interrupted call leaves no half files. Later calls return that folder at once.

    Args:
        cache_dir: where to cache (default :func:`tracks_directory`: ``$HEATPF_TRACKS_DIR`` or
            ``~/.cache/heatpf_jax/tracks``).

    Returns:
        ``<cache_dir>/kloppy-3.19.1``.

    Raises:
        RuntimeError: pip failed (no network, no pip, an index without the package), the download's
            sha256 differs from the published one, or the archive lacks a file; one line naming what
            to do.
        ValueError: the cache folder cannot be created or written.
    """
    root = tracks_directory(cache_dir)
    target = root / f"kloppy-{KLOPPY_VERSION}"
    if (target / "SOURCE.txt").is_file():
        return target
    if target.exists():
        raise RuntimeError(f"{target}: exists without SOURCE.txt (not written by fetch_kloppy_files); remove it "
                           "and call again")
    try:
        root.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(dir=root, prefix=".kloppy-fetch-"))
    except OSError as err:
        raise ValueError(f"{root}: cannot create the tracks cache here ({err.strerror}); set "
                         f"{TRACKS_DIR_ENV} to a writable folder") from None
    try:
        download, staging = work / "download", work / "files"
        download.mkdir()
        staging.mkdir()
        sdist = _pip_download(download)
        digest = _sha256(sdist)
        if digest != _SDIST_SHA256:
            raise RuntimeError(f"{sdist.name}: sha256 {digest} differs from the published {_SDIST_SHA256}; the "
                               "package index served another file: check pip's index settings")
        taken = _extract(sdist, staging)
        (staging / "SOURCE.txt").write_text(_source_text(sdist.name, digest, taken), encoding="utf-8")
        try:
            os.rename(staging, target)
        except OSError:
            if not (target / "SOURCE.txt").is_file():  # not a concurrent fetch that finished first
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def _pip_download(dest: Path) -> Path:
    """Runs ``pip download`` of kloppy's sdist into ``dest``; the archive's path."""
    command = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", ":all:",
               f"kloppy=={KLOPPY_VERSION}", "-d", str(dest)]
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=900, check=False)
    except (OSError, subprocess.TimeoutExpired) as err:
        raise RuntimeError(f"pip download of kloppy=={KLOPPY_VERSION} could not run ({type(err).__name__}: {err}); "
                           "check the network, or fetch on a machine with one and set "
                           f"{TRACKS_DIR_ENV} to the copied cache") from None
    if done.returncode != 0:
        lines = [line.strip() for line in (done.stderr or done.stdout or "").splitlines() if line.strip()]
        last = lines[-1] if lines else "no message"
        raise RuntimeError(f"pip download of kloppy=={KLOPPY_VERSION} failed (exit {done.returncode}: {last}); "
                           "check the network and pip's index settings, or fetch on a machine with a network "
                           f"and set {TRACKS_DIR_ENV} to the copied cache")
    found = sorted(dest.glob(f"kloppy-{KLOPPY_VERSION}.tar.gz"))
    if not found:
        raise RuntimeError(f"pip download of kloppy=={KLOPPY_VERSION} left no kloppy-{KLOPPY_VERSION}.tar.gz in "
                           f"{dest} (got {sorted(p.name for p in dest.iterdir())}); a wheel-only index? "
                           "pip must be able to fetch the source distribution")
    return found[0]


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _extract(sdist: Path, staging: Path) -> list[tuple[str, int, str]]:
    """Copies the wanted members (and kloppy's licence) out of the archive; ``(name, size, sha256)`` each."""
    prefix = f"kloppy-{KLOPPY_VERSION}"
    wanted = {f"{prefix}/kloppy/tests/files/{name}": name for name in KLOPPY_FILES}
    wanted[f"{prefix}/LICENSE"] = "LICENSE-kloppy.txt"
    taken = []
    try:
        with tarfile.open(sdist, "r:gz") as archive:
            for member_name, out_name in wanted.items():
                try:
                    member = archive.getmember(member_name)
                except KeyError:
                    raise RuntimeError(f"{sdist.name}: has no {member_name}; not kloppy {KLOPPY_VERSION}'s "
                                       "source distribution") from None
                source = archive.extractfile(member) if member.isfile() else None
                if source is None:
                    raise RuntimeError(f"{sdist.name}: {member_name} is not a regular file")
                digest = hashlib.sha256()
                with source, open(staging / out_name, "wb") as out:
                    while block := source.read(1 << 20):
                        digest.update(block)
                        out.write(block)
                taken.append((out_name, member.size, digest.hexdigest()))
    except (tarfile.TarError, EOFError, OSError) as err:
        raise RuntimeError(f"{sdist.name}: cannot be read as a .tar.gz ({err}); delete it and call again") from None
    return taken


def _source_text(archive: str, digest: str, taken: list[tuple[str, int, str]]) -> str:
    files = "\n".join(f"  {name}  {size} bytes  sha256 {sha}" for name, size, sha in taken)
    return f"""Real ball tracks for heatpf_jax's replay worlds (heatpf_jax.sim.tracks.fetch_kloppy_files).

Package: kloppy {KLOPPY_VERSION} (source distribution, https://pypi.org/project/kloppy/{KLOPPY_VERSION}/)
Fetched with: python -m pip download --no-deps --no-binary :all: kloppy=={KLOPPY_VERSION}
Archive: {archive}  sha256 {digest}
Files taken from kloppy-{KLOPPY_VERSION}/kloppy/tests/files/ (the Hawk-Eye files are left out on purpose:
they are reserved for independent evaluation):
{files}

Licences:
  kloppy: BSD 3-Clause License, Copyright (c) 2020, PySport (LICENSE-kloppy.txt, from the archive).
  skillcorner_*: SkillCorner open data (https://github.com/SkillCorner/opendata; FC Bayern Munchen -
    Borussia Dortmund, 2019-11-09, SkillCorner match 2417), MIT License, Copyright (c) 2020 SkillCorner;
    SkillCorner asks that users of the data credit SkillCorner.
  pff_*: PFF FC's FIFA World Cup 2022 broadcast tracking (games 10517 and 3812), released by PFF FC on
    request (https://www.blog.fc.pff.com/blog/pff-fc-release-2022-world-cup-data); the archive states no
    separate licence for this sample: research use, do not redistribute.
"""


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
