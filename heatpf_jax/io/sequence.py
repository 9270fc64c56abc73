"""The sequence file (.npz), version 1: a contract other tools rely on.

| key          | dtype, shape           | meaning                                              |
|--------------|------------------------|------------------------------------------------------|
| heatmaps     | float32 [T, H, W]      | activations in [0, 1]; ignored where has_heatmap is False |
| has_heatmap  | bool [T]               | True where step t brings a new heat map              |
| intrinsics   | float64 [4]            | fx, fy, cx, cy in heat-map pixels                    |
| cam_to_base  | float64 [T, 4, 4]      | camera optical frame -> robot base frame at step t   |
| odometry     | float64 [T, 3]         | (dx, dy, dtheta) from t-1 to t in the base of t-1; row 0 ignored |
| ball_radius  | float64 []             | projection plane height, metres                      |
| dt           | float64 []             | filter period, seconds                               |
| ground_truth | float64 [T, 2], optional | ball (x, y) in the base frame of step t            |
| robot_pose   | float64 [T, 3], optional | base (x, y, theta) in a world frame, from self-localisation |
| pose_confidence | float64 [T], optional | its confidence in [0, 1] (1 if absent); needs robot_pose |
| images       | uint8 [T, H, W, 3], optional | RGB frames at the heat maps' size (``heatpf colour``) |
| stamps       | int64 [T], optional    | the time of step t, ns, non-decreasing (an imported bag's clock) |
| settings     | str [] (a JSON object), optional | its maker's settings for filtering it, as ``--set`` takes them |

:func:`load_sequence` checks every key and raises :class:`SequenceError` with one
line naming the file, the key (where one is at fault) and the problem, also for a
file it cannot read (empty, damaged, a directory, a .npy array, text, object
arrays); ``stamps`` (kept by ``heatpf import-rosbag``) stamps the messages of ``heatpf run --bag``, so
that they play beside the robot's own bag; :func:`save_sequence` validates first and writes atomically (a
temporary file renamed into place), so nothing is half-written.

``settings`` is what the sequence's maker knows about its heat maps that a filter should follow: ``{name: value}``
(text, numbers or booleans) as ``heatpf run --set`` takes them. ``heatpf colour`` writes ``{"source": "pixels"}``:
a colour map's blob has the size of the colour window, which is a ground ball's there, not the size of the ball, so
no blob may be placed in the air by its size. ``heatpf run``, ``eval``, ``sweep`` and ``tune`` apply the
settings beneath the user's own (``--set``, ``--grid``, ``--params``) and print a line naming each one applied
(:func:`heatpf_jax.cli.settings.sequence_settings`); in Python, pass them to
:func:`heatpf_jax.presets.build` yourself.
"""

from __future__ import annotations

import codecs
import json
import math
import os
import warnings
import zipfile
import zlib
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.lib import format as npy_format

from heatpf_jax.io.files import write_atomic

__all__ = [
    "FORMAT_VERSION",
    "OPTIONAL_INPUTS",
    "Sequence",
    "SequenceError",
    "load_sequence",
    "save_sequence",
    "validate_sequence",
]

FORMAT_VERSION = 1


class SequenceError(ValueError):
    """A sequence file or object breaks the version-1 contract."""


class Sequence(NamedTuple):
    """A recorded or simulated sequence (see the module docstring for shapes)."""

    heatmaps: np.ndarray
    has_heatmap: np.ndarray
    intrinsics: np.ndarray
    cam_to_base: np.ndarray
    odometry: np.ndarray
    ball_radius: np.ndarray
    dt: np.ndarray
    ground_truth: np.ndarray | None = None
    robot_pose: np.ndarray | None = None
    pose_confidence: np.ndarray | None = None
    images: np.ndarray | None = None
    stamps: np.ndarray | None = None
    settings: dict[str, str | float | int | bool] | None = None

    @property
    def num_steps(self) -> int:
        return int(np.shape(self.heatmaps)[0])

    def head(self, num_steps: int) -> Sequence:
        """The first ``num_steps`` steps (per-step arrays cut, constants kept)."""
        per_step = ("heatmaps", "has_heatmap", "cam_to_base", "odometry", "ground_truth", "stamps", *OPTIONAL_INPUTS)
        return self._replace(
            **{k: getattr(self, k)[:num_steps] for k in per_step if getattr(self, k) is not None}
        )


