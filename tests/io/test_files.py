"""The atomic write helper: a failed write leaves the old file and no temporary file."""

from __future__ import annotations

import pytest

from heatpf_jax.io.files import write_atomic


def test_write_atomic_replaces_only_on_success(tmp_path):
    path = tmp_path / "out.csv"
    path.write_text("old\n")
    write_atomic(path, lambda fh: fh.write("new\n"))
    assert path.read_text() == "new\n"

    def fails(fh):
        fh.write("half")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_atomic(path, fails)
    assert path.read_text() == "new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


def test_write_atomic_binary(tmp_path):
    path = tmp_path / "blob.bin"
    write_atomic(path, lambda fh: fh.write(b"\x00\x01"), binary=True)
    assert path.read_bytes() == b"\x00\x01"
