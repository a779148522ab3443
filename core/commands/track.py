"""``zoopraxis track``: plates and markers in, result.json out (DESIGN, Command line)."""

import argparse
import time

from .common import (add_camera_tilt_argument, add_dims_argument, add_flip_argument,
                     add_output_arguments,
                     add_perspective_argument, add_pose_prior_arguments, check_output,
                     open_plates, parse_init_options, parse_view_values)
from ..errors import ZoopraxisError
from ..progress import ConsoleProgress

TRACKERS = ("differential", "particle", "hybrid")


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis track",
        description="Track an articulated body through synchronized plates, starting from the "
                    "joints clicked in markers.json, and write result.json.")
    p.add_argument("--plate", action="append", required=True, metavar="VIEW=PATH",
                   help="a plate: video file or image folder (repeat for each view)")
    p.add_argument("--markers", required=True, help="markers.json with the clicked joints")
    p.add_argument("--calibration", help="calibration.json or Pose2Sim/anipose TOML; without it "
                                         "the uncalibrated (scaled orthographic) mode runs")
    p.add_argument("--frames", help="START:END plate frames, END excluded (default: all)")
    p.add_argument("--tracker", choices=TRACKERS, default="differential")
    p.add_argument("--offset", action="append", metavar="VIEW=N",
                   help="plate frame offset of a view that starts later (repeatable)")
    p.add_argument("--template", default="full", help="body template (default full)")
    p.add_argument("--fps", type=float, help="frame rate of image-folder plates (default 30)")
    p.add_argument("--max-size", type=int, default=960,
                   help="longest side of the working images, pixels (default 960)")
    p.add_argument("--particles", type=int, default=2000,
                   help="particles of the particle and hybrid trackers (default 2000)")
    p.add_argument("--motion-prior", choices=("smooth", "walk", "general"),
                   help="how the particle and hybrid trackers predict the next frame: the "
                        "general prior learned from captures of any motion, how each joint "
                        "moves and which poses performers take "
                        "(core/priors/data/motion_prior.npz, the default), smooth motion of "
                        "every joint, or the walking prior learned from the walks of many "
                        "performers (core/priors/data/walk_prior.npz)")
    p.add_argument("--motion-model", metavar="FILE",
                   help="the general prior's model, learned by tools/learn_motion_prior.py "
                        "(default: the shipped one)")
    p.add_argument("--seed", type=int, default=2345)
    p.add_argument("--workers", type=int, default=0,
                   help="processes for the differential tracker's passes (a take with several "
                        "anchors has several); default: one per core, at most 4")
    p.add_argument("--refine-body", action="store_true",
                   help="after tracking, refine the limb lengths on the silhouettes and clicks "
                        "of the whole take and track again, keeping the better track "
                        "(differential tracker, calibrated views)")
    add_flip_argument(p)
    add_camera_tilt_argument(p)
    add_perspective_argument(p)
    add_pose_prior_arguments(p)
    add_dims_argument(p)
    add_output_arguments(p, "result.json")
    return p


