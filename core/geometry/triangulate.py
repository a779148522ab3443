"""Points from calibrated views and the alignment of point sets: linear triangulation,
least-squares similarity (Kabsch / Umeyama) and the Procrustes-aligned joint error."""

import numpy as np


def triangulate(cameras, uv):
    """Triangulate points clicked in several calibrated views (linear DLT, then no refinement).

    Parameters
    ----------
    cameras : list of PinholeCamera, length V
    uv : array, shape (V, N, 2)
        Observed (distorted) pixels; NaN where a point is not seen in a view.

    Returns
    -------
    X : array, shape (N, 3)
        World points; NaN where fewer than two views see the point.
    """
    uv = np.asarray(uv, dtype=float)
    V, N = uv.shape[:2]
    A = np.zeros((N, 2 * V, 4))
    seen = np.isfinite(uv).all(axis=-1)                                      # (V, N)
    for v, cam in enumerate(cameras):
        ideal = cam.undistort_points(np.where(seen[v, :, None], uv[v], 0.0))
        xy1 = np.concatenate([ideal, np.ones((N, 1))], axis=-1) @ np.linalg.inv(cam.K).T
        P = np.hstack([cam.R, cam.t[:, None]])                              # normalized camera
        rows = np.stack([xy1[:, :1] * P[2] - P[0], xy1[:, 1:2] * P[2] - P[1]], axis=1)
        A[:, 2 * v:2 * v + 2] = np.where(seen[v, :, None, None], rows, 0.0)
    # Equal row norms make the algebraic error close to the angular one.
    norms = np.linalg.norm(A, axis=-1, keepdims=True)
    A = np.divide(A, norms, out=np.zeros_like(A), where=norms > 0)
    Xh = np.linalg.svd(A)[2][:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):
        X = Xh[:, :3] / Xh[:, 3:]
    X[seen.sum(axis=0) < 2] = np.nan
    return X


def similarity_from_points(source, target, with_scale=True):
    """Least-squares similarity ``target ~ scale * R @ source + t`` (Kabsch / Umeyama).

    Parameters
    ----------
    source, target : array, shape (N, 3)
        Corresponding points, N >= 3 not all on a line.
    with_scale : bool

    Returns
    -------
    R : array, shape (3, 3)
    t : array, shape (3,)
    scale : float
    """
    source = np.asarray(source, float)
    target = np.asarray(target, float)
    mu_s, mu_t = source.mean(axis=0), target.mean(axis=0)
    a, b = source - mu_s, target - mu_t
    U, sv, Vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(U @ Vt)) or 1.0
    S = np.diag([1.0, 1.0, d])
    R = U @ S @ Vt
    scale = float(np.trace(np.diag(sv) @ S) / np.sum(a**2)) if with_scale else 1.0
    return R, mu_t - scale * R @ mu_s, scale


def procrustes_mpjpe(predicted, truth):
    """Mean per-joint position error after the best similarity alignment (metres).

    Parameters
    ----------
    predicted, truth : array, shape (N, 3)
    """
    R, t, s = similarity_from_points(predicted, truth)
    return float(np.mean(np.linalg.norm(s * predicted @ R.T + t - truth, axis=-1)))
