"""The particle filter as a take's stepper: Sidenbladh, Black & Fleet's tracker over a take.

Each pass has its own filter (:class:`particle.ParticleFilter`), started at the anchor's pose
and stepped one frame at a time under a temporal prior (smooth motion §6.1, the learned
walking cycle §6.2, or the general motion prior learned from capture, :mod:`general`); its
expected pose is the answer and its posterior's spread the pose's uncertainty. The
differential tracker's images and renders measure the step's grey residual, so that both
trackers report in one unit. Where the background model gives a foreground mask, the
filter's likelihood adds a silhouette cue (:data:`SILHOUETTE`, see :mod:`likelihood`), and each
frame's status also says how the pose sits in the foreground (:func:`coverage_status`). In one
calibrated view the cue is stricter and the particles are weighed by the general prior's pose
space too (:meth:`ParticleStepper.filter_options`).

A pass holds its particle cloud, which a pose cannot restart: passes run in turn, and a pass
that goes on after another is the same filter stepped further. Every random draw is seeded by
the pass's place in the take's plan: the same inputs give the same track.

:class:`hybrid.HybridStepper` puts the differential tracker behind the filter.
"""

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import ZoopraxisError
from ..imaging.background import model_coverage, silhouette_iou
from ..imaging.plates import to_gray_float
from ..priors.motion_prior import SmoothMotionPrior, smooth_sigmas
from ..priors.general import GeneralMotionPrior, MotionModel
from ..priors.walking import WalkingPrior
from .differential import DifferentialTracker, Settings, State, StepReport
from .frames import prepare_images
from .image_motion import accumulate
from .particle import ParticleFilter
from .stepper import Stepper

PRIORS = ("smooth", "walk", "general")

# Likelihood options of the trackers' filter: the silhouette cue (see :mod:`likelihood`) is on
# wherever the background model gives a foreground mask; the appearance alone drifts.
SILHOUETTE = 3.0

# Status from the silhouette: a pose that covers this much less of the drawn foreground pixels
# than the first anchor's pose did is "uncertain", twice as much "lost"; and a limb with less
# than this share of its points on the foreground is "uncertain", half of it "lost".
COVERAGE_DROP = 0.15
LIMB_ON_FOREGROUND = 0.5

# Seeds of successive passes' filters are this far apart.
SEED_STRIDE = 7919

# One calibrated view: the weight of the general prior's pose density in the filter's weights
# (:class:`particle.ParticleFilter` ``pose_weight``; 1: the learned Gaussian as it is), and
# the likelihood's points along the limbs' axes that the silhouette cue checks, seen or not
# (``likelihood.ImageLikelihood`` ``axis_points``). See :meth:`ParticleStepper.one_view`.
ONE_VIEW_POSE_WEIGHT = 1.0
ONE_VIEW_AXIS_POINTS = 5


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


def worse(a, b):
    """The worse of two statuses."""
    order = ("ok", "uncertain", "lost")
    return order[max(order.index(a), order.index(b))]


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


def measure_step(diff, state_t, images_t, images_t1, state_t1, renders_t):
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


@dataclass
class FilterFrame:
    """One frame as a filter's step needs it: the colour images, the shadow-free foreground
    masks (None: no background), the differential tracker's prepared images, and for the
    filter's silhouette cue the foreground with what the background model cannot tell from
    the person (cast shadows, clothes the floor's shade, pixels it never saw free) and the
    pixels surely the person (shadow-free, where the background is known)."""

    colour: list
    person: list
    images: list
    foreground: list = None
    cover: list = None


