"""Rigid-body motion: SO(3) and SE(3) exponentials and logarithms, twists, adjoints.

This is the algebra of Bregler & Malik §2.2 (after Murray, Li & Sastry): a twist is a 6-vector
``xi = [v, w]`` (linear part first, eq. 9), its hat is the 4x4 matrix in se(3), and the
exponential maps it to a rigid transform (eq. 10). Everything is vectorized: any leading batch
shape is allowed, e.g. ``exp_se3`` of an array of shape (N, 6) gives (N, 4, 4).

Convention: rotation matrices act on column vectors (``X' = R @ X``). A rigid transform
``T = [[R, p], [0, 1]]`` named ``B_from_A`` (or ``A2B``) maps points given in frame A into frame B.
Twists are ordered ``[v, w]`` as in Bregler & Malik eq. (9), not ``[w, v]``.
"""

import numpy as np

from ..errors import ZoopraxisError

# Below this angle the closed forms switch to Taylor series: the exact expressions divide
# small numbers by small numbers there, and the series are accurate to float64 precision.
_SMALL_ANGLE = 1e-6


def hat3(w):
    """Skew-symmetric matrix of a 3-vector, so that ``hat3(w) @ x == cross(w, x)``.

    Parameters
    ----------
    w : array, shape (..., 3)

    Returns
    -------
    W : array, shape (..., 3, 3)
    """
    w = np.asarray(w, dtype=float)
    W = np.zeros(w.shape[:-1] + (3, 3))
    W[..., 0, 1] = -w[..., 2]
    W[..., 0, 2] = w[..., 1]
    W[..., 1, 0] = w[..., 2]
    W[..., 1, 2] = -w[..., 0]
    W[..., 2, 0] = -w[..., 1]
    W[..., 2, 1] = w[..., 0]
    return W


def vee3(W):
    """Inverse of :func:`hat3`: the 3-vector of a skew-symmetric matrix (shape (..., 3, 3))."""
    W = np.asarray(W, dtype=float)
    return np.stack([W[..., 2, 1], W[..., 0, 2], W[..., 1, 0]], axis=-1)


def hat6(xi):
    """4x4 matrix of a twist ``[v, w]`` (Bregler & Malik eq. 9).

    Parameters
    ----------
    xi : array, shape (..., 6)

    Returns
    -------
    Xi : array, shape (..., 4, 4)
    """
    xi = np.asarray(xi, dtype=float)
    Xi = np.zeros(xi.shape[:-1] + (4, 4))
    Xi[..., :3, :3] = hat3(xi[..., 3:])
    Xi[..., :3, 3] = xi[..., :3]
    return Xi


def vee6(Xi):
    """Inverse of :func:`hat6`: the twist ``[v, w]`` of a 4x4 se(3) matrix."""
    Xi = np.asarray(Xi, dtype=float)
    return np.concatenate([Xi[..., :3, 3], vee3(Xi[..., :3, :3])], axis=-1)


def _rodrigues_coefficients(theta):
    """``a = sin(t)/t``, ``b = (1 - cos t)/t^2``, ``c = (t - sin t)/t^3`` with series near 0."""
    theta = np.asarray(theta, dtype=float)
    small = theta < _SMALL_ANGLE
    if not small.any():
        # the common case: no series, and sin(t) once
        sin = np.sin(theta)
        t2 = theta * theta
        return sin / theta, (1.0 - np.cos(theta)) / t2, (theta - sin) / (t2 * theta)
    t = np.where(small, 1.0, theta)
    t2 = t * t
    sin = np.sin(t)
    theta2 = theta**2
    a = np.where(small, 1.0 - theta2 / 6.0, sin / t)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(t)) / t2)
    c = np.where(small, 1.0 / 6.0 - theta2 / 120.0, (t - sin) / (t2 * t))
    return a, b, c


