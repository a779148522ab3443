"""Adapter between the scene and the core workers: initialization, tracking, board calibration.

The workers are imported when a job runs, so registering the add-on stays light; each is called
with its own signature, and the options of an initialization travel as one
:class:`core.initialize.options.InitOptions`.

Everything here reads the scene on the main thread (:func:`gather`) and hands plain core objects
to the workers, which may then run on another thread: no bpy there.
"""

import os
from dataclasses import dataclass, field, replace

from ..core.errors import ZoopraxisError

# The last initialization per scene, kept for the tracker (InitResult is not scene data).
_initial = {}


@dataclass
class Take:
    """Everything a job needs from the scene, as core objects.

    Attributes
    ----------
    plates : dict of str to core.plates.Plate
    paths : dict of str to str
    offsets : dict of str to int
    anchors : list of core.markers.Anchor
    cameras : dict of str to PinholeCamera, or None when uncalibrated
    frames : range
    tracker : str
    num_frames : int
    fps : float
    init_options : core.initialize.options.InitOptions
        The panel's template, depth flips (of anchor frames), camera tilt, pose prior file,
        body lengths kept from a file and near cameras.
    """

    plates: dict
    paths: dict
    offsets: dict
    anchors: list
    cameras: dict
    frames: range
    tracker: str
    num_frames: int
    fps: float = 30.0
    extra: dict = field(default_factory=dict)
    init_options: object = None

    def close(self):
        for plate in self.plates.values():
            plate.close()

    def options_at(self, anchors):
        """``init_options`` with the depth flips of these anchors' frames only."""
        frames = {a.frame for a in anchors}
        flips = {f: p for f, p in (self.init_options.flips or {}).items() if f in frames}
        return replace(self.init_options, flips=flips or None)


def gather(context, *, need_markers=True):
    """Read the take off the scene and check it, before any job starts.

    Raises
    ------
    ZoopraxisError
        No plates, an unreadable plate, views of different lengths, no or too few markers (a
        joint marked in no view), a calibrated view without a camera, a bad frame range.
    """
    from ..core.commands.common import read_dims
    from ..core.files.markers import check_markers, only_views, uncalibrated_views
    from ..core.files.plausible import check_calibration
    from ..core.imaging.plates import check_same_length, open_plate
    from ..core.initialize.options import CAMERA_TILT_DEG, InitOptions
    from ..core.priors.pose import resolve_pose_prior
    from ..core.priors.proportions import ProportionsPrior
    from . import markers
    from .calibration import cameras_from_scene

    scene = context.scene
    settings = scene.zoopraxis
    views = [v for v in settings.views]
    if not views:
        raise ZoopraxisError("no plates loaded: load one plate per camera first")
    paths = {v.name: v.path for v in views}
    offsets = {v.name: v.offset for v in views}
    cameras = cameras_from_scene(context, required=False) or None
    plates = {}
    try:
        for v in views:
            if v.clip is None:
                raise ZoopraxisError(f"view '{v.name}': its movie clip was removed; load the "
                                     "plate again or remove the view")
            plates[v.name] = open_plate(v.path, name=v.name)
        n = check_same_length(plates, offsets)
        anchors = markers.read_anchors(settings)
        if need_markers:
            check_markers(anchors, list(plates), n, path="joint markers",
                          image_sizes={name: p.image_size for name, p in plates.items()})
            if cameras is not None:
                for warning in check_calibration(cameras, anchors, "the scene's cameras"):
                    print(f"zoopraxis: warning: {warning}", flush=True)
            else:
                kept, warnings = uncalibrated_views(anchors, list(plates), "joint markers")
                for warning in warnings:
                    print(f"zoopraxis: warning: {warning}", flush=True)
                for name in [name for name in plates if name not in kept]:
                    plates.pop(name).close()
                    paths.pop(name)
                    offsets.pop(name)
                anchors = only_views(anchors, kept)
                check_markers(anchors, kept, n, path="joint markers")
        if settings.use_frame_range:
            start, stop = settings.frame_range_start, settings.frame_range_end
            if not 0 <= start < stop <= n:
                raise ZoopraxisError(f"frame range {start}:{stop} is outside the take (0:{n})")
            frames = range(start, stop)
        else:
            frames = range(0, n)
    except BaseException:
        for plate in plates.values():
            plate.close()
        raise
    fps = scene.render.fps / scene.render.fps_base
    import bpy

    template = settings.template.lower()

    def read_file(field, hint, path, read):
        """``read(path, template)`` of a panel's file field (None when empty), now: a missing
        file, or one of another template, is refused before any job starts."""
        if not path:
            return None
        try:
            return read(path, template)
        except ZoopraxisError as ex:
            for plate in plates.values():
                plate.close()
            raise ZoopraxisError(f"{field}: {ex} ({hint})") from None

    pose_prior = bpy.path.abspath(settings.pose_prior_path) if settings.pose_prior_path else ""
    read_file("Pose Prior", "clear the field for the shipped prior", pose_prior,
              resolve_pose_prior)
    proportions = read_file(
        "Proportions Prior", "clear the field for the shipped prior",
        bpy.path.abspath(settings.proportions_prior_path)
        if settings.proportions_prior_path else "",
        lambda path, _: ProportionsPrior.load(path))
    dims = read_file("Body Lengths From", "clear the field to fit the lengths",
                     bpy.path.abspath(settings.dims_path) if settings.dims_path else "",
                     read_dims)
    anchor_frames = {a.frame for a in anchors}
    flips = {f: p for f, p in parse_flips(settings.depth_flips).items() if f in anchor_frames}
    options = InitOptions(template=template, flips=flips or None,
                          pose_prior=pose_prior or "default",
                          pose_basis="default" if settings.use_pose_basis else None, dims=dims,
                          camera_tilt=(float(settings.camera_tilt), CAMERA_TILT_DEG[1]),
                          perspective=cameras is None and settings.near_cameras,
                          proportions=proportions)
    return Take(plates, paths, offsets, anchors, cameras, frames, settings.tracker.lower(), n,
                fps, init_options=options)


