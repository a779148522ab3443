"""A pose prior learned from motion capture: a kernel density of joint angles per body part
(:class:`PosePrior`), its file (``data/pose_prior.npz``, from ``tools/learn_pose_prior.py`` or
``zoopraxis prior``), the joint angles of captured takes (:func:`take_angles`) and the choice of
a prior for a fit (:func:`resolve_pose_prior`). Used by the initialization of frames clicked in
one view to choose each limb's depth sign.
"""

import copy
import zipfile
from pathlib import Path

import numpy as np

from ..body.kinematics import kinematics
from ..errors import ZoopraxisError

DEFAULT_POSE_PRIOR = Path(__file__).resolve().parent / "data" / "pose_prior.npz"

# Body parts of the prior, by DOF name prefix: each part's angles have their own density (the
# capture's few takes cannot say how every arm pose goes with every leg pose). The two legs
# share one: a stride sets one leg before the body and the other behind it, which is what one
# view cannot see. With a density per leg, one view's Procrustes-aligned error of held-out CMU
# frames was 10 mm larger (15 frames); of the body model's random poses, whose legs are
# independent, 1.6 mm smaller to 2.5 mm larger (two seeds of 20 poses).
PRIOR_PARTS = {"the trunk": ("lumbar_", "thorax_", "neck_"),
               "the left arm": ("l_shoulder_", "l_elbow_"),
               "the right arm": ("r_shoulder_", "r_elbow_"),
               "the legs": ("l_hip_", "l_knee_", "l_ankle_", "r_hip_", "r_knee_", "r_ankle_")}
# Kernel width per DOF, as a fraction of the data's spread (about Silverman's rule for a few
# hundred samples in 3-6 dimensions), and at least this many degrees.
PRIOR_BANDWIDTH = 0.5
# Weight of the broad everyday-pose Gaussian mixed into the learned density. The captures
# are a few takes: at 0.2 the fit pulled poses unlike theirs (random everyday poses of the
# body model) towards them, one view's Procrustes-aligned errors of such poses 3-18 mm larger
# (two benchmark seeds, 20 poses a row) for 5 mm less on held-out captured poses.
PRIOR_BROAD_WEIGHT = 0.5
PRIOR_MIN_BANDWIDTH_DEG = 4.0
# Gaussians per body part of the mixture that stands for the density in least squares.
PRIOR_COMPONENTS = 8


def mirror_angles(dof_names, angles):
    """Joint angles of the mirror-image pose (the subject's left and right swapped).

    Left and right DOFs exchange their values (the right side's axes are the left's mirrored,
    so a symmetric pose has equal angles); the trunk's and neck's sideways bend and twist
    change sign.

    Parameters
    ----------
    dof_names : sequence of str
    angles : array, shape (..., n_dofs)
    """
    names = list(dof_names)
    perm = [names.index({"l_": "r_", "r_": "l_"}.get(n[:2], n[:2]) + n[2:])
            if n[:2] in ("l_", "r_") else k for k, n in enumerate(names)]
    out = np.asarray(angles, float)[..., perm].copy()
    flip = [k for k, n in enumerate(names) if n.endswith(("_bend", "_twist"))
            and not n.startswith(("l_", "r_"))]
    out[..., flip] *= -1.0
    return out


