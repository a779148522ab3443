"""Articulated body: a kinematic tree of revolute degrees of freedom, product of exponentials.

Every degree of freedom (DOF) is a revolute twist (Bregler & Malik eq. 17); a ball joint is three
consecutive DOFs about orthogonal axes through the same centre (flexion, abduction, axial
rotation: an intrinsic Euler sequence, as Sidenbladh et al. use). A segment maps from the
reference configuration to the world by the product of exponentials (eq. 21)

.. math:: g_k(\\theta) = G_0 \\, e^{\\hat\\xi_1\\theta_1} \\cdots e^{\\hat\\xi_m\\theta_m}

over the DOFs on the path from the root to segment k, where ``G_0`` is the root (pelvis) pose.

Convention: the reference configuration is the body standing upright in its own frame, which is
the world frame of an unmoved body: origin at the pelvis (mid-point of the hip joint centres),
+Z up, facing -Y, the subject's left at +X (Blender's front view). Arms hang at the sides, legs
straight, feet pointing forward: all angles zero. Twists, shapes and landmarks are given in this
frame, so ``seg2world`` of a segment maps reference coordinates to world coordinates. Root
increments are spatial twists applied on the left: ``G_0 <- exp(delta) G_0``.

Positive angles: flexion for hips, shoulders, elbows, spine and neck (moving forward), knee
flexion (shank backward), ankle dorsiflexion (toes up), abduction (away from the midline),
internal rotation (toes or forearm turning inward), spine lateral bend to the subject's left
and axial rotation to the left. Right-side axes are the mirror images of the left-side ones, so
the same angle means the same motion on either side.
"""

from dataclasses import dataclass, field

import numpy as np

from ..geometry import se3
from ..errors import ZoopraxisError
from .joints import STANDARD_JOINTS

# ---------------------------------------------------------------------------------------------
# Template definitions
# ---------------------------------------------------------------------------------------------

# Default body dimensions (metres) of an adult of about 1.75 m. Lengths first, then radii.
# One name serves both sides, so left and right are tied by construction.
DEFAULT_DIMS = {
    # lengths
    "hip_width": 0.18,        # between the hip joint centres
    "thigh": 0.43,            # hip to knee
    "shank": 0.42,            # knee to ankle
    "ankle_height": 0.08,     # ankle centre above the sole
    "foot_length": 0.14,      # ankle to ball of the foot, along the foot
    "foot_drop": 0.06,        # ankle to ball of the foot, downwards
    "spine_lumbar": 0.10,     # pelvis to the lumbar joint
    "spine_thorax": 0.28,     # pelvis to the thoracic joint
    "torso": 0.50,            # pelvis to the base of the neck
    "neck_length": 0.17,      # base of the neck to the centre of the head
    "shoulder_width": 0.36,   # between the shoulder joint centres
    "shoulder_drop": 0.05,    # base of the neck to the shoulder joints, downwards
    "upper_arm": 0.29,        # shoulder to elbow
    "forearm": 0.26,          # elbow to wrist
    # radii (half-widths) of the segment shapes
    "pelvis_rx": 0.16, "pelvis_ry": 0.10,
    "waist_rx": 0.14, "waist_ry": 0.09,
    "chest_rx": 0.16, "chest_ry": 0.10,
    "neck_r": 0.05, "head_r": 0.10,
    "upper_arm_r": 0.045, "forearm_r": 0.037, "hand_r": 0.045,
    "thigh_r": 0.075, "shank_r": 0.05, "foot_r": 0.04,
}

LENGTH_DIMS = tuple(k for k in DEFAULT_DIMS if not k.endswith(("_r", "_rx", "_ry")))
RADIUS_DIMS = tuple(k for k in DEFAULT_DIMS if k.endswith(("_r", "_rx", "_ry")))
DIM_NAMES = tuple(DEFAULT_DIMS)

