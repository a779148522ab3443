"""Temporal priors for the particle filter: the smooth-motion prior, and the pose parameters
and their names that every prior and the particle filter share.

Sidenbladh, Black & Fleet (2000) §6 give two priors ``p(phi_t | phi_{t-1}, V_{t-1})``:

- :class:`SmoothMotionPrior` (§6.1): every parameter moves with constant velocity plus Gaussian
  noise, velocities do a Gaussian random walk, and joint limits are hard (the density is zero
  outside them, so samples there are drawn again). Any subset of the parameters may be tracked
  (their arm example: three shoulder angles and the elbow), the rest stay fixed.
- ``WalkingPrior`` (§6.2, eqs. 13-17, in :mod:`walking`): joint angles follow a walking cycle,
  the mean plus a few eigencurves learned by PCA from motion capture.

Both share one interface, used by :mod:`particle`::

    state = prior.init_state(pose, n, rng, spread=..., uniform=...)   # dict of (n, ...) arrays
    state = prior.propagate(state, rng)                                # one frame forward
    roots, angles = prior.poses(state)                                 # (n, 4, 4), (n, n_dofs)

A state is a dict of arrays whose first axis is the particle; the filter resamples it by indexing
every array with the same index array.

Converting motion capture into this body's angles (how the walking model's training data are
made, ``tools/learn_walk_prior.py``, and how tests start a tracker from a ground-truth pose) is
:mod:`fit3d`'s: :func:`fit3d.fit_pose`, :func:`fit3d.fit_body` and :func:`fit3d.root_from_joints`
are re-exported here for those callers.

Convention: world Z up, metres. Pose parameters are ordered as :func:`param_names` gives them:
pelvis position ``tx, ty, tz`` (world), root rotation ``rx, ry, rz`` (a rotation vector applied
on the left, in world axes: ``R <- exp(r) @ R``), then the body's DOF angles in radians. Noise
levels are per frame of the plate.
"""

import numpy as np

from ..geometry import se3
from ..errors import ZoopraxisError
from ..body.fit3d import fit_body, fit_pose, root_from_joints

ROOT_PARAMS = ("tx", "ty", "tz", "rx", "ry", "rz")

# Frame rate the default noise levels are given for; other rates scale them by 30 / fps.
REFERENCE_FPS = 30.0

# Redraws of samples that fall outside the joint limits before they are clipped (§6.1 makes
# the density zero outside; a sample whose mean lies far outside would never come back).
_LIMIT_REDRAWS = 8

def param_names(body):
    """Names of the pose parameters: ``tx ty tz rx ry rz`` then the body's DOF names."""
    return ROOT_PARAMS + tuple(body.dof_names)


def param_index(body, names):
    """Indices of pose parameters by name (see :func:`param_names`)."""
    all_names = param_names(body)
    out = []
    for name in names:
        if name not in all_names:
            raise ZoopraxisError(f"body template '{body.template}' has no pose parameter "
                                 f"'{name}' (expected tx..rz or a DOF name)")
        out.append(all_names.index(name))
    return np.array(out, dtype=int)


# ---------------------------------------------------------------------------------------------
# Smooth motion (§6.1)
# ---------------------------------------------------------------------------------------------


def smooth_sigmas(body, fps=REFERENCE_FPS):
    """Default per-frame noise of the smooth-motion prior.

    Heavy parts move less than light ones (§6.1): the torso and hips get smaller noise than
    shoulders and elbows.

    Returns
    -------
    sigma_position, sigma_velocity : array, shape (6 + n_dofs,)
        In the order of :func:`param_names`; metres and radians per frame.
    """
    s = REFERENCE_FPS / float(fps)
    pos = [0.005] * 3 + [0.01] * 3
    vel = [0.003] * 3 + [0.005] * 3
    for name in body.dof_names:
        heavy = any(k in name for k in ("hip", "lumbar", "thorax", "neck"))
        pos.append(0.01 if heavy else 0.02)
        vel.append(0.005 if heavy else 0.01)
    return np.array(pos) * s, np.array(vel) * s


