"""What a tracker is to the take driver: a stepper, and the differential tracker as one.

The driver (:func:`take.driver.run_take`) owns the take: passes between anchors, workers,
progress, cancel, blending, background models and each frame's status. A tracker only says how
to prepare a frame's images, how to start a pass at an anchor's pose and how to step it:

- :meth:`Stepper.prepare` makes the per-frame tracker whose renders also measure silhouettes;
- :meth:`Stepper.attach` hands it the take (:class:`take.driver.Take`: background models,
  working cameras) once these exist;
- :meth:`Stepper.frame_data` prepares a frame (in a thread, while the frame before is tracked);
- :meth:`Stepper.begin` starts a pass at an anchor and returns it; the pass's ``step(data)``
  gives the next frame's state and report, ``restart(before, state, data)`` puts a pass that
  runs on (in another process) at the pose where it stopped;
- :meth:`Stepper.blend_report` and :meth:`Stepper.finish` add what is the tracker's own to the
  blended frames' reports and to the result.
"""


import numpy as np

from ..imaging.plates import to_gray_float
from ..priors.general import MotionModel
from .differential import DifferentialTracker, Settings
from .frames import prepare_images


class Stepper:
    """The tracker side of a take; subclasses fill in :meth:`prepare`, :meth:`frame_data` and
    :meth:`begin`.

    Attributes
    ----------
    name : str
        The tracker's name in the result.
    forkable : bool
        Passes may run in forked worker processes: a pass that goes on after another restarts
        from its last two poses (``restart``). False where a pass holds more than its poses (a
        particle cloud): its passes run in turn.
    continues : bool
        A pass that goes on is the same object, stepped further (passes run in turn).
    remeasure : bool
        Tracked in one round with silhouettes, each frame's status is measured again against
        backgrounds with the tracked body kept out of them.
    """

    name = "stepper"
    forkable = True
    continues = False
    remeasure = False

    def prepare(self, body, calibrated, fps):
        """Make and return the per-frame tracker (a :class:`differential.DifferentialTracker`:
        the driver renders the model through it to measure silhouettes)."""
        raise NotImplementedError

    def attach(self, take):
        """Keep the take (:class:`take.driver.Take`) for :meth:`frame_data` and the passes."""
        self.take = take

    def rounds(self, use_bg):
        """How many rounds the take is tracked in (2: again with backgrounds estimated with the
        first round's body kept out of them)."""
        return 1

    def round_begins(self, index, rounds):
        """Round ``index`` of ``rounds`` (:meth:`rounds`) is about to be tracked."""

    def frame_data(self, frame):
        """Everything a step needs of one frame: its prepared images."""
        raise NotImplementedError

    def begin(self, job, index, state, data):
        """Start a pass at its anchor.

        Parameters
        ----------
        job : tuple
            ``(start, stop[, resume])``: where the pass starts, where this part of it ends.
        index : int
            The pass's place in the take's plan (:func:`take.driver.pass_indices`).
        state : differential.State
            The anchor's pose.
        data : object
            :meth:`frame_data` of the anchor frame.

        Returns
        -------
        object with ``step(data) -> (state, report)`` and ``restart(before, state, data)``
        """
        raise NotImplementedError

    def blend_report(self, blended, forward, backward, w):
        """Add what is the tracker's own to the report of a frame blended from two passes
        (``blended``, made by the driver; ``w``: 0 -> forward); return it."""
        return blended

    def finish(self, result, reports, anchor_frames):
        """Add what is the tracker's own to the result; return it."""
        return result


class DifferentialStepper(Stepper):
    """Bregler & Malik's differential tracker (:class:`differential.DifferentialTracker`).

    Tracked in two rounds where two views or more have silhouettes: the first backgrounds know
    where the person is at the anchors only, and take a person who stood still for a while for
    background there. (One view, where no limb search runs and the outline leaves the depth
    free, tracked walk131_single worse in two rounds: 202 mm PA against 145.)
    """

    name = "differential"

    def __init__(self, settings=None):
        self.settings = settings or Settings()
        self.tracker = None

    def prepare(self, body, calibrated, fps):
        self.tracker = DifferentialTracker(body, calibrated, self.settings)
        self.tracker.search.frame_rate(fps)
        if calibrated and self.settings.learned_carry:
            self.tracker.angle_carry, self.tracker.root_carry = learned_carry(
                body, fps, self.settings.velocity)
        if calibrated and self.settings.pose_space_weight > 0:
            # Calibrated only: on the real side-on walk (sports2d, one uncalibrated view, a
            # panning camera whose background model explains little) the pull shortened the
            # stride, the legs drawn together under the body where the walker's were spread
            # (frames called lost 8 -> 24, benchmarks/bench_real.py).
            self.tracker.pose_space = PoseSpacePull(body, self.settings.pose_space_weight)
        return self.tracker

    def rounds(self, use_bg):
        return 2 if sum(use_bg) >= 2 else 1

    def round_begins(self, index, rounds):
        # The first of two rounds tracks the body to keep it out of the next round's
        # backgrounds: the limb search's broad draws, its dearest part, wait for the last.
        if self.tracker.search is not None:
            self.tracker.search.broad = index == rounds - 1

    def frame_data(self, frame):
        take, settings = self.take, self.settings
        colours = take.source.colour(frame)

        def one(c):
            if not take.use_bg[c]:
                return prepare_images(to_gray_float(colours[c]), settings.levels,
                                      settings.smooth_sigma, colour=colours[c])
            bg = take.backgrounds[c]
            fg = bg.foreground(colours[c])
            return prepare_images(to_gray_float(colours[c]), settings.levels,
                                  settings.smooth_sigma, fg, bg.known, bg.person(colours[c], fg),
                                  colours[c])

        return self.tracker.map_views(one, len(colours))

    def begin(self, job, index, state, data):
        # each pass draws its own search samples: the same result whichever runs first
        if self.tracker.search is not None:
            self.tracker.search.reseed(job[:2] if len(job) == 2 else (*job[:2], job[2].frame))
        return _DifferentialPass(self.tracker, state, data)