def exp_so3(w):
    """Rotation matrix of a rotation vector (axis times angle), by Rodrigues' formula.

    .. math:: e^{\\hat w} = I + \\frac{\\sin\\theta}{\\theta}\\hat w
              + \\frac{1-\\cos\\theta}{\\theta^2}\\hat w^2, \\quad \\theta = |w|

    Parameters
    ----------
    w : array, shape (..., 3)

    Returns
    -------
    R : array, shape (..., 3, 3)
    """
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)
    a, b, _ = _rodrigues_coefficients(theta)
    W = hat3(w)
    return np.eye(3) + a[..., None, None] * W + b[..., None, None] * (W @ W)


def log_so3(R):
    """Rotation vector of a rotation matrix, the inverse of :func:`exp_so3`.

    Handles angles near 0 (series) and near pi, where ``sin(theta)`` vanishes and the axis is
    read from the symmetric part ``(R + I) / 2 = n n^T`` instead. Returned angles lie in [0, pi].

    Parameters
    ----------
    R : array, shape (..., 3, 3)

    Returns
    -------
    w : array, shape (..., 3)
    """
    R = np.asarray(R, dtype=float)
    cos_theta = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(cos_theta)
    skew = vee3(R - np.swapaxes(R, -1, -2)) / 2.0  # = sin(theta) * n
    sin_theta = np.sin(theta)

    small = theta < _SMALL_ANGLE
    safe_sin = np.where(small, 1.0, sin_theta)
    w = np.where(small[..., None], skew * (1.0 + theta[..., None] ** 2 / 6.0),
                 skew * (theta / safe_sin)[..., None])

    near_pi = theta > np.pi - 1e-3
    if np.any(near_pi):
        # sin(theta) is tiny: the antisymmetric part no longer fixes the axis well, but the
        # symmetric part does, up to sign: (R + R^T)/2 - cos(theta) I = (1 - cos theta) n n^T.
        Rp = R[near_pi]
        theta_p = theta[near_pi]
        M = (Rp + np.swapaxes(Rp, -1, -2)) / 2.0 - cos_theta[near_pi][:, None, None] * np.eye(3)
        col = np.argmax(np.diagonal(M, axis1=-2, axis2=-1), axis=-1)
        n = np.take_along_axis(M, col[:, None, None], axis=-1)[..., 0]
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        # The sign comes from the (small but exact) antisymmetric part when it is usable.
        sign = np.sign(np.einsum("...i,...i->...", n, skew[near_pi]))
        sign = np.where(sign == 0, 1.0, sign)
        w[near_pi] = n * (sign * theta_p)[..., None]
    return w


def left_jacobian_so3(w):
    """Left Jacobian of SO(3): ``exp(w + dw) ~ exp(J_l(w) dw) exp(w)``.

    It is also the matrix that maps the linear part of a twist to the translation of its
    exponential: ``exp_se3([v, w])[:3, 3] == J_l(w) @ v``.

    Parameters
    ----------
    w : array, shape (..., 3)

    Returns
    -------
    J : array, shape (..., 3, 3)
    """
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)
    _, b, c = _rodrigues_coefficients(theta)
    W = hat3(w)
    return np.eye(3) + b[..., None, None] * W + c[..., None, None] * (W @ W)