class PosePrior:
    """Kernel density of joint angles learned from motion capture, per body part.

    ``-log p(angles) = sum over parts of -log mean_i N(a_part; a_i,part, h^2)`` (up to a
    constant), with Gaussian kernels of width ``h`` per DOF, optionally mixed with a broad
    Gaussian (:meth:`with_broad`). Built by ``tools/learn_pose_prior.py`` from CMU captures.
    Least squares use it as a Gaussian mixture (:meth:`mixture`).

    Parameters
    ----------
    angles : array, shape (N, n_dofs)
        Sample poses (radians), in the order of ``dof_names``.
    dof_names : sequence of str
    template : str
        The body template the angles belong to.
    """

    def __init__(self, angles, dof_names, template="full", takes=None):
        self.samples = np.asarray(angles, float)
        self.dof_names = tuple(str(n) for n in dof_names)
        self.template = str(template)
        self.takes = np.full(len(self.samples), "", dtype=object) if takes is None else \
            np.asarray(takes, dtype=object)
        spread = self.samples.std(axis=0)
        self.bandwidth = np.maximum(PRIOR_BANDWIDTH * spread,
                                    np.radians(PRIOR_MIN_BANDWIDTH_DEG))
        self.parts = {part: np.array([k for k, n in enumerate(self.dof_names)
                                      if n.startswith(prefixes)])
                      for part, prefixes in PRIOR_PARTS.items()}
        self.broad = None
        self._learned = {}      # the samples' mixture per part, shared by with_broad copies
        self._mixture = None

    @classmethod
    def load(cls, path=None, exclude=(), exclude_subjects=()):
        """Read a prior file (``core/priors/data/pose_prior.npz`` by default).

        Parameters
        ----------
        exclude : sequence of str
            Takes to leave out (to evaluate on them).
        exclude_subjects : sequence of str
            Performers to leave out: every take named ``SUBJECT_TRIAL`` of theirs (CMU's
            naming, ``cmu.subject_of``).

        Raises
        ------
        ZoopraxisError
            A missing or malformed file, or nothing left after ``exclude``.
        """
        path = Path(path) if path is not None else DEFAULT_POSE_PRIOR
        try:
            with np.load(path) as data:
                angles, takes = data["angles"], data["takes"].astype(str)
                names, template = data["dof_names"].astype(str), str(data["template"])
        except (OSError, KeyError, ValueError, TypeError, EOFError, zipfile.BadZipFile) as exc:
            raise ZoopraxisError(f"{path}: not a pose prior file ({str(exc)[:80]})") from None
        if not (np.issubdtype(angles.dtype, np.number) and np.all(np.isfinite(angles))):
            raise ZoopraxisError(f"{path}: not a pose prior file (angles are not finite "
                                 "numbers)")
        from ..files.cmu import kept_takes

        keep = kept_takes(takes, exclude, exclude_subjects)
        if not keep.any():
            raise ZoopraxisError(f"{path}: no poses left after leaving out "
                                 f"{', '.join([*exclude, *map(str, exclude_subjects)])}")
        if angles.ndim != 2 or angles.shape != (len(takes), len(names)):
            raise ZoopraxisError(f"{path}: not a pose prior file (angles of shape "
                                 f"{angles.shape} for {len(takes)} poses of {len(names)} DOFs)")
        return cls(angles[keep], names, template, takes[keep])

    def save(self, path):
        """Write the prior's poses to ``path`` (``.npz``), as :meth:`load` reads them."""
        path = Path(path)
        try:
            with open(path, "wb") as stream:
                np.savez_compressed(stream, angles=self.samples.astype(np.float32),
                                    takes=np.array([str(t) for t in self.takes]),
                                    dof_names=np.array(self.dof_names),
                                    template=np.array(self.template))
        except OSError as error:
            raise ZoopraxisError(f"{path}: cannot write ({error.strerror})") from None

    @classmethod
    def from_takes(cls, takes, template="full"):
        """A prior of the poses of captured or tracked takes, and of their mirror images.

        Parameters
        ----------
        takes : dict of str to array, shape (F, n_dofs)
            Joint angles per take (:func:`take_angles`), keyed by the take's name.
        template : str

        Raises
        ------
        ZoopraxisError
            No poses at all.
        """
        kin = kinematics(template)
        names = kin.structure.dof_names
        angles, labels = [], []
        for name, a in takes.items():
            a = np.asarray(a, float).reshape(-1, len(names))
            # A left-right mirrored pose is as natural as the pose (and one view confuses them).
            angles += [a, mirror_angles(names, a)]
            labels += [name] * (2 * len(a))
        if not labels:
            raise ZoopraxisError("no poses to learn a pose prior from")
        return cls(np.concatenate(angles), names, template, labels)

    def with_broad(self, mean, sigma, weight=PRIOR_BROAD_WEIGHT):
        """The same prior mixed with a broad Gaussian of everyday poses (weight ``weight``):
        poses unlike any in the captures fall back on it instead of on their nearest sample.

        Parameters
        ----------
        mean, sigma : array, shape (n_dofs,)
        weight : float
        """
        out = copy.copy(self)
        out.broad = (np.asarray(mean, float), np.asarray(sigma, float), float(weight))
        out._mixture = None
        return out

    def part_costs(self, angles):
        """``-log p`` of each part's angles (nats, up to a constant).

        Parameters
        ----------
        angles : array, shape (B, n_dofs)

        Returns
        -------
        costs : array, shape (B, n_parts)
            In the order of ``PRIOR_PARTS``.
        """
        a = np.atleast_2d(np.asarray(angles, float))
        out = np.empty((len(a), len(self.parts)))
        for i, cols in enumerate(self.parts.values()):
            z = (a[:, None, cols] - self.samples[None, :, cols]) / self.bandwidth[cols]
            q = -0.5 * np.einsum("bnk,bnk->bn", z, z)                       # (B, N)
            top = q.max(axis=1, keepdims=True)
            log_p = top[:, 0] + np.log(np.mean(np.exp(q - top), axis=1)) \
                - np.log(self.bandwidth[cols]).sum()
            if self.broad is not None:
                mean, sigma, weight = self.broad
                zb = (a[:, cols] - mean[cols]) / sigma[cols]
                log_b = -0.5 * np.einsum("bk,bk->b", zb, zb) - np.log(sigma[cols]).sum()
                log_p = np.logaddexp(np.log1p(-weight) + log_p, np.log(weight) + log_b)
            out[:, i] = -log_p
        return out

    def cost(self, angles):
        """``-log p(angles)`` (nats, up to a constant), shape (B,)."""
        return self.part_costs(angles).sum(axis=1)

    def mixture(self):
        """The density as a Gaussian mixture per part, for least squares (cached).

        Each part's samples are summarised by PRIOR_COMPONENTS Gaussians (EM from k-means++
        seeds, deterministic), their covariances at least the kernels' widths; the broad
        Gaussian, if any, is one more component of its weight.

        Returns
        -------
        parts : list of (dofs, means (K, k), whiten (K, k, k), costs (K,))
            ``-log p(a) ~ min_k 0.5 |whiten_k (a - mean_k)|^2 + cost_k`` (nats).
        """
        if self._mixture is not None:
            return self._mixture
        out = []
        for part, cols in self.parts.items():
            if part not in self._learned:
                self._learned[part] = _fit_mixture(self.samples[:, cols], PRIOR_COMPONENTS,
                                                   self.bandwidth[cols] ** 2)
            weights, means, covs = self._learned[part]
            if self.broad is not None:
                mean, sigma, w = self.broad
                weights = np.append((1.0 - w) * weights, w)
                means = np.vstack([means, mean[cols]])
                covs = np.concatenate([covs, np.diag(sigma[cols] ** 2)[None]])
            whiten = np.linalg.cholesky(np.linalg.inv(covs)).swapaxes(-1, -2)  # W^T W = C^-1
            costs = -np.log(weights) + 0.5 * np.linalg.slogdet(covs)[1]
            out.append((cols, means, whiten, costs))
        self._mixture = out
        return out


