"""The hybrid tracker: a particle filter's coarse search in front of the differential tracker.

Bregler & Malik's differential tracker converges from a close enough start, but "may be expected
to fail when the motion from frame to frame is very large"; they propose to put "an initial
coarse search stage" in front of it (§5). Sidenbladh, Black & Fleet's particle filter is such a
search: it draws poses from a temporal prior and weighs them by the image (§4.1), so it follows
motions beyond the basin of a Gauss-Newton step; but a few thousand samples in 35 dimensions
land centimetres from the likelihood's peak, and its expected pose drifts. The filter alone is
:class:`filter_stepper.ParticleStepper`; the hybrid (:class:`HybridStepper`) does, every frame:

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

The filter's silhouette cue and the coverage status are the filter stepper's
(:mod:`filter_stepper`); the take (passes, blending, backgrounds, status) is the take driver's
(:func:`take.driver.run_take`). It needs calibrated cameras: the filter's likelihood projects
through perspective cameras.
"""

import numpy as np

from ..body.body import Pose
from ..errors import ZoopraxisError
from ..geometry import se3
from .differential import DifferentialTracker
from .filter_stepper import ParticleStepper, worse

# Share of the filter's particles drawn again around the refined pose after each hybrid step:
# enough that the refinement steers the search, few enough that the filter keeps hypotheses the
# refinement did not take.
RECENTRE = 0.5

# The hybrid's filter draws the smooth-motion prior's position noise this many times wider than
# the filter alone: the refinement brings the precision, the search must reach the limb that
# moved furthest (on fast walking, 2 to 4 times track alike, 1 worse). The general prior's
# learned noise is already as wide as the captures' motion and is not widened (synthetic
# walks, 300 particles, two seeds: 13 and 27 mm at 1 and 1.5, 19-26 and 32-41 at 3).
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


class HybridStepper(ParticleStepper):
    """The coarse search, then the refinement, every frame (see the module's docstring).

    Parameters as :class:`filter_stepper.ParticleStepper`, and
    recentre : float
        Share of the particles drawn again around each refined pose, 0 to 1.
    prior_scale : float, optional
        Default :data:`SEARCH_SPREAD` with the smooth prior, 1 with the general prior.
    layers : int, optional
        Default 0: the partitioned search does the annealing layers' work.
    settings : differential.Settings, optional
        The refinement's settings.
    """

    name = "hybrid"
    default_prior_scale = SEARCH_SPREAD
    default_layers = 0

    def __init__(self, particles=2000, seed=2345, prior="general", recentre=RECENTRE,
                 prior_scale=None, layers=None, silhouette=None, settings=None,
                 motion_model=None):
        if not 0 <= recentre <= 1:
            raise ZoopraxisError(f"recentre must be a share between 0 and 1, got {recentre}")
        super().__init__(particles, seed, prior, prior_scale, layers, silhouette, settings,
                         motion_model)
        self.recentre = recentre

    def tracker_settings(self, settings):
        return settings

    def make_tracker(self, body):
        return GuidedTracker(body, True, self.settings)

    def prepare(self, body, calibrated, fps):
        tracker = super().prepare(body, calibrated, fps)
        # The search draws as many poses as the filter has particles, shared among the groups.
        self.groups = search_groups(body, fps)
        self.search_n = max(2, self.particles // len(self.groups))
        return tracker

    def refine(self, tracking, found, data):
        diff, pf = self.diff, tracking.pf
        best = partitioned_search(pf, found.pose, self.groups, self.search_n,
                                  tracking.search_rng)
        # Start at what the search found; pull (weakly) towards the smooth prediction.
        diff.centre = diff.predict(tracking.state, tracking.previous)
        diff.proposal = self.state_of(best)
        new, report = diff.step(tracking.state, tracking.images, data.images, None,
                                tracking.renders)
        diff.proposal = diff.centre = None
        # The priors with velocities start the fresh particles at the refined motion.
        velocity = {"previous": tracking.state.pose(0)} if self.prior != "walk" else {}
        pf.recentre(new.pose(0), self.recentre, **velocity)
        return new, report

    def combine(self, status, filter_status):
        # The refinement fits the images, but the search behind it lost the body.
        return worse(status, "uncertain") if filter_status == "lost" else status

    def finish(self, result, reports, anchor_frames):
        result = super().finish(result, reports, anchor_frames)
        result.extra.update({"recentre": float(self.recentre),
                             "prior_scale": float(self.prior_scale)})
        return result


__all__ = ["HybridStepper", "GuidedTracker", "partitioned_search", "search_groups",
           "RECENTRE", "SEARCH_SPREAD", "SEARCH_WIDTHS"]
