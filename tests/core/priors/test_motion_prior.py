"""Temporal priors: fitting the body to joints, smooth motion with limits, the walking model."""

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


# -- the walking model (§6.2) -------------------------------------------------------------------


@pytest.fixture(scope="module")
def model():
    return mp.WalkModel.load()


def test_shipped_walk_model_is_small_and_covers_the_body(body, model):
    assert mp.DEFAULT_WALK_PRIOR.stat().st_size < 200_000
    assert set(model.dof_names) <= set(body.dof_names)
    assert model.mean.shape == (len(model.dof_names) + 6, model.n_samples)
    assert 1 <= model.n_components <= 8
    # Orthonormal eigencurves.
    B = model.basis.reshape(model.n_components, -1)
    np.testing.assert_allclose(B @ B.T, np.eye(model.n_components), atol=1e-9)
    # A walk: knees flex, hips swing, and the body moves forwards.
    knee = model.mean[model.curve_names.index("l_knee_flex")]
    assert knee.max() - knee.min() > 0.3
    assert model.mean[model.curve_names.index("speed")].mean() > 0.2
    assert 0.5 < model.cycle_seconds < 2.0
    # learned from the walks of many performers (tools/learn_walk_prior.py): 51 cycles of 12,
    # each with its mirror image, where the prior of subject 131 alone had 7
    assert len(model.coefficients) >= 80


def test_walk_model_evaluates_its_samples_and_is_periodic(model, rng):
    c = rng.normal(size=(1, model.n_components)) * model.coef_std
    k = 5
    value = model.evaluate(np.array([k / model.n_samples]), c)[0]
    np.testing.assert_allclose(value, model.mean[:, k] + np.einsum("d,dc->c", c[0],
                                                                   model.basis[:, :, k]))
    np.testing.assert_allclose(model.evaluate(np.array([0.3]), c),
                               model.evaluate(np.array([1.3]), c), atol=1e-12)
    # Between samples it interpolates linearly.
    half = model.evaluate(np.array([(k + 0.5) / model.n_samples]), c)[0]
    after = model.evaluate(np.array([(k + 1) / model.n_samples]), c)[0]
    np.testing.assert_allclose(half, 0.5 * (value + after), atol=1e-12)


def test_walk_model_fit_recovers_phase_and_coefficients(model, rng):
    n = len(model.dof_names)
    for phase in (0.1, 0.55, 0.9):
        c = rng.normal(size=model.n_components) * 0.5 * model.coef_std
        values = model.evaluate(np.array([phase]), c[None])[0]
        values[n:] = np.nan                       # a pose gives angles only
        fit_phase, fit_c, rms = model.fit(values)
        assert abs((fit_phase - phase + 0.5) % 1.0 - 0.5) <= 1.0 / model.n_samples
        assert rms < 0.05


def test_walk_model_round_trip_and_bad_files(model, tmp_path):
    path = tmp_path / "walk.npz"
    model.save(path)
    again = mp.WalkModel.load(path)
    np.testing.assert_array_equal(again.basis, model.basis)
    assert again.dof_names == model.dof_names
    with pytest.raises(ZoopraxisError, match="no such walking model"):
        mp.WalkModel.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "bad.npz", mean=np.zeros((3, 4)))
    with pytest.raises(ZoopraxisError, match="bad.npz: walking model lacks 'dof_names'"):
        mp.WalkModel.load(tmp_path / "bad.npz")


def test_learn_walk_model_finds_the_variation(body, rng):
    K = 32
    mu = np.arange(K) / K
    C = body.n_dofs + 6
    shapes = np.sin(2 * np.pi * (mu + rng.uniform(size=(C, 1))))
    cycles = np.array([1.0 + a * shapes + b * np.cos(2 * np.pi * mu)
                       for a, b in rng.normal(size=(12, 2))])
    model = mp.learn_walk_model(body, cycles, cycle_seconds=1.0)
    assert model.n_components == 2
    np.testing.assert_allclose(model.mean, cycles.mean(axis=0), atol=1e-12)
    rebuilt = model.mean + np.einsum("md,dck->mck", model.coefficients, model.basis)
    np.testing.assert_allclose(rebuilt, cycles, atol=1e-9)
    with pytest.raises(ZoopraxisError, match="at least 2 walking cycles"):
        mp.learn_walk_model(body, cycles[:1], cycle_seconds=1.0)