def main(argv):
    from ..files import calibfile, markers
    from ..imaging import plates
    from ..files.plausible import check_calibration, check_working_size

    args = build_parser().parse_args(argv)
    paths = parse_view_values(args.plate, "--plate")
    out = check_output(args.out, args.force, inputs=[
        ("--markers", args.markers), ("--calibration", args.calibration),
        ("--dims-from", args.dims_from), ("--pose-prior", args.pose_prior),
        ("--proportions-prior", args.proportions_prior),
        ("--motion-model", args.motion_model),
        *((f"--plate {view}", path) for view, path in paths.items())])
    offsets = parse_view_values(args.offset, "--offset", int)
    unknown = [v for v in offsets if v not in paths]
    if unknown:
        raise ZoopraxisError(f"--offset names view '{unknown[0]}', which has no --plate")
    opened = open_plates(paths, fps=args.fps)
    n = plates.check_same_length(opened, offsets)
    frames = plates.parse_frame_range(args.frames, n)
    anchors = markers.read_markers(args.markers)
    sizes = {v: p.image_size for v, p in opened.items()}
    markers.check_markers(anchors, list(opened), n, path=args.markers, image_sizes=sizes)
    cameras = None
    if args.calibration:
        cameras = calibfile.check_views(calibfile.read_calibration(args.calibration),
                                        list(opened), args.calibration)
        cameras, notes = calibfile.cameras_for_plates(
            cameras, sizes, args.calibration)
        for note in notes:
            print(f"track: note: {note}", flush=True)
        for warning in check_calibration(cameras, anchors, args.calibration):
            print(f"track: warning: {warning}", flush=True)
    else:
        anchors = _placeable_views(opened, offsets, anchors, n, args.markers)
    for warning in check_working_size(anchors, sizes, args.max_size):
        print(f"track: warning: {warning}", flush=True)
    if args.workers < 0:
        raise ZoopraxisError(f"--workers {args.workers}: give 0 (one per core) or more")
    if args.motion_prior not in (None, "smooth") and args.tracker == "differential":
        raise ZoopraxisError(f"--motion-prior {args.motion_prior} works with --tracker particle "
                             "or hybrid only")
    if args.motion_model and (args.motion_prior not in (None, "general")
                              or args.tracker == "differential"):
        raise ZoopraxisError("--motion-model needs --motion-prior general (--tracker particle "
                             "or hybrid)")
    if args.refine_body and args.tracker != "differential":
        raise ZoopraxisError("--refine-body works with --tracker differential only")
    if args.refine_body and cameras is None:
        raise ZoopraxisError("--refine-body needs --calibration (calibrated views)")
    init_options = parse_init_options(args, cameras is not None)
    stop = _StopOnInterrupt()
    kwargs = dict(frames=frames, offsets=offsets, init_options=init_options,
                  max_size=args.max_size, progress=ConsoleProgress("track"), cancel=stop,
                  log=lambda msg: print(f"track: {msg}", flush=True))
    t0 = time.perf_counter()
    with stop:
        if args.tracker == "differential" and args.refine_body:
            from ..take.finetune import finetune

            result = finetune(opened, anchors, cameras, **kwargs).result
        elif args.tracker == "differential":
            from ..take.track import default_workers, track

            workers = args.workers or default_workers()
            result = track(opened, anchors, cameras, workers=workers, **kwargs)
        else:
            from ..take.track import track_filter

            result = track_filter(opened, anchors, cameras, tracker=args.tracker,
                                  particles=args.particles, seed=args.seed,
                                  prior=args.motion_prior or "general",
                                  motion_model=args.motion_model,
                                  **kwargs)
    _write_or_rescue(out, result, args.force)
    elapsed = time.perf_counter() - t0
    counts = {s: result.status.count(s) for s in ("ok", "uncertain", "lost")}
    print(f"track: {result.num_frames} frames in {elapsed:.1f} s "
          f"({result.num_frames / max(elapsed, 1e-9):.1f} frames/s): {counts['ok']} ok, "
          f"{counts['uncertain']} uncertain, {counts['lost']} lost -> {out}")
    if stop.requested:
        print(f"track: cancelled; the {result.num_frames} frames tracked are in {out}")
        return 130
    return 0


def _placeable_views(opened, offsets, anchors, num_frames, path):
    """Uncalibrated: leave out (with a warning) the plates of views with too few clicks at the
    first anchor to place their camera; returns the anchors of the views kept."""
    from ..files import markers

    kept, warnings = markers.uncalibrated_views(anchors, list(opened), path)
    for warning in warnings:
        print(f"track: warning: {warning}", flush=True)
    if len(kept) == len(opened):
        return anchors
    for view in [v for v in opened if v not in kept]:
        opened.pop(view).close()
        offsets.pop(view, None)
    anchors = markers.only_views(anchors, kept)
    markers.check_markers(anchors, kept, num_frames, path=path)
    return anchors


def _write_or_rescue(out, result, force):
    """Write result.json; when that fails after the work (a disk filled up meanwhile), keep
    the frames in a file of the system's temporary folder and name it in the error."""
    import os
    import tempfile

    from ..files.result import write_result

    try:
        write_result(out, result, force=force)
    except ZoopraxisError as error:
        handle, rescue = tempfile.mkstemp(prefix="zoopraxis-track-", suffix=".json")
        os.close(handle)
        try:
            write_result(rescue, result, force=True)
        except ZoopraxisError:
            os.unlink(rescue)
            raise error from None
        raise ZoopraxisError(f"{error}; the {result.num_frames} frames tracked are saved in "
                             f"{rescue}") from None


class _StopOnInterrupt:
    """Turn the first Ctrl-C into a polite stop (the tracker returns what it has done, and it
    is written); a second Ctrl-C interrupts at once."""

    def __init__(self):
        self.requested = False
        self._old = None

    def __call__(self):
        return self.requested

    def _handle(self, signum, frame):
        import signal

        self.requested = True
        print("track: stopping after this frame (Ctrl-C again to abort)", flush=True)
        signal.signal(signal.SIGINT, self._old or signal.default_int_handler)

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc):
        import signal
        import threading

        if self._old is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, self._old)
        return False
