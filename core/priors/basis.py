"""A learned low-dimensional basis of 3D joint sets (shape and pose together) and its fit to the
2D joints of one scaled orthographic view, in the spirit of Ramakrishna, Kanade and Sheikh
(2012): the captured performers' standard joints, each centred on the pelvis, turned to a
canonical heading (the hips' line along x, z up) and scaled by the performer's size, with their
left-right mirror images, summarised by a mean and the leading principal components with their
variances (:class:`PoseBasis`). Its file (``data/pose_basis.npz``, from
``tools/learn_pose_basis.py``) keeps the canonical joint sets of every take, so that a
benchmark can leave performers out at load time, as the pose prior does.

:meth:`PoseBasis.fit_view` finds the joint sets that best explain one view's clicks: heading
and tilt, image scale and shift and the basis coefficients, under a Gaussian prior on the
coefficients, by alternating least squares from several headings (one view's depth-sign
ambiguity shows as different local minima). The 3D joints so found carry the bones' proportions
and each limb's depth sign at once.
"""

import copy
import zipfile
from pathlib import Path

import numpy as np

from ..body.joints import JOINT_INDEX, STANDARD_JOINTS
from ..errors import ZoopraxisError

DEFAULT_POSE_BASIS = Path(__file__).resolve().parent / "data" / "pose_basis.npz"

# Principal components kept.
BASIS_COMPONENTS = 40
# Bones whose lengths, summed and taken at their median over a take, give a performer's size
# (the unit of the canonical joint sets).
SIZE_BONES = (("pelvis", "neck"), ("l_hip", "l_knee"), ("r_hip", "r_knee"),
              ("l_knee", "l_ankle"), ("r_knee", "r_ankle"))
# The heading starts of a fit, every this many degrees, at each of these tilts (degrees, the
# camera looking down at the body).
FIT_HEADING_STEP_DEG = 30.0
FIT_TILTS_DEG = (0.0,)
FIT_ITERATIONS = 40
# Least spread (canonical units, about 11 mm of a body's) of a joint about the kept components
# in :meth:`PoseBasis.cost`: the joints the basis pins (the pelvis, the hips' line) are not
# exact in a body of other build.
COST_FLOOR = 0.005
# Weight of the basis against the broad Gaussian of :meth:`PoseBasis.with_broad` (as the pose
# prior's against its everyday Gaussian, pose.PRIOR_BROAD_WEIGHT).
BROAD_WEIGHT = 0.5
# Everyday joint sets drawn for the broad Gaussian (:func:`everyday_joint_sets`).
EVERYDAY_SETS = 4000
_PAIRS = [(JOINT_INDEX[n], JOINT_INDEX["r" + n[1:]]) for n in STANDARD_JOINTS
          if n.startswith("l_")]


def _mirror_perm():
    perm = np.arange(len(STANDARD_JOINTS))
    for a, b in _PAIRS:
        perm[a], perm[b] = b, a
    return perm


MIRROR = _mirror_perm()


def canonical_joints(joints):
    """Joint sets centred on the pelvis and turned about the vertical (z) so that the line
    from the right hip to the left hip points along +x. Shape (F, 17, 3) in and out."""
    X = np.asarray(joints, float)
    X = X - X[:, JOINT_INDEX["pelvis"]][:, None]
    across = X[:, JOINT_INDEX["l_hip"]] - X[:, JOINT_INDEX["r_hip"]]
    yaw = np.arctan2(across[:, 1], across[:, 0])
    c, s = np.cos(-yaw), np.sin(-yaw)
    R = np.zeros((len(X), 3, 3))
    R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
    return X @ np.swapaxes(R, 1, 2)


def _unit_vectors(joints):
    """Joint sets (B, 17, 3) canonical (:func:`canonical_joints`) and scaled to unit size
    (their own SIZE_BONES), flattened to (B, 51)."""
    X = np.asarray(joints, float).reshape(-1, len(STANDARD_JOINTS), 3)
    a = [JOINT_INDEX[p] for p, _ in SIZE_BONES]
    b = [JOINT_INDEX[q] for _, q in SIZE_BONES]
    size = np.linalg.norm(X[:, a] - X[:, b], axis=-1).sum(axis=1)
    return (canonical_joints(X) / size[:, None, None]).reshape(len(X), -1)