def parse_flips(text):
    """``"80:left leg;80:body"`` -> ``{80: ["left leg", "body"]}`` (unreadable items are
    dropped: the text is the add-on's own)."""
    out = {}
    for item in str(text or "").split(";"):
        frame, _, part = item.partition(":")
        try:
            frame = int(frame)
        except ValueError:
            continue
        if part and part not in out.setdefault(frame, []):
            out[frame].append(part)
    return {f: p for f, p in out.items() if p}


def format_flips(flips):
    """The inverse of :func:`parse_flips`."""
    return ";".join(f"{f}:{p}" for f, parts in sorted(flips.items()) for p in parts)


def initialize(take, *, progress=None, cancel=None):
    """Fit the body to the markers (:func:`core.initialize.run.initialize_take`)."""
    from ..core.initialize.run import initialize_take

    if progress:
        progress(0, 1)
    inside = [a for a in take.anchors if a.frame in take.frames] or take.anchors
    result = initialize_take(inside, list(take.plates), take.plates, take.cameras,
                             take.options_at(inside))
    if progress:
        progress(1, 1)
    return result


def _fingerprint(take):
    """What an initialization depends on: template, calibration, the anchors' clicks and the
    animator's choices for one-view anchors (flips, camera tilt, pose prior file, pose basis),
    near uncalibrated views, the body lengths kept from a file and the proportions prior."""
    clicks = tuple((a.frame, v, j, round(u, 2), round(w, 2))
                   for a in take.anchors if a.frame in take.frames
                   for v, joints in sorted(a.views.items())
                   for j, (u, w) in sorted(joints.items()))
    cameras = None if take.cameras is None else tuple(
        (v, tuple(round(x, 6) for x in c.P.ravel())) for v, c in sorted(take.cameras.items()))
    options = take.init_options
    flips = tuple(sorted((f, tuple(p)) for f, p in (options.flips or {}).items()))
    tilt = round(float(options.camera_tilt[0]), 3) if take.cameras is None else None
    prior = None
    if options.pose_prior != "default":
        try:
            prior = (options.pose_prior, os.stat(options.pose_prior).st_mtime_ns)
        except OSError:
            prior = (options.pose_prior, None)
    dims = None if not options.dims else tuple(sorted(options.dims.items()))
    basis = options.pose_basis is not None and take.cameras is None
    proportions = None if options.proportions is None else \
        (tuple(options.proportions.subjects), options.proportions.lengths.tobytes())
    return options.template, cameras, clicks, flips, tilt, prior, dims, options.perspective, \
        basis, proportions


def remember_initial(scene, init, take):
    _initial[scene.name] = (_fingerprint(take), init)


def initial_for(scene, take):
    """The remembered initialization if it was made from this take's markers and cameras."""
    fingerprint, init = _initial.get(scene.name, (None, None))
    return init if init is not None and fingerprint == _fingerprint(take) else None


def forget(scene=None):
    if scene is None:
        _initial.clear()
    else:
        _initial.pop(scene.name, None)


def track(take, *, init=None, progress=None, cancel=None, log=None):
    """Track the take (:func:`core.take.track.track`, or the particle/hybrid trackers); without
    ``init`` the tracker initializes from the markers with the take's options."""
    options = dict(frames=take.frames, offsets=take.offsets, init=init, progress=progress,
                   cancel=cancel, log=log, init_options=take.options_at(
                       [a for a in take.anchors if a.frame in take.frames]))
    if take.tracker == "differential":
        from ..core.take.track import track as differential

        return differential(take.plates, take.anchors, take.cameras, **options)
    from ..core.take.track import track_filter

    return track_filter(take.plates, take.anchors, take.cameras, tracker=take.tracker,
                        **options)


class _ShiftedPlate:
    """A plate read in take frames: take frame ``f`` is plate frame ``f + offset``."""

    def __init__(self, plate, offset, num_frames):
        self.plate, self.offset, self.num_frames = plate, int(offset), int(num_frames)
        self.name, self.image_size = plate.name, plate.image_size

    def read(self, frame, **options):
        return self.plate.read(int(frame) + self.offset, **options)


def calibrate(take, board, *, step=1, world_frame=None, max_rms=None, progress=None,
              cancel=None):
    """Calibrate the cameras from a board seen in the plates (:func:`core.calibration.calibrate.calibrate`).

    The board is searched in the take's frames (every ``step``-th); the views are read in take
    frames, so their offsets line them up, and ``world_frame`` is a take frame too.

    Parameters
    ----------
    take : Take
    board : core.calibrate.Board
        From :func:`core.calibration.calibrate.parse_board`.
    step : int
    world_frame : int, optional
        Take frame whose board pose defines the world; default: the calibration's choice.
    max_rms : float, optional
        Refusal threshold of the reprojection RMS, pixels; default the core's.

    Returns
    -------
    result : core.calibrate.CalibrationResult
        ``cameras`` and ``rms`` by view name, ``world_frame``, ``warnings``.
    """
    from ..core.calibration.calibrate import calibrate as calibrate_plates

    plates = {v: _ShiftedPlate(p, take.offsets.get(v, 0), take.num_frames)
              for v, p in take.plates.items()}
    options = dict(step=step, world_frame=world_frame, progress=progress, cancel=cancel)
    if max_rms is not None:
        options["max_rms"] = max_rms
    return calibrate_plates(plates, board, take.frames, **options)
