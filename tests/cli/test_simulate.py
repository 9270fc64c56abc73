"""``heatpf simulate`` and ``heatpf frame`` through ``main``: the files equal the library's worlds, the grid's
coordinates are the pixels' own, and bad input is one line before any work, leaving no file behind."""

from __future__ import annotations

import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.cli import main
from heatpf_jax.cli.simulate import draw_frame
from heatpf_jax.sim import simulate, simulate_family


@pytest.fixture(autouse=True)
def _no_compilation_cache(monkeypatch):
    monkeypatch.setenv("HEATPF_NO_CACHE", "1")


def _fields_close(got: hp.Sequence, want: hp.Sequence) -> None:
    for name in ("heatmaps", "ground_truth", "cam_to_base", "odometry", "has_heatmap", "intrinsics"):
        np.testing.assert_allclose(getattr(got, name), getattr(want, name), rtol=0, atol=1e-6, err_msg=name)


def test_simulate_a_family_world_and_rgb_frames(tmp_path, capsys):
    fam = tmp_path / "fam.npz"
    assert main(["simulate", "kicked_hidden", "--family", "--seed", "2", "--steps", "6", "--shrink", "4",
                 "-o", str(fam)]) == 0
    _fields_close(hp.load_sequence(fam), simulate_family("kicked_hidden", 2, num_steps=6, shrink=4))
    assert "family/kicked_hidden, seed 2: 6 steps" in capsys.readouterr().out

    rgb = tmp_path / "rgb.npz"
    assert main(["simulate", "standard", "--steps", "4", "--shrink", "4", "--rgb", "-o", str(rgb)]) == 0
    got, want = hp.load_sequence(rgb), simulate("standard", 0, num_steps=4, shrink=4, rgb=True)
    _fields_close(got, want)
    np.testing.assert_array_equal(got.images, want.images)

    png = tmp_path / "heat.png"
    assert main(["frame", str(rgb), "--step", "3", "--heatmap", "--grid", "5", "-o", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_grid_labels_are_the_pixels_coordinates():
    """One red pixel at column 7, row 4 of a 30 x 20 image is drawn where the axes put (x=7, y=4)."""
    image = np.full((20, 30, 3), 255, np.uint8)
    image[4, 7] = (255, 0, 0)
    fig = draw_frame(image, grid=5)
    fig.canvas.draw()
    rgba = np.asarray(fig.canvas.buffer_rgba())
    ax = fig.axes[0]
    height = rgba.shape[0]
    for (x, y), red in (((7, 4), True), ((8, 4), False), ((7, 5), False), ((4, 7), False)):
        px, py = ax.transData.transform((x, y))
        r, g, b = rgba[int(round(height - py)), int(round(px)), :3]
        assert (r > 200 and g < 60 and b < 60) == red, (x, y, (r, g, b))
    assert list(ax.get_xticks()) == [0, 5, 10, 15, 20, 25] and list(ax.get_yticks()) == [0, 5, 10, 15]
    import matplotlib.pyplot as plt

    plt.close(fig)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["simulate", "nope", "-o", "{out}"], "heatpf: error: scenario: unknown scenario 'nope'"),
        (["simulate", "standard", "--family", "--rgb", "-o", "{out}"], "heatpf: error: --rgb:"),
        (["simulate", "standard", "--steps", "0", "-o", "{out}"], "heatpf: error: --steps:"),
        (["simulate", "standard", "--steps", "3", "-o", "{existing}"], "heatpf: error: --output:"),
        (["frame", "{seq}", "--step", "20", "-o", "{out}"], "heatpf: error: --step: must be in [0, 19]"),
        (["frame", "{seq}", "--step", "1", "-o", "{out}"], "heatpf: error: --step: "),
        (["frame", "{seq}", "--step", "1", "--grid", "0", "--heatmap", "-o", "{out}"], "heatpf: error: --grid:"),
        (["frame", "{seq}", "--step", "1", "--heatmap", "-o", "{seq}"], "heatpf: error: --output:"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(argv, message, tmp_path, small_sequence, capsys):
    seq, existing, out = tmp_path / "seq.npz", tmp_path / "existing.npz", tmp_path / "out.file"
    hp.save_sequence(seq, small_sequence)
    existing.write_bytes(b"the user's file")
    before = seq.read_bytes()
    names = {"out": out, "existing": existing, "seq": seq}
    assert main([a.format(**names) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith(message) and err.count("\n") == 1, err
    assert not out.exists() and existing.read_bytes() == b"the user's file" and seq.read_bytes() == before
