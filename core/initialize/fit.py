"""Initialization from clicked joints (Bregler & Malik §2.6) and model fine-tuning (§2.7).

The animator clicks the 2D joints of one or more anchor frames in one or more views. This module
finds the body pose of each anchor frame, the joint angles and the body dimensions that put the
model's 17 standard joints where the clicks are: "minimizing the sum of squared differences
between the projected model joint locations and the user supplied model joint locations ... over
the poses, angles, and body dimensions" (§2.6). Left and right dimensions are one number each
(the body model ties them by construction), the angles are shared by all views of a frame, and
the dimensions by all anchors.

Two modes, as in the papers:

- calibrated (Yamamoto et al.; Sidenbladh et al.): perspective cameras known; one world pose
  (root) per anchor frame;
- uncalibrated (Bregler & Malik §2.3): one scaled orthographic camera per view and anchor frame
  ("the pose can be different" per view), the body root fixed at the identity, so the 3D result
  lives in a body-centred frame.

The problem is tri-linear (§2.6) and has mirror ambiguities, so it is solved from good starting
points (calibrated: triangulated joints, the trunk placed by Kabsch, inverse kinematics with
several starts per limb; uncalibrated: the body turned every 45 degrees, affine cameras for
the other views) by ``scipy.optimize.least_squares`` with analytic Jacobians, a robust loss on
the clicks, bounds for the joint limits and the dimensions, and priors of everyday angles and
of the template's proportions (what the clicks cannot see, e.g. the split of a bend between the
two spine joints, takes its likely value). In a frame clicked in one view, every limb is also
tried mirrored in depth, and the depth signs of the limbs' parts are chosen by the clicks
together with a pose prior learned from motion capture (:class:`PosePrior`, a kernel density
of joint angles per limb, ``core/priors/data/pose_prior.npz`` from ``tools/learn_pose_prior.py``).
The same prior, as a Gaussian mixture per limb (:meth:`PosePrior.mixture`), replaces the
everyday-angle prior in the least-squares fit of such a frame, so that it also sets the depth
of limbs nearly in the image plane, which the clicks leave almost free.
Clicks that look swapped left for right and outlying clicks are named in warnings and not
absorbed; a mirrored pose that fits (and is as likely) about as well is reported, with the
parts it moves (``InitResult.ambiguous_parts``). The animator, who sees the footage, may then
name limbs to turn to their other depth (``flips``; ``--flip`` on the command line, toggles in
the add-on's panel): each is fitted again from its reflected configurations.

:func:`refine_dims` is the joint-based form of model fine-tuning (§2.7): the same joint
problem over many frames with 2D joint observations; it is solved by blocks (Schur complement
on the shared dimensions, as in bundle adjustment). Fine-tuning on the images of a tracked take
(silhouettes and clicks) is ``finetune.py``.

Convention: world Z up, metres; OpenCV cameras and pixels (``X_c = R @ X_w + t``). Body
dimensions are the body model's ``LENGTH_DIMS`` (metres). Rotations in the parameter vectors
are increments ``exp(w) @ R_start`` on the left (spatial), like ``Pose.retract``.
"""

import copy
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from ..geometry import se3
from ..body.body import (DEFAULT_DIMS, DIM_NAMES, LENGTH_DIMS, RADIUS_DIMS, Pose, make_body,
                   reference_points)
from ..geometry.ortho import ScaledOrthoCamera
from ..errors import ZoopraxisError
from ..body.joints import JOINT_INDEX, STANDARD_JOINTS

N_JOINTS = len(STANDARD_JOINTS)

# Clicks are a few pixels off; beyond this the robust loss (soft L1) grows linearly, so one bad
# click pulls with a bounded force.
LOSS_SCALE_PX = 3.0

# Body dimensions stay inside these multiples of the template's defaults (adults and teenagers).
DIMS_RANGE = (0.6, 1.5)

# Priors, as in a maximum a posteriori fit: a quantity one prior spread away from its mean
# costs as much as one typical click error. What the clicks see well is not biased; what they
# cannot see (the split of a bend between the two spine joints, an arm's roll while the elbow
# is straight, the depth sign of a bone in a single view) takes the likelier value.
CLICK_SIGMA_PX = 2.0
# Mean and spread (degrees) of joint angles in everyday poses (standing, walking, reaching),
# by DOF name without the side prefix. DOFs not listed: mean 0, spread 30.
ANGLE_PRIOR_DEG = {
    "lumbar_flex": (0, 10), "lumbar_bend": (0, 8), "lumbar_twist": (0, 10),
    "thorax_flex": (0, 10), "thorax_bend": (0, 8), "thorax_twist": (0, 10),
    "neck_flex": (0, 20), "neck_bend": (0, 10), "neck_twist": (0, 25),
    "shoulder_flex": (0, 40), "shoulder_abd": (10, 25), "shoulder_rot": (0, 30),
    "elbow_flex": (30, 40), "elbow_abd": (0, 5), "elbow_rot": (0, 30),
    "hip_flex": (10, 30), "hip_abd": (0, 12), "hip_rot": (0, 12),
    "knee_flex": (20, 35), "knee_abd": (0, 4), "knee_rot": (0, 10),
    "ankle_flex": (0, 15), "ankle_inv": (0, 8),
}
# Spread of each length about the template's proportions, and of the overall body size about
# the template's: weakly held in calibrated views (one view cannot tell size from distance),
# fixed in scaled orthographic views (the camera scale absorbs it).
DIMS_PRIOR_SIGMA = 0.05
# ... but at least this many metres: the short lengths (the shoulders' drop below the neck, the
# ankle's height, the hips' width) are set by where joints get clicked more than by bone, and
# 5 % of them (2.5-9 mm) held CMU's skeletons (shoulder drop 30-60 % of the template's) so
# tight that one view leaned the trunk in depth to meet the clicks. With this floor
# (benchmarks/bench_initialize.py) held-out CMU frames went from 46.3 to 44.3 mm in one view
# (Procrustes-aligned) and from 12.9 to 12.0 mm in three calibrated views; the body model's
# one-view rows moved by -1.7, +1.9 and +1.3 mm, its calibrated ones by 0.1. At 3 cm the body
# model's one view was 2.5 mm worse (two seeds of 20 poses).
DIMS_PRIOR_FLOOR_M = 0.015
SIZE_PRIOR_SIGMA = {True: 0.12, False: 0.002}
# In 3D inverse kinematics (starting points only) a prior spread costs this many metres.
IK_PRIOR_M = 0.01

# What a fit of the lengths to frames each clicked in one view adds to the result's notes. One
# view sees a length only through its bone's foreshortening, and a limb's depth hangs on it.
# Held-out CMU frames in one view, 1080p from afar, 2 px clicks (benchmarks/bench_initialize.py):
# 51 mm off (Procrustes-aligned) with the lengths fitted to the clicks, 35 mm with the
# performer's lengths from a three-view init kept. On 18 such frames: 60 mm fitted; 50 mm with
# the lengths' prior centred on each performer's own proportions (lengths then within 5 %);
# kept, the true lengths give 37 mm, with 1 % random error 39 mm, with 2 % 43 mm.
ONE_VIEW_LENGTHS_NOTE = (
    "the body lengths were fitted to frames each clicked in one view, which shows them poorly, "
    "and the depth of the limbs depends on them: if this performer was clicked in several "
    "views in another shot, keep the lengths fitted there (--dims-from, or Body Lengths From "
    "in the add-on)")

# Pairs whose clicks may be exchanged by mistake (subject's left and right).
LR_PAIRS = tuple((f"l_{j}", f"r_{j}") for j in
                 ("shoulder", "elbow", "wrist", "hip", "knee", "ankle", "toe"))

# Limb parts whose depth can flip in one view: (pivot joint, joints beyond it).
LIMB_FLIPS = tuple((f"{s}_{a}", tuple(f"{s}_{j}" for j in rest)) for s in ("l", "r")
                   for a, *rest in (("shoulder", "elbow", "wrist"), ("elbow", "wrist"),
                                    ("hip", "knee", "ankle", "toe"), ("knee", "ankle", "toe")))

# Limbs whose two parts can each flip in depth: (pivot, middle joint, joints beyond the pivot,
# joints beyond the middle, DOF name prefixes of the limb).
_FLIP_LIMBS = tuple(
    (f"{s}_{a}", f"{s}_{b}", tuple(f"{s}_{j}" for j in (b,) + rest),
     tuple(f"{s}_{j}" for j in rest), tuple(f"{s}_{d}_" for d in dofs))
    for s in ("l", "r")
    for a, b, rest, dofs in (("shoulder", "elbow", ("wrist",), ("shoulder", "elbow")),
                             ("hip", "knee", ("ankle", "toe"), ("hip", "knee", "ankle"))))

# Parts of the body named in reports, by the joints that move with them.
BODY_PARTS = {"the trunk": ("neck", "l_shoulder", "r_shoulder", "l_hip", "r_hip"),
              "the head": ("head",),
              "the left arm": ("l_elbow", "l_wrist"), "the right arm": ("r_elbow", "r_wrist"),
              "the left leg": ("l_knee", "l_ankle", "l_toe"),
              "the right leg": ("r_knee", "r_ankle", "r_toe")}

# What an animator may turn to its other depth in a frame clicked in one view: a limb (its best
# other depth configuration) or the whole body (its mirror image in depth).
FLIP_PARTS = ("left arm", "right arm", "left leg", "right leg", "body")

# An alternative pose whose cost is within this many px^2 of the best one fits as well: under
# clicks of CLICK_SIGMA_PX it is at most e times less likely.
AMBIGUOUS_COST = CLICK_SIGMA_PX ** 2
_AMBIGUOUS_M = 0.10     # ... and it is a different pose if some joint moves this far

# Joints of the trunk, nearly rigid and nearly planar: they give a body's position and heading.
_TORSO = [JOINT_INDEX[n] for n in ("pelvis", "l_hip", "r_hip", "neck", "l_shoulder",
                                   "r_shoulder", "head")]

# A joint this many pixels (and this many times the view's median error) off the fit is named.
OUTLIER_PX = 4.0 * LOSS_SCALE_PX
OUTLIER_RATIO = 5.0

# Uncalibrated views of a near body (``initialize(..., perspective=True)``): the perspective of
# each camera (``ScaledOrthoCamera.kappa``, the inverse distance) is fitted, for cameras at least
# 1 / KAPPA_MAX metres from the body. It is not left to the clicks to say whether a view is
# near: an orthographic fit of a near view bends the pose to meet them, so that freeing the
# perspective lowers its cost by a nat or two there, no more than it does by fitting the clicks'
# noise in a far view (where it only breaks the ties of depth that one view must report).
KAPPA_MAX = 0.5

_ROOT_PARAMS = 6   # per frame: translation (3), rotation increment (3)
_CAM_PARAMS = 7    # per uncalibrated camera: log scale, rotation increment (3), shift (2), kappa
_MIN_VIEW_JOINTS = 4       # an uncalibrated view needs this many clicks to place its camera
_MIN_FRAME_JOINTS = 6      # joints a frame needs in its best view to pose the body
# A limb whose mirror image moves no joint more than this is not worth trying mirrored.
_MIN_FLIP_M = 0.05
_EXPLORE_NFEV = 30         # evaluations of a short fit that ranks a mirrored limb
# Above this many Jacobian entries the problem is solved by blocks (frames couple only through
# the dimensions); below, by scipy's least_squares on a dense Jacobian.
_DENSE_LIMIT = 400_000

# The camera that sees the body's front in the reference configuration (facing -Y, Z up):
# camera x = body +X (the subject's left on the image right), camera y = -Z, camera z = +Y.
_FRONT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


# ---------------------------------------------------------------------------------------------
# A pose prior learned from motion capture
# ---------------------------------------------------------------------------------------------

DEFAULT_POSE_PRIOR = Path(__file__).resolve().parents[1] / "priors" / "data" / "pose_prior.npz"

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
# Combinations of limb signs fitted in full: at most this many, within this many nats of the
# best before fitting.
PRIOR_REFITS = 4
PRIOR_MARGIN = 6.0
# Weight of the broad everyday-pose Gaussian mixed into the learned density. The captures
# are a few takes: at 0.2 the fit pulled poses unlike theirs (random everyday poses of the
# body model) towards them, one view's Procrustes-aligned errors of such poses 3-18 mm larger
# (two benchmark seeds, 20 poses a row) for 5 mm less on held-out captured poses.
PRIOR_BROAD_WEIGHT = 0.5
PRIOR_MIN_BANDWIDTH_DEG = 4.0
# Weight of the learned prior's -log p in the fit of frames seen in one view, in click
# variances per nat (1: the posterior of clicks with CLICK_SIGMA_PX noise).
PRIOR_WEIGHT = 1.0
# Gaussians per body part of the mixture that stands for the density in least squares.
PRIOR_COMPONENTS = 8
# A frame seen in one view is also searched from the prior's own poses whose projection best
# matches the clicks (each under its best scaled orthographic camera): this many of them, that
# differ by at least EXEMPLAR_APART_DEG in some angle, out of at most EXEMPLAR_POOL poses.
EXEMPLAR_STARTS = 2
EXEMPLAR_APART_DEG = 20.0
EXEMPLAR_POOL = 4000
# A camera that alone sees an anchor frame, uncalibrated, is taken to look at the upright body
# from about level: its line of sight this many degrees below the body's horizontal, give or
# take the second number (a camera's pitch and the pelvis's own lean together; CMU walks lean
# their pelvis 4-10 degrees). One view cannot see how the pelvis leans towards or away from
# it: without this the fit tilts the whole body by up to 19 degrees in depth to make its
# angles likelier.
CAMERA_TILT_DEG = (0.0, 10.0)


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
            naming, ``bvh.subject_of``).

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
        from ..files.cmu import subject_of

        subjects = np.array([subject_of(t) for t in takes])
        keep = ~np.isin(takes, list(exclude)) & ~np.isin(subjects, [str(s) for s in
                                                                     exclude_subjects])
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
        kin = _kinematics(template)
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
        return np.zeros((0, _kinematics(template).n_dofs)), np.zeros(0)
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


