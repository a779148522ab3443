"""The uncalibrated fit (Bregler & Malik §2.3): a scaled orthographic camera per view and
anchor frame, the body root at the identity, started from the body turned every 45 degrees and
from the pose prior's own poses."""

import numpy as np

from ..body.body import LENGTH_DIMS
from ..body.fit3d import dims_from_joints
from ..geometry import se3
from ..priors.basis import body_size
from ..geometry.ortho import ScaledOrthoCamera
from ..geometry.triangulate import similarity_from_points
from .fit import _Fit
from .problem import (CLICK_SIGMA_PX, DIMS_PRIOR_FLOOR_M, DIMS_PRIOR_SIGMA, DIMS_RANGE,
                      PRIOR_WEIGHT, _fit, _prior_residual, _rho_px, _State)
from .starts import _TORSO, _affine_camera, _fit_3d, _fit_limbs_3d, _ortho_camera

_MIN_VIEW_JOINTS = 4       # an uncalibrated view needs this many clicks to place its camera
# A frame seen in one view is also searched from the prior's own poses whose projection best
# matches the clicks (each under its best scaled orthographic camera): this many of them, that
# differ by at least EXEMPLAR_APART_DEG in some angle, out of at most EXEMPLAR_POOL poses.
EXEMPLAR_STARTS = 2
EXEMPLAR_APART_DEG = 20.0
EXEMPLAR_POOL = 4000
# A frame seen in one view is also searched from the pose basis' fits to its clicks
# (priors/basis.py): the joints of this many of its best local minima, posed by inverse
# kinematics with the lengths measured on them (and the lengths' prior centred there).
BASIS_STARTS = 2
# Weight of the basis' density of the 3D joints in the score that chooses the limbs' depth
# signs and the search (nats per nat).
BASIS_WEIGHT = 1.0
# The lengths' prior of uncalibrated views is heavy-tailed: Gaussian (DIMS_PRIOR_SIGMA about
# the template's proportions) within this many spreads, soft L1 beyond (problem._prior_residual),
# and the fits a frame's search compares are scored with it. One view sees a length only through
# its bone's foreshortening, and a Gaussian prior pays more to shrink a bone a third than to turn
# it in depth: fitted to one view of held-out CMU performers (bench_initialize.py --only
# held-out-subjects), shoulders of cgspeed's Daz figure (0.65 of the template's proportion) came
# out 50 % too wide and the trunk twisted to meet the clicks. See benchmarks/README.md.
DIMS_LOSS = 0.5


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
                       perspective=self.perspective, dims_prior=self.dims_prior,
                       dims_loss=DIMS_LOSS)
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
        own = self.dims_prior
        searches = [(True, None, own), (False, None, own)] + \
            [(True, s, own) for s in self._exemplars(f)] + \
            [(True, s, own if not self.fit_dims else (s.dims.copy(), DIMS_PRIOR_SIGMA))
             for s in self._basis_starts(f)]
        for in_fit, start, dims_prior in searches:
            self._prior_in_fit, self.ambiguous = in_fit, ambiguous
            self._start, self.dims_prior = start, dims_prior
            self.ambiguous_parts[frame] = list(parts)
            try:
                state = super()._frame(f)
            finally:
                self._prior_in_fit, self._start = True, None
            try:
                if not in_fit:
                    state, _, _ = _fit(self.kin, self.obs[f:f + 1], self.weights[f:f + 1],
                                       state, **self.options(state, f, fit_dims=self.fit_dims))
            finally:
                self.dims_prior = own
            found.append((float(self._score(state, f, state.angles)[0]), len(found), state,
                          self.warnings[kept:], self.ambiguous, self.ambiguous_parts[frame],
                          dims_prior))
            del self.warnings[kept:]
        _, _, state, notes, self.ambiguous, chosen, dims_prior = min(found,
                                                                     key=lambda t: t[:2])
        if dims_prior is not own:
            # the lengths' prior of the basis' start stays with its pose in the joint fit
            self._basis_dims.append(dims_prior[0])
            self.dims_prior = (np.mean(self._basis_dims, axis=0), DIMS_PRIOR_SIGMA)
        self.warnings += notes
        if chosen:
            self.ambiguous_parts[frame] = chosen
        else:
            self.ambiguous_parts.pop(frame, None)
        return state

    _start = None       # a start of _frame's search other than the body turns
    basis = None        # PoseBasis of 3D joint sets (priors/basis.py), or None

    @property
    def _basis_dims(self):
        if "_chosen_dims" not in self.__dict__:
            self._chosen_dims = []
        return self._chosen_dims

    def _score(self, state, f, angles):
        """As :meth:`_Fit._score`, plus the lengths' prior (when they are fitted: the fits
        compared may differ in their lengths) and the pose basis' density of the 3D joints
        (weight BASIS_WEIGHT)."""
        score = super()._score(state, f, angles)
        if self.fit_dims:
            score = score + self._dims_cost(state)
        if self.basis is not None and BASIS_WEIGHT > 0:
            score = score + BASIS_WEIGHT * self.basis.cost(
                self.kin.forward(np.atleast_2d(angles), state.dims)[0])
        return score

    def _dims_cost(self, state):
        """The lengths' prior cost (nats) of a state, as the fit weighs it."""
        mean, sigma = (self.kin.default_dims, DIMS_PRIOR_SIGMA) if self.dims_prior is None \
            else self.dims_prior
        spread = np.maximum(sigma, DIMS_PRIOR_FLOOR_M / mean)
        z, _ = _prior_residual((state.dims / mean - state.size) / spread, DIMS_LOSS)
        return 0.5 * float(np.sum(z ** 2))

    def _basis_starts(self, f):
        """Starts for a frame seen in one view from the pose basis' fits to its clicks
        (``PoseBasis.fit_view``): the BASIS_STARTS best, each posed by inverse kinematics on
        its joints (scaled to the template's size) with the lengths measured on them, unless
        the lengths are kept, and the camera of the fit."""
        if self.basis is None or BASIS_STARTS <= 0:
            return []
        kin = self.kin
        v = int(np.flatnonzero(self.usable[f])[0])
        uv = np.where((self.weights[f, v] > 0)[:, None], self.obs[f, v], np.nan)
        angles0 = kin.start_angles()
        size = self.sizes[v]
        centre = np.array([(size[0] - 1) / 2, (size[1] - 1) / 2])
        starts = []
        for fit in self.basis.fit_view(uv, noise_px=CLICK_SIGMA_PX)[:BASIS_STARTS]:
            Y0 = kin.forward(angles0[None], self.dims0)[0][0]
            unit = body_size(Y0[None])
            X = fit["joints"] * unit
            dims = self.dims0.copy()
            if self.fit_dims:
                measured = dims_from_joints(X)
                dims = np.array([measured.get(n, d) for n, d in zip(LENGTH_DIMS, dims)])
                dims = np.clip(dims, DIMS_RANGE[0] * self.dims0, DIMS_RANGE[1] * self.dims0)
                Y0 = kin.forward(angles0[None], dims)[0][0]
            R, t, _ = similarity_from_points(Y0[_TORSO], X[_TORSO], with_scale=False)
            root, angles, _ = _fit_3d(kin, X, dims, se3.transform(R, t), angles0)
            angles = _fit_limbs_3d(kin, X, dims, root, angles)
            # uv = s_b (R_b X / unit)_xy + t_b and X ~ root (Y): the camera of the body frame
            scale = fit["scale"] / unit
            R_cam = fit["camera"] @ root[:3, :3]
            shift = (fit["camera"] @ root[:3, 3])[:2] + (fit["shift"] - centre) / scale
            cams = [None] * len(self.views)
            cams[v] = ScaledOrthoCamera(self.views[v], size, float(scale), R=R_cam,
                                        t=[shift[0], shift[1], 10.0], c=centre)
            starts.append(_State(dims, 1.0, np.eye(4)[None], angles[None], [cams]))
        return starts
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
