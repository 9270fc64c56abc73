"""``heatpf colour``: a sequence's RGB frames into colour-likelihood heat maps; every argument checked first."""

import numpy as np
import pytest
from PIL import Image

from heatpf_jax.cli import main
from heatpf_jax.cli.colour import colour_sequence
from heatpf_jax.colour.reference import SCALED_PARAMS
from heatpf_jax.io.sequence import load_sequence, save_sequence
from heatpf_jax.sim import simulate
from heatpf_jax.sim.render import project_centre
from heatpf_jax.sim.scenarios import simulate_with_info


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
    printed = capsys.readouterr().out
    got = load_sequence(out)
    want, ref = colour_sequence(seq, box=(20, 10, 4, 4), frame=1)
    np.testing.assert_allclose(got.heatmaps, want.heatmaps, atol=1e-6)
    np.testing.assert_array_equal(got.images, seq.images)
    np.testing.assert_array_equal(got.ground_truth, seq.ground_truth)
    assert (f"reference: the object's box {','.join(map(str, ref.box))} in frame 1 (from the box 20,10,4,4); "
            f"background: the ring around it in frame 1; ") in printed
    assert f"its own score {ref.score:.3f}" in printed and "compilation" in printed and "ms a frame" in printed
    # A colour blob is as large as the window that made it: the file tells heatpf run not to read its size.
    assert got.settings == want.settings == {"source": "pixels"}
    assert f"wrote {out}, with the settings source=pixels (a colour blob is as large as the window" in printed
    before = out.read_bytes()
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "-o", str(out)]) == 2
    assert "--output" in _error(capsys) and out.read_bytes() == before  # never replaced without --force


def test_the_outline_shapes_the_maps_unless_asked_not_to(tmp_path, rgb_file, capsys):
    """By default the maps are the histograms' shaped by the ball's outline, as the library's default
    (``silhouette=True``), and the command prints the reference's silhouette score; ``--silhouette`` says the same;
    ``--no-silhouette`` gives the histograms alone, as ``silhouette=False``."""
    path, seq = rgb_file
    outlined, plain, named = tmp_path / "outlined.npz", tmp_path / "plain.npz", tmp_path / "named.npz"
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "-o", str(outlined)]) == 0
    printed = capsys.readouterr().out
    want, ref = colour_sequence(seq, box=(20, 10, 4, 4), frame=1, silhouette=True)
    assert ref.silhouette_score > 0.0
    assert (f"maps: the colour histograms shaped by the ball's outline (the reference's own silhouette score "
            f"{ref.silhouette_score:.3f}; --no-silhouette: the histograms alone)") in printed
    got = load_sequence(outlined)
    np.testing.assert_allclose(got.heatmaps, want.heatmaps, atol=1e-6)
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "--silhouette", "-o", str(named)]) == 0
    capsys.readouterr()
    np.testing.assert_allclose(load_sequence(named).heatmaps, want.heatmaps, atol=1e-6)
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "--no-silhouette", "-o", str(plain)]) == 0
    assert "maps: the colour histograms alone (--no-silhouette)" in capsys.readouterr().out
    histograms = load_sequence(plain).heatmaps
    alone, _ = colour_sequence(seq, box=(20, 10, 4, 4), frame=1, silhouette=False)
    np.testing.assert_allclose(histograms, alone.heatmaps, atol=1e-6)
    assert not np.allclose(got.heatmaps, histograms, atol=1e-3)
    assert np.all(got.heatmaps <= histograms + 1e-6)  # the outline never raises the histogram's value
    assert got.settings == {"source": "pixels"}