class SmoothMotionPrior:
    """Constant velocity with Gaussian noise and hard joint limits (§6.1).

    .. math:: p(\\phi_{i,t} | \\phi_{i,t-1}, V_{i,t-1}) = G(\\phi_{i,t} - (\\phi_{i,t-1}
              + V_{i,t-1}), \\sigma^\\phi_i) \\text{ inside the limits, 0 outside;} \\quad
              p(V_{i,t} | V_{i,t-1}) = G(V_{i,t} - V_{i,t-1}, \\sigma^V_i)

    State: ``t`` (n, 3) pelvis position, ``R`` (n, 3, 3) root rotation, ``angles`` (n, n_dofs),
    and their velocities ``dt`` (n, 3), ``dr`` (n, 3) (a rotation vector per frame, world
    axes), ``dangles`` (n, n_dofs).

    Parameters
    ----------
    body : BodyModel
    active : sequence of str, optional
        Pose parameters that move (:func:`param_names`); the others stay at their initial
        values. Default: all.
    sigma_position, sigma_velocity : array, shape (6 + n_dofs,), optional
        Per-frame noise; defaults :func:`smooth_sigmas` at ``fps``.
    fps : float
    carry_moves : bool
        Whether :meth:`perturb` (annealing layers) moves the velocities too.
    """

    def __init__(self, body, active=None, *, sigma_position=None, sigma_velocity=None,
                 fps=REFERENCE_FPS, carry_moves=False):
        self.body = body
        default_pos, default_vel = smooth_sigmas(body, fps)
        P = 6 + body.n_dofs
        self.sigma_position = self._sigma(sigma_position, default_pos, P, "sigma_position")
        self.sigma_velocity = self._sigma(sigma_velocity, default_vel, P, "sigma_velocity")
        mask = np.ones(P, bool)
        if active is not None:
            mask[:] = False
            mask[param_index(body, active)] = True
        self.active = mask
        self.sigma_position = np.where(mask, self.sigma_position, 0.0)
        self.sigma_velocity = np.where(mask, self.sigma_velocity, 0.0)
        self.carry_moves = bool(carry_moves)

    @staticmethod
    def _sigma(value, default, P, what):
        if value is None:
            return default
        s = np.broadcast_to(np.asarray(value, float), (P,)).copy()
        if np.any(~np.isfinite(s)) or np.any(s < 0):
            raise ZoopraxisError(f"SmoothMotionPrior: {what} must be finite and >= 0")
        return s

    def init_state(self, pose, n, rng, *, spread=None, uniform=None, previous=None):
        """Particles around a pose.

        Parameters
        ----------
        pose : Pose
            The hand-initialized pose of frame 0.
        n : int
        rng : numpy.random.Generator
        spread : array, shape (6 + n_dofs,), optional
            Standard deviation of the initial positions (default ``sigma_position``); only
            active parameters spread. Velocities start at zero with ``sigma_velocity``.
        uniform : dict of str to (float, float), optional
            Parameters drawn uniformly from ``(low, high)`` instead (the arm example's unknown
            upper-arm twist): absolute values for joint angles (clipped to the limits),
            offsets from the pose for the root parameters.
        previous : Pose, optional
            The pose one frame earlier: velocities start at the motion from it to ``pose``
            (active parameters only) instead of at zero, both with ``sigma_velocity`` noise.

        Returns
        -------
        state : dict of arrays
        """
        body = self.body
        P = 6 + body.n_dofs
        spread = self.sigma_position if spread is None else \
            np.broadcast_to(np.asarray(spread, float), (P,))
        spread = np.where(self.active, spread, 0.0)
        x = rng.normal(size=(n, P)) * spread
        x[:, 6:] += pose.angles
        for name, (lo, hi) in (uniform or {}).items():
            i = param_index(body, [name])[0]
            if not lo < hi:
                raise ZoopraxisError(f"uniform start for '{name}': low {lo} must be below "
                                     f"high {hi}")
            x[:, i] = rng.uniform(lo, hi, size=n)
        angles = body.clamp(x[:, 6:])
        v = rng.normal(size=(n, P)) * self.sigma_velocity
        if previous is not None:
            # Left increments in world axes, as propagate() applies them: R <- exp(dr) @ R.
            motion = np.concatenate([pose.root[:3, 3] - previous.root[:3, 3],
                                     se3.log_so3(pose.root[:3, :3] @ previous.root[:3, :3].T),
                                     pose.angles - previous.angles])
            v += np.where(self.active, motion, 0.0)
        return {"t": pose.root[:3, 3] + x[:, :3],
                "R": se3.exp_so3(x[:, 3:6]) @ pose.root[:3, :3],
                "angles": angles, "dt": v[:, :3], "dr": v[:, 3:6], "dangles": v[:, 6:]}

    def propagate(self, state, rng):
        """Draw the next frame's particles (§6.1); see the class docstring."""
        n = state["t"].shape[0]
        sp, sv = self.sigma_position, self.sigma_velocity
        noise = rng.normal(size=(n, 6)) * sp[:6]
        t = state["t"] + state["dt"] + noise[:, :3]
        R = se3.exp_so3(state["dr"] + noise[:, 3:]) @ state["R"]
        mean = state["angles"] + state["dangles"]
        angles = mean + rng.normal(size=mean.shape) * sp[6:]
        angles = self._inside_limits(angles, mean, sp[6:], rng)
        v = rng.normal(size=(n, 6 + self.body.n_dofs)) * sv
        return {"t": t, "R": R, "angles": angles, "dt": state["dt"] + v[:, :3],
                "dr": state["dr"] + v[:, 3:6], "dangles": state["dangles"] + v[:, 6:]}

    def perturb(self, state, cols, scale, rng):
        """Move some pose parameters of every particle by Gaussian noise (annealing layers).

        The noise is ``scale`` times the prior's own per-frame position noise, in the pose
        parameters ``cols`` only (:func:`param_names` order; rotations on the left, in world
        axes); joint limits stay hard. With ``carry_moves`` the velocities move by the same
        amount (a particle moved by ``d`` has come ``d`` further since the previous frame, and
        the next prediction carries that on): that lets the filter alone follow the
        accelerations of jumps (CMU 01_01, 40 frames: 128 mm against 198 mm without), but a
        move that fits one frame's image noise then carries on too (the arm example of
        ``tests/core/test_particle.py`` drifts twice as far), so it is off by default.

        Parameters
        ----------
        state : dict of arrays
        cols : array of int
        scale : float
        rng : numpy.random.Generator

        Returns
        -------
        state : dict of arrays
            A new dict (the arrays of ``state`` are not changed).
        """
        n = state["t"].shape[0]
        P = 6 + self.body.n_dofs
        d = np.zeros((n, P))
        cols = np.asarray(cols, int)
        d[:, cols] = rng.normal(size=(n, len(cols))) * (scale * self.sigma_position[cols])
        out = dict(state)
        if np.any(cols < 6):
            out["t"] = state["t"] + d[:, :3]
            out["R"] = se3.exp_so3(d[:, 3:6]) @ state["R"]
        mean = state["angles"]
        angles = self._inside_limits(mean + d[:, 6:], mean, scale * self.sigma_position[6:],
                                     rng)
        out["angles"] = angles
        if self.carry_moves:
            d[:, 6:] = angles - mean
            out["dt"] = state["dt"] + d[:, :3]
            out["dr"] = state["dr"] + d[:, 3:6]
            out["dangles"] = state["dangles"] + d[:, 6:]
        return out

    def _inside_limits(self, angles, mean, sigma, rng):
        return inside_limits(self.body, angles, mean, sigma, rng)

    def poses(self, state):
        """Root transforms (n, 4, 4) and angles (n, n_dofs) of the particles."""
        return state_poses(state)


