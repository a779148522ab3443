"""The pose prior learned from motion capture (core/priors/pose.py)."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.body.kinematics import kinematics
from zoopraxis.core.priors.pose import (DEFAULT_POSE_PRIOR, PRIOR_COMPONENTS, TAKE_DROP_M, PosePrior,
                                        default_pose_prior, mirror_angles, take_angles)
from zoopraxis.core.synthetic import synth
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX, STANDARD_JOINTS


def test_mirror_angles_swaps_sides_and_is_its_own_inverse(rng):
    body = bm.make_body("full")
    a = rng.normal(0.0, 0.3, (4, body.n_dofs))
    m = mirror_angles(body.dof_names, a)
    assert np.allclose(mirror_angles(body.dof_names, m), a)
    assert np.allclose(m[:, body.dof_index("r_knee_flex")], a[:, body.dof_index("l_knee_flex")])
    assert np.allclose(m[:, body.dof_index("lumbar_twist")], -a[:, body.dof_index("lumbar_twist")])
    # the mirrored pose's joints are the original's reflected in the body's sagittal plane
    X = body.joints(bm.Pose(np.eye(4), a[0]))
    Y = body.joints(bm.Pose(np.eye(4), m[0]))
    swap = [JOINT_INDEX[n.replace("l_", "#").replace("r_", "l_").replace("#", "r_")]
            for n in STANDARD_JOINTS]
    assert np.allclose(Y[swap] * [-1, 1, 1], X, atol=1e-9)


def test_pose_prior_file_and_exclusion():
    prior = default_pose_prior("full")
    assert prior is not None and prior.dof_names == bm.make_body("full").dof_names
    assert default_pose_prior("sidenbladh") is None
    held_out = PosePrior.load(exclude=["01_01"])
    assert 0 < len(held_out.samples) < len(prior.samples)
    # the shipped prior knows many performers; a whole performer can be left out
    subjects = {t.split("_")[0] for t in prior.takes}
    assert len(subjects) >= 17
    without = PosePrior.load(exclude_subjects=["02"])
    assert not any(t.startswith("02_") for t in without.takes)
    assert len(without.samples) == len(prior.samples) - sum(t.startswith("02_")
                                                            for t in prior.takes)
    with pytest.raises(ZoopraxisError, match="no poses left"):
        PosePrior.load(exclude_subjects=sorted(subjects))
    with pytest.raises(ZoopraxisError, match="not a pose prior file"):
        PosePrior.load(DEFAULT_POSE_PRIOR.with_name("missing.npz"))


def test_pose_prior_learned_from_takes_saves_and_loads(tmp_path, shared_data):
    """A take's 3D joints become angles (each frame fitted within a centimetre), the prior
    holds them and their mirror images labelled with the take, and its file reads back."""
    from zoopraxis.core.files import cmu as bvh

    joints = bvh.standard_joints(bvh.load_cmu(shared_data / "cmu_mocap" / "131_02.bvh",
                                              fps=30))
    joints[10, 5] = np.nan                                  # a frame with a joint missing
    angles, rms = take_angles(joints, step=10)
    assert len(angles) == len(joints[::10]) - 1 and np.median(rms) < 0.01
    prior = PosePrior.from_takes({"131_02": angles, "extra": angles[:3]})
    names = prior.dof_names
    assert prior.samples.shape == (2 * len(angles) + 6, len(names))
    assert np.allclose(prior.samples[len(angles):2 * len(angles)],
                       mirror_angles(names, angles))
    assert list(prior.takes).count("131_02") == 2 * len(angles)
    path = tmp_path / "walks.npz"
    prior.save(path)
    back = PosePrior.load(path)
    assert back.dof_names == names and back.template == "full"
    assert np.allclose(back.samples, prior.samples, atol=1e-6)
    assert len(PosePrior.load(path, exclude=["extra"]).samples) == 2 * len(angles)
    with pytest.raises(ZoopraxisError, match="no poses to learn"):
        PosePrior.from_takes({})


def test_take_angles_fits_poses_gathered_from_anywhere(rng):
    """Poses that do not follow each other (each frame's fit starts from the one before) are
    fitted again from the rest pose where that start misses: all 30 within TAKE_DROP_M (from
    the pose before alone, one of them missed by 120 mm and was left out)."""
    body = synth.random_subject(rng)
    poses = [synth.everyday_pose(body, rng) for _ in range(30)]
    angles, rms = take_angles(np.array([body.joints(p) for p in poses]))
    assert len(angles) == 30 and rms.max() < TAKE_DROP_M and np.median(rms) < 0.01


def test_prior_knows_a_stride_sets_the_legs_apart():
    """The legs share one density: strides of walks of performers the prior never saw are
    likelier than the same strides with the right leg set where the left one is (both legs
    before the body, or both behind it), what one view often cannot tell apart. Each leg on
    its own density, as the arms have, the two were as likely (median difference 0). The
    prior of every performer's dances, kicks and climbs holds it less firmly than the prior
    of four takes did (walks of 131 and jumps: 80 % of 131_02's strides, by more than 3
    nats): 70 % of these 132 strides, by 0.8 nats (median)."""
    with np.load(DEFAULT_POSE_PRIOR) as data:
        takes, everything = data["takes"].astype(str), data["angles"]
        names = list(data["dof_names"].astype(str))
    kin = kinematics("full")
    left = [k for k, n in enumerate(names) if n.startswith(("l_hip_", "l_knee_", "l_ankle_"))]
    right = [names.index("r_" + names[k][2:]) for k in left]
    worse = []
    for walks in (["02_01", "02_02"], ["12_01", "12_02", "12_03"], ["35_01"], ["131_02"],
                  ["06_01"], ["05_01"]):
        angles = everything[np.isin(takes, walks)]
        prior = PosePrior.load(exclude_subjects=[walks[0].split("_")[0]]).with_broad(
            kin.prior_mean, kin.prior_sigma)
        flex = angles[:, names.index("l_hip_flex")] - angles[:, names.index("r_hip_flex")]
        strides = angles[np.abs(flex) > np.radians(30)]
        together = strides.copy()
        together[:, right] = strides[:, left]   # the sides' axes mirror: same angles, same pose
        worse += list(prior.cost(together) - prior.cost(strides))
    assert len(worse) >= 100
    assert np.mean(np.array(worse) > 0) >= 0.65 and np.median(worse) > 0.5


def held_out_and_flipped(shared_data):
    """Angles of 131_03 every 25 frames, and the same with a thigh and an upper arm swung to
    the opposite side."""
    from zoopraxis.core.files import cmu as bvh
    from zoopraxis.core.body import fit3d

    joints = bvh.standard_joints(bvh.load_cmu(shared_data / "cmu_mocap" / "131_03.bvh",
                                              fps=30))[::25]
    body, poses, _ = fit3d.fit_sequence(joints)
    a = np.array([p.angles for p in poses])
    flipped = a.copy()
    for name in ("l_hip_flex", "r_shoulder_flex"):
        k = body.dof_index(name)
        flipped[:, k] = -a[:, k] - 0.3
    return a, flipped


def test_held_out_prior_prefers_captured_poses_to_their_flipped_limbs(shared_data):
    """Poses of a take the prior never saw are likelier than the same poses with a thigh and
    an upper arm swung to the opposite side."""
    prior = PosePrior.load(exclude=["131_03"])
    a, flipped = held_out_and_flipped(shared_data)
    worse = prior.cost(flipped) - prior.cost(a)
    assert np.mean(worse > 0) >= 0.8 and np.median(worse) > 2.0


def _mixture_cost(prior, angles):
    """-log p of angles (B, n) under the prior's mixture, its least-squares form."""
    total = 0.0
    for dofs, means, whiten, costs in prior.mixture():
        z = np.einsum("kij,bkj->bki", whiten, angles[:, None, dofs] - means[None])
        total = total + np.min(0.5 * np.einsum("bki,bki->bk", z, z) + costs, axis=1)
    return total


def test_prior_mixture_prefers_held_out_poses_to_their_flipped_limbs(shared_data):
    """The mixture that stands for the learned density in least squares keeps its preference
    (as the kernel density does, test above)."""
    kin = kinematics("full")
    prior = PosePrior.load(exclude=["131_03"]).with_broad(kin.prior_mean, kin.prior_sigma)
    a, flipped = held_out_and_flipped(shared_data)
    worse = _mixture_cost(prior, flipped) - _mixture_cost(prior, a)
    assert np.mean(worse > 0) >= 0.8 and np.median(worse) > 2.0
    for dofs, means, whiten, costs in prior.mixture():
        assert means.shape == (PRIOR_COMPONENTS + 1, len(dofs))    # + the broad one
        assert np.all(np.isfinite(whiten)) and np.all(np.isfinite(costs))