def test_the_window_options_reach_the_maps(tmp_path, rgb_file):
    """``--window-scale`` and ``--window-waist`` (the cross inside a round ball) give the library's maps with those
    numbers, and the cross's maps differ from the square's."""
    path, seq = rgb_file
    out = tmp_path / "cross.npz"
    assert main(["colour", str(path), "--box", "20,10,4,4", "--frame", "1", "--window-scale", "0.851",
                 "--window-waist", "0.618", "-o", str(out)]) == 0
    params = SCALED_PARAMS._replace(window_scale=0.851, window_waist=0.618)
    want, _ = colour_sequence(seq, box=(20, 10, 4, 4), frame=1, params=params)
    np.testing.assert_allclose(load_sequence(out).heatmaps, want.heatmaps, atol=1e-6)
    square, _ = colour_sequence(seq, box=(20, 10, 4, 4), frame=1, params=params._replace(window_waist=1.0))
    assert not np.allclose(square.heatmaps, want.heatmaps)


def _ball_box(seq, t, scale, offset):
    """A user's box in frame ``t``: ``scale`` times the ball's diameter, moved by ``offset`` of it down and right."""
    u, v, depth = project_centre(np.array([*seq.ground_truth[t], float(seq.ball_radius)]), seq.intrinsics,
                                 seq.cam_to_base[t])
    side = 2 * scale * float(seq.intrinsics[0]) * float(seq.ball_radius) / depth
    return int(round(u - side / 2 + offset * side)), int(round(v - side / 2 + offset * side)), round(side), round(side)


@pytest.fixture(scope="module")
def full_size(tmp_path_factory):
    """24 frames at the renderer's full size, 200 x 150 (the ball is in view on steps 0-19)."""
    seq, info = simulate_with_info("standard", 1, num_steps=24, rgb=True)
    path = tmp_path_factory.mktemp("full") / "in.npz"
    save_sequence(path, seq)
    return path, seq, info["visible"]


HEAD = 6  # frames of full_size_head


@pytest.fixture(scope="module")
def full_size_head(full_size, tmp_path_factory):
    """The first frames of ``full_size``: a map depends on its own frame and the reference alone, so the checks that
    only compare two references' maps run on these."""
    _, seq, _ = full_size
    path = tmp_path_factory.mktemp("head") / "in.npz"
    save_sequence(path, seq.head(HEAD))
    return path