class ParticleStepper(Stepper):
    """The particle filter alone, one filter step per frame.

    Parameters
    ----------
    particles : int
        Particles of the filter.
    seed : int
        Seeds every random draw.
    prior : {"general", "smooth", "walk"}
        The filter's temporal prior: the general motion prior's learned dynamics and pose
        space (any motion, :class:`general.GeneralMotionPrior`; the default), smooth motion
        (§6.1, any motion) or the learned walking cycle (§6.2). On the rendered benchmark
        sets, of performers it has not seen, the general prior is 26-85 mm closer after
        alignment than smooth motion with the filter alone and 0-18 mm with the hybrid
        (``benchmarks/README.md``).
    prior_scale : float, optional
        Scale of the smooth-motion or general prior's noise (default 1; the walking prior
        keeps its own).
    layers : int, optional
        Annealing passes of the filter (:class:`particle.ParticleFilter`); default 2.
    silhouette : float, optional
        Weight of the likelihood's silhouette cue where a view has a background model (0:
        appearance only, as in the paper). Default :data:`SILHOUETTE` with the smooth and
        general priors, 0 with the walking prior (there it made the hybrid's slow-walk test
        worse, 25 -> 40-54 mm; on the jumps, smooth prior, it removes the frames over 100 mm:
        30 -> 0).
    settings : differential.Settings, optional
        The image preparation's settings (one pyramid level: the images only measure the
        residual).
    motion_model : MotionModel or path, optional
        The general prior's learned model (default the shipped one).
    """

    name = "particle"
    forkable = False
    continues = True
    remeasure = True
    default_prior_scale = 1.0
    default_layers = 2

    def __init__(self, particles=2000, seed=2345, prior="general", prior_scale=None,
                 layers=None, silhouette=None, settings=None, motion_model=None):
        if prior not in PRIORS:
            raise ZoopraxisError(f"unknown motion prior '{prior}' (expected one of "
                                 f"{', '.join(PRIORS)})")
        if isinstance(particles, bool) or int(particles) != particles or particles < 1:
            raise ZoopraxisError(f"the number of particles must be a positive whole number, "
                                 f"got {particles!r}")
        if prior_scale is None:
            # The general prior's noise is learned, the captures' own change from frame to
            # frame: no tracker widens it.
            prior_scale = 1.0 if prior == "general" else self.default_prior_scale
        self.prior_scale = prior_scale
        if not self.prior_scale > 0:
            raise ZoopraxisError(f"prior_scale must be positive, got {prior_scale}")
        self.particles, self.seed, self.prior = int(particles), int(seed), prior
        self.layers = self.default_layers if layers is None else layers
        self.silhouette = (0.0 if prior == "walk" else SILHOUETTE) if silhouette is None \
            else silhouette
        # Read once here: every pass makes its own prior from it.
        self.motion_model = None if prior != "general" else motion_model \
            if isinstance(motion_model, MotionModel) else MotionModel.load(motion_model)
        settings = settings or Settings()
        if "limb_search" in {f.name for f in dataclasses.fields(settings)}:
            # The partitioned search is the hybrid's own limb search; the differential
            # tracker's silhouette search after the refinement undoes it (brisk walk: 27 -> 59
            # mm).
            settings = dataclasses.replace(settings, limb_search=False)
        self.settings = self.tracker_settings(settings)
        self.anchor_info = {}       # pass index -> (anchor frame, ess, covered share)

    def tracker_settings(self, settings):
        # No refinement: the images are prepared only to measure the residual, at one level.
        return dataclasses.replace(settings, levels=1, iterations=settings.iterations[-1:])

    def make_tracker(self, body):
        return DifferentialTracker(body, True, self.settings)

    def prepare(self, body, calibrated, fps):
        self.body, self.fps = body, fps
        self.diff = self.make_tracker(body)
        return self.diff

    def make_prior(self):
        if self.prior == "walk":
            return WalkingPrior(self.body, fps=self.fps)
        if self.prior == "general":
            return GeneralMotionPrior(self.body, self.motion_model, fps=self.fps,
                                      scale=self.prior_scale,
                                      carry_moves=self.name == "particle")
        sigma_position, _ = smooth_sigmas(self.body, self.fps)
        # The filter alone must follow accelerations through its layers' moves.
        return SmoothMotionPrior(self.body, fps=self.fps,
                                 sigma_position=self.prior_scale * sigma_position,
                                 carry_moves=self.name == "particle")

    def frame_data(self, frame):
        take, settings = self.take, self.settings
        colour = take.source.colour(frame)
        bgs, use = take.backgrounds, take.use_bg
        # each view's foreground and the same without cast shadows (None: no background)
        fg = [bgs[c].foreground(img) if use[c] else None for c, img in enumerate(colour)]
        person = [None if m is None else bgs[c].person(img, m)
                  for c, (img, m) in enumerate(zip(colour, fg))]
        images = [prepare_images(to_gray_float(img), settings.levels, settings.smooth_sigma,
                                 fg[c], bgs[c].known if use[c] else None, person[c])
                  for c, img in enumerate(colour)]
        if not self.one_view():
            return FilterFrame(colour, person, images, person, None)
        cover = [None if p is None else p & bgs[c].known if bgs[c].known is not None else p
                 for c, p in enumerate(person)]
        return FilterFrame(colour, person, images, fg, cover)

    def state_of(self, pose):
        cams = self.take.cameras
        return State(np.stack([pose.root] * len(cams)), pose.angles.copy(), list(cams))

    def begin(self, job, index, state, data):
        return _FilterPass(self, index, job[0], state, data)

    def one_view(self):
        """Whether the take has one view: the filter then leans on the silhouette and the
        pose space more (:meth:`filter_options`, :meth:`frame_data`)."""
        return len(self.take.cameras) == 1

    def pose_weight(self):
        """Weight of the pose space's density in the filter's weights: one view with the
        general prior only (see :data:`ONE_VIEW_POSE_WEIGHT`)."""
        return ONE_VIEW_POSE_WEIGHT if self.one_view() and self.prior == "general" else 0.0

    def filter_options(self):
        """The filter's options for this take's views.

        One view sees neither the depth of the limbs nor a limb that passes behind another:
        on walk131_single (a side view) the far leg, hidden as it crossed the near one, slid
        onto the background and stayed there, where its points matched the static background
        perfectly (the appearance is mapped at the estimate), and foreground the background
        model never saw free (where the person stood at the start) drew it further. So in one
        view a point off the foreground counts as the background's, every limb's axis must lie
        in the foreground seen or not (:data:`ONE_VIEW_AXIS_POINTS`), the coverage draws only
        pixels surely the person (:meth:`frame_data`), and the particles are weighed by the
        pose space's density (:meth:`pose_weight`). Several views see what one leaves free;
        there they are not measured to help (a two-view test of the filter tracking back
        from its first anchor went past its 50 mm bound, to 89), so they stay one view's.
        """
        one = self.one_view()
        return {"silhouette": self.silhouette, "pose_weight": self.pose_weight(),
                "axis_points": ONE_VIEW_AXIS_POINTS if one else 0, "background_points": one}

    def refine(self, tracking, found, data):
        """The frame's state and report from the filter's step (``found``)."""
        new = self.state_of(found.pose)
        return new, measure_step(self.diff, tracking.state, tracking.images, data.images, new,
                                 tracking.renders)

    def combine(self, status, filter_status):
        """The frame's status from the silhouette's and the filter's own."""
        return worse(status, filter_status)

    def blend_report(self, blended, forward, backward, w):
        near = forward if w < 0.5 else backward
        blended.spread = (1 - w) * forward.spread + w * backward.spread
        blended.filter_status, blended.ess, blended.covered = (near.filter_status, near.ess,
                                                               near.covered)
        return blended

    def finish(self, result, reports, anchor_frames):
        """The filter's spread, status and effective sample size in the result: at an anchor
        the pose is given (no spread; the first pass started there gives its sample size)."""
        order = [int(f) for f in result.frames]
        at_anchor = {}
        for index in sorted(self.anchor_info):
            frame, ess, covered = self.anchor_info[index]
            at_anchor.setdefault(frame, (ess, covered))
        P = 6 + self.body.n_dofs
        spread, filter_status, ess, covered = [], [], [], []
        for f in order:
            rep = reports.get(f)
            if f in anchor_frames or rep is None:
                e, cov = at_anchor.get(f, (float(self.particles), np.nan))
                spread.append(np.zeros(P))
                filter_status.append("ok")
                ess.append(e)
                covered.append(cov)
            else:
                spread.append(rep.spread)
                filter_status.append(rep.filter_status)
                ess.append(rep.ess)
                covered.append(rep.covered)
        result.spread = np.array(spread)
        for i, f in enumerate(order):
            if f in anchor_frames:
                continue
            # The filter's verdict and whether the pose still covers the silhouette (the
            # refinement can fit the image motion of limbs that left it).
            result.status[i] = worse(result.status[i], filter_status[i])
        result.extra.update({"tracker": self.name, "particles": self.particles,
                             "seed": self.seed, "motion_prior": self.prior,
                             "filter_status": filter_status,
                             "effective_sample_size": [round(float(e), 1) for e in ess],
                             "silhouette_covered": [None if not np.isfinite(c)
                                                    else round(float(c), 3) for c in covered],
                             "layers": int(self.layers), "silhouette": float(self.silhouette)})
        return result