def _fit_mixture(x, n_components, floor_var, iterations=60):
    """Gaussian mixture of the rows of ``x`` (N, k) by EM from k-means++ seeds (fixed seed),
    each covariance at least ``diag(floor_var)``. Returns weights (K,), means (K, k), covs
    (K, k, k)."""
    rng = np.random.default_rng(0)
    N, k = x.shape
    K = min(n_components, N)
    means = [x[rng.integers(N)]]
    for _ in range(1, K):
        d2 = np.min(((x[:, None] - np.array(means)[None]) ** 2 / floor_var).sum(-1), axis=1)
        means.append(x[rng.choice(N, p=d2 / d2.sum())] if d2.sum() > 0 else x[rng.integers(N)])
    means = np.array(means)
    spread = np.cov(x.T).reshape(k, k) if N > 1 else np.zeros((k, k))
    covs = np.broadcast_to(spread / K + np.diag(floor_var), (K, k, k)).copy()
    weights = np.full(K, 1.0 / K)
    for _ in range(iterations):
        d = x[:, None] - means[None]                                          # (N, K, k)
        inv = np.linalg.inv(covs)
        log_r = -0.5 * np.einsum("nki,kij,nkj->nk", d, inv, d) \
            - 0.5 * np.linalg.slogdet(covs)[1] + np.log(weights)
        log_r -= log_r.max(axis=1, keepdims=True)
        r = np.exp(log_r)
        r /= r.sum(axis=1, keepdims=True)
        n = r.sum(axis=0) + 1e-9                                              # (K,)
        weights = n / N
        means = (r.T @ x) / n[:, None]
        d = x[:, None] - means[None]
        covs = np.einsum("nk,nki,nkj->kij", r, d, d) / n[:, None, None] + np.diag(floor_var)
    return weights, means, covs


