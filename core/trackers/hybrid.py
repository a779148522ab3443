"""Particle filter and hybrid trackers over a take: plates and markers in, a TrackResult out.

Bregler & Malik's differential tracker converges from a close enough start, but "may be expected
to fail when the motion from frame to frame is very large"; they propose to put "an initial
coarse search stage" in front of it (§5). Sidenbladh, Black & Fleet's particle filter is such a
search: it draws poses from a temporal prior and weighs them by the image (§4.1), so it follows
motions beyond the basin of a Gauss-Newton step; but a few thousand samples in 35 dimensions
land centimetres from the likelihood's peak, and its expected pose drifts. The two trackers:

- ``particle``: the particle filter alone (:class:`particle.ParticleFilter`, smooth-motion prior
  §6.1 by default), one filter step per frame; the expected pose is the answer and the
  posterior's spread its uncertainty.
- ``hybrid``: the coarse search, then the refinement, every frame:

  1. the filter steps, its prior drawn :data:`SEARCH_SPREAD` times wider than alone
     (precision is the refinement's job), and proposes its expected pose;
  2. a partitioned search (:func:`partitioned_search`) moves the proposal one limb at a time to
     the best of a few hundred draws under the filter's likelihood: the likelihood is a product
     over limbs (eq. 12), so each limb is found in its own few dimensions, where the filter's
     joint draws over all 35 rarely get every limb right at once;
  3. the differential tracker refines from there (:class:`GuidedTracker`), its weak pull
     towards the prediction still aimed at its own constant-velocity prediction, so that what
     the images hardly see (the pelvis inside the body, depth) stays smooth;
  4. the refined pose goes back into the filter (:meth:`particle.ParticleFilter.recentre`: a
     share of the particles is drawn again around it, with its velocity, and it becomes the
     estimate the next appearance is mapped on, eq. 2), so the search and the refinement follow
     one track.

Where the background model gives a foreground mask, the filter's likelihood adds a silhouette
cue (:data:`SILHOUETTE`, see :mod:`likelihood`), and each frame's status also says how the pose
sits in the foreground (:func:`coverage_status`): a pose that leaves foreground uncovered, or
has a limb mostly off it, is "uncertain" or "lost" even where the refinement fits the image
motion. The filter alone (``particle``) runs partitioned annealing layers
(:class:`particle.ParticleFilter`, ``layers``).

The take runs from anchor to anchor as in :func:`track.track` (forward and backward passes
between anchors, blended; backward before the first anchor, forward after the last), with the
same working resolution, background model, silhouette status and result layout. Both trackers
need calibrated cameras: the filter's likelihood projects through perspective cameras.
"""

import dataclasses
import itertools

import numpy as np

from ..geometry import se3
from ..imaging.background import model_coverage, silhouette_iou
from ..body.body import Pose
from .differential import DifferentialTracker, Settings, State, StepReport, prepare_images
from ..errors import ZoopraxisError
from .image_motion import accumulate
from ..priors.motion_prior import SmoothMotionPrior, smooth_sigmas
from ..priors.walking import WalkingPrior
from .particle import ParticleFilter
from ..imaging.plates import to_gray_float
from ..take.track import (BLEND_REACH, Cancelled, FrameSource, Initial, blend_report, blend_states,
                    blend_weights, check_take, extend_passes, make_result, plan_passes,
                    remeasure, silhouette_measures, take_backgrounds, tracked_backgrounds)

TRACKERS = ("particle", "hybrid")
PRIORS = ("smooth", "walk")

# Share of the filter's particles drawn again around the refined pose after each hybrid step:
# enough that the refinement steers the search, few enough that the filter keeps hypotheses the
# refinement did not take.
RECENTRE = 0.5

# The hybrid's filter draws the smooth-motion prior's position noise this many times wider than
# the filter alone: the refinement brings the precision, the search must reach the limb that
# moved furthest (on fast walking, 2 to 4 times track alike, 1 worse).
SEARCH_SPREAD = 3.0


