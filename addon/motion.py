"""Segment motion of a tracked take: world transforms of every body segment per frame.

Pure numpy (no bpy), shared by baking and retargeting. A result with joint angles moves the
segments through the body's product of exponentials (``BodyModel.seg2world``); a result with only
3D joints falls back to aiming each segment at its child joint.

Convention: ``seg2world[f, k]`` maps the reference configuration (body standing, +Z up, facing
-Y, subject's left at +X; see :mod:`core.body.body`) to the world at frame ``f``. A bone built in the
reference configuration with rest matrix ``B_k`` is at ``seg2world[f, k] @ B_k`` in the world.
"""

import numpy as np

from ..core.body import body as body_mod
from ..core.errors import ZoopraxisError
from ..core.body.joints import JOINT_INDEX

# Where each segment's bone ends: the first of these reference points the body has.
_TAILS = {
    "pelvis": ("lumbar", "neck"),
    "abdomen": ("thorax",),
    "chest": ("neck",),
    "head": ("head",),
}
_SIDE_TAILS = {"upper_arm": "elbow", "forearm": "wrist", "thigh": "knee", "shank": "ankle",
               "foot": "toe"}


def body_of(result):
    """The fitted body of a result (its template and dimensions), or the default full body."""
    info = result.body or {}
    try:
        body = body_mod.make_body(info.get("template", "full"), info.get("dims"),
                                  shapes=info.get("shapes"))
    except ZoopraxisError as ex:
        raise ZoopraxisError(f"result body: {ex}") from None
    names = info.get("dof_names")
    if result.angles is not None and names is not None and tuple(names) != body.dof_names:
        raise ZoopraxisError(f"result body: its DOF names do not match template "
                             f"'{body.template}' ({len(names)} given, {body.n_dofs} expected)")
    return body


def bone_segments(body):
    """Bone geometry of every segment in the reference configuration.

    Returns
    -------
    bones : list of (name, parent name or None, head (3,), tail (3,))
        In segment order, so parents come first.
    """
    bones = []
    for k, name in enumerate(body.segment_names):
        head = body.reference_point(body.segment_joint[k])
        if name in _TAILS:
            tail_name = next(p for p in _TAILS[name] if _has_point(body, p, name))
        else:
            side, part = name.split("_", 1)
            tail_name = f"{side}_{_SIDE_TAILS[part]}"
        parent = body.segment_parents[k]
        bones.append((name, None if parent < 0 else body.segment_names[parent], head,
                      body.reference_point(tail_name)))
    return bones


def _has_point(body, point, segment):
    # The pelvis bone ends at the lumbar joint only when a spine segment rotates there.
    if segment == "pelvis" and point == "lumbar":
        return "abdomen" in body.segment_names
    return True


def check_angles(result, body):
    F = result.num_frames
    if result.roots is None or result.roots.shape != (F, 4, 4):
        raise ZoopraxisError(f"result: 'roots' must have shape ({F}, 4, 4)")
    if result.angles.shape != (F, body.n_dofs):
        raise ZoopraxisError(f"result: 'angles' has shape {result.angles.shape}, expected "
                             f"({F}, {body.n_dofs}) for template '{body.template}'")


def segment_motion(result, body):
    """World transforms of the segments at every frame of the result.

    Returns
    -------
    seg2world : array, shape (F, S, 4, 4)
    """
    if result.angles is not None:
        check_angles(result, body)
        return body.seg2world(result.roots, result.angles)
    return aimed_motion(result.joints3d, body)


