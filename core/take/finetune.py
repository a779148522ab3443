"""Model fine-tuning over a tracked sequence (Bregler & Malik §2.7).

"After tracking, refine the body dimensions over the whole sequence, and re-track if that
helps." The first track's poses are good enough to say where every segment is in every frame;
the images then say how long the segments are: the model's occluding contour should lie on the
person's silhouette against the background, in every sampled frame and view, and the model's
joints on the animator's clicks at the anchor frames. Both are image evidence; the tracker's
own projected joints are not used (they would only confirm the body they came from).

One joint problem over the sampled frames (those the first track marked ok): the limbs' lengths
(``REFINED_DIMS``) are shared, each frame has its own pose (root twist and angles). Residuals:

- silhouette: the observed signed distance (``background.signed_distance``, positive outside)
  at every contour pixel of the rendered model, robust, each frame and view weighted alike;
- clicks: model joints minus clicked joints at the anchor frames, robust;
- a weak prior holding each length near its start (what the images cannot see stays put).

A contour point on a segment moves with the segment's two end joints: at fixed angles the
joints are linear in the lengths (``BodyModel.joints_dims_jacobian``), and a point a fraction
``a`` of the way from the near to the far joint moves by ``(1 - a) dP + a dQ``; with the pose
it moves with its segment's spatial velocity (eq. 23). Levenberg-Marquardt with the frames
eliminated by the Schur complement (like ``initialize.refine_dims``); the contour is rendered
anew at every step.

Then the take is tracked again from the refined body, and the new track is kept only if the
tracker's own measures say it is better (silhouette overlap, frames lost).

Convention: world Z up, metres; OpenCV cameras and pixels; calibrated views only (scaled
orthographic views cannot see a body's size, and their per-view roots are not in a result).
"""

from dataclasses import dataclass, field

import cv2
import numpy as np

from ..geometry import se3
from ..imaging.background import BackgroundModel, signed_distance
from ..body.body import LENGTH_DIMS, Pose
from ..errors import ZoopraxisError
from ..trackers.image_motion import image_with_gradients, sample
from ..body.joints import JOINT_INDEX
from ..imaging.render import render

# Robust scales (working pixels) and weights. Each sampled frame and view counts as this many
# contour points, whatever its resolution and the person's size in it.
CONTOUR_SCALE_PX = 2.0
CLICK_SCALE_PX = 3.0
POINTS_PER_VIEW = 100.0
MAX_CONTOUR_POINTS = 800
# A length one prior spread (relative) from its start costs one squared pixel.
DIMS_PRIOR_SIGMA = 0.10
# Clicks count like this many contour points each (they say where the joint centres are).
CLICK_WEIGHT = 10.0
# The lengths refined: the legs' and the forearms'. The trunk's and the head's outlines are
# their radii more than their lengths (and clothes, hair), and its lengths and widths are what
# the anchors' clicks see best. An upper arm mostly lies along the trunk, where its outline
# merges with the trunk's: its length from silhouettes was unstable in tests (off by 10-20 %
# in both directions), so it stays as the clicks set it. A foot is a few pixels long.
REFINED_DIMS = ("thigh", "shank", "forearm")
# Spread of a pose's change from the tracked one: root translation (m), root rotation (rad),
# joint angles (rad).
POSE_PRIOR_SIGMA = (0.05, 0.1, 0.15)
POSE_PRIOR_WEIGHT = 10.0        # cost of one spread, squared pixels
# Lengths stay within these multiples of their start.
DIMS_STEP_RANGE = (0.7, 1.4)

# The two joints a segment's points move with: a contour point of the segment is placed a
# fraction of the way between them.
_SEGMENT_ENDS = {"pelvis": ("l_hip", "r_hip"), "abdomen": ("pelvis", "neck"),
                 "chest": ("pelvis", "neck"), "head": ("neck", "head")}
for _s in ("l", "r"):
    _SEGMENT_ENDS.update({f"{_s}_upper_arm": (f"{_s}_shoulder", f"{_s}_elbow"),
                          f"{_s}_forearm": (f"{_s}_elbow", f"{_s}_wrist"),
                          f"{_s}_thigh": (f"{_s}_hip", f"{_s}_knee"),
                          f"{_s}_shank": (f"{_s}_knee", f"{_s}_ankle"),
                          f"{_s}_foot": (f"{_s}_ankle", f"{_s}_toe")})


