"""Camera geometry: closed-form ray/plane intersections, OpenCV projection, round trips."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp

INTRINSICS = np.array([320.0, 300.0, 159.5, 119.5])  # fx != fy and cx != cy to catch swaps
K_CV = np.array([[INTRINSICS[0], 0.0, INTRINSICS[2]], [0.0, INTRINSICS[1], INTRINSICS[3]], [0.0, 0.0, 1.0]])

# One compiled function per shape: a batch of pixels against one pose.
_project_pixels = jax.jit(jax.vmap(hp.camera.project_pixel, in_axes=(0, None, None, None, None)))


BATCH = 300


def project_pixels(uv, pose, plane, max_distance=np.inf):
    """project_pixel on a batch of pixels, padded to one fixed batch size so that it compiles once."""
    uv = np.asarray(uv, np.float64)
    n = uv.shape[0]
    assert n <= BATCH
    padded = np.concatenate([uv, np.zeros((BATCH - n, 2))])
    xy, valid = _project_pixels(
        jnp.asarray(padded, jnp.float32),
        jnp.asarray(INTRINSICS, jnp.float32),
        jnp.asarray(pose, jnp.float32),
        jnp.float32(plane),
        jnp.float32(max_distance),
    )
    return np.asarray(xy, np.float64)[:n], np.asarray(valid)[:n]


def project_points_np(points, pose, intrinsics=INTRINSICS):
    """project_points as float32 JAX arrays, results back as float64 NumPy."""
    uv, depth = hp.camera.project_points(
        jnp.asarray(points, jnp.float32), jnp.asarray(intrinsics, jnp.float32), jnp.asarray(pose, jnp.float32)
    )
    return np.asarray(uv, np.float64), np.asarray(depth, np.float64)


def ground_hit_pitch_only(u, v, h, phi, plane):
    """Closed form for a camera at (0, 0, h) pitched down by phi (no yaw/roll).

    In the base frame the optical axes are x = (0, -1, 0), y = (-sin phi, 0, -cos phi), z = (cos phi, 0, -sin phi),
    so the ray through (a, b) = ((u - cx) / fx, (v - cy) / fy) is (cos phi - b sin phi, -a, -(sin phi + b cos phi)).
    """
    a = (u - INTRINSICS[2]) / INTRINSICS[0]
    b = (v - INTRINSICS[3]) / INTRINSICS[1]
    down = np.sin(phi) + b * np.cos(phi)
    s = (h - plane) / np.where(down > 0, down, np.nan)
    return np.stack([s * (np.cos(phi) - b * np.sin(phi)), -s * a], -1), down > 0


def random_pose(rng):
    return hp.camera.camera_pose(
        height=rng.uniform(0.3, 0.8),
        pitch=np.deg2rad(rng.uniform(10, 60)),
        yaw=rng.uniform(-np.pi, np.pi),
        roll=rng.uniform(-0.4, 0.4),
        x=rng.uniform(-0.2, 0.2),
        y=rng.uniform(-0.2, 0.2),
    )


# --------------------------------------------------------------------------- camera_pose


def test_camera_pose_is_rigid_and_axes_follow_conventions():
    rng = np.random.default_rng(20)
    for _ in range(20):
        h, phi, psi, rho = rng.uniform(0.2, 1.0), rng.uniform(-1.2, 1.2), rng.uniform(-3, 3), rng.uniform(-1, 1)
        x, y = rng.uniform(-1, 1, 2)
        pose = hp.camera.camera_pose(height=h, pitch=phi, yaw=psi, roll=rho, x=x, y=y)
        rot = pose[:3, :3]
        np.testing.assert_allclose(rot.T @ rot, np.eye(3), atol=1e-12)
        assert np.linalg.det(rot) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(pose[3], [0, 0, 0, 1])
        np.testing.assert_allclose(pose[:3, 3], [x, y, h])
        # Optical z (forward): heading psi, tilted down by phi; roll does not move it.
        fwd = np.array([np.cos(phi) * np.cos(psi), np.cos(phi) * np.sin(psi), -np.sin(phi)])
        np.testing.assert_allclose(rot[:, 2], fwd, atol=1e-12)
        # Without roll, optical x points right of the heading (horizontal) and optical y points down-ish.
        pose0 = hp.camera.camera_pose(height=h, pitch=phi, yaw=psi, x=x, y=y)
        right = np.array([np.sin(psi), -np.cos(psi), 0.0])
        np.testing.assert_allclose(pose0[:3, 0], right, atol=1e-12)
        np.testing.assert_allclose(pose0[:3, 1], np.cross(fwd, right), atol=1e-12)
        assert pose0[2, 1] <= 0.0
        # Roll rotates the image axes about the optical axis by |roll|.
        assert rot[:, 0] @ pose0[:3, 0] == pytest.approx(np.cos(rho), abs=1e-12)
        assert abs(rot[:, 0] @ pose0[:3, 1]) == pytest.approx(abs(np.sin(rho)), abs=1e-12)
    # Pitch only: z axis (cos phi, 0, -sin phi).
    for phi in (0.1, 0.5, 1.0):
        np.testing.assert_allclose(hp.camera.camera_pose(height=0.5, pitch=phi)[:3, 2], [np.cos(phi), 0, -np.sin(phi)])


# --------------------------------------------------------------------------- project_pixel, closed form


@pytest.mark.parametrize("h, phi_deg, plane", [(0.5, 30.0, 0.0), (0.7, 15.0, 0.05), (0.35, 55.0, 0.1), (1.2, 8.0, 0.0)])
def test_principal_point_and_rows_land_at_closed_form(h, phi_deg, plane):
    phi = np.deg2rad(phi_deg)
    pose = hp.camera.camera_pose(height=h, pitch=phi)
    alphas = np.deg2rad(np.array([-0.9 * phi_deg, -0.5 * phi_deg, -2.0, 0.0, 3.0, 10.0, 25.0]))
    betas = np.deg2rad(np.array([-20.0, -5.0, 0.0, 7.0, 20.0]))
    uv = np.concatenate(
        [
            np.stack([np.full_like(alphas, INTRINSICS[2]), INTRINSICS[3] + INTRINSICS[1] * np.tan(alphas)], 1),
            np.stack([INTRINSICS[2] + INTRINSICS[0] * np.tan(betas), np.full_like(betas, INTRINSICS[3])], 1),
        ]
    )
    xy, valid = project_pixels(uv, pose, plane)
    assert valid.all()
    n = alphas.size
    # Principal point (alpha = 0): x = (h - plane) / tan(phi), y = 0; row cy + fy tan(a): (h - plane) / tan(phi + a).
    np.testing.assert_allclose(xy[:n, 0], (h - plane) / np.tan(phi + alphas), rtol=2e-5)
    np.testing.assert_allclose(xy[:n, 1], 0.0, atol=1e-5)
    # Column cx + fx tan(b) on the principal row: same x, y = -(h - plane) tan(b) / sin(phi) (right is -y).
    np.testing.assert_allclose(xy[n:, 0], (h - plane) / np.tan(phi), rtol=2e-5)
    np.testing.assert_allclose(xy[n:, 1], -(h - plane) * np.tan(betas) / np.sin(phi), rtol=2e-5, atol=1e-6)


def test_random_pixels_match_closed_form_and_horizon_is_invalid():
    rng = np.random.default_rng(21)
    for h, phi, plane in [(0.6, 0.15, 0.0), (0.45, 0.25, 0.06)]:
        pose = hp.camera.camera_pose(height=h, pitch=phi)
        uv = np.stack([rng.uniform(0, 320, 300), rng.uniform(0, 240, 300)], 1)
        want, want_valid = ground_hit_pitch_only(uv[:, 0], uv[:, 1], h, phi, plane)
        # Keep away from the horizon row, where float32 decides the sign of a tiny dz.
        b = (uv[:, 1] - INTRINSICS[3]) / INTRINSICS[1]
        far = np.abs(np.sin(phi) + b * np.cos(phi)) > 1e-2
        xy, valid = project_pixels(uv, pose, plane)
        assert (~want_valid).sum() > 20 and want_valid.sum() > 20
        np.testing.assert_array_equal(valid[far], want_valid[far])
        ok = far & want_valid
        np.testing.assert_allclose(xy[ok], want[ok], rtol=1e-4, atol=1e-5)
        # Invalid rays return (0, 0).
        np.testing.assert_array_equal(xy[~valid], 0.0)
        # Above the horizon: v < cy - fy tan(phi).
        above = uv[:, 1] < INTRINSICS[3] - INTRINSICS[1] * np.tan(phi) - 0.5
        assert above.any() and not valid[above].any()


def test_parallel_and_upward_rays_are_invalid():
    # Level camera: the principal row is exactly parallel to the plane.
    level = hp.camera.camera_pose(height=0.5, pitch=0.0)
    uv = np.array([[INTRINSICS[2], INTRINSICS[3]], [10.0, INTRINSICS[3]], [300.0, INTRINSICS[3]], [100.0, 20.0]])
    xy, valid = project_pixels(uv, level, 0.0)
    assert not valid.any()
    np.testing.assert_array_equal(xy, 0.0)
    # A camera looking up never sees the floor.
    up = hp.camera.camera_pose(height=0.5, pitch=-0.3)
    grid = np.stack(np.meshgrid(np.arange(0, 320, 40.0), np.arange(0, 240, 40.0)), -1).reshape(-1, 2)
    # Rows below cy + fy tan(0.3) still point upwards.
    _, valid = project_pixels(grid, up, 0.0)
    assert not valid[grid[:, 1] < INTRINSICS[3] + INTRINSICS[1] * np.tan(0.3) - 1].any()
    # A plane above the camera, camera looking down: the intersection is behind the camera.
    down = hp.camera.camera_pose(height=0.3, pitch=0.5)
    _, valid = project_pixels(np.array([[INTRINSICS[2], INTRINSICS[3]]]), down, 0.5)
    assert not valid.any()


def test_yaw_rotates_the_landing_point_and_offset_translates_it():
    h, phi, plane = 0.55, np.deg2rad(25.0), 0.04
    d = (h - plane) / np.tan(phi)
    for psi in np.deg2rad([-150.0, -60.0, 0.0, 35.0, 90.0, 170.0]):
        for roll in (0.0, 0.3):  # roll about the optical axis does not move the principal point
            for ox, oy in ((0.0, 0.0), (0.3, -0.2)):
                pose = hp.camera.camera_pose(height=h, pitch=phi, yaw=psi, roll=roll, x=ox, y=oy)
                xy, valid = project_pixels(np.array([[INTRINSICS[2], INTRINSICS[3]]]), pose, plane)
                assert valid.all()
                np.testing.assert_allclose(xy[0], [ox + d * np.cos(psi), oy + d * np.sin(psi)], atol=2e-5)


def test_max_distance_invalidates_far_points():
    h, phi, plane = 0.6, np.deg2rad(20.0), 0.0
    d = (h - plane) / np.tan(phi)
    pose = hp.camera.camera_pose(height=h, pitch=phi)
    centre = np.array([[INTRINSICS[2], INTRINSICS[3]]])
    xy, valid = project_pixels(centre, pose, plane, max_distance=d * 1.01)
    assert valid.all()
    np.testing.assert_allclose(xy[0], [d, 0.0], rtol=2e-5, atol=1e-6)
    xy, valid = project_pixels(centre, pose, plane, max_distance=d * 0.99)
    assert not valid.any()
    np.testing.assert_array_equal(xy, 0.0)
    # Horizontal distance from the base origin, not from the camera: shift the camera sideways.
    pose = hp.camera.camera_pose(height=h, pitch=phi, y=1.0)
    radial = np.hypot(d, 1.0)
    assert project_pixels(centre, pose, plane, max_distance=radial * 1.01)[1].all()
    assert not project_pixels(centre, pose, plane, max_distance=radial * 0.99)[1].any()
    # A column of pixels: valid exactly where the closed-form distance is within the limit.
    rows = np.linspace(INTRINSICS[3] - 60, 239, 300)
    uv = np.stack([np.full_like(rows, 40.0), rows], 1)
    pose = hp.camera.camera_pose(height=h, pitch=phi)
    want, want_valid = ground_hit_pitch_only(uv[:, 0], uv[:, 1], h, phi, plane)
    dist = np.where(want_valid, np.hypot(want[:, 0], want[:, 1]), np.inf)
    limit = 2.0
    clear = np.abs(dist - limit) > 1e-3
    _, valid = project_pixels(uv, pose, plane, max_distance=limit)
    np.testing.assert_array_equal(valid[clear], (dist <= limit)[clear])
    assert valid.any() and not valid.all()


# --------------------------------------------------------------------------- project_points


def test_project_points_matches_opencv():
    rng = np.random.default_rng(22)
    worst_px = 0.0
    for _ in range(5):
        pose = random_pose(rng)
        rot, t = pose[:3, :3], pose[:3, 3]
        # Points in front of the camera (in the optical frame), mapped to the base frame.
        p_cam = np.stack([rng.uniform(-1, 1, 100), rng.uniform(-1, 1, 100), rng.uniform(0.5, 5.0, 100)], 1)
        points = p_cam @ rot.T + t
        rvec = cv2.Rodrigues(rot.T)[0]
        tvec = -rot.T @ t
        uv_cv, _ = cv2.projectPoints(points, rvec, tvec, K_CV, None)
        uv, depth = project_points_np(points, pose)
        worst_px = max(worst_px, float(np.abs(uv - uv_cv[:, 0, :]).max()))
        np.testing.assert_allclose(uv, uv_cv[:, 0, :], atol=1e-3)
        np.testing.assert_allclose(depth, p_cam[:, 2], rtol=1e-5, atol=1e-5)
    print(f"\nproject_points vs cv2.projectPoints: max difference {worst_px:.2e} px")
    # A point behind the camera has negative depth.
    pose = hp.camera.camera_pose(height=0.5, pitch=0.3)
    behind = (pose[:3, :3] @ np.array([0.1, 0.2, -1.0]) + pose[:3, 3])[None, :]
    assert project_points_np(behind, pose)[1][0] < 0


def test_project_points_under_strict_rank_promotion():
    pose = hp.camera.camera_pose(height=0.5, pitch=0.4)
    points = np.array([[1.0, 0.2, 0.0], [2.0, -0.5, 0.0]])
    uv, depth = hp.camera.project_points(jnp.asarray(points, jnp.float32), jnp.asarray(INTRINSICS, jnp.float32), pose)
    uv_cv, _ = cv2.projectPoints(points, cv2.Rodrigues(pose[:3, :3].T)[0], -pose[:3, :3].T @ pose[:3, 3], K_CV, None)
    np.testing.assert_allclose(np.asarray(uv), uv_cv[:, 0, :], atol=1e-3)


def test_round_trip_ground_points():
    rng = np.random.default_rng(23)
    for i in range(4):
        pose = hp.camera.camera_pose(
            height=rng.uniform(0.3, 0.8),
            pitch=np.deg2rad(rng.uniform(10, 60)),
            yaw=rng.uniform(-0.4, 0.4),
            roll=rng.uniform(-0.3, 0.3),
        )
        plane = [0.0, 0.05, 0.1, 0.0][i]
        pts = np.stack([rng.uniform(0.5, 6.0, 300), rng.uniform(-3.0, 3.0, 300), np.full(300, plane)], 1)
        p_cam = (pts - pose[:3, 3]) @ pose[:3, :3]
        front = p_cam[:, 2] > 0.05
        assert front.sum() > 200
        uv, depth = project_points_np(pts, pose)
        np.testing.assert_array_equal(depth > 0.05, front)
        xy, valid = project_pixels(uv, pose, plane)
        assert valid[front].all()
        err = np.hypot(*(xy[front] - pts[front, :2]).T)
        dist = np.hypot(*(pts[front, :2] - pose[:2, 3]).T)
        # float32: the error grows with distance (grazing rays); 1e-4 relative to the distance, squared beyond 1 m.
        assert np.all(err <= 1e-4 * np.maximum(dist, 1.0) ** 2), np.max(err / np.maximum(dist, 1.0) ** 2)
