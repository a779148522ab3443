"""Limbs must not pass through each other: sphere proxies and a penetration penalty.

Each segment is approximated by a few spheres along its bone, a little inside its shape. For
pairs of segments that cannot touch deeply (an arm and the trunk, the two arms, the two legs),
the penalty residual of two spheres is how far they overlap,
``max(0, r_i + r_j - |c_i - c_j|)``; the differential tracker adds these residuals to its least
squares so that a solution keeps the limbs apart, and the benchmarks report the largest
overlap.
"""

from dataclasses import dataclass

import numpy as np

from ..geometry import se3

# (segment, from point, to point, radius dimension, spheres, radius scale)
_PROXIES = (
    ("pelvis", "pelvis", "lumbar", "pelvis_ry", 2, 0.9),
    ("abdomen", "lumbar", "thorax", "waist_ry", 2, 0.9),
    ("chest", "thorax", "neck", "chest_ry", 3, 0.9),
    ("l_upper_arm", "l_shoulder", "l_elbow", "upper_arm_r", 3, 0.8),
    ("r_upper_arm", "r_shoulder", "r_elbow", "upper_arm_r", 3, 0.8),
    ("l_forearm", "l_elbow", "l_wrist", "forearm_r", 3, 0.8),
    ("r_forearm", "r_elbow", "r_wrist", "forearm_r", 3, 0.8),
    ("l_thigh", "l_hip", "l_knee", "thigh_r", 3, 0.8),
    ("r_thigh", "r_hip", "r_knee", "thigh_r", 3, 0.8),
    ("l_shank", "l_knee", "l_ankle", "shank_r", 3, 0.8),
    ("r_shank", "r_knee", "r_ankle", "shank_r", 3, 0.8),
    ("l_foot", "l_heel", "l_toe", "foot_r", 2, 0.8),
    ("r_foot", "r_heel", "r_toe", "foot_r", 2, 0.8),
)
_TRUNK = ("pelvis", "abdomen", "chest")
_PAIRS = (
    [(f"{s}_{arm}", t) for s in "lr" for arm in ("upper_arm", "forearm") for t in _TRUNK]
    + [(f"l_{a}", f"r_{b}") for a in ("thigh", "shank", "foot") for b in ("thigh", "shank", "foot")]
    + [(f"l_{a}", f"r_{b}") for a in ("upper_arm", "forearm") for b in ("upper_arm", "forearm")]
)


@dataclass
class Proxies:
    """Sphere proxies of a body.

    Attributes
    ----------
    segment : array of int, shape (M,)
    centre : array, shape (M, 3)
        Reference-frame centres.
    radius : array, shape (M,)
    pairs : array of int, shape (K, 2)
        Sphere index pairs that must not overlap.
    """

    segment: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    pairs: np.ndarray


def body_proxies(body):
    """Sphere proxies and the sphere pairs to keep apart, for the segments the body has."""
    has = set(body.segment_names)
    seg, centre, radius, owner = [], [], [], []
    for name, a, b, dim, n, k in _PROXIES:
        if name not in has:
            # templates without an abdomen carry the whole trunk on the pelvis
            if name in ("abdomen", "chest") and "pelvis" in has:
                name = "pelvis"
            else:
                continue
        pa, pb = body.reference_point(a), body.reference_point(b)
        for t in np.linspace(0.15, 0.85, n):
            seg.append(body.segment_index(name))
            centre.append(pa + t * (pb - pa))
            radius.append(k * body.dims[dim])
            owner.append(name)
    owner = np.array(owner)
    pairs = []
    for p, q in _PAIRS:
        ip = np.flatnonzero(owner == p)
        iq = np.flatnonzero(owner == q)
        for i in ip:
            for j in iq:
                pairs.append((i, j))
    # the same trunk spheres may be listed under several names when folded onto the pelvis
    pairs = np.unique(np.array(pairs, dtype=int).reshape(-1, 2), axis=0)
    return Proxies(np.array(seg), np.array(centre), np.array(radius), pairs)


def penetration(proxies, seg2world):
    """Overlap of every pair, metres (0 where apart), shape (K,)."""
    c = se3.apply(seg2world[proxies.segment], proxies.centre)
    i, j = proxies.pairs.T
    d = np.linalg.norm(c[i] - c[j], axis=1)
    return np.maximum(proxies.radius[i] + proxies.radius[j] - d, 0.0)


def penalty_system(proxies, seg2world, seg_jac):
    """Residuals and their Jacobian with respect to a pose increment, for overlapping pairs.

    Returns
    -------
    r : array, shape (k,)
        Overlaps of the pairs that overlap.
    J : array, shape (k, 6 + n_dofs)
        ``d r / d delta`` (a root motion moves both spheres alike and drops out).
    """
    c = se3.apply(seg2world[proxies.segment], proxies.centre)
    i, j = proxies.pairs.T
    diff = c[i] - c[j]
    d = np.linalg.norm(diff, axis=1)
    r = proxies.radius[i] + proxies.radius[j] - d
    active = r > 0
    if not np.any(active):
        return np.zeros(0), np.zeros((0, seg_jac.shape[2]))
    i, j, diff, d, r = i[active], j[active], diff[active], d[active], r[active]
    n = diff / np.maximum(d, 1e-9)[:, None]
    vi = se3.point_velocity_matrix(c[i]) @ seg_jac[proxies.segment[i]]      # (k, 3, P)
    vj = se3.point_velocity_matrix(c[j]) @ seg_jac[proxies.segment[j]]
    J = -np.einsum("ka,kap->kp", n, vi - vj)
    return r, J
