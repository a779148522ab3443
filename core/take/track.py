"""Track a take: plates and markers in, a :class:`result.TrackResult` out.

The take runs from anchor to anchor. Between two anchors it is tracked forward from the first
and backward from the second, each pass to a little past the middle, and the two passes are
blended there with weights that fall off with the distance from their anchor, so that a later
anchor corrects the drift of the earlier one; a pass goes further when the other one lost the
body on its way (:func:`extend_passes`). Before the first anchor the take is tracked backward,
after the last forward. Each anchor frame's pose comes from the markers
(:func:`initialize.initialize`, Bregler & Malik §2.6).

Working images are the plates scaled so that their longer side is at most ``max_size`` pixels;
results are reported in the plates' own pixels.
"""

import threading
from dataclasses import dataclass, field

import cv2
import numpy as np

from ..geometry import se3
from ..imaging.background import estimate_background, model_coverage, signed_distance, silhouette_iou
from ..body.body import Pose
from ..geometry.ortho import ScaledOrthoCamera
from ..trackers.differential import DifferentialTracker, Settings, State, prepare_images, thread_pool
from ..errors import ZoopraxisError
from ..initialize.fit import CAMERA_TILT_DEG
from ..files.markers import check_markers
from ..imaging.plates import to_gray_float
from ..trackers.recover import unexplained_foreground, unexplained_share
from ..files.result import TrackResult

# Status thresholds. The silhouette fit is the fraction of the model's silhouette that lies in
# the foreground (shadows and loose clothes make the foreground larger than the model, so the
# overlap the other way says little), compared with the same fraction at the anchor frame; the
# grey residual is compared with the take's median.
FIT_LOST, FIT_UNCERTAIN = 0.6, 0.8           # fraction of the anchor frame's silhouette fit
# The fit is what the silhouette term optimizes, so a model that shrank into one part of the
# person still fits; the overlap (intersection over union) relative to the anchor's catches it.
IOU_LOST, IOU_UNCERTAIN = 0.5, 0.6
RESIDUAL_LOST, RESIDUAL_UNCERTAIN = 4.0, 2.5   # times the take's median residual
MIN_ANCHOR_FIT = 0.6     # below this the foreground masks of a view are too poor to use
# A limb's silhouette score (recover.LimbSearch.fit: +1 inside the person's silhouette in every
# view, -1 outside): the whole body can overlap well while one leg is half a metre off.
LIMB_LOST, LIMB_UNCERTAIN = -0.25, 0.5
# Foreground that no part of the model explains, as a fraction of the model's area, above the
# anchor frame's (a body of another build leaves some at every frame): a limb or the whole
# body that has left the person leaves the person's own pixels unexplained. On the benchmark
# takes (walks, a brisk walk, jumps) the jumps' frames 200 mm off that the silhouette overlap
# still passed were at 0.26-0.75; of the frames the other measures called ok, only three of the
# brisk walk's (50-100 mm off) went above 0.25. Some good frames of a walk whose build differs
# from the model's exceed it too (17 of walk3's 206 frames under 50 mm; arms swinging out of
# the model's reach); those were uncertain already.
UNEXPLAINED_UNCERTAIN = 0.25
# Between two anchors the forward pass tracks to BLEND_REACH frames past the middle and the
# backward pass as far before it, and the two are blended over that stretch: each frame is
# tracked from its nearer anchor, and far fewer frames are tracked than with two whole passes.
# A pass whose quality (see blend_weights) falls below POOR_PASS before the stretch calls its
# partner on towards its anchor. bench_track's walk3-anchors (anchors every 100 frames, 2
# processes), runs alternated: whole passes (--whole-passes) 29.0 mm at 5.6-7.2 fps, 8 frames
# 28.0 mm at 10.3-12.0 fps. 15 frames gave 28.1 mm; 4 frames 25.6 mm, but left a jump at a
# seam: a joint acceleration of 50 mm per frame^2, where the walk's own reaches 22.
BLEND_REACH = 8
POOR_PASS = 0.5


@dataclass
class Initial:
    """Poses the tracker starts from: what :func:`initialize.initialize` returns.

    Attributes
    ----------
    body : BodyModel
    poses : dict of int to Pose
        Pose per anchor frame (world; body-centred when uncalibrated).
    cameras : dict of str to camera
        Calibrated: the plates' cameras. Uncalibrated: fitted scaled-orthographic cameras.
    view_cameras : dict of int to dict of str to camera, optional
        Uncalibrated: the fitted camera of every view at every anchor frame.
    warnings : list of str
    """

    body: object
    poses: dict
    cameras: dict
    view_cameras: dict = None
    warnings: list = field(default_factory=list)


class FrameSource:
    """Working-resolution colour frames of all views, decoded once and kept for the take.

    Backward passes read frames in reverse; decoding a video backwards is slow, so frames are
    kept in memory (uint8) up to ``budget_bytes`` and re-read beyond that.
    """

    def __init__(self, plates, views, offsets, factors, budget_bytes=3e9):
        self.plates = plates
        self.views = views
        self.offsets = offsets
        self.factors = factors
        self.cache = {}
        sizes = [int(round(plates[v].image_size[0] * factors[v]))
                 * int(round(plates[v].image_size[1] * factors[v])) * 3 for v in views]
        self.per_frame = sum(sizes)
        self.budget = budget_bytes
        self.lock = threading.Lock()

    def colour(self, frame):
        cached = self.cache.get(frame)
        if cached is not None:
            return cached
        with self.lock:     # decoders are not thread-safe (the next frame is read ahead)
            return self._read(frame)

    def _read(self, frame):
        if frame in self.cache:
            return self.cache[frame]
        out = []
        for v in self.views:
            img = self.plates[v].read(frame + self.offsets.get(v, 0))
            f = self.factors[v]
            if f != 1.0:
                w, h = self.plates[v].image_size
                img = cv2.resize(img, (int(round(w * f)), int(round(h * f))),
                                 interpolation=cv2.INTER_AREA)
            out.append(img)
        if (len(self.cache) + 1) * self.per_frame <= self.budget:
            self.cache[frame] = out
        return out


