"""Differential twist tracker: Gauss-Newton on image motion, one to eight views.

From a pose at frame t and the images of t and t+1 in every view, find the pose at t+1
(Bregler & Malik §2.5's recipe, with Yamamoto et al.'s calibrated multi-view system):

1. Render the model at the pose of t in each view: support map, depth and surface points
   (Yamamoto's region and depth images; B&M step 1-2).
2. From the coarsest pyramid level to the finest: linearise the image-motion residuals
   (:mod:`image_motion`), accumulate the normal equations per segment, solve for the pose
   increment, update root and angles, re-sample ``I(t+1)`` at the moved points (the warp of step
   4e) and iterate (Levenberg-Marquardt damping keeps every step downhill).
3. Support maps are refined by EM against a static background layer (§2.4): a pixel that is
   better explained by "nothing moved here" than by its segment's motion loses its weight.

Two persistent cues keep the frame-to-frame motion from drifting (Yamamoto §4): appearance
taken from the anchor frame, and the silhouette against a background model, both as residuals in
the same least squares. On colour plates the anchor's appearance includes its chromaticity
(colour without brightness, :func:`frames.chromaticity`): a bare forearm over a shirt of its
grey level, which the grey image cannot tell apart, keeps its colour while it turns and its
shading changes. Joint limits hold after every step.

Calibrated views share one world pose (Yamamoto eqs. 8-12); uncalibrated views each carry their
own scaled-orthographic pose of the body and share the joint angles (B&M eq. 28).
"""

from collections import OrderedDict
from dataclasses import dataclass, field
from functools import partial

import cv2
import numpy as np

from ..geometry import se3
from ..imaging.background import model_coverage, silhouette_iou
from ..body.body import Pose
from ..body.collision import body_proxies, penalty_system
from .frames import thread_pool
from .image_motion import (Accumulated, Stack, Term, accumulate, accumulate_stacked, assemble,
                           shown_in_render, support_weights)
from .anchor import Anchor
from .limb_refit import LimbRefit
from .recover import LimbSearch
from ..imaging.render import render, surface_points


@dataclass
class Settings:
    """Tracker settings; the defaults suit 480x360 to 960x540 working images at 25-60 fps."""

    levels: int = 3                   # pyramid levels (0 = working resolution)
    iterations: tuple = (4, 4, 3)     # Gauss-Newton iterations per level, coarse to fine
    stride: int = 2                   # pixel subsampling of the template at the finest level
    finest: int = 0                   # finest pyramid level solved (1: half resolution, faster)
    max_points: int = 5000            # per view and level
    smooth_sigma: float = 1.0         # Gaussian pre-smoothing of the grey images, pixels
    flow_weight: float = 1.0          # frame-to-frame image motion term
    flow_scale: float = 0.05          # robust scale of grey residuals (images in [0, 1])
    anchor_weight: float = 0.5        # persistent appearance term
    chroma_weight: float = 0.5        # the anchor's chromaticity (colour plates), relative to
                                      # the grey anchor at their robust scales
    chroma_scale: float = 0.02        # robust scale of chromaticity residuals
    whole_turn: bool = True           # a second start keeping the pelvis's whole turn
                                      # (limb_refit.py)
    hands: bool = True                # the limb search draws a lost arm's hand to its colour
    relight: bool = True              # the anchor under the light of the frame before
                                      # (light.py)
    silhouette_weight: float = 0.002  # signed-distance term (per pixel^2, relative to grey^2)
    silhouette_scale: float = 3.0     # robust scale of silhouette residuals, pixels
    silhouette_margin: float = 1.0    # contour may stray this far outside the silhouette, px
                                      # (negative: two-sided, the contour on the boundary)
    em: bool = True                   # EM refinement of the support maps
    velocity: float = 0.5             # fraction of the last motion used to predict the next
    learned_carry: bool = True        # calibrated: the pelvis's translation and the legs'
                                      # angles predicted with the carry learned from capture
                                      # (priors/general.py), not ``velocity``
                                      # (DifferentialStepper sets it)
    prior_weight: float = 0.01        # pull towards the prediction, relative to the data
    pose_space_weight: float = 0.01   # one calibrated view: pull of the angles towards the
                                      # pose space learned from capture (``pose_space``),
                                      # relative to the data (0: none)
    pose_space_views: float = 0.2     # two calibrated views or more: the pull's share of
                                      # one view's (it holds what they leave free: the
                                      # pelvis's turn traded for the hips' rotation)
    damping: float = 1e-3             # initial Levenberg-Marquardt damping
    collision_weight: float = 3e4     # limb overlap penalty, per square metre
    threads: int = 1                  # >1: views rendered, prepared and (uncalibrated) solved in
                                      # a thread pool (no gain measured at 480x360: numpy holds
                                      # the GIL between small operations)
    limb_search: bool = True          # silhouette search for limbs left behind (recover.py;
                                      # calibrated, two views or more)
    refit_tolerance: float = 0.05     # a limb the search moved is kept when the frame's cost
                                      # without that limb's image motion is at most this much
                                      # higher (the refit re-solves the whole body from another
                                      # start: the rest moves by a few per cent either way;
                                      # realistic sets, 0.02-0.05 alike, 0.1 worse on punch02)
    refit_view_drop: float = 0.02     # ... and no view's silhouette overlap (IoU) falls by
                                      # more than this (of 276 refits kept before, the 7 over
                                      # 0.02: 4 worse by 27-66 mm, the dance's flung legs
                                      # among them, 1 by 2 mm, 2 better by 4 and 15; at 0.03
                                      # two of the flings were kept)
    tolerance: float = 1e-5           # stop a level's iterations when no parameter moves more
                                      # (metres or radians)
    contour_per_level: bool = True    # render the contour at every pyramid level (False:
                                      # once per frame at the finest level, at the start pose)