# ---------------------------------------------------------------------------------------------
# Kinematics linear in the dimensions
# ---------------------------------------------------------------------------------------------

class _Kinematics:
    """Standard joints of a template and their derivatives, batched over frames.

    For fixed angles the joints are linear in the lengths (every joint centre of the reference
    configuration is; the twists carry them linearly; §2.6 calls the whole problem tri-linear),
    so one pass over the tree gives the joints, ``d joints / d angles`` (spatial twists, eq. 22)
    and the exact ``d joints / d dims`` together. Frame: the body's own (root at the identity).
    """

    def __init__(self, template):
        body = make_body(template)
        zero = dict.fromkeys(DIM_NAMES, 0.0)
        units = [reference_points({**zero, name: 1.0}) for name in LENGTH_DIMS]

        def per_dim(point):
            return np.stack([unit[point] for unit in units], axis=-1)      # (3, D)

        self.template = template
        self.structure = body
        self.n_dofs = body.n_dofs
        self.lower, self.upper = body.lower.copy(), body.upper.copy()
        self.axes = body.dof_axes
        self.parents = body.segment_parents
        self.dof_segment = body.dof_segment
        self.dofs_of_segment = [np.flatnonzero(body.dof_segment == k)
                                for k in range(body.n_segments)]
        self.pivots = np.stack([per_dim(j) for j in body.segment_joint])       # (S, 3, D)
        self.landmark_segment = body.landmark_segment
        self.landmarks = np.stack([per_dim(j) for j in STANDARD_JOINTS])       # (17, 3, D)
        self.landmark_chain = body.chain[body.landmark_segment].astype(float)  # (17, n)
        self.default_dims = np.array([DEFAULT_DIMS[n] for n in LENGTH_DIMS])
        prior = [ANGLE_PRIOR_DEG.get(_unsided(name), (0.0, 30.0)) for name in body.dof_names]
        self.prior_mean = np.clip(np.radians([m for m, _ in prior]), self.lower, self.upper)
        self.prior_sigma = np.radians([s for _, s in prior])

    def forward(self, angles, dims):
        """Joints in the body frame and their derivatives.

        Parameters
        ----------
        angles : array, shape (B, n_dofs)
        dims : array, shape (D,)
            ``LENGTH_DIMS`` in metres.

        Returns
        -------
        Y : array, shape (B, 17, 3)
            Standard joints with the root at the identity.
        dY_dangles : array, shape (B, 17, 3, n_dofs)
        dY_ddims : array, shape (B, 17, 3, D)
        """
        angles = np.asarray(angles, dtype=float)
        B, n = angles.shape
        D = len(dims)
        S = len(self.parents)
        E = se3.exp_so3(self.axes * angles[..., None])                        # (B, n, 3, 3)
        R_seg = np.empty((B, S, 3, 3))
        trans_dims = np.empty((B, S, 3, D))     # segment translation, linear in the dims
        pivot_dims = np.empty((B, S, 3, D))     # joint centre of the segment, in the body frame
        axes_body = np.empty((B, n, 3))
        eye = np.broadcast_to(np.eye(3), (B, 3, 3))
        for k in range(S):
            parent = self.parents[k]
            R_parent = eye if parent < 0 else R_seg[:, parent]
            t_parent = 0.0 if parent < 0 else trans_dims[:, parent]
            R = R_parent
            for j in self.dofs_of_segment[k]:
                axes_body[:, j] = R @ self.axes[j]
                R = R @ E[:, j]
            R_seg[:, k] = R
            # x -> R_parent (R_local (x - q) + q) + t_parent: every DOF of a segment turns
            # about the same joint centre q.
            pivot_dims[:, k] = R_parent @ self.pivots[k] + t_parent
            trans_dims[:, k] = pivot_dims[:, k] - R @ self.pivots[k]
        ls = self.landmark_segment
        Y_dims = R_seg[:, ls] @ self.landmarks + trans_dims[:, ls]            # (B, 17, 3, D)
        Y = Y_dims @ dims
        pivots = pivot_dims[:, self.dof_segment] @ dims                       # (B, n, 3)
        # eq. (22)-(23): a point moves by w' x (X - q') per unit of the angle, if DOF j is on
        # the path from the root to the point's segment.
        lever = Y[:, :, None, :] - pivots[:, None, :, :]                      # (B, 17, n, 3)
        J = np.cross(axes_body[:, None], lever) * self.landmark_chain[None, :, :, None]
        return Y, np.swapaxes(J, -1, -2), Y_dims

    def start_angles(self):
        """Angles to start a fit from: the prior's mean (knees and elbows a little bent)."""
        return self.prior_mean.copy()


def _unsided(name):
    return name[2:] if name.startswith(("l_", "r_")) else name


_KINEMATICS = {}


def _kinematics(template):
    if template not in _KINEMATICS:
        _KINEMATICS[template] = _Kinematics(template)
    return _KINEMATICS[template]


# ---------------------------------------------------------------------------------------------
# The joint problem
# ---------------------------------------------------------------------------------------------

@dataclass
class _State:
    """Everything the joint problem fits, for F frames and V views."""

    dims: np.ndarray          # (D,)
    size: float               # overall size relative to the template (the proportions' prior)
    roots: np.ndarray         # (F, 4, 4) world_from_pelvis
    angles: np.ndarray        # (F, n)
    cameras: list             # F lists of V cameras (None where a view has no camera)

    def copy(self):
        return _State(self.dims.copy(), float(self.size), self.roots.copy(), self.angles.copy(),
                      [list(row) for row in self.cameras])


def _soft_l1(m_robust, c):
    """Loss for least_squares (``f_scale = 1``): soft L1 of scale ``c`` pixels on the first
    ``m_robust`` residuals (the clicks), plain squares on the priors after them."""

    def loss(z):
        rho = np.empty((3, z.size))
        rho[0], rho[1], rho[2] = z, 1.0, 0.0
        q = 1.0 + z[:m_robust] / c**2
        root = np.sqrt(q)
        rho[0, :m_robust] = 2.0 * c**2 * (root - 1.0)
        rho[1, :m_robust] = 1.0 / root
        rho[2, :m_robust] = -0.5 / (c**2 * q * root)
        return rho

    return loss


