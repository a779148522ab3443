"""Rigid-body math: exp/log round trips, singular cases, adjoint identities, Jacobians."""

import numpy as np
import pytest

from zoopraxis.core.geometry import se3
from zoopraxis.core.errors import ZoopraxisError


def random_rotvecs(rng, n, max_angle=np.pi):
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    return axis * rng.uniform(0, max_angle, size=(n, 1))


# -- smoke and shapes ------------------------------------------------------------------------

def test_hat_vee_round_trip_and_cross_product(rng):
    w, x = rng.normal(size=(5, 3)), rng.normal(size=(5, 3))
    assert np.allclose(se3.vee3(se3.hat3(w)), w)
    assert np.allclose(np.einsum("nij,nj->ni", se3.hat3(w), x), np.cross(w, x))
    xi = rng.normal(size=(4, 6))
    assert se3.hat6(xi).shape == (4, 4, 4)
    assert np.allclose(se3.vee6(se3.hat6(xi)), xi)


def test_batch_shapes(rng):
    xi = rng.normal(size=(2, 3, 6))
    T = se3.exp_se3(xi)
    assert T.shape == (2, 3, 4, 4)
    assert se3.log_se3(T).shape == (2, 3, 6)
    assert se3.adjoint(T).shape == (2, 3, 6, 6)


# -- numerical correctness -----------------------------------------------------------------

def test_exp_so3_matches_matrix_series(rng):
    from scipy.linalg import expm

    for w in random_rotvecs(rng, 10):
        assert np.allclose(se3.exp_so3(w), expm(se3.hat3(w)), atol=1e-12)


def test_exp_se3_matches_matrix_exponential(rng):
    from scipy.linalg import expm

    for xi in rng.normal(size=(10, 6)):
        assert np.allclose(se3.exp_se3(xi), expm(se3.hat6(xi)), atol=1e-10)


def test_exp_log_round_trips(rng):
    w = random_rotvecs(rng, 200, max_angle=np.pi - 1e-2)
    assert np.allclose(se3.log_so3(se3.exp_so3(w)), w, atol=1e-9)
    xi = np.concatenate([rng.normal(size=(200, 3)), w], axis=1)
    assert np.allclose(se3.log_se3(se3.exp_se3(xi)), xi, atol=1e-8)
    R = se3.exp_so3(w)
    assert np.allclose(se3.exp_so3(se3.log_so3(R)), R, atol=1e-10)


def test_zero_and_tiny_rotation():
    assert np.allclose(se3.exp_so3(np.zeros(3)), np.eye(3))
    assert np.allclose(se3.log_so3(np.eye(3)), 0.0)
    tiny = np.array([1e-9, -2e-9, 3e-9])
    assert np.allclose(se3.log_so3(se3.exp_so3(tiny)), tiny, rtol=1e-6, atol=1e-15)
    xi = np.array([0.1, 0.2, 0.3, 0.0, 0.0, 0.0])  # pure translation
    T = se3.exp_se3(xi)
    assert np.allclose(T[:3, 3], xi[:3]) and np.allclose(T[:3, :3], np.eye(3))
    assert np.allclose(se3.log_se3(T), xi)


@pytest.mark.parametrize("eps", [0.0, 1e-8, 1e-5, 1e-3])
def test_rotation_near_pi(rng, eps):
    for axis in np.concatenate([np.eye(3), rng.normal(size=(5, 3))]):
        axis = axis / np.linalg.norm(axis)
        w = axis * (np.pi - eps)
        R = se3.exp_so3(w)
        w_back = se3.log_so3(R)
        assert np.isclose(np.linalg.norm(w_back), np.pi - eps, atol=1e-7)
        assert np.allclose(se3.exp_so3(w_back), R, atol=1e-7)
        if eps > 0:  # at exactly pi, +axis and -axis are the same rotation
            assert np.allclose(w_back, w, atol=1e-5)


def test_adjoint_conjugation_identity(rng):
    T = se3.exp_se3(rng.normal(size=6))
    xi = rng.normal(size=6)
    lhs = se3.hat6(se3.adjoint(T) @ xi)
    rhs = T @ se3.hat6(xi) @ se3.invert(T)
    assert np.allclose(lhs, rhs)
    # exp of the transported twist is the conjugated exponential
    assert np.allclose(se3.exp_se3(se3.adjoint(T) @ xi), T @ se3.exp_se3(xi) @ se3.invert(T))


def test_invert_and_apply(rng):
    T = se3.exp_se3(rng.normal(size=(3, 6)))
    assert np.allclose(se3.invert(T) @ T, np.eye(4))
    X = rng.normal(size=(3, 3))
    assert np.allclose(se3.apply(se3.invert(T), se3.apply(T, X)), X)


def test_revolute_twist_rotates_about_axis_through_point(rng):
    q = rng.normal(size=3)
    axis = np.array([0.0, 0.0, 1.0])
    xi = se3.revolute_twist(axis, q)
    T = se3.exp_se3(xi * np.pi / 2)
    assert np.allclose(se3.apply(T, q), q)                    # points on the axis stay
    assert np.allclose(se3.apply(T, q + [1, 0, 0]), q + [0, 1, 0])


