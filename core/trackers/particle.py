"""Particle filter over the articulated body: Sidenbladh, Black & Fleet (2000), §4.1.

The posterior over pose (and velocity, or walking phase) is a set of weighted samples. Each frame
(sequential importance resampling):

1. draw N samples from the previous posterior (systematic resampling of the weights);
2. move each by the temporal prior ``p(phi_t | phi_{t-1}, V_{t-1})`` (:mod:`motion_prior`);
3. weight each by the image likelihood ``p(I_t | phi_t, R_t)`` (:mod:`likelihood`), whose
   appearance ``R_t`` is I(t-1) mapped onto the model at the previous estimate, or at each
   sample's own previous pose (eq. 2; ``appearance``), tempered when the weights would fall
   on too few particles (:func:`tempered_weights`);
4. report the expected pose (the weighted mean, §7) and the posterior's spread.

One call of :meth:`ParticleFilter.step` is one frame, so a caller (the command line, or the
hybrid tracker that hands the expected pose to the differential tracker) drives the filter frame
by frame and reads the expected pose, its spread and the particle set after each::

    pf = ParticleFilter(body, cameras, WalkingPrior(body, fps=30), n_particles=2000, seed=0)
    step = pf.start(images_of_frame_0, pose_0)        # one image per camera
    for images in later_frames:
        step = pf.step(images)                        # step.pose, step.spread, step.status,
                                                      # step.roots, step.angles, step.weights

Everything is vectorized over the particles: the kinematics of all particles is one batched
product of exponentials (:class:`BatchKinematics`), the likelihood a few array operations per
limb over all particles and sampled points.

Convention: world Z up, metres; pose parameters ordered as :func:`motion_prior.param_names`
(pelvis position, root rotation vector in world axes, DOF angles). The spread of the rotation is
that of the rotation vectors ``log(R_i R_mean^T)``, i.e. of the left (world-frame) increment that
takes the mean root rotation to each particle's.
"""

from dataclasses import dataclass

import numpy as np

from ..geometry import se3
from ..body.body import Pose
from ..errors import ZoopraxisError
from .likelihood import ImageLikelihood, prepare_image
from ..priors.motion_prior import param_names

STATUSES = ("ok", "uncertain", "lost")
APPEARANCES = ("estimate", "particle")


class BatchKinematics:
    """Forward kinematics of many poses of one body (Bregler & Malik eq. 21), fast.

    Every DOF of the body is revolute with a unit axis ``w`` through a point ``q``, so its
    exponential has the closed form ``R = I + sin(a) W + (1 - cos(a)) W^2``,
    ``p = (I - R) q`` (Rodrigues) with ``W = hat(w)`` precomputed; the segments then compose
    down the tree with one batched 4x4 product per DOF. Same result as ``body.seg2world``.

    Parameters
    ----------
    body : BodyModel
    """

    def __init__(self, body):
        self.body = body
        w = body.twists[:, 3:]
        if not np.allclose(np.linalg.norm(w, axis=1), 1.0):
            raise ZoopraxisError(f"body template '{body.template}': every DOF must be a "
                                 "revolute joint with a unit axis")
        W = se3.hat3(w)                                               # (n, 3, 3)
        self.W, self.W2 = W, W @ W
        # (I - R) q = -(sin(a) W q + (1 - cos(a)) W^2 q): the translation needs only these.
        self.Wq = np.einsum("kij,kj->ki", W, body.dof_points)
        self.W2q = np.einsum("kij,kj->ki", self.W2, body.dof_points)
        self._dofs_of = [np.flatnonzero(body.dof_segment == k) for k in range(body.n_segments)]

    def seg2world(self, roots, angles):
        """World transforms of every segment of every pose.

        Parameters
        ----------
        roots : array, shape (N, 4, 4)
            ``world_from_pelvis`` per pose.
        angles : array, shape (N, n_dofs)

        Returns
        -------
        seg2world : array, shape (N, S, 4, 4)
        """
        roots = np.asarray(roots, float)
        angles = np.asarray(angles, float)
        N, n = angles.shape
        # DOF-major layout: every E[j] and T[k] below is one contiguous (N, 4, 4) block.
        s = np.sin(angles).T[:, :, None, None]
        c = (1.0 - np.cos(angles)).T[:, :, None, None]
        E = np.zeros((n, N, 4, 4))
        E[:, :, :3, :3] = np.eye(3) + s * self.W[:, None] + c * self.W2[:, None]
        E[:, :, :3, 3] = -(s[..., 0] * self.Wq[:, None] + c[..., 0] * self.W2q[:, None])
        E[:, :, 3, 3] = 1.0
        T = np.empty((self.body.n_segments, N, 4, 4))
        for k, parent in enumerate(self.body.segment_parents):
            M = roots if parent < 0 else T[parent]
            for j in self._dofs_of[k]:
                M = M @ E[j]
            T[k] = M
        return np.ascontiguousarray(T.transpose(1, 0, 2, 3))

    def joints(self, seg2world):
        """The 17 standard joints of every pose, (N, 17, 3), from its segment transforms."""
        T = seg2world[:, self.body.landmark_segment]                  # (N, 17, 4, 4)
        return np.einsum("njab,jb->nja", T[:, :, :3, :3], self.body.landmark_points) \
            + T[:, :, :3, 3]


