"""The calibrated fit: perspective cameras known, one world pose per anchor frame (Yamamoto et
al.; Sidenbladh et al.), started from triangulated joints."""

import numpy as np

from ..body.joints import JOINT_INDEX
from ..geometry import se3
from ..geometry.triangulate import similarity_from_points, triangulate
from .fit import _Fit
from .problem import DIMS_RANGE, _fit, _State
from .starts import _TORSO, _fit_3d, _image_scale, _poses_on_points, _rot_z


class _CalibratedFit(_Fit):
    """Calibrated views: one world pose per anchor frame."""

    calibrated = True

    dims_prior = None       # (mean, sigma) of the lengths (proportions.ProportionsPrior)

    def __init__(self, kin, obs, weights, cameras, views, anchors, dims0, fit_dims, warnings):
        super().__init__(kin, obs, weights, views, anchors, dims0, fit_dims, warnings)
        self.cams = cameras

    def options(self, state, f, fit_dims):
        return dict(free_root=True, fit_dims=fit_dims, calibrated=True,
                    dims_prior=self.dims_prior)

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
            states = [self._state(root, angles, dims, scale) for root, angles in
                      _poses_on_points(kin, X, dims, se3.transform(R, t), angles0)]
            if len(states) == 1:
                return states[0]
            obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
            fits = [_fit(kin, obs, w, state, **self.options(state, f, fit_dims=self.fit_dims))
                    for state in states]
            return min(fits, key=lambda fit: fit[1])[0]
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
