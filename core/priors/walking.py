"""The learned walking prior of Sidenbladh, Black & Fleet (2000) §6.2 (eqs. 13-17): joint angles
follow a walking cycle, the mean plus a few eigencurves learned by PCA from motion capture
(:class:`WalkModel`, learned by :func:`learn_walk_model` from cycles that
:func:`find_gait_cycles` and :func:`cycle_curves` cut out of captures), parameterized by a phase
and the eigen-coefficients; the torso moves forward at the learned speed (:class:`WalkingPrior`).
The model ships as ``data/walk_prior.npz`` (about 60 kB), learned from CMU walks by
``tools/learn_walk_prior.py``, which rebuilds it.

:class:`WalkingPrior` has the interface of :class:`motion_prior.SmoothMotionPrior` (``init_state``,
``propagate``, ``poses``), used by :mod:`particle`.

Convention: world Z up, metres; pose parameters in the order of
:func:`motion_prior.param_names`; noise levels per frame of the plate.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..geometry import se3
from ..body.body import mirror_dof_index
from ..errors import ZoopraxisError
from ..body.joints import JOINT_INDEX
from .motion_prior import REFERENCE_FPS, read_model

DEFAULT_WALK_PRIOR = Path(__file__).resolve().parent / "data" / "walk_prior.npz"


# ---------------------------------------------------------------------------------------------
# The walking model (§6.2): eigencurves of joint angles over a gait cycle
# ---------------------------------------------------------------------------------------------

# Curves of a walking cycle besides the joint angles, all in the heading frame (the reference
# orientation turned about world Z to face the direction of travel): forward speed in metres
# per cycle (d distance / d phase, so that speed times the phase step is the distance walked in
# a frame), the pelvis's sideways and vertical offsets from their cycle means (metres), and the
# root rotation relative to the heading frame (a rotation vector in heading axes, radians).
ROOT_CURVES = ("speed", "sway", "bob", "tilt_x", "tilt_y", "tilt_z")


@dataclass(frozen=True)
class WalkModel:
    """Mean walking cycle and eigencurves (eq. 13): ``A* = A_mean + B c``.

    Attributes
    ----------
    dof_names : tuple of str
        Joint angles the model covers (a body maps its DOFs to them by name).
    mean : array, shape (C, K)
        Mean of each curve over K phase samples ``mu = k / K``; curves are ``dof_names`` then
        :data:`ROOT_CURVES`.
    basis : array, shape (d, C, K)
        Eigencurves ``B_j``, orthonormal over all C x K entries.
    coef_std : array, shape (d,)
        Standard deviation of the training cycles' coefficients along each eigencurve.
    cycle_seconds : float
        Mean duration of a training cycle.
    leg_length : float
        Thigh plus shank of the body the curves were fitted with, metres (speeds and offsets
        scale with it).
    coefficients : array, shape (m, d)
        The training cycles' coefficients (for inspection and tests).
    """

    dof_names: tuple
    mean: np.ndarray
    basis: np.ndarray
    coef_std: np.ndarray
    cycle_seconds: float
    leg_length: float
    coefficients: np.ndarray

    @property
    def n_curves(self):
        return self.mean.shape[0]

    @property
    def n_samples(self):
        return self.mean.shape[1]

    @property
    def n_components(self):
        return self.basis.shape[0]

    @property
    def curve_names(self):
        return tuple(self.dof_names) + ROOT_CURVES

    def evaluate(self, phase, coefficients):
        """Curve values at phases (eq. 13 interpolated at ``mu``, periodic linear).

        Parameters
        ----------
        phase : array, shape (N,)
            Phase in cycles; only the fractional part matters (0 = the left foot passing the right).
        coefficients : array, shape (N, d)

        Returns
        -------
        values : array, shape (N, C)
        """
        K = self.n_samples
        x = np.mod(np.asarray(phase, float), 1.0) * K
        i0 = np.floor(x).astype(int) % K
        i1 = (i0 + 1) % K
        f = (x - np.floor(x))[:, None]
        c = np.asarray(coefficients, float)
        # Gather the two neighbouring phase samples of mean and basis: (N, C) and (N, d, C).
        mean = (1 - f) * self.mean[:, i0].T + f * self.mean[:, i1].T
        B = (1 - f)[:, :, None] * self.basis[:, :, i0].transpose(2, 0, 1) \
            + f[:, :, None] * self.basis[:, :, i1].transpose(2, 0, 1)
        return mean + np.einsum("nd,ndc->nc", c, B)

    def fit(self, values, *, mask=None, ridge=0.01):
        """Phase and coefficients whose curves best match given values (e.g. a pose's angles).

        Every phase sample is tried; at each the coefficients solve a ridge regression, the
        maximum a posteriori estimate for a mismatch of variance ``ridge`` (rad^2) per value
        and coefficients distributed as the training cycles' (``coef_std``).

        Parameters
        ----------
        values : array, shape (C,)
            Target curve values; entries with ``mask`` False (or NaN) are ignored.
        mask : array of bool, shape (C,), optional

        Returns
        -------
        phase : float
        coefficients : array, shape (d,)
        rms : float
            RMS mismatch over the used entries.
        """
        v = np.asarray(values, float)
        use = np.isfinite(v) if mask is None else (np.asarray(mask, bool) & np.isfinite(v))
        best = (np.inf, 0.0, np.zeros(self.n_components))
        reg = ridge * np.diag(1.0 / np.maximum(self.coef_std, 1e-9) ** 2)
        for k in range(self.n_samples):
            B = self.basis[:, use, k].T                              # (C_used, d)
            r = v[use] - self.mean[use, k]
            c = np.linalg.solve(B.T @ B + reg, B.T @ r)
            err = np.sum((r - B @ c) ** 2)
            if err < best[0]:
                best = (err, k / self.n_samples, c)
        return best[1], best[2], float(np.sqrt(best[0] / max(use.sum(), 1)))

    def save(self, path):
        """Write the model as a compressed npz (all arrays plus the DOF names)."""
        np.savez_compressed(path, dof_names=np.array(self.dof_names), mean=self.mean,
                            basis=self.basis, coef_std=self.coef_std,
                            cycle_seconds=self.cycle_seconds, leg_length=self.leg_length,
                            coefficients=self.coefficients, root_curves=np.array(ROOT_CURVES))

    @classmethod
    def load(cls, path=None):
        """Read a model written by :meth:`save`; default the shipped ``data/walk_prior.npz``."""
        path = Path(DEFAULT_WALK_PRIOR if path is None else path)
        fields = read_model(path, "walking model", "tools/learn_walk_prior.py",
                            ("dof_names", "mean", "basis", "coef_std", "cycle_seconds",
                             "leg_length", "coefficients"))
        dof_names = tuple(str(s) for s in fields["dof_names"])
        mean, basis = fields["mean"].astype(float), fields["basis"].astype(float)
        C = len(dof_names) + len(ROOT_CURVES)
        if mean.ndim != 2 or mean.shape[0] != C or basis.ndim != 3 \
                or basis.shape[1:] != mean.shape:
            raise ZoopraxisError(f"{path}: walking model arrays have inconsistent shapes "
                                 f"(mean {mean.shape}, basis {basis.shape}, {C} curves)")
        return cls(dof_names, mean, basis, fields["coef_std"].astype(float),
                   float(fields["cycle_seconds"]), float(fields["leg_length"]),
                   fields["coefficients"].astype(float))


def heading_rotation(forward):
    """Rotation about world Z that turns the reference facing (-Y) towards ``forward``.

    Parameters
    ----------
    forward : array, shape (..., 3) or (..., 2)
        Horizontal direction of travel (only x and y are used).

    Returns
    -------
    R : array, shape (..., 3, 3)
        ``world_from_heading``: ``R @ [0, -1, 0]`` is the unit horizontal ``forward``.
    """
    f = np.asarray(forward, float)
    a = np.arctan2(f[..., 0], -f[..., 1])
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1] = c, -s
    R[..., 1, 0], R[..., 1, 1] = s, c
    R[..., 2, 2] = 1.0
    return R


def find_gait_cycles(joints, fps, *, min_speed=0.12, min_seconds=0.5, max_seconds=2.0,
                     min_separation=0.08, max_turn=np.radians(35.0)):
    """Gait cycles of the steady forward walking in a capture.

    Phase 0 of a cycle is the left foot passing the right one (the middle of the left swing):
    the separation of the ankles along the direction of travel, left minus right, crosses zero
    upwards. Unlike a heel strike, which slow walks blur into a plateau of that separation,
    the crossing is sharp. Crossings count only between a clear right-ahead and a clear
    left-ahead stance (``min_separation``, a hysteresis that ignores shuffles and jitter). A
    cycle is kept only if the pelvis moves forward at ``min_speed`` or more throughout, its
    duration is plausible, and the hips face the direction of travel within ``max_turn``
    throughout (which rejects spins and side steps: the prior models walking forwards).

    Parameters
    ----------
    joints : array, shape (F, 17, 3)
    fps : float

    Returns
    -------
    cycles : list of (float, float)
        Start and end of each cycle in (fractional) frames.
    heading : array, shape (F, 3)
        Smoothed unit direction of travel per frame.
    """
    from scipy.ndimage import gaussian_filter1d

    J = np.asarray(joints, float)
    pelvis = J[:, JOINT_INDEX["pelvis"]]
    vel = gaussian_filter1d(np.gradient(pelvis[:, :2], axis=0), 0.3 * fps, axis=0,
                            mode="nearest") * fps
    speed = np.linalg.norm(vel, axis=1)
    heading = np.zeros((len(J), 3))
    heading[:, :2] = vel / np.maximum(speed, 1e-9)[:, None]
    sep = np.sum((J[:, JOINT_INDEX["l_ankle"], :2] - J[:, JOINT_INDEX["r_ankle"], :2])
                 * heading[:, :2], axis=1)
    # Hysteresis: the frames clearly left-ahead (+1) or right-ahead (-1), in order.
    clear = np.flatnonzero(np.abs(sep) > min_separation)
    side = np.sign(sep[clear])
    rising = np.flatnonzero((side[:-1] < 0) & (side[1:] > 0))
    crossings = []
    for k in rising:
        a, b = clear[k], clear[k + 1]
        i = a + int(np.argmax(sep[a:b + 1] >= 0)) - 1     # last frame below zero
        crossings.append(i + sep[i] / (sep[i] - sep[i + 1]))
    hips = J[:, JOINT_INDEX["l_hip"], :2] - J[:, JOINT_INDEX["r_hip"], :2]
    # The reference faces -Y with its left at +X, so the facing is the hip axis turned by -90.
    facing = np.stack([hips[:, 1], -hips[:, 0]], axis=1)
    turn = np.abs(np.arctan2(facing[:, 0] * heading[:, 1] - facing[:, 1] * heading[:, 0],
                             np.sum(facing * heading[:, :2], axis=1)))
    cycles = []
    for a, b in zip(crossings[:-1], crossings[1:]):
        if not min_seconds <= (b - a) / fps <= max_seconds:
            continue
        span = slice(int(np.floor(a)), int(np.ceil(b)) + 1)
        if speed[span].min() < min_speed or turn[span].max() > max_turn:
            continue
        cycles.append((float(a), float(b)))
    return cycles, heading


def cycle_curves(body, poses, start, end, n_samples=64):
    """Resample one gait cycle of fitted poses into the walking model's curves.

    Parameters
    ----------
    body : BodyModel
        The body the poses were fitted with.
    poses : list of Pose
        Fitted poses of the whole capture (frames before and after the cycle give the speed
        at its ends).
    start, end : float
        Start and end of the cycle, fractional frames (:func:`find_gait_cycles`).
    n_samples : int
        K, the phase samples ``mu = k / K``.

    Returns
    -------
    curves : array, shape (n_dofs + 6, K)
        The DOF angles then :data:`ROOT_CURVES` (see there for units).
    """
    frames = np.arange(len(poses))
    roots = np.array([p.root for p in poses])
    angles = np.array([p.angles for p in poses])
    position = roots[:, :3, 3]

    def at(times, values):
        values = values.reshape(len(frames), -1)
        return np.array([np.interp(times, frames, v) for v in values.T])

    p0 = at([start], position)[:, 0]
    Rh = heading_rotation(at([end], position)[:, 0] - p0)
    # Positions and orientations in the heading frame, relative to the cycle's start.
    local = (position - p0) @ Rh
    speed = np.gradient(-local[:, 1]) * (end - start)             # metres per cycle
    tilt = se3.log_so3(Rh.T @ roots[:, :3, :3])
    times = start + (end - start) * np.arange(n_samples) / n_samples
    sway = at(times, local[:, 0])
    bob = at(times, local[:, 2])
    return np.concatenate([at(times, angles), at(times, speed), sway - sway.mean(),
                           bob - bob.mean(), at(times, tilt)])


def mirror_curves(body, curves):
    """The mirror image of a cycle: left and right swapped, half a cycle later.

    The mirrored walker's left foot passes its right where the original's right passed its
    left, half a cycle in; shifting by K / 2 puts that event back at phase 0. Sideways sway
    and the tilts about the forward and vertical axes change sign (mirror x -> -x in the
    heading frame: a rotation vector (wx, wy, wz) becomes (wx, -wy, -wz)).

    Parameters
    ----------
    curves : array, shape (n_dofs + 6, K)

    Returns
    -------
    mirrored : array, same shape
    """
    n = body.n_dofs
    K = curves.shape[1]
    out = curves.copy()
    out[:n] = curves[mirror_dof_index(body)]
    for name, sign in (("sway", -1), ("tilt_y", -1), ("tilt_z", -1)):
        i = n + ROOT_CURVES.index(name)
        out[i] = sign * curves[i]
    return np.roll(out, -(K // 2), axis=1)


def learn_walk_model(body, cycles, *, cycle_seconds, variance=0.95, max_components=8):
    """Principal component analysis of walking cycles (§6.2, eq. 13).

    The cycles, each all curves of :func:`cycle_curves` concatenated, are centred on their
    mean and decomposed by SVD; the fewest eigencurves whose squared singular values hold
    ``variance`` of the total are kept. Speeds (metres per cycle) and angles (radians) have
    similar ranges, so like the paper the curves are not rescaled.

    Parameters
    ----------
    body : BodyModel
        The body the cycles were fitted with.
    cycles : array, shape (m, C, K)
    cycle_seconds : float
        Mean duration of the cycles.

    Returns
    -------
    WalkModel
    """
    A = np.asarray(cycles, float)
    m, C, K = A.shape
    if m < 2:
        raise ZoopraxisError(f"learn_walk_model: need at least 2 walking cycles, got {m}")
    if C != body.n_dofs + len(ROOT_CURVES):
        raise ZoopraxisError(f"learn_walk_model: cycles have {C} curves, the body needs "
                             f"{body.n_dofs + len(ROOT_CURVES)}")
    flat = A.reshape(m, -1)
    mean = flat.mean(axis=0)
    U, S, Vt = np.linalg.svd(flat - mean, full_matrices=False)
    share = np.cumsum(S ** 2) / np.sum(S ** 2)
    d = int(min(np.searchsorted(share, variance) + 1, max_components, m - 1))
    basis = Vt[:d].reshape(d, C, K)
    coefficients = U[:, :d] * S[:d]
    coef_std = S[:d] / np.sqrt(m - 1)
    leg = body.dims["thigh"] + body.dims["shank"]
    return WalkModel(tuple(body.dof_names), mean.reshape(C, K), basis, coef_std,
                     float(cycle_seconds), float(leg), coefficients)


# ---------------------------------------------------------------------------------------------
# The walking prior (§6.2, eqs. 14-17)
# ---------------------------------------------------------------------------------------------


class WalkingPrior:
    """Walking as a point moving along the learned cycle (eqs. 14-17).

    State: ``c`` (n, d) eigen-coefficients, ``phase`` (n,) in cycles, ``rate`` (n,) phase
    advance per frame, ``t`` (n, 3) the pelvis path (the pelvis without its learned sway and
    bob), ``R`` (n, 3, 3) heading (``world_from_heading``) and ``dr`` (n, 3) its angular
    velocity (rotation vector per frame, world axes). Per frame:

    - eq. (14): ``c_t = c_{t-1} + N(0, (eps * coef_std)^2)``;
    - eq. (15): ``mu_t = mu_{t-1} + rate_{t-1} + N(0, sigma_phase^2)``, and the rate does a
      random walk. The paper's eq. (15) has no drift term; without one a walk's phase could
      only advance by noise, so the phase advances at a tracked rate instead;
    - eq. (16): the path moves along the heading's forward direction by the learned speed
      times the phase step, ``tau_t = tau_{t-1} + v(mu, c) rate R [0, -1, 0] + N(0, s_tau^2)``;
    - eq. (17): the heading turns by its angular velocity plus noise (smooth motion).

    Joint angles are the curves at the new phase, ``theta^l = A*(mu_t)``, plus a per-DOF
    ``offset`` (n, n_dofs), clipped to the limits; DOFs the model lacks take their initial
    values plus the offset. The offsets are this implementation's addition to the paper's
    prior: a few eigencurves learned from a few walkers do not hold another walker's style
    (the arms held higher, a longer stride), so each angle may leave the learned cycle by a
    slowly varying amount, a random walk of ``sigma_offset`` per frame drawn back towards
    zero by ``offset_pull`` of itself per frame. They start at the initial pose's own
    mismatch to the cycle. With ``sigma_offset=0`` the prior is the paper's.
    The root is ``R exp(tilt(mu, c))`` at ``t + R [sway, 0, bob]``.

    Parameters
    ----------
    body : BodyModel
    model : WalkModel, optional
        Default: the shipped model.
    fps : float
        Frame rate of the plates (sets the initial phase rate from ``model.cycle_seconds``).
    eps : float
        Coefficient noise as a fraction of ``coef_std`` (the paper's epsilon).
    sigma_phase, sigma_rate : float
        Phase noise and phase-rate noise per frame, cycles. The rate changes slowly: a
        tracker that loses a little ground on the walker would otherwise learn to walk slower
        and fall further behind.
    sigma_path : float or array, shape (3,)
        Path noise per frame, metres.
    sigma_turn : float or array, shape (3,)
        Angular-velocity noise of the heading per frame (radians); 0 holds the heading fixed.
    sigma_offset : float or array, shape (n_dofs,)
        Per-frame noise of the angle offsets from the cycle, radians.
    offset_pull : float
        Share of its offset an angle gives back per frame, 0 to 1.
    """

    def __init__(self, body, model=None, *, fps=REFERENCE_FPS, eps=0.1, sigma_phase=0.005,
                 sigma_rate=0.0002, sigma_path=0.01, sigma_turn=(0.0, 0.0, 0.005),
                 sigma_offset=0.0, offset_pull=0.0):
        self.body = body
        self.model = WalkModel.load() if model is None else model
        self.fps = float(fps)
        missing = [n for n in self.model.dof_names if n not in body.dof_names]
        if missing:
            raise ZoopraxisError(f"walking model has DOF '{missing[0]}' that body template "
                                 f"'{body.template}' lacks")
        self._dofs = np.array([body.dof_names.index(n) for n in self.model.dof_names])
        self._n = len(self.model.dof_names)
        # Speeds and offsets scale with the leg: a longer-legged walker strides further.
        self.scale = (body.dims["thigh"] + body.dims["shank"]) / self.model.leg_length
        self.eps = float(eps)
        self.sigma_phase = float(sigma_phase)
        self.sigma_rate = float(sigma_rate)
        self.sigma_path = np.broadcast_to(np.asarray(sigma_path, float), (3,)).copy()
        self.sigma_turn = np.broadcast_to(np.asarray(sigma_turn, float), (3,)).copy()
        self.sigma_offset = np.broadcast_to(np.asarray(sigma_offset, float),
                                            (body.n_dofs,)).copy()
        if np.any(~np.isfinite(self.sigma_offset)) or np.any(self.sigma_offset < 0) \
                or not 0 <= offset_pull <= 1:
            raise ZoopraxisError("WalkingPrior: sigma_offset must be >= 0 and offset_pull "
                                 "in [0, 1]")
        self.offset_pull = float(offset_pull)

    @property
    def default_rate(self):
        """Phase advance per frame of the mean training walk."""
        return 1.0 / (self.model.cycle_seconds * self.fps)

    def _curves(self, phase, c):
        v = self.model.evaluate(phase, c)
        n = self._n
        return v[:, :n], v[:, n:]

    def fit_pose(self, pose):
        """Phase and coefficients of the cycle closest to a pose's angles.

        Returns
        -------
        phase : float
        coefficients : array, shape (d,)
        rms : float
            Angle mismatch, radians.
        """
        values = np.full(self.model.n_curves, np.nan)
        values[:self._n] = pose.angles[self._dofs]
        return self.model.fit(values)

    def init_state(self, pose, n, rng, *, spread=None, phase=None, coefficients=None,
                   rate=None, uniform=None):
        """Particles around a pose (frame 0).

        Parameters
        ----------
        pose : Pose
        n : int
        rng : numpy.random.Generator
        spread : dict, optional
            Initial standard deviations: keys ``phase`` (cycles, default 0.03), ``c``
            (fraction of ``coef_std``, default 0.3), ``rate`` (fraction of the rate,
            default 0.15), ``t`` (metres, default 0.02), ``r`` (radians, default 0.02).
        phase, coefficients : optional
            Where on the cycle the pose is; default :meth:`fit_pose`.
        rate : float, optional
            Phase advance per frame; default the training walk's.
        uniform : dict, optional
            Not used by this prior (accepted for a common interface); must be empty.

        Returns
        -------
        state : dict of arrays
        """
        if uniform:
            raise ZoopraxisError("WalkingPrior: uniform starts apply to the smooth-motion "
                                 "prior only")
        s = {"phase": 0.03, "c": 0.3, "rate": 0.15, "t": 0.02, "r": 0.02, **(spread or {})}
        if phase is None or coefficients is None:
            fit_phase, fit_c, _ = self.fit_pose(pose)
            phase = fit_phase if phase is None else phase
            coefficients = fit_c if coefficients is None else coefficients
        rate = self.default_rate if rate is None else float(rate)
        d = self.model.n_components
        c = np.asarray(coefficients, float) + rng.normal(size=(n, d)) * s["c"] * \
            self.model.coef_std
        mu = phase + rng.normal(size=n) * s["phase"]
        rates = rate * (1.0 + rng.normal(size=n) * s["rate"])
        # Undo the learned tilt, sway and bob at this phase to find the heading and the path.
        _, root_curves = self._curves(np.array([phase]), np.asarray(coefficients)[None])
        heading = pose.root[:3, :3] @ se3.exp_so3(root_curves[0, 3:6]).T
        # Keep the heading upright: the walker's path is horizontal.
        fwd = heading @ np.array([0.0, -1.0, 0.0])
        heading = heading_rotation(fwd)
        offset = heading @ (self.scale * np.array([root_curves[0, 1], 0.0, root_curves[0, 2]]))
        t = pose.root[:3, 3] - offset + rng.normal(size=(n, 3)) * s["t"]
        R = se3.exp_so3(rng.normal(size=(n, 3)) * s["r"] * (self.sigma_turn > 0)) @ heading
        offset = np.zeros((n, self.body.n_dofs))
        if np.any(self.sigma_offset > 0):
            dof_curves, _ = self._curves(np.array([phase]), np.asarray(coefficients)[None])
            offset[:, self._dofs] = pose.angles[self._dofs] - dof_curves[0]
        return {"c": c, "phase": mu, "rate": rates, "t": t, "R": R,
                "dr": np.zeros((n, 3)), "rest": np.broadcast_to(pose.angles, (n, len(
                    pose.angles))).copy(), "offset": offset}

    def propagate(self, state, rng):
        """Draw the next frame's particles (eqs. 14-17); see the class docstring."""
        n, d = state["c"].shape
        c = state["c"] + rng.normal(size=(n, d)) * self.eps * self.model.coef_std
        _, root_curves = self._curves(state["phase"], state["c"])
        step = state["rate"]
        forward = state["R"] @ np.array([0.0, -1.0, 0.0])
        t = state["t"] + (self.scale * root_curves[:, 0] * step)[:, None] * forward \
            + rng.normal(size=(n, 3)) * self.sigma_path
        phase = state["phase"] + step + rng.normal(size=n) * self.sigma_phase
        rate = np.maximum(step + rng.normal(size=n) * self.sigma_rate, 0.0)
        dr = state["dr"] + rng.normal(size=(n, 3)) * self.sigma_turn
        R = se3.exp_so3(state["dr"]) @ state["R"]
        offset = state["offset"]
        if np.any(self.sigma_offset > 0):
            offset = (1.0 - self.offset_pull) * offset \
                + rng.normal(size=offset.shape) * self.sigma_offset
        return {"c": c, "phase": phase, "rate": rate, "t": t, "R": R, "dr": dr,
                "rest": state["rest"], "offset": offset}

    def perturb(self, state, cols, scale, rng):
        """Move some pose parameters of every particle by Gaussian noise (annealing layers).

        Root parameters (``cols`` below 6) move the walk itself: the path by ``sigma_path``,
        the heading by ``sigma_turn``, the phase by ``sigma_phase`` and the coefficients by
        ``eps * coef_std``; DOF columns move those angles' offsets by ``sigma_offset``; all
        noise is ``scale`` times the per-frame value.

        Returns
        -------
        state : dict of arrays
            A new dict (the arrays of ``state`` are not changed).
        """
        n, d = state["c"].shape
        cols = np.asarray(cols, int)
        out = dict(state)
        if np.any(cols < 6):
            out["t"] = state["t"] + rng.normal(size=(n, 3)) * (scale * self.sigma_path)
            out["R"] = se3.exp_so3(rng.normal(size=(n, 3)) * (scale * self.sigma_turn)) \
                @ state["R"]
            out["phase"] = state["phase"] + rng.normal(size=n) * (scale * self.sigma_phase)
            out["c"] = state["c"] + rng.normal(size=(n, d)) * (scale * self.eps
                                                                * self.model.coef_std)
        dofs = cols[cols >= 6] - 6
        if dofs.size and np.any(self.sigma_offset[dofs] > 0):
            offset = state["offset"].copy()
            offset[:, dofs] += rng.normal(size=(n, dofs.size)) * (scale
                                                                  * self.sigma_offset[dofs])
            out["offset"] = offset
        return out

    def poses(self, state):
        """Root transforms (n, 4, 4) and angles (n, n_dofs) of the particles."""
        dof_curves, root_curves = self._curves(state["phase"], state["c"])
        angles = state["rest"].copy()
        angles[:, self._dofs] = dof_curves
        angles = self.body.clamp(angles + state["offset"])
        n = len(angles)
        offset = np.zeros((n, 3))
        offset[:, 0] = self.scale * root_curves[:, 1]
        offset[:, 2] = self.scale * root_curves[:, 2]
        roots = np.zeros((n, 4, 4))
        roots[:, :3, :3] = state["R"] @ se3.exp_so3(root_curves[:, 3:6])
        roots[:, :3, 3] = state["t"] + np.einsum("nij,nj->ni", state["R"], offset)
        roots[:, 3, 3] = 1.0
        return roots, angles