def _blend_camera(a, b, w):
    """Uncalibrated cameras between two states: the scale geometrically, the perspective
    linearly (w: 0 -> a)."""
    s = float(np.exp((1 - w) * np.log(a.s) + w * np.log(b.s)))
    if not (a.kappa or b.kappa):
        return a.replace(s=s)
    kappa = (1 - w) * a.kappa + w * b.kappa
    if not kappa > 0.0:         # at the far one of a far and a near camera
        return (b if w >= 0.5 else a).replace(s=s)
    return a.replace(s=s, kappa=kappa, t=[0.0, 0.0, 1.0 / kappa])


def blend_states(a, b, w):
    """Pose between two states: angles linearly, roots along the SE(3) geodesic (w: 0 -> a)."""
    out = a.copy()
    out.angles = (1 - w) * a.angles + w * b.angles
    for c in range(len(a.roots)):
        rel = se3.log_se3(b.roots[c] @ se3.invert(a.roots[c]))
        out.roots[c] = se3.exp_se3(w * rel) @ a.roots[c]
    if hasattr(a.cameras[0], "s"):
        out.cameras = [_blend_camera(ca, cb, w) for ca, cb in zip(a.cameras, b.cameras)]
    return out


def plan_passes(anchor_frames, frames, reach=BLEND_REACH):
    """The tracking passes of a take: from the first anchor back to the take's start, between
    each two anchors (forward, then backward, to be blended), and from the last anchor to the
    end.

    Parameters
    ----------
    anchor_frames : list of int
        Sorted anchor frames inside ``frames``.
    frames : range
    reach : int or None
        Between two anchors, how far past the middle each pass tracks at first
        (:func:`blend_stretch`).

    Returns
    -------
    passes : list of (int, int, (int, int) or None)
        ``(start, stop, stretch)``, both ends included. Between two anchors ``start < stop``
        and ``stretch`` is the blended stretch ``(lo, hi)``: the forward pass tracks to
        ``hi``, the backward one to ``lo``. None for a single pass.
    total : int
        Frames the passes track at first: for progress.
    """
    passes = []
    if anchor_frames[0] > frames.start:
        passes.append((anchor_frames[0], frames.start, None))
    for a, b in zip(anchor_frames[:-1], anchor_frames[1:]):
        passes.append((a, b, blend_stretch(a, b, reach)))
    if anchor_frames[-1] < frames.stop - 1:
        passes.append((anchor_frames[-1], frames.stop - 1, None))
    total = sum(abs(b - a) if st is None else st[1] - a + b - st[0] for a, b, st in passes)
    return passes, total


def _pass_quality(reports):
    """Each frame's largest grey residual over the views and mean silhouette overlap."""
    r = np.array([np.max(rep.residual) for rep in reports], float)
    iou = np.array([np.nanmean(rep.iou) if np.isfinite(rep.iou).any() else np.nan
                    for rep in reports], float)
    return r, iou


def _references(forward, backward):
    """The better pass's typical residual and overlap over the frames both tracked (a whole
    pass may be lost)."""
    rf, iou_f = _pass_quality(forward)
    rb, iou_b = _pass_quality(backward)
    r_ref = min(np.median(rf), np.median(rb)) + 1e-9
    medians = [np.nanmedian(i) for i in (iou_f, iou_b) if np.isfinite(i).any()]
    return r_ref, (max(medians) if medians else np.nan)