class GuidedTracker(DifferentialTracker):
    """The differential tracker, started from a proposal instead of its own prediction.

    Set :attr:`proposal` (a :class:`differential.State`) before :meth:`step`: the Gauss-Newton
    iterations start there. The step's weak pull towards its prediction (``prior_weight``,
    decisive only for what the images do not determine) goes to :attr:`centre` when that is
    set, else to the proposal. Without a proposal the tracker predicts by constant velocity, as
    the base class does.
    """

    proposal = None
    centre = None

    def predict(self, state, previous=None):
        if self.proposal is not None:
            return self.proposal.copy()
        return super().predict(state, previous)

    def _difference(self, target, state):
        # step() pulls towards its prediction through this difference only.
        return super()._difference(target if self.centre is None else self.centre, state)


# Search widths per frame at 30 fps (standard deviations): pelvis position (m), root rotation,
# trunk and neck angles, leg angles, arm angles (rad). About the largest frame-to-frame change
# of each in the CMU jumps and brisk walk, beyond the constant-velocity prediction.
SEARCH_WIDTHS = {"root": (0.03, 0.06), "trunk": 0.08, "leg": 0.15, "arm": 0.2}


def search_groups(body, fps=30.0):
    """Pose parameters searched together, and their search widths.

    Parameters
    ----------
    body : BodyModel
    fps : float
        Frame rate of the plates (widths scale with the time between frames).

    Returns
    -------
    groups : list of (array of int, array of float)
        Parameter indices (ordered as :func:`motion_prior.param_names`) and their standard
        deviations per frame: the root, the trunk and head, then each leg and each arm, parents
        before children.
    """
    k = 30.0 / fps
    position, rotation = SEARCH_WIDTHS["root"]
    groups = [(np.arange(6), k * np.array([position] * 3 + [rotation] * 3))]
    parts = [(("lumbar", "thorax", "neck"), SEARCH_WIDTHS["trunk"])]
    for side in "lr":
        parts.append(((f"{side}_hip", f"{side}_knee", f"{side}_ankle"), SEARCH_WIDTHS["leg"]))
    for side in "lr":
        parts.append(((f"{side}_shoulder", f"{side}_elbow"), SEARCH_WIDTHS["arm"]))
    for prefixes, width in parts:
        cols = [6 + i for i, name in enumerate(body.dof_names) if name.startswith(prefixes)]
        if cols:
            groups.append((np.array(cols), np.full(len(cols), k * width)))
    return groups


def partitioned_search(pf, pose, groups, n, rng):
    """Move a pose one group of parameters at a time to the best of ``n`` draws.

    Partitioned sampling (MacCormick & Isard): the likelihood multiplies over limbs (eq. 12),
    so one limb can be searched with the rest of the body held. For each group in turn, ``n``
    poses are drawn around the current one in that group's parameters only (the current pose
    is the first draw), weighed by the filter's likelihood
    (:meth:`particle.ParticleFilter.score`), and the best is kept. A few hundred draws in four
    dimensions find a limb that a few thousand in 35 miss.

    Parameters
    ----------
    pf : ParticleFilter
        After :meth:`~particle.ParticleFilter.step` on the frame searched.
    pose : Pose
        Where the search starts (the filter's expected pose).
    groups : list of (array of int, array of float)
        From :func:`search_groups`.
    n : int
        Draws per group.
    rng : numpy.random.Generator

    Returns
    -------
    Pose
    """
    body = pf.body
    root, angles = np.array(pose.root, float), np.array(pose.angles, float)
    for cols, width in groups:
        delta = np.zeros((n, 6 + body.n_dofs))
        delta[1:, cols] = rng.normal(size=(n - 1, len(cols))) * width
        roots = np.repeat(root[None], n, axis=0)
        roots[:, :3, 3] += delta[:, :3]
        # Rotation increments on the left, in world axes (motion_prior's convention).
        roots[:, :3, :3] = se3.exp_so3(delta[:, 3:6]) @ root[:3, :3]
        trial = body.clamp(angles + delta[:, 6:])
        best = int(np.argmax(pf.score(roots, trial)))
        root, angles = roots[best], trial[best]
    return Pose(root, angles)