@dataclass
class BodyFit:
    """What :func:`fit_body_to_images` found.

    Attributes
    ----------
    body : BodyModel
        With the refined limb lengths (``REFINED_DIMS``); the rest as it was.
    poses : list of Pose
        Refined pose of every sampled frame.
    cost_before, cost_after : float
        Objective at the start and at the end (contour and click terms, robust).
    contour_rms : tuple of float
        Root-mean-square contour distance to the silhouette (working pixels), before and after.
    iterations : int
    cancelled : bool
    """

    body: object
    poses: list
    cost_before: float
    cost_after: float
    contour_rms: tuple
    iterations: int
    cancelled: bool = False


def _segment_ends(body):
    ends = []
    for name in body.segment_names:
        if name not in _SEGMENT_ENDS:
            raise ZoopraxisError(f"body fine-tuning: template '{body.template}' has a segment "
                                 f"'{name}' it does not know")
        p, q = _SEGMENT_ENDS[name]
        ends.append((JOINT_INDEX[p], JOINT_INDEX[q]))
    return np.array(ends)


def _robust(r, scale):
    """Soft-L1 cost ``2 c^2 (sqrt(1 + r^2/c^2) - 1)`` and its IRLS weight."""
    q = np.sqrt(1.0 + (r / scale) ** 2)
    return 2.0 * scale ** 2 * (q - 1.0), 1.0 / q