def partitions(body):
    """Pose parameters that move limbs independently, and the segments each moves.

    The likelihood is a product over limbs (eq. 12), and a leg's angles change only the leg's
    factors: partitioned sampling (MacCormick & Isard) can search the leg with the rest held.
    The partition: the root (all segments), the trunk and neck angles (the segments above the
    pelvis), then each leg and each arm; parents before children.

    Parameters
    ----------
    body : BodyModel

    Returns
    -------
    groups : list of (array of int, array of int)
        Pose parameter columns (:func:`motion_prior.param_names` order) and the segments
        whose pose they change (the DOFs' segments and all their descendants).
    """
    below = [{k} for k in range(body.n_segments)]
    for k in range(body.n_segments - 1, -1, -1):        # parents precede their children
        parent = body.segment_parents[k]
        if parent >= 0:
            below[parent] |= below[k]
    groups = [(np.arange(6), np.arange(body.n_segments))]
    parts = [("lumbar", "thorax", "neck")]
    for limb in (("hip", "knee", "ankle"), ("shoulder", "elbow")):
        for side in "lr":
            parts.append(tuple(f"{side}_{j}" for j in limb))
    for prefixes in parts:
        dofs = [i for i, name in enumerate(body.dof_names) if name.startswith(prefixes)]
        if not dofs:
            continue
        segments = set()
        for i in dofs:
            segments |= below[body.dof_segment[i]]
        groups.append((6 + np.array(dofs), np.array(sorted(segments))))
    return groups


def systematic_resample(weights, rng):
    """Indices of N draws from the weights by systematic (low-variance) resampling.

    One uniform offset and N evenly spaced pointers into the cumulative weights: every particle
    with weight ``w`` is drawn ``floor(N w)`` or ``ceil(N w)`` times.

    Parameters
    ----------
    weights : array, shape (N,)
        Normalized weights.
    rng : numpy.random.Generator

    Returns
    -------
    index : array of int, shape (N,)
    """
    N = len(weights)
    cumulative = np.cumsum(weights)
    cumulative[-1] = 1.0
    pointers = (rng.uniform() + np.arange(N)) / N
    return np.searchsorted(cumulative, pointers)


