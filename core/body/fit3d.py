"""Fit the body model to known 3D joint positions (motion capture, triangulated joints).

Used to pose the model on ground truth for tests and benchmarks, to turn a capture into joint
angles (the walking prior's training data, ``tools/learn_walk_prior.py``; re-animation), and to
give the trackers a pose from 3D joints:

- :func:`fit_pose`: one frame's root and angles;
- :func:`fit_sequence`: lengths measured on the joints (:func:`dims_from_joints`), then every
  frame's pose;
- :func:`fit_body`: lengths and poses fitted together (a template whose joints sit elsewhere
  than the capture's).

Convention: world Z up, metres; poses are ``body.Pose`` (``world_from_pelvis`` and the angles).
"""

import numpy as np

from ..geometry import se3
from .body import DEFAULT_DIMS, LENGTH_DIMS, Pose, make_body
from ..errors import ZoopraxisError
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


def root_from_joints(joints):
    """A root transform from standard joints: pelvis position, hips give left, spine gives up.

    Parameters
    ----------
    joints : array, shape (17, 3)

    Returns
    -------
    world_from_pelvis : array, shape (4, 4)
        Reference axes (body module convention): x to the subject's left, z up the spine,
        y = z x x (backwards), so the body faces -y.
    """
    J = np.asarray(joints, float)
    x = J[JOINT_INDEX["l_hip"]] - J[JOINT_INDEX["r_hip"]]
    z = J[JOINT_INDEX["neck"]] - J[JOINT_INDEX["pelvis"]]
    x = x / np.linalg.norm(x)
    z = z - (z @ x) * x
    z = z / np.linalg.norm(z)
    return se3.transform(np.column_stack([x, np.cross(z, x), z]), J[JOINT_INDEX["pelvis"]])


def fit_pose(body, joints3d, init=None, *, weights=None, iterations=60, prior=1e-5, tol=1e-8):
    """Pose that best matches 3D joints, within the joint limits (Levenberg-Marquardt).

    Minimizes ``sum_j w_j |X_j(pose) - Y_j|^2 + prior * |angles - angles_0|^2`` over the root
    and the angles with ``body.joints_jacobian``; angles are clamped to the joint limits after
    every step.

    Parameters
    ----------
    body : BodyModel
    joints3d : array, shape (17, 3)
        Target standard joints, world metres; NaN rows are ignored (at least 4 must be known).
    init : Pose, optional
        Starting pose (the previous frame's, when fitting a sequence), whose angles the prior
        pulls towards; by default zero angles at the root that best aligns the trunk joints.
    weights : array, shape (17,), optional
    iterations : int
        Most Levenberg-Marquardt steps.
    prior : float
        Weight of the pull towards the starting angles, m^2 per rad^2. It settles what the
        joints leave free (the twist of a straight arm): 1e-5 barely biases what they see,
        1e-3 (:func:`fit_sequence`) also keeps nearly unobservable angles still.
    tol : float
        Stop when a step lowers the cost by less than this fraction.

    Returns
    -------
    pose : Pose
    rms : float
        Root-mean-square joint error over the known joints, metres.
    """
    X = np.asarray(joints3d, float)
    if X.shape != (17, 3):
        raise ZoopraxisError(f"fit_pose: joints must have shape (17, 3), got {X.shape}")
    ok = np.all(np.isfinite(X), axis=1)
    if ok.sum() < 4:
        raise ZoopraxisError(f"fit_pose: only {ok.sum()} of 17 joints are known; need 4")
    w = np.ones(17) if weights is None else np.asarray(weights, float)
    w = np.where(ok, w, 0.0)
    sw = np.sqrt(w)
    Xs = np.where(ok[:, None], X, 0.0)
    pose = init.copy() if init is not None else Pose(_initial_root(body, X),
                                                      np.zeros(body.n_dofs))
    pose.angles = body.clamp(pose.angles)
    anchor = pose.angles.copy()
    P = body.n_params

    def cost_of(p):
        r = (body.joints(p) - Xs) * sw[:, None]
        return float(np.sum(r * r) + prior * np.sum((p.angles - anchor) ** 2))

    cost = cost_of(pose)
    lam = 1e-3
    for _ in range(iterations):
        Xm, Jm = body.joints_jacobian(pose)
        Jw = (Jm * sw[:, None, None]).reshape(-1, P)
        H = Jw.T @ Jw
        g = Jw.T @ ((Xm - Xs) * sw[:, None]).reshape(-1)
        H[6:, 6:] += prior * np.eye(body.n_dofs)
        g[6:] += prior * (pose.angles - anchor)
        # Raise the damping until a step goes downhill (a clamped angle can make the
        # undamped step useless).
        decrease = None
        for _ in range(10):
            cand = pose.retract(-np.linalg.solve(H + lam * np.diag(np.diag(H) + 1e-9), g))
            cand.angles = body.clamp(cand.angles)
            c2 = cost_of(cand)
            if c2 < cost:
                decrease = cost - c2
                pose, cost = cand, c2
                lam = max(lam / 3.0, 1e-9)
                break
            lam *= 4.0
        if decrease is None or decrease < tol * max(cost, 1e-12):
            break
    err = np.linalg.norm(body.joints(pose) - Xs, axis=1)[ok]
    return pose, float(np.sqrt(np.mean(err ** 2)))