class _Problem:
    """Reprojection of the model joints over frames and views, as a least-squares problem.

    Parameter vector: ``[dims (D), size]`` when the dimensions are fitted, then per frame
    ``[root translation (3), root rotation increment (3)]`` when roots are free and the angles
    when they are, then ``[log scale, rotation increment (3), image shift (2), kappa]`` per free
    (scaled orthographic) camera; ``kappa`` stays the camera's own but in the frames where
    ``perspective`` (bool, or per frame) is true.
    Residuals: the weighted click errors (2 per clicked joint and view, robust), then the
    priors.
    """

    def __init__(self, kin, obs, weights, state, *, free_root, free_angles=True, free_cams=None,
                 fit_dims=True, calibrated=True, loss_scale=LOSS_SCALE_PX, dims_range=DIMS_RANGE,
                 pose_prior=None, prior_frames=None, tilt=None, tilt_frames=None,
                 perspective=False, dims_prior=None):
        self.kin = kin
        # (mean (D,), relative sigma (D,)) of the lengths about ``size * mean``: the template's
        # proportions and DIMS_PRIOR_SIGMA unless a learned proportions prior is given.
        self.dims_mean, self.dims_sigma = (kin.default_dims, DIMS_PRIOR_SIGMA) \
            if dims_prior is None else (np.asarray(dims_prior[0], float),
                                        np.asarray(dims_prior[1], float))
        self.obs = np.asarray(obs, dtype=float)                     # (F, V, 17, 2)
        F, V = self.obs.shape[:2]
        w = np.where(np.isfinite(self.obs).all(axis=-1), np.asarray(weights, float), 0.0)
        self.mask = w > 0
        self.sqrt_w = np.sqrt(w)
        self.F, self.V = F, V
        self.state = state.copy()
        self.free_root = free_root
        self.free_angles = free_angles
        self.fit_dims = fit_dims
        self.loss_scale = loss_scale
        self.dims_range = dims_range
        self.calibrated = calibrated
        # The learned pose prior replaces the everyday-pose Gaussian in these frames.
        self.pose_prior = pose_prior if free_angles else None
        self.prior_frames = np.zeros(F, bool) if self.pose_prior is None else \
            np.ones(F, bool) if prior_frames is None else np.asarray(prior_frames, bool)
        if not self.prior_frames.any():
            self.pose_prior = None
        # (mean, sigma) of the body's up axis along the line of sight of the free cameras of
        # these frames (the sine of the camera's tilt): a Gaussian prior.
        self.tilt = tilt
        self.tilt_frames = np.zeros(F, bool) if tilt is None or tilt_frames is None else \
            np.asarray(tilt_frames, bool)
        free_cams = np.zeros((F, V), bool) if free_cams is None else np.asarray(free_cams, bool)
        self.cam_index = np.full((F, V), -1)
        self.cam_index[free_cams] = np.arange(free_cams.sum())
        self.free_pairs = np.argwhere(free_cams)                     # (C, 2) frame, view
        # Free cameras whose perspective is fitted
        self.near = np.broadcast_to(np.asarray(perspective, bool), (F,))[self.free_pairs[:, 0]]
        D, n = len(state.dims), kin.n_dofs
        self.D = D
        self.frame_size = (_ROOT_PARAMS if free_root else 0) + (n if free_angles else 0)
        self.off_frame = D + 1 if fit_dims else 0
        self.off_cam = self.off_frame + F * self.frame_size
        self.n_params = self.off_cam + _CAM_PARAMS * len(self.free_pairs)
        self._index = np.argwhere(self.mask)                         # (M, 3) frame, view, joint
        self.m_obs = 2 * len(self._index)
        # Reference rotations: the parameters hold increments on them.
        self.root_R = state.roots[:, :3, :3].copy()
        cams = [state.cameras[f][v] for f, v in self.free_pairs]
        self.cam_s = np.array([c.s for c in cams])
        self.cam_R = np.array([c.R for c in cams]).reshape(-1, 3, 3)
        self.cam_t = np.array([c.t[:2] for c in cams]).reshape(-1, 2)
        self.cam_c = np.array([c.c for c in cams]).reshape(-1, 2)
        self.cam_k = np.array([c.kappa for c in cams])
        self._cache_x = None
        self._fixed_joints = None       # the joints, when no body parameter is free

    # -- parameters ---------------------------------------------------------------------------

    def x0(self):
        s = self.state
        parts = []
        if self.fit_dims:
            parts += [s.dims, [s.size]]
        frame = []
        if self.free_root:
            frame += [s.roots[:, :3, 3], np.zeros((self.F, 3))]
        if self.free_angles:
            frame += [s.angles]
        if frame:
            parts.append(np.concatenate(frame, axis=1).ravel())
        cam0 = np.zeros((len(self.free_pairs), _CAM_PARAMS))
        cam0[:, 6] = self.cam_k
        parts.append(cam0.ravel())
        x = np.concatenate([np.ravel(p) for p in parts])
        lo, hi = self.bounds()
        return np.clip(x, lo, hi)

    def bounds(self):
        lo = np.full(self.n_params, -np.inf)
        hi = np.full(self.n_params, np.inf)
        if self.fit_dims:
            d0 = self.kin.default_dims
            lo[:self.D], hi[:self.D] = self.dims_range[0] * d0, self.dims_range[1] * d0
            lo[self.D], hi[self.D] = self.dims_range
        if self.free_angles:
            a0 = self.off_frame + (_ROOT_PARAMS if self.free_root else 0)
            cols = a0 + np.arange(self.F)[:, None] * self.frame_size + np.arange(self.kin.n_dofs)
            lo[cols] = self.kin.lower
            hi[cols] = self.kin.upper
        k = self.off_cam + np.flatnonzero(self.near) * _CAM_PARAMS + 6
        lo[k], hi[k] = 0.0, np.maximum(KAPPA_MAX, self.cam_k[self.near])
        return lo, hi

    def _split(self, x):
        s = self.state
        if self.fit_dims:
            dims, size = x[:self.D], x[self.D]
        else:
            dims, size = s.dims, s.size
        frame = x[self.off_frame:self.off_cam].reshape(self.F, self.frame_size)
        if self.free_root:
            p, w = frame[:, :3], frame[:, 3:6]
            R = se3.exp_so3(w) @ self.root_R
        else:
            p, w, R = s.roots[:, :3, 3], None, s.roots[:, :3, :3]
        angles = frame[:, -self.kin.n_dofs:] if self.free_angles else s.angles
        cams = x[self.off_cam:].reshape(-1, _CAM_PARAMS)
        return dims, size, p, w, R, angles, cams

    def unpack(self, x):
        """The state at parameter vector ``x``."""
        dims, size, p, _, R, angles, cams = self._split(x)
        out = self.state.copy()
        out.dims, out.size = np.array(dims, float), float(size)
        out.roots = np.tile(np.eye(4), (self.F, 1, 1))
        out.roots[:, :3, :3] = se3.orthonormalize(R)
        out.roots[:, :3, 3] = p
        out.angles = np.clip(angles, self.kin.lower, self.kin.upper)
        s, Rc, t, k = self._cam_params(cams)
        for i, (f, v) in enumerate(self.free_pairs):
            old = out.cameras[f][v]
            out.cameras[f][v] = old.replace(s=s[i], R=se3.orthonormalize(Rc[i]),
                                            t=np.array([t[i, 0], t[i, 1], old.t[2]]),
                                            kappa=float(k[i]))
        return out

    def _cam_params(self, cams):
        s = self.cam_s * np.exp(cams[:, 0])
        R = se3.exp_so3(cams[:, 1:4]) @ self.cam_R
        t = self.cam_t + cams[:, 4:6]
        return s, R, t, np.where(self.near, cams[:, 6], self.cam_k)

    # -- evaluation ---------------------------------------------------------------------------

    def _joints(self, x):
        """World joints (F, 17, 3) and their derivatives by the frame parameters and dims."""
        body_fixed = not (self.fit_dims or self.free_root or self.free_angles)
        if body_fixed and self._fixed_joints is not None:
            return self._fixed_joints
        out = self._moving_joints(x)
        if body_fixed:
            self._fixed_joints = out
        return out

    def _moving_joints(self, x):
        dims, _, p, w, R, angles, _ = self._split(x)
        Y, JA, Yd = self.kin.forward(angles, dims)
        X = Y @ np.swapaxes(R, -1, -2) + p[:, None]
        parts = []
        if self.free_root:
            RY = X - p[:, None]
            J_rot = -se3.hat3(RY) @ se3.left_jacobian_so3(w)[:, None]
            parts += [np.broadcast_to(np.eye(3), J_rot.shape), J_rot]
        if self.free_angles:
            parts.append(R[:, None] @ JA)
        J_frame = np.concatenate(parts, axis=-1) if parts else np.zeros(X.shape + (0,))
        return X, J_frame, R[:, None] @ Yd

    def _project(self, X, cams):
        """Pixels (F, V, 17, 2), ``d uv / d X`` (F, V, 17, 2, 3) and the free cameras'
        derivatives (C, 17, 2, 6)."""
        F, V = self.F, self.V
        uv = np.full((F, V, N_JOINTS, 2), np.nan)
        A = np.zeros((F, V, N_JOINTS, 2, 3))
        free = self.cam_index >= 0
        for v in range(V):
            fixed = [f for f in range(F) if not free[f, v] and self.state.cameras[f][v] is not None
                     and self.mask[f, v].any()]
            if not fixed:
                continue
            first = self.state.cameras[fixed[0]][v]
            if all(self.state.cameras[f][v] is first for f in fixed):
                uv[fixed, v], A[fixed, v] = first.project_jacobian(X[fixed])
            else:
                for f in fixed:
                    uv[f, v], A[f, v] = self.state.cameras[f][v].project_jacobian(X[f])
        G = np.zeros((len(self.free_pairs), N_JOINTS, 2, _CAM_PARAMS))
        if len(self.free_pairs):
            s, Rc, t, k = self._cam_params(cams)
            fi, vi = self.free_pairs.T
            Xc = X[fi] @ np.swapaxes(Rc, -1, -2)                              # (C, 17, 3)
            shifted = Xc[..., :2] + t[:, None]
            d = 1.0 + k[:, None] * Xc[..., 2]                                 # (C, 17)
            sd = s[:, None] / d
            uv[fi, vi] = sd[..., None] * shifted + self.cam_c[:, None]
            q = sd[..., None] * shifted * (k[:, None, None] / d[..., None])  # (C, 17, 2)
            A[fi, vi] = sd[..., None, None] * Rc[:, None, :2] \
                - q[..., None] * Rc[:, None, None, 2]
            G[..., 0] = sd[..., None] * shifted
            rot = -se3.hat3(Xc) @ se3.left_jacobian_so3(cams[:, 1:4])[:, None]
            G[..., 1:4] = sd[..., None, None] * rot[..., :2, :] \
                - q[..., None] * rot[..., None, 2, :]
            G[..., 0, 4] = G[..., 1, 5] = sd
            G[..., 6] = -(sd * self.near[:, None])[..., None] * shifted \
                * (Xc[..., 2] / d)[..., None]
        return uv, A, G

    def evaluate(self, x):
        """Residuals (m,) and the Jacobian (dense or CSR), cached for the last ``x``."""
        if self._cache_x is not None and np.array_equal(x, self._cache_x):
            return self._cache
        dims, size, *_, cams = self._split(x)
        X, J_frame, Xd = self._joints(x)
        uv, A, G = self._project(X, cams)
        fi, vi, ji = self._index.T
        M = len(fi)
        sw = self.sqrt_w[fi, vi, ji][:, None]
        r_obs = (sw * (uv[fi, vi, ji] - self.obs[fi, vi, ji])).ravel()
        Aw = A[fi, vi, ji] * sw[..., None]                                    # (M, 2, 3)
        rows_obs = np.arange(2 * M).reshape(M, 2)
        rows, cols, vals = [], [], []

        def block(r, c, v):
            r, c = np.broadcast_arrays(r, c)
            rows.append(r.ravel())
            cols.append(c.ravel())
            vals.append(np.broadcast_to(v, r.shape).ravel())

        if self.fit_dims:
            block(rows_obs[..., None], np.arange(self.D), Aw @ Xd[fi, ji])
        if self.frame_size:
            c0 = self.off_frame + fi * self.frame_size
            block(rows_obs[..., None], (c0[:, None] + np.arange(self.frame_size))[:, None],
                  Aw @ J_frame[fi, ji])
        ci = self.cam_index[fi, vi]
        on = ci >= 0
        if on.any():
            c0 = self.off_cam + ci[on] * _CAM_PARAMS
            block(rows_obs[on][..., None], (c0[:, None] + np.arange(_CAM_PARAMS))[:, None],
                  G[ci[on], ji[on]] * sw[on][..., None])
        # Priors (no robust loss): proportions, size, rest angles.
        res = [r_obs]
        row = 2 * M
        if self.fit_dims:
            d0 = self.dims_mean
            wd = CLICK_SIGMA_PX / np.maximum(self.dims_sigma, DIMS_PRIOR_FLOOR_M / d0)
            res.append(wd * (dims / d0 - size))
            r = row + np.arange(self.D)
            block(r, np.arange(self.D), wd / d0)
            block(r, self.D, -wd)
            row += self.D
            wk = CLICK_SIGMA_PX / SIZE_PRIOR_SIGMA[self.calibrated]
            res.append([wk * (size - 1.0)])
            block(row, self.D, wk)
            row += 1
        if self.free_angles:
            n = self.kin.n_dofs
            wa = np.outer(~self.prior_frames, CLICK_SIGMA_PX / self.kin.prior_sigma).ravel()
            angles = self._split(x)[5]
            res.append(wa * (angles - self.kin.prior_mean).ravel())
            a0 = self.off_frame + (_ROOT_PARAMS if self.free_root else 0)
            cols_a = a0 + np.arange(self.F)[:, None] * self.frame_size + np.arange(n)
            block(row + np.arange(self.F * n), cols_a.ravel(), wa)
            row += self.F * n
            if self.pose_prior is not None:
                scale = np.sqrt(PRIOR_WEIGHT) * CLICK_SIGMA_PX
                frames = np.flatnonzero(self.prior_frames)
                for dofs, means, whiten, costs in self.pose_prior.mixture():
                    # The likeliest component of each frame: its whitened distance (a linear
                    # residual) and its cost over the best component's (a constant one), so
                    # that 0.5 r^2 is PRIOR_WEIGHT click variances per nat.
                    d = angles[frames][:, None, dofs] - means[None]              # (B, K, k)
                    z = np.einsum("kij,bkj->bki", whiten, d)
                    total = 0.5 * np.einsum("bki,bki->bk", z, z) + costs
                    best = np.argmin(total, axis=1)
                    B, k = len(frames), len(dofs)
                    res.append(scale * z[np.arange(B), best].ravel())
                    block(row + np.arange(B * k).reshape(B, k, 1),
                          cols_a[frames][:, dofs][:, None, :], scale * whiten[best])
                    row += B * k
                    res.append(scale * np.sqrt(2.0 * (costs[best] - costs.min())))
                    row += B
        pick = np.flatnonzero(self.tilt_frames[self.free_pairs[:, 0]]) \
            if len(self.free_pairs) else []
        if len(pick):
            _, Rc, _, _ = self._cam_params(cams)
            up = Rc[pick][:, :, 2]                                 # body Z, camera coordinates
            wt = CLICK_SIGMA_PX / self.tilt[1]
            res.append(wt * (up[:, 2] - self.tilt[0]))
            d_up = -se3.hat3(up) @ se3.left_jacobian_so3(cams[pick, 1:4])      # (C, 3, 3)
            block(row + np.arange(len(pick))[:, None],
                  (self.off_cam + pick * _CAM_PARAMS + 1)[:, None] + np.arange(3), wt * d_up[:, 2])
            row += len(pick)
        r = np.concatenate([np.ravel(p) for p in res])
        rows, cols, vals = (np.concatenate(a) for a in (rows, cols, vals))
        if r.size * self.n_params <= _DENSE_LIMIT:
            J = np.zeros((r.size, self.n_params))
            J[rows, cols] = vals
        else:
            J = sparse.csr_matrix((vals, (rows, cols)), shape=(r.size, self.n_params))
        self._cache_x, self._cache = x.copy(), (r, J)
        return r, J

    def solve(self, max_nfev=200):
        """Run the robust fit; returns (state, cost) with cost ``0.5 sum rho`` in px^2.

        Small problems go to ``least_squares`` (dogbox: its box-shaped trust region copes with
        angles resting on their limits). Large ones, many frames coupled only through the
        dimensions, to :meth:`_solve_blocks`.
        """
        x0 = self.x0()
        if self.n_params == 0 or self.m_obs == 0:
            return self.state.copy(), 0.0
        lo, hi = self.bounds()
        if sparse.issparse(self.evaluate(x0)[1]):
            x, cost = self._solve_blocks(x0, lo, hi, max_iter=max_nfev)
            return self.unpack(x), cost
        result = least_squares(
            lambda x: self.evaluate(x)[0], x0, jac=lambda x: self.evaluate(x)[1],
            bounds=(lo, hi), method="dogbox", loss=_soft_l1(self.m_obs, self.loss_scale),
            f_scale=1.0, x_scale=1.0, max_nfev=max_nfev)
        return self.unpack(result.x), float(result.cost)

    def _cost(self, r):
        return 0.5 * float(np.sum(_soft_l1(self.m_obs, self.loss_scale)(r ** 2)[0]))

    def _solve_blocks(self, x, lo, hi, max_iter=100):
        """Levenberg-Marquardt by the Schur complement, as in bundle adjustment.

        The normal equations of a frame's own parameters (root, angles, cameras) form one
        block; the blocks couple only through the global ones (dimensions, size), which are
        solved first from the reduced system ``S = V - sum_f W_f U_f^-1 W_f^T``. The robust loss
        enters as iteratively reweighted least squares; bounds by projecting each step.

        Returns
        -------
        x : array, shape (N,)
        cost : float
        """
        G = self.off_frame
        F = self.F
        local = [list(range(self.off_frame + f * self.frame_size,
                            self.off_frame + (f + 1) * self.frame_size)) for f in range(F)]
        for i, (f, _) in enumerate(self.free_pairs):
            local[f] += list(range(self.off_cam + i * _CAM_PARAMS,
                                   self.off_cam + (i + 1) * _CAM_PARAMS))
        P = max(len(cols) for cols in local)
        index = np.full((F, P), -1)
        for f, cols in enumerate(local):
            index[f, :len(cols)] = cols
        pad = index < 0
        idx = np.where(pad, 0, index)
        loss = _soft_l1(self.m_obs, self.loss_scale)
        r, J = self.evaluate(x)
        cost = self._cost(r)
        lam = 1e-3
        for _ in range(max_iter):
            w = loss(r ** 2)[1]
            Jw = sparse.diags(w) @ J
            H = (J.T @ Jw).tocsr()
            g = -(Jw.T @ r)
            H_gg = H[:G, :G].toarray()
            H_gl = H[:G].toarray()[:, idx] * ~pad                         # (G, F, P)
            U_full = np.zeros((F, P, P))
            for f, cols in enumerate(local):
                U_full[f, :len(cols), :len(cols)] = H[cols][:, cols].toarray()
            b_l = np.where(pad, 0.0, g[idx])
            while True:
                A = U_full + lam * (np.eye(P) * (np.diagonal(U_full, axis1=1, axis2=2)[:, None]
                                                 + 1e-9)) + np.eye(P) * pad[:, None, :]
                Ainv_b = np.linalg.solve(A, b_l[..., None])[..., 0]           # (F, P)
                if G:
                    Wt = np.transpose(H_gl, (1, 2, 0))                      # (F, P, G)
                    Ainv_W = np.linalg.solve(A, Wt)                         # (F, P, G)
                    S = H_gg + lam * np.diag(np.diag(H_gg) + 1e-9) \
                        - np.einsum("fpg,fph->gh", Wt, Ainv_W)
                    d_g = np.linalg.solve(S, g[:G] - np.einsum("fpg,fp->g", Wt, Ainv_b))
                    d_l = Ainv_b - Ainv_W @ d_g
                else:
                    d_g, d_l = np.zeros(0), Ainv_b
                step = np.zeros_like(x)
                step[:G] = d_g
                step[idx[~pad]] = d_l[~pad]
                x_new = np.clip(x + step, lo, hi)
                r_new, J_new = self.evaluate(x_new)
                cost_new = self._cost(r_new)
                if cost_new < cost:
                    break
                lam *= 4.0
                if lam > 1e8:
                    return x, cost
            done = cost - cost_new < 1e-7 * cost
            x, r, J, cost = x_new, r_new, J_new, cost_new
            lam = max(lam / 3.0, 1e-7)
            if done:
                break
        return x, cost

    def errors(self, state=None):
        """Click errors in pixels, (F, V, 17), NaN where not clicked."""
        problem = self if state is None else _Problem(
            self.kin, self.obs, self.sqrt_w**2, state, free_root=False, free_angles=False,
            fit_dims=False, calibrated=self.calibrated)
        x = problem.x0()
        X, _, _ = problem._joints(x)
        uv, _, _ = problem._project(X, x[problem.off_cam:].reshape(-1, _CAM_PARAMS))
        err = np.linalg.norm(uv - problem.obs, axis=-1)
        return np.where(problem.mask, err, np.nan)