def tempered_weights(log_likelihood, min_ess, log_prior=None):
    """Normalized weights ``w ~ L^b``, with the largest ``b <= 1`` that keeps enough particles.

    The likelihood multiplies hundreds of pixels as if independent; neighbouring pixels are
    not, and the model is not the body, so the evidence is overcounted and a frame's weights
    can fall on a handful of particles, which resampling then copies over the whole set (the
    posterior collapses, most visibly along directions the image does not constrain, such as
    the twist of a straight arm). As in the annealed particle filter (Deutscher et al., the
    paper's [7]), the log-likelihood is scaled down just enough that the effective sample size
    ``1 / sum w^2`` stays at ``min_ess`` times the number of particles.

    Parameters
    ----------
    log_likelihood : array, shape (N,)
    min_ess : float
        Smallest effective sample size as a share of N (0 disables the tempering).
    log_prior : array, shape (N,), optional
        A log-density the weights are multiplied by untempered, ``w ~ L^b p``: a proper
        density over the pose does not overcount evidence as the pixels do.

    Returns
    -------
    weights : array, shape (N,)
    b : float
        The exponent used, in (0, 1].
    """
    d = np.asarray(log_likelihood, float)
    d = d - d.max()
    target = min_ess * len(d)
    p = np.zeros_like(d) if log_prior is None else np.asarray(log_prior, float)

    def weights(b):
        x = b * d + p
        w = np.exp(x - x.max())
        return w / w.sum()

    w = weights(1.0)
    if min_ess <= 0 or 1.0 / np.sum(w ** 2) >= target:
        return w, 1.0
    lo, hi = 0.0, 1.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        if 1.0 / np.sum(weights(mid) ** 2) >= target:
            lo = mid
        else:
            hi = mid
    return weights(lo), lo


def posterior_mean(roots, angles, weights):
    """Expected pose and per-parameter spread of a weighted particle set (§7).

    Translations and angles average linearly. Rotations average as the weighted chordal mean
    (the rotation nearest to ``sum w_i R_i``, by SVD), which equals the Karcher mean to
    second order for the concentrated clouds a tracker has.

    Parameters
    ----------
    roots : array, shape (N, 4, 4)
    angles : array, shape (N, n_dofs)
    weights : array, shape (N,)
        Normalized.

    Returns
    -------
    pose : Pose
    spread : array, shape (6 + n_dofs,)
        Weighted standard deviations: pelvis position (metres), root rotation vector about the
        mean (radians, world axes), angles (radians). Shaped for ``TrackResult.spread``.
    """
    w = np.asarray(weights, float)
    t = w @ roots[:, :3, 3]
    R = se3.orthonormalize(np.einsum("n,nij->ij", w, roots[:, :3, :3]))
    a = w @ angles
    r = se3.log_so3(roots[:, :3, :3] @ R.T)
    std = np.sqrt(np.concatenate([
        w @ (roots[:, :3, 3] - t) ** 2,
        w @ r ** 2,
        w @ (angles - a) ** 2]))
    return Pose(se3.transform(R, t), a), std


@dataclass
class FilterStep:
    """The filter's answer for one frame.

    Attributes
    ----------
    frame : int
        Frames since :meth:`ParticleFilter.start` (0 there).
    pose : Pose
        Expected pose, the weighted mean of the particles (§7).
    spread : array, shape (6 + n_dofs,)
        Posterior standard deviation per pose parameter (see :func:`posterior_mean`).
    joints : array, shape (17, 3)
        Standard joints of the expected pose, world metres.
    joint_spread : array, shape (17,)
        Posterior spread of each standard joint: RMS distance of the particles' joint from
        the weighted mean joint, metres.
    status : {"ok", "uncertain", "lost"}
        ``lost`` when the particles explain few of the compared pixels (weighted inlier share
        below ``lost_inliers``); ``uncertain`` when the joints spread more than
        ``uncertain_spread`` (RMS over joints); else ``ok``.
    ess : float
        Effective sample size ``1 / sum w^2``.
    temper : float
        Exponent the frame's likelihood was raised to (1 unless tempered).
    inliers : float
        Weighted mean share of compared pixels that match (see ``LikelihoodResult``).
    roots : array, shape (N, 4, 4)
    angles : array, shape (N, n_dofs)
    weights : array, shape (N,)
    log_likelihood : array, shape (N,)
    state : dict of arrays
        The prior's state of every particle (velocities, phase, ...).
    """

    frame: int
    pose: Pose
    spread: np.ndarray
    joints: np.ndarray
    joint_spread: np.ndarray
    status: str
    ess: float
    temper: float
    inliers: float
    roots: np.ndarray
    angles: np.ndarray
    weights: np.ndarray
    log_likelihood: np.ndarray
    state: dict


