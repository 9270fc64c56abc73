"""``heatpf colour``: a sequence's RGB frames into colour-likelihood heat maps; every argument checked first."""

import numpy as np
import pytest
from PIL import Image

from heatpf_jax.cli import main
from heatpf_jax.colour_likelihood import ColourParams, colour_heatmaps
from heatpf_jax.colour_space import num_bins, patch_histogram, smooth_chromaticity, smooth_intensity
from heatpf_jax.sequence import load_sequence, save_sequence
from heatpf_jax.sim import simulate


@pytest.fixture(scope="module")
def rgb_file(tmp_path_factory):
    seq = simulate("standard", 0, num_steps=4, shrink=4, rgb=True)
    path = tmp_path_factory.mktemp("rgb") / "in.npz"
    save_sequence(path, seq)
    return path, seq


def _error(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_box_in_a_frame_gives_the_library_heat_maps(tmp_path, rgb_file, capsys):
    path, seq = rgb_file
    out = tmp_path / "colour.npz"
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "-o", str(out)]) == 0
    got = load_sequence(out)
    q = smooth_chromaticity(smooth_intensity(patch_histogram(seq.images[1], (20, 10, 4, 4))))
    want = colour_heatmaps(seq.images, q, seq.intrinsics, seq.cam_to_base, seq.ball_radius, ColourParams(),
                           top_bins=num_bins())  # every bin: exact whatever the command's table size
    np.testing.assert_allclose(got.heatmaps, np.asarray(want), atol=1e-6)
    np.testing.assert_array_equal(got.images, seq.images)
    np.testing.assert_array_equal(got.ground_truth, seq.ground_truth)
    before = out.read_bytes()
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "-o", str(out)]) == 2
    assert "--output" in _error(capsys) and out.read_bytes() == before  # never replaced without --force


def test_reference_images_png_and_npy(tmp_path, rgb_file):
    path, seq = rgb_file
    patch = seq.images[0, 8:16, 18:26]
    Image.fromarray(patch).save(tmp_path / "ref.png")
    np.save(tmp_path / "ref.npy", patch)
    outs = []
    for ref in ("ref.png", "ref.npy"):
        out = tmp_path / f"{ref}.npz"
        assert main(["colour", str(path), "--reference", str(tmp_path / ref), "-o", str(out)]) == 0
        outs.append(load_sequence(out).heatmaps)
    np.testing.assert_array_equal(outs[0], outs[1])  # PNG is lossless


@pytest.mark.parametrize("args, message", [
    (["--box", "20,10,4"], "--box: expected x,y,w,h"),
    (["--box", "45,10,8,8", "--frame", "0"], "--box: 45,10,8,8 is not inside frame 0"),
    (["--box", "1,1,4,4", "--frame", "9"], "--frame: must be in [0, 3]"),
    (["--box", "1,1,4,4"], "--reference: give a reference image"),
    (["--box", "1,1,4,4", "--frame", "0", "--theta", "1.0"], "--theta: must lie in [0, 1)"),
    (["--box", "1,1,4,4", "--frame", "0", "--chroma-smoothing", "0.5"], "--chroma-smoothing: must lie in [0, 0.5)"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, rgb_file, capsys, args, message):
    path, _ = rgb_file
    out = tmp_path / "o.npz"
    assert main(["colour", str(path), *args, "-o", str(out)]) == 2
    assert message in _error(capsys) and not out.exists()


def test_a_sequence_without_images_is_refused(tmp_path, rgb_file, capsys):
    path, seq = rgb_file
    plain = tmp_path / "plain.npz"
    save_sequence(plain, seq._replace(images=None))
    assert main(["colour", str(plain), "--box", "1,1,4,4", "--frame", "0", "-o", str(tmp_path / "o.npz")]) == 2
    assert _error(capsys).endswith("images: missing; heatpf colour needs RGB frames (key images, uint8 [T, H, W, 3])")