def body_size(joints):
    """A performer's size from a take's joints (F, 17, 3): the median over frames of the summed
    lengths of SIZE_BONES."""
    X = np.asarray(joints, float)
    a = [JOINT_INDEX[p] for p, _ in SIZE_BONES]
    b = [JOINT_INDEX[q] for _, q in SIZE_BONES]
    return float(np.median(np.linalg.norm(X[:, a] - X[:, b], axis=-1).sum(axis=1)))


def mirror_joints(Y):
    """The left-right mirror image of canonical joint sets (x negated, sides exchanged)."""
    out = np.asarray(Y, float)[..., MIRROR, :].copy()
    out[..., 0] *= -1.0
    return out


class PoseBasis:
    """Mean and principal components of canonical 3D joint sets (see the module's text).

    Parameters
    ----------
    joints : array, shape (N, 17, 3)
        Canonical joint sets (:func:`canonical_joints`, in units of the performer's size);
        their mirror images are added.
    takes : array of str, shape (N,), optional
    components : int
    """

    def __init__(self, joints, takes=None, components=BASIS_COMPONENTS):
        Y = np.asarray(joints, float)
        self.joints = Y
        self.takes = np.full(len(Y), "", dtype=object) if takes is None else \
            np.asarray(takes, dtype=object)
        data = np.concatenate([Y, mirror_joints(Y)]).reshape(2 * len(Y), -1)
        self.mean = data.mean(axis=0)
        _, S, Vt = np.linalg.svd(data - self.mean, full_matrices=False)
        K = min(int(components), len(Vt))
        var = S ** 2 / max(len(data) - 1, 1)
        self.components = Vt[:K]                                   # (K, 51)
        self.variances = var[:K]
        # what the kept components miss, per joint (variance, canonical units squared)
        rest = (Vt[K:] ** 2 * var[K:, None]).sum(axis=0).reshape(-1, 3)
        self.residual = rest.sum(axis=1) / 3.0                      # (17,)

    @classmethod
    def load(cls, path=None, exclude=(), exclude_subjects=(), components=BASIS_COMPONENTS):
        """Read a basis file (``core/priors/data/pose_basis.npz`` by default), leaving out
        takes (``exclude``) or performers (``exclude_subjects``, CMU's ``SUBJECT``).

        Raises
        ------
        ZoopraxisError
            A missing or malformed file, or nothing left.
        """
        path = Path(path) if path is not None else DEFAULT_POSE_BASIS
        try:
            with np.load(path) as data:
                joints, takes = data["joints"].astype(float), data["takes"].astype(str)
        except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise ZoopraxisError(f"{path}: not a pose basis file ({str(exc)[:80]})") from None
        if joints.ndim != 3 or joints.shape[1:] != (len(STANDARD_JOINTS), 3) or \
                len(joints) != len(takes) or not np.all(np.isfinite(joints)):
            raise ZoopraxisError(f"{path}: not a pose basis file (joints of shape "
                                 f"{joints.shape} for {len(takes)} takes)")
        from ..files.cmu import kept_takes

        keep = kept_takes(takes, exclude, exclude_subjects)
        if not keep.any():
            raise ZoopraxisError(f"{path}: no joint sets left after leaving out "
                                 f"{', '.join([*exclude, *map(str, exclude_subjects)])}")
        return cls(joints[keep], takes[keep], components)

    def save(self, path):
        """Write the canonical joint sets (float16) and their takes to ``path`` (``.npz``)."""
        try:
            with open(path, "wb") as stream:
                np.savez_compressed(stream, joints=self.joints.astype(np.float16),
                                    takes=np.array([str(t) for t in self.takes]))
        except OSError as error:
            raise ZoopraxisError(f"{path}: cannot write ({error.strerror})") from None

    @classmethod
    def from_takes(cls, takes, components=BASIS_COMPONENTS):
        """A basis of takes' joints: dict of take name to (F, 17, 3) world joints (Z up)."""
        joints, labels = [], []
        for name, X in takes.items():
            X = np.asarray(X, float)
            X = X[np.isfinite(X).all(axis=(1, 2))]
            if not len(X):
                continue
            joints.append(canonical_joints(X) / body_size(X))
            labels += [name] * len(X)
        if not labels:
            raise ZoopraxisError("no joint sets to learn a pose basis from")
        return cls(np.concatenate(joints), labels, components)

    broad = None        # (mean, precision, half log-determinant, weight): see with_broad

    def cost(self, joints):
        """``-log p`` (nats, up to a constant) of joint sets (B, 17, 3), any heading, position
        and size: each turned to the canonical heading, scaled to unit size (its own
        SIZE_BONES) and judged by the Gaussian of the kept components and of the residual,
        mixed with the broad Gaussian of :meth:`with_broad` if there is one."""
        unit = _unit_vectors(joints)
        d = unit - self.mean
        c = d @ self.components.T
        rest = (d - c @ self.components).reshape(len(d), -1, 3)
        own = 0.5 * (c ** 2 / self.variances).sum(1) + \
            0.5 * ((rest ** 2).sum(-1) / np.maximum(self.residual, COST_FLOOR ** 2)).sum(1)
        if self.broad is None or self.broad[3] >= 1.0:
            return own
        mean, precision, half_logdet, weight = self.broad
        e = unit - mean
        other = 0.5 * np.einsum("bi,ij,bj->b", e, precision, e)
        # both normalised (the constant 51/2 log 2 pi is common), then shifted so that a set
        # far from the broad Gaussian costs what the basis alone says (plus -log weight)
        return -np.logaddexp(np.log(weight) - own - self._half_logdet,
                             np.log1p(-weight) - other - half_logdet) - self._half_logdet

    @property
    def _half_logdet(self):
        """Half the log-determinant of the covariance whose Gaussian :meth:`cost` is: the
        components' variances in their span, each joint's residual across it."""
        if "_hld" not in self.__dict__:
            V = self.components
            rest = np.repeat(np.maximum(self.residual, COST_FLOOR ** 2), 3)
            across = np.eye(V.shape[1]) - V.T @ V
            precision = V.T @ (V / self.variances[:, None]) + across @ (across / rest[:, None])
            self._hld = -0.5 * float(np.linalg.slogdet(precision)[1])
        return self._hld

    def with_broad(self, joints, weight=BROAD_WEIGHT):
        """The same basis whose density is mixed with a broad Gaussian of other joint sets
        (``joints``, shape (N, 17, 3), any heading and size; their mirror images are added),
        weight ``1 - weight`` against the basis' ``weight``. Both are normalised, so a pose
        unlike the captures' but like those joint sets falls back on the broad one, while
        among poses like the captures' the basis decides.

        The initialization mixes in the body's everyday poses (:func:`everyday_joint_sets`):
        one view of the body model's random everyday poses (independent angles within
        everyday spreads, unlike captured poses) is otherwise turned towards the captures'
        depths (benchmarks/README.md, "The pose basis with the everyday poses beside it").
        """
        if not 0.0 < weight <= 1.0:
            raise ZoopraxisError(f"pose basis: the weight of the basis against the broad "
                                 f"Gaussian must be in (0, 1], not {weight}")
        Y = canonical_joints(np.asarray(joints, float))
        data = _unit_vectors(np.concatenate([Y, mirror_joints(Y)]))
        mean = data.mean(axis=0)
        cov = np.cov(data.T) + COST_FLOOR ** 2 * np.eye(data.shape[1])
        out = copy.copy(self)
        out.broad = (mean, np.linalg.inv(cov), 0.5 * float(np.linalg.slogdet(cov)[1]),
                     float(weight))
        return out

    def shapes(self, coefficients):
        """Canonical joint sets of coefficients (..., K): shape (..., 17, 3)."""
        c = np.asarray(coefficients, float)
        return (self.mean + c @ self.components).reshape(c.shape[:-1] + (-1, 3))

    def fit_view(self, uv, noise_px=2.0, headings_deg=None, tilts_deg=FIT_TILTS_DEG,
                 iterations=FIT_ITERATIONS):
        """Joint sets of the basis that explain one view's clicks, best first.

        The model: ``uv_j = s * P R (mean_j + B_j c) + t`` with ``R`` a rotation, ``P`` the
        first two rows, ``s`` pixels per canonical unit, ``t`` the image shift and ``c ~
        N(0, variances)``. Each joint's click has the noise ``noise_px`` and the basis' own
        error at it (``residual``, in pixels at scale ``s``). From every start (heading x tilt,
        the image's up taken from the clicks) it alternates the linear solve of ``(s, s c, t)``
        given ``R`` with the rotation nearest to the best affine camera of the shape.

        Parameters
        ----------
        uv : array, shape (17, 2)
            NaN where not clicked (pixels, image y down).

        Returns
        -------
        fits : list of dict
            One per distinct local minimum, by ``cost`` (nats: clicks and coefficients):
            ``joints`` (17, 3) canonical joints of the fit (basis units), ``camera`` (3, 3)
            rotation from canonical to camera axes (x right, y down, z away), ``scale``,
            ``shift``, ``coefficients``, ``cost``.
        """
        uv = np.asarray(uv, float)
        seen = np.isfinite(uv).all(axis=-1)
        if seen.sum() < 4:
            return []
        steps = np.arange(0.0, 360.0, FIT_HEADING_STEP_DEG) if headings_deg is None \
            else np.asarray(headings_deg, float)
        yaw, tilt = [a.ravel() for a in np.meshgrid(np.radians(steps),
                                                    np.radians(np.asarray(tilts_deg, float)))]
        R = _start_rotations(uv, yaw, tilt)                               # (S, 3, 3)
        K = len(self.variances)
        B = self.components.reshape(K, -1, 3)[:, seen]                    # (K, m, 3)
        mu = self.mean.reshape(-1, 3)[seen]
        target = uv[seen]
        m = len(target)
        res = self.residual[seen]
        # starting scale: the clicks' spread over the mean shape's
        spread = np.sqrt(((target - target.mean(0)) ** 2).sum() / max(((mu - mu.mean(0)) ** 2)
                                                                      .sum() * 2 / 3, 1e-9))
        s = np.full(len(R), spread)
        S = len(R)
        for _ in range(iterations):
            w = 1.0 / (noise_px ** 2 + s[:, None] ** 2 * res[None])       # (S, m)
            P = R[:, :2]                                                   # (S, 2, 3)
            # design of the linear unknowns (a = s, b = s c, t): (S, m, 2, K + 3)
            A = np.empty((S, m, 2, K + 3))
            A[..., 0] = np.einsum("sij,mj->smi", P, mu)
            A[..., 1:K + 1] = np.einsum("sij,kmj->smik", P, B)
            A[..., K + 1:] = np.eye(2)
            Aw = A * w[:, :, None, None]
            H = np.einsum("smia,smib->sab", Aw, A)
            g = np.einsum("smia,mi->sa", Aw, target)
            H[:, np.arange(1, K + 1), np.arange(1, K + 1)] += \
                1.0 / (s[:, None] ** 2 * self.variances[None])
            x = np.linalg.solve(H, g[..., None])[..., 0]
            s = np.maximum(x[:, 0], 1e-6)
            c = x[:, 1:K + 1] / s[:, None]
            t = x[:, K + 1:]
            Y = mu[None] + np.einsum("sk,kmj->smj", c, B)                  # (S, m, 3)
            # rotation: the best affine camera of the shape, made a scaled rotation
            Yc = Y - np.einsum("sm,smj->sj", w, Y)[:, None] / w.sum(1)[:, None, None]
            Tc = target[None] - np.einsum("sm,mi->si", w, target)[:, None] / \
                w.sum(1)[:, None, None]
            G = np.einsum("sm,smj,smk->sjk", w, Yc, Yc) + 1e-9 * np.eye(3)
            C = np.einsum("sm,smj,smi->sji", w, Yc, Tc)                    # (S, 3, 2)
            M = np.swapaxes(np.linalg.solve(G, C), 1, 2)                   # (S, 2, 3)
            U, _, Vt = np.linalg.svd(M, full_matrices=False)
            rows = U @ Vt
            R = np.concatenate([rows, np.cross(rows[:, 0], rows[:, 1])[:, None]], axis=1)
        # final cost
        w = 1.0 / (noise_px ** 2 + s[:, None] ** 2 * res[None])
        proj = s[:, None, None] * np.einsum("sij,smj->smi", R[:, :2], Y) + t[:, None]
        clicks = 0.5 * (w * ((proj - target) ** 2).sum(-1)).sum(1) - np.log(w).sum(1)
        prior = 0.5 * (c ** 2 / self.variances).sum(1)
        cost = clicks + prior
        order = np.argsort(cost)
        fits = []
        full = self.shapes(c)
        for i in order:
            if any(np.abs(full[i] - f["joints"]).max() < 0.02 for f in fits):
                continue
            fits.append(dict(joints=full[i], camera=R[i], scale=float(s[i]), shift=t[i],
                             coefficients=c[i], cost=float(cost[i])))
        return fits