def _rho_px(errors, c=LOSS_SCALE_PX):
    """Soft L1 of click errors (pixels), per error: ``c^2 (sqrt(1 + e^2 / c^2) - 1)``."""
    return c**2 * (np.sqrt(1.0 + errors**2 / c**2) - 1.0)


def _robust_cost(errors, c=LOSS_SCALE_PX):
    """About what click errors (pixels, NaN ignored) add to the fit's cost, ``0.5 sum rho``
    (the fit's soft L1 acts per coordinate; this per-point form is close)."""
    return float(np.sum(_rho_px(errors[np.isfinite(errors)], c)))


def _fit(kin, obs, weights, state, **options):
    max_nfev = options.pop("max_nfev", 200)
    problem = _Problem(kin, obs, weights, state, **options)
    fitted, cost = problem.solve(max_nfev=max_nfev)
    return fitted, cost, problem


# ---------------------------------------------------------------------------------------------
# Geometry for starting points
# ---------------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------------------------

@dataclass
class InitResult:
    """What :func:`initialize` found.

    Attributes
    ----------
    body : BodyModel
        The template with the fitted dimensions (lengths fitted; radii scaled with the size).
    poses : dict of int to Pose
        Per anchor frame. Calibrated: world poses. Uncalibrated: root at the identity (a
        body-centred frame) and the angles.
    cameras : dict of str to camera
        Calibrated: the given cameras. Uncalibrated: the fitted ScaledOrthoCamera of each view
        at the first anchor frame.
    view_cameras : dict of int to dict of str to ScaledOrthoCamera, or None
        Uncalibrated: the fitted camera of every view at every anchor frame (one pose per view).
    errors : dict of int to dict of str to array, shape (17,)
        Click errors in pixels per frame and view, NaN where a joint was not clicked.
    rms : dict of str to float
        Root-mean-square click error per view over all anchors, pixels.
    warnings : list of str
        One line each: swapped or outlying clicks, views left out, a mirrored pose that fits.
    ambiguous : bool
        A mirrored (depth-flipped) pose fits about as well for some anchor frame.
    calibrated : bool
    swapped : list of (int, str, str, str)
        ``(frame, view, joint, joint)`` click pairs fitted exchanged because they looked swapped.
    ambiguous_parts : dict of int to list of str
        Per anchor frame, the ``FLIP_PARTS`` that another depth would fit about as well: what
        the animator may flip (``initialize(..., flips=...)``) after judging the result by eye.
    flipped : dict of int to list of str
        The flips asked for and made, per anchor frame.
    notes : list of str
        One line each: what the animator may do for a better fit that is no fault of the
        clicks (``ONE_VIEW_LENGTHS_NOTE``).
    """

    body: object
    poses: dict
    cameras: dict
    view_cameras: dict
    errors: dict
    rms: dict
    warnings: list
    ambiguous: bool
    calibrated: bool
    swapped: list = field(default_factory=list)
    ambiguous_parts: dict = field(default_factory=dict)
    flipped: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def flip_notes(self):
        """One line per anchor frame where parts were flipped in depth."""
        return [f"frame {frame}: flipped in depth: {', '.join(parts)}"
                for frame, parts in sorted(self.flipped.items())]

    def distance_note(self):
        """One line: each uncalibrated view's fitted camera distance at the first anchor
        (``perspective=True``; "far" where none was fitted)."""
        return "camera distance (m): " + ", ".join(
            f"{view} {1.0 / cam.kappa:.1f}" if getattr(cam, "kappa", 0.0) else f"{view} far"
            for view, cam in self.cameras.items())

    @property
    def dims(self):
        """Fitted lengths, ``{name: metres}`` over ``LENGTH_DIMS``."""
        return {name: self.body.dims[name] for name in LENGTH_DIMS}

    def joints3d(self, frame):
        """Model joints of an anchor frame, (17, 3): world (calibrated) or body frame."""
        return self.body.joints(self.poses[frame])

    def to_json(self):
        """The JSON object of an init.json file (``zoopraxis-init/1``)."""
        def clean(a):
            return [None if not np.isfinite(x) else round(float(x), 3) for x in a]

        cams = self.view_cameras or {f: self.cameras for f in self.poses}
        return {
            "format": "zoopraxis-init/1",
            "mode": "calibrated" if self.calibrated else "uncalibrated",
            "template": self.body.template,
            "dims": {k: round(float(v), 5) for k, v in self.body.dims.items()},
            "dof_names": list(self.body.dof_names),
            "joints": list(STANDARD_JOINTS),
            "anchors": [{
                "frame": int(f),
                "pose": [round(float(x), 6) for x in pose.to_vector()],
                "joints3d": np.round(self.joints3d(f), 5).tolist(),
                "views": {v: {"camera": cams[f][v].to_dict(),
                              "errors": clean(self.errors[f][v])}
                          for v in self.errors[f]},
            } for f, pose in sorted(self.poses.items())],
            "rms": {v: round(float(x), 3) for v, x in self.rms.items()},
            "warnings": list(self.warnings),
            "ambiguous": bool(self.ambiguous),
            "ambiguous_parts": {str(f): list(p) for f, p in sorted(self.ambiguous_parts.items())},
            "flipped": {str(f): list(p) for f, p in sorted(self.flipped.items())},
            "notes": list(self.notes),
        }


def read_init(path):
    """Read an init.json file into an :class:`InitResult` (:func:`init_from_json`).

    Raises
    ------
    ZoopraxisError
        Not a regular file, not JSON, or not a well-formed init.json, naming the file.
    """
    from ..files.inputs import read_json

    return init_from_json(read_json(path, "init file"), path)


def init_from_json(data, path="init.json"):
    """Rebuild an :class:`InitResult` from the JSON object of an init.json file.

    Raises
    ------
    ZoopraxisError
        A missing key, a wrong format or a value of the wrong type, naming the file.
    """
    try:
        return _init_from_json(data, path)
    except ZoopraxisError as error:
        if str(error).startswith(str(path)):
            raise
        raise ZoopraxisError(f"{path}: {error}") from None
    except (TypeError, ValueError, AttributeError, KeyError, IndexError, OverflowError) as error:
        raise ZoopraxisError(f"{path}: malformed init file ({type(error).__name__}: "
                             f"{str(error)[:80]})") from None


def _init_from_json(data, path):
    from ..files.calibfile import camera_from_dict
    from ..files.plausible import check_body_dims

    if not isinstance(data, dict) or data.get("format") != "zoopraxis-init/1":
        raise ZoopraxisError(f"{path}: not a zoopraxis-init/1 file")
    for key in ("mode", "template", "dims", "anchors"):
        if key not in data:
            raise ZoopraxisError(f"{path}: missing required key '{key}'")
    if not isinstance(data["dims"], dict) or not isinstance(data["anchors"], list):
        raise ZoopraxisError(f"{path}: 'dims' must be an object and 'anchors' a list")
    check_body_dims(data["dims"], path)
    body = make_body(data["template"], data["dims"])
    poses, view_cameras, errors = {}, {}, {}
    for a in data["anchors"]:
        for key in ("frame", "pose", "views"):
            if key not in a:
                raise ZoopraxisError(f"{path}: an anchor misses key '{key}'")
        f = int(a["frame"])
        vector = np.asarray(a["pose"], float)
        if not np.all(np.isfinite(vector)):
            raise ZoopraxisError(f"{path}: frame {f}: pose holds NaN or infinity")
        if vector.shape != (6 + body.n_dofs,):
            raise ZoopraxisError(f"{path}: frame {f}: pose has {vector.size} numbers, the "
                                 f"'{body.template}' body needs {6 + body.n_dofs}")
        poses[f] = Pose.from_vector(vector)
        view_cameras[f] = {v: camera_from_dict(d["camera"], str(path))
                           for v, d in a["views"].items()}
        errors[f] = {v: np.array([np.nan if e is None else e for e in d.get("errors", [])],
                                 float) for v, d in a["views"].items()}
    calibrated = data["mode"] == "calibrated"
    first = min(poses) if poses else None
    return InitResult(body=body, poses=poses,
                      cameras=view_cameras[first] if first is not None else {},
                      view_cameras=None if calibrated else view_cameras, errors=errors,
                      rms=dict(data.get("rms", {})), warnings=list(data.get("warnings", [])),
                      ambiguous=bool(data.get("ambiguous", False)), calibrated=calibrated,
                      ambiguous_parts={int(f): list(p) for f, p in
                                       dict(data.get("ambiguous_parts", {})).items()},
                      flipped={int(f): list(p) for f, p in dict(data.get("flipped", {})).items()},
                      notes=[str(n) for n in data.get("notes", [])])


# ---------------------------------------------------------------------------------------------
# Initialization
# ---------------------------------------------------------------------------------------------

def _observations(anchors, views):
    """Clicks as an array (F, V, 17, 2), NaN where not clicked."""
    obs = np.full((len(anchors), len(views), N_JOINTS, 2), np.nan)
    for f, anchor in enumerate(anchors):
        for v, view in enumerate(views):
            obs[f, v] = anchor.array(view)
    return obs


def _check_anchors(anchors, views):
    if not anchors:
        raise ZoopraxisError("no anchor frames: click the joints on a first frame")
    for a in anchors:
        best = max((a.joint_count(v) for v in views), default=0)
        if best < _MIN_FRAME_JOINTS and _seen_twice(a, views) < _MIN_FRAME_JOINTS:
            raise ZoopraxisError(
                f"frame {a.frame}: at most {best} joints clicked in one view; click at least "
                f"{_MIN_FRAME_JOINTS} joints in one view to pose the body")


def _seen_twice(anchor, views):
    count = {}
    for v in views:
        for j in anchor.views.get(v, {}):
            count[j] = count.get(j, 0) + 1
    return sum(1 for c in count.values() if c >= 2)