# Likelihood options of the trackers' filter: the silhouette cue (see :mod:`likelihood`) is on
# wherever the background model gives a foreground mask; the appearance alone drifts.
SILHOUETTE = 3.0

# Status from the silhouette: a pose that covers this much less of the drawn foreground pixels
# than the first anchor's pose did is "uncertain", twice as much "lost"; and a limb with less
# than this share of its points on the foreground is "uncertain", half of it "lost".
COVERAGE_DROP = 0.15
LIMB_ON_FOREGROUND = 0.5


def coverage_status(covered, reference, limb_share=np.nan, drop=COVERAGE_DROP,
                    limb_min=LIMB_ON_FOREGROUND):
    """Status of a frame from how its pose sits in the foreground.

    Two failures: limbs that slid off the body onto the background (their points leave the
    foreground), and limbs that slid onto the body from where they were (the foreground they
    left is no longer covered).

    Parameters
    ----------
    covered, reference : float
        The frame's covered share and the anchor's (NaN: not measured).
    limb_share : float
        The smallest share of a limb's points on the foreground (NaN: not measured).
    drop, limb_min : float

    Returns
    -------
    {"ok", "uncertain", "lost"}
    """
    status = "ok"
    if np.isfinite(covered) and np.isfinite(reference):
        if covered < reference - 2 * drop:
            return "lost"
        if covered < reference - drop:
            status = "uncertain"
    if np.isfinite(limb_share):
        if limb_share < 0.5 * limb_min:
            return "lost"
        if limb_share < limb_min:
            status = "uncertain"
    return status


def _worse(a, b):
    order = ("ok", "uncertain", "lost")
    return order[max(order.index(a), order.index(b))]


