"""Temporal priors: parameter names, fitting the body to joints (re-exported from fit3d), smooth
motion with limits; the walking model and prior are in test_walking."""

import numpy as np
import pytest

from zoopraxis.core.body import fit3d
from zoopraxis.core.geometry import se3
from zoopraxis.core.priors import motion_prior as mp
from zoopraxis.core.body.body import Pose, make_body
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX


@pytest.fixture(scope="module")
def body():
    return make_body("sidenbladh")


def random_pose(body, rng, spread=0.4):
    """A pose with every angle well inside its limits and the elbows and knees bent."""
    mid = 0.5 * (body.lower + body.upper)
    half = 0.5 * (body.upper - body.lower)
    angles = mid + spread * half * rng.uniform(-1, 1, body.n_dofs)
    root = se3.transform(se3.exp_so3(rng.normal(0, 0.3, 3)), rng.normal(0, 1, 3))
    return Pose(root, angles)


# -- parameters ---------------------------------------------------------------------------------


def test_param_names_put_the_root_first(body):
    names = mp.param_names(body)
    assert names[:6] == ("tx", "ty", "tz", "rx", "ry", "rz")
    assert names[6:] == body.dof_names
    assert list(mp.param_index(body, ["rz", "l_elbow_flex"])) == [
        5, 6 + body.dof_index("l_elbow_flex")]


def test_param_index_names_the_unknown_parameter(body):
    with pytest.raises(ZoopraxisError, match="no pose parameter 'l_wrist_flex'"):
        mp.param_index(body, ["l_wrist_flex"])


# -- fitting the body to joints (core.fit3d, re-exported for the walking prior's training) --------


def test_fitting_is_fit3d_s(body):
    assert mp.fit_pose is fit3d.fit_pose and mp.fit_body is fit3d.fit_body
    assert mp.root_from_joints is fit3d.root_from_joints


def test_root_from_joints_faces_minus_y_at_rest(body):
    root = fit3d.root_from_joints(body.joints(body.rest_pose()))
    np.testing.assert_allclose(root, np.eye(4), atol=1e-12)


def test_fit_pose_recovers_a_known_pose(body, rng):
    for _ in range(3):
        truth = random_pose(body, rng)
        pose, rms = fit3d.fit_pose(body, body.joints(truth))
        assert rms < 1e-3
        np.testing.assert_allclose(body.joints(pose), body.joints(truth), atol=3e-3)


def test_fit_pose_from_the_previous_frame_follows_a_motion(body, rng):
    truth = random_pose(body, rng, 0.3)
    pose, _ = fit3d.fit_pose(body, body.joints(truth))
    moved = Pose(se3.exp_se3([0.05, 0.0, 0.02, 0.0, 0.0, 0.1]) @ truth.root,
                 body.clamp(truth.angles + 0.05))
    again, rms = fit3d.fit_pose(body, body.joints(moved), pose)
    assert rms < 1e-3


def test_fit_pose_ignores_unknown_joints(body, rng):
    truth = random_pose(body, rng)
    joints = body.joints(truth)
    joints[JOINT_INDEX["head"]] = np.nan
    pose, rms = fit3d.fit_pose(body, joints)
    assert rms < 1e-3


def test_fit_pose_refuses_bad_joints(body):
    with pytest.raises(ZoopraxisError, match=r"shape \(17, 3\)"):
        fit3d.fit_pose(body, np.zeros((16, 3)))
    with pytest.raises(ZoopraxisError, match="only 2 of 17 joints"):
        fit3d.fit_pose(body, np.r_[np.zeros((2, 3)), np.full((15, 3), np.nan)])
    with pytest.raises(ZoopraxisError, match=r"fit_body: joints must have shape \(F, 17, 3\)"):
        fit3d.fit_body(body, np.zeros((17, 3)))


def test_fit_body_recovers_limb_lengths(body, rng):
    lengths = {"thigh": 0.47, "shank": 0.45, "upper_arm": 0.31, "forearm": 0.24,
               "hip_width": 0.2, "shoulder_width": 0.4}
    truth = body.with_dims(lengths)
    poses = [random_pose(body, rng, 0.3) for _ in range(4)]
    joints = np.array([truth.joints(p) for p in poses])
    fitted, fitted_poses, rms = fit3d.fit_body(body, joints)
    assert rms.max() < 3e-3
    for name, value in lengths.items():
        assert abs(fitted.dims[name] - value) < 5e-3, name


# -- smooth motion (§6.1) -----------------------------------------------------------------------


def test_smooth_prior_moves_at_constant_velocity_without_noise(body, rng):
    P = 6 + body.n_dofs
    prior = mp.SmoothMotionPrior(body, sigma_position=np.zeros(P), sigma_velocity=np.zeros(P))
    state = prior.init_state(body.rest_pose(), 3, rng)
    state["dangles"][:] = 0.01
    state["dt"][:] = [0.02, 0.0, 0.0]
    state["dr"][:] = [0.0, 0.0, 0.05]
    for _ in range(5):
        state = prior.propagate(state, rng)
    roots, angles = prior.poses(state)
    expected = np.clip(0.05, body.lower, body.upper)
    np.testing.assert_allclose(angles, np.broadcast_to(expected, angles.shape), atol=1e-12)
    np.testing.assert_allclose(roots[:, :3, 3], np.broadcast_to([0.1, 0, 0], (3, 3)))
    np.testing.assert_allclose(roots[0, :3, :3], se3.exp_so3([0, 0, 0.25]), atol=1e-12)


