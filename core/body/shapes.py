"""Segment shapes of the body templates: ellipsoid blobs or tapered cylinders and spheres.

Bregler & Malik approximate body segments by ellipsoidal 3D blobs (§2.2.2); Sidenbladh et al.
use 9 cylinders (the torso with an elliptic cross-section) and 3 spheres (Fig. 1). Both families
are built here from the body dimensions, in the reference frame of :mod:`body` (standing, +Z up,
facing -Y, subject's left at +X), each primitive attached to the segment it moves with.
"""

import numpy as np

from .primitives import Primitives, cylinder, ellipsoid

# Blobs reach a little past the joint centres so neighbouring segments overlap and the
# silhouette has no gaps at the joints.
_OVERLAP = 1.08


def _frame_along(direction, x_hint=(1.0, 0.0, 0.0)):
    """Rotation whose z column is ``direction`` and whose x column is as close to ``x_hint``."""
    z = np.asarray(direction, float)
    z = z / np.linalg.norm(z)
    x = np.asarray(x_hint, float) - np.dot(x_hint, z) * z
    if np.linalg.norm(x) < 1e-9:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def _blob(segment, a, b, rx, ry=None, overlap=_OVERLAP):
    """Ellipsoid spanning points ``a`` to ``b`` with cross-section semi-axes (rx, ry)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    half = 0.5 * np.linalg.norm(b - a) * overlap
    return ellipsoid(segment, (a + b) / 2, (rx, rx if ry is None else ry, half),
                     axes=_frame_along(b - a))


def _tube(segment, a, b, r_base, r_top):
    return cylinder(segment, a, b, r_base, r_top, x_dir=(1.0, 0.0, 0.0))


def body_primitives(body):
    """Primitives of ``body`` for the renderer (see :class:`primitives.Primitives`)."""
    d, p = body.dims, body._points
    seg = body.segment_index
    has = set(body.segment_names)
    blobs = body.shapes == "ellipsoid"
    prims = []

    def limb(segment, a, b, r, taper=0.8):
        if blobs:
            prims.append(_blob(seg(segment), p[a], p[b], r))
        else:
            prims.append(_tube(seg(segment), p[a], p[b], r * 1.1, r * 1.1 * taper))

    # trunk
    below = np.array([0.0, 0.0, -0.1])
    if "abdomen" in has:
        spans = (("pelvis", p["pelvis"] + below, p["lumbar"] + [0, 0, 0.03], "pelvis"),
                 ("abdomen", p["lumbar"], p["thorax"], "waist"),
                 ("chest", p["thorax"], p["neck"], "chest"))
    else:
        spans = (("pelvis", p["pelvis"] + below, p["neck"], "chest"),)
    for segment, a, b, r in spans:
        rx, ry = d[f"{r}_rx"], d[f"{r}_ry"]
        if blobs:
            prims.append(_blob(seg(segment), a, b, rx, ry, overlap=1.0))
        else:
            prims.append(cylinder(seg(segment), a, b, rx, rx, ry_ratio=ry / rx,
                                  x_dir=(1.0, 0.0, 0.0)))

    # neck and head
    if blobs:
        prims.append(_blob(seg("head"), p["neck"], p["head"] - [0, 0, 0.5 * d["head_r"]],
                           d["neck_r"]))
        prims.append(ellipsoid(seg("head"), p["head"],
                               (0.8 * d["head_r"], 0.95 * d["head_r"], 1.15 * d["head_r"])))
    else:
        prims.append(_tube(seg("head"), p["neck"], p["head"] - [0, 0, 0.8 * d["head_r"]],
                           d["neck_r"], d["neck_r"]))
        prims.append(ellipsoid(seg("head"), p["head"], (d["head_r"],) * 3))

    for s in ("l", "r"):
        limb(f"{s}_upper_arm", f"{s}_shoulder", f"{s}_elbow", d["upper_arm_r"])
        limb(f"{s}_forearm", f"{s}_elbow", f"{s}_wrist", d["forearm_r"])
        limb(f"{s}_thigh", f"{s}_hip", f"{s}_knee", d["thigh_r"])
        limb(f"{s}_shank", f"{s}_knee", f"{s}_ankle", d["shank_r"])
        hand_c = p[f"{s}_wrist"] - [0, 0, 0.8 * d["hand_r"]]
        if blobs:
            prims.append(ellipsoid(seg(f"{s}_forearm"), hand_c,
                                   (0.5 * d["hand_r"], d["hand_r"], 1.3 * d["hand_r"])))
        else:
            prims.append(ellipsoid(seg(f"{s}_forearm"), hand_c, (d["hand_r"],) * 3))
        # Templates without feet carry a rigid foot on the shank.
        foot_seg = seg(f"{s}_foot") if f"{s}_foot" in has else seg(f"{s}_shank")
        heel, toe = p[f"{s}_heel"], p[f"{s}_toe"] + [0, -0.3 * d["foot_r"], 0]
        if blobs:
            prims.append(_blob(foot_seg, heel, toe, 1.1 * d["foot_r"], 0.8 * d["foot_r"]))
        else:
            prims.append(_tube(foot_seg, heel, toe, d["foot_r"], 0.8 * d["foot_r"]))
    return Primitives.concat(prims)
