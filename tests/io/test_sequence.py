"""The version-1 sequence file contract: round trip and every documented error."""

import errno
import importlib
import os
import pickle
import zipfile

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.sim import simulate_standard


@pytest.fixture(scope="module")
def seq() -> hp.Sequence:
    return simulate_standard(7, num_steps=6, shrink=5)


def _save_raw(path, **arrays):
    np.savez(path, **arrays)
    return path


def test_round_trip_preserves_every_key(tmp_path, seq):
    path = tmp_path / "seq.npz"
    hp.save_sequence(path, seq)
    loaded = hp.load_sequence(path)
    for key in hp.Sequence._fields:
        np.testing.assert_array_equal(getattr(loaded, key), getattr(seq, key), err_msg=key)
    assert loaded.heatmaps.dtype == np.float32 and loaded.cam_to_base.dtype == np.float64
    assert loaded.has_heatmap.dtype == bool


def test_ground_truth_is_optional(tmp_path, seq):
    path = tmp_path / "nogt.npz"
    hp.save_sequence(path, seq._replace(ground_truth=None))
    assert hp.load_sequence(path).ground_truth is None


def _bad(seq, **changes):
    arrays = {k: v for k, v in seq._asdict().items() if v is not None}
    arrays.update(changes)
    return {k: v for k, v in arrays.items() if v is not None}


@pytest.mark.parametrize(
    "change, field, fragment",
    [
        (lambda s: _bad(s, odometry=None), "odometry", "missing"),
        (lambda s: _bad(s, heatmaps=s.heatmaps[0]), "heatmaps", "shape"),
        (lambda s: _bad(s, heatmaps=(s.heatmaps * 255).astype(np.uint8)), "heatmaps", "dtype"),
        (lambda s: _bad(s, has_heatmap=s.has_heatmap.astype(np.float64)), "has_heatmap", "dtype"),
        (lambda s: _bad(s, intrinsics=s.intrinsics[:3]), "intrinsics", "shape"),
        (lambda s: _bad(s, odometry=s.odometry[:-1]), "odometry", "length"),
        (lambda s: _bad(s, ground_truth=np.zeros((s.num_steps, 3))), "ground_truth", "shape"),
        (lambda s: _bad(s, heatmaps=np.where(np.arange(s.heatmaps.size).reshape(s.heatmaps.shape) == 5,
                                             np.nan, s.heatmaps).astype(np.float32)), "heatmaps", "non-finite"),
        (lambda s: _bad(s, heatmaps=s.heatmaps + 1.5), "heatmaps", "[0, 1]"),
        (lambda s: _bad(s, heatmaps=s.heatmaps - 0.5), "heatmaps", "[0, 1]"),
        (lambda s: _bad(s, odometry=np.full_like(s.odometry, np.inf)), "odometry", "non-finite"),
        (lambda s: _bad(s, cam_to_base=s.cam_to_base * np.array([1, 1, 1.1, 1])[None, None, :]),
         "cam_to_base", "rigid"),
        (lambda s: _bad(s, cam_to_base=s.cam_to_base @ np.diag([1.0, 1.0, -1.0, 1.0])), "cam_to_base", "rigid"),
        (lambda s: _bad(s, dt=np.asarray(0.0)), "dt", "positive"),
        (lambda s: _bad(s, intrinsics=np.array([-1.0, 1.0, 0.0, 0.0])), "intrinsics", "positive"),
    ],
)
def test_bad_files_name_the_field(tmp_path, seq, change, field, fragment):
    path = _save_raw(tmp_path / "bad.npz", **change(seq))
    message = _load_error(path)
    assert message.startswith(f"{path}: {field}: "), message
    assert fragment in message, message


def test_validate_sequence_names_the_field_without_a_file(seq):
    with pytest.raises(hp.SequenceError) as info:
        hp.validate_sequence(seq._replace(odometry=np.array([["a", "b", "c"]] * seq.num_steps)))
    assert str(info.value) == "odometry: expected dtype float64, got text (str)"
    with pytest.raises(hp.SequenceError, match=r"^dt: cannot be made an array \(a list of ragged"):
        hp.validate_sequence(seq._replace(dt=[1.0, [2.0, 3.0]]))


# --------------------------------------------------------------------------- files that are not sequences


def _load_error(path) -> str:
    """The message of the SequenceError that loading ``path`` raises, checked to be one plain line."""
    with pytest.raises(hp.SequenceError) as info:
        hp.load_sequence(path)
    message = str(info.value)
    assert "\n" not in message and message == message.strip(), repr(message)
    # Nothing from NumPy's or zipfile's own wording, and no chained exception behind it.
    for internal in ("pickled", "allow_pickle", "context manager", "Errno", "zip file", "EOF", "CRC"):
        assert internal not in message, message
    assert info.value.__cause__ is None and info.value.__suppress_context__
    return message