def test_smooth_prior_spreads_by_its_sigma(body, rng):
    prior = mp.SmoothMotionPrior(body, sigma_velocity=0.0)
    pose = random_pose(body, rng, 0.2)
    state = prior.init_state(pose, 20000, rng, spread=np.zeros(6 + body.n_dofs))
    moved = prior.propagate(state, rng)
    measured = np.std(moved["angles"] - pose.angles, axis=0)
    np.testing.assert_allclose(measured, prior.sigma_position[6:], rtol=0.05)


def test_smooth_prior_keeps_angles_inside_the_limits(body, rng):
    wild = mp.SmoothMotionPrior(body, sigma_position=0.5, sigma_velocity=0.3)
    state = wild.init_state(random_pose(body, rng, 0.9), 500, rng)
    for _ in range(10):
        state = wild.propagate(state, rng)
        assert np.all(state["angles"] >= body.lower) and np.all(state["angles"] <= body.upper)
    # The limits truncate the Gaussian (samples outside are drawn again) rather than pile
    # samples up on them, as clipping would: a third of these would land outside.
    prior = mp.SmoothMotionPrior(body, sigma_position=0.3, sigma_velocity=0.0)
    pose = Pose(np.eye(4), body.lower + 0.1)
    state = prior.propagate(prior.init_state(pose, 2000, rng, spread=0.0), rng)
    on_limit = np.isclose(state["angles"], body.lower) | np.isclose(state["angles"], body.upper)
    assert on_limit.mean() < 0.01
    assert np.all(state["angles"] >= body.lower)


def test_smooth_prior_holds_inactive_parameters(body, rng):
    arm = ["l_shoulder_flex", "l_shoulder_abd", "l_shoulder_rot", "l_elbow_flex"]
    prior = mp.SmoothMotionPrior(body, active=arm)
    pose = random_pose(body, rng, 0.3)
    state = prior.init_state(pose, 200, rng)
    for _ in range(5):
        state = prior.propagate(state, rng)
    roots, angles = prior.poses(state)
    moving = mp.param_index(body, arm) - 6
    fixed = np.setdiff1d(np.arange(body.n_dofs), moving)
    np.testing.assert_array_equal(angles[:, fixed], np.broadcast_to(pose.angles[fixed],
                                                                    (200, len(fixed))))
    np.testing.assert_allclose(roots, np.broadcast_to(pose.root, roots.shape), atol=1e-12)
    assert np.all(np.std(angles[:, moving], axis=0) > 0.01)


def test_smooth_prior_uniform_start(body, rng):
    prior = mp.SmoothMotionPrior(body)
    state = prior.init_state(body.rest_pose(), 20000, rng,
                             uniform={"l_shoulder_rot": (-1.0, 1.0)})
    twist = state["angles"][:, body.dof_index("l_shoulder_rot")]
    assert twist.min() >= -1.0 and twist.max() <= 1.0
    assert abs(np.std(twist) - 2.0 / np.sqrt(12.0)) < 0.01


def test_smooth_prior_refuses_bad_settings(body, rng):
    with pytest.raises(ZoopraxisError, match="sigma_position must be finite and >= 0"):
        mp.SmoothMotionPrior(body, sigma_position=-1.0)
    with pytest.raises(ZoopraxisError, match="no pose parameter 'elbow'"):
        mp.SmoothMotionPrior(body, active=["elbow"])
    with pytest.raises(ZoopraxisError, match="uniform start for 'l_elbow_flex'"):
        mp.SmoothMotionPrior(body).init_state(body.rest_pose(), 10, rng,
                                              uniform={"l_elbow_flex": (1.0, 0.5)})


# -- annealing moves ----------------------------------------------------------------------------


def test_smooth_prior_perturb_moves_one_group_and_its_velocity(body, rng):
    prior = mp.SmoothMotionPrior(body)
    state = prior.init_state(random_pose(body, rng), 500, rng)
    cols = mp.param_index(body, ["l_hip_flex", "l_knee_flex"])
    moved = prior.perturb(state, cols, 2.0, rng)
    d = moved["angles"] - state["angles"]
    others = np.setdiff1d(np.arange(body.n_dofs), cols - 6)
    assert np.all(d[:, others] == 0)
    np.testing.assert_allclose(moved["t"], state["t"])
    np.testing.assert_allclose(d.std(axis=0)[cols - 6], 2.0 * prior.sigma_position[cols],
                               rtol=0.15)
    assert moved["dangles"] is state["dangles"]
    carried = mp.SmoothMotionPrior(body, carry_moves=True).perturb(state, cols, 2.0, rng)
    np.testing.assert_allclose(carried["dangles"] - state["dangles"],
                               carried["angles"] - state["angles"], atol=1e-12)
    assert np.any(carried["dangles"] != state["dangles"])
    assert np.all(moved["angles"] >= body.lower) and np.all(moved["angles"] <= body.upper)
    root = prior.perturb(state, np.arange(6), 1.0, rng)
    assert np.all(root["angles"] == state["angles"])
    np.testing.assert_allclose((root["t"] - state["t"]).std(axis=0),
                               prior.sigma_position[:3], rtol=0.15)