def initialize(anchors, cameras, *, template="full", calibrated=True, dims=None, fit_dims=True,
               views=None, pose_prior="default", flips=None, camera_tilt=CAMERA_TILT_DEG,
               perspective=False, proportions=None):
    """Pose, angles and body dimensions from the clicked joints of anchor frames (§2.6).

    Parameters
    ----------
    anchors : list of markers.Anchor
        Clicked joints per anchor frame and view (pixels).
    cameras : dict of str to camera
        Calibrated: the perspective cameras of the views. Uncalibrated: only their image sizes
        are used (a camera or a ``(width, height)`` per view); may be None, then the clicks set
        the principal point.
    template : str
        Body template (``body.TEMPLATES``).
    calibrated : bool
        Calibrated perspective views with one world pose per anchor, or Bregler & Malik's
        uncalibrated mode with one scaled orthographic camera per view and anchor.
    dims : dict, optional
        Starting body dimensions (metres); defaults to the template's.
    fit_dims : bool
        Fit the lengths (shared by all anchors); otherwise keep ``dims``.
    views : list of str, optional
        The views to use; default all views of ``cameras`` (calibrated) or with clicks.
    pose_prior : PosePrior, "default", path or None
        In frames clicked in one view, chooses the depth sign of each limb (the mirror
        ambiguity) and, uncalibrated, is the angle prior of the fit (weight PRIOR_WEIGHT):
        the shipped prior learned from motion capture (``"default"``, if there is one for the
        template), a given one or the file of one (``zoopraxis prior``: learned from takes of
        the kind of motion at hand), or none (then the angle prior of everyday poses alone
        decides).
    flips : dict of int to list of str, optional
        Per anchor frame clicked in one view, body parts (``FLIP_PARTS``: "left arm", ...,
        "body") to turn to their other depth: the best fitting pose in which that limb lies
        otherwise in depth (or the whole body's mirror image), even if it fits a little worse.
        The animator's answer to a reported ambiguity (``InitResult.ambiguous_parts``).
    camera_tilt : (float, float) or None
        Uncalibrated, in frames clicked in one view: how far (degrees) the camera is expected
        to look down at the upright body, and give or take how much (a Gaussian prior on the
        depth lean one view cannot see; ``CAMERA_TILT_DEG``: level, 10 degrees). None: no
        prior. A camera looking up has a negative tilt.
    perspective : bool
        Uncalibrated: the views are near the body (a phone or a normal lens a few metres away,
        at least 1 / KAPPA_MAX), so each camera's perspective is fitted too
        (``ScaledOrthoCamera.kappa``). Default: far or telephoto views, scaled orthographic.
    proportions : proportions.ProportionsPrior, "default" or None
        Uncalibrated, when the lengths are fitted: the prior of the body's proportions, learned
        from many performers (``"default"``: the shipped one), or None (the default) for the
        template's proportions, each within DIMS_PRIOR_SIGMA. Not the default: on held-out CMU
        performers in one view it was 72.6 mm off instead of 64.2 (36 frames; 60.1 instead of
        57.2 for those with their own lengths, 88.2 instead of 72.9 for those on cgspeed's Daz
        figure), and random bodies of the template's proportions came out 75 mm off instead
        of under 40 (benchmarks/bench_initialize.py --only held-out-subjects).

    Returns
    -------
    result : InitResult

    Raises
    ------
    ZoopraxisError
        No anchors, a view without a camera, a frame with too few clicks, a flip of an unknown
        part or of a frame that is not an anchor, perspective asked of calibrated views.
    """
    if perspective and calibrated:
        raise ZoopraxisError("perspective is fitted for uncalibrated views only (calibrated "
                             "cameras have their own)")
    anchors = sorted(anchors, key=lambda a: a.frame)
    flips = check_flips(flips, [a.frame for a in anchors])
    frames = [a.frame for a in anchors]
    if len(set(frames)) != len(frames):
        raise ZoopraxisError(f"frame {next(f for f in frames if frames.count(f) > 1)} has two "
                             "anchors")
    clicked = []
    for a in anchors:
        clicked += [v for v in a.views if a.joint_count(v) and v not in clicked]
    if calibrated:
        cameras = cameras or {}
        for a in anchors:
            for v in a.views:
                if a.joint_count(v) and v not in cameras and (views is None or v in views):
                    raise ZoopraxisError(
                        f"frame {a.frame}: view '{v}' has no camera in the calibration "
                        f"(cameras: {', '.join(cameras) or 'none'})")
        views = list(views) if views is not None else list(cameras)
        missing = [v for v in views if v not in cameras]
        if missing:
            raise ZoopraxisError(f"view '{missing[0]}' has no camera in the calibration "
                                 f"(cameras: {', '.join(cameras) or 'none'})")
    else:
        views = list(views) if views is not None else \
            list(cameras or {}) + [v for v in clicked if v not in (cameras or {})]
    if not views:
        raise ZoopraxisError("no views: give the cameras or click joints in some view")
    _check_anchors(anchors, views)
    kin = _kinematics(template)
    dims0 = kin.default_dims.copy() if not dims else \
        np.array([float(dims.get(n, DEFAULT_DIMS[n])) for n in LENGTH_DIMS])
    obs = _observations(anchors, views)
    weights = np.ones(obs.shape[:3])
    warnings = []
    if calibrated:
        fit = _CalibratedFit(kin, obs, weights, [cameras[v] for v in views], views, anchors,
                             dims0, fit_dims, warnings)
    else:
        sizes = [_image_size(cameras, v, obs[:, i]) for i, v in enumerate(views)]
        fit = _UncalibratedFit(kin, obs, weights, sizes, views, anchors, dims0, fit_dims,
                               warnings)
        if camera_tilt is not None:
            down, spread = check_camera_tilt(camera_tilt)
            # A camera looking down sees the body's up axis turned away from it.
            fit.tilt = (-np.sin(np.radians(down)), np.sin(np.radians(spread)))
        fit.perspective = bool(perspective)
        if isinstance(proportions, str) and proportions == "default":
            from ..priors.proportions import default_proportions_prior

            proportions = default_proportions_prior()
        if proportions is not None:
            fit.dims_prior = proportions.mean_sigma()
            if not dims:
                # start from the proportions' mean (at the template's size)
                fit.dims0 = fit.dims_prior[0].copy()
    pose_prior = resolve_pose_prior(pose_prior, template)
    fit.prior = None if pose_prior is None else \
        pose_prior.with_broad(kin.prior_mean, kin.prior_sigma)
    fit.flips = flips
    result = fit.run()
    if calibrated:
        from ..files.plausible import fit_rms_warnings

        result.warnings.extend(fit_rms_warnings(result.rms, {v: cameras[v] for v in views}))
    if fit_dims and all(_seen_twice(a, views) < _MIN_FRAME_JOINTS for a in anchors):
        result.notes.append(ONE_VIEW_LENGTHS_NOTE)
    return result


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
            pose_prior.dof_names) != tuple(_kinematics(template).structure.dof_names)):
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


def check_camera_tilt(camera_tilt, what=None):
    """``(down, spread)`` degrees as floats (``initialize``'s ``camera_tilt``).

    Raises
    ------
    ZoopraxisError
        A tilt outside -90..90 degrees or a spread outside 0 (excluded)..90, named by
        ``what`` (default: the values).
    """
    down, spread = (float(x) for x in camera_tilt)
    if not (abs(down) < 90.0 and 0.0 < spread <= 90.0):
        raise ZoopraxisError(f"{what or f'camera tilt {down:g}:{spread:g}'}: the tilt must lie "
                             "between -90 and 90 degrees and the spread between 0 (excluded) "
                             "and 90")
    return down, spread


def flip_part(name):
    """A body part's name as ``FLIP_PARTS`` spell it ("the Left-Leg" -> "left leg"), or None."""
    text = " ".join(str(name).lower().replace("-", " ").replace("_", " ").split())
    if text.startswith("the "):
        text = text[4:]
    if text in ("whole body", "all"):
        text = "body"
    return text if text in FLIP_PARTS else None


def check_flips(flips, frames):
    """Flips as ``{frame: [part, ...]}`` with the parts' names checked.

    Raises
    ------
    ZoopraxisError
        An unknown part or a frame that is not an anchor frame.
    """
    out = {}
    for frame, parts in (flips or {}).items():
        if int(frame) not in frames:
            raise ZoopraxisError(f"depth flip: frame {frame} is not an anchor frame (anchors: "
                                 f"{', '.join(str(f) for f in frames) or 'none'})")
        for part in ([parts] if isinstance(parts, str) else parts):
            name = flip_part(part)
            if name is None:
                raise ZoopraxisError(f"depth flip at frame {frame}: unknown body part '{part}' "
                                     f"(one of: {', '.join(FLIP_PARTS)})")
            if name not in out.setdefault(int(frame), []):
                out[int(frame)].append(name)
    return out


def parse_flip(text):
    """``"80:left-leg"`` -> ``(80, "left leg")`` (the command line's ``--flip``).

    Raises
    ------
    ZoopraxisError
    """
    frame, _, part = str(text).partition(":")
    try:
        frame = int(frame)
    except ValueError:
        frame = None
    name = flip_part(part) if part else None
    if frame is None or name is None:
        raise ZoopraxisError(f"--flip '{text}': expected FRAME:PART, PART one of "
                             f"{', '.join(p.replace(' ', '-') for p in FLIP_PARTS)}")
    return frame, name


def _image_size(cameras, view, uv):
    if cameras and view in cameras:
        entry = cameras[view]
        return tuple(int(x) for x in getattr(entry, "image_size", entry))
    pts = uv[np.isfinite(uv).all(axis=-1)]
    if len(pts) == 0:
        return (640, 480)
    # Without a size, centre the principal point on the clicks (it is redundant with the
    # camera's image shift anyway).
    return tuple(int(np.ceil(2 * x + 1)) for x in pts.mean(axis=0))


