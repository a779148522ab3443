"""Lens distortion: OpenCV's 5-coefficient model (radial k1, k2, k3 and tangential p1, p2) in
normalized image coordinates, and its inverse by Newton's method. Used by ``PinholeCamera``.

Convention:
    Normalized coordinates are ``(X_c / Z_c, Y_c / Z_c)`` in OpenCV camera axes; ``dist`` is
    ``[k1, k2, p1, p2, k3]`` as OpenCV orders it.
"""

import numpy as np


def distort_xy(x, y, dist, jacobian=False):
    """``distort`` on separate coordinate arrays; the Jacobian as its 3 distinct entries."""
    k1, k2, p1, p2, k3 = dist
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy2 = 2.0 * x * y
    x_d = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    y_d = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    if not jacobian:
        return x_d, y_d
    dradial_dr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    # The tangential terms are the gradient of p2 x r2 + p1 y r2, so the Jacobian is symmetric.
    j_xx = radial + 2.0 * x * x * dradial_dr2 + 2.0 * p1 * y + 6.0 * p2 * x
    j_xy = xy2 * dradial_dr2 + 2.0 * p1 * x + 2.0 * p2 * y
    j_yy = radial + 2.0 * y * y * dradial_dr2 + 6.0 * p1 * y + 2.0 * p2 * x
    return x_d, y_d, j_xx, j_xy, j_yy


# Below this r^2 no term of the distortion model overflows (they are at most 3 r^2).
_R2_PLAIN = 1e300


def no_distortion(dist):
    """Whether all five coefficients are +0.0 (not -0.0, which changes the signs of zeros)."""
    return not dist.any() and not np.signbit(dist).any()


def distort(xy, dist, jacobian=False):
    """Apply lens distortion to normalized coordinates.

    .. math:: x_d = x (1 + k_1 r^2 + k_2 r^4 + k_3 r^6) + 2 p_1 x y + p_2 (r^2 + 2 x^2)

    and likewise for ``y_d`` with ``p1`` and ``p2`` exchanged.

    Parameters
    ----------
    xy : array, shape (..., 2)
        Undistorted normalized coordinates ``(X_c / Z_c, Y_c / Z_c)``.
    dist : array, shape (5,)
        ``[k1, k2, p1, p2, k3]``.
    jacobian : bool
        Also return ``d xy_d / d xy``.

    Returns
    -------
    xy_d : array, shape (..., 2)
    J : array, shape (..., 2, 2)
        Only if ``jacobian``.
    """
    if not jacobian and no_distortion(dist):
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x
        r2 += y * y
        if np.all(r2 < _R2_PLAIN):
            # With all coefficients +0 and r^2 finite, the model's sums are x + (+0) and
            # y + (+0) exactly (the +0 terms only turn -0 into +0): the same values.
            return xy + 0.0
    out = distort_xy(xy[..., 0], xy[..., 1], dist, jacobian)
    xy_d = np.stack(out[:2], axis=-1)
    if not jacobian:
        return xy_d
    j_xx, j_xy, j_yy = out[2:]
    J = np.stack([np.stack([j_xx, j_xy], axis=-1), np.stack([j_xy, j_yy], axis=-1)], axis=-2)
    return xy_d, J


def undistort(xy_d, dist, max_iterations=30):
    """Invert ``distort`` by Newton's method; NaN where the lens model has no valid inverse.

    Parameters
    ----------
    xy_d : array, shape (..., 2)
        Distorted normalized coordinates.
    dist : array, shape (5,)

    Returns
    -------
    xy : array, shape (..., 2)
        Undistorted normalized coordinates, accurate to round-off. NaN where Newton
        does not converge or converges past the fold of the distortion polynomial (where the model
        turns back on itself and ``det(d xy_d / d xy) <= 0``): no point in front of the lens
        images there.
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    if not np.any(dist):
        return xy_d.copy()
    # Work on contiguous coordinate arrays, shrinking to the points still moving: a full image
    # is millions of points and most converge in 3-4 steps.
    x_target = np.ascontiguousarray(xy_d[..., 0]).ravel()
    y_target = np.ascontiguousarray(xy_d[..., 1]).ravel()
    x, y = x_target.copy(), y_target.copy()
    tolerance = 1e-12 * (1.0 + np.maximum(np.abs(x_target), np.abs(y_target)))
    valid = np.zeros(x.size, dtype=bool)
    active = np.flatnonzero(np.isfinite(x_target) & np.isfinite(y_target))
    for _ in range(max_iterations):
        if active.size == 0:
            break
        xa, ya = x[active], y[active]
        f_x, f_y, j_xx, j_xy, j_yy = distort_xy(xa, ya, dist, jacobian=True)
        r_x = f_x - x_target[active]
        r_y = f_y - y_target[active]
        det = j_xx * j_yy - j_xy * j_xy
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            # The step is taken by converged points too: at quadratic convergence it is the
            # cheapest way from 1e-12 to round-off.
            x[active] = xa - (j_yy * r_x - j_xy * r_y) / det
            y[active] = ya - (j_xx * r_y - j_xy * r_x) / det
        done = np.maximum(np.abs(r_x), np.abs(r_y)) <= tolerance[active]
        valid[active[done & (det > 0)]] = True
        active = active[~done]
    x[~valid] = np.nan
    y[~valid] = np.nan
    return np.stack([x, y], axis=-1).reshape(xy_d.shape)
