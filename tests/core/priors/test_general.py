"""The general motion prior: learning its dynamics and pose space, the shipped model, the prior's
draws (damped velocity, correlated noise, the pull towards the pose space, limits), and its use
by the particle and hybrid trackers."""

import numpy as np
import pytest

from zoopraxis.core.body.body import Pose, make_body
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.geometry import se3
from zoopraxis.core.priors import general
from zoopraxis.core.priors.motion_prior import param_index
from zoopraxis.core.trackers.filter_stepper import ParticleStepper
from zoopraxis.core.trackers.hybrid import HybridStepper


@pytest.fixture(scope="module")
def body():
    return make_body("full")


@pytest.fixture(scope="module")
def shipped():
    return general.MotionModel.load()


def synthetic_runs(body, rng, *, a=0.9, sigma=0.02, runs=40, length=30):
    """Runs of a damped constant velocity whose knee noise is shared by both knees (a jump)
    and whose poses keep the elbows equal; everything else still. Roots walk along x."""
    D = body.n_dofs
    knees = [body.dof_index("l_knee_flex"), body.dof_index("r_knee_flex")]
    elbows = [body.dof_index("l_elbow_flex"), body.dof_index("r_elbow_flex")]
    out = []
    for _ in range(runs):
        x = np.full(D, 0.0) + 0.3 * (body.lower + body.upper) / 2
        x[elbows] = rng.uniform(0.2, 1.2)
        v = np.zeros(D)
        angles = []
        for _ in range(length):
            e = np.zeros(D)
            e[knees] = rng.normal() * sigma
            v = a * v + e
            x = x + v
            angles.append(x.copy())
        roots = np.repeat(np.eye(4)[None], length, axis=0)
        roots[:, 0, 3] = 0.04 * np.arange(length)
        out.append((roots, np.array(angles)))
    return out


# -- learning ------------------------------------------------------------------------------------


def test_learning_recovers_damping_shared_noise_and_the_pose_space(body, rng):
    model = general.learn_motion_model(body.dof_names, synthetic_runs(body, rng), mirror=False)
    lk, rk = body.dof_index("l_knee_flex"), body.dof_index("r_knee_flex")
    np.testing.assert_allclose(model.damping[[lk, rk]], 0.9, atol=0.03)
    # The knees' noise is one principal direction, both knees alike.
    first = model.noise_basis[0]
    assert abs(abs(first[lk]) - np.sqrt(0.5)) < 0.02 and abs(first[lk] - first[rk]) < 0.02
    np.testing.assert_allclose(model.noise_std[0], 0.02 * np.sqrt(2), rtol=0.1)
    cov = model.noise_cov
    assert cov[lk, rk] / np.sqrt(cov[lk, lk] * cov[rk, rk]) > 0.9     # less the floor of the rest
    # Equal elbows: the pose space holds (l + r) elbow, not (l - r).
    le, re = body.dof_index("l_elbow_flex"), body.dof_index("r_elbow_flex")
    same, apart = np.zeros(body.n_dofs), np.zeros(body.n_dofs)
    same[[le, re]], apart[[le, re]] = 0.3, (0.3, -0.3)
    base = model.pose_mean
    d_same, d_apart = model.mahalanobis(np.array([base + same, base + apart]))
    assert d_apart > 10 * d_same
    # The root moves 4 cm a frame along x, steadily.
    assert model.root_damping[0] > 0.95 and model.root_noise[0] < 1e-3


def test_rest_off_the_pose_space_is_chosen_on_performers_left_out(body, rng):
    # Each performer moves along the same direction, each from his own pose: a space learned
    # from the others misses a performer by his own offset (0.2 rad per angle).
    D = body.n_dofs
    along = rng.normal(size=D)
    along /= np.linalg.norm(along)
    angles, performers = [], []
    for k in range(6):
        own = rng.normal(size=D) * 0.2
        angles.append(own + rng.normal(size=(200, 1)) * along + rng.normal(size=(200, D)) * 0.01)
        performers.append(str(k))
    assert general.pose_rest_floor(angles, performers) >= 0.15
    assert general.pose_rest_floor(angles[:1], performers[:1]) == general.MIN_POSE_REST
    # Performers alike: the floor stays low.
    alike = [a - a.mean(axis=0) for a in angles]
    assert general.pose_rest_floor(alike, performers) <= 0.075


def test_learning_adds_the_mirror_images(body, rng):
    runs = synthetic_runs(body, rng, runs=4)
    lone = general.learn_motion_model(body.dof_names, runs, mirror=False)
    both = general.learn_motion_model(body.dof_names, runs)
    assert both.frames == 2 * lone.frames
    # Mirrored, every left angle has its right twin's spread.
    le, re = body.dof_index("l_shoulder_abd"), body.dof_index("r_shoulder_abd")
    assert both.velocity_std[le] == pytest.approx(both.velocity_std[re])