class _Fit:
    """Shared driver: starting points per anchor, the joint problem, checks of the clicks."""

    calibrated = True

    def __init__(self, kin, obs, weights, views, anchors, dims0, fit_dims, warnings):
        self.kin = kin
        self.obs = obs
        self.weights = weights
        self.views = views
        self.anchors = anchors
        self.frames = [a.frame for a in anchors]
        self.dims0 = dims0
        self.fit_dims = fit_dims
        self.warnings = warnings
        self.ambiguous = False
        self.swapped = []
        self.prior = None       # PosePrior: the angle prior of frames seen in one view
        self.flips = {}         # anchor frame -> FLIP_PARTS the animator turned
        self.ambiguous_parts = {}
        self.flipped = {}

    # Subclasses give start(f) -> _State of one frame (F = 1), options(state, f, fit_dims) ->
    # _Problem options, depth_direction(state, f) and mirrored(state, f) for frames seen in one
    # view (else None), and _cameras(state) -> (cameras, view_cameras).

    def run(self):
        states = [self._apply_flips(self._frame(f), f) for f in range(len(self.frames))]
        state = self._merge(states)
        state, cost = self._solve_all(state)
        state = self._check_swaps(state, cost)
        self._check_outliers(state)
        return self._result(state)

    def _frame(self, f):
        """Best fit of one anchor frame alone; alternatives that fit as well are reported."""
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        state = self.start(f)
        state, cost, _ = _fit(self.kin, obs, w, state,
                              **self.options(state, f, fit_dims=self.fit_dims))
        state, cost, rivals = self._explore_limbs(state, cost, f)
        mirrored = self.mirrored(state, f)
        if mirrored is not None:
            alt, alt_cost, _ = _fit(self.kin, obs, w, mirrored,
                                    **self.options(mirrored, f, fit_dims=self.fit_dims))
            if self.prior is not None and self.depth_direction(state, f) is not None:
                # One view: the fit and its whole-body mirror, each limb at either depth
                # sign, judged by the clicks and the learned prior together.
                return self._choose_by_prior([state, alt], f)
            if alt_cost < cost:
                rivals.append((state, cost))
                state, cost = alt, alt_cost
            else:
                rivals.append((alt, alt_cost))
        seen = []
        for alt, alt_cost in rivals:
            if alt_cost > cost + 4 * AMBIGUOUS_COST or not self._moved_parts(state, alt):
                continue
            # Rivals come from short fits: converge the close ones before judging them.
            alt, alt_cost, _ = _fit(self.kin, obs, w, alt,
                                    **self.options(alt, f, fit_dims=self.fit_dims))
            if alt_cost > cost + AMBIGUOUS_COST:
                continue
            moved = self._moved_parts(state, alt)
            if moved and moved not in seen:
                seen.append(moved)
                self.ambiguous = True
                self._note_ambiguous(f, moved)
                self.warnings.append(
                    f"frame {self.frames[f]}: a pose with {_join(moved)} mirrored in depth "
                    f"fits about as well (cost {alt_cost:.1f} vs {cost:.1f} px^2); the 3D pose "
                    "is uncertain there: click this frame in another view")
        return state

    def _limb_variants(self, state, f):
        """Each limb's angles with its upper and lower part at either depth sign (§2.6's
        ambiguity of one view), posed by inverse kinematics on the reflected joints.

        Returns
        -------
        variants : list (limbs) of list of (angles of the limb's DOFs, flips)
            The first variant of each limb is the state's own.
        dofs : list (limbs) of array of int
        """
        kin = self.kin
        normal = self.depth_direction(state, f)
        names = kin.structure.dof_names
        Y = kin.forward(state.angles, state.dims)[0][0]
        X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
        variants, dofs = [], []
        for pivot, middle, upper, lower, prefixes in _FLIP_LIMBS:
            moved = np.array([k for k, n in enumerate(names) if n.startswith(prefixes)])
            own = [(state.angles[0, moved].copy(), ())]
            for flips in (("upper",), ("lower",), ("upper", "lower")):
                target = X.copy()
                shifted = 0.0
                for part, (centre, rows) in zip(("upper", "lower"),
                                                ((pivot, upper), (middle, lower))):
                    if part not in flips:
                        continue
                    rows = [JOINT_INDEX[j] for j in rows]
                    p = target[JOINT_INDEX[centre]]
                    n = normal(p)
                    shift = 2.0 * ((target[rows] - p) @ n)[:, None] * n
                    target[rows] -= shift
                    shifted = max(shifted, np.abs(shift).max())
                if shifted < _MIN_FLIP_M:
                    continue    # that part lies in the image plane: its mirror is itself
                angles = state.angles[0].copy()
                angles[moved] = kin.prior_mean[moved]
                _, angles, _ = _fit_3d(kin, target, state.dims, state.roots[0], angles,
                                       free_root=False, dofs=moved)
                own.append((angles[moved], flips))
            variants.append(own)
            dofs.append(moved)
        return variants, dofs

    def _click_costs(self, state, f, angles):
        """Robust click cost (px^2) of a frame's state with each row of ``angles`` (B, n)."""
        kin = self.kin
        Y = kin.forward(angles, state.dims)[0]                                # (B, 17, 3)
        X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
        costs = np.zeros(len(angles))
        for v, cam in enumerate(self._frame_cameras(state)):
            uv = self.obs[f, v]
            seen = np.isfinite(uv).all(axis=-1) & (self.weights[f, v] > 0)
            if cam is None or not seen.any():
                continue
            err = np.linalg.norm(cam.project(X[:, seen]) - uv[seen], axis=-1)  # (B, m)
            costs += np.sum(_rho_px(err), axis=1)
        return costs

    def _score(self, state, f, angles):
        """Negative log posterior (nats, up to a constant) of a frame's state with each row of
        ``angles``: the clicks under CLICK_SIGMA_PX noise, the learned pose prior and the
        camera tilt prior."""
        return self._click_costs(state, f, angles) / CLICK_SIGMA_PX**2 + self.prior.cost(angles) \
            + self._tilt_cost(state)

    def _tilt_cost(self, state):
        """Prior cost (nats) of how the camera of a one-view frame looks at the body."""
        return 0.0

    def _choose_by_prior(self, starts, f):
        """Choose the depth sign of every limb by the clicks and the learned pose prior.

        Every combination of the limbs' variants (:meth:`_limb_variants`) of every start (the
        fit and its whole-body mirror) is scored without refitting (reflected limbs project
        alike), the best is fitted, and the best combination that differs in some body part
        is fitted and scored too: if it is within one nat, the prior cannot decide between
        them and a warning names the parts.
        """
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        pool = []
        for k, state in enumerate(starts):
            variants, dofs = self._limb_variants(state, f)
            grids = np.meshgrid(*[np.arange(len(v)) for v in variants], indexing="ij")
            picks = np.stack([g.ravel() for g in grids], axis=1)            # (B, limbs)
            angles = np.repeat(state.angles, len(picks), axis=0)
            for i, (own, moved) in enumerate(zip(variants, dofs)):
                table = np.array([a for a, _ in own])
                angles[:, moved] = table[picks[:, i]]
            scores = self._score(state, f, angles)
            pool += [(float(sc), k, a) for sc, a in zip(scores, angles)]
        pool.sort(key=lambda t: t[0])

        def fitted(entry):
            _, k, angles = entry
            trial = starts[k].copy()
            trial.angles[0] = angles
            trial, _, _ = _fit(self.kin, obs, w, trial,
                               **self.options(trial, f, fit_dims=self.fit_dims))
            return trial, float(self._score(trial, f, trial.angles)[0])

        # The few best combinations that differ from each other are fitted and scored
        # again: a reflected limb posed by inverse kinematics can miss its clicks a little.
        chosen = []
        for entry in pool:
            if entry[0] > pool[0][0] + PRIOR_MARGIN or len(chosen) == PRIOR_REFITS:
                break
            trial = starts[entry[1]].copy()
            trial.angles[0] = entry[2]
            if all(self._moved_parts(other, trial) for other, _ in chosen):
                chosen.append((trial, entry))
        results = sorted((fitted(entry) for _, entry in chosen), key=lambda t: t[1])
        best, best_score = results[0]
        for alt, alt_score in results[1:]:
            moved = self._moved_parts(best, alt)
            if moved and alt_score < best_score + 1.0:
                self.ambiguous = True
                self._note_ambiguous(f, moved)
                self.warnings.append(
                    f"frame {self.frames[f]}: a pose with {_join(moved)} mirrored in depth "
                    f"fits about as well (clicks and pose prior: {alt_score:.1f} vs "
                    f"{best_score:.1f} nats); the 3D pose is uncertain there: click this frame "
                    "in another view")
                break
        return best

    def _frame_cameras(self, state):
        """The cameras of a one-frame state, per view (None where none)."""
        return list(state.cameras[0])

    def _explore_limbs(self, state, cost, f):
        """Try each limb (and each lower limb) turned to its depth mirror image, §2.6's
        ambiguity of a single view: a bone pointing towards the camera projects like one
        pointing away. Local fits cannot cross between the two, so each is started by inverse
        kinematics from the reflected joints and kept if it fits better (clicks and prior).

        Returns
        -------
        state : _State
        cost : float
        rivals : list of (_State, float)
            The alternatives met, for the ambiguity report.
        """
        rivals = []
        normal = self.depth_direction(state, f)
        if normal is None:
            return state, cost, rivals
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        names = self.kin.structure.dof_names
        for _ in range(2):
            improved = False
            for pivot, distal in LIMB_FLIPS:
                Y = self.kin.forward(state.angles, state.dims)[0][0]
                X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
                p = X[JOINT_INDEX[pivot]]
                n = normal(p)
                target = X.copy()
                rows = [JOINT_INDEX[j] for j in distal]
                shift = 2.0 * ((X[rows] - p) @ n)[:, None] * n
                if np.abs(shift).max() < _MIN_FLIP_M:
                    continue        # the limb lies in the image plane: its mirror is itself
                target[rows] -= shift
                moved = [k for k, name in enumerate(names)
                         if name.startswith((pivot + "_",) + tuple(j + "_" for j in distal))]
                angles = state.angles[0].copy()
                angles[moved] = self.kin.prior_mean[moved]
                root, angles, _ = _fit_3d(self.kin, target, state.dims, state.roots[0], angles,
                                          free_root=False, dofs=moved)
                trial = state.copy()
                trial.roots[0], trial.angles[0] = root, angles
                # A short fit tells the basins apart; the winner is refined below.
                trial, trial_cost, _ = _fit(self.kin, obs, w, trial, max_nfev=_EXPLORE_NFEV,
                                            **self.options(trial, f, fit_dims=self.fit_dims))
                if trial_cost < cost - 1e-6:
                    rivals.append((state, cost))
                    state, cost, improved = trial, trial_cost, True
                else:
                    rivals.append((trial, trial_cost))
            if not improved:
                break
            state, cost, _ = _fit(self.kin, obs, w, state,
                                  **self.options(state, f, fit_dims=self.fit_dims))
        return state, cost, rivals

    def _moved_parts(self, a, b):
        """Body parts (``BODY_PARTS`` names) whose joints differ by more than _AMBIGUOUS_M
        between two poses of a frame, with the trunks aligned."""
        Ya = self.kin.forward(a.angles, a.dims)[0][0]
        Yb = self.kin.forward(b.angles, b.dims)[0][0]
        R, t, scale = similarity_from_points(Ya[_TORSO], Yb[_TORSO])
        apart = np.linalg.norm(scale * Ya @ R.T + t - Yb, axis=-1)
        return [part for part, joints in BODY_PARTS.items()
                if apart[[JOINT_INDEX[j] for j in joints]].max() > _AMBIGUOUS_M]

    def _note_ambiguous(self, f, moved):
        """Remember the parts (``FLIP_PARTS``) another depth of frame ``f`` moves."""
        parts = self.ambiguous_parts.setdefault(self.frames[f], [])
        whole = any(m in ("the trunk", "the head") for m in moved)
        for name in ["body"] if whole else [m[len("the "):] for m in moved]:
            if name not in parts:
                parts.append(name)

    def _posterior(self, state, f):
        """Clicks (and the learned prior, if any, and the camera tilt prior) of a one-frame
        state, nats."""
        clicks = float(self._click_costs(state, f, state.angles)[0]) / CLICK_SIGMA_PX**2
        prior = 0.0 if self.prior is None else float(self.prior.cost(state.angles)[0])
        return clicks + prior + self._tilt_cost(state)

    def _apply_flips(self, state, f):
        """Turn the parts the animator named for frame ``f`` to their other depth."""
        frame = self.frames[f]
        for part in self.flips.get(frame, ()):
            if self.depth_direction(state, f) is None:
                self.warnings.append(f"frame {frame}: clicked in more than one view, so its "
                                     f"depth is seen; the flip of the {part} is ignored")
                continue
            flipped = self._flip(state, f, part)
            if flipped is None:
                self.warnings.append(f"frame {frame}: the {part} lies across the view (its "
                                     "other depth is the same pose); nothing to flip")
                continue
            before = float(self._click_costs(state, f, state.angles)[0])
            after = float(self._click_costs(flipped, f, flipped.angles)[0])
            clicks = int(np.isfinite(self.obs[f]).all(axis=-1).sum())
            if after > 2.0 * before + clicks * CLICK_SIGMA_PX ** 2:
                self.warnings.append(
                    f"frame {frame}: no pose with the {part} at its other depth fits the "
                    f"clicks (mean click error {np.sqrt(after / clicks):.1f} px against "
                    f"{np.sqrt(before / clicks):.1f} px); not flipped")
                continue
            state = flipped
            self.flipped.setdefault(frame, []).append(part)
        return state

    def _flip(self, state, f, part):
        """The best fitting pose of a one-view frame with ``part`` at its other depth: the
        limb's other depth configurations (upper part, lower part, both; posed by inverse
        kinematics on the reflected joints) or the whole body's mirror, each fitted; None if
        no such pose differs from ``state`` there."""
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        if part == "body":
            wanted = None
            trials = [self.mirrored(state, f)]
            if trials[0] is not None and self.prior is not None:
                # the mirror's limbs at either depth, chosen as for the fit itself (its notes
                # of ambiguity are about the mirror, not the pose returned: left out)
                kept, ambiguous = len(self.warnings), self.ambiguous
                parts = {k: list(v) for k, v in self.ambiguous_parts.items()}
                trial, _, _ = _fit(self.kin, obs, w, trials[0],
                                   **self.options(trials[0], f, fit_dims=self.fit_dims))
                trials.append(self._choose_by_prior([trial], f))
                del self.warnings[kept:]
                self.ambiguous, self.ambiguous_parts = ambiguous, parts
        else:
            side, limb = part.split()
            pivot = f"{side[0]}_{'shoulder' if limb == 'arm' else 'hip'}"
            variants, dofs = self._limb_variants(state, f)
            i = [limb_[0] for limb_ in _FLIP_LIMBS].index(pivot)
            trials, wanted = [], f"the {part}"
            for angles, _ in variants[i][1:]:
                trial = state.copy()
                trial.angles[0, dofs[i]] = angles
                trials.append(trial)
        best = None
        for trial in trials:
            if trial is None:
                continue
            trial, _, _ = _fit(self.kin, obs, w, trial,
                               **self.options(trial, f, fit_dims=self.fit_dims))
            moved = self._moved_parts(state, trial)
            if not moved or (wanted is not None and wanted not in moved):
                continue        # the fit went back to the pose it came from
            score = self._posterior(trial, f)
            if best is None or score < best[0]:
                best = (score, trial)
        return None if best is None else best[1]

    def _merge(self, states):
        dims = np.median([s.dims for s in states], axis=0)
        size = float(np.median([s.size for s in states]))
        return _State(dims, size, np.concatenate([s.roots for s in states]),
                      np.concatenate([s.angles for s in states]),
                      [s.cameras[0] for s in states])

    def _solve_all(self, state, obs=None):
        obs = self.obs if obs is None else obs
        state, cost, _ = _fit(self.kin, obs, self.weights, state,
                              **self.options(state, None, fit_dims=self.fit_dims))
        return state, cost

    def _check_swaps(self, state, cost):
        """Find click pairs that look exchanged (left for right) in one view, §2.6's clicks.

        A pair is a suspect when its clicks lie off the fit, each nearer the other's
        projection. A frame clicked in one view only bends towards wrong clicks, so there
        every pair is a suspect once some click lies far off. A suspect is confirmed when
        fitting with the pair exchanged removes most of what the pair costs; the fit then keeps
        the exchanged clicks and a warning names them.
        """
        for f in range(len(self.frames)):
            clicked = [v for v in range(len(self.views)) if np.isfinite(self.obs[f, v]).any()]
            for v in clicked:
                for _ in range(2):       # a second exchanged pair in the same view
                    err = self._errors(state)
                    found = self._best_swap(state, cost, err, f, v, single=len(clicked) == 1)
                    if found is None:
                        break
                    (left, right), alt, alt_cost, obs, before = found
                    alt_err = _Problem(self.kin, obs, self.weights, alt, free_root=False,
                                       free_angles=False, fit_dims=False).errors()
                    pair = [JOINT_INDEX[left], JOINT_INDEX[right]]
                    self.warnings.append(
                        f"frame {self.frames[f]}, view {self.views[v]}: {left} and {right} look "
                        f"swapped ({before:.1f} px from the fit, "
                        f"{np.nanmax(alt_err[f, v, pair]):.1f} px if exchanged); fitted them "
                        "exchanged: check the clicks")
                    self.swapped.append((self.frames[f], self.views[v], left, right))
                    self.obs, state, cost = obs, alt, alt_cost
        return state

    def _best_swap(self, state, cost, err, f, v, single):
        """The exchanged pair of view ``v`` in frame ``f`` that lowers the cost most, if any
        lowers it enough: ``((left, right), state, cost, obs, error before)`` or None."""
        o = self.obs[f, v]
        proj = self._projections(state)[f, v]
        far_off = np.nanmax(err[f, v]) > OUTLIER_PX
        best = None
        for left, right in LR_PAIRS:
            a, b = JOINT_INDEX[left], JOINT_INDEX[right]
            if not (np.isfinite(o[a]).all() and np.isfinite(o[b]).all()):
                continue
            apart = np.linalg.norm(o[a] - o[b])
            if apart < 2 * LOSS_SCALE_PX:
                continue
            e_now = err[f, v, a] ** 2 + err[f, v, b] ** 2
            e_swap = np.sum((proj[a] - o[b]) ** 2) + np.sum((proj[b] - o[a]) ** 2)
            off = np.sqrt(e_now / 2)
            suspect = (off > 3 * LOSS_SCALE_PX and off > 0.5 * apart and e_swap < 0.8 * e_now) \
                or (single and far_off)
            if not suspect:
                continue
            obs = self.obs.copy()
            obs[f, v, [a, b]] = obs[f, v, [b, a]]
            alt, alt_cost = self._solve_all(state, obs)
            # Exchanging must remove most of what the pair costs now.
            pair_cost = _robust_cost(err[f, v, [a, b]])
            gain = cost - alt_cost
            if gain > max(0.5 * pair_cost, 2 * LOSS_SCALE_PX ** 2) and \
                    (best is None or alt_cost < best[2]):
                best = ((left, right), alt, alt_cost, obs, off)
        return best

    def _check_outliers(self, state):
        err = self._errors(state)
        for f in range(len(self.frames)):
            for v in range(len(self.views)):
                e = err[f, v]
                if not np.isfinite(e).any():
                    continue
                typical = np.nanmedian(e)
                for j in np.flatnonzero(e > max(OUTLIER_PX, OUTLIER_RATIO * typical)):
                    self.warnings.append(
                        f"frame {self.frames[f]}, view {self.views[v]}: {STANDARD_JOINTS[j]} is "
                        f"{e[j]:.1f} px from the fitted pose (view median {typical:.1f} px): "
                        "check the click")

    def _errors(self, state):
        return _Problem(self.kin, self.obs, self.weights, state, free_root=False,
                        free_angles=False, fit_dims=False).errors()

    def _projections(self, state):
        problem = _Problem(self.kin, self.obs, np.ones_like(self.weights), state,
                           free_root=False, free_angles=False, fit_dims=False)
        x = problem.x0()
        X, _, _ = problem._joints(x)
        return problem._project(X, x[problem.off_cam:].reshape(-1, _CAM_PARAMS))[0]

    def _body(self, state):
        lengths = dict(zip(LENGTH_DIMS, state.dims))
        radii = {n: DEFAULT_DIMS[n] * state.size for n in RADIUS_DIMS}
        return make_body(self.kin.template, {**lengths, **radii})

    def _result(self, state):
        err = self._errors(state)
        body = self._body(state)
        errors = {}
        for f, frame in enumerate(self.frames):
            errors[frame] = {view: err[f, v] for v, view in enumerate(self.views)
                             if np.isfinite(err[f, v]).any()}
        rms = {}
        for v, view in enumerate(self.views):
            e = err[:, v]
            if np.isfinite(e).any():
                rms[view] = float(np.sqrt(np.nanmean(e ** 2)))
        poses = {frame: Pose(state.roots[f].copy(), body.clamp(state.angles[f]))
                 for f, frame in enumerate(self.frames)}
        cameras, view_cameras = self._cameras(state)
        return InitResult(body=body, poses=poses, cameras=cameras, view_cameras=view_cameras,
                          errors=errors, rms=rms, warnings=self.warnings,
                          ambiguous=self.ambiguous, calibrated=self.calibrated,
                          swapped=self.swapped,
                          ambiguous_parts={k: list(v) for k, v in self.ambiguous_parts.items()
                                           if v},
                          flipped={k: list(v) for k, v in self.flipped.items()})