def left_jacobian_inv_so3(w):
    """Inverse of :func:`left_jacobian_so3` in closed form (finite for angles below 2 pi)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1)
    small = theta < 1e-4
    t = np.where(small, 1.0, theta)
    # coefficient of W^2: 1/t^2 - (1 + cos t) / (2 t sin t), series 1/12 + t^2/720 near 0
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(small, 1.0 / 12.0 + theta**2 / 720.0,
                     1.0 / t**2 - (1.0 + np.cos(t)) / (2.0 * t * np.sin(t)))
    W = hat3(w)
    return np.eye(3) - 0.5 * W + d[..., None, None] * (W @ W)


def exp_se3(xi):
    """Rigid transform of a twist ``[v, w]`` (Bregler & Malik eq. 10, closed form).

    .. math:: e^{\\hat\\xi} = \\begin{bmatrix} e^{\\hat w} & J_l(w)\\,v \\\\ 0 & 1 \\end{bmatrix}

    Parameters
    ----------
    xi : array, shape (..., 6)

    Returns
    -------
    T : array, shape (..., 4, 4)
    """
    xi = np.asarray(xi, dtype=float)
    v, w = xi[..., :3], xi[..., 3:]
    # exp_so3(w) and left_jacobian_so3(w) share the angle, coefficients and hat matrices
    theta = np.linalg.norm(w, axis=-1)
    a, b, c = _rodrigues_coefficients(theta)
    W = hat3(w)
    W2 = W @ W
    b = b[..., None, None]
    T = np.zeros(xi.shape[:-1] + (4, 4))
    T[..., :3, :3] = np.eye(3) + a[..., None, None] * W + b * W2
    T[..., :3, 3] = np.einsum("...ij,...j->...i", np.eye(3) + b * W + c[..., None, None] * W2, v)
    T[..., 3, 3] = 1.0
    return T


class RevoluteExp:
    """:func:`exp_se3` of revolute twists (unit axis ``w``, ``v = -w x q``) times angles, with
    the hat matrices formed once: ``R = I + sin(t) W + (1 - cos(t)) W^2`` and the translation
    ``(I - R) q`` (Bregler & Malik eq. 17). A body's joints make this exponential thousands of
    times a frame; it equals :func:`exp_se3` to rounding.

    Parameters
    ----------
    twists : array, shape (n, 6)
        Revolute twists (:func:`revolute_twist`); anything else is refused.
    """

    def __init__(self, twists):
        twists = np.asarray(twists, dtype=float)
        v, w = twists[:, :3], twists[:, 3:]
        if (np.abs(np.linalg.norm(w, axis=1) - 1.0).max(initial=0.0) > 1e-9
                or np.abs(np.einsum("ij,ij->i", v, w)).max(initial=0.0) > 1e-9):
            raise ZoopraxisError("RevoluteExp needs unit axes with v = -w x q")
        self.W = hat3(w)                                    # (n, 3, 3)
        self.W2 = self.W @ self.W
        p = np.cross(w, v)                                  # the axis point nearest the origin
        self.Wp = np.einsum("nij,nj->ni", self.W, p)
        self.W2p = np.einsum("nij,nj->ni", self.W2, p)

    def __call__(self, angles, dofs=None):
        """Transforms (..., k, 4, 4) of ``angles`` (..., k) about the twists ``dofs`` (k,
        default all n)."""
        angles = np.asarray(angles, dtype=float)
        if dofs is not None:
            dofs = np.asarray(dofs, dtype=np.intp)      # a tuple would index several axes
        W, W2, Wp, W2p = (self.W, self.W2, self.Wp, self.W2p) if dofs is None else (
            self.W[dofs], self.W2[dofs], self.Wp[dofs], self.W2p[dofs])
        s = np.sin(angles)[..., None]
        k = 1.0 - np.cos(angles)
        k = k[..., None]
        T = np.zeros(angles.shape + (4, 4))
        T[..., :3, :3] = W * s[..., None]
        T[..., :3, :3] += W2 * k[..., None]
        T[..., 0, 0] += 1.0
        T[..., 1, 1] += 1.0
        T[..., 2, 2] += 1.0
        T[..., :3, 3] = -(Wp * s + W2p * k)
        T[..., 3, 3] = 1.0
        return T


def log_se3(T):
    """Twist ``[v, w]`` of a rigid transform, the inverse of :func:`exp_se3`.

    Parameters
    ----------
    T : array, shape (..., 4, 4)

    Returns
    -------
    xi : array, shape (..., 6)
    """
    T = np.asarray(T, dtype=float)
    w = log_so3(T[..., :3, :3])
    v = np.einsum("...ij,...j->...i", left_jacobian_inv_so3(w), T[..., :3, 3])
    return np.concatenate([v, w], axis=-1)


def transform(R=None, p=None):
    """4x4 rigid transform from a rotation (3, 3) and a translation (3,); either may be omitted."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def invert(T):
    """Inverse of rigid transforms, using ``R^T`` rather than a general matrix inverse.

    Parameters
    ----------
    T : array, shape (..., 4, 4)
    """
    T = np.asarray(T, dtype=float)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", Rt, T[..., :3, 3])
    out[..., 3, 3] = 1.0
    return out


