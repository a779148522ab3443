"""Track a take: plates and markers in, a :class:`result.TrackResult` out.

The entry points of the trackers: :func:`track` (Bregler & Malik's differential tracker, the
default) and :func:`track_filter` (Sidenbladh, Black & Fleet's particle filter, alone or as the
coarse search of the hybrid). Each fits the anchors' poses to the markers
(:func:`initialize.initialize`, Bregler & Malik §2.6) unless given them, and runs the take
through the one driver (:func:`take.driver.run_take`) with its tracker's stepper.
"""

from dataclasses import dataclass, field

from ..errors import ZoopraxisError
from ..initialize.fit import CAMERA_TILT_DEG
from ..trackers.filter_stepper import ParticleStepper
from ..trackers.hybrid import HybridStepper
from ..trackers.stepper import DifferentialStepper
from .driver import check_take, run_take
from .passes import BLEND_REACH
from .workers import default_workers

FILTER_TRACKERS = {"particle": ParticleStepper, "hybrid": HybridStepper}


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
    return run_take(DifferentialStepper(settings), plates, cameras, init, views, offsets, frames,
                    inside, max_size=max_size, progress=progress, cancel=cancel, log=log,
                    workers=workers, blend_reach=blend_reach)


def track_filter(plates, anchors, cameras=None, *, tracker="hybrid", particles=2000, seed=2345,
                 frames=None, offsets=None, template="full", max_size=960, progress=None,
                 cancel=None, log=None, init=None, settings=None, prior="smooth",
                 recentre=None, prior_scale=None, layers=None, silhouette=None,
                 blend_reach=BLEND_REACH, flips=None, pose_prior="default", dims=None):
    """Track a take with the particle filter, alone or as the coarse stage of the hybrid.

    Parameters
    ----------
    plates : dict of str to Plate
        One plate per view, in view order.
    anchors : list of markers.Anchor
    cameras : dict of str to PinholeCamera
        One per view. Required: for uncalibrated plates use :func:`track`.
    tracker : {"particle", "hybrid"}
    particles, seed, prior, prior_scale, layers, silhouette, settings
        The filter's (:class:`trackers.filter_stepper.ParticleStepper`); the same inputs and
        seed give the same track.
    recentre : float, optional
        Hybrid: share of the particles drawn again around each refined pose, 0 to 1 (default
        :data:`trackers.hybrid.RECENTRE`).
    frames, offsets, max_size, progress, cancel, log, blend_reach
        As :func:`track`.
    init : Initial, optional
        Starting poses; by default fitted to the markers with :func:`initialize.initialize`.
    template, flips, pose_prior, dims : optional
        When ``init`` is not given: the initialization's (:func:`track`).

    Returns
    -------
    TrackResult
        With ``spread``: the filter's posterior standard deviation per pose parameter and frame
        (zero at the anchors' given poses); ``extra`` holds the filter's own per-frame status
        and effective sample size.
    """
    if tracker not in FILTER_TRACKERS:
        raise ZoopraxisError(f"unknown tracker '{tracker}' (expected one of "
                             f"{', '.join(FILTER_TRACKERS)})")
    options = dict(particles=particles, seed=seed, prior=prior, prior_scale=prior_scale,
                   layers=layers, silhouette=silhouette, settings=settings)
    if tracker == "hybrid" and recentre is not None:
        options["recentre"] = recentre
    stepper = FILTER_TRACKERS[tracker](**options)
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
    if init is None:
        from ..initialize.fit import initialize

        res = initialize(inside, {v: cameras[v] for v in views}, template=template,
                         calibrated=True, views=views, flips=flips, pose_prior=pose_prior,
                         dims=dims, fit_dims=not dims)
        for note in res.flip_notes():
            log(note)
        init = Initial(res.body, res.poses, res.cameras, None, list(getattr(res, "warnings", [])))
    return run_take(stepper, plates, cameras, init, views, offsets, frames, inside,
                    max_size=max_size, progress=progress, cancel=cancel, log=log,
                    blend_reach=blend_reach)


__all__ = ["track", "track_filter", "Initial", "default_workers", "FILTER_TRACKERS"]