def test_learning_refuses_what_it_cannot_use(body):
    with pytest.raises(ZoopraxisError, match="no sequence of 3 frames"):
        general.learn_motion_model(body.dof_names, [(np.eye(4)[None], np.zeros((1, 29)))])
    with pytest.raises(ZoopraxisError, match="expected 29 angles"):
        general.learn_motion_model(body.dof_names,
                                   [(np.repeat(np.eye(4)[None], 5, 0), np.zeros((5, 3)))])


def test_model_round_trip_and_bad_files(body, rng, tmp_path):
    model = general.learn_motion_model(body.dof_names, synthetic_runs(body, rng, runs=5))
    model.save(tmp_path / "m.npz")
    back = general.MotionModel.load(tmp_path / "m.npz")
    assert back.dof_names == model.dof_names and back.frames == model.frames
    np.testing.assert_allclose(back.noise_cov, model.noise_cov, rtol=1e-5, atol=1e-9)
    with pytest.raises(ZoopraxisError, match="no such motion model"):
        general.MotionModel.load(tmp_path / "none.npz")
    np.savez(tmp_path / "bad.npz", dof_names=np.array(["a"]))
    with pytest.raises(ZoopraxisError, match="lacks 'fps'"):
        general.MotionModel.load(tmp_path / "bad.npz")


def test_shipped_model_is_small_and_learned_from_many_performers(body, shipped):
    assert general.DEFAULT_MOTION_PRIOR.stat().st_size < 50_000
    assert set(body.dof_names) <= set(shipped.dof_names)
    assert shipped.frames > 10_000
    assert 3 <= len(shipped.pose_std) <= general.POSE_COMPONENTS
    # Light limbs move more than the trunk; velocities carry on from frame to frame.
    sigma = np.sqrt(np.diag(shipped.noise_cov))
    names = list(shipped.dof_names)
    assert sigma[names.index("l_elbow_flex")] > sigma[names.index("lumbar_twist")]
    assert np.median(shipped.damping) > 0.3


# -- the prior -----------------------------------------------------------------------------------


def start_pose(body, shipped):
    root = se3.transform(se3.exp_so3(np.array([0.0, 0.0, 0.5])), np.array([0.2, 0.1, 0.95]))
    return Pose(root, body.clamp(shipped.pose_mean[[shipped.dof_names.index(n)
                                                   for n in body.dof_names]]))


def test_prior_carries_the_damped_velocity(body, shipped, rng):
    prior = general.GeneralMotionPrior(body, shipped, scale=1e-6, drift=0.0)
    pose = start_pose(body, shipped)
    before = pose.copy()
    before.angles = before.angles - 0.01
    before.root = before.root.copy()
    before.root[:3, 3] -= [0.02, 0.0, 0.0]
    state = prior.init_state(pose, 4, rng, previous=before, spread=np.zeros(35))
    v0 = state["dangles"].copy()
    nxt = prior.propagate(state, rng)
    predicted = pose.angles + prior.damping * v0
    inside = (predicted > body.lower + 1e-3) & (predicted < body.upper - 1e-3)
    assert inside.mean() > 0.8
    np.testing.assert_allclose(nxt["angles"][inside], predicted[inside], atol=1e-4)
    np.testing.assert_allclose(nxt["t"][:, 0], pose.root[0, 3]
                               + prior.root_damping[0] * state["dt"][:, 0], atol=1e-4)
    roots, angles = prior.poses(nxt)
    assert roots.shape == (4, 4, 4) and angles.shape == (4, body.n_dofs)


def test_prior_noise_is_correlated_as_learned(body, shipped, rng):
    prior = general.GeneralMotionPrior(body, shipped, drift=0.0)
    pose = start_pose(body, shipped)
    state = prior.init_state(pose, 20000, rng, spread=np.zeros(35))
    state["dangles"][:] = 0.0
    step = prior.propagate(state, rng)["angles"] - pose.angles
    i, j = (body.dof_index(n) for n in ("l_hip_flex", "l_knee_flex"))
    ii, jj = (shipped.dof_names.index(n) for n in ("l_hip_flex", "l_knee_flex"))
    learned = shipped.noise_cov[ii, jj] / np.sqrt(shipped.noise_cov[ii, ii]
                                                  * shipped.noise_cov[jj, jj])
    drawn = np.corrcoef(step[:, i], step[:, j])[0, 1]
    assert abs(drawn - learned) < 0.05 and abs(learned) > 0.1
    np.testing.assert_allclose(step.std(axis=0)[j], prior.noise_sigma[j], rtol=0.1)