# key: (dtype kind check, dtype name for messages, shape with None for T/H/W)
_SPEC = {
    "heatmaps": ("f", "float32", ("T", "H", "W")),
    "has_heatmap": ("b", "bool", ("T",)),
    "intrinsics": ("f", "float64", (4,)),
    "cam_to_base": ("f", "float64", ("T", 4, 4)),
    "odometry": ("f", "float64", ("T", 3)),
    "ball_radius": ("f", "float64", ()),
    "dt": ("f", "float64", ()),
    "ground_truth": ("f", "float64", ("T", 2)),
    "robot_pose": ("f", "float64", ("T", 3)),
    "pose_confidence": ("f", "float64", ("T",)),
    "images": ("u", "uint8", ("T", "H", "W", 3)),
    "stamps": ("i", "int64", ("T",)),
}
OPTIONAL_INPUTS = ("robot_pose", "pose_confidence", "images")  # optional keys a method may read
_REQUIRED = tuple(k for k in _SPEC if k not in ("ground_truth", "stamps", *OPTIONAL_INPUTS))


def _settings_from_text(arr: np.ndarray) -> dict:
    """The ``settings`` member (a JSON object as text) as a dict, or a SequenceError."""
    if arr.shape != () or arr.dtype.kind != "U":
        raise SequenceError(f"settings: expected text (a JSON object), got {_dtype_words(arr.dtype)} of shape "
                            f"{arr.shape}")
    try:
        value = json.loads(str(arr))
    except ValueError as err:
        raise SequenceError(f"settings: not JSON ({err.msg} at character {err.pos})") from None
    if not isinstance(value, dict):
        raise SequenceError(f"settings: expected a JSON object, got {type(value).__name__}")
    return value


def _check_array(key: str, value, dims: dict[str, int]) -> np.ndarray:
    kind, dtype_name, shape = _SPEC[key]
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):
        kind_of = type(value).__name__
        raise SequenceError(f"{key}: cannot be made an array (a {kind_of} of ragged or mixed items)") from None
    if arr.dtype.kind != kind:
        raise SequenceError(f"{key}: expected dtype {dtype_name}, got {_dtype_words(arr.dtype)}")
    if arr.ndim != len(shape):
        raise SequenceError(f"{key}: expected shape {_fmt(shape)}, got {arr.shape}")
    for axis, (want, got) in enumerate(zip(shape, arr.shape, strict=True)):
        if isinstance(want, str):
            if want in dims and dims[want] != got:
                raise SequenceError(f"{key}: axis {axis} ({want}) has length {got}, expected {dims[want]}")
            dims.setdefault(want, got)
        elif want != got:
            raise SequenceError(f"{key}: expected shape {_fmt(shape)}, got {arr.shape}")
    if kind == "f" and not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise SequenceError(f"{key}: non-finite value at index {tuple(int(i) for i in bad)}")
    return arr


_KIND_WORDS = {
    "U": "text (str)",
    "S": "bytes",
    "O": "Python objects (an object array)",
    "V": "raw or structured records",
    "M": "dates",
    "m": "time spans",
}


def _dtype_words(dtype: np.dtype) -> str:
    """A dtype in plain words: numbers by name (``float32``), the rest by what they hold (``text (str)``)."""
    return _KIND_WORDS.get(dtype.kind, dtype.name)


def _fmt(shape) -> str:
    return "[" + ", ".join(str(s) for s in shape) + "]"


