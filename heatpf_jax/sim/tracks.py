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

The track type and its pieces live in :mod:`heatpf_jax.sim.tracks_pieces` and the parsers in
:mod:`heatpf_jax.sim.tracks_formats`; this module re-exports them.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from heatpf_jax.sim.tracks_formats import load_pff, load_skillcorner
from heatpf_jax.sim.tracks_pieces import BallTrack, resample_track, segments

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