def learned_carry(body, fps, velocity):
    """How much of their last change the legs' angles and the pelvis keep in the differential
    tracker's prediction (see :meth:`differential.DifferentialTracker.predict`).

    The legs' angles (hips, knees, ankles) and the pelvis's translation keep the share of
    their velocity that captured performers' keep from one frame to the next
    (:class:`general.MotionModel` ``damping`` and ``root_damping``: 0.6-0.87 for the legs,
    0.93-0.99 for the pelvis at 30 fps; a heavy body's momentum); every other angle and the
    pelvis's turn keep ``velocity``. With one half for everything, a walker's pelvis and
    swinging legs lagged by half a frame's stride and were fitted from the wrong place; with
    the learned carry of the arms, trunk and turn too, the dance and swordplay got worse
    (``benchmarks/README.md``).

    Returns
    -------
    angle_carry : array, shape (n_dofs,)
    root_carry : array, shape (6,)
        Per world axis, ``tx ty tz rx ry rz``.
    """
    model = MotionModel.load()
    power = model.fps / fps
    rows, cols = model.shared_dofs(body.dof_names)
    legs = np.array([body.dof_names[i][2:].startswith(("hip", "knee", "ankle")) for i in rows],
                    bool)
    angle_carry = np.full(body.n_dofs, float(velocity))
    angle_carry[rows[legs]] = model.damping[cols[legs]] ** power
    root_carry = np.full(6, float(velocity))
    root_carry[:3] = model.root_damping[:3] ** power
    return angle_carry, root_carry


class PoseSpacePull:
    """The pull of the differential tracker's angles towards the pose space learned
    from capture (:class:`general.MotionModel`: the probabilistic PCA of captured poses).

    One view measures the limbs across its line of sight and leaves their depth free: a hip's
    abduction and turn, a shoulder's, move the knee, foot or elbow towards the camera at little
    cost in the image. The step's weak pull towards the prediction keeps whatever depth the
    last frames drifted to: over walk131_single the feet and elbows wandered 0.1-0.3 m in depth
    while their images stayed within 10-15 px. The pose space's Gaussian is weak along the ways
    people move and strong across them, so in the directions the image leaves free it draws
    the limbs back to poses people make. It is part of the step's cost (a step must lower the
    image cost and the pull together) and scaled like the pull towards the prediction:
    ``weight`` times the median data curvature of the angles, negligible where the image
    measures them. Two calibrated views or more get a fifth of it
    (``Settings.pose_space_views``, :meth:`DifferentialTracker._step`): they measure the limbs'
    depth, but a pelvis turned about the vertical with both hips turned back shows little in
    any outline. Uncalibrated views get none (:meth:`DifferentialStepper.prepare`).

    Parameters
    ----------
    body : BodyModel
    weight : float
        The pull's median curvature over the data's (``Settings.pose_space_weight``).
    """

    def __init__(self, body, weight):
        self.mean, self.precision = MotionModel.load().pose_space(body.dof_names)
        self.weight = float(weight)
        self._median_precision = float(np.median(np.diag(self.precision)))

    def system(self, angles, diag, angle_cols):
        """``(W, g, cost)``: the curvature and gradient of ``|angles - mean|^2_W`` over all
        parameters, in the units of the data's normal equations (half the cost's), and the
        function ``cost(angles)``.

        Parameters
        ----------
        angles : array, shape (n_dofs,)
        diag : array, shape (P,)
            The diagonal of the data's normal equations at ``angles``.
        angle_cols : array of int
            The angles' columns among the P parameters.
        """
        data = float(np.median(diag[angle_cols]))
        Wa = self.precision * (self.weight * (data + 1e-12) / (self._median_precision + 1e-12))
        W = np.zeros((len(diag), len(diag)))
        W[np.ix_(angle_cols, angle_cols)] = Wa
        g = np.zeros(len(diag))
        g[angle_cols] = Wa @ (angles - self.mean)

        def cost(a):
            x = a - self.mean
            return float(x @ Wa @ x)

        return W, g, cost


class _DifferentialPass:
    """One pass of the differential tracker: the last two poses, images and renders."""

    def __init__(self, tracker, state, images):
        self.tracker = tracker
        self.renders = tracker.render_views(state)
        tracker.set_anchor(state, images, self.renders)
        self.previous, self.state, self.images = None, state, images

    def restart(self, before, state, images):
        self.previous, self.state, self.images = before, state, images
        self.renders = self.tracker.render_views(state)

    def step(self, images):
        new, report = self.tracker.step(self.state, self.images, images, self.previous,
                                        self.renders)
        self.previous, self.state, self.images, self.renders = (self.state, new, images,
                                                                report.renders)
        report.renders = None       # full-size images: keep them only for the next step
        return new, report


__all__ = ["Stepper", "DifferentialStepper", "learned_carry", "PoseSpacePull"]