class _Problem:
    """The contour and click residuals of a body over the sampled frames."""

    def __init__(self, body, cameras, sdf, clicks, dims0, valid):
        self.template_body = body
        self.cameras = cameras          # V working cameras
        self.sdf = sdf                  # K lists of V stacks (H, W, 3) or None
        self.valid = valid              # K lists of V bool images or None (all valid)
        self.clicks = clicks            # K arrays (V, 17, 2), NaN where not clicked
        self.dims0 = dims0
        self.ends = _segment_ends(body)
        self.names = list(REFINED_DIMS)

    def body_with(self, dims):
        body = self.template_body
        return body.with_dims(dict(zip(self.names, dims)))

    def linearize(self, dims, poses, jacobians=True):
        """Cost and, with ``jacobians``, the normal equations' blocks.

        Returns
        -------
        cost : float
        rms : float
            Contour distance RMS, pixels.
        blocks : tuple or None
            ``(H_ff (K, P, P), H_fd (K, P, D), g_f (K, P), H_dd (D, D), g_d (D,))`` of the
            robust (reweighted) Gauss-Newton system, without the prior.
        """
        body = self.body_with(dims)
        prims = body.primitives()
        K, D = len(poses), len(dims)
        P = 6 + body.n_dofs
        H_ff = np.zeros((K, P, P))
        H_fd = np.zeros((K, P, D))
        g_f = np.zeros((K, P))
        H_dd = np.zeros((D, D))
        g_d = np.zeros(D)
        cost, sq, count = 0.0, 0.0, 0
        for k, pose in enumerate(poses):
            T, seg_J = body.kinematics(pose)
            Xj, Jj = body.joints_jacobian(pose)                          # (17, 3), (17, 3, P)
            Jd = body.joints_dims_jacobian(pose, self.names)              # (17, 3, D)
            rows = []          # (residuals, weights, d r / d pose, d r / d dims) per view
            for c, cam in enumerate(self.cameras):
                if self.sdf[k][c] is None:
                    continue
                rr = render(cam, T, prims, want=("point",))
                fgm = rr.label >= 0
                inner = cv2.erode(fgm.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
                vv, uu = np.nonzero(fgm & ~inner)
                if len(vv) == 0:
                    continue
                if len(vv) > MAX_CONTOUR_POINTS:
                    keep = np.linspace(0, len(vv) - 1, MAX_CONTOUR_POINTS).astype(int)
                    vv, uu = vv[keep], uu[keep]
                seg = rr.label[vv, uu].astype(np.int64)
                X = rr.point[vv, uu].astype(np.float64)
                uv, A = cam.project_jacobian(X)
                vals, inside = sample(self.sdf[k][c], uv)
                if self.valid[k][c] is not None:
                    # Where the background was never seen the silhouette says nothing.
                    px = np.clip(np.rint(uv).astype(int), 0,
                                 np.array(self.valid[k][c].shape[::-1]) - 1)
                    inside &= self.valid[k][c][px[:, 1], px[:, 0]]
                if not inside.any():
                    continue
                seg, X, A, vals = seg[inside], X[inside], A[inside], vals[inside].astype(float)
                r = vals[:, 0]
                rho, w = _robust(r, CONTOUR_SCALE_PX)
                weight = POINTS_PER_VIEW / len(r)
                cost += weight * rho.sum()
                sq += float(np.sum(r ** 2))
                count += len(r)
                if not jacobians:
                    continue
                dr_dX = np.einsum("ni,nij->nj", vals[:, 1:3], A)              # (N, 3)
                J_pose = np.einsum("nj,njk->nk", dr_dX, se3.point_velocity_matrix(X)
                                   @ seg_J[seg])
                p, q = self.ends[seg].T
                axis = Xj[q] - Xj[p]
                a = np.einsum("ni,ni->n", X - Xj[p], axis) / np.maximum(
                    np.einsum("ni,ni->n", axis, axis), 1e-9)
                J_pt = (1.0 - a)[:, None, None] * Jd[p] + a[:, None, None] * Jd[q]
                J_dims = np.einsum("nj,njd->nd", dr_dX, J_pt)
                rows.append((r, weight * w, J_pose, J_dims))
            clicked = np.isfinite(self.clicks[k]).all(axis=-1)              # (V, 17)
            for c in np.flatnonzero(clicked.any(axis=1)):
                j = np.flatnonzero(clicked[c])
                uv, A = self.cameras[c].project_jacobian(Xj[j])
                r = (uv - self.clicks[k][c, j]).ravel()
                rho, w = _robust(r, CLICK_SCALE_PX)
                cost += CLICK_WEIGHT * rho.sum()
                if not jacobians:
                    continue
                J_pose = (A @ Jj[j]).reshape(-1, P)
                J_dims = (A @ Jd[j]).reshape(-1, D)
                rows.append((r, CLICK_WEIGHT * w, J_pose, J_dims))
            for r, w, J_pose, J_dims in rows:
                Jw = J_pose * w[:, None]
                H_ff[k] += Jw.T @ J_pose
                H_fd[k] += Jw.T @ J_dims
                g_f[k] -= Jw.T @ r
                Dw = J_dims * w[:, None]
                H_dd += Dw.T @ J_dims
                g_d -= Dw.T @ r
        rms = float(np.sqrt(sq / count)) if count else float("nan")
        blocks = (H_ff, H_fd, g_f, H_dd, g_d) if jacobians else None
        return cost, rms, blocks

    def prior(self, dims):
        """Prior cost of the lengths (relative to their start) and its Gauss-Newton terms (the
        halved gradient's negative and Hessian, like the data's)."""
        w = 1.0 / (DIMS_PRIOR_SIGMA * self.dims0) ** 2
        e = dims - self.dims0
        return float(np.sum(w * e ** 2)), -w * e, np.diag(w)


def fit_body_to_images(body, poses, cameras, masks, clicks=None, *, valid=None, iterations=10,
                       cancel=None, log=None):
    """Refine a body's lengths and the poses of some frames on silhouettes and clicks (§2.7).

    Parameters
    ----------
    body : BodyModel
        The body the frames were tracked with; its lengths are the start.
    poses : list of Pose
        World pose of each frame (calibrated cameras).
    cameras : list of PinholeCamera
        One per view, at the resolution of the masks.
    masks : list of list of array of bool, shape (H, W), or None
        Foreground mask per frame and view (None: the view gives no silhouette there).
    clicks : list of array, shape (V, 17, 2), optional
        Clicked joints per frame in the cameras' pixels, NaN where not clicked.
    valid : list of list of array of bool, shape (H, W), or None, optional
        Where each mask can be trusted (the background was seen there); default everywhere.
    iterations : int
        Levenberg-Marquardt steps at most.
    cancel : callable() -> bool, optional
        Polled before each step; on cancel the best body so far is returned.
    log : callable(str), optional

    Returns
    -------
    fit : BodyFit
    """
    log = log or (lambda msg: None)
    K, V = len(poses), len(cameras)
    if len(masks) != K or any(len(m) != V for m in masks):
        raise ZoopraxisError(f"body fine-tuning: need {K} frames x {V} views of masks")
    if clicks is None:
        clicks = [np.full((V, 17, 2), np.nan) for _ in range(K)]
    sdf = [[None if m is None else image_with_gradients(signed_distance(np.asarray(m, bool)))
            for m in row] for row in masks]
    dims0 = body.dims_vector(REFINED_DIMS)
    if valid is None:
        valid = [[None] * V for _ in range(K)]
    problem = _Problem(body, cameras, sdf, clicks, dims0, valid)
    lo, hi = DIMS_STEP_RANGE[0] * dims0, DIMS_STEP_RANGE[1] * dims0
    dims = dims0.copy()
    poses = [p.copy() for p in poses]
    # The poses stay near the track's: a frame without clicks whose silhouette is poor must
    # not wander off (each pose parameter's change from the track, in spreads).
    n = body.n_dofs
    w_pose = POSE_PRIOR_WEIGHT / np.concatenate([np.full(3, POSE_PRIOR_SIGMA[0]) ** 2,
                                               np.full(3, POSE_PRIOR_SIGMA[1]) ** 2,
                                               np.full(n, POSE_PRIOR_SIGMA[2]) ** 2])
    moved = np.zeros((len(poses), 6 + n))        # change from the track (sum of the steps)

    def pose_prior(moved):
        return float(np.sum(w_pose * moved ** 2))

    cost, rms0, blocks = problem.linearize(dims, poses)
    cost += problem.prior(dims)[0] + pose_prior(moved)
    cost0, rms = cost, rms0
    lam = 1e-3
    done = 0
    cancelled = False
    for done in range(1, iterations + 1):
        if cancel is not None and cancel():
            cancelled = True
            done -= 1
            break
        H_ff, H_fd, g_f, H_dd, g_d = blocks
        _, g_p, H_p = problem.prior(dims)
        H_dd, g_d = H_dd + H_p, g_d + g_p
        H_ff = H_ff + w_pose[:, None] * np.eye(6 + n)
        g_f = g_f - w_pose * moved
        accepted = False
        while lam < 1e6:
            eye = np.eye(H_ff.shape[1])
            A = H_ff + lam * (np.diagonal(H_ff, axis1=1, axis2=2)[:, :, None] * eye + 1e-6 * eye)
            Ainv_W = np.linalg.solve(A, H_fd)                                # (K, P, D)
            Ainv_b = np.linalg.solve(A, g_f[..., None])[..., 0]              # (K, P)
            S = H_dd + lam * np.diag(np.diag(H_dd)) \
                - np.einsum("kpd,kpe->de", H_fd, Ainv_W)
            d_dims = np.linalg.solve(S, g_d - np.einsum("kpd,kp->d", H_fd, Ainv_b))
            d_pose = Ainv_b - Ainv_W @ d_dims
            new_dims = np.clip(dims + d_dims, lo, hi)
            new_poses = [Pose(p.retract(d).root, body.clamp(p.retract(d).angles))
                         for p, d in zip(poses, d_pose)]
            new_cost, new_rms, new_blocks = problem.linearize(new_dims, new_poses)
            new_cost += problem.prior(new_dims)[0] + pose_prior(moved + d_pose)
            if new_cost < cost:
                accepted = True
                break
            lam *= 4.0
        if not accepted:
            break
        gain = cost - new_cost
        dims, poses, cost, rms, blocks = new_dims, new_poses, new_cost, new_rms, new_blocks
        moved = moved + d_pose
        lam = max(lam / 3.0, 1e-7)
        log(f"fine-tune step {done}: cost {cost:.1f}, contour RMS {rms:.2f} px")
        if gain < 1e-4 * cost:
            break
    return BodyFit(problem.body_with(dims), poses, cost0, cost, (rms0, rms), done, cancelled)


# ---------------------------------------------------------------------------------------------
# Fine-tuning a tracked take
# ---------------------------------------------------------------------------------------------

@dataclass
class FinetuneResult:
    """What :func:`finetune` did.

    Attributes
    ----------
    result : TrackResult
        The better of the first track and the re-track (the first when not kept).
    first : TrackResult
        The track before fine-tuning.
    retrack : TrackResult or None
        The track with the refined body (None if it was not run).
    body_before, body_after : BodyModel
    kept : bool
        The re-track was better and is ``result``.
    measures : dict of str to dict
        ``{"before": ..., "after": ...}`` from :func:`track_measures`.
    fit : BodyFit or None
    samples : list of int
        The frames the lengths were fitted on (``fit.poses`` are theirs).
    cancelled : bool
    log : list of str
    """

    result: object
    first: object
    retrack: object
    body_before: object
    body_after: object
    kept: bool
    measures: dict
    fit: object = None
    samples: list = field(default_factory=list)
    cancelled: bool = False
    log: list = field(default_factory=list)

    def lengths(self):
        """``{name: (before, after)}`` of the length dimensions, metres."""
        return {n: (self.body_before.dims[n], self.body_after.dims[n]) for n in LENGTH_DIMS}


def track_measures(result):
    """The tracker's own measures of a result, over the frames it tracked (not the anchors).

    Returns
    -------
    measures : dict
        ``iou`` and ``fit``: mean silhouette overlap and fit (NaN without silhouettes);
        ``residual``: median grey residual over views and frames; ``ok``, ``uncertain``,
        ``lost``: status counts.
    """
    anchors = set(result.extra.get("anchors", []))
    tracked = np.array([f not in anchors for f in result.frames], bool)

    def mean_of(key):
        a = np.asarray(result.extra.get(key, []), float)
        if a.size == 0:
            return float("nan")
        a = a[tracked]
        a = a[a >= 0]
        return float(a.mean()) if a.size else float("nan")

    res = np.array([result.residual[v] for v in result.residual]).T          # (F, V)
    res = res[tracked]
    res = res[res > 0]
    return {"iou": mean_of("silhouette_iou"), "fit": mean_of("silhouette_fit"),
            "residual": float(np.median(res)) if res.size else float("nan"),
            **{s: int(result.status.count(s)) for s in ("ok", "uncertain", "lost")}}


def is_better(after, before):
    """Whether a re-track is better than the first by the tracker's measures: no more frames
    lost, no more frames lost or uncertain together, and a lower grey residual (or, with no
    residuals, a higher silhouette overlap).

    The grey residual is how well the model's motion explains the images: a limb of the
    wrong length carries points that do not move with the person. The silhouette overlap
    is a poor judge of lengths: where the person's outline is larger than the model's (another
    build, clothes), longer limbs overlap more. On twelve benchmark re-tracks (three CMU walks,
    lengths 8 % short, right or 9 % long, estimated and clean backgrounds) the overlap rule
    kept the re-track in 2 of the 9 where it helped; this rule in 7 of the 9, and rejected 2
    of the 3 that were worse (the third: 0.8 mm worse).
    """
    if after["lost"] > before["lost"] or \
            after["lost"] + after["uncertain"] > before["lost"] + before["uncertain"]:
        return False
    if np.isfinite(after["residual"]) and np.isfinite(before["residual"]):
        return after["residual"] < before["residual"]
    return after["iou"] > before["iou"]


def _sample_frames(result, n):
    """Up to ``n`` tracked frames spread over the take, anchors first: frames whose status is
    ok (a pose that drifted would teach the lengths its error), or if there are fewer than
    three of those, all frames not lost."""
    anchors = [int(a) for a in result.extra.get("anchors", [])]
    for allowed in (("ok",), ("ok", "uncertain")):
        usable = [int(f) for f, s in zip(result.frames, result.status) if s in allowed]
        if len(usable) >= 3:
            break
    rest = [f for f in usable if f not in anchors]
    k = max(n - len(anchors), 0)
    pick = [rest[i] for i in np.unique(np.linspace(0, len(rest) - 1, k).astype(int))] \
        if rest and k else []
    return anchors + pick


def finetune(plates, anchors, cameras, *, result=None, init=None, frames=None, offsets=None,
             template="full", settings=None, max_size=960, backgrounds=None, samples=12,
             iterations=10, progress=None, cancel=None, log=None, flips=None,
             pose_prior="default", dims=None):
    """Track, refine the body's lengths on the images of the whole take, track again (§2.7).

    Parameters
    ----------
    plates : dict of str to Plate
    anchors : list of markers.Anchor
    cameras : dict of str to PinholeCamera
        The calibration (fine-tuning needs calibrated views).
    result : TrackResult, optional
        A first track of these plates (its ``body`` must be ``init.body``); tracked here when
        not given.
    init : track.Initial, optional
        Starting poses and body; by default fitted to the anchors' clicks.
    frames, offsets, template, settings, max_size
        As for :func:`track.track`.
    backgrounds : dict of str to BackgroundModel or array, optional
        Known backgrounds (clean plates, BGR) per view; by default estimated from the plates
        with the person, as the first track placed it, left out.
    samples : int
        Frames the lengths are fitted on (anchors included), spread over the take.
    iterations : int
        Steps of the fit.
    progress : callable(done, total), optional
        Over the whole job: first track, fit, re-track.
    cancel : callable() -> bool, optional
        On cancel the work done is kept: the first track (partial or whole) if the cancel came
        before the re-track finished.
    log : callable(str), optional
    flips, pose_prior : optional
        When ``init`` is not given, for anchor frames clicked in one view: the body parts
        turned to their other depth and the pose prior (:func:`initialize.initialize`).
    dims : dict, optional
        When ``init`` is not given: the performer's body lengths, kept instead of fitted to
        the clicks (the refinement still refines them).

    Returns
    -------
    FinetuneResult

    Raises
    ------
    ZoopraxisError
        No calibration, a view without a camera, bad anchors or frames (as :func:`track.track`).
    """
    from . import track as T
    from .driver import FrameSource
    from ..trackers.differential import Settings
    from ..initialize.fit import initialize

    lines = []

    def say(msg):
        lines.append(msg)
        if log is not None:
            log(msg)

    if not cameras:
        raise ZoopraxisError("body fine-tuning needs calibrated views: give a calibration")
    views = list(plates)
    missing = [v for v in views if v not in cameras]
    if missing:
        raise ZoopraxisError(f"body fine-tuning: the calibration has no camera for view "
                             f"'{missing[0]}'")
    offsets = dict(offsets or {})
    settings = settings or Settings()
    from ..imaging.plates import check_same_length

    n_total = check_same_length(plates, offsets)
    frames = range(0, n_total) if frames is None else frames
    inside = [a for a in anchors if frames.start <= a.frame < frames.stop]
    if init is None and inside:
        res = initialize(inside, {v: cameras[v] for v in views}, template=template,
                         calibrated=True, views=views, flips=flips, pose_prior=pose_prior,
                         dims=dims, fit_dims=not dims)
        for note in res.flip_notes():
            say(note)
        init = T.Initial(res.body, res.poses, res.cameras, None, list(res.warnings))
    # Progress over the whole job: a track's steps, the fit's steps, the re-track's steps.
    stage = {"base": 0, "steps": None}

    def staged(done, total):
        stage["steps"] = stage["steps"] or total
        if progress is not None:
            grand = 2 * stage["steps"] + iterations
            progress(min(stage["base"] + done, grand), grand)

    def track_once(start):
        return T.track(plates, anchors, cameras, frames=frames, offsets=offsets,
                       template=template, settings=settings, init=start, max_size=max_size,
                       progress=staged, cancel=cancel, log=log)

    first = result if result is not None else track_once(init)
    body0 = init.body
    before = track_measures(first)

    picked = []

    def finish(kept_result, retrack, body_after, kept, after=None, fit=None, cancelled=False):
        return FinetuneResult(kept_result, first, retrack, body0, body_after, kept,
                              {"before": before, "after": after}, fit, list(picked), cancelled,
                              lines)

    if first.extra.get("cancelled"):
        say("fine-tune: cancelled during the first track; keeping it")
        return finish(first, None, body0, False, cancelled=True)
    stage["steps"] = stage["steps"] or max(len(first.frames) - 1, 1)
    stage["base"] = stage["steps"]

    # Working resolution, as the tracker's.
    factors = {v: min(1.0, max_size / max(plates[v].image_size)) for v in views}
    work = [cameras[v].scaled(factors[v], sampling="resize") if factors[v] != 1.0 else cameras[v]
            for v in views]
    source = FrameSource(plates, views, offsets, factors)
    index = {int(f): i for i, f in enumerate(first.frames)}
    pose_of = {f: Pose(first.roots[i], first.angles[i]) for f, i in index.items()}
    picked[:] = _sample_frames(first, samples)
    say(f"fine-tune: fitting the lengths on {len(picked)} frames x {len(views)} views")
    models = _backgrounds(backgrounds, views, source, body0, work, pose_of, factors)
    masks = [[None if models[c] is None else models[c].foreground(img)
              for c, img in enumerate(source.colour(f))] for f in picked]
    seen = [None if m is None or m.known is None else
            ~cv2.dilate((~m.known).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
            for m in models]
    valid = [list(seen) for _ in picked]
    by_frame = {a.frame: a for a in inside}
    clicks = []
    for f in picked:
        uv = np.full((len(views), 17, 2), np.nan)
        if f in by_frame:
            for c, v in enumerate(views):
                uv[c] = by_frame[f].array(v) * factors[v]
        clicks.append(uv)

    def fit_progress_cancel():
        staged(0, stage["steps"])
        stage["base"] += 1
        return cancel is not None and cancel()

    fit = fit_body_to_images(body0, [pose_of[f] for f in picked], work, masks, clicks,
                             valid=valid, iterations=iterations, cancel=fit_progress_cancel,
                             log=say)
    body1 = fit.body
    say("fine-tune: lengths " + ", ".join(
        f"{n} {1000 * body0.dims[n]:.0f}->{1000 * body1.dims[n]:.0f} mm"
        for n in LENGTH_DIMS if abs(body1.dims[n] - body0.dims[n]) >= 5e-4) +
        f"; contour RMS {fit.contour_rms[0]:.2f} -> {fit.contour_rms[1]:.2f} px")
    if fit.cancelled:
        say("fine-tune: cancelled; keeping the first track")
        return finish(first, None, body1, False, fit=fit, cancelled=True)
    # The anchors' poses for the new body: the fit's, or the clicks fitted again with the
    # lengths held, whichever lies nearer the clicks.
    again = initialize(inside, {v: cameras[v] for v in views}, template=body1.template,
                       calibrated=True, dims=body1.dims, fit_dims=False, views=views,
                       flips=flips, pose_prior=pose_prior)
    refined = dict(zip(picked, fit.poses))

    def click_rms(pose, anchor):
        X = body1.joints(pose)
        err = [np.linalg.norm(cameras[v].project(X) - anchor.array(v), axis=1) for v in views]
        return float(np.sqrt(np.nanmean(np.concatenate(err) ** 2)))

    start = T.Initial(body1, {a.frame: min((refined[a.frame], again.poses[a.frame]),
                                           key=lambda p, a=a: click_rms(p, a))
                              for a in inside}, dict(cameras), None, [])
    stage["base"] = stage["steps"] + iterations
    second = track_once(start)
    if second.extra.get("cancelled"):
        say("fine-tune: cancelled during the re-track; keeping the first track")
        return finish(first, second, body1, False, fit=fit, cancelled=True)
    after = track_measures(second)
    kept = is_better(after, before)
    say(f"fine-tune: grey residual {before['residual']:.2f} -> {after['residual']:.2f}, "
        f"silhouette overlap {before['iou']:.3f} -> {after['iou']:.3f}, lost "
        f"{before['lost']} -> {after['lost']}, uncertain {before['uncertain']} -> "
        f"{after['uncertain']}: {'keeping the re-track' if kept else 'keeping the first track'}")
    return finish(second if kept else first, second, body1, kept, after, fit)


def _backgrounds(given, views, source, body, cameras, pose_of, factors):
    """Background model per view: given (clean plates) or estimated from up to 25 frames with
    the person, where the first track put it, kept out of each frame
    (:func:`backgrounds.backgrounds_without_body`)."""
    from .backgrounds import backgrounds_without_body

    frames = sorted(pose_of)
    sample_frames = [frames[i] for i in np.unique(
        np.linspace(0, len(frames) - 1, min(25, len(frames))).astype(int))]
    given = given or {}
    prims = body.primitives()

    def silhouettes(f):
        seg2world = body.seg2world(pose_of[f])
        return [render(cameras[c], seg2world, prims, want=()).label >= 0
                for c in range(len(views))]

    out = backgrounds_without_body(source, sample_frames, silhouettes,
                                   [v not in given and len(sample_frames) >= 5 for v in views],
                                   margin=15)
    for c, v in enumerate(views):
        if v in given:
            bg = given[v]
            if not isinstance(bg, BackgroundModel):
                img = np.asarray(bg)
                f = factors[v]
                if f != 1.0:
                    h, w = img.shape[:2]
                    img = cv2.resize(img, (int(round(w * f)), int(round(h * f))),
                                     interpolation=cv2.INTER_AREA)
                img = img.astype(np.float32) / (255.0 if img.dtype == np.uint8 else 1.0)
                bg = BackgroundModel(img, 0.01, None)
            out[c] = bg
    return out


__all__ = ["finetune", "FinetuneResult", "fit_body_to_images", "BodyFit", "track_measures",
           "is_better"]
