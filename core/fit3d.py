"""Fit the body model to known 3D joint positions (motion capture, triangulated joints).

Used to pose the model on ground truth for tests and benchmarks, to turn a capture into joint
angles (walking prior, re-animation), and to give the trackers a pose from 3D joints.
"""

import numpy as np

from . import se3
from .body import DEFAULT_DIMS, Pose, make_body
from .errors import ZoopraxisError
from .joints import JOINT_INDEX


def dims_from_joints(joints3d):
    """Body lengths measured on 3D joints (mean over frames, left and right averaged).

    Parameters
    ----------
    joints3d : array, shape (F, 17, 3) or (17, 3)

    Returns
    -------
    dims : dict
        The length dimensions of :data:`body.DEFAULT_DIMS` the joints determine.
    """
    X = np.asarray(joints3d, float).reshape(-1, 17, 3)
    J = JOINT_INDEX

    def dist(a, b):
        return float(np.mean(np.linalg.norm(X[:, J[a]] - X[:, J[b]], axis=-1)))

    def both(a, b):
        return 0.5 * (dist("l_" + a, "l_" + b) + dist("r_" + a, "r_" + b))

    # The ankle-to-toe vector splits into forward and downward parts in the rest pose; use
    # the mean drop seen in the data where the foot is flat-ish, clipped to a sane range.
    foot = both("ankle", "toe")
    drop = float(np.clip(0.4 * foot, 0.03, 0.08))
    dims = {
        "hip_width": dist("l_hip", "r_hip"),
        "thigh": both("hip", "knee"),
        "shank": both("knee", "ankle"),
        "foot_length": float(np.sqrt(max(foot ** 2 - drop ** 2, 1e-4))),
        "foot_drop": drop,
        "shoulder_width": dist("l_shoulder", "r_shoulder"),
        "upper_arm": both("shoulder", "elbow"),
        "forearm": both("elbow", "wrist"),
        "neck_length": dist("neck", "head"),
    }
    torso = dist("pelvis", "neck")
    dims["torso"] = torso
    shoulder_mid = 0.5 * (X[:, J["l_shoulder"]] + X[:, J["r_shoulder"]])
    dims["shoulder_drop"] = float(np.clip(np.mean(np.linalg.norm(
        shoulder_mid - X[:, J["neck"]], axis=-1)), 0.0, 0.15))
    scale = torso / DEFAULT_DIMS["torso"]
    dims["spine_lumbar"] = DEFAULT_DIMS["spine_lumbar"] * scale
    dims["spine_thorax"] = DEFAULT_DIMS["spine_thorax"] * scale
    return dims


def _initial_root(body, X):
    """Root transform from the hips and the neck (Kabsch on the trunk joints)."""
    J = JOINT_INDEX
    idx = [J["pelvis"], J["l_hip"], J["r_hip"], J["neck"], J["l_shoulder"], J["r_shoulder"]]
    ref = body.joints(body.rest_pose())[idx]
    obs = X[idx]
    ok = np.all(np.isfinite(obs), axis=1)
    if ok.sum() < 3:
        raise ZoopraxisError("need the pelvis, hips or shoulders to place the body")
    a, b = ref[ok], obs[ok]
    ca, cb = a.mean(0), b.mean(0)
    U, _, Vt = np.linalg.svd((b - cb).T @ (a - ca))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    return se3.transform(R, cb - R @ ca)


def fit_pose(body, joints3d, init=None, *, weights=None, iterations=40, prior=1e-3):
    """Pose that best matches 3D joints, within the joint limits (damped Gauss-Newton).

    Parameters
    ----------
    body : BodyModel
    joints3d : array, shape (17, 3)
        NaN rows are ignored.
    init : Pose, optional
        Starting pose (the previous frame's, when fitting a sequence).
    weights : array, shape (17,), optional
    prior : float
        Weight of a pull towards ``init`` angles (or zero angles), keeping unobservable DOFs
        (e.g. axial rotations of straight limbs) still.

    Returns
    -------
    pose : Pose
    rms : float
        Root-mean-square joint error, metres.
    """
    X = np.asarray(joints3d, float)
    ok = np.all(np.isfinite(X), axis=1)
    w = np.ones(17) if weights is None else np.asarray(weights, float)
    w = np.where(ok, w, 0.0)
    Xs = np.where(ok[:, None], X, 0.0)
    pose = init.copy() if init is not None else Pose(_initial_root(body, X),
                                                      np.zeros(body.n_dofs))
    anchor = pose.angles.copy()
    lam = 1e-3
    P = body.n_params

    def cost_of(p):
        r = (body.joints(p) - Xs) * np.sqrt(w)[:, None]
        return float(np.sum(r * r) + prior * np.sum((p.angles - anchor) ** 2))

    cost = cost_of(pose)
    for _ in range(iterations):
        Xm, Jm = body.joints_jacobian(pose)
        r = ((Xm - Xs) * w[:, None]).reshape(-1)
        Jw = (Jm * np.sqrt(w)[:, None, None]).reshape(-1, P)
        H = Jw.T @ Jw
        g = Jw.T @ ((Xm - Xs) * np.sqrt(w)[:, None]).reshape(-1)
        H[6:, 6:] += prior * np.eye(body.n_dofs)
        g[6:] += prior * (pose.angles - anchor)
        del r
        delta = -np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-9), g)
        cand = pose.retract(delta)
        cand.angles = body.clamp(cand.angles)
        c2 = cost_of(cand)
        if c2 < cost:
            pose, cost = cand, c2
            lam = max(lam / 5, 1e-7)
            if np.abs(delta).max() < 1e-7:
                break
        else:
            lam *= 10
            if lam > 1e6:
                break
    err = np.linalg.norm(body.joints(pose) - Xs, axis=1)[ok]
    return pose, float(np.sqrt(np.mean(err ** 2)))


def fit_sequence(joints3d, template="full", *, body=None, prior=1e-3):
    """Body dimensions and per-frame poses that match a sequence of 3D joints.

    Parameters
    ----------
    joints3d : array, shape (F, 17, 3)

    Returns
    -------
    body : BodyModel
    poses : list of Pose
    rms : array, shape (F,)
        Per-frame joint RMS error, metres.
    """
    X = np.asarray(joints3d, float)
    if body is None:
        body = make_body(template, dims_from_joints(X))
    poses, rms = [], []
    pose = None
    for f in range(len(X)):
        pose, e = fit_pose(body, X[f], pose, prior=prior)
        poses.append(pose)
        rms.append(e)
    return body, poses, np.array(rms)
