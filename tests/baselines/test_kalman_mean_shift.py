"""The Kalman variant ("Mean Shift + KL") against a NumPy Kalman filter on its own measurements."""

import numpy as np

from tests.baselines.moving_disc import TRACKERS, run_tracker


def test_kalman_variant_is_a_kalman_filter_on_its_measurements(sequence):
    """The filtered positions equal a NumPy constant-velocity Kalman filter run on the mean-shift results
    the tracker recorded (the disc stays inside the image, so the in-image clip is a no-op)."""
    frames, path, q = sequence
    tracker = TRACKERS["mean_shift_kalman"]
    p = tracker.default_params()
    _, info = run_tracker("mean_shift_kalman", frames, q, path[0])
    assert np.all(np.asarray(info.found))
    f = np.eye(4)
    f[0, 2] = f[1, 3] = 1.0
    g = np.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]])
    qn = p.accel_std**2 * g @ g.T
    hm = np.eye(2, 4)
    r = p.meas_std**2 * np.eye(2)
    x = np.array([path[0, 0], path[0, 1], 0.0, 0.0])
    cov = np.diag([p.init_position_std**2] * 2 + [p.init_velocity_std**2] * 2)
    want = []
    for z in np.asarray(info.measurement, np.float64):
        x, cov = f @ x, f @ cov @ f.T + qn
        s = hm @ cov @ hm.T + r
        gain = cov @ hm.T @ np.linalg.inv(s)
        x = x + gain @ (z - hm @ x)
        cov = (np.eye(4) - gain @ hm) @ cov
        want.append(x[:2])
    np.testing.assert_allclose(np.asarray(info.position), np.array(want), atol=2e-3)
    # And the measurements are the mean shift's: not simply the true path (the filter does something).
    assert not np.allclose(np.asarray(info.position), np.asarray(info.measurement), atol=1e-2)