def fit_body(body, joints, *, iterations=20, dims=None, ridge=1e-4, prior=1e-5):
    """Fit body lengths and per-frame poses to a sequence of 3D standard joints.

    Every frame's pose starts from :func:`fit_pose` (each frame from the previous one); then
    Gauss-Newton steps refine the lengths and all poses together. At fixed angles the joints
    are linear in the lengths (``body.joints_dims_jacobian``), and each pose only touches its
    own frame, so the normal equations are block-diagonal in the poses: the shared lengths
    are solved on their Schur complement, then each pose on its own block. A ridge towards
    the starting lengths keeps lengths no joint measures (a template's spine) where they are;
    a length driven below a fifth of its start is held there.

    Unlike :func:`fit_sequence`, which measures the lengths on the joints once, this fits them
    (a body of another template, whose joints sit elsewhere, still fits as well as it can).

    Parameters
    ----------
    body : BodyModel
    joints : array, shape (F, 17, 3)
        NaN rows (unknown joints) are ignored.
    iterations : int
        Gauss-Newton steps over lengths and poses together.
    dims : sequence of str, optional
        Length names to fit; default all of ``body.LENGTH_DIMS``.
    ridge : float
        Weight of the pull towards the starting lengths, per frame (m^2 per m^2).
    prior : float
        Pull of the angles towards their starting values (see :func:`fit_pose`).

    Returns
    -------
    body : BodyModel
        With the fitted lengths (radii unchanged).
    poses : list of Pose
    rms : array, shape (F,)
        Joint RMS per frame, metres.
    """
    Y = np.asarray(joints, float)
    if Y.ndim != 3 or Y.shape[1:] != (17, 3):
        raise ZoopraxisError(f"fit_body: joints must have shape (F, 17, 3), got {Y.shape}")
    names = tuple(LENGTH_DIMS if dims is None else dims)
    d_start = body.dims_vector(names)
    floor = 0.2 * d_start
    known = np.all(np.isfinite(Y), axis=2)                             # (F, 17)
    poses, prev = [], None
    for frame in Y:
        prev, _ = fit_pose(body, frame, prev, prior=prior)
        poses.append(prev)
    Y = np.where(known[..., None], Y, 0.0)
    anchors = [p.angles.copy() for p in poses]
    n, D, F = body.n_dofs, len(names), len(Y)

    def residuals(b, ps):
        return [((b.joints(p) - Y[f]) * known[f, :, None]).ravel() for f, p in enumerate(ps)]

    def cost(b, ps):
        r = residuals(b, ps)
        return sum(x @ x for x in r) + prior * sum(
            np.sum((p.angles - a) ** 2) for p, a in zip(ps, anchors)) + ridge * F * np.sum(
            (b.dims_vector(names) - d_start) ** 2)

    current = cost(body, poses)
    lam = 1e-4
    for _ in range(iterations):
        d = body.dims_vector(names)
        H_dd = ridge * F * np.eye(D)
        g_d = ridge * F * (d - d_start)
        blocks = []
        for f, pose in enumerate(poses):
            w = np.repeat(known[f], 3)[:, None]
            X, Jp = body.joints_jacobian(pose)
            A = Jp.reshape(51, -1) * w
            B = body.joints_dims_jacobian(pose, names).reshape(51, D) * w
            r = ((X - Y[f]) * known[f, :, None]).ravel()
            H_pp = A.T @ A
            H_pp[6:, 6:] += prior * np.eye(n)
            H_pp += lam * np.diag(np.diag(H_pp) + 1e-9)
            g_p = A.T @ r
            g_p[6:] += prior * (pose.angles - anchors[f])
            H_pd = A.T @ B
            solve = np.linalg.solve(H_pp, np.column_stack([H_pd, g_p]))
            H_dd += B.T @ B - H_pd.T @ solve[:, :D]
            g_d += B.T @ r - H_pd.T @ solve[:, D]
            blocks.append(solve)
        step_d = np.linalg.solve(H_dd + lam * np.diag(np.diag(H_dd)), -g_d)
        trial_body = body.with_dims(dict(zip(names, np.maximum(d + step_d, floor))))
        trial_poses = []
        for pose, solve in zip(poses, blocks):
            moved = pose.retract(-(solve[:, D] + solve[:, :D] @ step_d))
            moved.angles = body.clamp(moved.angles)
            trial_poses.append(moved)
        trial = cost(trial_body, trial_poses)
        if trial < current:
            decrease = current - trial
            body, poses, current = trial_body, trial_poses, trial
            lam = max(lam / 3.0, 1e-9)
            if decrease < 1e-10 * max(current, 1e-12):
                break
        else:
            lam *= 10.0
    rms = np.array([np.sqrt(np.sum(r ** 2) / max(3 * known[f].sum(), 1))
                    for f, r in enumerate(residuals(body, poses))])
    return body, poses, rms


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