# Axes of the left side in the reference frame, and limits in degrees. A DOF is
# (suffix, axis, lower, upper); right-side axes are mirrored by _mirror_axis.
_X, _Y, _Z = np.eye(3)
_SPINE_DOFS = (("flex", _X, -30, 60), ("bend", _Y, -35, 35), ("twist", _Z, -40, 40))
_NECK_DOFS = (("flex", _X, -50, 70), ("bend", _Y, -40, 40), ("twist", _Z, -75, 75))
_HIP_DOFS = (("flex", -_X, -30, 125), ("abd", -_Y, -30, 50), ("rot", -_Z, -45, 45))
_KNEE_DOFS = (("flex", _X, 0, 150),)
_ANKLE_DOFS = (("flex", -_X, -50, 30), ("inv", _Y, -25, 35))
_SHOULDER_DOFS = (("flex", -_X, -60, 180), ("abd", -_Y, -30, 180), ("rot", -_Z, -90, 90))
_ELBOW_DOFS = (("flex", -_X, 0, 150),)
# Yamamoto et al. give every part three rotations; elbows and knees keep two more here
# (abduction and axial rotation) only in that template.
_ELBOW3_DOFS = (("flex", -_X, 0, 150), ("abd", -_Y, -15, 15), ("rot", -_Z, -80, 80))
_KNEE3_DOFS = (("flex", _X, 0, 150), ("abd", -_Y, -10, 10), ("rot", -_Z, -30, 30))


def _mirror_axis(axis):
    """Axis of the right-side DOF: rotation axes are pseudo-vectors, so mirroring x -> -x
    maps (wx, wy, wz) to (wx, -wy, -wz)."""
    return np.array([axis[0], -axis[1], -axis[2]])


def reference_points(dims):
    """Named points of the reference configuration (standing, arms down), linear in ``dims``.

    Parameters
    ----------
    dims : dict of str to float

    Returns
    -------
    points : dict of str to array, shape (3,)
        Joint centres and landmarks in the body reference frame (see module Convention).
    """
    d = dims
    p = {"pelvis": np.zeros(3),
         "lumbar": np.array([0.0, 0.0, d["spine_lumbar"]]),
         "thorax": np.array([0.0, 0.0, d["spine_thorax"]]),
         "neck": np.array([0.0, 0.0, d["torso"]]),
         "head": np.array([0.0, 0.0, d["torso"] + d["neck_length"]])}
    for side, sx in (("l", 1.0), ("r", -1.0)):
        hip = np.array([sx * d["hip_width"] / 2, 0.0, 0.0])
        knee = hip - [0.0, 0.0, d["thigh"]]
        ankle = knee - [0.0, 0.0, d["shank"]]
        toe = ankle + [0.0, -d["foot_length"], -d["foot_drop"]]
        heel = ankle + [0.0, 0.25 * d["foot_length"], -d["ankle_height"] + d["foot_r"]]
        shoulder = np.array([sx * d["shoulder_width"] / 2, 0.0, d["torso"] - d["shoulder_drop"]])
        elbow = shoulder - [0.0, 0.0, d["upper_arm"]]
        wrist = elbow - [0.0, 0.0, d["forearm"]]
        for name, value in (("hip", hip), ("knee", knee), ("ankle", ankle), ("toe", toe),
                            ("heel", heel), ("shoulder", shoulder), ("elbow", elbow),
                            ("wrist", wrist)):
            p[f"{side}_{name}"] = value
    return p


@dataclass(frozen=True)
class _SegmentSpec:
    name: str
    parent: str | None
    joint: str                      # reference point the segment's DOFs rotate about
    dofs: tuple = ()                # left-side DOF specs (suffix, axis, lo, hi)
    side: str = ""                  # "l", "r" or ""


def _limbs(upper_dofs, elbow_dofs, hip_dofs, knee_dofs, with_feet, arm_parent, neck_parent):
    specs = []
    for side in ("l", "r"):
        specs += [
            _SegmentSpec(f"{side}_upper_arm", arm_parent, f"{side}_shoulder", upper_dofs, side),
            _SegmentSpec(f"{side}_forearm", f"{side}_upper_arm", f"{side}_elbow", elbow_dofs,
                         side),
            _SegmentSpec(f"{side}_thigh", "pelvis", f"{side}_hip", hip_dofs, side),
            _SegmentSpec(f"{side}_shank", f"{side}_thigh", f"{side}_knee", knee_dofs, side),
        ]
        if with_feet:
            specs.append(_SegmentSpec(f"{side}_foot", f"{side}_shank", f"{side}_ankle",
                                      _ANKLE_DOFS, side))
    specs.append(_SegmentSpec("head", neck_parent, "neck", _NECK_DOFS))
    return specs