def validate_sequence(seq: Sequence) -> Sequence:
    """Checks a sequence against the contract and returns it with canonical dtypes.

    Raises:
        SequenceError: naming the key and the problem (missing key, wrong dtype or
            shape, non-finite values, activations outside [0, 1], a non-rigid
            ``cam_to_base``, non-positive intrinsics, dt or a negative radius).
    """
    dims: dict[str, int] = {}
    out = {}
    for key in _SPEC:
        value = getattr(seq, key)
        if value is None:
            if key in _REQUIRED:
                raise SequenceError(f"{key}: missing")
            out[key] = None
            continue
        out[key] = _check_array(key, value, dims)
    if dims["T"] < 1:
        raise SequenceError("heatmaps: the sequence has no steps (T = 0)")
    if out["images"] is not None and out["images"].dtype != np.uint8:
        raise SequenceError(f"images: expected dtype uint8, got {_dtype_words(out['images'].dtype)}")
    if out["pose_confidence"] is not None:
        if out["robot_pose"] is None:
            raise SequenceError("pose_confidence: given without robot_pose (the confidence of which poses?)")
        conf = out["pose_confidence"]
        if conf.size and (conf.min() < 0.0 or conf.max() > 1.0):
            bad = int(np.flatnonzero((conf < 0.0) | (conf > 1.0))[0])
            raise SequenceError(f"pose_confidence: must lie in [0, 1], got {conf[bad]} at step {bad}")
    if out["stamps"] is not None and np.any(np.diff(out["stamps"]) < 0):
        bad = int(np.flatnonzero(np.diff(out["stamps"]) < 0)[0]) + 1
        raise SequenceError(f"stamps: must not decrease, got {int(out['stamps'][bad])} ns at step {bad} after "
                            f"{int(out['stamps'][bad - 1])} ns")
    settings = _check_settings(seq.settings)
    if dims["H"] < 1 or dims["W"] < 1:
        raise SequenceError(f"heatmaps: empty heat maps of shape {out['heatmaps'].shape[1:]}")
    heat = out["heatmaps"]
    if heat.size and (heat.min() < 0.0 or heat.max() > 1.0):
        bad = np.argwhere((heat < 0.0) | (heat > 1.0))[0]
        raise SequenceError(
            f"heatmaps: activations must lie in [0, 1], got {heat[tuple(bad)]} at index {tuple(int(i) for i in bad)}"
        )
    intr = out["intrinsics"]
    if intr[0] <= 0 or intr[1] <= 0:
        raise SequenceError(f"intrinsics: fx and fy must be positive, got {intr[:2].tolist()}")
    pose = out["cam_to_base"].astype(np.float64)
    rot = pose[:, :3, :3]
    ortho_err = np.abs(np.einsum("tji,tjk->tik", rot, rot) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(rot)
    bottom_err = np.abs(pose[:, 3, :] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1)
    bad = np.flatnonzero((ortho_err > 1e-5) | (np.abs(det - 1.0) > 1e-5) | (bottom_err > 1e-9))
    if bad.size:
        t = int(bad[0])
        raise SequenceError(
            f"cam_to_base: step {t} is not a rigid transform (|R^T R - I| = {ortho_err[t]:.2e}, "
            f"det R = {det[t]:.6f}, last row {pose[t, 3].tolist()})"
        )
    if out["ball_radius"] < 0:
        raise SequenceError(f"ball_radius: must be >= 0, got {float(out['ball_radius'])}")
    if out["dt"] <= 0:
        raise SequenceError(f"dt: must be positive, got {float(out['dt'])}")
    return Sequence(
        heatmaps=heat.astype(np.float32, copy=False),
        has_heatmap=out["has_heatmap"].astype(bool, copy=False),
        intrinsics=intr.astype(np.float64, copy=False),
        cam_to_base=pose,
        odometry=out["odometry"].astype(np.float64, copy=False),
        ball_radius=out["ball_radius"].astype(np.float64, copy=False),
        dt=out["dt"].astype(np.float64, copy=False),
        ground_truth=_float64(out["ground_truth"]),
        robot_pose=_float64(out["robot_pose"]),
        pose_confidence=_float64(out["pose_confidence"]),
        images=out["images"],
        stamps=None if out["stamps"] is None else out["stamps"].astype(np.int64, copy=False),
        settings=settings,
    )


def _check_settings(settings) -> dict[str, str | float | int | bool] | None:
    """``settings`` as a plain dict (``None`` stays), or a SequenceError naming the entry at fault."""
    if settings is None:
        return None
    if not isinstance(settings, dict):
        raise SequenceError(f"settings: expected a mapping of names to values, got {type(settings).__name__}")
    out = {}
    for name, value in settings.items():
        if not isinstance(name, str) or not name.strip():
            raise SequenceError(f"settings: names must be non-empty text, got {name!r}")
        if isinstance(value, np.generic):
            value = value.item()
        if not isinstance(value, str | bool | int | float):
            raise SequenceError(f"settings: {name}: expected text, a number or a boolean, got {type(value).__name__}")
        if isinstance(value, float) and not math.isfinite(value):
            raise SequenceError(f"settings: {name}: non-finite value {value}")
        out[name] = value
    return out


def _float64(arr: np.ndarray | None) -> np.ndarray | None:
    return None if arr is None else arr.astype(np.float64, copy=False)


def load_sequence(path: str | os.PathLike) -> Sequence:
    """Loads and validates a version-1 sequence file.

    Only the sequence's keys are read; other members of the archive are ignored.

    Raises:
        SequenceError: one line naming the file (and the key at fault, if any) and the
            problem: a missing, unreadable, empty or damaged file, a file of another
            kind (a directory, a .npy array, text, a pickle), an object array, or a
            key that breaks the contract (see :func:`validate_sequence`).
    """
    path = Path(path)
    try:
        present = _read_archive(path)
        if path.suffix.lower() != ".npz":
            named = f"the suffix '{path.suffix}'" if path.suffix else "no suffix"
            warnings.warn(f"{path}: a .npz archive with {named} (sequence files are .npz); read as a sequence "
                          "file", UserWarning, stacklevel=2)
        version = present.pop("format_version", None)
        if version is not None:
            if version.shape != () or version.dtype.kind not in "iu":
                raise SequenceError(f"format_version: expected an integer, got {_dtype_words(version.dtype)} "
                                    f"of shape {version.shape}")
            if int(version) != FORMAT_VERSION:
                raise SequenceError(f"format_version: {int(version)} is not supported "
                                    f"(this reads version {FORMAT_VERSION})")
        if not present:
            raise SequenceError(f"a zip archive without any of the sequence keys, not {_WHAT}")
        missing = [k for k in _REQUIRED if k not in present]
        if missing:
            raise SequenceError(f"{missing[0]}: missing (required keys: {', '.join(_REQUIRED)})")
        if "settings" in present:
            present["settings"] = _settings_from_text(present["settings"])
        return validate_sequence(Sequence(**present))
    except SequenceError as err:
        raise SequenceError(f"{path}: {err}") from None


_WHAT = f"a sequence file (.npz with the keys {', '.join(_REQUIRED)})"
# Errors a damaged archive member raises while it is decompressed and parsed.
# (RuntimeError: an encrypted member; NotImplementedError: an unknown compression.)
_DAMAGED = (zipfile.BadZipFile, zlib.error, EOFError, ValueError, OSError, RuntimeError, NotImplementedError)


def _read_archive(path: Path) -> dict[str, np.ndarray]:
    """The sequence keys (and ``format_version``) of the .npz at ``path``; a SequenceError without the path."""
    if path.is_dir():
        raise SequenceError(f"a directory, not {_WHAT}")
    try:
        fh = open(path, "rb")  # closed by the ``with`` below
    except FileNotFoundError:
        raise SequenceError("no such file") from None
    except PermissionError:
        raise SequenceError("permission denied (this user may not read the file)") from None
    except OSError as err:
        raise SequenceError(f"cannot be opened ({err.strerror or type(err).__name__})") from None
    with fh:
        try:
            head = fh.read(512)
            fh.seek(0)
        except OSError as err:
            raise SequenceError(f"cannot be read ({err.strerror or type(err).__name__})") from None
        if not head.startswith((b"PK\x03\x04", b"PK\x05\x06")):  # a zip archive's first entry, or an empty one
            raise SequenceError(_kind_of(head))
        try:
            archive = zipfile.ZipFile(fh)
        except (zipfile.BadZipFile, OSError, ValueError):
            raise SequenceError("a damaged or truncated .npz (zip) archive") from None
        with archive:
            members = {name.removesuffix(".npy"): name for name in archive.namelist()}
            return {key: _read_member(archive, members[key], key)
                    for key in (*_SPEC, "format_version", "settings") if key in members}


def _kind_of(head: bytes) -> str:
    """What a file that is not a zip archive is, from its first bytes."""
    if not head:
        return f"an empty file (0 bytes), not {_WHAT}"
    if head.startswith(b"\x93NUMPY"):
        return f"a .npy array, not {_WHAT}"
    if head.startswith(b"\x80"):
        return f"a Python pickle, not {_WHAT}"
    try:
        codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
        text = b"\x00" not in head
    except UnicodeDecodeError:
        text = False
    return f"a text file, not {_WHAT}" if text else f"not a zip archive, so not {_WHAT}"


def _read_member(archive: zipfile.ZipFile, name: str, key: str) -> np.ndarray:
    """One array of the archive; its dtype is read from the header first so object arrays are never unpickled."""
    damaged = f"{key}: damaged data (the archive is corrupt or truncated)"
    try:
        with archive.open(name) as fh:
            version = npy_format.read_magic(fh)
            read_header = npy_format.read_array_header_1_0 if version == (1, 0) else npy_format.read_array_header_2_0
            _, _, dtype = read_header(fh)
    except ValueError:  # a header that is not NumPy's
        raise SequenceError(f"{key}: not a readable NumPy array (damaged, or not written by NumPy)") from None
    except _DAMAGED:
        raise SequenceError(damaged) from None
    if dtype.hasobject:
        raise SequenceError(f"{key}: expected dtype {_expected_dtype(key)}, got Python objects "
                            "(an object array; these are never loaded)")
    try:
        with archive.open(name) as fh:
            return npy_format.read_array(fh, allow_pickle=False)
    except _DAMAGED:
        raise SequenceError(damaged) from None


def _expected_dtype(key: str) -> str:
    if key == "settings":
        return "text (a JSON object)"
    return _SPEC[key][1] if key in _SPEC else "int64"


def save_sequence(path: str | os.PathLike, seq: Sequence) -> None:
    """Validates ``seq`` and writes it atomically as a version-1 .npz file."""
    seq = validate_sequence(seq)
    path = Path(path)
    arrays = {k: v for k, v in seq._asdict().items() if v is not None and k != "settings"}
    if seq.settings is not None:
        arrays["settings"] = np.asarray(json.dumps(seq.settings, sort_keys=True))
    arrays["format_version"] = np.asarray(FORMAT_VERSION, np.int64)
    write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays), binary=True)
