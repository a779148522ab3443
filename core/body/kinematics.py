"""Standard joints of a body template and their derivatives by the angles and the lengths,
batched over poses: the forward kinematics of the fits from clicked joints (initialize) and of
the pose prior (priors.pose).

The body model (``body.py``) poses one segment tree for rendering and tracking; this engine
computes only the 17 standard joints, with the lengths kept as a linear factor, so that one pass
gives the joints, their derivatives by the angles and their exact derivatives by the lengths.
Both follow the same tree and the same twists (tests/core/body/test_kinematics.py checks that
they agree).
"""

import numpy as np

from ..geometry import se3
from .body import DEFAULT_DIMS, DIM_NAMES, LENGTH_DIMS, make_body, reference_points
from .joints import STANDARD_JOINTS

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


class Kinematics:
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


_CACHE = {}


def kinematics(template):
    """The :class:`Kinematics` of a template (made once)."""
    if template not in _CACHE:
        _CACHE[template] = Kinematics(template)
    return _CACHE[template]