def apply(T, X):
    """Apply rigid transforms to points: ``R @ X + p``.

    Parameters
    ----------
    T : array, shape (..., 4, 4)
    X : array, shape (..., 3), broadcast against T's batch shape
    """
    T = np.asarray(T, dtype=float)
    X = np.asarray(X, dtype=float)
    return np.einsum("...ij,...j->...i", T[..., :3, :3], X) + T[..., :3, 3]


def adjoint(T):
    """Adjoint of a rigid transform, acting on twists ordered ``[v, w]``.

    Bregler & Malik footnote 1: ``Ad_g = [[R, p^ R], [0, R]]``. It maps a twist expressed in frame
    A to the same motion expressed in frame B when ``T`` is ``B_from_A``:
    ``hat6(adjoint(T) @ xi) == T @ hat6(xi) @ inv(T)``.

    Parameters
    ----------
    T : array, shape (..., 4, 4)

    Returns
    -------
    Ad : array, shape (..., 6, 6)
    """
    T = np.asarray(T, dtype=float)
    R, p = T[..., :3, :3], T[..., :3, 3]
    Ad = np.zeros(T.shape[:-2] + (6, 6))
    Ad[..., :3, :3] = R
    Ad[..., :3, 3:] = hat3(p) @ R
    Ad[..., 3:, 3:] = R
    return Ad


def revolute_twist(axis, point):
    """Twist of a revolute joint with unit ``axis`` through ``point`` (Bregler & Malik eq. 17).

    .. math:: \\xi = [-\\omega \\times q, \\omega]

    Parameters
    ----------
    axis : array, shape (..., 3)
        Rotation axis; normalized here.
    point : array, shape (..., 3)
        Any point on the axis.
    """
    axis = np.asarray(axis, dtype=float)
    norm = np.linalg.norm(axis, axis=-1, keepdims=True)
    if np.any(norm < 1e-12):
        raise ZoopraxisError("revolute joint axis has zero length")
    w = axis / norm
    return np.concatenate([-np.cross(w, point), w], axis=-1)


def point_velocity_matrix(X):
    """Matrix that maps a spatial twist to the velocity of points: ``dX = [I, -X^] @ xi``.

    For a point ``X`` moved by ``exp(hat6(xi) * s)``, the velocity at ``s = 0`` is
    ``v + w x X = v - X x w``. This is the 3D part of Bregler & Malik eqs. (14) and (23).

    Parameters
    ----------
    X : array, shape (..., 3)

    Returns
    -------
    M : array, shape (..., 3, 6)
    """
    X = np.asarray(X, dtype=float)
    M = np.zeros(X.shape[:-1] + (3, 6))
    M[..., 0, 0] = M[..., 1, 1] = M[..., 2, 2] = 1.0
    M[..., :, 3:] = -hat3(X)
    return M


def is_rotation(R, tol=1e-6):
    """True where ``R`` (shape (..., 3, 3)) is orthonormal with determinant +1."""
    R = np.asarray(R, dtype=float)
    eye_err = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
    return (eye_err < tol) & (np.linalg.det(R) > 0)


def check_rotation(R, name="R", tol=1e-6):
    """Return ``R`` as a float (3, 3) array, or raise ZoopraxisError saying what is wrong."""
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise ZoopraxisError(f"{name} must be a 3x3 rotation matrix, got shape {R.shape}")
    if not np.all(np.isfinite(R)):
        raise ZoopraxisError(f"{name} contains NaN or infinite values")
    err = np.abs(R.T @ R - np.eye(3)).max()
    if err > tol:
        raise ZoopraxisError(f"{name} is not orthonormal (|R^T R - I| = {err:.2g})")
    if np.linalg.det(R) < 0:
        raise ZoopraxisError(f"{name} is a reflection (determinant -1), not a rotation")
    return R


def orthonormalize(R):
    """Nearest rotation matrix (polar decomposition by SVD), for drift after many products."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    D = np.ones(U.shape[:-1])
    D[..., -1] = np.sign(np.linalg.det(U @ Vt))
    return (U * D[..., None, :]) @ Vt