def test_a_users_box_at_the_default_threshold(tmp_path, full_size, full_size_head, capsys):
    """A box 30 % larger than the ball and off-centre by a quarter of it, taken as a user takes it; the maps are
    near 1 at the ball and ``heatpf run`` tracks it at its default threshold (no --set); the box saved as an
    image gives maps that peak at the ball too (its background: the input's frames)."""
    path, seq, visible = full_size
    assert visible[0] and visible.mean() > 0.8
    box = _ball_box(seq, 0, 1.3, 0.25)
    out = tmp_path / "colour.npz"
    assert main(["colour", str(path), "--box", ",".join(map(str, box)), "--frame", "0", "-o", str(out)]) == 0
    heat = load_sequence(out).heatmaps
    uv = np.array([project_centre(np.array([*g, float(seq.ball_radius)]), seq.intrinsics, c)[:2]
                   for g, c in zip(seq.ground_truth, seq.cam_to_base, strict=True)])
    vv, uu = np.mgrid[0:heat.shape[1], 0:heat.shape[2]]
    near = (uu[None] - uv[:, 0, None, None]) ** 2 + (vv[None] - uv[:, 1, None, None]) ** 2 <= 8.0**2
    at_ball = np.where(near, heat, 0).max(axis=(1, 2))[visible]
    assert np.median(at_ball) > 0.8 and at_ball.min() > 0.3, at_ball
    assert np.where(near, 0, heat).max() < 0.3  # nothing else over the threshold
    capsys.readouterr()
    csv = tmp_path / "est.csv"
    assert main(["run", str(out), "-o", str(csv)]) == 0
    assert f"{out}: source=pixels from the sequence's settings" in capsys.readouterr().out
    est = np.loadtxt(csv, delimiter=",", skiprows=1)[:, 1:3]
    error = np.linalg.norm(est - seq.ground_truth, axis=1)
    assert error[10:20].mean() < 0.03, error  # the ball in view (it is hidden on steps 20-26 of this seed)
    # The box cut out and saved as an image is found in frame 0, pixel for pixel: the same reference, the same maps
    # (checked on the first frames: each map depends on its frame and the reference alone).
    x, y, w, h = box
    Image.fromarray(seq.images[0, y:y + h, x:x + w]).save(tmp_path / "ball.png")
    out_png = tmp_path / "colour_png.npz"
    assert main(["colour", str(full_size_head), "--reference", str(tmp_path / "ball.png"), "-o", str(out_png)]) == 0
    printed = capsys.readouterr().out
    assert f"--reference: {tmp_path / 'ball.png'} is the box {x},{y},{w},{h} of frame 0, pixel for pixel" in printed
    assert "background: the ring around it in frame 0" in printed
    np.testing.assert_allclose(load_sequence(out_png).heatmaps, heat[:HEAD], atol=1e-6)
    # Saved as a JPEG, it is found within the tolerance (a lossy copy), at the same box.
    Image.fromarray(seq.images[0, y:y + h, x:x + w]).save(tmp_path / "ball.jpg", quality=90)
    assert main(["colour", str(full_size_head), "--reference", str(tmp_path / "ball.jpg"), "-o", str(out_png),
                 "--force"]) == 0
    printed = capsys.readouterr().out
    assert f"is the box {x},{y},{w},{h} of frame 0, to within " in printed and "(a lossy copy)" in printed
    np.testing.assert_allclose(load_sequence(out_png).heatmaps, heat[:HEAD], atol=1e-6)
    # An image that is no box of the frames (here the box enlarged 1.5 times) is taken by itself, its background
    # the input's frames; its maps peak at the ball too.
    Image.fromarray(seq.images[0, y:y + h, x:x + w]).resize((3 * w // 2, 3 * h // 2)).save(tmp_path / "ball2.png")
    assert main(["colour", str(path), "--reference", str(tmp_path / "ball2.png"), "-o", str(out_png),
                 "--force"]) == 0
    printed = capsys.readouterr().out
    assert "background: the input's frames" in printed and "of frame" not in printed
    heat_png = load_sequence(out_png).heatmaps
    assert np.median(np.where(near, heat_png, 0).max(axis=(1, 2))[visible]) > 0.8, heat_png.max(axis=(1, 2))


def test_any_length_is_mapped_by_one_program_in_chunks(monkeypatch):
    """``colour_sequence`` maps frames in chunks of one program's size, whatever the input's length (one
    compilation serves every file of these sizes); a frame's map is the same in whichever chunk and place it falls,
    and the padding of the last chunk does not reach the maps (a map depends on its frame and the reference alone).
    On the small frames of ``rgb_file`` (the chunking does not depend on the frames' size; its program is theirs)."""
    from heatpf_jax.cli import colour as cli_colour
    from heatpf_jax.colour import likelihood

    seq = simulate("standard", 0, num_steps=9, shrink=4, rgb=True)
    lowered = []
    real = likelihood.colour_heatmaps

    class Spy:
        def lower(self, images, *args, **kwargs):
            lowered.append(np.shape(images))
            return real.lower(images, *args, **kwargs)

    monkeypatch.setattr(likelihood, "colour_heatmaps", Spy())
    box = _ball_box(seq, 0, 1.3, 0.25)
    whole, _ = colour_sequence(seq, box=box, frame=0)  # two calls of 8 frames, the second padded with 7
    # Frames 1-2 left out: frames 3-8 move to other places (frame 8 into the first chunk), one call padded with one
    # frame; frame 0 (the reference's) stays.
    keep = np.r_[0, 3:9]
    per_step = ("heatmaps", "has_heatmap", "cam_to_base", "odometry", "ground_truth", "images")
    shifted, _ = colour_sequence(seq._replace(**{k: getattr(seq, k)[keep] for k in per_step}), box=box, frame=0)
    assert cli_colour._CHUNK_FRAMES == 8
    assert lowered == [(8, *seq.images.shape[1:])] * 2
    assert whole.heatmaps.shape == seq.heatmaps.shape and shifted.heatmaps.shape[0] == len(keep)
    assert np.all(whole.heatmaps[keep].max(axis=(1, 2)) > 0.3)  # the ball is in every one of these maps
    np.testing.assert_allclose(shifted.heatmaps, whole.heatmaps[keep], atol=1e-6)


def test_a_box_without_the_object_is_warned_about(tmp_path, full_size_head, capsys):
    out = tmp_path / "o.npz"
    assert main(["colour", str(full_size_head), "--box", "20,110,14,14", "--frame", "0", "-o", str(out)]) == 0
    warning = _error(capsys)
    assert warning.startswith("heatpf: warning: --box: the reference's own score is low"), warning


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
    # Cut out of frame 0, the image is found there: a --box inside it is that box of the frame.
    out = tmp_path / "inside.npz"
    assert main(["colour", str(path), "--reference", str(tmp_path / "ref.png"), "--box", "1,2,4,5", "-o",
                 str(out)]) == 0
    want, _ = colour_sequence(seq, box=(19, 10, 4, 5), frame=0)
    np.testing.assert_allclose(load_sequence(out).heatmaps, want.heatmaps, atol=1e-6)


@pytest.mark.parametrize("args, message", [
    (["--box", "20,10,4"], "--box: expected x,y,w,h"),
    (["--box", "45,10,8,8", "--frame", "0"], "--box: 45,10,8,8 is not inside frame 0"),
    (["--box", "1,1,4,4", "--frame", "9"], "--frame: must be in [0, 3]"),
    (["--box", "1,1,4,4"], "--reference: give a reference image"),
    (["--box", "1,1,4,4", "--frame", "0", "--theta", "1.0"], "--theta: must lie in [0, 1)"),
    (["--box", "1,1,4,4", "--frame", "0", "--chroma-smoothing", "0.5"], "--chroma-smoothing: must lie in [0, 0.5)"),
    (["--box", "1,1,4,4", "--frame", "0", "--window-waist", "1.5"], "--window-waist: must lie in [0, 1]"),
])
def test_bad_arguments_are_one_line_errors(tmp_path, rgb_file, capsys, args, message):
    path, _ = rgb_file
    out = tmp_path / "o.npz"
    assert main(["colour", str(path), *args, "-o", str(out)]) == 2
    assert message in _error(capsys) and not out.exists()


def test_an_unknown_background_is_a_one_line_usage_error(tmp_path, rgb_file, capsys):
    path, _ = rgb_file
    with pytest.raises(SystemExit) as exit_:
        main(["colour", str(path), "--box", "1,1,4,4", "--frame", "0", "--background", "sky", "-o",
              str(tmp_path / "o.npz")])
    assert exit_.value.code == 2
    assert "argument --background: invalid choice: 'sky'" in _error(capsys)


def test_a_sequence_without_images_is_refused(tmp_path, rgb_file, capsys):
    path, seq = rgb_file
    plain = tmp_path / "plain.npz"
    save_sequence(plain, seq._replace(images=None))
    assert main(["colour", str(plain), "--box", "1,1,4,4", "--frame", "0", "-o", str(tmp_path / "o.npz")]) == 2
    assert _error(capsys).endswith("images: missing; heatpf colour needs RGB frames (key images, uint8 [T, H, W, 3])")


def test_the_commands_defaults_are_the_librarys():
    """``heatpf colour``'s window and theta are those of ``SCALED_PARAMS``, with which the benchmarks measure."""
    from heatpf_jax.cli.parser import _build_parser

    args = _build_parser().parse_args(["colour", "in.npz", "--box", "1,1,4,4", "--frame", "0", "-o", "o.npz"])
    assert args.window_scale == SCALED_PARAMS.window_scale and args.theta == SCALED_PARAMS.theta
    assert args.window_waist == SCALED_PARAMS.window_waist