def _rotation_between(a, b):
    """Shortest-arc rotations taking unit vectors ``a`` to ``b``, shape (F, 3, 3)."""
    v = np.cross(a, b)
    c = np.sum(a * b, axis=-1)
    s = np.linalg.norm(v, axis=-1)
    K = np.zeros(a.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        factor = np.where(s > 1e-12, (1 - c) / np.maximum(s * s, 1e-24), 0.5)
    R = np.eye(3) + K + K @ K * factor[..., None, None]
    # Opposite vectors: half a turn about any axis perpendicular to a.
    opposite = (s <= 1e-12) & (c < 0)
    if np.any(opposite):
        axis = np.cross(a[opposite], [1.0, 0.0, 0.0])
        small = np.linalg.norm(axis, axis=-1) < 1e-6
        axis[small] = np.cross(a[opposite][small], [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        R[opposite] = 2 * axis[:, :, None] * axis[:, None, :] - np.eye(3)
    return R


def _frame(x_dir, z_dir):
    """Rotations whose z column is ``z_dir`` and x column the part of ``x_dir`` orthogonal to it.

    ``_frame(z_hint, x)[..., [2, 1, 0]] * [1, -1, 1]`` is the rotation with x column exactly
    ``x`` and z column the part of ``z_hint`` orthogonal to it.
    """
    z = z_dir / np.linalg.norm(z_dir, axis=-1, keepdims=True)
    x = x_dir - np.sum(x_dir * z, axis=-1, keepdims=True) * z
    x /= np.linalg.norm(x, axis=-1, keepdims=True)
    return np.stack([x, np.cross(z, x), z], axis=-1)


def aimed_motion(joints3d, body):
    """Segment transforms aiming each bone at its child joint, for results without angles.

    The pelvis takes its orientation from the hips (subject's left at +X) and the way up to the
    neck; abdomen and chest aim at the neck, turned by the hip and shoulder lines; every other
    segment turns by the shortest arc from where its parent carries it to the direction of its
    child joint, so axial twist is not observed and stays the parent's. Bone lengths are the
    body's, so joints further down the chain sit within the lengths' mismatch of the given ones.

    Parameters
    ----------
    joints3d : array, shape (F, 17, 3)
    body : BodyModel

    Returns
    -------
    seg2world : array, shape (F, S, 4, 4)
    """
    X = np.asarray(joints3d, float)
    if not np.all(np.isfinite(X)):
        frame = int(np.argwhere(~np.isfinite(X))[0, 0])
        raise ZoopraxisError(f"result: joints3d of frame index {frame} are not finite")
    J = {name: X[:, i] for name, i in JOINT_INDEX.items()}
    F = len(X)
    out = np.tile(np.eye(4), (F, body.n_segments, 1, 1))
    hips = J["l_hip"] - J["r_hip"]
    shoulders = J["l_shoulder"] - J["r_shoulder"]
    targets = {b[0]: b for b in bone_segments(body)}
    for k, name in enumerate(body.segment_names):
        _, parent, head, tail = targets[name]
        if parent is None:
            origin = J["pelvis"]
        else:
            P = out[:, body.segment_names.index(parent)]
            origin = P[:, :3, :3] @ head + P[:, :3, 3]
        # Trunk segments stand upright in the reference frame (x to the subject's left, z
        # up): their frames come from the hip and shoulder lines and the way to the neck.
        if name == "pelvis":
            # The hip line is exact, so the thighs start at the hips given.
            R = _frame(J["neck"] - origin, hips)[..., [2, 1, 0]] * [1.0, -1.0, 1.0]
        elif name == "abdomen":
            R = _frame(hips + shoulders, J["neck"] - origin)
        elif name == "chest":
            R = _frame(shoulders, J["neck"] - origin)
        else:
            goal = J[_tail_joint(body, name)] - origin
            goal /= np.linalg.norm(goal, axis=-1, keepdims=True)
            carried = P[:, :3, :3] @ ((tail - head) / np.linalg.norm(tail - head))
            R = _rotation_between(carried, goal) @ P[:, :3, :3]
        out[:, k, :3, :3] = R
        out[:, k, :3, 3] = origin - R @ head
    return out


def _tail_joint(body, segment):
    if segment == "head":
        return "head"
    side, part = segment.split("_", 1)
    return f"{side}_{_SIDE_TAILS[part]}"


def invert(T):
    """Inverse of rigid transforms, shape (..., 4, 4)."""
    out = np.zeros_like(T)
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out