def test_left_jacobian_against_finite_differences(rng):
    w = random_rotvecs(rng, 1, 2.5)[0]
    dw = 1e-6
    J = np.zeros((3, 3))
    R = se3.exp_so3(w)
    for i in range(3):
        e = np.zeros(3)
        e[i] = dw
        J[:, i] = se3.log_so3(se3.exp_so3(w + e) @ R.T) / dw
    assert np.allclose(J, se3.left_jacobian_so3(w), atol=1e-5)
    assert np.allclose(se3.left_jacobian_inv_so3(w) @ se3.left_jacobian_so3(w), np.eye(3))


def test_point_velocity_matrix_against_finite_differences(rng):
    X = rng.normal(size=(4, 3))
    xi = rng.normal(size=6)
    h = 1e-7
    numeric = (se3.apply(se3.exp_se3(xi * h), X) - se3.apply(se3.exp_se3(-xi * h), X)) / (2 * h)
    assert np.allclose(se3.point_velocity_matrix(X) @ xi, numeric, atol=1e-6)


def test_orthonormalize_recovers_rotation(rng):
    R = se3.exp_so3(rng.normal(size=3))
    noisy = R + 1e-4 * rng.normal(size=(3, 3))
    assert se3.is_rotation(se3.orthonormalize(noisy))
    assert np.allclose(se3.orthonormalize(noisy), R, atol=1e-3)


# -- bad input ---------------------------------------------------------------------------------

def test_check_rotation_errors():
    with pytest.raises(ZoopraxisError, match="3x3"):
        se3.check_rotation(np.eye(4))
    with pytest.raises(ZoopraxisError, match="orthonormal"):
        se3.check_rotation(np.eye(3) * 2)
    with pytest.raises(ZoopraxisError, match="reflection"):
        se3.check_rotation(np.diag([1.0, 1.0, -1.0]))
    with pytest.raises(ZoopraxisError, match="NaN"):
        se3.check_rotation(np.full((3, 3), np.nan))
    with pytest.raises(ZoopraxisError, match="zero length"):
        se3.revolute_twist(np.zeros(3), np.zeros(3))


def test_exp_se3_equals_its_rotation_and_left_jacobian(rng):
    # exp_se3 computes the rotation and J_l(w) v in one pass; compare with the two functions
    # and with the plain Rodrigues coefficients, including angles on the series branch.
    xi = rng.normal(size=(4, 25, 6))
    xi[0, ::3, 3:] *= 1e-9
    xi[1, :, 3:] = 0.0
    T = se3.exp_se3(xi)
    assert np.allclose(T[..., :3, :3], se3.exp_so3(xi[..., 3:]), rtol=0, atol=1e-12)
    Jv = np.einsum("...ij,...j->...i", se3.left_jacobian_so3(xi[..., 3:]), xi[..., :3])
    assert np.allclose(T[..., :3, 3], Jv, rtol=0, atol=1e-12)
    assert np.array_equal(T[..., 3, :], np.broadcast_to([0, 0, 0, 1.0], T.shape[:-2] + (4,)))
    theta = np.concatenate([rng.uniform(1e-5, 3.0, 50), [0.0, 1e-9, 5e-7]])
    a, b, c = se3._rodrigues_coefficients(theta)
    big = theta > 1e-6
    t = theta[big]
    assert np.allclose(a[big], np.sin(t) / t, rtol=1e-12, atol=0)
    assert np.allclose(b[big], (1 - np.cos(t)) / t**2, rtol=1e-12, atol=0)
    assert np.allclose(c[big], (t - np.sin(t)) / t**3, rtol=1e-9, atol=0)
    assert np.allclose([a[~big], b[~big], c[~big]], [[1.0], [0.5], [1 / 6]], atol=1e-12)


def test_revolute_exponential_equals_exp_se3(rng):
    """The joints' exponential with its hat matrices formed once equals the general one, for
    batches of angles, a subset of the twists, and angles of 0, tiny and past pi."""
    axes = rng.normal(size=(7, 3))
    points = rng.normal(size=(7, 3))
    twists = se3.revolute_twist(axes, points)
    exp = se3.RevoluteExp(twists)
    angles = rng.uniform(-4, 4, size=(5, 7))
    angles[0, :3] = [0.0, 1e-9, -np.pi]
    assert np.allclose(exp(angles), se3.exp_se3(twists * angles[..., None]), atol=1e-12)
    dofs = np.array([4, 1])
    assert np.allclose(exp(angles[:, dofs], dofs),
                       se3.exp_se3(twists[dofs] * angles[:, dofs, None]), atol=1e-12)
    assert np.allclose(exp(angles[2, [3]], [3])[0], se3.exp_se3(twists[3] * angles[2, 3]),
                       atol=1e-12)
    assert np.array_equal(exp(angles[:, dofs], tuple(dofs)), exp(angles[:, dofs], dofs))
    with pytest.raises(ZoopraxisError):
        se3.RevoluteExp(np.array([[0.5, 0.0, 0.0, 1.0, 0.0, 0.0]]))     # a screw, not a hinge
