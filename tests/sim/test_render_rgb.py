"""RGB frames of the simulated world: the ball where the heat map has it (OpenCV's projection), hidden when
occluded, deterministic, with changing light."""

import cv2
import numpy as np
import pytest

from heatpf_jax.sim.render_rgb import render_rgb, render_rgb_frame
from heatpf_jax.sim.scenarios import simulate_with_info


@pytest.fixture(scope="module")
def occlusion():
    seq, info = simulate_with_info("occlusion", 2, num_steps=80, rgb=True)
    return seq, info


def _ball_centre(frame, truth_uv, radius_px):
    """Centroid of the bright, grey pixels near the expected place."""
    rgb = frame.astype(float)
    bright = (rgb.min(axis=-1) > 130) & (np.ptp(rgb, axis=-1) < 40)
    vv, uu = np.mgrid[: frame.shape[0], : frame.shape[1]]
    near = (uu - truth_uv[0]) ** 2 + (vv - truth_uv[1]) ** 2 <= (2.5 * radius_px) ** 2
    sel = bright & near
    return (uu[sel].mean(), vv[sel].mean(), int(sel.sum())) if sel.any() else (np.nan, np.nan, 0)


def test_ball_is_drawn_at_its_projection_and_hidden_when_occluded(occlusion):
    """The ball's silhouette (the pixels it changes in a noise-free frame) is centred on OpenCV's projection
    of the ground-truth centre; while occluded, no white ball is near that place."""
    seq, info = occlusion
    frames = seq.images
    assert frames.shape == (*seq.heatmaps.shape, 3) and frames.dtype == np.uint8
    k = np.array([[seq.intrinsics[0], 0, seq.intrinsics[2]], [0, seq.intrinsics[1], seq.intrinsics[3]], [0, 0, 1]])
    shape = seq.heatmaps.shape[1:]
    clutter = {"robots": np.zeros((0, 2)), "posts": np.zeros((0, 2))}
    checked = 0
    for t in range(0, seq.num_steps, 3):
        cam = info["true_cam_to_base"][t]
        pose = np.linalg.inv(cam)
        rvec, _ = cv2.Rodrigues(pose[:3, :3])
        centre = np.array([[*seq.ground_truth[t], float(seq.ball_radius)]])
        uv = cv2.projectPoints(centre, rvec, pose[:3, 3], k, None)[0].reshape(2)
        depth = (pose[:3, :3] @ centre[0] + pose[:3, 3])[2]
        radius_px = seq.intrinsics[0] * float(seq.ball_radius) / depth
        margin = 3 * radius_px
        inside = margin <= uv[0] <= shape[1] - margin and margin <= uv[1] <= shape[0] - margin
        args = (seq.intrinsics, cam, shape, info["robot_pose"][t])
        rest = (float(seq.ball_radius), clutter, np.zeros((0, 2)), np.zeros(0))
        without = render_rgb_frame(*args, [], *rest)
        if info["occluded"][t]:
            # No more white near the ball's place than the field lines there make.
            assert _ball_centre(frames[t], uv, radius_px)[2] <= _ball_centre(without, uv, radius_px)[2] + 3, t
        elif inside:
            with_ball = render_rgb_frame(*args, [(seq.ground_truth[t], np.eye(3))], *rest)
            vv, uu = np.nonzero(np.any(with_ball != without, axis=-1))
            assert np.hypot(uu.mean() - uv[0], vv.mean() - uv[1]) < 0.5, (t, uu.mean(), vv.mean(), uv)
            checked += 1
    assert checked > 5 and info["occluded"].any()


def test_frames_are_deterministic_and_the_light_changes(occlusion):
    seq, info = occlusion
    brightness = seq.images.reshape(seq.num_steps, -1).mean(axis=1)
    assert brightness.max() / brightness.min() > 1.05
    n = 6  # the first frames of the same world, rendered again
    short = {k: v[:n] if isinstance(v, np.ndarray) and v.shape[:1] == (seq.num_steps,) else v for k, v in info.items()}
    head = seq.head(n)
    np.testing.assert_array_equal(render_rgb(head, short, seed=2), seq.images[:n])
    assert not np.array_equal(render_rgb(head, short, seed=3), seq.images[:n])
