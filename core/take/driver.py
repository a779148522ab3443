"""The one take driver: every tracker runs a take through :func:`run_take`.

A tracker is a stepper (:class:`trackers.stepper.Stepper`): it starts a pass at an anchor's
pose and steps it one frame at a time, state and prepared images in, state and a report of
per-view measures out. Everything else is written here once, for every tracker: the working
resolution, the background models, the passes between anchors (:mod:`take.passes`), running
them in turn or in worker processes (:mod:`take.workers`), progress and cancel, blending two
passes, a second round with backgrounds that know where the tracked body was, and each frame's
status (:mod:`take.status`).

Working images are the plates scaled so that their longer side is at most ``max_size`` pixels;
results are reported in the plates' own pixels.
"""

import threading
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ZoopraxisError
from ..files.markers import check_markers
from ..geometry import se3
from ..geometry.ortho import ScaledOrthoCamera
from ..trackers.differential import State
from ..trackers.frames import thread_pool
from .backgrounds import anchor_references, remeasure, take_backgrounds, tracked_backgrounds
from .passes import BLEND_REACH, blend_states, blend_weights, extend_passes, plan_passes
from .status import blend_report, make_result, silhouette_measures
from .workers import (Cancelled, _can_fork, _Later, _run_in_processes, _run_in_turn,
                      default_cores)


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


class _Resume:
    """Where a pass that goes on stopped: the frame, the pose before it and the pose at it,
    and the pass itself where it can go on as it is (``live``: passes run in turn by a stepper
    whose passes hold more than a pose, see :attr:`trackers.stepper.Stepper.continues`).
    Hashable by identity, so that a job holding it keys the results."""

    __slots__ = ("frame", "before", "state", "live")

    def __init__(self, frame, before, state, live=None):
        self.frame, self.before, self.state, self.live = frame, before, state, live


class _Measure:
    """A job that measures the silhouettes of blended poses (:func:`track`'s
    ``blended_fit``) at ``frames``. Hashable by identity, as :class:`_Resume`."""

    __slots__ = ("frames", "states")

    def __init__(self, frames, states):
        self.frames, self.states = frames, states


@dataclass
class Take:
    """What a stepper sees of the take it tracks (:meth:`trackers.stepper.Stepper.attach`).

    Attributes
    ----------
    body : BodyModel
    views : list of str
    calibrated : bool
    fps : float
    source : FrameSource
        Working-resolution colour frames.
    cameras : list of camera or None
        Calibrated: each view's camera at the working resolution.
    backgrounds : list of BackgroundModel or None
    use_bg : list of bool
        Whether a view's silhouettes are used.
    log : callable(str)
    """

    body: object
    views: list
    calibrated: bool
    fps: float
    source: FrameSource
    cameras: list
    backgrounds: list
    use_bg: list
    log: object


def anchor_states(init, views, cameras, factors):
    """``state_at(frame)``: the tracker's state at an anchor frame, from the initialization
    (working-resolution cameras; uncalibrated, each view's fitted camera at that frame)."""
    calibrated = cameras is not None

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

    return state_at


def pass_indices(passes):
    """Each pass's place in the plan: ``(anchor, direction) -> k`` (direction +1 forward, -1
    backward; one pass leaves an anchor each way), forward before backward between two
    anchors. A stepper that draws random numbers seeds each pass by it, so a pass draws the
    same whichever runs first."""
    order = []
    for a, b, stretch in passes:
        order.append((a, 1 if b > a else -1))
        if stretch is not None:
            order.append((b, -1))
    return {key: k for k, key in enumerate(order)}