def _goodness(reports, references, smooth):
    """Per frame, 1 for a pass as good as the reference, towards 0 for one that has lost the
    body (a grey residual above the reference, or a poorer overlap); a running mean over
    ``smooth`` frames keeps it from jumping."""
    r_ref, iou_ref = references
    r, iou = _pass_quality(reports)
    g = np.exp(-np.maximum(r / r_ref - 1.0, 0.0))
    if np.isfinite(iou_ref):
        g *= np.clip(np.nan_to_num(iou, nan=iou_ref) / iou_ref, 0.05, 1.0) ** 2
    n = len(g)
    if smooth > 1 and n > 1:
        kernel = np.ones(min(smooth, n)) / min(smooth, n)
        g = np.convolve(np.pad(g, len(kernel) // 2, mode="edge"), kernel, "valid")[:n]
    return g


def blend_weights(forward, backward, smooth=5):
    """How much of the backward pass each frame of a blended stretch takes (0: all forward).

    By distance, the nearer anchor's pass counts more; by quality, a pass that has lost the
    body (a grey residual well above the two passes' median, or a poorer silhouette overlap)
    counts less, so that a blend does not drag a good pass towards a lost one.

    Parameters
    ----------
    forward, backward : list of StepReport
        The two passes' reports at the frames of the stretch, in frame order.
    smooth : int
        Frames of the running mean that keeps the weights from jumping.

    Returns
    -------
    array, shape (n,)
    """
    n = len(forward)
    if n == 0:
        return np.zeros(0)
    w = np.arange(1, n + 1) / (n + 1)
    refs = _references(forward, backward)
    gf, gb = _goodness(forward, refs, smooth), _goodness(backward, refs, smooth)
    return w * gb / ((1 - w) * gf + w * gb + 1e-12)


def blend_stretch(a, b, reach=None):
    """The frames between anchors ``a < b`` that both passes track at first: ``reach`` frames
    either side of the middle (all of them when ``reach`` is None or the anchors are close).

    Returns
    -------
    lo, hi : int
        The forward pass tracks ``a+1 .. hi``, the backward pass ``lo .. b-1``.
    """
    if reach is None:
        return a + 1, b - 1
    mid = (a + b) // 2
    return max(a + 1, mid - reach), min(b - 1, mid + reach)


def extend_passes(forward, backward, lo, hi, reach, poor=POOR_PASS, smooth=5):
    """How far the two passes between two anchors must go on after their first stretch.

    A pass that lost the body before the blended stretch ``lo .. hi`` began leaves frames that
    only it has tracked: its partner goes on towards the first anchor, to ``reach`` frames
    before the first frame where the lost pass's quality (:func:`_goodness`, against the two
    passes' references over the stretch) falls below ``poor``.

    Parameters
    ----------
    forward : dict of int to StepReport
        Frames ``a+1 .. hi``.
    backward : dict of int to StepReport
        Frames ``lo .. b-1``.

    Returns
    -------
    forward_to : int
        The last frame the forward pass must reach (``hi`` when it need not go on).
    backward_to : int
        The first frame the backward pass must reach (``lo`` when it need not go on).
    """
    stretch = range(lo, hi + 1)
    if not stretch:
        return hi, lo       # adjacent anchors: nothing between them
    refs = _references([forward[f] for f in stretch], [backward[f] for f in stretch])
    backward_to, forward_to = lo, hi
    early = sorted(f for f in forward if f < lo)
    if early:
        g = _goodness([forward[f] for f in early], refs, smooth)
        bad = [f for f, x in zip(early, g) if x < poor]
        if bad:
            backward_to = max(early[0], bad[0] - reach)
    late = sorted(f for f in backward if f > hi)
    if late:
        g = _goodness([backward[f] for f in late], refs, smooth)
        bad = [f for f, x in zip(late, g) if x < poor]
        if bad:
            forward_to = min(late[-1], bad[-1] + reach)
    return forward_to, backward_to


def take_backgrounds(tracker, source, views, frames, inside, state_at, log):
    """Background model per view, whether to use it, and the first anchor's silhouette fit,
    overlap and unexplained foreground (the references for the frames' status).

    Frames spread over the take give each view's background; the model's dilated silhouette at
    the anchors keeps the person out of it; a view whose foreground does not cover the model at
    the first anchor goes without silhouettes.
    """
    sample = sample_frames(frames)
    log(f"background: {len(sample)} frames per view")
    per_view = [[] for _ in views]
    for f in sample:
        for c, img in enumerate(source.colour(int(f))):
            per_view[c].append(img)
    exclude = [[] for _ in views]
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    for a in inside:
        renders_a = tracker.render_views(state_at(a.frame), want=())
        for c, img in enumerate(source.colour(a.frame)):
            mask = cv2.dilate((renders_a[c].label >= 0).astype(np.uint8), kernel) > 0
            exclude[c].append((img, mask))
    # one view per thread: the estimate is whole-image numpy and OpenCV work, outside the GIL
    backgrounds = list(thread_pool("views", 2).map(
        lambda c: estimate_background(per_view[c], exclude=exclude[c])
        if len(per_view[c]) >= 5 else None, range(len(views))))
    use_bg = [bg is not None for bg in backgrounds]
    a0 = inside[0].frame
    r0 = tracker.render_views(state_at(a0), want=())
    colour0 = source.colour(a0)
    ref_fit = np.full(len(views), np.nan)
    ref_iou = np.full(len(views), np.nan)
    ref_unexplained = np.full(len(views), np.nan)
    for c in range(len(views)):
        if not use_bg[c]:
            continue
        bg = backgrounds[c]
        cov = model_coverage(r0[c].label >= 0, bg.foreground(colour0[c]) & bg.known, bg.known)
        if cov < 0.5:
            use_bg[c] = False
            log(f"view '{views[c]}': background model unreliable here "
                f"(covers {cov:.0%} of the body); silhouettes off")
            continue
        fg = bg.foreground(colour0[c])
        ref_fit[c] = model_coverage(r0[c].label >= 0, fg)
        ref_iou[c] = max(silhouette_iou(r0[c].label >= 0, fg), 0.05)
        if ref_fit[c] < MIN_ANCHOR_FIT:
            use_bg[c] = False
            log(f"view '{views[c]}': only {ref_fit[c]:.0%} of the model lies in the "
                "foreground at the anchor; silhouettes off")
            ref_fit[c] = ref_iou[c] = np.nan
            continue
        ref_unexplained[c] = unexplained_fraction(bg.person(colour0[c], fg), r0[c].label,
                                                  bg.known)
    return backgrounds, use_bg, ref_fit, ref_iou, ref_unexplained


def sample_frames(frames):
    """The frames spread over the take that the background models are estimated from."""
    return np.unique(np.linspace(frames.start, frames.stop - 1,
                                 min(25, len(frames))).astype(int))


def tracked_backgrounds(tracker, source, views, frames, states, use_bg):
    """Background models estimated again with the tracked body kept out of them.

    The first estimate knows where the person is at the anchor frames only; a person who
    stands still for a third of the take or more (a crouch before a jump, a turn on the spot)
    is taken for background there, and the foreground loses them. With the tracked poses,
    every sampled frame's (dilated) model silhouette is kept out.

    Returns
    -------
    list of BackgroundModel or None
        Per view; None where the view's background is not used.
    """
    sample = [int(f) for f in sample_frames(frames) if int(f) in states]
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    per_view = [[] for _ in views]
    masks = [[] for _ in views]
    for f in sample:
        renders = tracker.render_views(states[f], want=())
        for c, img in enumerate(source.colour(f)):
            per_view[c].append(img)
            masks[c].append(cv2.dilate((renders[c].label >= 0).astype(np.uint8), kernel) > 0)
    return list(thread_pool("views", 2).map(
        lambda c: estimate_background(per_view[c], masks=np.stack(masks[c]))
        if use_bg[c] and len(sample) >= 5 else None, range(len(views))))


def remeasure(tracker, source, states, reports, anchor_frames, backgrounds, use_bg, limbs):
    """The silhouette measures of every tracked frame and of the first anchor against new
    background models (:func:`tracked_backgrounds`), in place of the reports' own.

    Returns
    -------
    ref_fit, ref_iou, ref_unexplained : array, shape (V,)
        The first anchor's, the references of the frames' status.
    """
    usable = [u and bg is not None for u, bg in zip(use_bg, backgrounds)]
    for f, rep in reports.items():
        if rep is None or f in anchor_frames:
            continue
        rep.coverage, rep.iou, rep.unexplained, limb_fit = silhouette_measures(
            tracker, states[f], source.colour(f), backgrounds, usable, limbs=limbs)
        if limb_fit is not None:
            rep.limb_fit = limb_fit
    return anchor_references(tracker, source, states, anchor_frames, backgrounds, use_bg)


def anchor_references(tracker, source, states, anchor_frames, backgrounds, use_bg):
    """The first anchor's silhouette fit, overlap and unexplained foreground against
    ``backgrounds``, where ``use_bg``: the references of the frames' status."""
    a0 = anchor_frames[0]
    usable = [u and bg is not None for u, bg in zip(use_bg, backgrounds)]
    fit, iou, unexplained, _ = silhouette_measures(tracker, states[a0], source.colour(a0),
                                                   backgrounds, usable)
    return fit, np.maximum(iou, 0.05), unexplained


def unexplained_fraction(foreground, labels, known=None):
    """Foreground no part of the model explains (thick blobs, :func:`recover.
    unexplained_foreground`), as a fraction of the model's area."""
    return unexplained_share(unexplained_foreground(foreground, labels, known), labels)


def silhouette_measures(tracker, state, colours, backgrounds, use_bg, limbs=False):
    """Silhouette fit, overlap and unexplained foreground of a pose in every view whose
    background is used.

    Returns
    -------
    fit, iou, unexplained : array, shape (V,)
        NaN where a view has no usable background.
    limb_fit : dict of str to float or None
        With ``limbs`` and two or more views with silhouettes: each limb's silhouette score
        (:meth:`recover.LimbSearch.fit`).
    """
    V = len(colours)
    fit = np.full(V, np.nan)
    iou = np.full(V, np.nan)
    unexplained = np.full(V, np.nan)
    if not any(use_bg):
        return fit, iou, unexplained, None
    renders = tracker.render_views(state, want=())
    sdfs = [None] * V
    for c, img in enumerate(colours):
        if use_bg[c]:
            fg = backgrounds[c].foreground(img)
            person = backgrounds[c].person(img, fg)
            fit[c] = model_coverage(renders[c].label >= 0, fg)
            iou[c] = silhouette_iou(renders[c].label >= 0, fg)
            unexplained[c] = unexplained_fraction(person, renders[c].label,
                                                  backgrounds[c].known)
            if limbs:
                sdfs[c] = signed_distance(fg)
    if not limbs or tracker.search is None or sum(d is not None for d in sdfs) < 2:
        return fit, iou, unexplained, None
    return fit, iou, unexplained, tracker.search.fit(state, sdfs, [r.label for r in renders])


def frame_status(rel_fit, rel_iou, residual_ratio, limb_fit=None, unexplained_excess=None):
    """ok, uncertain or lost, from one frame's diagnostics.

    Parameters
    ----------
    rel_fit, rel_iou : array, shape (V,)
        Silhouette fit and overlap per view relative to the anchor frame's (NaN: no mask).
    residual_ratio : float
        The frame's worst grey residual over the take's median.
    limb_fit : dict of str to float, optional
        Each limb's silhouette score (:meth:`recover.LimbSearch.fit`).
    unexplained_excess : array, shape (V,), optional
        Unexplained foreground (:func:`unexplained_fraction`) above the anchor frame's, per
        view (NaN: not measured).
    """
    excess = np.asarray([] if unexplained_excess is None else unexplained_excess, float)
    excess = excess[np.isfinite(excess)]
    worst_limb = min(limb_fit.values()) if limb_fit else np.inf
    rel_fit = np.asarray(rel_fit, float)
    rel_iou = np.asarray(rel_iou, float)
    rel_fit, rel_iou = rel_fit[np.isfinite(rel_fit)], rel_iou[np.isfinite(rel_iou)]
    # Fast motion raises the grey residual of a good fit too: where silhouettes are measured,
    # a high residual alone makes a frame uncertain, and lost only if a silhouette doubts it.
    doubted = ((len(rel_fit) and rel_fit.min() < FIT_UNCERTAIN)
               or (len(rel_iou) and rel_iou.min() < IOU_UNCERTAIN)
               or not (len(rel_fit) or len(rel_iou)))
    if ((len(rel_fit) and np.median(rel_fit) < FIT_LOST)
            or (len(rel_iou) and np.median(rel_iou) < IOU_LOST)
            or (residual_ratio > RESIDUAL_LOST and doubted)
            or worst_limb < LIMB_LOST):
        return "lost"
    if ((len(rel_fit) and rel_fit.min() < FIT_UNCERTAIN)
            # in one view a limb in front of the body scores low where it belongs (its points
            # fall on the rest of the body); only a limb outside the silhouette says "lost"
            or (worst_limb < LIMB_UNCERTAIN and len(rel_fit) >= 2)
            or (len(rel_iou) and rel_iou.min() < IOU_UNCERTAIN)
            or (len(excess) and excess.max() > UNEXPLAINED_UNCERTAIN)
            or residual_ratio > RESIDUAL_UNCERTAIN):
        return "uncertain"
    return "ok"


def blend_report(fwd, bwd, w, measured):
    """Diagnostics of a blended frame: residuals weighted like the poses, the silhouette
    fit, overlap, unexplained foreground and limb scores measured on the blended pose
    (:func:`silhouette_measures`)."""
    from ..trackers.differential import StepReport

    fit, iou, unexplained, limb_fit = measured
    out = StepReport(residual=(1 - w) * fwd.residual + w * bwd.residual,
                     iou=iou, cost=(1 - w) * fwd.cost
                     + w * bwd.cost, iterations=fwd.iterations + bwd.iterations,
                     renders=None, coverage=fit)
    out.unexplained = unexplained
    if limb_fit is not None:
        out.limb_fit = limb_fit
    out.recovered = sorted(set(fwd.recovered or []) | set(bwd.recovered or []))
    return out


def anchor_frames_all(anchors):
    return [a.frame for a in anchors]


class Cancelled(Exception):
    """Raised inside the tracking loop when the caller's cancel() says so."""


def check_take(plates, anchors, cameras, frames, offsets):
    """Check a take's inputs, in one line each: plates of one length, a frame range inside
    them, cameras for every view at the plates' size (when given), markers on known views and
    at least one anchor inside the range.

    Returns
    -------
    views : list of str
    offsets : dict of str to int
    frames : range
    inside : list of markers.Anchor
        The anchors inside ``frames``.
    """
    from ..imaging.plates import check_same_length

    views = list(plates)
    offsets = dict(offsets or {})
    n_total = check_same_length(plates, offsets)
    frames = range(0, n_total) if frames is None else frames
    if len(frames) < 1:
        raise ZoopraxisError("the frame range is empty")
    if frames.start < 0 or frames.stop > n_total:
        raise ZoopraxisError(f"frames {frames.start}:{frames.stop} are outside the take "
                             f"(0:{n_total})")
    if cameras is not None:
        missing = [v for v in views if v not in cameras]
        if missing:
            raise ZoopraxisError(f"the calibration has no camera for view '{missing[0]}'")
        for v in views:
            if tuple(cameras[v].image_size) != tuple(plates[v].image_size):
                raise ZoopraxisError(
                    f"view '{v}': calibration image size {tuple(cameras[v].image_size)} differs "
                    f"from the plate's {tuple(plates[v].image_size)}")
    check_markers(anchors, views, n_total)
    inside = [a for a in anchors if frames.start <= a.frame < frames.stop]
    if not inside:
        raise ZoopraxisError(f"no marker anchor inside frames {frames.start}:{frames.stop} "
                             f"(anchors at {', '.join(str(a.frame) for a in anchors)})")
    return views, offsets, frames, inside


def _run_in_turn(run, jobs, progress, cancel, then=None):
    """Run the passes one after the other; a cancel keeps the frames tracked so far.

    ``progress(n)`` gets the frames tracked so far; ``then(job, frames)``, called as each pass
    ends, returns the passes to run after it (:func:`track`'s passes that go on).
    """
    results = {}
    done = 0

    def report(n):
        nonlocal done
        done += n
        if progress is not None:
            progress(done)

    queue = list(jobs)
    while queue:
        job = queue.pop(0)
        try:
            results[job] = run(job, report, cancel)
        except Cancelled as exc:
            results[job] = exc.args[0]
            return results, True
        if then is not None:
            queue += then(job, results[job])
    return results, False


class _Later:
    """``fn(*args)`` made when its result is asked for (a future without a thread)."""

    __slots__ = ("fn", "args")

    def __init__(self, fn, *args):
        self.fn, self.args = fn, args

    def result(self):
        return self.fn(*self.args)


def default_cores():
    """Cores this process may run on."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:      # not on Linux
        return os.cpu_count() or 1


def default_workers():
    """Worker processes for the passes when none are asked for: one per core, at most 4."""
    return min(default_cores(), 4)


def _can_fork():
    """Worker processes share the take by forking: on Linux (macOS forbids forking a process
    with system frameworks loaded, Windows cannot fork), and not inside the Blender application
    (its window, GPU and job threads must not be forked; Blender as a Python module may)."""
    import multiprocessing
    import sys

    bpy = sys.modules.get("bpy")
    in_blender = bpy is not None and bool(getattr(getattr(bpy, "app", None), "binary_path", ""))
    return (sys.platform.startswith("linux") and not in_blender
            and "fork" in multiprocessing.get_all_start_methods())


_FORKED = None      # (run, counter, stop event): what a forked worker runs


class _Resume:
    """Where a pass that goes on stopped: the frame, the pose before it and the pose at it.
    Hashable by identity, so that a job holding it keys the results."""

    __slots__ = ("frame", "before", "state")

    def __init__(self, frame, before, state):
        self.frame, self.before, self.state = frame, before, state


class _Measure:
    """A job that measures the silhouettes of blended poses (:func:`track`'s
    ``blended_fit``) at ``frames``. Hashable by identity, as :class:`_Resume`."""

    __slots__ = ("frames", "states")

    def __init__(self, frames, states):
        self.frames, self.states = frames, states


def _ignore_interrupt():
    """Ctrl-C reaches the whole process group: the parent turns it into a polite stop."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _forked_pass(job):
    run, counter, stop = _FORKED

    def report(n):
        with counter.get_lock():
            counter.value += n

    try:
        return run(job, report, stop.is_set), False
    except Cancelled as exc:
        return exc.args[0], True


def _run_in_processes(run, jobs, workers, progress, cancel, then=None):
    """Run independent passes in forked worker processes (they inherit the plates, the
    background models and the tracker), polling progress and cancel every quarter second.
    ``progress`` and ``then`` as in :func:`_run_in_turn`: a pass ``then`` returns starts as
    soon as a worker is free."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait

    global _FORKED
    ctx = multiprocessing.get_context("fork")
    counter = ctx.Value("i", 0)
    stop = ctx.Event()
    _FORKED = (run, counter, stop)
    results, cancelled = {}, False
    try:
        with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_ignore_interrupt) as pool:
            futures = {pool.submit(_forked_pass, job): job for job in jobs}
            pending = set(futures)
            try:
                while pending:
                    finished, pending = wait(pending, timeout=0.25,
                                             return_when=FIRST_COMPLETED)
                    for fut in finished:
                        out, was_cancelled = fut.result()
                        job = futures[fut]
                        results[job] = out
                        cancelled |= was_cancelled
                        if then is not None and not (cancelled or stop.is_set()):
                            for new in then(job, out):
                                started = pool.submit(_forked_pass, new)
                                futures[started] = new
                                pending.add(started)
                    if progress is not None:
                        progress(counter.value)
                    if cancel is not None and not stop.is_set() and cancel():
                        stop.set()
            except BaseException:
                # an error in one pass, or a second Ctrl-C: the other workers stop at their
                # next frame instead of finishing their passes before the pool closes
                stop.set()
                raise
    finally:
        _FORKED = None
    return results, cancelled or stop.is_set()


def _tracking_view(cam, body2world, near):
    """An uncalibrated view as the tracker holds it: the body's pose in the camera frame and
    the camera, unrotated. In a take with near cameras (``near``: some ``kappa > 0``) the body
    is moved to the depth of the world origin, where the camera's scale ``s`` and perspective
    ``kappa`` are measured, and the camera's ``t_z`` keeps the depths it gives: a near camera
    has its centre at depth 0, where the renderer puts a pinhole's. Far cameras of other takes
    are kept as they always were."""
    body2cam = se3.transform(cam.R, cam.t) @ body2world
    if not near:
        return body2cam, ScaledOrthoCamera(cam.name, cam.image_size, cam.s, c=cam.c)
    body2cam[2, 3] -= cam.t[2]
    depth = 1.0 / cam.kappa if cam.kappa else cam.t[2]
    return body2cam, ScaledOrthoCamera(cam.name, cam.image_size, cam.s, t=[0.0, 0.0, depth],
                                       c=cam.c, kappa=cam.kappa)


def track(plates, anchors, cameras=None, *, frames=None, offsets=None, template="full",
          settings=None, init=None, max_size=960, progress=None, cancel=None, log=None,
          workers=1, blend_reach=BLEND_REACH, flips=None, camera_tilt=CAMERA_TILT_DEG,
          pose_prior="default", dims=None, perspective=False):
    """Track a take with the differential tracker.

    Parameters
    ----------
    plates : dict of str to Plate
        One plate per view, in view order.
    anchors : list of markers.Anchor
    cameras : dict of str to PinholeCamera, optional
        Calibrated mode when given (one per view); uncalibrated otherwise.
    frames : range, optional
        Take frames to track (default: all frames the plates share).
    offsets : dict of str to int, optional
        Per-view plate frame offset (take frame f is plate frame f + offset).
    init : Initial, optional
        Starting poses; by default fitted to the markers with :func:`initialize.initialize`.
    progress : callable(done, total), optional
    cancel : callable() -> bool, optional
        Polled once a frame; on cancel the frames already tracked are returned.
    workers : int
        Processes for the tracking passes (a take with several anchors has several
        independent passes); 1 runs them in turn. Worker processes fork, so they are used on
        Linux outside Blender only.
    blend_reach : int or None
        Between two anchors, how many frames past the middle each pass tracks at first
        (:data:`BLEND_REACH`); None tracks both passes from anchor to anchor.
    flips : dict of int to list of str, optional
        Body parts to turn to their other depth at anchor frames clicked in one view
        (:func:`initialize.initialize`), when ``init`` is not given.
    camera_tilt : (float, float) or None
        Uncalibrated, when ``init`` is not given: how far the camera of an anchor frame
        clicked in one view looks down at the subject, give or take how much (degrees;
        :func:`initialize.initialize`).
    pose_prior : PosePrior, "default", path or None
        When ``init`` is not given: the pose prior of anchor frames clicked in one view
        (:func:`initialize.initialize`).
    dims : dict, optional
        When ``init`` is not given: the performer's body lengths, kept instead of fitted.
    perspective : bool
        Uncalibrated, when ``init`` is not given: fit each view's perspective (views near the
        body; :func:`initialize.initialize`) and track through it.

    Returns
    -------
    TrackResult
    """
    views, offsets, frames, inside = check_take(plates, anchors, cameras, frames, offsets)
    calibrated = cameras is not None
    log = log or (lambda msg: None)
    settings = settings or Settings()

    if init is None:
        from ..initialize.fit import initialize

        res = initialize(inside, {v: cameras[v] if calibrated else tuple(plates[v].image_size)
                                  for v in views},
                         template=template, calibrated=calibrated, views=views, flips=flips,
                         camera_tilt=camera_tilt, pose_prior=pose_prior, dims=dims,
                         fit_dims=not dims, perspective=perspective)
        for note in res.flip_notes() + ([res.distance_note()] if perspective else []):
            log(note)
        for note in res.notes:
            log(f"note: {note}")
        init = Initial(res.body, res.poses, res.cameras, getattr(res, "view_cameras", None),
                       list(getattr(res, "warnings", [])))
    for w in init.warnings:
        log(f"warning: {w}")
    if len(views) == 1:
        log("note: one view does not measure the depth of the limbs; the frames between "
            "anchors are reported uncertain at best")
    body = init.body

    # Working resolution and cameras
    factors = {v: min(1.0, max_size / max(plates[v].image_size)) for v in views}
    source = FrameSource(plates, views, offsets, factors)

    def working_cameras(cams):
        return [cams[v].scaled(factors[v], sampling="resize") if factors[v] != 1.0 else cams[v]
                for v in views]

    near = not calibrated and any(
        getattr(cam, "kappa", 0.0) for cams in [init.cameras, *(init.view_cameras or {}).values()]
        for cam in cams.values())

    def state_at(frame):
        pose = init.poses[frame]
        if calibrated:
            return State(np.stack([pose.root] * len(views)), pose.angles.copy(),
                         working_cameras(cameras))
        vc = (init.view_cameras or {}).get(frame, init.cameras)
        roots, cams = zip(*(_tracking_view(vc[v], pose.root, near) for v in views))
        return State(np.stack(roots), pose.angles.copy(), working_cameras(dict(zip(views, cams))))

    tracker = DifferentialTracker(body, calibrated, settings)

    # Background models from frames spread over the take; at the anchor frames the model's
    # (dilated) silhouette says where the person is, which keeps a slow mover out of it.
    backgrounds, use_bg, ref_fit, ref_iou, ref_unexplained = take_backgrounds(
        tracker, source, views, frames, inside, state_at, log)

    def images(frame):
        colours = source.colour(frame)

        def one(c):
            if not use_bg[c]:
                return prepare_images(to_gray_float(colours[c]), settings.levels,
                                      settings.smooth_sigma)
            fg = backgrounds[c].foreground(colours[c])
            return prepare_images(to_gray_float(colours[c]), settings.levels,
                                  settings.smooth_sigma, fg, backgrounds[c].known,
                                  backgrounds[c].person(colours[c], fg))

        return tracker.map_views(one, len(colours))

    anchor_frames = [a.frame for a in inside]
    passes, first_total = plan_passes(anchor_frames, frames, blend_reach)
    total = first_total

    anchor_states = {a: state_at(a) for a in anchor_frames}

    spare_core = True

    def images_ahead(frame):
        """The next frame's images (decoding, foreground, pyramids, distance images: OpenCV
        work that runs outside the GIL), prepared in a thread while this one is tracked when
        a core is spare; when every core runs a pass, the thread would only take turns with
        the tracking (measured: 4 % more CPU a frame), and they are made when asked for."""
        if spare_core:
            return thread_pool("frames", 1).submit(images, frame)
        return _Later(images, frame)

    def run(job, report, should_stop):
        """Track from anchor ``job[0]`` to frame ``job[1]`` (inclusive), either direction; a
        third item (:class:`_Resume`) is where an earlier part of the same pass stopped. A
        :class:`_Measure` job measures blended poses instead."""
        if isinstance(job, _Measure):
            return {f: blended_fit(st, f) for f, st in zip(job.frames, job.states)}
        start, stop = job[:2]
        step = 1 if stop > start else -1
        # each pass draws its own search samples: the same result whichever runs first
        if tracker.search is not None:
            tracker.search.reseed(job[:2] if len(job) == 2 else (*job[:2], job[2].frame))
        st = state_at(start)
        ims = images(start)
        renders = tracker.render_views(st)
        tracker.set_anchor(st, ims, renders)
        prev = None
        first = start
        if len(job) > 2:
            first, prev, st = job[2].frame, job[2].before, job[2].state
            ims = images(first)
            renders = tracker.render_views(st)
        out = {}
        ahead = images_ahead(first + step) if first != stop else None
        for f in range(first + step, stop + step, step):
            if should_stop is not None and should_stop():
                raise Cancelled(out)
            ims1 = ahead.result()
            ahead = images_ahead(f + step) if f != stop else None
            new, rep = tracker.step(st, ims, ims1, prev, renders)
            prev, st, ims, renders = st, new, ims1, rep.renders
            rep.renders = None      # full-size images: keep them only for the next step
            out[f] = (new, rep)
            report(1)
        return out

    def blended_fit(state, frame):
        """Silhouette fit and overlap of a blended pose, measured anew: they are not either
        pass's."""
        return silhouette_measures(tracker, state, source.colour(frame), backgrounds, use_bg,
                                   limbs=calibrated)

    def run_passes(round_index, rounds, before=0):
        """Track every pass of the take with the current background models (round
        ``round_index`` of ``rounds``, after ``before`` frames tracked in earlier rounds: for
        progress); returns the states and reports of every frame tracked and whether a cancel
        stopped it."""
        nonlocal spare_core, total
        total = first_total
        states, reports = dict(anchor_states), dict.fromkeys(anchor_frames)
        # First the single passes and, between two anchors, each pass up to a little past the
        # middle; as soon as both of a pair are done, a pass whose partner lost the body on the
        # way goes on towards it.
        pairs = {(a, b): st for a, b, st in passes if st is not None}
        jobs = [(a, b) for a, b, st in passes if st is None]
        part_of = {}        # job -> the pass (from anchor, to anchor) it belongs to
        for (a, b), (lo, hi) in pairs.items():
            if lo <= hi:        # adjacent anchors have nothing between them
                jobs += [(a, hi), (b, lo)]
                part_of[(a, hi)], part_of[(b, lo)] = (a, b), (b, a)
        tracked = {(a, b): {} for a, b, _ in passes}    # pass -> frame -> (state, report)
        tracked.update({(b, a): {} for a, b in pairs})
        running = {pair: 2 for pair, (lo, hi) in pairs.items() if lo <= hi}  # jobs of a pair
        blends = {}         # pair -> [(frame, weight, blended state)]
        measured = {}       # frame -> silhouette_measures of its blended pose

        def blend(a, b):
            """The blended frames of the pair ``a < b`` (both passes done), made once."""
            if (a, b) not in blends:
                fwd, bwd = tracked[(a, b)], tracked[(b, a)]
                both = [f for f in range(a + 1, b) if f in fwd and f in bwd]
                weights = blend_weights([fwd[f][1] for f in both], [bwd[f][1] for f in both])
                blends[(a, b)] = [(f, w, blend_states(fwd[f][0], bwd[f][0], w))
                                  for f, w in zip(both, weights)]
            return blends[(a, b)]

        def then(job, out):
            nonlocal total
            if isinstance(job, _Measure):
                measured.update(out)
                return []
            tracked[part_of.get(job, job[:2])].update(out)
            pair = part_of.get(job)
            if pair is None:
                return []
            a, b = min(pair), max(pair)
            running[(a, b)] -= 1
            more = []
            if len(job) == 2 and running[(a, b)] == 1:
                return []       # the other pass is still running
            if len(job) == 2:
                lo, hi = pairs[(a, b)]
                fwd, bwd = tracked[(a, b)], tracked[(b, a)]
                to_f, to_b = extend_passes({f: r for f, (_, r) in fwd.items()},
                                           {f: r for f, (_, r) in bwd.items()}, lo, hi,
                                           blend_reach)
                for (start, stop), part, at, to in (((a, b), fwd, hi, to_f),
                                                    ((b, a), bwd, lo, to_b)):
                    if to != at:
                        step = 1 if stop > start else -1
                        before = part[at - step][0] if at - step != start else state_at(start)
                        job = (start, to, _Resume(at, before, part[at][0]))
                        part_of[job] = (start, stop)
                        more.append(job)
                        total += abs(to - at)
                if more:
                    log(f"frames {a}-{b}: {len(more)} pass{'es go' if len(more) > 1 else ' goes'} "
                        "on where the other lost the body")
                    running[(a, b)] += len(more)
            if running[(a, b)] == 0:
                # Both passes are done: the blended poses' silhouettes are measured in the
                # workers, in as many parts as there are workers, while other passes run.
                frames_b = [(f, st) for f, _, st in blend(a, b)]
                for k in range(processes):
                    share = frames_b[k::processes]
                    if share:
                        more.append(_Measure([f for f, _ in share], [st for _, st in share]))
            return more

        def counted(n):
            if progress is not None:
                progress(before + n, before + total + (rounds - 1 - round_index) * first_total)

        # longest first: even out the workers
        jobs.sort(key=lambda job: -abs(job[1] - job[0]))
        processes = 1
        if workers > 1 and len(jobs) > 1 and _can_fork():
            processes = min(workers, len(jobs))
            log(f"tracking {len(jobs)} passes in {processes} processes")
            spare_core = processes < default_cores()
            results, cancelled = _run_in_processes(run, jobs, processes, counted, cancel, then)
        else:
            results, cancelled = _run_in_turn(run, jobs, counted, cancel, then)
        if cancelled:
            # what the passes tracked and measured before the cancel reached them
            for job, out in results.items():
                if isinstance(job, _Measure):
                    measured.update(out)
                else:
                    tracked[part_of.get(job, job[:2])].update(out)

        for a, b, stretch in passes:
            fwd, bwd = tracked[(a, b)], tracked.get((b, a), {})
            inner = range(a + 1, b)
            both = [f for f in inner if f in fwd and f in bwd]
            if stretch is not None and both and all(f in fwd or f in bwd for f in inner):
                for f, w, state in blend(a, b):
                    states[f] = state
                    # measured by a worker, or here (a cancel stopped the measuring jobs)
                    fit = measured.get(f) or blended_fit(state, f)
                    reports[f] = blend_report(fwd[f][1], bwd[f][1], w, fit)
            # frames only one pass tracked (or a pair cut short by a cancel): keep them all
            for part in (fwd, bwd):
                for f, (st, rep) in part.items():
                    if f not in states:
                        states[f], reports[f] = st, rep
        return states, reports, cancelled

    # Two rounds where the silhouettes of two views or more are used: the first backgrounds
    # know where the person is at the anchors only, and take a person who stood still for a
    # while for background there; the first round's track keeps the body out of the second
    # round's backgrounds. (One view, where no limb search runs and the outline leaves the
    # depth free, tracked walk131_single worse in two rounds: 202 mm PA against 145.)
    rounds = 2 if sum(use_bg) >= 2 else 1
    states, reports, cancelled = run_passes(0, rounds)
    if cancelled:
        log("cancelled: keeping the frames tracked so far")
    elif rounds == 2:
        refined = tracked_backgrounds(tracker, source, views, frames, states, use_bg)
        log("background: estimated again with the tracked body kept out of it; tracking again")
        first = states, reports
        backgrounds = [r if r is not None else b for r, b in zip(refined, backgrounds)]
        states, reports, cancelled = run_passes(1, rounds, before=total)
        if cancelled:
            # the first round's frames were measured against the first backgrounds
            log("cancelled: keeping the first round's track")
            states, reports = first
            ref_fit, ref_iou, ref_unexplained = remeasure(
                tracker, source, states, reports, anchor_frames, refined, use_bg,
                limbs=calibrated)
        else:
            # the second round measured its frames against these backgrounds already
            ref_fit, ref_iou, ref_unexplained = anchor_references(
                tracker, source, states, anchor_frames, backgrounds, use_bg)

    return make_result(body, views, plates, factors, states, reports, calibrated, init,
                        anchor_frames, frames, cancelled, ref_fit, ref_iou, ref_unexplained)