def _template_specs(template):
    if template == "full":
        trunk = [_SegmentSpec("pelvis", None, "pelvis"),
                 _SegmentSpec("abdomen", "pelvis", "lumbar", _SPINE_DOFS),
                 _SegmentSpec("chest", "abdomen", "thorax", _SPINE_DOFS)]
        return trunk + _limbs(_SHOULDER_DOFS, _ELBOW_DOFS, _HIP_DOFS, _KNEE_DOFS, True,
                              "chest", "chest")
    if template in ("muybridge", "sidenbladh"):
        # Bregler & Malik §3.2: 3-DOF hips, shoulders and neck, 1-DOF knees and elbows = 19.
        # Sidenbladh et al. Fig. 1: the same joints; with the 6 of the torso, 25 parameters.
        trunk = [_SegmentSpec("pelvis", None, "pelvis")]
        return trunk + _limbs(_SHOULDER_DOFS, _ELBOW_DOFS, _HIP_DOFS, _KNEE_DOFS, False,
                              "pelvis", "pelvis")
    if template == "yamamoto":
        # Yamamoto et al. §2.1: 12 parts (head, chest, abdomen, waist, upper arms, forearms,
        # thighs, shins), three rotations at every joint.
        trunk = [_SegmentSpec("pelvis", None, "pelvis"),
                 _SegmentSpec("abdomen", "pelvis", "lumbar", _SPINE_DOFS),
                 _SegmentSpec("chest", "abdomen", "thorax", _SPINE_DOFS)]
        return trunk + _limbs(_SHOULDER_DOFS, _ELBOW3_DOFS, _HIP_DOFS, _KNEE3_DOFS, False,
                              "chest", "chest")
    raise ZoopraxisError(f"unknown body template '{template}' (expected one of "
                         f"{', '.join(TEMPLATES)})")


TEMPLATES = ("full", "muybridge", "sidenbladh", "yamamoto")
_DEFAULT_SHAPES = {"full": "ellipsoid", "muybridge": "ellipsoid", "sidenbladh": "cylinder",
                   "yamamoto": "ellipsoid"}


def _landmark_segments(segment_names):
    """Which segment carries each of the 17 standard joints (the most distal one that moves
    with it, so the landmark follows that segment's motion)."""
    has = set(segment_names)
    out = {"pelvis": "pelvis", "neck": "head", "head": "head"}
    for s in ("l", "r"):
        out[f"{s}_shoulder"] = f"{s}_upper_arm"
        out[f"{s}_elbow"] = f"{s}_forearm"
        out[f"{s}_wrist"] = f"{s}_forearm"
        out[f"{s}_hip"] = f"{s}_thigh"
        out[f"{s}_knee"] = f"{s}_shank"
        out[f"{s}_ankle"] = f"{s}_foot" if f"{s}_foot" in has else f"{s}_shank"
        out[f"{s}_toe"] = f"{s}_foot" if f"{s}_foot" in has else f"{s}_shank"
    return out


# ---------------------------------------------------------------------------------------------
# Poses
# ---------------------------------------------------------------------------------------------


@dataclass
class Pose:
    """Root pose and joint angles of one body.

    Attributes
    ----------
    root : array, shape (4, 4)
        ``world_from_pelvis``: the reference frame's pose in the world (``G_0``).
    angles : array, shape (n_dofs,)
        Joint angles in radians, in the body's DOF order.
    """

    root: np.ndarray
    angles: np.ndarray

    def copy(self):
        return Pose(self.root.copy(), self.angles.copy())

    def to_vector(self):
        """``[translation (3), rotation vector (3), angles]`` for optimizers and filters."""
        return np.concatenate([self.root[:3, 3], se3.log_so3(self.root[:3, :3]), self.angles])

    @classmethod
    def from_vector(cls, x):
        x = np.asarray(x, dtype=float)
        return cls(se3.transform(se3.exp_so3(x[3:6]), x[:3]), x[6:].copy())

    def retract(self, delta):
        """Apply an increment ``[spatial root twist (6), angle changes]``.

        The root moves by ``exp(hat6(delta[:6])) @ root`` (a twist expressed in the world frame),
        the angles add; this is the update of Bregler & Malik §2.5 (c)-(d) with the root twist
        taken in the spatial rather than the body frame.
        """
        delta = np.asarray(delta, dtype=float)
        root = se3.exp_se3(delta[:6]) @ self.root
        root[:3, :3] = se3.orthonormalize(root[:3, :3])
        return Pose(root, self.angles + delta[6:])


