"""The version-1 sequence file contract: round trip and every documented error."""

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
    with pytest.raises(hp.SequenceError) as info:
        hp.load_sequence(path)
    message = str(info.value)
    assert message.startswith(field), message
    assert fragment in message, message


def test_unreadable_and_missing_files(tmp_path):
    with pytest.raises(hp.SequenceError, match="no such file"):
        hp.load_sequence(tmp_path / "absent.npz")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip file at all")
    with pytest.raises(hp.SequenceError, match="not a readable"):
        hp.load_sequence(junk)


def test_save_refuses_bad_sequence_and_keeps_existing_file(tmp_path, seq):
    path = tmp_path / "keep.npz"
    hp.save_sequence(path, seq)
    before = path.read_bytes()
    with pytest.raises(hp.SequenceError, match="heatmaps"):
        hp.save_sequence(path, seq._replace(heatmaps=seq.heatmaps + 2.0))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.npz"]  # no temporary file left behind