# Canonical body axes to camera axes for a body seen from the front, upright: camera x = body
# +x, camera y (down) = body -z, camera z (away) = body +y.
_FRONT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def _start_rotations(uv, yaw, tilt):
    """Rotations (S, 3, 3) from canonical joints to the camera: the body turned by ``yaw``
    about its vertical, the camera looking down by ``tilt``, the image rolled so that the body's
    up is the clicks' up (pelvis to neck)."""
    up = uv[JOINT_INDEX["neck"]] - uv[JOINT_INDEX["pelvis"]]
    roll = 0.0 if not np.isfinite(up).all() else np.arctan2(up[1], up[0]) + np.pi / 2
    cr, sr = np.cos(roll), np.sin(roll)
    R_roll = np.array([[cr, -sr, 0.0], [sr, cr, 0.0], [0.0, 0.0, 1.0]])
    S = len(yaw)
    Rz = np.zeros((S, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1] = np.cos(yaw), -np.sin(yaw), \
        np.sin(yaw), np.cos(yaw)
    Rz[:, 2, 2] = 1.0
    Rx = np.zeros((S, 3, 3))
    Rx[:, 0, 0] = 1.0
    Rx[:, 1, 1], Rx[:, 1, 2], Rx[:, 2, 1], Rx[:, 2, 2] = np.cos(tilt), -np.sin(tilt), \
        np.sin(tilt), np.cos(tilt)
    return R_roll @ Rx @ _FRONT @ Rz


_BASES = {}
_EVERYDAY = {}


def everyday_joint_sets(kin, n=EVERYDAY_SETS, seed=0, spread=0.05):
    """Joint sets (n, 17, 3) of the body's everyday poses: angles drawn from the kinematics'
    everyday Gaussian (``kin.prior_mean``, ``kin.prior_sigma``, within the joints' limits, the
    pose prior's broad Gaussian) on lengths spread by ``spread`` (relative, Gaussian) about the
    template's. The same sets for the same template every time (``seed``)."""
    key = (kin.template, int(n), int(seed), float(spread))
    if key not in _EVERYDAY:
        rng = np.random.default_rng(seed)
        groups = 20
        per = -(-int(n) // groups)
        out = []
        for _ in range(groups):
            dims = kin.default_dims * (1.0 + spread * rng.normal(size=len(kin.default_dims)))
            angles = np.clip(kin.prior_mean + kin.prior_sigma *
                             rng.normal(size=(per, kin.n_dofs)), kin.lower, kin.upper)
            out.append(kin.forward(angles, dims)[0])
        _EVERYDAY[key] = np.concatenate(out)[:int(n)]
    return _EVERYDAY[key]


def default_pose_basis():
    """The shipped basis, or None if there is no file."""
    if "default" not in _BASES:
        _BASES["default"] = PoseBasis.load() if DEFAULT_POSE_BASIS.is_file() else None
    return _BASES["default"]


def resolve_pose_basis(pose_basis):
    """``initialize``'s ``pose_basis`` as a PoseBasis or None: ``"default"`` is the shipped
    basis (None if there is none), a path is read from its file."""
    if isinstance(pose_basis, str) and pose_basis == "default":
        return default_pose_basis()
    if isinstance(pose_basis, (str, Path)):
        return PoseBasis.load(pose_basis)
    return pose_basis