def run_take(stepper, plates, cameras, init, views, offsets, frames, inside, *, max_size=960,
             progress=None, cancel=None, log=None, workers=1, blend_reach=BLEND_REACH):
    """Track a take with one stepper, from anchor to anchor.

    Parameters
    ----------
    stepper : trackers.stepper.Stepper
    plates : dict of str to Plate
    cameras : dict of str to camera or None
        Calibrated mode when given; uncalibrated otherwise.
    init : InitResult
        The anchors' poses.
    views, offsets, frames, inside
        From :func:`check_take`.
    max_size : int
        Longest side of the working images, pixels.
    progress : callable(done, total), optional
    cancel : callable() -> bool, optional
        Polled once a frame; on cancel the frames already tracked are returned.
    log : callable(str), optional
    workers : int
        Processes for the passes (1: in turn). Worker processes fork: on Linux outside the
        Blender application, and only for steppers whose passes can restart from a pose
        (:attr:`trackers.stepper.Stepper.forkable`).
    blend_reach : int or None
        Between two anchors, how many frames past the middle each pass tracks at first
        (:data:`take.passes.BLEND_REACH`); None tracks both passes from anchor to anchor.

    Returns
    -------
    TrackResult
    """
    calibrated = cameras is not None
    log = log or (lambda msg: None)
    for w in init.warnings:
        log(f"warning: {w}")
    if len(views) == 1:
        log("note: one view does not measure the depth of the limbs; the frames between "
            "anchors are reported uncertain at best")
    body = init.body
    fps = plates[views[0]].fps or 30.0

    factors = {v: min(1.0, max_size / max(plates[v].image_size)) for v in views}
    source = FrameSource(plates, views, offsets, factors)
    state_at = anchor_states(init, views, cameras, factors)
    work_cams = None
    if calibrated:
        work_cams = [cameras[v].scaled(factors[v], sampling="resize") if factors[v] != 1.0
                     else cameras[v] for v in views]
    tracker = stepper.prepare(body, calibrated, fps)

    # Background models from frames spread over the take; at the anchor frames the model's
    # (dilated) silhouette says where the person is, which keeps a slow mover out of it.
    backgrounds, use_bg, ref_fit, ref_iou, ref_unexplained = take_backgrounds(
        tracker, source, views, frames, inside, state_at, log)
    take = Take(body, views, calibrated, fps, source, work_cams, backgrounds, use_bg, log)
    stepper.attach(take)

    anchor_frames = [a.frame for a in inside]
    passes, first_total = plan_passes(anchor_frames, frames, blend_reach)
    index_of = pass_indices(passes)
    total = first_total
    anchor_poses = {a: state_at(a) for a in anchor_frames}
    spare_core = True
    live = {}       # job -> its pass, where passes run in turn and go on as they are

    def data_ahead(frame):
        """The next frame's prepared images (decoding, foreground, pyramids, distance images:
        OpenCV work that runs outside the GIL), made in a thread while this one is tracked when
        a core is spare; when every core runs a pass, the thread would only take turns with
        the tracking (measured: 4 % more CPU a frame), and they are made when asked for."""
        if spare_core:
            return thread_pool("frames", 1).submit(stepper.frame_data, frame)
        return _Later(stepper.frame_data, frame)

    def run(job, report, should_stop):
        """Track from anchor ``job[0]`` to frame ``job[1]`` (inclusive), either direction; a
        third item (:class:`_Resume`) is where an earlier part of the same pass stopped. A
        :class:`_Measure` job measures blended poses instead."""
        if isinstance(job, _Measure):
            return {f: blended_fit(st, f) for f, st in zip(job.frames, job.states)}
        start, stop = job[:2]
        step = 1 if stop > start else -1
        resume = job[2] if len(job) > 2 else None
        first = start if resume is None else resume.frame
        if resume is not None and resume.live is not None:
            tracking = resume.live
        else:
            tracking = stepper.begin(job, index_of[(start, step)], state_at(start),
                                     stepper.frame_data(start))
            if resume is not None:
                tracking.restart(resume.before, resume.state, stepper.frame_data(first))
        if stepper.continues:
            live[job] = tracking
        out = {}
        ahead = data_ahead(first + step) if first != stop else None
        for f in range(first + step, stop + step, step):
            if should_stop is not None and should_stop():
                raise Cancelled(out)
            data = ahead.result()
            ahead = data_ahead(f + step) if f != stop else None
            out[f] = tracking.step(data)
            report(1)
        return out

    def blended_fit(state, frame):
        """Silhouette fit and overlap of a blended pose, measured anew: they are not either
        pass's."""
        return silhouette_measures(tracker, state, source.colour(frame), backgrounds, use_bg,
                                   limbs=calibrated)

    part_of = {}        # job -> the pass (from anchor, to anchor) it belongs to

    def run_passes(round_index, rounds, before=0):
        """Track every pass of the take with the current background models (round
        ``round_index`` of ``rounds``, after ``before`` frames tracked in earlier rounds: for
        progress); returns the states and reports of every frame tracked and whether a cancel
        stopped it."""
        nonlocal spare_core, total
        total = first_total
        # before the worker processes of this round fork: they inherit what it sets
        stepper.round_begins(round_index, rounds)
        states, reports = dict(anchor_poses), dict.fromkeys(anchor_frames)
        # First the single passes and, between two anchors, each pass up to a little past the
        # middle; as soon as both of a pair are done, a pass whose partner lost the body on the
        # way goes on towards it.
        pairs = {(a, b): st for a, b, st in passes if st is not None}
        jobs = [(a, b) for a, b, st in passes if st is None]
        part_of.clear()
        live.clear()
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
                        # the part that stopped at ``at``: (a, hi) forward, (b, lo) backward
                        resume = _Resume(at, before, part[at][0],
                                         live.get((start, hi if start == a else lo)))
                        job = (start, to, resume)
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
        if workers > 1 and len(jobs) > 1 and stepper.forkable and _can_fork():
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
                    reports[f] = stepper.blend_report(
                        blend_report(fwd[f][1], bwd[f][1], w, fit), fwd[f][1], bwd[f][1], w)
            # frames only one pass tracked (or a pair cut short by a cancel): keep them all
            for part in (fwd, bwd):
                for f, (st, rep) in part.items():
                    if f not in states:
                        states[f], reports[f] = st, rep
        return states, reports, cancelled

    # Two rounds where the stepper asks for them (:meth:`trackers.stepper.Stepper.rounds`):
    # the first backgrounds know where the person is at the anchors only, and take a person
    # who stood still for a while for background there; the first round's track keeps the body
    # out of the second round's backgrounds.
    rounds = stepper.rounds(use_bg)
    states, reports, cancelled = run_passes(0, rounds)
    if cancelled:
        log("cancelled: keeping the frames tracked so far")
    elif rounds == 2:
        refined = tracked_backgrounds(tracker, source, views, frames, states, use_bg,
                                      anchor_frames)
        log("background: estimated again with the tracked body kept out of it; tracking again")
        first = states, reports
        backgrounds = [r if r is not None else b for r, b in zip(refined, backgrounds)]
        take.backgrounds = backgrounds
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
    elif stepper.remeasure and any(use_bg):
        # each frame's status against backgrounds with the tracked body kept out of them
        ref_fit, ref_iou, ref_unexplained = remeasure(
            tracker, source, states, reports, anchor_frames,
            tracked_backgrounds(tracker, source, views, frames, states, use_bg, anchor_frames),
            use_bg,
            limbs=calibrated)

    result = make_result(body, views, plates, factors, states, reports, calibrated, init,
                         anchor_frames, frames, cancelled, ref_fit, ref_iou, ref_unexplained)
    return stepper.finish(result, reports, anchor_frames)