@dataclass
class State:
    """Pose of the tracked body: shared angles and one root per view.

    Calibrated views all hold the same world root; uncalibrated views hold the body's pose in
    their own camera frame, and their scaled-orthographic cameras carry the scale.
    """

    roots: np.ndarray        # (V, 4, 4)
    angles: np.ndarray       # (n_dofs,)
    cameras: list            # per view, at working resolution
    # DOFs the limb search corrected at this frame: their change from the frame before is
    # the estimate's correction, not the body's motion, and is not carried on (``predict``)
    corrected: np.ndarray = None

    def copy(self):
        return State(self.roots.copy(), self.angles.copy(), list(self.cameras))

    def pose(self, view=0):
        return Pose(self.roots[view], self.angles)


@dataclass
class StepReport:
    """Diagnostics of one tracked frame."""

    residual: np.ndarray          # (V,) mean absolute grey residual of the flow term, 0-255
    iou: np.ndarray               # (V,) model/foreground silhouette overlap (NaN: no mask)
    cost: float
    iterations: int
    renders: list = field(default_factory=list)   # per view RenderResult at the new pose
    coverage: np.ndarray = None   # (V,) fraction of the model's silhouette inside the foreground
    recovered: list = field(default_factory=list)   # limbs moved by the silhouette search
    limb_fit: dict = None         # limb name -> silhouette score in [-1, 1] (recover.py)
    unexplained: np.ndarray = None  # (V,) thick foreground blobs the model misses / model area