def test_drift_pulls_poses_no_performer_made_back_to_the_pose_space(body, shipped, rng):
    pose = start_pose(body, shipped)
    # One knee and one elbow bent hard, the other limbs straight: far from the captured poses.
    odd = pose.copy()
    odd.angles = odd.angles.copy()
    odd.angles[body.dof_index("l_knee_flex")] = 1.4
    odd.angles[body.dof_index("l_elbow_flex")] = 1.4
    idx = [body.dof_names.index(n) for n in shipped.dof_names if n in body.dof_names]
    distance = {}
    for drift in (0.0, 1.0):
        prior = general.GeneralMotionPrior(body, shipped, drift=drift)
        draws = np.random.default_rng(7)            # the same noise with and without
        state = prior.init_state(odd, 2000, draws, spread=np.zeros(35))
        state["dangles"][:] = 0.0
        for _ in range(20):
            state = prior.propagate(state, draws)
        distance[drift] = np.median(shipped.mahalanobis(state["angles"][:, idx]))
    assert distance[1.0] < 0.8 * distance[0.0]


def test_prior_keeps_the_limits_and_perturbs_only_what_it_is_asked(body, shipped, rng):
    prior = general.GeneralMotionPrior(body, shipped, scale=20.0)
    pose = start_pose(body, shipped)
    state = prior.init_state(pose, 500, rng)
    for _ in range(3):
        state = prior.propagate(state, rng)
    assert np.all(state["angles"] >= body.lower - 1e-12)
    assert np.all(state["angles"] <= body.upper + 1e-12)
    cols = param_index(body, ["l_knee_flex", "l_hip_flex"])
    moved = prior.perturb(state, cols, 1.0, rng)
    change = np.abs(moved["angles"] - state["angles"]).max(axis=0)
    assert np.all(change[cols - 6] > 0) and np.all(np.delete(change, cols - 6) == 0)
    np.testing.assert_array_equal(moved["t"], state["t"])


def test_prior_refuses_bad_input(body, shipped, rng):
    with pytest.raises(ZoopraxisError, match="scale > 0"):
        general.GeneralMotionPrior(body, shipped, scale=0.0)
    prior = general.GeneralMotionPrior(body, shipped)
    with pytest.raises(ZoopraxisError, match="uniform starts"):
        prior.init_state(start_pose(body, shipped), 3, rng, uniform={"l_shoulder_rot": (0, 1)})


def test_prior_follows_the_plate_rate(body, shipped):
    at30 = general.GeneralMotionPrior(body, shipped, fps=30.0)
    at60 = general.GeneralMotionPrior(body, shipped, fps=60.0)
    np.testing.assert_allclose(at60.damping, at30.damping ** 0.5)
    np.testing.assert_allclose(at60.noise_sigma, 0.5 * at30.noise_sigma)


# -- the trackers use it -------------------------------------------------------------------------


@pytest.mark.parametrize("stepper", [ParticleStepper, HybridStepper])
def test_trackers_make_the_general_prior(body, stepper, tmp_path):
    s = stepper(prior="general")
    s.body, s.fps = body, 30.0
    prior = s.make_prior()
    assert isinstance(prior, general.GeneralMotionPrior)
    assert prior.scale == s.prior_scale == 1.0 and s.silhouette > 0     # learned: not widened
    assert prior.carry_moves == (stepper is ParticleStepper)
    with pytest.raises(ZoopraxisError, match="no such motion model"):
        stepper(prior="general", motion_model=tmp_path / "none.npz")


def test_pose_log_prior_is_the_pose_space_gaussian(body, shipped):
    prior = general.GeneralMotionPrior(body, shipped)
    pose = start_pose(body, shipped)
    odd = np.stack([pose.angles, pose.angles])
    odd[1, body.dof_index("l_knee_flex")] = 1.4            # a bent knee, the other straight
    odd[1, body.dof_index("l_elbow_flex")] = 1.4
    idx = [body.dof_names.index(n) for n in shipped.dof_names if n in body.dof_names]
    assert len(idx) == len(shipped.dof_names)
    np.testing.assert_allclose(prior.pose_log_prior(odd),
                               -0.5 * shipped.mahalanobis(odd[:, idx]), rtol=1e-6, atol=1e-6)
    assert prior.pose_log_prior(odd)[1] < prior.pose_log_prior(odd)[0] - 1


def test_one_view_weighs_particles_by_the_pose_space(body):
    from types import SimpleNamespace
    from zoopraxis.core.trackers import filter_stepper
    s = ParticleStepper(prior="general")
    s.take = SimpleNamespace(cameras=[object()])
    assert s.pose_weight() == filter_stepper.ONE_VIEW_POSE_WEIGHT > 0
    one = s.filter_options()
    assert one["pose_weight"] > 0 and one["axis_points"] > 0 and one["background_points"]
    s.take = SimpleNamespace(cameras=[object(), object()])
    assert s.pose_weight() == 0.0
    assert s.filter_options() == {"silhouette": s.silhouette, "pose_weight": 0.0,
                                  "axis_points": 0, "background_points": False}
    s = ParticleStepper(prior="smooth")
    s.take = SimpleNamespace(cameras=[object()])
    assert s.pose_weight() == 0.0
