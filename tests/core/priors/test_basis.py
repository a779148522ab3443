"""The pose basis: canonical joint sets, their principal components, leaving performers out,
the density of 3D joints and the fit to one view's clicks (core/priors/basis.py)."""

import numpy as np
import pytest

from zoopraxis.core.body.joints import JOINT_INDEX
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.geometry.triangulate import procrustes_mpjpe
from zoopraxis.core.priors.basis import (PoseBasis, _unit_vectors, body_size,
                                         canonical_joints, default_pose_basis, mirror_joints)
from zoopraxis.core.synthetic import synth


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _random_poses(rng, n):
    """Joint sets of random everyday poses of random bodies, anywhere, any heading."""
    out = []
    for _ in range(n):
        body = synth.random_subject(rng)
        X = body.joints(synth.everyday_pose(body, rng))
        out.append(X @ _rot_z(rng.uniform(0, 2 * np.pi)).T + rng.normal(0, 1, 3))
    return np.array(out)


def test_canonical_joints_face_one_way_and_mirror_back(rng):
    X = _random_poses(rng, 5)
    Y = canonical_joints(X)
    across = Y[:, JOINT_INDEX["l_hip"]] - Y[:, JOINT_INDEX["r_hip"]]
    assert np.allclose(Y[:, JOINT_INDEX["pelvis"]], 0.0)
    assert np.allclose(across[:, 1], 0.0) and np.all(across[:, 0] > 0)
    assert np.allclose(canonical_joints(X @ _rot_z(0.7).T * 2.0), 2.0 * Y)
    assert np.allclose(mirror_joints(mirror_joints(Y)), Y)
    assert np.allclose(canonical_joints(mirror_joints(Y)), mirror_joints(Y))


def test_cost_ignores_place_heading_and_size_and_prefers_the_poses_learned(rng):
    basis = PoseBasis.from_takes({"a_01": _random_poses(rng, 300)}, components=20)
    X = _random_poses(rng, 4)
    moved = 1.3 * X @ _rot_z(2.0).T + [1.0, -2.0, 0.5]
    assert np.allclose(basis.cost(X), basis.cost(moved))
    # a pose with the legs' and arms' joints scrambled is far less likely
    scrambled = X[:, np.random.default_rng(0).permutation(17)]
    assert np.all(basis.cost(scrambled) > basis.cost(X) + 50.0)


def test_fit_to_one_view_finds_a_pose_of_the_basis(rng):
    """The basis' own poses, seen from any heading by a scaled orthographic camera with 2 px
    clicks, come back as the best fit within 40 mm (median of six, of a 1.8 m body,
    Procrustes-aligned; the depth the clicks leave free shrinks towards the mean: 20-63 mm),
    the clicks within 3 px."""
    basis = PoseBasis.from_takes({"a_01": _random_poses(rng, 300)}, components=20)
    errors = []
    for _ in range(6):
        Y = basis.shapes(rng.normal(0, 1, 20) * np.sqrt(basis.variances))
        R = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]]) @ _rot_z(rng.uniform(0, 6.3))
        uv = 400.0 * Y @ R[:2].T + [960.0, 540.0] + rng.normal(0, 2.0, (17, 2))
        best = basis.fit_view(uv)[0]
        errors.append(1000 * procrustes_mpjpe(best["joints"], Y) * 1.8 / body_size(Y[None]))
        proj = best["scale"] * best["joints"] @ best["camera"][:2].T + best["shift"]
        assert np.sqrt(np.mean(np.sum((proj - uv) ** 2, axis=1))) < 3.0
    assert np.median(errors) < 40.0 and max(errors) < 80.0


def test_load_leaves_performers_out():
    everything = default_pose_basis()
    assert everything is not None and len(everything.variances) > 10
    subjects = {t.split("_")[0] for t in everything.takes}
    assert {"01", "131"} <= subjects
    held = PoseBasis.load(exclude_subjects=["131"], exclude=["01_01"])
    assert not any(t.startswith("131_") or t == "01_01" for t in held.takes)
    assert len(held.joints) < len(everything.joints)
    with pytest.raises(ZoopraxisError, match="no joint sets left"):
        PoseBasis.load(exclude_subjects=sorted(subjects))