def read_model(path, what, tool, needed):
    """The arrays of a learned model's npz file, by name.

    Parameters
    ----------
    path : path
    what : str
        What the file holds, for the errors ("walking model").
    tool : str
        The script that learns it, for the error of a missing file.
    needed : sequence of str
        Arrays the file must hold.

    Raises
    ------
    ZoopraxisError
        One line naming the file: missing, not an npz, or without one of ``needed``.
    """
    try:
        with np.load(path) as data:
            fields = {k: data[k] for k in data.files}
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such {what} (rebuild it with {tool})") from None
    except (OSError, ValueError) as exc:
        raise ZoopraxisError(f"{path}: not a {what} npz ({exc})") from None
    missing = [k for k in needed if k not in fields]
    if missing:
        raise ZoopraxisError(f"{path}: {what} lacks '{missing[0]}'")
    return fields


def inside_limits(body, angles, mean, sigma, rng):
    """Redraw the angles outside the body's limits from their Gaussian (a truncated Gaussian),
    :data:`_LIMIT_REDRAWS` times at most, then clip.

    Parameters
    ----------
    body : BodyModel
    angles, mean : array, shape (n, n_dofs)
        The draws (changed in place) and the means they were drawn around.
    sigma : array, shape (n_dofs,)
    rng : numpy.random.Generator
    """
    lo, hi = body.lower, body.upper
    for _ in range(_LIMIT_REDRAWS):
        bad = (angles < lo) | (angles > hi)
        if not bad.any():
            break
        rows, cols = np.nonzero(bad)
        angles[rows, cols] = mean[rows, cols] + rng.normal(size=rows.size) * sigma[cols]
    return np.clip(angles, lo, hi)


def state_poses(state):
    """Root transforms (n, 4, 4) and angles (n, n_dofs) of a state holding ``t``, ``R`` and
    ``angles`` (the smooth and the general prior's)."""
    n = state["t"].shape[0]
    roots = np.zeros((n, 4, 4))
    roots[:, :3, :3] = state["R"]
    roots[:, :3, 3] = state["t"]
    roots[:, 3, 3] = 1.0
    return roots, state["angles"]


__all__ = ["SmoothMotionPrior", "inside_limits", "state_poses", "read_model", "param_names",
           "param_index", "smooth_sigmas", "fit_pose", "fit_body", "root_from_joints",
           "ROOT_PARAMS"]
