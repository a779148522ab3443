"""The walking model and prior: the shipped model, learning it from gait cycles, and the walking
prior's particles."""

import numpy as np
import pytest

from zoopraxis.core.geometry import se3
from zoopraxis.core.priors import motion_prior as mp
from zoopraxis.core.priors import walking
from zoopraxis.core.body.body import Pose
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX

from tests.core.priors.test_motion_prior import body, random_pose  # noqa: F401 (fixture)


@pytest.fixture(scope="module")
def model():
    return walking.WalkModel.load()


def test_shipped_walk_model_is_small_and_covers_the_body(body, model):
    assert walking.DEFAULT_WALK_PRIOR.stat().st_size < 200_000
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
    again = walking.WalkModel.load(path)
    np.testing.assert_array_equal(again.basis, model.basis)
    assert again.dof_names == model.dof_names
    with pytest.raises(ZoopraxisError, match="no such walking model"):
        walking.WalkModel.load(tmp_path / "missing.npz")
    np.savez(tmp_path / "bad.npz", mean=np.zeros((3, 4)))
    with pytest.raises(ZoopraxisError, match="bad.npz: walking model lacks 'dof_names'"):
        walking.WalkModel.load(tmp_path / "bad.npz")


def test_learn_walk_model_finds_the_variation(body, rng):
    K = 32
    mu = np.arange(K) / K
    C = body.n_dofs + 6
    shapes = np.sin(2 * np.pi * (mu + rng.uniform(size=(C, 1))))
    cycles = np.array([1.0 + a * shapes + b * np.cos(2 * np.pi * mu)
                       for a, b in rng.normal(size=(12, 2))])
    model = walking.learn_walk_model(body, cycles, cycle_seconds=1.0)
    assert model.n_components == 2
    np.testing.assert_allclose(model.mean, cycles.mean(axis=0), atol=1e-12)
    rebuilt = model.mean + np.einsum("md,dck->mck", model.coefficients, model.basis)
    np.testing.assert_allclose(rebuilt, cycles, atol=1e-9)
    with pytest.raises(ZoopraxisError, match="at least 2 walking cycles"):
        walking.learn_walk_model(body, cycles[:1], cycle_seconds=1.0)


def test_mirror_curves_twice_is_the_identity(body, model):
    # a training cycle: the mean of cycles and their mirror images, and so its leading
    # eigencurves, can be their own mirror images
    curves = model.mean + np.einsum("d,dck->ck", model.coefficients[0], model.basis)
    once = walking.mirror_curves(body, curves)
    assert not np.allclose(once, curves)
    np.testing.assert_allclose(walking.mirror_curves(body, once), curves, atol=1e-12)
    left, right = (model.curve_names.index(n) for n in ("l_knee_flex", "r_knee_flex"))
    np.testing.assert_allclose(once[left], np.roll(curves[right], -model.n_samples // 2))


def test_heading_rotation_turns_the_facing_to_the_direction_of_travel(rng):
    forward = rng.normal(size=(5, 3))
    forward[:, 2] = 0
    R = walking.heading_rotation(forward)
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
    cycles, heading = walking.find_gait_cycles(synthetic_walk(fps), fps)
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
    assert walking.find_gait_cycles(joints, fps)[0] == []


def test_cmu_slow_walk_has_gait_cycles(shared_data):
    from zoopraxis.core.files import cmu

    joints = cmu.standard_joints(cmu.load_cmu(shared_data / "cmu_mocap" / "131_02.bvh", fps=30))
    cycles, _ = walking.find_gait_cycles(joints, 30.0)
    assert len(cycles) >= 3
    assert all(0.5 < (b - a) / 30.0 < 2.0 for a, b in cycles)


def quiet(spread=0.0):
    return {"phase": spread, "c": spread, "rate": spread, "t": spread, "r": spread}


def test_walking_prior_reproduces_the_model_cycle(body, model, rng):
    prior = walking.WalkingPrior(body, model, fps=30, eps=0, sigma_phase=0, sigma_rate=0,
                            sigma_path=0, sigma_turn=0)
    c = model.coef_std * 0.3
    start = walking.WalkingPrior(body, model, fps=30)
    # A pose on the cycle at phase 0.25, facing +x.
    seed = {"c": c[None], "phase": np.array([0.25]), "rate": np.array([0.0]),
            "t": np.array([[0.0, 0.0, 0.9]]), "R": walking.heading_rotation([1.0, 0, 0])[None],
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
    prior = walking.WalkingPrior(body, model)
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
    prior = walking.WalkingPrior(body, model, fps=30)
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
    fake = walking.WalkModel(("l_wrist_flex",) + model.dof_names[1:], model.mean, model.basis,
                        model.coef_std, model.cycle_seconds, model.leg_length,
                        model.coefficients)
    with pytest.raises(ZoopraxisError, match="DOF 'l_wrist_flex' that body template"):
        walking.WalkingPrior(body, fake)
    with pytest.raises(ZoopraxisError, match="smooth-motion prior only"):
        walking.WalkingPrior(body, model).init_state(body.rest_pose(), 5, rng,
                                                uniform={"l_shoulder_rot": (0, 1)})


def test_walking_prior_offsets_start_at_the_pose_and_fade(body, model, rng):
    prior = walking.WalkingPrior(body, model, fps=30, sigma_offset=1e-6, offset_pull=0.5)
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
    paper = walking.WalkingPrior(body, model, fps=30)
    state = paper.init_state(Pose(roots[0], styled), 1, rng, spread=still)
    assert abs(paper.poses(state)[1][0, body.dof_index("r_shoulder_abd")]
               - styled[body.dof_index("r_shoulder_abd")]) > 0.1


def test_walking_prior_perturb_moves_the_walk_or_the_offsets(body, model, rng):
    prior = walking.WalkingPrior(body, model, fps=30, sigma_offset=0.02)
    pose = Pose(*[a[0] for a in walking.WalkingPrior(body, model).poses(
        walking.WalkingPrior(body, model).init_state(random_pose(body, rng), 1, rng))])
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
        walking.WalkingPrior(body, model, sigma_offset=-0.1)
