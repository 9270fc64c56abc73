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

:func:`load_sequence` checks every key and raises :class:`SequenceError` naming
the key and the problem; :func:`save_sequence` validates first and writes
atomically (a temporary file renamed into place), so nothing is half-written.
"""

from __future__ import annotations

import os
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from heatpf_jax.files import write_atomic

__all__ = ["FORMAT_VERSION", "Sequence", "SequenceError", "load_sequence", "save_sequence", "validate_sequence"]

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

    @property
    def num_steps(self) -> int:
        return int(np.shape(self.heatmaps)[0])

    def head(self, num_steps: int) -> Sequence:
        """The first ``num_steps`` steps (per-step arrays cut, constants kept)."""
        per_step = ("heatmaps", "has_heatmap", "cam_to_base", "odometry", "ground_truth")
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
}
_REQUIRED = tuple(k for k in _SPEC if k != "ground_truth")


def _check_array(key: str, value, dims: dict[str, int]) -> np.ndarray:
    kind, dtype_name, shape = _SPEC[key]
    arr = np.asarray(value)
    if arr.dtype.kind != kind:
        raise SequenceError(f"{key}: expected dtype {dtype_name}, got {arr.dtype}")
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
        ground_truth=None if out["ground_truth"] is None else out["ground_truth"].astype(np.float64, copy=False),
    )


def load_sequence(path: str | os.PathLike) -> Sequence:
    """Loads and validates a version-1 sequence file.

    Raises:
        SequenceError: the file cannot be read as .npz, or breaks the contract
            (the message names the key and the problem).
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            present = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise SequenceError(f"{path}: no such file") from None
    except (OSError, ValueError, zipfile.BadZipFile) as err:
        raise SequenceError(f"{path}: not a readable .npz file ({err})") from None
    missing = [k for k in _REQUIRED if k not in present]
    if missing:
        raise SequenceError(f"{missing[0]}: missing from {path.name} (required keys: {', '.join(_REQUIRED)})")
    version = present.get("format_version")
    if version is not None and int(version) != FORMAT_VERSION:
        raise SequenceError(f"format_version: {int(version)} is not supported (this reads version {FORMAT_VERSION})")
    return validate_sequence(Sequence(**{k: present.get(k) for k in _SPEC}))


def save_sequence(path: str | os.PathLike, seq: Sequence) -> None:
    """Validates ``seq`` and writes it atomically as a version-1 .npz file."""
    seq = validate_sequence(seq)
    path = Path(path)
    arrays = {k: v for k, v in seq._asdict().items() if v is not None}
    arrays["format_version"] = np.asarray(FORMAT_VERSION, np.int64)
    write_atomic(path, lambda fh: np.savez_compressed(fh, **arrays), binary=True)