def track(plates, anchors, cameras=None, *, tracker="hybrid", particles=2000, seed=2345,
          frames=None, offsets=None, template="full", max_size=960, progress=None, cancel=None,
          log=None, init=None, settings=None, prior="smooth", recentre=RECENTRE,
          prior_scale=None, layers=None, silhouette=None, blend_reach=BLEND_REACH, flips=None,
          pose_prior="default", dims=None):
    """Track a take with the particle filter, alone or as the coarse stage of the hybrid.

    Parameters
    ----------
    plates : dict of str to Plate
        One plate per view, in view order.
    anchors : list of markers.Anchor
    cameras : dict of str to PinholeCamera
        One per view. Required: for uncalibrated plates use :func:`track.track`.
    tracker : {"particle", "hybrid"}
    particles : int
        Particles of the filter.
    seed : int
        Seeds every random draw: the same inputs give the same track.
    frames : range, optional
        Take frames to track (default: all frames the plates share).
    offsets : dict of str to int, optional
        Per-view plate frame offset (take frame f is plate frame f + offset).
    template : str
        Body template of the initialization from the markers.
    max_size : int
        Longest side of the working images, pixels.
    progress : callable(done, total), optional
    cancel : callable() -> bool, optional
        Polled once a frame; on cancel the frames already tracked are returned.
    log : callable(str), optional
    init : track.Initial, optional
        Starting poses; by default fitted to the markers with :func:`initialize.initialize`.
    settings : differential.Settings, optional
        The refinement's settings (hybrid) and the image preparation's.
    prior : {"smooth", "walk"}
        The filter's temporal prior: smooth motion (§6.1, any motion) or the learned walking
        cycle (§6.2).
    recentre : float
        Hybrid: share of the particles drawn again around each refined pose, 0 to 1.
    prior_scale : float, optional
        Scale of the smooth-motion prior's position noise; default 1 for the filter alone,
        :data:`SEARCH_SPREAD` for the hybrid (the walking prior keeps its own).
    layers : int, optional
        Annealing passes of the filter (:class:`particle.ParticleFilter`); default 2 for the
        filter alone, 0 for the hybrid (whose partitioned search does that work).
    silhouette : float, optional
        Weight of the likelihood's silhouette cue where a view has a background model (0:
        appearance only, as in the paper). Default :data:`SILHOUETTE` with the smooth prior,
        0 with the walking prior (there it made the hybrid's slow-walk test worse, 25 -> 40-54
        mm; on the jumps, smooth prior, it removes the frames over 100 mm: 30 -> 0).
    blend_reach : int or None
        Between two anchors, how many frames past the middle each pass tracks at first
        (:data:`track.BLEND_REACH`); None tracks both passes from anchor to anchor.
    flips, pose_prior : optional
        When ``init`` is not given, for anchor frames clicked in one view: the body parts
        turned to their other depth and the pose prior (:func:`initialize.initialize`).
    dims : dict, optional
        When ``init`` is not given: the performer's body lengths, kept instead of fitted.

    Returns
    -------
    TrackResult
        With ``spread``: the filter's posterior standard deviation per pose parameter and frame
        (zero at the anchors' given poses); ``extra`` holds the filter's own per-frame status
        and effective sample size.
    """
    if tracker not in TRACKERS:
        raise ZoopraxisError(f"unknown tracker '{tracker}' (expected one of "
                             f"{', '.join(TRACKERS)})")
    if prior not in PRIORS:
        raise ZoopraxisError(f"unknown motion prior '{prior}' (expected one of "
                             f"{', '.join(PRIORS)})")
    if isinstance(particles, bool) or int(particles) != particles or particles < 1:
        raise ZoopraxisError(f"the number of particles must be a positive whole number, "
                             f"got {particles!r}")
    if not 0 <= recentre <= 1:
        raise ZoopraxisError(f"recentre must be a share between 0 and 1, got {recentre}")
    if prior_scale is None:
        prior_scale = SEARCH_SPREAD if tracker == "hybrid" else 1.0
    if not prior_scale > 0:
        raise ZoopraxisError(f"prior_scale must be positive, got {prior_scale}")
    if layers is None:
        layers = 2 if tracker == "particle" else 0
    if silhouette is None:
        silhouette = SILHOUETTE if prior == "smooth" else 0.0
    if cameras is None:
        raise ZoopraxisError(f"the {tracker} tracker needs a calibration (its likelihood "
                             "projects through perspective cameras); for uncalibrated plates "
                             "use --tracker differential")
    views, offsets, frames, inside = check_take(plates, anchors, cameras, frames, offsets)
    for v in views:
        if not hasattr(cameras[v], "K"):
            raise ZoopraxisError(f"view '{v}': the {tracker} tracker needs a perspective "
                                 "camera")
    log = log or (lambda msg: None)
    settings = settings or Settings()
    if "limb_search" in {f.name for f in dataclasses.fields(settings)}:
        # The partitioned search is the hybrid's own limb search; the differential tracker's
        # silhouette search after the refinement undoes it (brisk walk: 27 -> 59 mm).
        settings = dataclasses.replace(settings, limb_search=False)

    if init is None:
        from ..initialize.fit import initialize

        res = initialize(inside, {v: cameras[v] for v in views}, template=template,
                         calibrated=True, views=views, flips=flips, pose_prior=pose_prior,
                         dims=dims, fit_dims=not dims)
        for note in res.flip_notes():
            log(note)
        init = Initial(res.body, res.poses, res.cameras, None, list(getattr(res, "warnings", [])))
    for w in init.warnings:
        log(f"warning: {w}")
    body = init.body
    fps = plates[views[0]].fps or 30.0

    factors = {v: min(1.0, max_size / max(plates[v].image_size)) for v in views}
    source = FrameSource(plates, views, offsets, factors)
    work_cams = [cameras[v].scaled(factors[v], sampling="resize") if factors[v] != 1.0
                 else cameras[v] for v in views]

    def state_of(pose):
        return State(np.stack([pose.root] * len(views)), pose.angles.copy(), list(work_cams))

    def state_at(frame):
        return state_of(init.poses[frame])

    if tracker == "particle":
        # No refinement: the images are prepared only to measure the residual, at one level.
        settings = dataclasses.replace(settings, levels=1, iterations=settings.iterations[-1:])
    diff = GuidedTracker(body, True, settings)
    backgrounds, use_bg, ref_fit, ref_iou, ref_unexplained = take_backgrounds(
        diff, source, views, frames, inside, state_at, log)

    def masks(colour):
        """Each view's foreground and the same without cast shadows (None: no background)."""
        fg = [backgrounds[c].foreground(img) if use_bg[c] else None
              for c, img in enumerate(colour)]
        return fg, [None if m is None else backgrounds[c].person(img, m)
                    for c, (img, m) in enumerate(zip(colour, fg))]

    def images(colour, fg, person):
        return [prepare_images(to_gray_float(img), settings.levels, settings.smooth_sigma,
                               fg[c], backgrounds[c].known if use_bg[c] else None, person[c])
                for c, img in enumerate(colour)]

    def make_prior():
        if prior == "walk":
            return WalkingPrior(body, fps=fps)
        sigma_position, _ = smooth_sigmas(body, fps)
        # The filter alone must follow accelerations through its layers' moves.
        return SmoothMotionPrior(body, fps=fps, sigma_position=prior_scale * sigma_position,
                                 carry_moves=tracker == "particle")

    anchor_frames = [a.frame for a in inside]
    passes, total = plan_passes(anchor_frames, frames, blend_reach)
    done = 0
    seeds = iter(range(seed, seed + 7919 * (len(passes) * 2 + 1), 7919))
    # The search draws as many poses as the filter has particles, shared among the groups.
    groups = search_groups(body, fps)
    search_n = max(2, particles // len(groups))
    # Each pass draws its search samples from its own generator (the first pass's is the
    # take's): passes between two anchors advance in turn.
    search_rngs = (np.random.default_rng(seed + 1 if k == 0 else [seed + 1, k])
                   for k in itertools.count())

    def run(start, stop):
        """Track from anchor ``start`` towards ``stop`` (inclusive), either direction: a
        generator of (frame, (state, step report, spread, filter status, effective sample size,
        silhouette cover)), the anchor frame first, one frame tracked per item."""
        nonlocal done
        step = 1 if stop > start else -1
        st = state_at(start)
        colour = source.colour(start)
        fg, person = masks(colour)
        ims = images(colour, fg, person)
        renders = diff.render_views(st)
        diff.set_anchor(st, ims, renders)
        anchor_terms = diff.anchor_terms     # this pass's: another may set its own meanwhile
        search_rng = next(search_rngs)
        prev = None
        pf = ParticleFilter(body, work_cams, make_prior(), n_particles=particles,
                            seed=next(seeds), layers=layers, silhouette=silhouette)
        first = pf.start(colour, st.pose(0))
        pf.likelihood.set_foreground(person)
        reference = covered_at(pf, st.pose(0))
        yield start, (st, None, first.spread, "ok", first.ess, reference)
        for f in range(start + step, stop + step, step):
            if cancel is not None and cancel():
                raise Cancelled()
            colour = source.colour(f)
            fg, person = masks(colour)
            ims1 = images(colour, fg, person)
            fs = pf.step(colour, person)
            diff.anchor_terms = anchor_terms
            if tracker == "particle":
                new = state_of(fs.pose)
                rep = _measure(diff, st, ims, ims1, new, renders)
            else:
                found = partitioned_search(pf, fs.pose, groups, search_n, search_rng)
                # Start at what the search found; pull (weakly) towards the smooth prediction.
                diff.centre = diff.predict(st, prev)
                diff.proposal = state_of(found)
                new, rep = diff.step(st, ims, ims1, None, renders)
                diff.proposal = diff.centre = None
                velocity = {"previous": st.pose(0)} if prior == "smooth" else {}
                pf.recentre(new.pose(0), recentre, **velocity)
            covered, limb_share = silhouette_fit(pf, new.pose(0))
            status = coverage_status(covered, reference, limb_share)
            if tracker == "particle":
                status = _worse(status, fs.status)
            elif fs.status == "lost":
                # The refinement fits the images, but the search behind it lost the body.
                status = _worse(status, "uncertain")
            prev, st, ims, renders = st, new, ims1, rep.renders
            rep.renders = None      # full-size images: keep them only for the next step
            done += 1
            if progress is not None:
                progress(done, total)
            yield f, (new, rep, fs.spread, status, fs.ess, covered)

    def advance(frames_of_pass, out, until):
        """Take a pass's frames into ``out`` up to frame ``until``."""
        while until not in out:
            f, item = next(frames_of_pass)
            out[f] = item

    def blended_fit(state, frame):
        """Silhouette fit and overlap of a blended pose, measured anew."""
        return silhouette_measures(diff, state, source.colour(frame), backgrounds, use_bg)

    tracked = {}
    cancelled = False
    parts = []      # every pass's frames so far: kept on a cancel
    try:
        for a, b, stretch in passes:
            fwd = {}
            parts.append(fwd)
            if stretch is None:
                advance(run(a, b), fwd, b)
                for f, item in fwd.items():
                    tracked.setdefault(f, item)
                continue
            bwd = {}
            parts.append(bwd)
            lo, hi = stretch
            forward, backward = run(a, b), run(b, a)
            advance(forward, fwd, hi)
            advance(backward, bwd, lo)
            to_f, to_b = extend_passes({f: item[1] for f, item in fwd.items() if f != a},
                                       {f: item[1] for f, item in bwd.items() if f != b},
                                       lo, hi, blend_reach)
            if (to_f, to_b) != (hi, lo):
                log(f"frames {a}-{b}: a pass goes on where the other lost the body")
                total += to_f - hi + lo - to_b
                advance(forward, fwd, to_f)
                advance(backward, bwd, to_b)
            tracked.setdefault(a, fwd[a])
            tracked.setdefault(b, bwd[b])
            both = [f for f in range(a + 1, b) if f in fwd and f in bwd]
            weights = blend_weights([fwd[f][1] for f in both], [bwd[f][1] for f in both])
            for f, w in zip(both, weights):
                (sf, rf, pf_, *_), (sb, rb, pb, *_) = fwd[f], bwd[f]
                state = blend_states(sf, sb, w)
                near = fwd[f] if w < 0.5 else bwd[f]
                tracked[f] = (state, blend_report(rf, rb, w, blended_fit(state, f)),
                              (1 - w) * pf_ + w * pb, near[3], near[4], near[5])
            # frames only one pass tracked
            for part in (fwd, bwd):
                for f, item in part.items():
                    tracked.setdefault(f, item)
    except Cancelled:
        cancelled = True
        for part in parts:
            for f, item in part.items():
                tracked.setdefault(f, item)
        log("cancelled: keeping the frames tracked so far")
    for a in anchor_frames:
        tracked.setdefault(a, (state_at(a), None, None, "ok", float(particles), np.nan))
    if not cancelled and any(use_bg):
        # each frame's status against backgrounds with the tracked body kept out of them
        states = {f: item[0] for f, item in tracked.items()}
        ref_fit, ref_iou, ref_unexplained = remeasure(
            diff, source, states, {f: item[1] for f, item in tracked.items()}, anchor_frames,
            tracked_backgrounds(diff, source, views, frames, states, use_bg), use_bg,
            limbs=True)

    result = make_result(body, views, plates, factors,
                          {f: item[0] for f, item in tracked.items()},
                          {f: item[1] for f, item in tracked.items()}, True, init,
                          anchor_frames, frames, cancelled, ref_fit, ref_iou, ref_unexplained)
    order = [int(f) for f in result.frames]
    filter_status = [tracked[f][3] for f in order]
    # At an anchor the pose is given: no spread (the filter's initial cloud is its own choice).
    P = 6 + body.n_dofs
    result.spread = np.array([np.zeros(P) if f in anchor_frames or tracked[f][2] is None
                              else tracked[f][2] for f in order])
    for i, f in enumerate(order):
        if f in anchor_frames:
            continue
        # The filter's verdict and whether the pose still covers the silhouette (the
        # refinement can fit the image motion of limbs that left it).
        result.status[i] = _worse(result.status[i], filter_status[i])
    result.extra.update({"tracker": tracker, "particles": int(particles), "seed": int(seed),
                         "motion_prior": prior, "filter_status": filter_status,
                         "effective_sample_size": [round(float(tracked[f][4]), 1)
                                                   for f in order],
                         "silhouette_covered": [None if not np.isfinite(tracked[f][5])
                                                else round(float(tracked[f][5]), 3)
                                                for f in order],
                         "layers": int(layers), "silhouette": float(silhouette)})
    if tracker == "hybrid":
        result.extra.update({"recentre": float(recentre), "prior_scale": float(prior_scale)})
    return result


def covered_at(pf, pose):
    """Share of the frame's drawn foreground pixels a pose's limbs cover (NaN: no masks)."""
    seg2world = pf.kinematics.seg2world(pose.root[None], pose.angles[None])
    return float(pf.likelihood.coverage_of(seg2world)[0])


def silhouette_fit(pf, pose):
    """How a pose sits in the foreground of the frame the filter last weighed.

    Returns
    -------
    covered : float
        Share of the drawn foreground pixels its limbs cover (NaN: no masks).
    limb_share : float
        The smallest share of a limb's compared points that fall on the foreground (NaN: no
        masks).
    """
    result = pf.measure(pose.root[None], pose.angles[None])
    share = result.on_foreground[0]
    limb = float(np.nanmin(share)) if np.any(np.isfinite(share)) else float("nan")
    return float(result.covered[0]), limb


def _measure(diff, state_t, images_t, images_t1, state_t1, renders_t):
    """Image evidence of a pose the differential tracker did not find.

    The residual is the differential tracker's own: the mean absolute grey difference (0-255)
    between frame t's model pixels and where the pose at t+1 moves them in frame t+1
    (brightness constancy, Bregler & Malik eq. 3), so that both trackers report in one unit;
    the silhouette fit and overlap are taken against the foreground mask.
    """
    V = len(state_t.cameras)
    flow = diff.template_terms(state_t, images_t, renders_t)[0]
    renders = diff.render_views(state_t1)
    residual = np.zeros(V)
    iou = np.full(V, np.nan)
    coverage = np.full(V, np.nan)
    for c in range(V):
        acc = accumulate(flow[c], images_t1[c].stacks[0], state_t1.cameras[c],
                         diff.body.seg2world(state_t1.pose(c)), diff.body.n_segments,
                         robust=False)
        if acc.inside.any():
            residual[c] = 255.0 * np.mean(np.abs(acc.residual[acc.inside]))
        if images_t1[c].foreground is not None:
            model = renders[c].label >= 0
            iou[c] = silhouette_iou(model, images_t1[c].foreground)
            coverage[c] = model_coverage(model, images_t1[c].foreground)
    return StepReport(residual, iou, 0.0, 0, renders, coverage)


__all__ = ["track", "GuidedTracker", "partitioned_search", "search_groups", "coverage_status",
           "covered_at", "silhouette_fit", "TRACKERS", "PRIORS", "RECENTRE", "SEARCH_SPREAD",
           "SEARCH_WIDTHS", "SILHOUETTE", "COVERAGE_DROP", "LIMB_ON_FOREGROUND"]