class _FilterPass:
    """One pass: its filter, its search draws and the differential tracker's last images."""

    def __init__(self, stepper, index, start, state, data):
        diff = stepper.diff
        self.stepper = stepper
        self.state, self.previous, self.images = state, None, data.images
        self.renders = diff.render_views(state)
        diff.set_anchor(state, data.images, self.renders)
        self.anchor_terms = diff.anchor_terms   # this pass's: another may set its own meanwhile
        seed = stepper.seed
        self.search_rng = np.random.default_rng(seed + 1 if index == 0 else [seed + 1, index])
        self.pf = ParticleFilter(stepper.body, stepper.take.cameras, stepper.make_prior(),
                                 n_particles=stepper.particles,
                                 seed=seed + SEED_STRIDE * index, layers=stepper.layers,
                                 **stepper.filter_options())
        first = self.pf.start(data.colour, state.pose(0))
        self.pf.likelihood.set_foreground(data.foreground, data.cover)
        self.reference = covered_at(self.pf, state.pose(0))
        stepper.anchor_info[index] = (start, first.ess, self.reference)

    def restart(self, before, state, data):
        raise RuntimeError("a particle filter's pass goes on as it is; it cannot restart")

    def step(self, data):
        stepper = self.stepper
        found = self.pf.step(data.colour, data.foreground, data.cover)
        stepper.diff.anchor_terms = self.anchor_terms
        new, report = stepper.refine(self, found, data)
        covered, limb_share = silhouette_fit(self.pf, new.pose(0))
        status = stepper.combine(coverage_status(covered, self.reference, limb_share),
                                 found.status)
        self.previous, self.state, self.images, self.renders = (self.state, new, data.images,
                                                                report.renders)
        report.renders = None       # full-size images: keep them only for the next step
        report.spread, report.filter_status = found.spread, status
        report.ess, report.covered = found.ess, covered
        return new, report


__all__ = ["ParticleStepper", "coverage_status", "covered_at", "silhouette_fit", "worse",
           "measure_step", "PRIORS", "SILHOUETTE", "COVERAGE_DROP", "LIMB_ON_FOREGROUND"]