# ---------------------------------------------------------------------------------------------
# The body model
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BodyModel:
    """A kinematic tree with its dimensions and segment shapes. Build with :func:`make_body`.

    Attributes
    ----------
    template : str
    shapes : str
        "ellipsoid" (Bregler & Malik blobs) or "cylinder" (Sidenbladh et al.; tapered cylinders
        and spheres).
    dims : dict of str to float
    segment_names : tuple of str
    segment_parents : array, shape (S,)
        Parent segment index, -1 for the root.
    dof_names : tuple of str
    dof_segment : array, shape (n_dofs,)
        The segment each DOF moves (with all its descendants).
    dof_axes, dof_points : array, shape (n_dofs, 3)
        Axis and a point on it, in the reference frame.
    lower, upper : array, shape (n_dofs,)
        Joint limits in radians.
    twists : array, shape (n_dofs, 6)
        Reference twists ``xi_j = [-w x q, w]`` (eq. 17).
    chain : array of bool, shape (S, n_dofs)
        ``chain[k, j]``: DOF j moves segment k.
    """

    template: str
    shapes: str
    dims: dict
    segment_names: tuple
    segment_parents: np.ndarray
    segment_joint: tuple
    dof_names: tuple
    dof_segment: np.ndarray
    dof_axes: np.ndarray
    dof_points: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    twists: np.ndarray
    chain: np.ndarray
    landmark_segment: np.ndarray      # (17,) segment index carrying each standard joint
    landmark_points: np.ndarray       # (17, 3) reference positions of the standard joints
    _points: dict = field(repr=False, compare=False)
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    # -- sizes and lookups ------------------------------------------------------------------

    @property
    def n_segments(self):
        return len(self.segment_names)

    @property
    def n_dofs(self):
        return len(self.dof_names)

    @property
    def n_params(self):
        """Parameters of a pose increment: 6 for the root twist plus one per DOF."""
        return 6 + self.n_dofs

    def segment_index(self, name):
        try:
            return self.segment_names.index(name)
        except ValueError:
            raise ZoopraxisError(f"body template '{self.template}' has no segment '{name}'")

    def dof_index(self, name):
        try:
            return self.dof_names.index(name)
        except ValueError:
            raise ZoopraxisError(f"body template '{self.template}' has no DOF '{name}'")

    def reference_point(self, name):
        """A named point (joint centre or landmark) of the reference configuration, (3,)."""
        return self._points[name].copy()

    def with_dims(self, dims):
        """The same template with other body dimensions (missing names keep their values)."""
        merged = dict(self.dims)
        unknown = set(dims) - set(DIM_NAMES)
        if unknown:
            raise ZoopraxisError(f"unknown body dimension(s): {', '.join(sorted(unknown))}")
        merged.update({k: float(v) for k, v in dims.items()})
        return make_body(self.template, merged, shapes=self.shapes)

    def dims_vector(self, names=LENGTH_DIMS):
        return np.array([self.dims[n] for n in names])

    def rest_pose(self, root=None):
        """All angles zero (standing, arms down), with an optional root transform."""
        return Pose(np.eye(4) if root is None else np.array(root, dtype=float),
                    np.zeros(self.n_dofs))

    def clamp(self, angles):
        """Angles clipped to the joint limits (any leading batch shape)."""
        return np.clip(angles, self.lower, self.upper)

    def limit_violation(self, angles):
        """How far angles lie outside their limits (0 inside), same shape as ``angles``."""
        return np.maximum(self.lower - angles, 0.0) + np.maximum(angles - self.upper, 0.0)

    # -- forward kinematics -----------------------------------------------------------------

    def _prefix_and_segments(self, root, angles):
        """Batched product of exponentials.

        Returns ``dof_prefix`` (B, n, 4, 4), the transform applied before DOF j's own
        exponential (``G_0`` times the exponentials of all DOFs above j), and ``seg2world``
        (B, S, 4, 4).
        """
        B = root.shape[0]
        E = self._exp(angles)                                           # (B, n, 4, 4)
        seg2world = np.empty((B, self.n_segments, 4, 4))
        prefix = np.empty((B, self.n_dofs, 4, 4))
        for k, parent, dofs in self._plan:
            T = root if parent < 0 else seg2world[:, parent]
            for j in dofs:
                prefix[:, j] = T
                T = T @ E[:, j]
            seg2world[:, k] = T
        return prefix, seg2world

    @property
    def _exp(self):
        """The joints' exponentials (:class:`se3.RevoluteExp`): ``_exp(angles[, dofs])``."""
        cached = self._cache.get("exp")
        if cached is None:
            cached = self._cache["exp"] = se3.RevoluteExp(self.twists)
        return cached

    @property
    def _dofs_of_segment(self):
        cached = self._cache.get("dofs_of_segment")
        if cached is None:
            cached = [np.flatnonzero(self.dof_segment == k) for k in range(self.n_segments)]
            self._cache["dofs_of_segment"] = cached
        return cached

    @property
    def _plan(self):
        """``(segment, parent, DOF indices)`` of every segment, parents first, as Python ints
        (the kinematic loops run thousands of times a frame)."""
        cached = self._cache.get("plan")
        if cached is None:
            cached = [(k, int(self.segment_parents[k]), self._dofs_of_segment[k].tolist())
                      for k in range(self.n_segments)]
            self._cache["plan"] = cached
        return cached

    def _chain_plan(self, segments):
        """What :meth:`seg2world_of` needs for ``segments``: the DOFs of the segments and their
        ancestors, and per such segment (parents first) its position, its parent's position
        (-1: the root) and the positions of its DOFs among those DOFs."""
        key = ("chain", segments)
        cached = self._cache.get(key)
        if cached is None:
            need = set()
            for k in segments:
                while k >= 0 and k not in need:
                    need.add(k)
                    k = int(self.segment_parents[k])
            chain = sorted(need)            # a parent always comes before its children
            assert all(self.segment_parents[k] < k for k in chain)
            where = {k: i for i, k in enumerate(chain)}
            dofs, steps = [], []
            for k in chain:
                own = self._dofs_of_segment[k].tolist()
                steps.append((where[k], where.get(int(self.segment_parents[k]), -1),
                              list(range(len(dofs), len(dofs) + len(own)))))
                dofs += own
            cached = (np.array(dofs, dtype=int), steps, [where[k] for k in segments])
            self._cache[key] = cached
        return cached

    def seg2world_of(self, pose, angles=None, segments=()):
        """:meth:`seg2world` of some segments only: the product of exponentials runs over
        their chains to the root, not the whole body (the same arithmetic, so the same values).

        Parameters
        ----------
        pose, angles
            As for :meth:`seg2world`; one root may also go with a batch of angles.
        segments : sequence of int

        Returns
        -------
        seg2world : array, shape (len(segments), 4, 4) or (B, len(segments), 4, 4)
        """
        root, angles, single = self._batch(pose, angles)
        single = single and angles.shape[0] == 1
        dofs, steps, pick = self._chain_plan(tuple(int(k) for k in segments))
        A = angles[:, dofs]
        n = max(root.shape[0], A.shape[0])
        # One root with a batch of angles that differ in a few DOFs only (a limb's draws):
        # the chain above them is the same for every draw and is formed once.
        same = ((A == A[:1]).all(axis=0) if root.shape[0] == 1 and n > 1
                else np.zeros(len(dofs), bool))
        E_one = self._exp(A[0, same], dofs[same])
        E_all = self._exp(A[:, ~same], dofs[~same])
        where = np.cumsum(same) - 1, np.cumsum(~same) - 1
        T_chain = []
        for i, parent, local in steps:
            T = root if parent < 0 else T_chain[parent]
            for j in local:
                T = T @ (E_one[where[0][j]][None] if same[j] else E_all[:, where[1][j]])
            T_chain.append(T)
        T = np.empty((n, len(pick), 4, 4))
        for i, k in enumerate(pick):
            T[:, i] = T_chain[k]
        return T[0] if single else T

    @staticmethod
    def _batch(pose_or_root, angles):
        if isinstance(pose_or_root, Pose):
            root, angles = pose_or_root.root, pose_or_root.angles
        else:
            root = pose_or_root
        root = np.asarray(root, dtype=float)
        angles = np.asarray(angles, dtype=float)
        single = root.ndim == 2
        return np.atleast_3d(root).reshape(-1, 4, 4), angles.reshape(-1, angles.shape[-1]), single

    def seg2world(self, pose, angles=None):
        """World transforms of the segments (product of exponentials, eq. 21).

        Parameters
        ----------
        pose : Pose, or array of shape (4, 4) or (B, 4, 4)
            A Pose, or root transforms ``world_from_pelvis`` with ``angles`` given separately.
        angles : array, shape (n_dofs,) or (B, n_dofs), optional

        Returns
        -------
        seg2world : array, shape (S, 4, 4) or (B, S, 4, 4)
            Maps reference-frame coordinates of each segment into the world.
        """
        root, angles, single = self._batch(pose, angles)
        _, T = self._prefix_and_segments(root, angles)
        return T[0] if single else T

    def joints(self, pose, angles=None):
        """World positions of the 17 standard joints (order of ``joints.STANDARD_JOINTS``).

        Returns
        -------
        X : array, shape (17, 3) or (B, 17, 3)
        """
        root, angles, single = self._batch(pose, angles)
        _, T = self._prefix_and_segments(root, angles)
        X = se3.apply(T[:, self.landmark_segment], self.landmark_points)
        return X[0] if single else X

    def kinematics(self, pose):
        """``seg2world`` and ``segment_jacobians`` of one pose from a single pass.

        Returns
        -------
        seg2world : array, shape (S, 4, 4)
        J : array, shape (S, 6, 6 + n_dofs)
        """
        prefix, T = self._prefix_and_segments(pose.root[None], pose.angles[None])
        tw = np.einsum("nij,nj->ni", se3.adjoint(prefix[0]), self.twists)
        J = np.zeros((self.n_segments, 6, self.n_params))
        J[:, :, :6] = np.eye(6)
        J[:, :, 6:] = self.chain[:, None, :] * tw.T[None]
        return T[0], J

    def segment_jacobians(self, pose):
        """Spatial velocity of every segment per unit of each pose parameter.

        Column 0-5: the root twist (moves every segment); column 6 + j: DOF j, non-zero only
        on segments in its subtree. The velocity of a world point X on segment k is
        ``se3.point_velocity_matrix(X) @ J[k] @ delta`` (eqs. 23-24); the image-motion
        Jacobian follows by the chain rule through the camera.

        Returns
        -------
        J : array, shape (S, 6, 6 + n_dofs)
        """
        return self.kinematics(pose)[1]

    def joints_jacobian(self, pose):
        """Standard joints and their derivative with respect to a pose increment.

        Returns
        -------
        X : array, shape (17, 3)
        J : array, shape (17, 3, 6 + n_dofs)
            ``dX / d delta`` for ``pose.retract(delta)`` at ``delta = 0``.
        """
        X = self.joints(pose)
        seg_J = self.segment_jacobians(pose)[self.landmark_segment]      # (17, 6, P)
        return X, se3.point_velocity_matrix(X) @ seg_J

    def joints_dims_jacobian(self, pose, names=LENGTH_DIMS):
        """Derivative of the standard joints with respect to body dimensions at fixed angles.

        For fixed angles the joints are linear in the lengths (the joint centres enter the
        twists linearly; Bregler & Malik §2.6 call the full problem tri-linear), so this is exact.

        Returns
        -------
        J : array, shape (17, 3, len(names))
        """
        base_root = pose.root.copy()
        base_root[:3, 3] = 0.0
        cols = []
        zero = {n: 0.0 for n in DIM_NAMES}
        for name in names:
            unit = make_body(self.template, {**zero, name: 1.0}, shapes=self.shapes,
                             validate=False)
            cols.append(unit.joints(base_root, pose.angles))
        return np.stack(cols, axis=-1)

    # -- shapes -----------------------------------------------------------------------------

    def primitives(self):
        """Segment shapes for the renderer, in each segment's reference frame."""
        from .shapes import body_primitives

        return body_primitives(self)