def _join(words):
    """'a', 'a and b', 'a, b and c'."""
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


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


class _CalibratedFit(_Fit):
    """Calibrated views: one world pose per anchor frame."""

    calibrated = True

    def __init__(self, kin, obs, weights, cameras, views, anchors, dims0, fit_dims, warnings):
        super().__init__(kin, obs, weights, views, anchors, dims0, fit_dims, warnings)
        self.cams = cameras

    def options(self, state, f, fit_dims):
        return dict(free_root=True, fit_dims=fit_dims, calibrated=True)

    def _state(self, root, angles, dims, size=1.0):
        return _State(np.array(dims, float), size, root[None].copy(), angles[None].copy(),
                      [list(self.cams)])

    def start(self, f):
        kin = self.kin
        obs = self.obs[f]
        X = triangulate(self.cams, obs)
        angles0 = kin.start_angles()
        Y_rest = kin.forward(angles0[None], self.dims0)[0][0]
        ok = [j for j in _TORSO if np.isfinite(X[j]).all()]
        if len(ok) >= 3 and np.linalg.matrix_rank(X[ok] - X[ok].mean(axis=0), tol=0.02) >= 2:
            R, t, scale = similarity_from_points(Y_rest[ok], X[ok])
            # Clicked bodies differ in size: start the lengths at the trunk's (when fitted).
            scale = float(np.clip(scale, *DIMS_RANGE)) if self.fit_dims else 1.0
            dims = self.dims0 * scale
            root, angles, _ = _fit_3d(kin, X, dims, se3.transform(R, t), angles0)
            angles = _fit_limbs_3d(kin, X, dims, root, angles)
            return self._state(root, angles, dims, scale)
        return self._multistart(f, angles0, Y_rest)

    def _multistart(self, f, angles0, Y_rest):
        """Few views see the torso: try upright roots turned every 45 degrees about Z, each
        placed on the ray through the clicked pelvis at the depth its size suggests."""
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        counts = np.isfinite(obs[0]).all(axis=-1).sum(axis=-1)
        v = int(np.argmax(counts))
        cam, uv = self.cams[v], obs[0, v]
        seen = np.isfinite(uv).all(axis=-1)
        ppm = _image_scale(uv, Y_rest)
        depth = cam.K[0, 0] / ppm
        anchor_px = uv[JOINT_INDEX["pelvis"]] if seen[JOINT_INDEX["pelvis"]] \
            else uv[seen].mean(axis=0)
        centre = cam.unproject(anchor_px, depth)
        best = None
        for yaw in np.radians(np.arange(0, 360, 45)):
            root = se3.transform(_rot_z(yaw), centre)
            state = self._state(root, angles0, self.dims0)
            fitted, cost, _ = _fit(self.kin, obs, w, state, free_root=True, fit_dims=False,
                                   max_nfev=60)
            if best is None or cost < best[1]:
                best = (fitted, cost)
        return best[0]

    def depth_direction(self, state, f):
        """For a frame clicked in one view only: the viewing ray's direction at a point."""
        clicked = [v for v in range(len(self.views)) if np.isfinite(self.obs[f, v]).any()]
        if len(clicked) != 1:
            return None
        centre = self.cams[clicked[0]].center
        return lambda p: (p - centre) / np.linalg.norm(p - centre)

    def mirrored(self, state, f):
        """The depth-flipped pose of a frame clicked in one view only (else None): the joints
        reflected in the plane through the pelvis facing the camera."""
        clicked = [v for v in range(len(self.views)) if np.isfinite(self.obs[f, v]).any()]
        if len(clicked) != 1:
            return None
        cam = self.cams[clicked[0]]
        Y = self.kin.forward(state.angles, state.dims)[0][0]
        X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
        pelvis = X[JOINT_INDEX["pelvis"]]
        n = pelvis - cam.center
        n /= np.linalg.norm(n)
        target = X - 2.0 * ((X - pelvis) @ n)[:, None] * n
        R, t, _ = similarity_from_points(Y[_TORSO], target[_TORSO], with_scale=False)
        root, angles, _ = _fit_3d(self.kin, target, state.dims, se3.transform(R, t),
                                  self.kin.start_angles())
        return self._state(root, angles, state.dims, state.size)

    def _cameras(self, state):
        return dict(zip(self.views, self.cams)), None


