"""Track a take: plates and markers in, a :class:`result.TrackResult` out.

The entry points of the trackers: :func:`track` (Bregler & Malik's differential tracker, the
default) and :func:`track_filter` (Sidenbladh, Black & Fleet's particle filter, alone or as the
coarse search of the hybrid). Each fits the anchors' poses to the markers
(:func:`initialize.run.initialize_take`, Bregler & Malik §2.6) unless given them, and runs the take
through the one driver (:func:`take.driver.run_take`) with its tracker's stepper.
"""

from ..errors import ZoopraxisError
from ..initialize.options import InitOptions
from ..trackers.filter_stepper import ParticleStepper
from ..trackers.hybrid import HybridStepper
from ..trackers.stepper import DifferentialStepper
from .driver import check_take, run_take
from .passes import BLEND_REACH
from .workers import default_workers

FILTER_TRACKERS = {"particle": ParticleStepper, "hybrid": HybridStepper}


def track(plates, anchors, cameras=None, *, frames=None, offsets=None, settings=None,
          init=None, max_size=960, progress=None, cancel=None, log=None, workers=1,
          blend_reach=BLEND_REACH, init_options=None):
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
    init : InitResult, optional
        Starting poses; by default fitted to the markers (:func:`initialize.run.initialize_take`
        with ``init_options``).
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
    init_options : InitOptions, optional
        How to initialize from the markers when ``init`` is not given (template, flips, pose
        prior, body lengths, camera tilt, perspective); default ``InitOptions()``. The
        perspective fitted to uncalibrated views is tracked through.

    Returns
    -------
    TrackResult
    """
    views, offsets, frames, inside = check_take(plates, anchors, cameras, frames, offsets)
    log = log or (lambda msg: None)

    if init is None:
        from ..initialize.run import initialize_take

        init = initialize_take(inside, views, plates, cameras, init_options or InitOptions(),
                               log)
    return run_take(DifferentialStepper(settings), plates, cameras, init, views, offsets, frames,
                    inside, max_size=max_size, progress=progress, cancel=cancel, log=log,
                    workers=workers, blend_reach=blend_reach)


def track_filter(plates, anchors, cameras=None, *, tracker="hybrid", particles=2000, seed=2345,
                 frames=None, offsets=None, max_size=960, progress=None, cancel=None,
                 log=None, init=None, settings=None, prior="general", recentre=None,
                 prior_scale=None, layers=None, silhouette=None, blend_reach=BLEND_REACH,
                 init_options=None, motion_model=None):
    """Track a take with the particle filter, alone or as the coarse stage of the hybrid.

    Parameters
    ----------
    plates : dict of str to Plate
        One plate per view, in view order.
    anchors : list of markers.Anchor
    cameras : dict of str to PinholeCamera
        One per view. Required: for uncalibrated plates use :func:`track`.
    tracker : {"particle", "hybrid"}
    particles, seed, prior, prior_scale, layers, silhouette, settings, motion_model
        The filter's (:class:`trackers.filter_stepper.ParticleStepper`); the same inputs and
        seed give the same track.
    recentre : float, optional
        Hybrid: share of the particles drawn again around each refined pose, 0 to 1 (default
        :data:`trackers.hybrid.RECENTRE`).
    frames, offsets, max_size, progress, cancel, log, blend_reach
        As :func:`track`.
    init : InitResult, optional
        Starting poses; by default fitted to the markers (:func:`initialize.run.initialize_take`
        with ``init_options``).
    init_options : InitOptions, optional
        As :func:`track` (calibrated views: the camera tilt does not apply, perspective is
        refused).

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
                   layers=layers, silhouette=silhouette, settings=settings,
                   motion_model=motion_model)
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
        from ..initialize.run import initialize_take

        init = initialize_take(inside, views, plates, cameras, init_options or InitOptions(),
                               log)
    return run_take(stepper, plates, cameras, init, views, offsets, frames, inside,
                    max_size=max_size, progress=progress, cancel=cancel, log=log,
                    blend_reach=blend_reach)


__all__ = ["track", "track_filter", "default_workers", "FILTER_TRACKERS"]