def make_body(template="full", dims=None, *, shapes=None, validate=True):
    """Build a body model from a template and body dimensions.

    Parameters
    ----------
    template : {"full", "muybridge", "sidenbladh", "yamamoto"}
        ``full``: pelvis, abdomen, chest, head, arms, legs and feet, 29 DOFs covering all 17
        standard joints. ``muybridge``: Bregler & Malik's 19-DOF body. ``sidenbladh``: the
        25-parameter body of Sidenbladh et al. (19 DOFs plus the root). ``yamamoto``: the
        12-part body of Yamamoto et al. (three rotations per joint).
    dims : dict, optional
        Body dimensions in metres (see ``DEFAULT_DIMS``); missing names take the defaults.
    shapes : {"ellipsoid", "cylinder"}, optional
        Segment shape family; defaults to the template's own.
    """
    if template not in TEMPLATES:
        _template_specs(template)  # raises with the list of templates
    merged = dict(DEFAULT_DIMS)
    if dims:
        unknown = set(dims) - set(DIM_NAMES)
        if unknown:
            raise ZoopraxisError(f"unknown body dimension(s): {', '.join(sorted(unknown))}")
        merged.update({k: float(v) for k, v in dims.items()})
    if validate:
        bad = [k for k in LENGTH_DIMS + RADIUS_DIMS
               if not np.isfinite(merged[k]) or merged[k] < 0
               or (merged[k] == 0 and k not in ("shoulder_drop",))]
        if bad:
            raise ZoopraxisError("body dimensions must be positive: "
                                 + ", ".join(f"{k}={merged[k]}" for k in bad))
    shapes = shapes or _DEFAULT_SHAPES[template]
    if shapes not in ("ellipsoid", "cylinder"):
        raise ZoopraxisError(f"unknown shape family '{shapes}' (expected ellipsoid or cylinder)")

    specs = _template_specs(template)
    points = reference_points(merged)
    names = tuple(s.name for s in specs)
    parents = np.array([-1 if s.parent is None else names.index(s.parent) for s in specs])

    dof_names, dof_segment, axes, qs, lo, hi = [], [], [], [], [], []
    for k, spec in enumerate(specs):
        joint_name = spec.joint
        for suffix, axis, lower, upper in spec.dofs:
            dof_names.append(f"{joint_name}_{suffix}")
            dof_segment.append(k)
            axes.append(_mirror_axis(axis) if spec.side == "r" else np.array(axis, float))
            qs.append(points[joint_name])
            lo.append(np.radians(lower))
            hi.append(np.radians(upper))
    axes = np.array(axes)
    qs = np.array(qs)
    twists = se3.revolute_twist(axes, qs)

    n = len(dof_names)
    chain = np.zeros((len(specs), n), dtype=bool)
    for k in range(len(specs)):
        a = k
        while a >= 0:
            chain[k, np.array(dof_segment) == a] = True
            a = parents[a]

    carrier = _landmark_segments(names)
    landmark_segment = np.array([names.index(carrier[j]) for j in STANDARD_JOINTS])
    landmark_points = np.array([points[j] for j in STANDARD_JOINTS])

    return BodyModel(template=template, shapes=shapes, dims=merged, segment_names=names,
                     segment_parents=parents, segment_joint=tuple(s.joint for s in specs),
                     dof_names=tuple(dof_names), dof_segment=np.array(dof_segment, dtype=int),
                     dof_axes=axes, dof_points=qs, lower=np.array(lo), upper=np.array(hi),
                     twists=twists, chain=chain, landmark_segment=landmark_segment,
                     landmark_points=landmark_points, _points=points)


def mirror_dof_index(body):
    """Index permutation swapping each left DOF with its right counterpart (for the
    mirrored-pose ambiguity of a single view, and for Muybridge-style cycle mirroring)."""
    perm = []
    for name in body.dof_names:
        if name.startswith("l_"):
            perm.append(body.dof_names.index("r_" + name[2:]))
        elif name.startswith("r_"):
            perm.append(body.dof_names.index("l_" + name[2:]))
        else:
            perm.append(body.dof_names.index(name))
    return np.array(perm)


__all__ = ["BodyModel", "Pose", "make_body", "reference_points", "mirror_dof_index",
           "TEMPLATES", "DEFAULT_DIMS", "LENGTH_DIMS", "RADIUS_DIMS", "DIM_NAMES"]
