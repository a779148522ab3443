"""Body model: templates, product of exponentials, Jacobians, limits, symmetry."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.geometry import se3
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX, MIRROR_PERMUTATION, STANDARD_JOINTS


def random_pose(body, rng, spread=0.5):
    """A pose inside the joint limits with a random root."""
    mid = (body.lower + body.upper) / 2
    half = (body.upper - body.lower) / 2
    angles = mid + spread * half * rng.uniform(-1, 1, size=body.n_dofs)
    root = se3.exp_se3(np.concatenate([rng.normal(size=3), rng.normal(size=3)]))
    return bm.Pose(root, angles)


def J(name):
    return JOINT_INDEX[name]


# -- templates ---------------------------------------------------------------------------------

def test_template_sizes():
    muy = bm.make_body("muybridge")
    assert muy.n_dofs == 19                       # Bregler & Malik §3.2
    sid = bm.make_body("sidenbladh")
    assert sid.n_params == 25 and sid.shapes == "cylinder"   # Sidenbladh et al. §2
    yam = bm.make_body("yamamoto")
    assert yam.n_segments == 12                   # Yamamoto et al. §2.1
    full = bm.make_body("full")
    assert {"l_foot", "r_foot", "chest", "abdomen"} <= set(full.segment_names)


@pytest.mark.parametrize("template", bm.TEMPLATES)
def test_every_template_gives_the_17_joints(template, rng):
    body = bm.make_body(template)
    X = body.joints(random_pose(body, rng))
    assert X.shape == (len(STANDARD_JOINTS), 3) and np.all(np.isfinite(X))
    # bone lengths are kept whatever the pose
    rest = body.joints(body.rest_pose())
    for a, b, dim in (("l_hip", "l_knee", "thigh"), ("r_knee", "r_ankle", "shank"),
                      ("l_shoulder", "l_elbow", "upper_arm"), ("r_elbow", "r_wrist", "forearm")):
        assert np.isclose(np.linalg.norm(X[J(a)] - X[J(b)]), body.dims[dim])
        assert np.isclose(np.linalg.norm(rest[J(a)] - rest[J(b)]), body.dims[dim])


def test_rest_pose_layout_follows_the_convention():
    body = bm.make_body("full")
    X = body.joints(body.rest_pose())
    assert np.allclose(X[J("pelvis")], 0.0)
    assert np.allclose((X[J("l_hip")] + X[J("r_hip")]) / 2, X[J("pelvis")])
    assert X[J("l_hip")][0] > 0 and X[J("r_hip")][0] < 0          # subject's left at +X
    assert X[J("head")][2] > X[J("neck")][2] > X[J("pelvis")][2] > X[J("l_knee")][2]
    assert X[J("l_toe")][1] < X[J("l_ankle")][1]                   # feet point to -Y
    height = X[J("head")][2] - (X[J("l_ankle")][2] - body.dims["ankle_height"])
    assert 1.55 < height + body.dims["head_r"] < 1.95


# -- angle meaning -------------------------------------------------------------------------------

def set_angles(body, **values):
    pose = body.rest_pose()
    for name, deg in values.items():
        pose.angles[body.dof_index(name)] = np.radians(deg)
    return body.joints(pose)


def test_positive_angles_mean_flexion_abduction_on_both_sides():
    body = bm.make_body("full")
    rest = body.joints(body.rest_pose())
    for s, sx in (("l", 1), ("r", -1)):
        X = set_angles(body, **{f"{s}_hip_flex": 30})
        assert X[J(f"{s}_knee")][1] < rest[J(f"{s}_knee")][1] - 0.1       # knee forward (-Y)
        X = set_angles(body, **{f"{s}_knee_flex": 60})
        assert X[J(f"{s}_ankle")][1] > rest[J(f"{s}_ankle")][1] + 0.1     # shank backward
        X = set_angles(body, **{f"{s}_hip_abd": 30})
        assert sx * (X[J(f"{s}_knee")][0] - rest[J(f"{s}_knee")][0]) > 0.1  # away from midline
        X = set_angles(body, **{f"{s}_shoulder_abd": 90})
        assert sx * (X[J(f"{s}_wrist")][0] - rest[J(f"{s}_shoulder")][0]) > 0.4
        X = set_angles(body, **{f"{s}_elbow_flex": 90})
        assert X[J(f"{s}_wrist")][1] < rest[J(f"{s}_elbow")][1] - 0.2     # forearm forward
        X = set_angles(body, **{f"{s}_ankle_flex": 20})
        assert X[J(f"{s}_toe")][2] > rest[J(f"{s}_toe")][2]                # toes up
        X = set_angles(body, **{f"{s}_hip_rot": 40, f"{s}_knee_flex": 90})
        assert sx * (X[J(f"{s}_ankle")][0] - X[J(f"{s}_knee")][0]) > 0.1  # internal: shank out


def test_mirrored_angles_give_mirrored_joints(rng):
    body = bm.make_body("full")
    perm = bm.mirror_dof_index(body)
    pose = random_pose(body, rng)
    pose.root = np.eye(4)
    # Mirroring x -> -x flips the sign of the trunk's bend and twist (about Y and Z).
    sign = np.array([-1.0 if n.endswith(("_bend", "_twist")) else 1.0 for n in body.dof_names])
    mirrored = bm.Pose(np.eye(4), pose.angles[perm] * sign)
    X, Xm = body.joints(pose), body.joints(mirrored)
    assert np.allclose(Xm, X[list(MIRROR_PERMUTATION)] * [-1, 1, 1])


# -- numerical correctness ---------------------------------------------------------------------

@pytest.mark.parametrize("template", bm.TEMPLATES)
def test_joints_jacobian_against_finite_differences(template, rng):
    body = bm.make_body(template)
    pose = random_pose(body, rng)
    X, Jac = body.joints_jacobian(pose)
    h = 1e-6
    numeric = np.zeros_like(Jac)
    for i in range(body.n_params):
        d = np.zeros(body.n_params)
        d[i] = h
        numeric[..., i] = (body.joints(pose.retract(d)) - body.joints(pose.retract(-d))) / (2 * h)
    assert np.allclose(Jac, numeric, atol=1e-6)


def test_segment_jacobians_move_surface_points(rng):
    body = bm.make_body("full")
    pose = random_pose(body, rng)
    Js = body.segment_jacobians(pose)
    T = body.seg2world(pose)
    k = body.segment_index("l_shank")
    local = rng.normal(size=(5, 3)) * 0.1 + body.reference_point("l_knee")
    Xw = se3.apply(T[k], local)
    delta = rng.normal(size=body.n_params) * 1e-6
    moved = se3.apply(body.seg2world(pose.retract(delta))[k], local)
    predicted = Xw + (se3.point_velocity_matrix(Xw) @ Js[k] @ delta)
    assert np.allclose(moved, predicted, atol=1e-10)
    # DOFs outside the chain don't move the segment
    assert np.allclose(Js[k][:, 6 + body.dof_index("r_knee_flex")], 0.0)
    assert not np.allclose(Js[k][:, 6 + body.dof_index("l_knee_flex")], 0.0)


def test_dims_jacobian_is_exact(rng):
    body = bm.make_body("full")
    pose = random_pose(body, rng)
    Jd = body.joints_dims_jacobian(pose)
    d0 = body.dims_vector()
    step = rng.normal(size=d0.shape) * 0.02
    other = body.with_dims(dict(zip(bm.LENGTH_DIMS, d0 + step)))
    predicted = body.joints(pose) + Jd @ step
    assert np.allclose(other.joints(pose), predicted, atol=1e-12)


def test_batched_kinematics_equal_single(rng):
    body = bm.make_body("muybridge")
    poses = [random_pose(body, rng) for _ in range(4)]
    roots = np.stack([p.root for p in poses])
    angles = np.stack([p.angles for p in poses])
    batch = body.joints(roots, angles)
    assert batch.shape == (4, 17, 3)
    for i, p in enumerate(poses):
        assert np.allclose(batch[i], body.joints(p))
    assert body.seg2world(roots, angles).shape == (4, body.n_segments, 4, 4)


def test_pose_vector_round_trip(rng):
    body = bm.make_body("full")
    pose = random_pose(body, rng)
    back = bm.Pose.from_vector(pose.to_vector())
    assert np.allclose(back.root, pose.root) and np.allclose(back.angles, pose.angles)


def test_limits_clamp_and_violation():
    body = bm.make_body("full")
    angles = np.zeros(body.n_dofs)
    k = body.dof_index("l_knee_flex")
    angles[k] = -0.5
    assert body.limit_violation(angles)[k] == pytest.approx(0.5)
    assert body.clamp(angles)[k] == 0.0
    assert np.all(body.lower < body.upper)


def test_left_and_right_dimensions_are_tied():
    body = bm.make_body("full", {"thigh": 0.5})
    X = body.joints(body.rest_pose())
    assert np.isclose(np.linalg.norm(X[J("l_hip")] - X[J("l_knee")]), 0.5)
    assert np.isclose(np.linalg.norm(X[J("r_hip")] - X[J("r_knee")]), 0.5)


# -- bad input ---------------------------------------------------------------------------------

def test_bad_templates_and_dims():
    with pytest.raises(ZoopraxisError, match="unknown body template 'robot'"):
        bm.make_body("robot")
    with pytest.raises(ZoopraxisError, match="unknown body dimension.*tail"):
        bm.make_body("full", {"tail": 1.0})
    with pytest.raises(ZoopraxisError, match="positive: thigh=-0.1"):
        bm.make_body("full", {"thigh": -0.1})
    with pytest.raises(ZoopraxisError, match="no segment 'tail'"):
        bm.make_body("full").segment_index("tail")
    with pytest.raises(ZoopraxisError, match="shape family"):
        bm.make_body("full", shapes="voxels")


@pytest.mark.parametrize("template", bm.TEMPLATES)
def test_seg2world_of_some_segments_equals_the_whole_body(template, rng):
    body = bm.make_body(template)
    roots = se3.exp_se3(rng.normal(size=(7, 6)))
    angles = rng.uniform(body.lower, body.upper, size=(7, body.n_dofs))
    full = body.seg2world(roots, angles)
    for segments in ([0], [body.n_segments - 1], [3, 1], list(range(body.n_segments)),
                     [body.n_segments - 1, 2, body.n_segments - 2]):
        part = body.seg2world_of(roots, angles, segments)
        assert part.shape == (7, len(segments), 4, 4)
        assert np.allclose(part, full[:, segments], rtol=0, atol=1e-9)
        # one root with a batch of angles, and one pose
        assert np.allclose(body.seg2world_of(roots[2], angles, segments),
                           body.seg2world(np.repeat(roots[2][None], 7, axis=0),
                                          angles)[:, segments], rtol=0, atol=1e-9)
        single = body.seg2world_of(bm.Pose(roots[4], angles[4]), segments=segments)
        assert np.allclose(single, full[4, segments], rtol=0, atol=1e-9)
