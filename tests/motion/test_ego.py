"""Ego-motion pieces (Olufs et al. 3.5): pose deltas, confidence weighting, rotation only or all of it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import heatpf_jax as hp
from heatpf_jax.motion.ego import EGO_MOTIONS, LocalisationEgo, NoEgo, OdometryEgo, pose_confidences, pose_deltas
from heatpf_jax.presets import FilterOptions, build
from heatpf_jax.rollout import prepare_run
from tests.conftest import SMALL_FILTER, step_inputs


def _homogeneous(pose):
    c, s = np.cos(pose[2]), np.sin(pose[2])
    return np.array([[c, -s, pose[0]], [s, c, pose[1]], [0.0, 0.0, 1.0]])


def test_pose_deltas_against_homogeneous_transforms(rng):
    poses = np.cumsum(rng.normal(size=(12, 3)) * [0.3, 0.3, 0.8], axis=0) + [1e4, -3e3, 0.0]  # far from origin
    delta = pose_deltas(poses)
    assert np.all(delta[0] == 0.0)
    for t in range(1, len(poses)):
        rel = np.linalg.inv(_homogeneous(poses[t - 1])) @ _homogeneous(poses[t])
        np.testing.assert_allclose(delta[t, :2], rel[:2, 2], atol=1e-9)
        np.testing.assert_allclose(delta[t, 2], np.arctan2(rel[1, 0], rel[0, 0]), atol=1e-12)
    near = poses - poses[0]  # traced poses (a vmapped batch) take the float32 path
    np.testing.assert_allclose(pose_deltas(jnp.asarray(near, jnp.float32), jnp), pose_deltas(near), atol=2e-5)
    conf = np.array([0.9, 0.1, 0.8])
    np.testing.assert_allclose(pose_confidences(jnp.asarray(conf), 3, jnp), pose_confidences(conf, 3), atol=1e-7)


def test_pose_confidence_of_a_delta_is_the_lower_of_its_poses():
    conf = np.array([0.9, 0.1, 0.8, 0.95, 0.3])
    np.testing.assert_allclose(pose_confidences(conf, 5), [0.9, 0.1, 0.1, 0.8, 0.3])
    np.testing.assert_allclose(pose_confidences(None, 3), [1.0, 1.0, 1.0])


def test_pieces_split_the_motion_between_particles_and_tracks(small_sequence):
    plain = step_inputs(small_sequence, 1, odometry=(0.1, 0.02, -0.05))
    delta = jnp.array([0.2, -0.1, 0.3], jnp.float32)
    inputs = plain._replace(pose_delta=delta, pose_confidence=jnp.float32(0.25))
    odo = OdometryEgo().ego(inputs, None)
    np.testing.assert_array_equal(odo.particles, inputs.odometry)
    np.testing.assert_array_equal(odo.tracks, inputs.odometry)
    assert np.all(NoEgo().ego(inputs, None).particles == 0) and np.all(NoEgo().ego(inputs, None).tracks == 0)
    paper = LocalisationEgo().ego(inputs, None)
    np.testing.assert_allclose(paper.particles, [0.0, 0.0, 0.075], atol=1e-7)  # rotation only, weighted
    np.testing.assert_allclose(paper.tracks, [0.05, -0.025, 0.075], atol=1e-7)  # tracks: all of it
    full = LocalisationEgo(translate=True, weighted=False).ego(inputs, None)
    np.testing.assert_allclose(full.particles, delta)
    with pytest.raises(ValueError, match="robot_pose"):
        LocalisationEgo().ego(plain, None)


def test_a_sequence_without_poses_is_refused_in_one_line(small_sequence):
    model = build("paper", FilterOptions(ego="pose", num_particles=64, max_measurements=64)).model
    with pytest.raises(ValueError, match=r"^robot_pose: the sequence has no robot_pose"):
        prepare_run(small_sequence, model.default_params(), model)
    # Without a localisation ego-motion the optional keys are dropped: one compilation with or without them.
    plain = build("paper", FilterOptions(num_particles=64, max_measurements=64)).model
    seq = small_sequence._replace(robot_pose=np.zeros((small_sequence.num_steps, 3)))
    assert prepare_run(seq, plain.default_params(), plain)[0].robot_pose is None


def test_exact_localisation_at_full_confidence_is_the_odometry(small_sequence, rng):
    """With the odometry set to the pose deltas and confidence 1, ``pose_full`` is ``odometry`` bit for bit."""
    poses = np.cumsum(rng.normal(0.0, [0.05, 0.05, 0.1], (small_sequence.num_steps, 3)), axis=0) + [40.0, -12.0, 0.0]
    seq = small_sequence._replace(odometry=pose_deltas(poses), robot_pose=poses,
                                  pose_confidence=np.ones(small_sequence.num_steps))
    params = SMALL_FILTER.make_params(k=3)  # the model and shapes of test_tracker's: one compilation
    key = jax.random.key(1)
    ra = hp.run(key, seq, params, SMALL_FILTER).info.mean
    full = SMALL_FILTER._replace(ego=LocalisationEgo(translate=True))
    rb = hp.run(key, seq, params, full).info.mean
    np.testing.assert_array_equal(np.asarray(ra), np.asarray(rb))


def test_weighting_ignores_a_localisation_jump(small_sequence):
    """A standing robot whose localisation jumps 0.5 m and 30 degrees away and back at confidence 0.01:
    with the heat maps gone from the jump on, the estimate holds the ball only when weighted."""
    n = small_sequence.num_steps
    robot_pose = np.zeros((n, 3))
    robot_pose[12:15] = [0.5, 0.3, np.deg2rad(30.0)]
    conf = np.full(n, 0.95)
    conf[12:15] = 0.01
    seq = small_sequence._replace(has_heatmap=np.arange(n) < 12, robot_pose=robot_pose, pose_confidence=conf)
    errors = {}
    for weighted in (True, False):
        model = SMALL_FILTER._replace(ego=LocalisationEgo(weighted=weighted))
        mean = np.asarray(hp.run(jax.random.key(0), seq, model.make_params(aging=0.0), model).info.mean)
        errors[weighted] = float(np.linalg.norm(mean[13] - seq.ground_truth[11]))
    assert errors[True] < 0.15 and errors[False] > 0.5, errors


def test_every_named_ego_motion_builds():
    for name in EGO_MOTIONS:
        model = build("heatmap", FilterOptions(ego=name)).model
        assert model.requires == (("robot_pose",) if name.startswith("pose") else ())
    with pytest.raises(ValueError, match="^ego: must be one of"):
        build("heatmap", FilterOptions(ego="gps"))