def make_result(body, views, plates, factors, states, reports, calibrated, init,
                 anchor_frames, frames, cancelled, ref_fit, ref_iou, ref_unexplained):
    order = sorted(states)
    F = len(order)
    joints3d = np.zeros((F, 17, 3))
    joints2d = {v: np.zeros((F, 17, 2)) for v in views}
    residual = {v: np.zeros(F) for v in views}
    roots = np.zeros((F, 4, 4))
    angles = np.zeros((F, body.n_dofs))
    iou = np.full((F, len(views)), np.nan)
    fit = np.full((F, len(views)), np.nan)
    limb_fit, recovered = [], []
    unexplained = np.full((F, len(views)), np.nan)
    ref = None
    if not calibrated:
        # Body-centred frame: the body as camera 0 saw it at the first anchor, made Z-up.
        a0 = states[anchor_frames[0]]
        ref = se3.invert(a0.roots[0])
    for i, f in enumerate(order):
        st = states[f]
        if calibrated:
            root = st.roots[0]
        else:
            root = ref @ st.roots[0]
        pose = Pose(root, st.angles)
        roots[i], angles[i] = root, st.angles
        joints3d[i] = body.joints(pose)
        for c, v in enumerate(views):
            cam = st.cameras[c]
            full = cam.scaled(1.0 / factors[v], sampling="resize") if factors[v] != 1.0 else cam
            joints2d[v][i] = full.project(body.joints(st.pose(c)))
            rep = reports.get(f)
            if c == 0:
                limb_fit.append({k: round(x, 3) for k, x in
                                 (getattr(rep, "limb_fit", None) or {}).items()})
                recovered.append(list(getattr(rep, "recovered", None) or []))
            if rep is not None:
                residual[v][i] = rep.residual[c]
                iou[i, c] = rep.iou[c]
                if rep.coverage is not None:
                    fit[i, c] = rep.coverage[c]
                if getattr(rep, "unexplained", None) is not None:
                    unexplained[i, c] = rep.unexplained[c]
    from ..body.collision import body_proxies, penetration

    proxies = body_proxies(body)
    overlap = np.array([penetration(proxies, body.seg2world(Pose(roots[i], angles[i]))).max()
                        if len(proxies.pairs) else 0.0 for i in range(F)])
    status = []
    res_all = np.array([[residual[v][i] for v in views] for i in range(F)])
    med = np.median(res_all[res_all > 0]) if np.any(res_all > 0) else 1.0
    for i, f in enumerate(order):
        if f in anchor_frames:
            status.append("ok")
            continue
        verdict = frame_status(fit[i] / ref_fit, iou[i] / ref_iou, res_all[i].max() / med,
                               limb_fit[i], unexplained[i] - ref_unexplained)
        # One view does not measure how far a limb reaches towards or away from it: a pose
        # whose outline fits may still be wrong in depth by 20 cm or more.
        status.append("uncertain" if verdict == "ok" and len(views) == 1 else verdict)
    fps = plates[views[0]].fps or 30.0
    body_info = {"template": body.template, "shapes": body.shapes,
                 "dims": {k: round(v, 5) for k, v in body.dims.items()},
                 "dof_names": list(body.dof_names)}
    extra = {"tracker": "differential", "anchors": [int(a) for a in anchor_frames],
             "silhouette_iou": np.round(np.nan_to_num(iou, nan=-1.0), 4).tolist(),
             "silhouette_fit": np.round(np.nan_to_num(fit, nan=-1.0), 4).tolist(),
             "cancelled": cancelled,
             "limb_overlap_mm": np.round(1000 * overlap, 2).tolist(),
             "limb_fit": limb_fit, "recovered_limbs": recovered,
             "unexplained": np.round(np.nan_to_num(unexplained, nan=-1.0), 4).tolist(),
             "unexplained_anchor": np.round(np.nan_to_num(ref_unexplained, nan=-1.0),
                                            4).tolist(),
             "warnings": list(init.warnings)}
    return TrackResult(mode="calibrated" if calibrated else "uncalibrated", fps=float(fps),
                       frames=np.array(order), joints3d=joints3d, joints2d=joints2d,
                       residual=residual, status=status, body=body_info, roots=roots,
                       angles=angles, extra=extra)