def _contour_pixels(mask):
    """Rows and columns of the mask's pixels with a 3x3 neighbour off the mask (the image's
    edge counts as on it), in row-major order: ``np.nonzero(mask & ~cv2.erode(mask))``,
    worked out on the mask's bounding box grown by a pixel rather than on the whole image."""
    rows = np.flatnonzero(mask.any(axis=1))
    if rows.size == 0:
        return np.nonzero(np.zeros((0, 0), bool))
    cols = np.flatnonzero(mask.any(axis=0))
    H, W = mask.shape
    r0, r1 = max(rows[0] - 1, 0), min(rows[-1] + 2, H)
    c0, c1 = max(cols[0] - 1, 0), min(cols[-1] + 2, W)
    box = mask[r0:r1, c0:c1]
    # Inside the image the box's outer ring is off the mask, as in the whole image; at the
    # image's edge both erode with the same border.
    eroded = cv2.erode(box.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    vv, uu = np.nonzero(box & ~eroded)
    vv += r0
    uu += c0
    return vv, uu


def _median(x):
    """``np.median`` of a short 1-D array: the middle value, or the mean of the two middle
    values (``(a + b) / 2``, the same sum and quotient), without np.median's overhead."""
    if len(x) == 0 or np.isnan(x).any():
        return np.median(x)
    s = np.sort(x)
    h = len(s) // 2
    if len(s) % 2:
        return s[h]
    return (s[h - 1] + s[h]) / 2.0


class DifferentialTracker(Anchor, LimbRefit):
    """Gauss-Newton tracker over a body model and a set of views.

    Parameters
    ----------
    body : BodyModel
    calibrated : bool
        True: ``State.roots`` are all the same world pose and cameras are perspective.
        False: each view has its own root and a scaled-orthographic camera (B&M §2.3).
    settings : Settings
    """

    def __init__(self, body, calibrated, settings=None):
        self.body = body
        self.calibrated = calibrated
        self.settings = settings or Settings()
        self.prims = body.primitives()
        self.proxies = body_proxies(body)
        self.anchor_terms = None
        self.chroma_terms = None
        self.light = None
        self.search = LimbSearch(body)
        # caches of derived values, read-only once made (see the methods that fill them)
        self._scaled = {}
        self._stack_cache = None
        self._param_groups_cache = {}
        self._seg2world_cache = OrderedDict()
        self._visible_cache = {}

    # -- parameter layout ---------------------------------------------------------------------

    def layout(self, n_views):
        """Columns of each view's root twist, its scale, and the shared angles."""
        n = self.body.n_dofs
        if self.calibrated:
            roots = [np.arange(6)] * n_views
            scales = [None] * n_views
            angles = np.arange(6, 6 + n)
            return roots, scales, angles, 6 + n
        roots = [np.arange(7 * c, 7 * c + 6) for c in range(n_views)]
        scales = [7 * c + 6 for c in range(n_views)]
        angles = np.arange(7 * n_views, 7 * n_views + n)
        return roots, scales, angles, 7 * n_views + n

    def _param_groups(self, n_views):
        """Index groups of like parameters: root translations, root rotations, scales, angles
        (made once per number of views; read-only)."""
        cache = self._param_groups_cache
        groups = cache.get(n_views)
        if groups is None:
            groups = cache[n_views] = self._make_param_groups(n_views)
            for g in groups:
                g.flags.writeable = False
        return groups

    def _make_param_groups(self, n_views):
        roots_cols, scale_cols, angle_cols, _ = self.layout(n_views)
        roots = np.unique(np.concatenate(roots_cols))
        groups = [roots[np.arange(len(roots)) % 6 < 3], roots[np.arange(len(roots)) % 6 >= 3],
                  angle_cols]
        if scale_cols[0] is not None:
            groups.append(np.array(scale_cols))
        return groups

    def _about_pelvis(self, state):
        """Calibrated views: the matrix from the step's parameters, the root's twist taken about
        the pelvis at ``p``, to those :meth:`retract` applies (about the world origin: ``v + p x
        w``); None for scaled orthography. About the origin a turn on the spot is a turn and a
        swing back as long as ``|p|``, which the pull towards the prediction held back: the
        spine's and hips' twists took the turn up instead (dance05_hard's pirouette)."""
        if not self.calibrated:
            return None
        M = np.eye(6 + self.body.n_dofs)
        M[:3, 3:6] = se3.hat3(state.roots[0][:3, 3])
        return M

    def retract(self, state, delta):
        """Apply a parameter increment to a state, clamping the angles to the joint limits."""
        roots_cols, scale_cols, angle_cols, _ = self.layout(len(state.cameras))
        new = state.copy()
        if self.calibrated:
            root = se3.exp_se3(delta[:6]) @ state.roots[0]
            root[:3, :3] = se3.orthonormalize(root[:3, :3])
            new.roots[:] = root
        else:
            for c, cols in enumerate(roots_cols):
                root = se3.exp_se3(delta[cols]) @ state.roots[c]
                root[:3, :3] = se3.orthonormalize(root[:3, :3])
                new.roots[c] = root
                cam = state.cameras[c]
                new.cameras[c] = cam.replace(s=cam.s * float(np.exp(delta[scale_cols[c]])))
        new.angles = self.body.clamp(state.angles + delta[angle_cols])
        return new

    # Per world axis, the share of the pelvis's last motion carried into the next frame's
    # prediction (``tx ty tz rx ry rz``), or None: the root moves as the angles do,
    # ``settings.velocity`` of its last screw motion. Calibrated views only (see
    # :meth:`predict`); the take's stepper sets it from the motion learned from capture.
    root_carry = None
    # Per joint angle, the share of its last change carried into the prediction, or None:
    # ``settings.velocity`` for every angle.
    angle_carry = None
    # Calibrated views: the pull towards the pose space learned from capture
    # (:class:`stepper.PoseSpacePull`), or None; the take's stepper sets it.
    pose_space = None

    def predict(self, state, previous=None):
        """Constant-velocity prediction, damped by ``settings.velocity`` (per angle by
        :attr:`angle_carry` where that is set), and the pelvis's by :attr:`root_carry` where
        that is set (calibrated views: it moves in world axes). The angles the limb search
        corrected at ``state`` (``State.corrected``) are not carried on."""
        if previous is None or self.settings.velocity == 0:
            return state.copy()
        k = self.settings.velocity
        carry = k if self.angle_carry is None else np.asarray(self.angle_carry, float)
        new = state.copy()
        velocity = state.angles - previous.angles
        if state.corrected is not None:
            velocity[state.corrected] = 0.0
        new.angles = self.body.clamp(state.angles + carry * velocity)
        if self.root_carry is not None and self.calibrated:
            carry = np.asarray(self.root_carry, float)
            root, before = state.roots[0], previous.roots[0]
            moved = root.copy()
            moved[:3, 3] += carry[:3] * (root[:3, 3] - before[:3, 3])
            turn = se3.log_so3(root[:3, :3] @ before[:3, :3].T)     # world axes
            moved[:3, :3] = se3.exp_so3(carry[3:] * turn) @ root[:3, :3]
            new.roots[:] = moved
            return new
        for c in range(len(state.roots)):
            motion = se3.log_se3(state.roots[c] @ se3.invert(previous.roots[c]))
            new.roots[c] = se3.exp_se3(k * motion) @ state.roots[c]
        return new

    # -- terms ----------------------------------------------------------------------------------

    def _camera_at(self, camera, level):
        """The camera of a pyramid level; kept per camera object, so the renderer's ray grids
        (cached per camera) are built once per take, not at every iteration."""
        if level == 0:
            return camera
        key = (id(camera), level)
        hit = self._scaled.get(key)
        if hit is not None and hit[0] is camera:
            return hit[1]
        if len(self._scaled) > 64:          # scaled-orthographic views change every frame
            self._scaled.clear()
        scaled = camera.scaled(0.5 ** level)
        self._scaled[key] = (camera, scaled)
        return scaled

    def _seg2world(self, state, c):
        """``body.seg2world(state.pose(c))``, remembered for the last few poses: calibrated
        views share one pose, and the anchor's visibility, the contours, the templates and
        the renders of a frame ask for the same poses again. Read-only; the same values."""
        root, angles = state.roots[c], state.angles
        key = (root.tobytes(), angles.tobytes(), angles.shape)
        cache = self._seg2world_cache
        T = cache.get(key)
        if T is None:
            T = self.body.seg2world(state.pose(c))
            T.flags.writeable = False
            cache[key] = T
            while len(cache) > 8:
                cache.popitem(last=False)
        return T

    def template_terms(self, state, images_t, renders):
        """Image-motion terms from the rendered model at frame t, per view and level.

        Returns
        -------
        terms : list (levels) of list (views) of Term
        """
        s = self.settings
        out = []
        seg2world = [self._seg2world(state, c) for c in range(len(images_t))]
        world2seg = [se3.invert(T) for T in seg2world]
        for level in range(s.levels):
            if level < min(s.finest, s.levels - 1):
                out.append(None)        # finer than the tracker solves
                continue
            per_view = []
            for c, (im, rr) in enumerate(zip(images_t, renders)):
                step = 2 ** level
                stride = s.stride if level == 0 else 1
                k = step * stride
                lab = rr.label[::k, ::k]
                vv, uu = np.nonzero(lab >= 0)
                if len(vv) > s.max_points:
                    keep = np.linspace(0, len(vv) - 1, s.max_points).astype(int)
                    vv, uu = vv[keep], uu[keep]
                seg = lab[vv, uu].astype(np.int64)
                # the render's surface points at these pixels (``rr.point[vv * k, uu * k]``
                # to the bit), from its depth image: no point image for the whole view
                X = surface_points(state.cameras[c], rr.depth, vv * k,
                                   uu * k).astype(np.float64)
                ref = se3.apply(world2seg[c][seg], X)
                gray = im.gray[level]
                gv, gu = vv * stride, uu * stride
                gv = np.minimum(gv, gray.shape[0] - 1)
                gu = np.minimum(gu, gray.shape[1] - 1)
                target = gray[gv, gu].astype(np.float64)
                weight = np.ones(len(seg))
                if im.foreground is not None:
                    # A model pixel the background model calls background is likely not body:
                    # start the EM from a low prior there.
                    fg = im.foreground[vv * step * stride, uu * step * stride]
                    weight = np.where(fg, 1.0, 0.25)
                uv = np.column_stack([gu, gv]).astype(np.float64)
                per_view.append(Term(c, seg, ref, target, weight, s.flow_scale, "flow", uv))
            out.append(per_view)
        return out

    def contour_terms(self, state, level):
        """Silhouette terms: the model's contour points should lie on the observed boundary.

        The contour is rendered at the current estimate and at the level's resolution, so the
        points are the occluding contour of the pose being refined, not of the previous frame.
        """
        def one(c):
            cam_l = self._camera_at(state.cameras[c], level)
            T = self._seg2world(state, c)
            # Points are wanted at the contour only: render without them, then take the
            # contour's points from the depth image (the same values).
            rr = render(cam_l, T, self.prims, want=())
            vv, uu = _contour_pixels(rr.label >= 0)
            if len(vv) > 1500:
                keep = np.linspace(0, len(vv) - 1, 1500).astype(int)
                vv, uu = vv[keep], uu[keep]
            seg = rr.label[vv, uu].astype(np.int64)
            X = surface_points(cam_l, rr.depth, vv, uu).astype(np.float64)
            ref = se3.apply(se3.invert(T)[seg], X)
            return Term(c, seg, ref, np.zeros(len(seg)), np.ones(len(seg)),
                        self.settings.silhouette_scale / 2 ** level, "silhouette",
                        hinge=None if self.settings.silhouette_margin < 0
                        else self.settings.silhouette_margin / 2 ** level)

        return self.map_views(one, len(state.cameras))

    def coarser_contour(self, terms, level, from_level):
        """Contour terms rendered at ``from_level``, thinned and rescaled for ``level``."""
        s = self.settings
        out = []
        for t in terms:
            sub = t.subset(np.arange(0, len(t), 2 ** (level - from_level)))
            sub.scale = s.silhouette_scale / 2 ** level
            sub.hinge = None if s.silhouette_margin < 0 else s.silhouette_margin / 2 ** level
            out.append(sub)
        return out

    @staticmethod
    def _image_of(images, key, level):
        """The image (with gradients) that terms named ``key`` sample."""
        if key == "silhouette":
            return images.sdf[level]
        if key.startswith("chroma"):
            return images.chroma[int(key[6:])][level]
        return images.stacks[level]

    # -- rendering -------------------------------------------------------------------------------

    def render_views(self, state, want=()):
        def one(c):
            return render(state.cameras[c], self._seg2world(state, c), self.prims, want=want)

        return self.map_views(one, len(state.cameras))

    def map_views(self, fn, n):
        """``[fn(c) for c in range(n)]``, over views in parallel when ``settings.threads``."""
        if n > 1 and self.settings.threads > 1:
            return list(thread_pool("views", 2).map(fn, range(n)))
        return [fn(c) for c in range(n)]

    # -- one frame ---------------------------------------------------------------------------------

    def _visible(self, term, state, level, renders):
        """Anchor points still visible at the current pose (depth test against the render)."""
        c = term.view
        cam = self._camera_at(state.cameras[c], level)
        # A frame whose step runs twice (a limb search's refit) asks again with the same
        # frame-t pose and renders: answer from the last time.
        seen = self._visible_cache
        key = (id(term), level)
        pose = (state.roots[c].tobytes(), state.angles.tobytes())
        hit = seen.get(key)
        if hit is not None and hit[0] is term and hit[1] is renders[c] and hit[2] is cam \
                and hit[3] == pose:
            return hit[4].copy()
        X = se3.apply(self._seg2world(state, c)[term.segment], term.ref_points)
        visible = shown_in_render(term.segment, cam.project(X), renders[c].label, level)
        if len(seen) > 64:
            seen.clear()
        seen[key] = (term, renders[c], cam, pose, visible.copy())
        return visible

    def _system(self, state, level, terms_by_view, images, em_weights, lazy=False):
        """Total normal equations over views and terms at ``state``.

        Terms of one view are summed per segment first and mapped to the pose parameters
        once (:func:`image_motion.assemble`). With ``lazy``, returns ``(normal_equations,
        cost, accs)`` where ``normal_equations()`` gives ``(H, g)``: a step that raises the
        cost is rejected on the cost alone (calibrated views then skip the Jacobians). Call
        it before the next system is made; ``normal_equations(em)`` makes them under other EM
        weights (the costs do not depend on those).
        """
        roots_cols, scale_cols, angle_cols, P = self.layout(len(state.cameras))
        kin = self.body.kinematics(state.pose(0)) if self.calibrated else None
        if self.calibrated:
            data, cost, accs = self._stacked_system(state, level, terms_by_view, images,
                                                    em_weights, kin)
        else:
            def views(em):
                H, g, cost, accs = np.zeros((P, P)), np.zeros(P), 0.0, {}
                for Hc, gc, cost_c, accs_c in self.map_views(
                        lambda c: self._view_system(state, level, terms_by_view, images,
                                                    em, c), len(terms_by_view)):
                    cost += cost_c
                    accs.update(accs_c)
                    if Hc is not None:
                        H += Hc
                        g += gc
                return H, g, cost, accs

            H, g, cost, accs = views(em_weights)

            def data(em=None):
                # other EM weights: the views' systems again (the costs stay the same)
                return (H, g) if em is None else views(em)[:2]
        penalty = None
        if self.settings.collision_weight > 0 and len(self.proxies.pairs):
            # Limbs must not pass through each other (penalty on sphere-proxy overlaps).
            seg2world, seg_jac = kin if self.calibrated else self.body.kinematics(state.pose(0))
            r, J = penalty_system(self.proxies, seg2world, seg_jac)
            if len(r):
                penalty = (r, J)
                cost += self.settings.collision_weight * float(r @ r)

        def normal_equations(em_weights=None):
            H, g = data(em_weights)
            if penalty is not None:
                r, J = penalty
                w = self.settings.collision_weight
                cols = np.concatenate([roots_cols[0], angle_cols])
                H[np.ix_(cols, cols)] += w * J.T @ J
                g[cols] += w * J.T @ r
            return H, g

        if lazy:
            return normal_equations, cost, accs
        H, g = normal_equations()
        return H, g, cost, accs

    def _stacked_system(self, state, level, terms_by_view, images, em_weights, kin):
        """Calibrated views: all views' terms summed per segment in one pass (they share
        the world pose, so one kinematics and one mapping to the parameters serve them)."""
        roots_cols, _, angle_cols, P = self.layout(len(state.cameras))
        cached = self._stack_cache
        if cached is None or cached[0] is not terms_by_view or cached[1] != level:
            keys, parts, weights = [], [], []
            for c, terms in enumerate(terms_by_view):
                for key, term, weight in terms:
                    if term is None or len(term) == 0 or weight == 0:
                        continue
                    keys.append((c, key))
                    parts.append(term)
                    weights.append(weight)
            cached = (terms_by_view, level, keys, Stack(parts), weights)
            self._stack_cache = cached
        _, _, keys, stack, weights = cached
        if not keys:
            return (lambda em=None: (np.zeros((P, P)), np.zeros(P))), 0.0, {}
        seg2world, seg_jac = kin
        imgs = [self._image_of(images[c], key, level) for c, key in keys]
        cams = [self._camera_at(state.cameras[c], level) for c, _ in keys]
        total, per_part = accumulate_stacked(stack, imgs, cams, weights, seg2world,
                                             self.body.n_segments,
                                             extra_weights=[em_weights.get(k) for k in keys],
                                             lazy=True)

        def normal_equations(em=None):
            acc = total() if em is None else total([em.get(k) for k in keys])
            return assemble(acc, seg_jac, root_cols=roots_cols[0], angle_cols=angle_cols,
                            n_params=P)

        return normal_equations, total.cost, dict(zip(keys, per_part))

    def _view_system(self, state, level, terms_by_view, images, em_weights, c):
        """One uncalibrated view's normal equations (its own root and scale)."""
        roots_cols, scale_cols, angle_cols, P = self.layout(len(state.cameras))
        seg2world, seg_jac = self.body.kinematics(state.pose(c))
        cam = self._camera_at(state.cameras[c], level)
        A = b = None
        cost_c, accs_c = 0.0, {}
        for key, term, weight in terms_by_view[c]:
            if term is None or len(term) == 0 or weight == 0:
                continue
            stack = self._image_of(images[c], key, level)
            acc = accumulate(term, stack, cam, seg2world, self.body.n_segments,
                             with_scale=not self.calibrated,
                             extra_weight=em_weights.get((c, key)))
            A = weight * acc.A if A is None else A + weight * acc.A
            b = weight * acc.b if b is None else b + weight * acc.b
            cost_c += weight * acc.cost
            accs_c[(c, key)] = acc
        if A is None:
            return None, None, cost_c, accs_c
        total = Accumulated(A, b, 0.0, 0.0, None, None)
        Hc, gc = assemble(total, seg_jac, root_cols=roots_cols[c], angle_cols=angle_cols,
                          n_params=P, scale_col=scale_cols[c])
        return Hc, gc, cost_c, accs_c

    def step(self, state_t, images_t, images_t1, previous=None, renders_t=None, start=None):
        """Track one frame: the pose at t+1 from the pose at t.

        Parameters
        ----------
        state_t : State
        images_t, images_t1 : list of ViewImages
        previous : State, optional
            Pose at t-1, for the constant-velocity prediction.
        renders_t : list of RenderResult, optional
            Renders of ``state_t`` (from the previous step), to save rendering them again.
        start : State, optional
            Where the iterations start and what the weak prior pulls towards, instead of the
            constant-velocity prediction (a coarse search's proposal).

        Returns
        -------
        state : State
        report : StepReport
        """
        if renders_t is None:
            renders_t = self.render_views(state_t)
        flow = self.template_terms(state_t, images_t, renders_t)
        self.light = self._relight(state_t, renders_t, images_t)
        state, report = self._step(state_t, images_t, images_t1, previous, renders_t, start, flow)
        if start is None and self.settings.whole_turn:
            state, report = self._whole_turn(state, report, state_t, images_t, images_t1,
                                             previous, renders_t, flow)
        if self.search is None:
            return state, report
        return self._search_limbs(state, report, state_t, images_t, images_t1, previous,
                                  renders_t, flow)

    def _step(self, state_t, images_t, images_t1, previous, renders_t, start, flow=None,
              look=None):
        """``(state, report)`` solved coarse to fine from the prediction (or ``start``); a
        ``look`` (callable of a state) saying False at the coarser levels' pose stops the step
        there with ``(None, None)`` (a refit's finest level, a quarter of its time, saved)."""
        s = self.settings
        V = len(state_t.cameras)
        if flow is None:
            flow = self.template_terms(state_t, images_t, renders_t)
        use_sil = images_t1[0].sdf is not None and s.silhouette_weight > 0
        state = self.predict(state_t, previous) if start is None else start.copy()
        prior_center = state.copy()
        total_iters = 0
        cost = 0.0
        finest = min(s.finest, s.levels - 1)
        base_contour = None
        for level in reversed(range(finest, s.levels)):
            if look is not None and level == finest < s.levels - 1 and not look(state):
                return None, None
            sil = None
            if use_sil and s.contour_per_level:
                sil = self.contour_terms(state, level)
            elif use_sil:
                if base_contour is None:
                    base_contour = self.contour_terms(state, finest)
                sil = self.coarser_contour(base_contour, level, finest)
            terms_by_view = self._level_terms(flow, level, state_t, renders_t, sil, images_t1)
            em = {}
            lam = s.damping
            H, g, cost, accs = self._system(state, level, terms_by_view, images_t1, em)
            iters = s.iterations[min(s.levels - 1 - level, len(s.iterations) - 1)]
            # An accepted step's normal equations are made when the next step needs them
            # (before any other system): none for the level's last step.
            pending = None
            for it in range(iters):
                if pending is not None:
                    H, g = pending()
                    pending = None
                # calibrated: solved for the root's twist about the pelvis (_about_pelvis)
                M = self._about_pelvis(state)
                Hs, gs = (H, g) if M is None else (M.T @ H @ M, M.T @ g)
                diag = np.diag(Hs).copy()
                # Pull towards the prediction with a curvature of prior_weight times the median
                # data curvature of the same kind of parameter: negligible for what the images
                # determine, decisive for what they don't (a limb hidden in every view, depth
                # under orthographic projection).
                reg = np.zeros_like(diag)
                for cols in self._param_groups(V):
                    reg[cols] = s.prior_weight * (_median(diag[cols]) + 1e-12)
                prior_delta = self._difference(prior_center, state)
                if M is not None:
                    # the tilts pulled by their own curvature (the rotations' median is a
                    # tilt's); the turn about the vertical not at all: the images measure it,
                    # and a pull left the turn to the spine's and hips' twists, which cost less
                    reg[3:5] = s.prior_weight * diag[3:5]
                    reg[5] = 0.0
                    prior_delta[:3] -= M[:3, 3:6] @ prior_delta[3:6]
                A = Hs + lam * np.diag(diag) + np.diag(reg)
                rhs = -(gs - reg * prior_delta)
                # Several views measure more of the pose, but not all: the pelvis's turn about
                # the vertical trades for both hips' rotation (the thighs turn about their own
                # axes, which their outlines hardly show), and a walker's pelvis drifted 30-40
                # degrees that way with the hips at their limits (walk131_hard): a weaker pull
                # holds it.
                share = 1.0 if V == 1 else s.pose_space_views
                pose_term = None if self.pose_space is None or share <= 0 else \
                    self.pose_space.system(state.angles, share * diag, self.layout(V)[2])
                if pose_term is not None:
                    # damped like the data (Marquardt): where the image hardly measures an
                    # angle the pull alone would otherwise take it to the mean in one step
                    A += pose_term[0] * (1 + lam * np.eye(len(A)))
                    rhs -= pose_term[1]
                try:
                    delta = np.linalg.solve(A, rhs)
                except np.linalg.LinAlgError:
                    delta = np.linalg.lstsq(A, rhs, rcond=None)[0]
                if M is not None:
                    delta = M @ delta
                candidate = self.retract(state, delta)
                system2, cost2, accs2 = self._system(candidate, level, terms_by_view, images_t1,
                                                     em, lazy=True)
                total_iters += 1
                # the pull towards the pose space is part of what a step must lower (else a step
                # that only follows it always raises the data's cost and is turned down)
                pose_cost = (0.0, 0.0) if pose_term is None else (
                    pose_term[2](state.angles), pose_term[2](candidate.angles))
                if cost2 + pose_cost[1] <= (cost + pose_cost[0]) * (1 + 1e-9):
                    if s.em and it == 0:
                        # the support maps' EM step at the accepted pose; the costs do not
                        # change with the weights, the normal equations are made with them
                        em = self._em_weights(terms_by_view, images_t1, accs2, level)
                        pending = partial(system2, em)
                    else:
                        pending = system2
                    state, cost, accs = candidate, cost2, accs2
                    lam = max(lam / 3, 1e-6)
                    if np.abs(delta).max() < s.tolerance:
                        break
                else:
                    lam *= 10
                    if lam > 1e4:
                        break
        renders = self.render_views(state)
        residual = np.zeros(V)
        iou = np.full(V, np.nan)
        coverage = np.full(V, np.nan)
        for c in range(V):
            acc = accs.get((c, "flow"))
            if acc is not None and acc.inside.any():
                residual[c] = 255.0 * np.mean(np.abs(acc.residual[acc.inside]))
            if images_t1[c].foreground is not None:
                iou[c] = silhouette_iou(renders[c].label >= 0, images_t1[c].foreground)
                coverage[c] = model_coverage(renders[c].label >= 0, images_t1[c].foreground)
        return state, StepReport(residual, iou, cost, total_iters, renders, coverage)

    def _level_terms(self, flow, level, state_t, renders_t, sil, images_t1, without=None):
        """Each view's terms at one pyramid level: image motion and anchor appearance (one
        term, two weights: they sample the same image) and the contour's. ``without``: segments
        whose image-motion points are left out (their anchor appearance stays)."""
        s = self.settings
        terms_by_view = []
        for c in range(len(flow[level])):
            ft = flow[level][c]
            weight = ft.weight * s.flow_weight
            if without is not None:
                weight = np.where(np.isin(ft.segment, without), 0.0, weight)
            parts = [Term(c, ft.segment, ft.ref_points, ft.target, weight, ft.scale, "flow",
                          ft.uv)]
            chroma = []
            if self.anchor_terms is not None and s.anchor_weight > 0:
                at = self.anchor_terms[level][c]
                seen = self._visible(at, state_t, level, renders_t)
                at = at.subset(seen)
                gray, lit = self.anchor_targets(c, level, seen)
                parts.append(Term(c, at.segment, at.ref_points, gray,
                                  at.weight * s.anchor_weight, at.scale, "anchor",
                                  np.full((len(at), 2), np.nan)))
                if self.chroma_terms is not None and images_t1[c].chroma is not None:
                    weight = s.chroma_weight * (s.flow_scale / s.chroma_scale) ** 2
                    chroma = [(t.name, t.subset(seen), weight)
                              for t in self.chroma_terms[level][c]]
                    for (_, t, _), target in zip(chroma, lit):
                        t.target = target
            terms = [("flow", Term.concat(parts, "flow"), 1.0)] + chroma
            if sil is not None and images_t1[c].sdf is not None and s.silhouette_weight > 0:
                # distances shrink with the pyramid level: keep pixel units per level
                terms.append(("silhouette", sil[c], s.silhouette_weight * 4 ** level))
            terms_by_view.append(terms)
        return terms_by_view

    def frame_cost(self, state, state_t, images_t1, renders_t, flow, without=None):
        """The least-squares cost of a pose at the finest level solved: image motion, anchor
        appearance, contours and limb overlap (``without``: segments whose image-motion points
        are left out)."""
        level = min(self.settings.finest, self.settings.levels - 1)
        use_sil = images_t1[0].sdf is not None and self.settings.silhouette_weight > 0
        sil = self.contour_terms(state, level) if use_sil else None
        terms = self._level_terms(flow, level, state_t, renders_t, sil, images_t1, without)
        return self._system(state, level, terms, images_t1, {}, lazy=True)[1]

    def _difference(self, target, state):
        """Parameter vector that moves ``state`` to ``target`` (to first order)."""
        roots_cols, scale_cols, angle_cols, P = self.layout(len(state.cameras))
        d = np.zeros(P)
        last = None     # calibrated views share one root: its logarithm is taken once
        for c, cols in enumerate(roots_cols):
            key = (target.roots[c].tobytes(), state.roots[c].tobytes())
            if last is None or last[0] != key:
                last = (key, se3.log_se3(target.roots[c] @ se3.invert(state.roots[c])))
            d[cols] = last[1]
            if scale_cols[c] is not None:
                d[scale_cols[c]] = np.log(target.cameras[c].s / state.cameras[c].s)
        d[angle_cols] = target.angles - state.angles
        return d

    def _em_weights(self, terms_by_view, images_t1, accs, level):
        """One EM step on the support maps (:func:`image_motion.support_weights`)."""
        return support_weights(terms_by_view, [im.stacks[level] for im in images_t1], accs,
                               self.settings.flow_scale, self.settings.flow_weight)