def test_bad_file_is_named(tmp_path):
    bad = tmp_path / "basis.npz"
    np.savez(bad, joints=np.zeros((3, 5, 3)), takes=np.array(["a", "b", "c"]))
    with pytest.raises(ZoopraxisError, match="not a pose basis file"):
        PoseBasis.load(bad)
    with pytest.raises(ZoopraxisError, match="not a pose basis file"):
        PoseBasis.load(tmp_path / "missing.npz")


def _quadratic(data, X):
    """Half the squared Mahalanobis distance of joint sets ``X`` under the Gaussian of the
    canonical unit-size joint sets ``data`` and their mirror images (floored as the basis)."""
    d = _unit_vectors(np.concatenate([data, mirror_joints(canonical_joints(data))]))
    cov = np.cov(d.T) + 0.005 ** 2 * np.eye(d.shape[1])
    e = _unit_vectors(X) - d.mean(axis=0)
    return 0.5 * np.einsum("bi,ij,bj->b", e, np.linalg.inv(cov), e)


def test_everyday_gaussian_beside_the_basis_judges_what_the_basis_does_not_know():
    """The shipped basis mixed half and half with the Gaussian of the body's everyday poses
    (both normalised): captured joint sets are still judged by the basis (differences of cost
    as the basis', to 0.05 nats), everyday ones the basis finds unlikely by the everyday
    Gaussian (differences as its own), and never more than the basis alone says (plus log 2)."""
    from zoopraxis.core.body.kinematics import kinematics
    from zoopraxis.core.priors.basis import everyday_joint_sets

    kin = kinematics("full")
    basis = default_pose_basis()
    everyday = everyday_joint_sets(kin)
    mixed = basis.with_broad(everyday)
    assert np.array_equal(everyday, everyday_joint_sets(kin))        # the same every time
    captured = basis.joints[::97]
    own, both = basis.cost(captured), mixed.cost(captured)
    assert np.all(both <= own + np.log(2) + 1e-9)
    assert np.abs(np.diff(both) - np.diff(own)).max() < 0.05
    others = everyday_joint_sets(kin, n=400, seed=5)
    own, both = basis.cost(others), mixed.cost(others)
    assert np.all(both <= own + np.log(2) + 1e-9)
    far = own > np.median(own)              # those the basis finds least likely
    assert np.median(own[far] - both[far]) > 10.0
    broad = _quadratic(everyday, others[far])
    assert np.abs(np.diff(both[far]) - np.diff(broad)).max() < 0.05
    # with all the weight on the basis, the basis alone
    assert np.allclose(basis.with_broad(everyday, weight=1.0).cost(others), own)
    with pytest.raises(ZoopraxisError, match="must be in"):
        basis.with_broad(everyday, weight=0.0)


def test_basis_density_is_the_gaussian_of_its_components_and_residual(rng):
    """The basis' cost is half the squared Mahalanobis distance under one covariance, its
    components' variances in their span and each joint's (floored) residual across it, and
    its normaliser (the mixture's weight against the everyday Gaussian rests on it) is half
    that covariance's log-determinant."""
    basis = default_pose_basis()
    V = basis.components
    across = np.eye(V.shape[1]) - V.T @ V
    rest = np.repeat(np.maximum(basis.residual, 0.005 ** 2), 3)
    cov = V.T @ (basis.variances[:, None] * V) + across @ (rest[:, None] * across)
    assert np.isclose(basis._half_logdet, 0.5 * np.linalg.slogdet(cov)[1], rtol=0, atol=1e-6)
    X = _random_poses(rng, 5)
    d = _unit_vectors(X) - basis.mean
    expected = 0.5 * np.einsum("bi,ij,bj->b", d, np.linalg.inv(cov), d)
    assert np.allclose(basis.cost(X), expected, rtol=1e-6)