KEYS = "(.npz with the keys heatmaps, has_heatmap, intrinsics, cam_to_base, odometry, ball_radius, dt)"


def _empty(tmp_path, seq):
    (path := tmp_path / "empty.npz").write_bytes(b"")
    return path


def _npy(tmp_path, seq):
    np.save(path := tmp_path / "seq.npy", seq.heatmaps)
    return path


def _text(tmp_path, seq):
    (path := tmp_path / "seq.npz").write_text("heatmaps,has_heatmap\n0.5,1\n")
    return path


def _pickle(tmp_path, seq):
    with open(path := tmp_path / "seq.pkl", "wb") as fh:
        pickle.dump(seq._asdict(), fh)
    return path


def _directory(tmp_path, seq):
    (path := tmp_path / "seq.npz").mkdir()
    return path


def _truncated(tmp_path, seq):
    hp.save_sequence(full := tmp_path / "full.npz", seq)
    data = full.read_bytes()
    (path := tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    return path


def _corrupt_member(tmp_path, seq):
    """An uncompressed archive with bytes of odometry's array data flipped (its CRC no longer matches)."""
    path = _save_raw(tmp_path / "corrupt.npz", **_bad(seq))
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("odometry.npy")
    data = bytearray(path.read_bytes())
    end = info.header_offset + 30 + len(info.filename) + len(info.extra) + info.compress_size
    data[end - 16 : end] = bytes(b ^ 0xFF for b in data[end - 16 : end])  # the last values, past the .npy header
    path.write_bytes(bytes(data))
    return path


def _object_array(tmp_path, seq):
    arrays = _bad(seq, odometry=np.array([1, "a"], dtype=object))
    np.savez(path := tmp_path / "objects.npz", **arrays, allow_pickle=True)
    return path


def _strings(tmp_path, seq):
    return _save_raw(tmp_path / "strings.npz", **_bad(seq, intrinsics=np.array(["fx", "fy", "cx", "cy"])))


def _version_text(tmp_path, seq):
    return _save_raw(tmp_path / "v.npz", **_bad(seq), format_version=np.array("one"))


def _version_2(tmp_path, seq):
    return _save_raw(tmp_path / "v2.npz", **_bad(seq), format_version=np.array(2))


def _other_zip(tmp_path, seq):
    with zipfile.ZipFile(path := tmp_path / "notes.zip", "w") as archive:
        archive.writestr("readme.txt", "hello")
    return path


UNREADABLE = [
    (_empty, f"an empty file (0 bytes), not a sequence file {KEYS}"),
    (_npy, f"a .npy array, not a sequence file {KEYS}"),
    (_text, f"a text file, not a sequence file {KEYS}"),
    (_pickle, f"a Python pickle, not a sequence file {KEYS}"),
    (_directory, f"a directory, not a sequence file {KEYS}"),
    (_truncated, "a damaged or truncated .npz (zip) archive"),
    (_corrupt_member, "odometry: damaged data (the archive is corrupt or truncated)"),
    (_object_array,
     "odometry: expected dtype float64, got Python objects (an object array; these are never loaded)"),
    (_strings, "intrinsics: expected dtype float64, got text (str)"),
    (_version_text, "format_version: expected an integer, got text (str) of shape ()"),
    (_version_2, "format_version: 2 is not supported (this reads version 1)"),
    (_other_zip, f"a zip archive without any of the sequence keys, not a sequence file {KEYS}"),
]


@pytest.mark.parametrize(
    "make, expected", [pytest.param(m, e, id=m.__name__.strip("_")) for m, e in UNREADABLE]
)
def test_unreadable_files_give_one_plain_line(tmp_path, seq, make, expected):
    path = make(tmp_path, seq)
    assert _load_error(path) == f"{path}: {expected}"


def test_missing_file(tmp_path):
    assert _load_error(tmp_path / "absent.npz") == f"{tmp_path / 'absent.npz'}: no such file"


def test_file_without_read_permission(tmp_path, seq, monkeypatch):
    path = tmp_path / "locked.npz"
    hp.save_sequence(path, seq)
    path.chmod(0)
    if os.access(path, os.R_OK):  # root reads anything: stand in for the refusal the OS gives other users
        def refuse(file, *args, **kwargs):
            raise PermissionError(errno.EACCES, "Permission denied", str(file))

        monkeypatch.setattr(importlib.import_module("heatpf_jax.io.sequence"), "open", refuse, raising=False)
    try:
        assert _load_error(path) == f"{path}: permission denied (this user may not read the file)"
    finally:
        path.chmod(0o644)


def test_cli_reports_an_empty_file_in_one_line(tmp_path, capsys):
    from heatpf_jax.cli.parser import main

    path = tmp_path / "empty.npz"
    path.write_bytes(b"")
    out = tmp_path / "o.csv"
    assert main(["run", str(path), "--output", str(out)]) == 2
    captured = capsys.readouterr()
    assert captured.err.splitlines() == [f"heatpf: error: {path}: an empty file (0 bytes), not a sequence file {KEYS}"]
    assert "Traceback" not in captured.err + captured.out
    assert not out.exists()


def test_save_refuses_bad_sequence_and_keeps_existing_file(tmp_path, seq):
    path = tmp_path / "keep.npz"
    hp.save_sequence(path, seq)
    before = path.read_bytes()
    with pytest.raises(hp.SequenceError, match="heatmaps"):
        hp.save_sequence(path, seq._replace(heatmaps=seq.heatmaps + 2.0))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.npz"]  # no temporary file left behind


def test_stamps_round_trip_and_are_checked(tmp_path, small_sequence):
    """The optional clock: kept through save and load (int64 ns), cut by ``head``, refused when it decreases or is
    not integral, and never an input of the run (the same estimates with or without it)."""
    import jax

    stamps = 1_700_000_000_000_000_000 + np.arange(small_sequence.num_steps, dtype=np.int64) * 100_000_000
    path = tmp_path / "timed.npz"
    hp.save_sequence(path, small_sequence._replace(stamps=stamps))
    got = hp.load_sequence(path)
    assert got.stamps.dtype == np.int64
    np.testing.assert_array_equal(got.stamps, stamps)
    np.testing.assert_array_equal(got.head(3).stamps, stamps[:3])
    back = stamps.copy()
    back[4] = back[3] - 1
    with pytest.raises(hp.SequenceError, match=r"^stamps: must not decrease, got \d+ ns at step 4 after"):
        hp.validate_sequence(small_sequence._replace(stamps=back))
    with pytest.raises(hp.SequenceError, match="^stamps: expected dtype int64, got float64"):
        hp.validate_sequence(small_sequence._replace(stamps=stamps.astype(np.float64)))
    model, params = hp.build("kalman")
    plain = hp.run(jax.random.key(0), small_sequence, params, model).info.mean
    timed = hp.run(jax.random.key(0), got, params, model).info.mean
    np.testing.assert_array_equal(np.asarray(timed), np.asarray(plain))


def test_settings_round_trip_and_are_checked(tmp_path, seq):
    """The maker's settings: a JSON object of names and plain values, kept through save and load, checked with one
    line naming ``settings`` (and the entry at fault), and never an input of the run."""
    import jax

    advice = {"source": "pixels", "threshold": 0.25, "k": 3, "wide": True}
    path = tmp_path / "advised.npz"
    hp.save_sequence(path, seq._replace(settings=advice))
    got = hp.load_sequence(path)
    assert got.settings == advice and hp.load_sequence(_plain_file(tmp_path, seq)).settings is None
    with zipfile.ZipFile(path) as archive:  # text in the archive, never a pickled object
        assert "settings.npy" in archive.namelist()
    for text, fragment in (("[1, 2]", "expected a JSON object, got list"), ("{source", "not JSON"),
                           ('{"k": NaN}', "k: non-finite value nan"), ('{"k": [1]}', "k: expected text, a number")):
        bad = _save_raw(tmp_path / "bad.npz", **_bad(seq), settings=np.asarray(text))
        message = _load_error(bad)
        assert message.startswith(f"{bad}: settings: ") and fragment in message, message
    bad = _save_raw(tmp_path / "bad.npz", **_bad(seq), settings=np.zeros(2))
    assert "settings: expected text (a JSON object), got float64" in _load_error(bad)
    with pytest.raises(hp.SequenceError, match="^settings: expected a mapping of names to values, got list$"):
        hp.validate_sequence(seq._replace(settings=["source=pixels"]))
    model, params = hp.build("kalman")
    plain = hp.run(jax.random.key(0), seq, params, model).info.mean
    advised = hp.run(jax.random.key(0), got, params, model).info.mean
    np.testing.assert_allclose(np.asarray(advised), np.asarray(plain), atol=1e-6)


def _plain_file(tmp_path, seq):
    path = tmp_path / "plain.npz"
    hp.save_sequence(path, seq)
    return path
