"""Starting points of the initialization's fits: scaled orthographic cameras from the clicks
of one view, and inverse kinematics on 3D joints (triangulated, or reflected in depth)."""

import numpy as np
from scipy.optimize import least_squares

from ..body.joints import JOINT_INDEX, STANDARD_JOINTS
from ..geometry import se3
from ..geometry.ortho import ScaledOrthoCamera

# In 3D inverse kinematics (starting points only) a prior spread costs this many metres.
IK_PRIOR_M = 0.01
# Joints of the trunk, nearly rigid and nearly planar: they give a body's position and heading.
_TORSO = [JOINT_INDEX[n] for n in ("pelvis", "l_hip", "r_hip", "neck", "l_shoulder",
                                   "r_shoulder", "head")]
# The camera that sees the body's front in the reference configuration (facing -Y, Z up):
# camera x = body +X (the subject's left on the image right), camera y = -Z, camera z = +Y.
_FRONT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _rot_z(angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _image_up(uv):
    """Unit 2D direction from the hips to the neck / shoulders in one view, or None."""
    def mean(names):
        pts = uv[[JOINT_INDEX[n] for n in names]]
        pts = pts[np.isfinite(pts).all(axis=-1)]
        return pts.mean(axis=0) if len(pts) else None

    low = mean(["pelvis"]) if np.isfinite(uv[JOINT_INDEX["pelvis"]]).all() \
        else mean(["l_hip", "r_hip"])
    high = mean(["neck"]) if np.isfinite(uv[JOINT_INDEX["neck"]]).all() \
        else mean(["l_shoulder", "r_shoulder", "head"])
    if low is None or high is None or np.linalg.norm(high - low) < 1e-6:
        return None
    d = high - low
    return d / np.linalg.norm(d)


_SCALE_BONES = (("pelvis", "neck"), ("l_hip", "l_knee"), ("r_hip", "r_knee"),
                ("l_knee", "l_ankle"), ("r_knee", "r_ankle"), ("l_shoulder", "l_elbow"),
                ("r_shoulder", "r_elbow"), ("l_elbow", "l_wrist"), ("r_elbow", "r_wrist"),
                ("l_shoulder", "r_shoulder"), ("neck", "head"))


def _image_scale(uv, Y):
    """Pixels per metre of one view from clicked bone lengths: foreshortening only shortens
    a bone, so the longest-looking bones (relative to their 3D length) give the scale."""
    a = np.array([JOINT_INDEX[p] for p, _ in _SCALE_BONES])
    b = np.array([JOINT_INDEX[q] for _, q in _SCALE_BONES])
    length_2d = np.linalg.norm(uv[a] - uv[b], axis=-1)
    length_3d = np.linalg.norm(Y[a] - Y[b], axis=-1)
    ratio = length_2d / length_3d
    ratio = np.sort(ratio[np.isfinite(ratio)])[::-1]
    if ratio.size == 0:
        pts = uv[np.isfinite(uv).all(axis=-1)]
        return max(np.ptp(pts[:, 1]) / 1.6, 1.0) if len(pts) > 1 else 100.0
    return float(np.median(ratio[:3]))


def _ortho_camera(name, image_size, uv, Y, yaw, pitch=0.0):
    """A scaled orthographic camera that sees body-frame joints ``Y`` turned by ``yaw`` about
    the body's vertical, upright as the clicks ``uv`` are, at their scale and position."""
    up = _image_up(uv)
    # The front camera maps body +Z to image (0, -1); roll the image so it maps to ``up``.
    roll = 0.0 if up is None else np.arctan2(up[1], up[0]) + np.pi / 2
    c, s = np.cos(roll), np.sin(roll)
    R_roll = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    cp, sp = np.cos(pitch), np.sin(pitch)
    R_pitch = np.array([[1.0, 0.0, 0.0], [0.0, cp, -sp], [0.0, sp, cp]])
    R = R_roll @ R_pitch @ _FRONT @ _rot_z(yaw)
    scale = _image_scale(uv, Y)
    centre = ((image_size[0] - 1) / 2, (image_size[1] - 1) / 2)
    seen = np.isfinite(uv).all(axis=-1)
    proj = Y @ R[:2].T
    shift = np.mean((uv[seen] - centre) / scale - proj[seen], axis=0)
    return ScaledOrthoCamera(name, image_size, scale, R=R, t=[shift[0], shift[1], 10.0], c=centre)


def _affine_camera(name, image_size, uv, Y):
    """The scaled orthographic camera closest to the affine camera that maps body points ``Y``
    (17, 3) to clicks ``uv`` (17, 2; NaN where not clicked), by linear least squares.

    An affine camera ``uv = A @ Y + b`` is fitted; the scaled rotation nearest to ``A`` has the
    rows ``U @ Vt`` of its singular value decomposition and the mean singular value as scale.
    """
    seen = np.isfinite(uv).all(axis=-1)
    Yh = np.concatenate([Y[seen], np.ones((seen.sum(), 1))], axis=1)
    P = np.linalg.lstsq(Yh, uv[seen], rcond=None)[0].T                     # (2, 4)
    U, S, Vt = np.linalg.svd(P[:, :3], full_matrices=False)
    rows = U @ Vt
    R = np.vstack([rows, np.cross(rows[0], rows[1])])
    scale = max(float(S.mean()), 1e-6)
    centre = ((image_size[0] - 1) / 2, (image_size[1] - 1) / 2)
    shift = (P[:, 3] - centre) / scale
    return ScaledOrthoCamera(name, image_size, scale, R=R, t=[shift[0], shift[1], 10.0],
                             c=centre)


def _fit_3d(kin, target, dims, root, angles, free_root=True, dofs=None):
    """Inverse kinematics: root and angles that put the joints on 3D points (metres).

    Parameters
    ----------
    target : array, shape (17, 3)
        NaN where unknown.
    root : array, shape (4, 4)
    angles : array, shape (n,)
    free_root : bool
        Fit the root too, or keep ``root``.
    dofs : array of int, optional
        The angles to fit (default all); the others keep their values.

    Returns
    -------
    root : array, shape (4, 4)
    angles : array, shape (n,)
    """
    seen = np.isfinite(target).all(axis=-1)
    R0, p0 = root[:3, :3], root[:3, 3]
    dofs = np.arange(kin.n_dofs) if dofs is None else np.asarray(dofs)
    n = len(dofs)
    base = np.array(angles, float)
    k = 6 if free_root else 0
    wa = IK_PRIOR_M / kin.prior_sigma[dofs]

    def split(x):
        a = base.copy()
        a[dofs] = x[k:]
        if free_root:
            return x[:3], x[3:6], se3.exp_so3(x[3:6]) @ R0, a
        return p0, None, R0, a

    def fun(x):
        p, w, R, a = split(x)
        Y, JA, _ = kin.forward(a[None], dims)
        X = Y[0] @ R.T + p
        r = np.concatenate([(X - target)[seen].ravel(), wa * (x[k:] - kin.prior_mean[dofs])])
        parts = [R @ JA[0][..., dofs]]
        if free_root:
            J_rot = -se3.hat3(X - p) @ se3.left_jacobian_so3(w)
            parts = [np.broadcast_to(np.eye(3), J_rot.shape), J_rot] + parts
        J = np.concatenate(parts, axis=-1)[seen].reshape(-1, k + n)
        J = np.vstack([J, np.hstack([np.zeros((n, k)), np.diag(wa)])])
        return r, J

    lo = np.concatenate([np.full(k, -np.inf), kin.lower[dofs]])
    hi = np.concatenate([np.full(k, np.inf), kin.upper[dofs]])
    x0 = np.concatenate([p0, np.zeros(3)])[:k]
    x0 = np.clip(np.concatenate([x0, base[dofs]]), lo, hi)
    res = least_squares(lambda x: fun(x)[0], x0, jac=lambda x: fun(x)[1], bounds=(lo, hi),
                        method="dogbox", loss="soft_l1", f_scale=0.05, max_nfev=100)
    p, _, R, a = split(res.x)
    return se3.transform(se3.orthonormalize(R), p), np.clip(a, kin.lower, kin.upper), res.cost


# Limbs whose angles the 3D starting fit tries from several starts, with the DOFs varied: a
# limb's roll and lift can wind the wrong way round and lock on a joint limit.
_LIMB_STARTS = {
    "shoulder": ("elbow", (("shoulder_rot", (-0.9, 0.0, 0.9)), ("shoulder_abd", (0.2, 1.2)))),
    "hip": ("knee", (("hip_rot", (-0.5, 0.0, 0.5)), ("hip_flex", (0.2, 1.2)))),
}


_LIMB_JOINTS = {"shoulder": ("elbow", "wrist"), "hip": ("knee", "ankle", "toe")}
# A limb whose joints all lie this close to their 3D points is taken as fitted.
_LIMB_MISS_M = 0.04


def _fit_limbs_3d(kin, target, dims, root, angles):
    """Refit each arm or leg that misses its 3D points from several starts, keeping the best
    (see _LIMB_STARTS).

    Returns
    -------
    angles : array, shape (n,)
    """
    names = kin.structure.dof_names
    index = {name: k for k, name in enumerate(names)}
    angles = angles.copy()
    Y = kin.forward(angles[None], dims)[0][0]
    miss = np.linalg.norm(Y @ root[:3, :3].T + root[:3, 3] - target, axis=-1)
    for side in ("l", "r"):
        for proximal, (distal, grid) in _LIMB_STARTS.items():
            prefixes = (f"{side}_{proximal}_", f"{side}_{distal}_")
            dofs = [k for k, name in enumerate(names) if name.startswith(prefixes)]
            limb = [JOINT_INDEX[j] for j in STANDARD_JOINTS if j.startswith(f"{side}_")
                    and j[2:] in _LIMB_JOINTS[proximal]]
            if not dofs or not np.nanmax(miss[limb], initial=0.0) > _LIMB_MISS_M:
                continue
            best = _fit_3d(kin, target, dims, root, angles, free_root=False, dofs=dofs)
            (first, first_values), (second, second_values) = grid
            for a in first_values:
                for b in second_values:
                    start = angles.copy()
                    start[index[f"{side}_{first}"]] = a
                    start[index[f"{side}_{second}"]] = b
                    trial = _fit_3d(kin, target, dims, root, start, free_root=False, dofs=dofs)
                    if trial[2] < best[2]:
                        best = trial
            angles = best[1]
    return angles


def _poses_on_points(kin, target, dims, root, angles):
    """Roots and angles that put the body on 3D points (triangulated joints) from a root placed
    on the trunk's points, by two orders of the inverse kinematics (one pose when both agree).

    The whole body fitted first (root free) and then each limb that misses from several
    starts holds for most poses; a limb far from the starting angles (a kicking leg raised
    past the horizontal) may instead drag the root off the trunk, and the limbs' starts are then
    tried about a misplaced hip (a 3-view init of a front kick started 0.46 m off at the ankle
    and ended 16-23 px from the clicks). The limbs fitted first, about the trunk's root, then
    the whole body, then the limbs again do not depend on the root staying put, but reach a
    worse pose as often as a better one: the fit to the clicks judges.

    Returns
    -------
    list of (root, angles)
        root : array, shape (4, 4); angles : array, shape (n,)
    """
    fitted_root, fitted, _ = _fit_3d(kin, target, dims, root, angles)
    poses = [(fitted_root, _fit_limbs_3d(kin, target, dims, fitted_root, fitted))]
    limbs = _fit_limbs_3d(kin, target, dims, root, angles)
    fitted_root, fitted, _ = _fit_3d(kin, target, dims, root, limbs)
    second = (fitted_root, _fit_limbs_3d(kin, target, dims, fitted_root, fitted))
    if (np.abs(second[1] - poses[0][1]).max() > 1e-3
            or np.abs(second[0] - poses[0][0]).max() > 1e-3):
        poses.append(second)
    return poses
