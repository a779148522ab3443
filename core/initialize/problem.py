"""The joint problem of the initialization (Bregler & Malik §2.6): reprojection of the model
joints over anchor frames and views as a robust least-squares problem with analytic Jacobians
(:class:`_Problem`), what it fits (:class:`_State`), and the priors' weights.

Convention: world Z up, metres; OpenCV cameras and pixels. Rotations in the parameter vectors
are increments ``exp(w) @ R_start`` on the left (spatial), like ``Pose.retract``.
"""

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from ..body.joints import STANDARD_JOINTS
from ..geometry import se3

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
# Uncalibrated views of a near body (``initialize(..., perspective=True)``): the perspective of
# each camera (``ScaledOrthoCamera.kappa``, the inverse distance) is fitted, for cameras at least
# 1 / KAPPA_MAX metres from the body. It is not left to the clicks to say whether a view is
# near: an orthographic fit of a near view bends the pose to meet them, so that freeing the
# perspective lowers its cost by a nat or two there, no more than it does by fitting the clicks'
# noise in a far view (where it only breaks the ties of depth that one view must report).
KAPPA_MAX = 0.5

_ROOT_PARAMS = 6   # per frame: translation (3), rotation increment (3)
_CAM_PARAMS = 7    # per uncalibrated camera: log scale, rotation increment (3), shift (2), kappa
# Above this many Jacobian entries the problem is solved by blocks (frames couple only through
# the dimensions); below, by scipy's least_squares on a dense Jacobian.
_DENSE_LIMIT = 400_000
# Weight of the learned prior's -log p in the fit of frames seen in one view, in click
# variances per nat (1: the posterior of clicks with CLICK_SIGMA_PX noise).
PRIOR_WEIGHT = 1.0


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
    priors (the lengths' soft L1 beyond ``dims_loss`` spreads when given, ``_prior_residual``).
    """

    def __init__(self, kin, obs, weights, state, *, free_root, free_angles=True, free_cams=None,
                 fit_dims=True, calibrated=True, loss_scale=LOSS_SCALE_PX, dims_range=DIMS_RANGE,
                 pose_prior=None, prior_frames=None, tilt=None, tilt_frames=None,
                 perspective=False, dims_prior=None, dims_loss=None):
        self.kin = kin
        self.dims_loss = dims_loss
        # (mean (D,), relative sigma (D,)) of the lengths about ``size * mean``: the template's
        # proportions and DIMS_PRIOR_SIGMA unless the fit gives its own (a learned proportions
        # prior, run.one_view_dims_prior, run.SEVERAL_VIEWS_DIMS_SIGMA).
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
            spread = np.maximum(self.dims_sigma, DIMS_PRIOR_FLOOR_M / d0)
            if self.dims_loss is None:
                # Gaussian: the arithmetic as it always was, so that calibrated fits are the
                # same to the bit
                wd = CLICK_SIGMA_PX / spread
                res.append(wd * (dims / d0 - size))
            else:
                z, dz = _prior_residual((dims / d0 - size) / spread, self.dims_loss)
                wd = CLICK_SIGMA_PX * dz / spread
                res.append(CLICK_SIGMA_PX * z)
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


def _prior_residual(z, scale):
    """A Gaussian prior's whitened residuals ``z`` made soft L1 of ``scale`` (in spreads; None:
    left Gaussian), as residuals ``r`` with ``0.5 r^2 = scale^2 (sqrt(1 + z^2 / scale^2) - 1)``,
    and ``dr / dz``."""
    if scale is None:
        return z, np.ones_like(z)
    q = np.sqrt(1.0 + (z / scale) ** 2)
    # 2 (q - 1) = 2 (z / scale)^2 / (q + 1), without cancelling near z = 0
    r = z * np.sqrt(2.0 / (1.0 + q))
    dz = np.sqrt(0.5 * (1.0 + q)) / q
    return r, dz


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