class _UncalibratedFit(_Fit):
    """Uncalibrated views (Bregler & Malik §2.3): a scaled orthographic camera per view and
    anchor, the body root at the identity, angles shared by the views of a frame."""

    calibrated = False

    dims_prior = None       # (mean, sigma) of the lengths (proportions.ProportionsPrior)

    def __init__(self, kin, obs, weights, sizes, views, anchors, dims0, fit_dims, warnings):
        super().__init__(kin, obs, weights, views, anchors, dims0, fit_dims, warnings)
        self.sizes = sizes
        counts = np.isfinite(obs).all(axis=-1).sum(axis=-1)               # (F, V)
        self.usable = counts >= _MIN_VIEW_JOINTS
        for f, v in np.argwhere((counts > 0) & ~self.usable):
            warnings.append(f"frame {anchors[f].frame}, view {views[v]}: only {counts[f, v]} "
                            f"joints clicked (need {_MIN_VIEW_JOINTS} to place an uncalibrated "
                            "view); view left out of this frame")
            self.weights[f, v] = 0.0

    def options(self, state, f, fit_dims):
        free = np.array([[c is not None for c in row] for row in state.cameras])
        options = dict(free_root=False, free_cams=free, fit_dims=fit_dims, calibrated=False,
                       perspective=self.perspective, dims_prior=self.dims_prior)
        if self.prior is not None and PRIOR_WEIGHT > 0 and self._prior_in_fit:
            # Frames seen in one view: the learned prior decides what the clicks leave free.
            options.update(pose_prior=self.prior, prior_frames=free.sum(axis=1) == 1)
        if self.tilt is not None:
            options.update(tilt=self.tilt, tilt_frames=free.sum(axis=1) == 1)
        return options

    _prior_in_fit = True

    def _frame(self, f):
        """As :meth:`_Fit._frame`; a frame seen in one view is searched twice, with the learned
        prior in the fit and without it (the everyday-pose Gaussian instead), and the second
        result is fitted again with the prior. The lower score (clicks and learned prior) wins.

        The prior pulls each local fit towards the captures' poses, which can lead the search
        of depth signs into a wrong basin for poses unlike them; the search without it finds
        the basin the clicks favour, and the final score compares both on the same terms.
        """
        if self.prior is None or PRIOR_WEIGHT <= 0 or self.usable[f].sum() != 1:
            return super()._frame(f)
        kept, ambiguous = len(self.warnings), self.ambiguous
        frame = self.frames[f]
        parts = list(self.ambiguous_parts.get(frame, []))
        found = []
        searches = [(True, None), (False, None)] + [(True, s) for s in self._exemplars(f)]
        for in_fit, start in searches:
            self._prior_in_fit, self.ambiguous = in_fit, ambiguous
            self._start = start
            self.ambiguous_parts[frame] = list(parts)
            try:
                state = super()._frame(f)
            finally:
                self._prior_in_fit, self._start = True, None
            if not in_fit:
                state, _, _ = _fit(self.kin, self.obs[f:f + 1], self.weights[f:f + 1], state,
                                   **self.options(state, f, fit_dims=self.fit_dims))
            found.append((float(self._score(state, f, state.angles)[0]), len(found), state,
                          self.warnings[kept:], self.ambiguous, self.ambiguous_parts[frame]))
            del self.warnings[kept:]
        _, _, state, notes, self.ambiguous, chosen = min(found, key=lambda t: t[:2])
        self.warnings += notes
        if chosen:
            self.ambiguous_parts[frame] = chosen
        else:
            self.ambiguous_parts.pop(frame, None)
        return state

    _start = None       # a start of _frame's search other than the body turns
    _pool = None        # _exemplars' (prior poses, their joints at the starting lengths)

    def start(self, f):
        """Best single-view fit over body turns, then each other view's camera alone."""
        if self._start is not None:
            return self._start.copy()
        return self._starts(f, 2)[0]

    def _exemplars(self, f):
        """Starts for a frame seen in one view from the learned prior's own poses: the
        EXEMPLAR_STARTS poses (at the starting lengths) whose joints, under the scaled
        orthographic camera nearest to their best affine camera, fall nearest to the clicks
        (robust cost), apart from each other by EXEMPLAR_APART_DEG in some angle.

        The body turns and the limbs' depth signs reach the poses near the everyday mean; a
        pose of the captures far from it (a deep lunge, an arm across the body) is found from
        the nearest captured pose instead.
        """
        if EXEMPLAR_STARTS <= 0 or len(self.prior.samples) == 0:
            return []
        v = int(np.flatnonzero(self.usable[f])[0])
        uv = self.obs[f, v]
        seen = np.isfinite(uv).all(axis=-1) & (self.weights[f, v] > 0)
        if self._pool is None:      # the prior's poses at the starting lengths, once a fit
            samples = self.prior.samples
            if len(samples) > EXEMPLAR_POOL:
                samples = samples[np.linspace(0, len(samples) - 1, EXEMPLAR_POOL).astype(int)]
            self._pool = samples, np.concatenate(
                [self.kin.forward(chunk, self.dims0)[0]
                 for chunk in np.array_split(samples, -(-len(samples) // 500))])
        samples, Y = self._pool
        Ys = Y[:, seen]                                                        # (N, m, 3)
        Yc = Ys - Ys.mean(axis=1, keepdims=True)
        target = uv[seen] - uv[seen].mean(axis=0)                              # (m, 2)
        # The best affine camera of each pose, then the scaled rotation nearest to it.
        G = np.swapaxes(Yc, 1, 2) @ Yc + 1e-9 * np.eye(3)
        A = np.swapaxes(np.linalg.solve(G, np.swapaxes(Yc, 1, 2) @ target), 1, 2)  # (N, 2, 3)
        U, S, Vt = np.linalg.svd(A, full_matrices=False)
        rows = U @ Vt                                                          # (N, 2, 3)
        scale = S.mean(axis=1)
        err = np.linalg.norm(scale[:, None, None] * (Yc @ np.swapaxes(rows, 1, 2)) - target,
                             axis=-1)
        cost = np.sum(_rho_px(err), axis=1)
        picked = []
        for _ in range(EXEMPLAR_STARTS):
            if not np.isfinite(cost).any():
                break
            i = int(np.argmin(cost))
            picked.append(i)
            near = np.abs(samples - samples[i]).max(axis=1) < np.radians(EXEMPLAR_APART_DEG)
            cost = np.where(near, np.inf, cost)
        size = self.sizes[v]
        centre = ((size[0] - 1) / 2, (size[1] - 1) / 2)
        starts = []
        for i in picked:
            R = np.vstack([rows[i], np.cross(rows[i][0], rows[i][1])])
            shift = (uv[seen].mean(axis=0) - centre) / scale[i] - R[:2] @ Ys[i].mean(axis=0)
            cams = [None] * len(self.views)
            cams[v] = ScaledOrthoCamera(self.views[v], size, float(scale[i]), R=R,
                                        t=[shift[0], shift[1], 10.0], c=centre)
            angles = np.clip(samples[i], self.kin.lower, self.kin.upper)
            starts.append(_State(self.dims0.copy(), 1.0, np.eye(4)[None], angles[None], [cams]))
        return starts

    def _starts(self, f, keep):
        """Single-view fits from the ``keep`` best body turns, best first, each with the other
        views' cameras placed."""
        kin = self.kin
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        views = list(np.flatnonzero(self.usable[f]))
        counts = np.isfinite(obs[0]).all(axis=-1).sum(axis=-1)
        views.sort(key=lambda v: -counts[v])
        angles0 = kin.start_angles()
        Y = kin.forward(angles0[None], self.dims0)[0][0]
        first = views[0]
        only = np.zeros_like(w)
        only[0, first] = w[0, first]
        free = np.zeros((1, len(self.views)), bool)
        free[0, first] = True
        # The camera alone for the body at rest, turned every 45 degrees, ranks the turns
        # cheaply; the best few are then fitted with the angles.
        trials = []
        for yaw in np.radians(np.arange(0, 360, 45)):
            cams = [None] * len(self.views)
            cams[first] = _ortho_camera(self.views[first], self.sizes[first], obs[0, first], Y,
                                        yaw)
            state = _State(self.dims0.copy(), 1.0, np.eye(4)[None], angles0[None].copy(), [cams])
            trials.append(_fit(kin, obs, only, state, free_root=False, free_angles=False,
                               fit_dims=False, free_cams=free, calibrated=False,
                               max_nfev=30)[:2])
        trials.sort(key=lambda t: t[1])
        fits = []
        for state, _ in trials[:keep]:
            fitted, cost, _ = _fit(kin, obs, only, state, free_root=False, fit_dims=False,
                                   free_cams=free, calibrated=False, max_nfev=100)
            fits.append((cost, len(fits), fitted))
        fits.sort(key=lambda t: t[:2])
        out = []
        for _, _, state in fits:
            Y = kin.forward(state.angles, state.dims)[0][0]
            for v in views[1:]:
                state.cameras[0][v] = self._place_camera(state, f, v, Y)
            out.append(state)
        return out

    def _place_camera(self, state, f, v, Y):
        """Camera of view ``v`` alone for a known body: the affine camera of the clicks, made
        a scaled rotation, then fitted robustly."""
        obs = self.obs[f:f + 1]
        only = np.zeros_like(self.weights[f:f + 1])
        only[0, v] = self.weights[f, v]
        trial = state.copy()
        trial.cameras[0][v] = _affine_camera(self.views[v], self.sizes[v], obs[0, v], Y)
        free = np.zeros((1, len(self.views)), bool)
        free[0, v] = True
        fitted, _, _ = _fit(self.kin, obs, only, trial, free_root=False, free_angles=False,
                            free_cams=free, fit_dims=False, calibrated=False, max_nfev=50)
        return fitted.cameras[0][v]

    tilt = None     # (mean, sigma): see CAMERA_TILT_DEG and _Problem
    perspective = False     # the views' perspective (kappa) is fitted: see KAPPA_MAX

    def _tilt_cost(self, state):
        cams = [c for c in state.cameras[0] if c is not None]
        if self.tilt is None or len(cams) != 1:
            return 0.0
        return 0.5 * ((cams[0].R[2, 2] - self.tilt[0]) / self.tilt[1]) ** 2

    def depth_direction(self, state, f):
        """For a frame with one usable view: that camera's viewing direction."""
        views = [v for v in range(len(self.views)) if state.cameras[0][v] is not None]
        if len(views) != 1:
            return None
        forward = state.cameras[0][views[0]].R[2]
        return lambda p: forward

    def mirrored(self, state, f):
        """The depth-flipped pose: the joints reflected in the first view's image plane, posed
        again by inverse kinematics, with every view's camera turned to see the same image."""
        views = [v for v in range(len(self.views)) if state.cameras[0][v] is not None]
        n = state.cameras[0][views[0]].R[2]
        Y = self.kin.forward(state.angles, state.dims)[0][0]
        M = np.eye(3) - 2.0 * np.outer(n, n)
        target = Y @ M
        R, t, _ = similarity_from_points(Y[_TORSO], target[_TORSO], with_scale=False)
        root, angles, _ = _fit_3d(self.kin, target, state.dims, se3.transform(R, t),
                                  self.kin.start_angles())
        out = _State(state.dims.copy(), state.size, np.eye(4)[None], angles[None],
                     [list(state.cameras[0])])
        for v in views:
            cam = state.cameras[0][v]
            # image = s (R_v Y + t_v)_xy and Y ~ M (R_T Y' + p_T): the new camera keeps the
            # first two rows of R_v M R_T (any such pair completes to a rotation).
            rows = cam.R @ M @ root[:3, :3]
            R_new = np.vstack([rows[:2], np.cross(rows[0], rows[1])])
            shift = cam.t[:2] + (cam.R @ M @ root[:3, 3])[:2]
            out.cameras[0][v] = cam.replace(R=R_new, t=[shift[0], shift[1], cam.t[2]])
        return out

    def _cameras(self, state):
        view_cameras = {}
        for f, frame in enumerate(self.frames):
            view_cameras[frame] = {view: state.cameras[f][v] for v, view in enumerate(self.views)
                                   if state.cameras[f][v] is not None}
        return dict(view_cameras[self.frames[0]]), view_cameras


# ---------------------------------------------------------------------------------------------
# Model fine-tuning (§2.7)
# ---------------------------------------------------------------------------------------------

@dataclass
class RefineResult:
    """What :func:`refine_dims` found.

    Attributes
    ----------
    body : BodyModel
        With the refined lengths.
    poses : dict of int to Pose
    cameras : dict
        As given, or per frame with the refined scaled orthographic cameras.
    rms : dict of str to float
        Root-mean-square observation error per view, pixels (unweighted).
    """

    body: object
    poses: dict
    cameras: dict
    rms: dict


def refine_dims(body, poses_by_frame, observations, cameras, *, weights=None, fit_poses=True,
                loss_scale=LOSS_SCALE_PX, dims_range=DIMS_RANGE):
    """Refine the body dimensions (and the poses) over many frames: model fine-tuning (§2.7).

    One joint problem over all frames: the lengths are shared, every frame has its own pose,
    and the projected model joints should meet the 2D joint observations (the tracker's
    projected joints, the anchors' clicks) with the given weights.

    Parameters
    ----------
    body : BodyModel
        Current model; its lengths are the start, its template is kept.
    poses_by_frame : dict of int to Pose
    observations : dict of int to dict of str to array, shape (17, 2)
        2D joints per frame and view, pixels; NaN where not observed.
    cameras : dict of str to camera, or dict of int to dict of str to camera
        Static cameras per view: the roots and angles are refined. Or cameras per frame and
        view (Bregler & Malik's one pose per view): scaled orthographic ones are refined with
        the angles and the roots stay as given.
    weights : dict of int to dict of str to array, shape (17,), optional
        Confidence of each observation (default 1).
    fit_poses : bool
        Refine the poses too; otherwise only the dimensions move.
    loss_scale : float
        Robust loss scale, pixels.
    dims_range : (float, float)
        Bounds of the lengths as multiples of the template's defaults.

    Returns
    -------
    result : RefineResult

    Raises
    ------
    ZoopraxisError
        A frame without a pose, a view without a camera, a wrongly shaped observation.
    """
    frames = sorted(observations)
    if not frames:
        raise ZoopraxisError("refine_dims: no observations")
    per_frame = all(isinstance(k, (int, np.integer)) for k in cameras) and bool(cameras)
    views = []
    for f in frames:
        if f not in poses_by_frame:
            raise ZoopraxisError(f"refine_dims: frame {f} has observations but no pose")
        views += [v for v in observations[f] if v not in views]
    obs = np.full((len(frames), len(views), N_JOINTS, 2), np.nan)
    w = np.ones(obs.shape[:3])
    cams = []
    for i, f in enumerate(frames):
        row = []
        for k, v in enumerate(views):
            if v in observations[f]:
                a = np.asarray(observations[f][v], float)
                if a.shape != (N_JOINTS, 2):
                    raise ZoopraxisError(f"refine_dims: frame {f}, view {v}: observations must "
                                         f"have shape (17, 2), got {a.shape}")
                obs[i, k] = a
                if weights is not None and f in weights and v in weights[f]:
                    w[i, k] = np.asarray(weights[f][v], float)
            source = cameras.get(f, {}) if per_frame else cameras
            if v not in source and np.isfinite(obs[i, k]).any():
                where = f"frame {f}, " if per_frame else ""
                raise ZoopraxisError(f"refine_dims: {where}view {v} has no camera")
            row.append(source.get(v))
        cams.append(row)
    kin = _kinematics(body.template)
    dims = body.dims_vector(LENGTH_DIMS)
    size = float(np.median(dims / kin.default_dims))
    state = _State(dims, size, np.array([poses_by_frame[f].root for f in frames]),
                   np.array([poses_by_frame[f].angles for f in frames]), cams)
    free_cams = np.array([[per_frame and isinstance(c, ScaledOrthoCamera) and fit_poses
                           for c in row] for row in cams])
    calibrated = not free_cams.any()
    fitted, _, problem = _fit(kin, obs, w, state, free_root=fit_poses and not free_cams.any(),
                              free_angles=fit_poses, free_cams=free_cams, fit_dims=True,
                              calibrated=calibrated, loss_scale=loss_scale,
                              dims_range=dims_range)
    lengths = dict(zip(LENGTH_DIMS, fitted.dims))
    radii = {n: body.dims[n] * fitted.size / size for n in RADIUS_DIMS}
    new_body = body.with_dims({**lengths, **radii})
    poses = {f: Pose(fitted.roots[i].copy(), new_body.clamp(fitted.angles[i]))
             for i, f in enumerate(frames)}
    err = problem.errors(fitted)
    rms = {v: float(np.sqrt(np.nanmean(err[:, k] ** 2))) for k, v in enumerate(views)
           if np.isfinite(err[:, k]).any()}
    if per_frame:
        out_cams = {f: {v: fitted.cameras[i][k] for k, v in enumerate(views)
                        if fitted.cameras[i][k] is not None} for i, f in enumerate(frames)}
    else:
        out_cams = dict(cameras)
    return RefineResult(new_body, poses, out_cams, rms)


__all__ = ["initialize", "InitResult", "PosePrior", "default_pose_prior", "mirror_angles",
           "take_angles", "resolve_pose_prior",
           "init_from_json", "read_init", "refine_dims", "RefineResult",
           "triangulate", "similarity_from_points", "procrustes_mpjpe", "LR_PAIRS",
           "LOSS_SCALE_PX", "DIMS_RANGE"]