# A frame of a take whose fitted joints miss the take's by more than this (RMS, metres) is
# fitted again from the rest pose; one that still misses by TAKE_DROP_M is left out of a prior.
TAKE_REFIT_M = 0.015
TAKE_DROP_M = 0.03


def take_angles(joints3d, template="full", step=1):
    """Joint angles of a take's 3D joints, for :meth:`PosePrior.from_takes`: the template's
    lengths measured on the joints, then each frame's pose fitted (``fit3d.fit_sequence``,
    each frame from the one before). A frame that fit misses (a jump between frames far apart,
    or poses gathered from anywhere) is fitted again from the rest pose, and left out if that
    misses too (TAKE_REFIT_M, TAKE_DROP_M).

    Parameters
    ----------
    joints3d : array, shape (F, 17, 3)
        World metres; frames with a missing joint (NaN) are left out.
    step : int
        Every ``step``-th frame.

    Returns
    -------
    angles : array, shape (F', n_dofs)
    rms : array, shape (F',)
        Each fitted frame's joint RMS error, metres.
    """
    from ..body.fit3d import fit_pose, fit_sequence

    X = np.asarray(joints3d, float)[::max(1, int(step))]
    X = X[np.isfinite(X).all(axis=(1, 2))]
    if not len(X):
        return np.zeros((0, kinematics(template).n_dofs)), np.zeros(0)
    body, poses, rms = fit_sequence(X, template)
    angles = np.array([p.angles for p in poses])
    for f in np.flatnonzero(rms > TAKE_REFIT_M):
        pose, e = fit_pose(body, X[f], prior=1e-3)
        if e < rms[f]:
            angles[f], rms[f] = pose.angles, e
    keep = rms <= TAKE_DROP_M
    return angles[keep], rms[keep]


_POSE_PRIORS = {}


def default_pose_prior(template):
    """The shipped prior for a template, or None (no file, or learned on another template)."""
    if template not in _POSE_PRIORS:
        prior = None
        if DEFAULT_POSE_PRIOR.is_file():
            prior = PosePrior.load()
            if prior.template != template:
                prior = None
        _POSE_PRIORS[template] = prior
    return _POSE_PRIORS[template]


def resolve_pose_prior(pose_prior, template):
    """``initialize``'s ``pose_prior`` as a PosePrior or None: ``"default"`` is the shipped
    prior of the template (None if there is none), a path is read from its file.

    Raises
    ------
    ZoopraxisError
        An unreadable file, or a prior learned on another template (naming the file).
    """
    if isinstance(pose_prior, str) and pose_prior == "default":
        return default_pose_prior(template)
    where = ""
    if isinstance(pose_prior, (str, Path)):
        path = Path(pose_prior)
        if not path.is_file():
            raise ZoopraxisError(f"{path}: no such pose prior file")
        where = f"{path}: "
        pose_prior = _load_prior_file(path)
    if pose_prior is not None and (pose_prior.template != template or tuple(
            pose_prior.dof_names) != tuple(kinematics(template).structure.dof_names)):
        raise ZoopraxisError(f"{where}the pose prior was learned on the "
                             f"'{pose_prior.template}' body, not on '{template}'")
    return pose_prior


_PRIOR_FILES = {}


def _load_prior_file(path):
    """A prior file's PosePrior, read once per file version (re-initializations of a track
    share it, and its mixture)."""
    stat = path.stat()
    key = (str(path.resolve()), stat.st_mtime_ns, stat.st_size)
    if key not in _PRIOR_FILES:
        _PRIOR_FILES.clear()
        _PRIOR_FILES[key] = PosePrior.load(path)
    return _PRIOR_FILES[key]