class ParticleFilter:
    """Sequential importance resampling over the articulated body (§4.1).

    Parameters
    ----------
    body : BodyModel
    cameras : list of PinholeCamera
        Calibrated views; every frame gives one image per camera, in this order.
    prior : SmoothMotionPrior or WalkingPrior
        The temporal model (anything with ``init_state``, ``propagate``, ``poses``).
    n_particles : int
    seed : int
        Seeds every random draw (resampling, prior noise, pixel sampling): the same inputs
        give the same track.
    likelihood : ImageLikelihood, optional
        Default: ``ImageLikelihood(body, cameras, seed=seed + 1, **likelihood_options)``.
    appearance : {"estimate", "particle"}
        Where I(t-1) is mapped onto the model (eq. 2): at the previous expected pose, shared
        by all particles, or at each particle's own previous pose, as the paper's §4.1 does.
        The shared appearance resists drift: a particle that slides off a limb onto a static
        background no longer matches it, whereas with its own appearance a limb that stands
        still over a static background matches perfectly, wherever it is. (What keeps the
        twist of a straight arm uncertain is the limb surface, ``surface="patch"``.)
    min_ess : float
        Effective sample size, as a share of ``n_particles``, below which a frame's
        likelihood is tempered (:func:`tempered_weights`); 0 for the plain filter.
    lost_inliers, uncertain_spread : float
        Thresholds of :attr:`FilterStep.status`.
    layers : int
        Annealing passes per frame after the plain SIR step (0: the plain filter). A few
        thousand particles over 35 parameters rarely draw every limb right at once; each pass
        goes through the :func:`partitions` in turn (partitioned sampling, MacCormick &
        Isard, inside the layers of Deutscher et al.'s annealed filter): resample by the
        likelihood tempered to ``layer_ess`` (:func:`tempered_weights`), move that group's
        parameters by ``prior.perturb`` (the prior's own per-frame noise times
        ``layer_scale``, halved each pass), and weigh again only the limbs it moves. The
        frame's weights come from a last weighing of the whole body. Each pass costs about
        two weighings of all particles. The annealed posterior is narrower than the true one.
    layer_scale, layer_ess : float
        See ``layers``.
    pose_weight : float
        Weight of the prior's pose density (``prior.pose_log_prior``, the learned pose
        space's Gaussian) in the weights, untempered (:func:`tempered_weights`); 0 for none.
        One view leaves the limbs' depth, and a leg hidden behind the other, to the motion
        prior alone, whose pull towards the pose space is as weak as its noise: particles
        weighed by the image only keep whatever depth the last frames drifted to.
    **likelihood_options
        Passed to :class:`ImageLikelihood` (``sigma_image``, ``n_points``, ``surface``,
        ``appearance_rate``, ...).
    """

    def __init__(self, body, cameras, prior, *, n_particles=1000, seed=0, likelihood=None,
                 appearance="estimate", min_ess=0.1, lost_inliers=0.3,
                 uncertain_spread=0.08, layers=0, layer_scale=1.0, layer_ess=0.5,
                 pose_weight=0.0, **likelihood_options):
        if int(n_particles) != n_particles or n_particles < 1:
            raise ZoopraxisError(f"ParticleFilter: n_particles must be a positive whole number, "
                                 f"got {n_particles!r}")
        if prior.body is not body and prior.body.dof_names != body.dof_names:
            raise ZoopraxisError("ParticleFilter: the prior was made for another body")
        self.body = body
        self.cameras = list(cameras)
        self.prior = prior
        self.n_particles = int(n_particles)
        self.rng = np.random.default_rng(seed)
        self.likelihood = likelihood if likelihood is not None else ImageLikelihood(
            body, cameras, seed=seed + 1, **likelihood_options)
        self.kinematics = BatchKinematics(body)
        if appearance not in APPEARANCES:
            raise ZoopraxisError(f"ParticleFilter: appearance must be one of "
                                 f"{', '.join(APPEARANCES)}, got {appearance!r}")
        self.appearance = appearance
        self.min_ess = float(min_ess)
        self.temper = 1.0
        self.lost_inliers = float(lost_inliers)
        self.uncertain_spread = float(uncertain_spread)
        if int(layers) != layers or layers < 0 or not layer_scale > 0 \
                or not 0 < layer_ess <= 1:
            raise ZoopraxisError(f"ParticleFilter: need layers >= 0 (whole), layer_scale > 0 "
                                 f"and 0 < layer_ess <= 1, got {layers}, {layer_scale}, "
                                 f"{layer_ess}")
        if layers and not hasattr(prior, "perturb"):
            raise ZoopraxisError("ParticleFilter: annealing layers need a prior with perturb()")
        self.layers = int(layers)
        self.layer_scale = float(layer_scale)
        self.layer_ess = float(layer_ess)
        if not pose_weight >= 0:
            raise ZoopraxisError(f"ParticleFilter: pose_weight must be >= 0, got {pose_weight}")
        if pose_weight and not hasattr(prior, "pose_log_prior"):
            raise ZoopraxisError("ParticleFilter: a pose weight needs a prior with "
                                 "pose_log_prior() (the general motion prior)")
        self.pose_weight = float(pose_weight)
        self.groups = partitions(body)
        self.param_names = param_names(body)
        self._images = None
        self._frame = -1

    def _prepare(self, images):
        if len(images) != len(self.cameras):
            raise ZoopraxisError(f"ParticleFilter: {len(self.cameras)} views but "
                                 f"{len(images)} images")
        out = []
        for cam, image in zip(self.cameras, images):
            gray = prepare_image(image)
            if gray.shape != (cam.height, cam.width):
                raise ZoopraxisError(f"view '{cam.name}': image is {gray.shape[1]}x"
                                     f"{gray.shape[0]}, the camera expects "
                                     f"{cam.width}x{cam.height}")
            out.append(gray)
        return out

    def start(self, images, pose, **init_options):
        """Frame 0: particles around a hand-initialized pose (§7).

        Parameters
        ----------
        images : list of array
            Frame 0 of every view (any format ``plates.to_gray_float`` accepts).
        pose : Pose
            The initial pose (from clicked joints, or ground truth in tests).
        **init_options
            Passed to ``prior.init_state`` (``spread``, ``uniform``, ``phase``, ...).

        Returns
        -------
        FilterStep
            The initial particles' expectation (the given pose, up to sampling, where no
            parameter is drawn uniformly) and spread.
        """
        self._images = self._prepare(images)
        self.likelihood.reset()
        self.state = self.prior.init_state(pose, self.n_particles, self.rng, **init_options)
        roots, angles = self.prior.poses(self.state)
        self._seg2world = self.kinematics.seg2world(roots, angles)
        self.weights = np.full(self.n_particles, 1.0 / self.n_particles)
        self._frame = 0
        self.temper = 1.0
        # The expectation of the initial particles, not the given pose: with a parameter drawn
        # uniformly (the arm example's twist), the given value is not known.
        self.pose, spread = posterior_mean(roots, angles, self.weights)
        return self._report(roots, angles, np.zeros(self.n_particles), 1.0, spread)

    def step(self, images, foreground=None, cover=None):
        """Advance one frame: resample, predict, weigh, estimate.

        Parameters
        ----------
        images : list of array
            The next frame of every view.
        foreground : list of (array of bool or None), optional
            The frame's foreground mask per view, for the likelihood's silhouette cue
            (:meth:`likelihood.ImageLikelihood.set_foreground`); default none.
        cover : list of (array of bool or None), optional
            The pixels the limbs must cover, per view (``set_foreground``'s ``cover``).

        Returns
        -------
        FilterStep
        """
        if self._images is None:
            raise ZoopraxisError("ParticleFilter: call start() with the first frame first")
        images_now = self._prepare(images)
        self.likelihood.set_foreground(foreground, cover)
        index = systematic_resample(self.weights, self.rng)
        state = self.prior.propagate({k: v[index] for k, v in self.state.items()}, self.rng)
        roots, angles = self.prior.poses(state)
        seg2world = self.kinematics.seg2world(roots, angles)
        # The appearance: I(t-1) mapped onto the model at the previous estimate (eq. 2), or
        # at every particle's own previous pose.
        self.likelihood.set_reference(
            self.kinematics.seg2world(self.pose.root[None], self.pose.angles[None])[0],
            self._images)
        previous = (self._images, self._seg2world[index]) \
            if self.appearance == "particle" else None
        result = self.likelihood.evaluate(images_now, seg2world, previous)
        if self.layers:
            state, seg2world, result = self._anneal(images_now, state, seg2world, previous,
                                                    result)
            roots, angles = self.prior.poses(state)
        ll = result.log_likelihood
        w, self.temper = tempered_weights(ll, self.min_ess, self._log_prior(angles))
        self.state, self._seg2world, self.weights = state, seg2world, w
        self._images = images_now
        self._frame += 1
        self.pose, spread = posterior_mean(roots, angles, w)
        return self._report(roots, angles, ll, float(w @ result.inliers), spread)

    def _log_prior(self, angles):
        """The pose density's share of the weights (None without ``pose_weight``)."""
        if not self.pose_weight:
            return None
        return self.pose_weight * self.prior.pose_log_prior(angles)

    def _anneal(self, images, state, seg2world, previous, result):
        """The annealing passes of partitioned sampling (see ``layers``)."""
        lik = self.likelihood
        per_segment, coverage = result.per_segment.copy(), result.coverage
        # Which foreground pixels each limb covers: a group's move changes its limbs' only.
        _, hits = lik.capsule_hits(seg2world)
        for layer in range(self.layers):
            scale = self.layer_scale * 0.5 ** layer
            for cols, segments in self.groups:
                w, _ = tempered_weights(per_segment.sum(axis=1) + coverage, self.layer_ess,
                                        self._log_prior(state["angles"]))
                index = systematic_resample(w, self.rng)
                state = self.prior.perturb({k: v[index] for k, v in state.items()}, cols,
                                           scale, self.rng)
                per_segment = per_segment[index]
                hits = [None if h is None else h[index] for h in hits]
                if previous is not None:
                    previous = (previous[0], previous[1][index])
                roots, angles = self.prior.poses(state)
                seg2world = self.kinematics.seg2world(roots, angles)
                part = lik.evaluate(images, seg2world, previous, segments=segments,
                                    with_coverage=False)
                per_segment[:, segments] = part.per_segment[:, segments]
                caps, moved = lik.capsule_hits(seg2world, segments)
                for h, m in zip(hits, moved):
                    if h is not None:
                        h[:, caps] = m
                coverage, _ = lik.coverage_from_hits(hits)
        return state, seg2world, lik.evaluate(images, seg2world, previous)

    def measure(self, roots, angles, caller="measure"):
        """The likelihood's full answer for given poses in the last frame :meth:`step`
        weighed (log-likelihood, inliers, silhouette cover, ...), not tempered.

        Parameters
        ----------
        roots : array, shape (K, 4, 4)
        angles : array, shape (K, n_dofs)
        caller : str
            The method named in the error when no frame has been weighed yet.

        Returns
        -------
        likelihood.LikelihoodResult
        """
        if self._frame < 1:
            raise ZoopraxisError(f"ParticleFilter: {caller}() needs a frame weighed by step()")
        seg2world = self.kinematics.seg2world(np.asarray(roots, float),
                                              np.asarray(angles, float))
        return self.likelihood.evaluate(self._images, seg2world)

    def score(self, roots, angles):
        """Log-likelihood of given poses in the last frame :meth:`step` weighed, with the
        same appearance as its particles (not tempered).

        Parameters
        ----------
        roots : array, shape (K, 4, 4)
        angles : array, shape (K, n_dofs)

        Returns
        -------
        log_likelihood : array, shape (K,)
        """
        return self.measure(roots, angles, caller="score").log_likelihood

    def recentre(self, pose, fraction=0.5, **init_options):
        """Draw a share of the particles again around a pose found by other means.

        The hybrid tracker refines the filter's expected pose by Gauss-Newton on the image
        (Bregler & Malik's differential tracker behind the filter as a coarse search stage).
        Feeding the refined pose back keeps the two on one track: the posterior is resampled
        to equal weights, ``fraction`` of the particles (chosen at random) are replaced by
        fresh ones from ``prior.init_state`` around ``pose``, and ``pose`` becomes the
        estimate on which the next frame's appearance is mapped (eq. 2).

        Parameters
        ----------
        pose : Pose
        fraction : float
            Share of the particles to draw again, 0 to 1.
        **init_options
            Passed to ``prior.init_state`` (``spread``, ``previous``, ...).
        """
        if self._images is None:
            raise ZoopraxisError("ParticleFilter: call start() with the first frame first")
        if not 0 <= fraction <= 1:
            raise ZoopraxisError(f"ParticleFilter: recentre fraction must be in [0, 1], "
                                 f"got {fraction}")
        N = self.n_particles
        index = systematic_resample(self.weights, self.rng)
        state = {k: v[index] for k, v in self.state.items()}
        m = int(round(fraction * N))
        if m:
            rows = self.rng.choice(N, m, replace=False)
            fresh = self.prior.init_state(pose, m, self.rng, **init_options)
            for k in state:
                state[k][rows] = fresh[k]
        roots, angles = self.prior.poses(state)
        self.state = state
        self._seg2world = self.kinematics.seg2world(roots, angles)
        self.weights = np.full(N, 1.0 / N)
        self.pose = Pose(np.array(pose.root, float), np.array(pose.angles, float))

    def _report(self, roots, angles, ll, inliers, spread):
        w = self.weights
        X = self.kinematics.joints(self._seg2world)                   # (N, 17, 3)
        mean_joints = np.einsum("n,nja->ja", w, X)
        joint_spread = np.sqrt(np.einsum("n,nj->j", w, np.sum((X - mean_joints) ** 2, axis=2)))
        if inliers < self.lost_inliers:
            status = "lost"
        elif np.sqrt(np.mean(joint_spread ** 2)) > self.uncertain_spread:
            status = "uncertain"
        else:
            status = "ok"
        return FilterStep(frame=self._frame, pose=self.pose.copy(), spread=spread,
                          joints=self.body.joints(self.pose), joint_spread=joint_spread,
                          status=status, ess=float(1.0 / np.sum(w ** 2)), temper=self.temper,
                          inliers=inliers,
                          roots=roots, angles=angles, weights=w.copy(), log_likelihood=ll,
                          state=self.state)


__all__ = ["ParticleFilter", "FilterStep", "BatchKinematics", "systematic_resample", "partitions",
           "tempered_weights",
           "posterior_mean", "STATUSES"]
