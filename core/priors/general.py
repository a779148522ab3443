"""The general motion prior of the particle filter: dynamics and a pose space learned from motion
capture of any motion (dance, jumps, sport), for what the walking prior (§6.2) does not hold.

Sidenbladh, Black & Fleet (2000) give a smooth-motion prior (§6.1: every angle on its own, with
hand-set noise) and a walking prior (§6.2: one activity's cycle, learned). Between the two,
:class:`GeneralMotionPrior` keeps the smooth prior's constant-velocity form but learns from
capture what moves how much and what moves together:

- **per-DOF dynamics**: each joint angle's velocity decays by a learned factor per frame (a
  damped constant velocity, an AR(2) in the angle), and the one-step prediction error has a
  learned covariance, low-rank (its principal components: the joint angles that accelerate
  together, both knees in a jump) plus a diagonal rest;
- **a pose space**: the principal components of the captured poses with a diagonal rest
  (probabilistic PCA, :class:`MotionModel`); each step drifts the angles towards it by the
  Langevin drift of the step's own noise, ``-1/2 Sigma_e Sigma_pose^-1 (phi - mu)``, so that
  a random walk with noise ``Sigma_e`` stays distributed like the captured poses. The drift is
  weak along the space (poses far from the mean pose stay reachable: a dancer's raised leg)
  and strong across it (combinations of angles no performer made).

The root (pelvis position and orientation) moves the same way without a pose space: learned
damping and noise, horizontal axes alike and the turn about the vertical apart from the tilts.

The model is learned by :func:`learn_motion_model` from poses fitted to captures
(``tools/learn_motion_prior.py``) and ships as ``data/motion_prior.npz`` (a few kB).
:class:`GeneralMotionPrior` has the interface of :class:`motion_prior.SmoothMotionPrior`
(``init_state``, ``propagate``, ``perturb``, ``poses``) and its state (``t``, ``R``,
``angles`` and their velocities ``dt``, ``dr``, ``dangles``).

Convention: world Z up, metres; pose parameters in the order of
:func:`motion_prior.param_names` (root rotations applied on the left, in world axes); a
velocity is the change over one frame. The model holds per-frame values at
:data:`motion_prior.REFERENCE_FPS`: at another frame rate the damping ``a`` becomes
``a ** (30 / fps)`` and the noise scales by ``30 / fps``, as the smooth prior's does.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ZoopraxisError
from ..geometry import se3
from .motion_prior import REFERENCE_FPS, inside_limits, read_model, state_poses
from .pose import mirror_angles

DEFAULT_MOTION_PRIOR = Path(__file__).resolve().parent / "data" / "motion_prior.npz"

# Share of the variance the principal components keep, and their most.
POSE_VARIANCE, POSE_COMPONENTS = 0.95, 12
NOISE_VARIANCE, NOISE_COMPONENTS = 0.9, 10

# Smallest diagonal rests (radians): an angle the fits to the captures hardly moved (the neck's
# twist, which no marker of the 17 joints shows) must still follow the image a little, step by
# step and away from the pose space.
MIN_NOISE_REST, MIN_POSE_REST = 0.005, 0.05

# Candidate floors of the pose space's rest (radians) when performers are left out in turn
# (:func:`pose_rest_floor`).
REST_FLOORS = (0.05, 0.075, 0.1, 0.15, 0.2, 0.3, 0.4)


@dataclass(frozen=True)
class MotionModel:
    """Learned dynamics and pose space of joint angles (per frame at ``fps``).

    Attributes
    ----------
    dof_names : tuple of str
        The joint angles, in the order of the arrays below (a body maps its DOFs by name).
    fps : float
        Frame rate the per-frame values are given for.
    damping : array, shape (D,)
        Per-frame velocity factor ``a`` of each angle, 0 to 1.
    noise_basis : array, shape (k_e, D)
        Orthonormal principal directions of the one-step prediction error.
    noise_std : array, shape (k_e,)
        Its standard deviation along each, radians per frame.
    noise_rest : array, shape (D,)
        Standard deviation of what the directions leave of it, per angle.
    velocity_std : array, shape (D,)
        Standard deviation of each angle's velocity, radians per frame (the spread of the
        velocities a filter starts with).
    pose_mean : array, shape (D,)
    pose_basis : array, shape (k, D)
        Orthonormal principal directions of the captured poses.
    pose_std : array, shape (k,)
    pose_rest : array, shape (D,)
        Standard deviation off the pose space, per angle, radians.
    root_damping, root_noise, root_velocity_std : array, shape (6,)
        The same for ``tx ty tz rx ry rz`` (metres and radians per frame; world axes, the
        horizontal ones alike).
    frames : int
        Frames the model was learned from (with mirror images).
    """

    dof_names: tuple
    fps: float
    damping: np.ndarray
    noise_basis: np.ndarray
    noise_std: np.ndarray
    noise_rest: np.ndarray
    velocity_std: np.ndarray
    pose_mean: np.ndarray
    pose_basis: np.ndarray
    pose_std: np.ndarray
    pose_rest: np.ndarray
    root_damping: np.ndarray
    root_noise: np.ndarray
    root_velocity_std: np.ndarray
    frames: int

    _ARRAYS = ("damping", "noise_basis", "noise_std", "noise_rest", "velocity_std",
               "pose_mean", "pose_basis", "pose_std", "pose_rest", "root_damping",
               "root_noise", "root_velocity_std")

    @property
    def noise_cov(self):
        """Covariance of the one-step prediction error, shape (D, D)."""
        B = self.noise_basis
        return B.T @ np.diag(self.noise_std ** 2) @ B + np.diag(self.noise_rest ** 2)

    @property
    def pose_cov(self):
        """Covariance of the poses (probabilistic PCA), shape (D, D)."""
        B = self.pose_basis
        return B.T @ np.diag(self.pose_std ** 2) @ B + np.diag(self.pose_rest ** 2)

    def shared_dofs(self, dof_names):
        """The DOFs ``dof_names`` (a body's) shares with the model, in ``dof_names``' order:
        ``(rows, cols)``, their positions in ``dof_names`` and in :attr:`dof_names`."""
        index = {name: i for i, name in enumerate(self.dof_names)}
        rows = np.array([i for i, name in enumerate(dof_names) if name in index], int)
        cols = np.array([index[dof_names[i]] for i in rows], int)
        return rows, cols

    def pose_space(self, dof_names):
        """The pose space's Gaussian over a body's DOFs ``dof_names``, in their order: its mean
        and precision ``(mu, W)``; DOFs the model does not know get a zero mean and no
        precision (left alone)."""
        rows, cols = self.shared_dofs(dof_names)
        mean = np.zeros(len(dof_names))
        mean[rows] = self.pose_mean[cols]
        precision = np.zeros((len(dof_names), len(dof_names)))
        precision[np.ix_(rows, rows)] = np.linalg.inv(self.pose_cov[np.ix_(cols, cols)])
        return mean, precision

    def mahalanobis(self, angles):
        """Squared Mahalanobis distance of poses to the pose space's Gaussian.

        Parameters
        ----------
        angles : array, shape (N, D)

        Returns
        -------
        d2 : array, shape (N,)
        """
        x = np.asarray(angles, float) - self.pose_mean
        return np.einsum("nd,nd->n", x, np.linalg.solve(self.pose_cov, x.T).T)

    def save(self, path):
        """Write the model as a compressed npz (float32 arrays: a few kB)."""
        np.savez_compressed(path, dof_names=np.array(self.dof_names), fps=self.fps,
                            frames=self.frames,
                            **{k: getattr(self, k).astype(np.float32) for k in self._ARRAYS})

    @classmethod
    def load(cls, path=None):
        """Read a model written by :meth:`save`; default the shipped ``data/motion_prior.npz``."""
        path = Path(DEFAULT_MOTION_PRIOR if path is None else path)
        fields = read_model(path, "motion model", "tools/learn_motion_prior.py",
                            ("dof_names", "fps", "frames") + cls._ARRAYS)
        names = tuple(str(s) for s in fields["dof_names"])
        arrays = {k: fields[k].astype(float) for k in cls._ARRAYS}
        D = len(names)
        shapes_ok = all(arrays[k].shape == (D,) for k in (
            "damping", "noise_rest", "velocity_std", "pose_mean", "pose_rest")) \
            and all(arrays[k].shape == (6,) for k in (
                "root_damping", "root_noise", "root_velocity_std")) \
            and arrays["noise_basis"].shape == (len(arrays["noise_std"]), D) \
            and arrays["pose_basis"].shape == (len(arrays["pose_std"]), D)
        if not shapes_ok:
            raise ZoopraxisError(f"{path}: motion model arrays have inconsistent shapes "
                                 f"({D} angles)")
        return cls(names, float(fields["fps"]), frames=int(fields["frames"]), **arrays)


def _components(X, variance, most, centre, floor):
    """Principal directions of the rows of X: (mean, basis (k, D), std (k,), rest (D,))."""
    mean = X.mean(axis=0) if centre else np.zeros(X.shape[1])
    Y = X - mean
    _, S, Vt = np.linalg.svd(Y, full_matrices=False)
    share = np.cumsum(S ** 2) / max(np.sum(S ** 2), 1e-30)
    k = int(min(np.searchsorted(share, variance) + 1, most, len(S)))
    basis = Vt[:k]
    std = S[:k] / np.sqrt(len(X))
    left = Y - (Y @ basis.T) @ basis
    rest = np.maximum(np.sqrt(np.mean(left ** 2, axis=0)), floor)
    return mean, basis, std, rest


def _damping(V, groups=()):
    """Least-squares factor ``a`` of ``v_t = a v_{t-1}`` per column, over a list of (F, C)
    velocity sequences, one regression over each group of columns; clipped to [0, 1]."""
    num = sum(np.sum(v[1:] * v[:-1], axis=0) for v in V)
    den = sum(np.sum(v[:-1] ** 2, axis=0) for v in V)
    for g in groups:
        num[list(g)], den[list(g)] = num[list(g)].sum(), den[list(g)].sum()
    return np.clip(num / np.maximum(den, 1e-30), 0.0, 1.0)


def _pooled(std, groups):
    """Each group of columns given its pooled standard deviation."""
    out = np.array(std, float)
    for g in groups:
        out[list(g)] = np.sqrt(np.mean(out[list(g)] ** 2))
    return out


def _pose_nll(X, mean, basis, std, rest):
    """Mean negative log density of poses X under the probabilistic PCA."""
    S = basis.T @ np.diag(std ** 2) @ basis + np.diag(rest ** 2)
    d = X - mean
    return 0.5 * (np.mean(np.einsum("nd,nd->n", d, np.linalg.solve(S, d.T).T))
                  + np.linalg.slogdet(2 * np.pi * S)[1])


def pose_rest_floor(angles, performers):
    """The floor of the pose space's rest that serves performers not seen.

    A pose space learned from a few performers is too tight for another one: his poses lie
    further off it than the training poses do. Each performer is left out in turn, the space
    learned from the others, and the left-out poses' mean negative log density measured for
    each of :data:`REST_FLOORS`. The floor chosen is the one whose worst regret over the
    performers (its cost less the performer's best) is least: the captures cluster (the Daz
    conversions put every performer on one skeleton, so they fit alike), and a sum over the
    performers would choose what suits the cluster, where a dancer unlike the rest needs a
    floor four times higher (CMU 49, 94, 05: 0.3 rad against the cluster's 0.05).

    Parameters
    ----------
    angles : list of array, shape (F_i, D)
    performers : list of str
        The performer of each array.

    Returns
    -------
    floor : float
        :data:`MIN_POSE_REST` when there are fewer than two performers.
    """
    names = sorted(set(performers))
    if len(names) < 2:
        return MIN_POSE_REST
    cost = np.zeros((len(names), len(REST_FLOORS)))
    for i, name in enumerate(names):
        seen = np.concatenate([a for a, p in zip(angles, performers) if p != name])
        unseen = np.concatenate([a for a, p in zip(angles, performers) if p == name])
        mean, basis, std, rest = _components(seen, POSE_VARIANCE, POSE_COMPONENTS, True, 0.0)
        cost[i] = [_pose_nll(unseen, mean, basis, std, np.maximum(rest, floor))
                   for floor in REST_FLOORS]
    regret = cost - cost.min(axis=1, keepdims=True)
    return REST_FLOORS[int(np.argmin(regret.max(axis=0)))]


def learn_motion_model(dof_names, sequences, fps=REFERENCE_FPS, *, mirror=True,
                       performers=None):
    """Learn a :class:`MotionModel` from sequences of fitted poses.

    Every sequence is a run of consecutive frames at ``fps``; with ``mirror`` each is added a
    second time with left and right swapped (:func:`pose.mirror_angles`).

    1. Velocities are the angles' changes per frame; the damping of each angle is the least
       squares ``a`` of ``v_t = a v_{t-1}``, and the prediction errors
       ``e_t = v_t - a v_{t-1}`` are decomposed by PCA (no centring: their mean is zero).
    2. The poses are decomposed by PCA around their mean; what the components leave has a
       floor chosen by leaving performers out (:func:`pose_rest_floor`), when they are given.
    3. The root: position changes and rotation increments ``log(R_t R_{t-1}^T)`` (world
       axes), the same damping and error per axis, pooled over x and y.

    Parameters
    ----------
    dof_names : sequence of str
    sequences : list of (roots, angles)
        ``roots`` (F, 4, 4) world-from-pelvis, ``angles`` (F, D); F >= 3.
    fps : float
    performers : list of str, optional
        The performer of each sequence.

    Returns
    -------
    MotionModel
    """
    names = tuple(dof_names)
    performers = [""] * len(sequences) if performers is None else list(performers)
    if len(performers) != len(sequences):
        raise ZoopraxisError(f"learn_motion_model: {len(performers)} performers for "
                             f"{len(sequences)} sequences")
    angles, root, whose = [], [], []
    for (roots, a), performer in zip(sequences, performers):
        roots, a = np.asarray(roots, float), np.asarray(a, float)
        if len(a) < 3:
            continue
        if a.shape[1] != len(names) or roots.shape != (len(a), 4, 4):
            raise ZoopraxisError(f"learn_motion_model: a sequence has angles {a.shape} and "
                                 f"roots {roots.shape}, expected {len(names)} angles")
        angles.append(a)
        whose.append(performer)
        if mirror:
            angles.append(mirror_angles(names, a))
            whose.append(performer)
        dr = se3.log_so3(roots[1:, :3, :3] @ np.swapaxes(roots[:-1, :3, :3], 1, 2))
        root.append(np.concatenate([np.diff(roots[:, :3, 3], axis=0), dr], axis=1))
    if not angles:
        raise ZoopraxisError("learn_motion_model: no sequence of 3 frames or more")
    V = [np.diff(a, axis=0) for a in angles]
    a = _damping(V)
    E = np.concatenate([v[1:] - a * v[:-1] for v in V])
    _, noise_basis, noise_std, noise_rest = _components(E, NOISE_VARIANCE, NOISE_COMPONENTS,
                                                        False, MIN_NOISE_REST)
    X = np.concatenate(angles)
    pose_mean, pose_basis, pose_std, pose_rest = _components(
        X, POSE_VARIANCE, POSE_COMPONENTS, True, pose_rest_floor(angles, whose))
    groups = ((0, 1), (3, 4))                  # x and y alike, the tilts rx and ry alike
    root_a = _damping(root, groups)
    root_e = np.concatenate([v[1:] - root_a * v[:-1] for v in root])
    root_noise = _pooled(np.sqrt(np.mean(root_e ** 2, axis=0)), groups)
    root_vel = _pooled(np.sqrt(np.mean(np.concatenate(root) ** 2, axis=0)), groups)
    return MotionModel(names, float(fps), a, noise_basis, noise_std, noise_rest,
                       np.sqrt(np.mean(np.concatenate(V) ** 2, axis=0)), pose_mean,
                       pose_basis, pose_std, pose_rest, root_a, root_noise, root_vel,
                       frames=int(len(X)))


class GeneralMotionPrior:
    """Damped constant velocity with learned, correlated noise and a pull towards the learned
    pose space; hard joint limits (see the module's docstring).

    Per frame, with ``phi`` the angles, ``v`` their velocity, ``a`` the damping:

    .. math:: \\phi_t = \\phi_{t-1} + a \\odot v_{t-1}
              - \\tfrac{1}{2} \\Sigma_e \\Sigma_{pose}^{-1} (\\phi_{t-1} - \\mu) + e_t,
              \\quad e_t \\sim N(0, s^2 \\Sigma_e), \\quad v_t = \\phi_t - \\phi_{t-1}

    inside the limits (a component drawn outside is drawn again, then clipped); the root the
    same without the drift, with diagonal noise. ``s`` is ``scale``.

    Parameters
    ----------
    body : BodyModel
    model : MotionModel or path, optional
        Default: the shipped model. DOFs of the body the model lacks move as independent
        angles with the model's median noise, without drift.
    fps : float
        Frame rate of the plates.
    scale : float
        Multiplies every noise level (the hybrid searches wider than the filter alone).
    drift : float
        Multiplies the pull towards the pose space (0: none; 1: the Langevin drift of the
        unscaled noise).
    carry_moves : bool
        Whether :meth:`perturb` (annealing layers) moves the velocities too (see
        :meth:`motion_prior.SmoothMotionPrior.perturb`).
    """

    def __init__(self, body, model=None, *, fps=REFERENCE_FPS, scale=1.0, drift=1.0,
                 carry_moves=False):
        if not isinstance(model, MotionModel):
            model = MotionModel.load(model)
        if not scale > 0 or not drift >= 0:
            raise ZoopraxisError(f"GeneralMotionPrior: need scale > 0 and drift >= 0, got "
                                 f"{scale} and {drift}")
        self.body, self.model = body, model
        self.fps, self.scale, self.carry_moves = float(fps), float(scale), bool(carry_moves)
        D = body.n_dofs
        rows, cols = model.shared_dofs(body.dof_names)
        if not len(rows):
            raise ZoopraxisError(f"motion model shares no DOF with body template "
                                 f"'{body.template}'")
        k = model.fps / self.fps                                  # frames of the model per frame
        # Per-frame values at the plate's rate, in the body's DOF order.
        self.damping = np.ones(D)
        self.damping[rows] = model.damping[cols] ** k
        noise = np.zeros((D, D))
        noise[np.ix_(rows, rows)] = model.noise_cov[np.ix_(cols, cols)]
        other = np.setdiff1d(np.arange(D), rows)
        median = np.median(np.sqrt(np.diag(model.noise_cov)))
        noise[other, other] = median ** 2
        noise *= k ** 2
        self.noise_factor = np.linalg.cholesky(noise + 1e-12 * np.eye(D)).T   # e = z @ F
        self.noise_sigma = np.sqrt(np.diag(noise))
        self.velocity_std = np.full(D, median * k)
        self.velocity_std[rows] = model.velocity_std[cols] * k
        # The pose space's Gaussian over the body's DOFs (:meth:`pose_log_prior`).
        self.pose_mean, self.pose_precision = model.pose_space(body.dof_names)
        # The drift matrix G, applied as phi - (phi - mu) @ G.T; over the model's DOFs only.
        G = np.zeros((D, D))
        pose_cov = model.pose_cov[np.ix_(cols, cols)]
        G[np.ix_(rows, rows)] = 0.5 * np.linalg.solve(pose_cov, noise[np.ix_(rows, rows)]).T
        self.drift = float(drift) * G
        self.root_damping = model.root_damping ** k
        self.root_noise = model.root_noise * k
        self.root_velocity_std = model.root_velocity_std * k

    @property
    def sigma_position(self):
        """Per-frame noise of every pose parameter (:func:`motion_prior.param_names` order),
        the marginal standard deviations of the correlated noise, times ``scale``."""
        return self.scale * np.concatenate([self.root_noise, self.noise_sigma])

    def _noise(self, n, rng, scale):
        """Correlated angle noise (n, D) and root noise (n, 6)."""
        e = rng.normal(size=(n, self.body.n_dofs)) @ self.noise_factor
        return scale * e, scale * rng.normal(size=(n, 6)) * self.root_noise

    def init_state(self, pose, n, rng, *, spread=None, uniform=None, previous=None):
        """Particles around a pose.

        Positions spread by one frame's noise (``spread`` overrides it per parameter, as in
        :meth:`motion_prior.SmoothMotionPrior.init_state`); velocities start at the motion
        from ``previous`` give or take one frame's noise, or without it are drawn from the
        captures' velocities.

        Parameters
        ----------
        pose : Pose
        n : int
        rng : numpy.random.Generator
        spread : array, shape (6 + n_dofs,), optional
        uniform : dict, optional
            Not used by this prior (accepted for a common interface); must be empty.
        previous : Pose, optional

        Returns
        -------
        state : dict of arrays
        """
        if uniform:
            raise ZoopraxisError("GeneralMotionPrior: uniform starts apply to the "
                                 "smooth-motion prior only")
        e, r = self._noise(n, rng, self.scale)
        if spread is not None:
            s = np.broadcast_to(np.asarray(spread, float), (6 + self.body.n_dofs,))
            r = rng.normal(size=(n, 6)) * s[:6]
            e = rng.normal(size=(n, self.body.n_dofs)) * s[6:]
        angles = self.body.clamp(pose.angles + e)
        if previous is None:
            # The velocity is unknown: drawn from the captures' velocities (one frame later
            # the velocity is each particle's own displacement, chosen by the image).
            v = rng.normal(size=(n, 6 + self.body.n_dofs)) * np.concatenate(
                [self.root_velocity_std, self.velocity_std])
        else:
            # The motion from the previous pose, give or take one frame's noise.
            v_angles, v_root = self._noise(n, rng, self.scale)
            v = np.concatenate([v_root, v_angles], axis=1) + np.concatenate([
                pose.root[:3, 3] - previous.root[:3, 3],
                se3.log_so3(pose.root[:3, :3] @ previous.root[:3, :3].T),
                pose.angles - previous.angles])
        return {"t": pose.root[:3, 3] + r[:, :3], "R": se3.exp_so3(r[:, 3:]) @ pose.root[:3, :3],
                "angles": angles, "dt": v[:, :3], "dr": v[:, 3:6], "dangles": v[:, 6:]}

    def propagate(self, state, rng):
        """Draw the next frame's particles; see the class docstring."""
        n = state["t"].shape[0]
        e, r = self._noise(n, rng, self.scale)
        a = self.root_damping
        dt = a[:3] * state["dt"] + r[:, :3]
        dr = a[3:] * state["dr"] + r[:, 3:]
        phi = state["angles"]
        mean = phi + self.damping * state["dangles"] - (phi - self.pose_mean) @ self.drift.T
        angles = self._inside_limits(mean + e, mean, self.scale * self.noise_sigma, rng)
        return {"t": state["t"] + dt, "R": se3.exp_so3(dr) @ state["R"], "angles": angles,
                "dt": dt, "dr": dr, "dangles": angles - phi}

    def perturb(self, state, cols, scale, rng):
        """Move some pose parameters of every particle (annealing layers).

        The move is ``scale`` times one frame's correlated noise, in the parameters ``cols``
        only (the noise's marginal over them); joint limits stay hard; with ``carry_moves``
        the velocities move by as much.

        Returns
        -------
        state : dict of arrays
            A new dict (the arrays of ``state`` are not changed).
        """
        n = state["t"].shape[0]
        e, r = self._noise(n, rng, scale * self.scale)
        d = np.concatenate([r, e], axis=1)
        keep = np.zeros(d.shape[1], bool)
        keep[np.asarray(cols, int)] = True
        d[:, ~keep] = 0.0
        out = dict(state)
        if keep[:6].any():
            out["t"] = state["t"] + d[:, :3]
            out["R"] = se3.exp_so3(d[:, 3:6]) @ state["R"]
        mean = state["angles"]
        angles = self._inside_limits(mean + d[:, 6:], mean,
                                     scale * self.scale * self.noise_sigma, rng)
        out["angles"] = angles
        if self.carry_moves:
            out["dt"] = state["dt"] + d[:, :3]
            out["dr"] = state["dr"] + d[:, 3:6]
            out["dangles"] = state["dangles"] + angles - mean
        return out

    def _inside_limits(self, angles, mean, sigma, rng):
        return inside_limits(self.body, angles, mean, sigma, rng)

    def pose_log_prior(self, angles):
        """Log-density of poses under the pose space's Gaussian, up to a constant:
        ``-1/2 (phi - mu)^T Sigma_pose^-1 (phi - mu)`` over the model's DOFs.

        Parameters
        ----------
        angles : array, shape (N, n_dofs)

        Returns
        -------
        log_prior : array, shape (N,)
        """
        x = np.asarray(angles, float) - self.pose_mean
        return -0.5 * np.einsum("nd,nd->n", x @ self.pose_precision, x)

    def poses(self, state):
        """Root transforms (n, 4, 4) and angles (n, n_dofs) of the particles."""
        return state_poses(state)


__all__ = ["GeneralMotionPrior", "MotionModel", "learn_motion_model", "DEFAULT_MOTION_PRIOR"]