def test_mirror_curves_twice_is_the_identity(body, model):
    # a training cycle: the mean of cycles and their mirror images, and so its leading
    # eigencurves, can be their own mirror images
    curves = model.mean + np.einsum("d,dck->ck", model.coefficients[0], model.basis)
    once = mp.mirror_curves(body, curves)
    assert not np.allclose(once, curves)
    np.testing.assert_allclose(mp.mirror_curves(body, once), curves, atol=1e-12)
    left, right = (model.curve_names.index(n) for n in ("l_knee_flex", "r_knee_flex"))
    np.testing.assert_allclose(once[left], np.roll(curves[right], -model.n_samples // 2))


def test_heading_rotation_turns_the_facing_to_the_direction_of_travel(rng):
    forward = rng.normal(size=(5, 3))
    forward[:, 2] = 0
    R = mp.heading_rotation(forward)
    facing = R @ np.array([0.0, -1.0, 0.0])
    np.testing.assert_allclose(facing, forward / np.linalg.norm(forward, axis=1)[:, None],
                               atol=1e-12)
    assert np.all(se3.is_rotation(R))


def synthetic_walk(fps=60.0, seconds=4.0, cycle=1.0, speed=1.2):
    """Joints of a stick walker along +x: pelvis forward at ``speed``, ankles swinging."""
    t = np.arange(int(seconds * fps)) / fps
    joints = np.zeros((len(t), 17, 3))
    x = speed * t
    swing = 0.3 * np.sin(2 * np.pi * t / cycle)
    for name, y, dx in (("pelvis", 0.0, 0 * t), ("l_hip", 0.1, 0 * t), ("r_hip", -0.1, 0 * t),
                        ("l_ankle", 0.1, swing), ("r_ankle", -0.1, -swing)):
        joints[:, JOINT_INDEX[name]] = np.stack([x + dx, np.full_like(t, y), 0 * t], axis=1)
    return joints


def test_find_gait_cycles_in_a_synthetic_walk():
    fps = 60.0
    cycles, heading = mp.find_gait_cycles(synthetic_walk(fps), fps)
    assert len(cycles) >= 2
    for a, b in cycles:
        # One cycle per second, starting where the left ankle passes the right one.
        assert abs((b - a) / fps - 1.0) < 0.02
        assert abs(a / fps - round(a / fps)) < 0.02
    np.testing.assert_allclose(heading[len(heading) // 2], [1, 0, 0], atol=1e-6)


def test_find_gait_cycles_rejects_walking_sideways():
    fps = 60.0
    joints = synthetic_walk(fps)
    # Same feet, but the hips face across the path: a side step, not a walk.
    joints[:, JOINT_INDEX["l_hip"], :2] = joints[:, JOINT_INDEX["pelvis"], :2] + [0.1, 0.0]
    joints[:, JOINT_INDEX["r_hip"], :2] = joints[:, JOINT_INDEX["pelvis"], :2] - [0.1, 0.0]
    assert mp.find_gait_cycles(joints, fps)[0] == []


def test_cmu_slow_walk_has_gait_cycles(shared_data):
    from zoopraxis.core.files import cmu

    joints = cmu.standard_joints(cmu.load_cmu(shared_data / "cmu_mocap" / "131_02.bvh", fps=30))
    cycles, _ = mp.find_gait_cycles(joints, 30.0)
    assert len(cycles) >= 3
    assert all(0.5 < (b - a) / 30.0 < 2.0 for a, b in cycles)


# -- the walking prior (eqs. 14-17) -------------------------------------------------------------


def quiet(spread=0.0):
    return {"phase": spread, "c": spread, "rate": spread, "t": spread, "r": spread}


def test_walking_prior_reproduces_the_model_cycle(body, model, rng):
    prior = mp.WalkingPrior(body, model, fps=30, eps=0, sigma_phase=0, sigma_rate=0,
                            sigma_path=0, sigma_turn=0)
    c = model.coef_std * 0.3
    start = mp.WalkingPrior(body, model, fps=30)
    # A pose on the cycle at phase 0.25, facing +x.
    seed = {"c": c[None], "phase": np.array([0.25]), "rate": np.array([0.0]),
            "t": np.array([[0.0, 0.0, 0.9]]), "R": mp.heading_rotation([1.0, 0, 0])[None],
            "dr": np.zeros((1, 3)), "rest": np.zeros((1, body.n_dofs)),
            "offset": np.zeros((1, body.n_dofs))}
    roots, angles = start.poses(seed)
    pose = Pose(roots[0], angles[0])
    state = prior.init_state(pose, 1, rng, spread=quiet(), phase=0.25, coefficients=c,
                             rate=0.03)
    np.testing.assert_allclose(state["t"], seed["t"], atol=1e-9)
    np.testing.assert_allclose(state["R"], seed["R"], atol=1e-9)
    travelled = 0.0
    for k in range(10):
        speed = model.evaluate(state["phase"], state["c"])[0, len(model.dof_names)]
        travelled += prior.scale * speed * 0.03
        state = prior.propagate(state, rng)
    assert abs(state["phase"][0] - 0.55) < 1e-12
    np.testing.assert_allclose(state["t"][0], [travelled, 0.0, 0.9], atol=1e-9)
    roots, angles = prior.poses(state)
    expected = model.evaluate(np.array([0.55]), c[None])[0, :len(model.dof_names)]
    index = [body.dof_index(n) for n in model.dof_names]
    np.testing.assert_allclose(angles[0, index],
                               np.clip(expected, body.lower[index], body.upper[index]),
                               atol=1e-12)


def test_walking_prior_finds_the_phase_of_a_pose(body, model, rng):
    prior = mp.WalkingPrior(body, model)
    c = model.coef_std * rng.normal(size=model.n_components) * 0.3
    for phase in (0.2, 0.7):
        state = {"c": c[None], "phase": np.array([phase]), "rate": np.zeros(1),
                 "t": np.zeros((1, 3)), "R": np.eye(3)[None], "dr": np.zeros((1, 3)),
                 "rest": np.zeros((1, body.n_dofs)), "offset": np.zeros((1, body.n_dofs))}
        roots, angles = prior.poses(state)
        found, _, rms = prior.fit_pose(Pose(roots[0], angles[0]))
        assert abs((found - phase + 0.5) % 1.0 - 0.5) <= 2.0 / model.n_samples
        assert rms < 0.05


def test_walking_prior_particles_spread_as_asked(body, model, rng):
    prior = mp.WalkingPrior(body, model, fps=30)
    pose = Pose(se3.transform(None, [0, 0, 0.9]), np.zeros(body.n_dofs))
    state = prior.init_state(pose, 5000, rng, phase=0.4, coefficients=np.zeros(
        model.n_components), spread={"phase": 0.05, "c": 0.3, "rate": 0.1, "t": 0.02, "r": 0})
    assert abs(np.std(state["phase"]) - 0.05) < 0.003
    np.testing.assert_allclose(np.std(state["c"], axis=0), 0.3 * model.coef_std, rtol=0.05)
    assert abs(np.mean(state["rate"]) - prior.default_rate) < 0.01 * prior.default_rate
    roots, angles = prior.poses(prior.propagate(state, rng))
    assert roots.shape == (5000, 4, 4) and angles.shape == (5000, body.n_dofs)
    assert np.all(se3.is_rotation(roots[:, :3, :3]))


def test_walking_prior_refuses_what_it_cannot_do(body, model, rng):
    fake = mp.WalkModel(("l_wrist_flex",) + model.dof_names[1:], model.mean, model.basis,
                        model.coef_std, model.cycle_seconds, model.leg_length,
                        model.coefficients)
    with pytest.raises(ZoopraxisError, match="DOF 'l_wrist_flex' that body template"):
        mp.WalkingPrior(body, fake)
    with pytest.raises(ZoopraxisError, match="smooth-motion prior only"):
        mp.WalkingPrior(body, model).init_state(body.rest_pose(), 5, rng,
                                                uniform={"l_shoulder_rot": (0, 1)})


# -- annealing moves and the walking prior's offsets --------------------------------------------


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


def test_walking_prior_offsets_start_at_the_pose_and_fade(body, model, rng):
    prior = mp.WalkingPrior(body, model, fps=30, sigma_offset=1e-6, offset_pull=0.5)
    c = model.coef_std * 0.3
    on_cycle = {"c": c[None], "phase": np.array([0.4]), "rate": np.zeros(1),
                "t": np.zeros((1, 3)), "R": np.eye(3)[None], "dr": np.zeros((1, 3)),
                "rest": np.zeros((1, body.n_dofs)), "offset": np.zeros((1, body.n_dofs))}
    roots, angles = prior.poses(on_cycle)
    styled = angles[0].copy()
    styled[body.dof_index("r_shoulder_abd")] += 0.3          # the arm held out: off the cycle
    still = {k: 0.0 for k in ("phase", "c", "rate", "t", "r")}
    state = prior.init_state(Pose(roots[0], styled), 4, rng, spread=still)
    np.testing.assert_allclose(prior.poses(state)[1], np.broadcast_to(styled, (4, body.n_dofs)),
                               atol=1e-9)
    for _ in range(10):
        state = prior.propagate(state, rng)
    assert np.abs(state["offset"]).max() < 0.3 * 0.5 ** 9
    # The paper's prior (no offsets) cannot hold the arm out.
    paper = mp.WalkingPrior(body, model, fps=30)
    state = paper.init_state(Pose(roots[0], styled), 1, rng, spread=still)
    assert abs(paper.poses(state)[1][0, body.dof_index("r_shoulder_abd")]
               - styled[body.dof_index("r_shoulder_abd")]) > 0.1


def test_walking_prior_perturb_moves_the_walk_or_the_offsets(body, model, rng):
    prior = mp.WalkingPrior(body, model, fps=30, sigma_offset=0.02)
    pose = Pose(*[a[0] for a in mp.WalkingPrior(body, model).poses(
        mp.WalkingPrior(body, model).init_state(random_pose(body, rng), 1, rng))])
    state = prior.init_state(pose, 300, rng)
    walk = prior.perturb(state, np.arange(6), 1.0, rng)
    assert np.all(walk["offset"] == state["offset"])
    assert np.all(walk["phase"] != state["phase"]) and np.all(walk["c"] != state["c"])
    arm = mp.param_index(body, ["l_shoulder_flex", "l_elbow_flex"])
    limb = prior.perturb(state, arm, 1.0, rng)
    assert np.all(limb["phase"] == state["phase"])
    changed = np.flatnonzero(np.any(limb["offset"] != state["offset"], axis=0))
    np.testing.assert_array_equal(changed, arm - 6)
    with pytest.raises(ZoopraxisError, match="sigma_offset must be >= 0"):
        mp.WalkingPrior(body, model, sigma_offset=-0.1)
