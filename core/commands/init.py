"""``zoopraxis init``: pose, angles and body dimensions from the clicked joints (markers.json)."""

import argparse
import json
import sys

from .common import (add_camera_tilt_argument, add_dims_argument, add_flip_argument,
                     add_output_arguments,
                     add_perspective_argument, add_pose_prior_arguments, check_output,
                     check_template, parse_init_options)


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis init",
        description="Fit the body model to the clicked joints of the anchor frames: root pose, "
                    "joint angles and body dimensions (Bregler & Malik §2.6). Without "
                    "--calibration every view gets a scaled orthographic camera per anchor.")
    p.add_argument("--markers", required=True, help="markers.json with the clicked joints")
    p.add_argument("--calibration", default=None,
                   help="calibration.json or Pose2Sim / anipose TOML (default: uncalibrated)")
    p.add_argument("--plate", action="append", metavar="NAME=PATH", required=True,
                   help="a view: video file or folder of images (repeat for every view)")
    p.add_argument("--template", default="full",
                   help="body template: full, muybridge, sidenbladh or yamamoto (full)")
    p.add_argument("--fixed-dims", action="store_true",
                   help="keep the template's body dimensions instead of fitting them")
    add_dims_argument(p)
    add_pose_prior_arguments(p)
    add_flip_argument(p)
    add_camera_tilt_argument(p)
    add_perspective_argument(p)
    add_output_arguments(p, "init.json")
    return p


def main(argv):
    from ..body.body import LENGTH_DIMS
    from ..files.calibfile import cameras_for_plates, check_views, read_calibration
    from .calibrate import parse_plate_options
    from .common import open_plates
    from ..initialize.run import initialize_take
    from ..files.markers import check_markers, read_markers
    from ..files.outputs import write_text
    from ..files.plausible import check_calibration

    args = build_parser().parse_args(argv)
    out = check_output(args.out, args.force, inputs=[
        ("--markers", args.markers), ("--calibration", args.calibration),
        ("--dims-from", args.dims_from), ("--pose-prior", args.pose_prior),
        ("--proportions-prior", args.proportions_prior),
        *((f"--plate {view}", path) for view, path in parse_plate_options(args.plate).items())])
    check_template(args.template)
    options = parse_init_options(args, bool(args.calibration), fit_dims=not args.fixed_dims)
    dims = options.dims
    plates = open_plates(parse_plate_options(args.plate))
    views = list(plates)
    anchors = read_markers(args.markers)
    check_markers(anchors, views, min(p.num_frames for p in plates.values()), args.markers,
                  image_sizes={v: p.image_size for v, p in plates.items()})
    if args.calibration:
        cameras = check_views(read_calibration(args.calibration), views, args.calibration)
        cameras, notes = cameras_for_plates(
            cameras, {v: p.image_size for v, p in plates.items()}, args.calibration)
        for note in notes:
            print(f"note: {note}")
        for warning in check_calibration(cameras, anchors, args.calibration):
            print(f"warning: {warning}")
    else:
        cameras = None
    mode = "calibrated" if args.calibration else "uncalibrated"
    print(f"init: fitting {len(anchors)} anchor frame{'s' if len(anchors) > 1 else ''} in "
          f"{len(views)} view{'s' if len(views) > 1 else ''} ({mode})", file=sys.stderr,
          flush=True)
    # the notes are printed below, after the lengths and click errors
    result = initialize_take(anchors, views, plates, cameras, options)
    print("body dimensions (m): " + ", ".join(f"{name} {result.body.dims[name]:.3f}"
                                             for name in LENGTH_DIMS)
          + (f" (kept from {args.dims_from})" if dims else ""))
    print("rms per view (px): " + ", ".join(f"{view} {rms:.2f}"
                                           for view, rms in result.rms.items()))
    if args.perspective:
        print(result.distance_note())
    for warning in result.warnings:
        print(f"warning: {warning}")
    for note in result.flip_notes():
        print(note)
    for note in result.notes:
        print(f"note: {note}")
    if result.ambiguous:
        print("warning: the 3D pose is ambiguous (see above)")
    for frame, parts in sorted(result.ambiguous_parts.items()):
        options = " ".join(f"--flip {frame}:{p.replace(' ', '-')}" for p in parts)
        print(f"frame {frame}: look at the fitted body; if it is wrong there, run again with "
              f"{options}")
    write_text(out, json.dumps(result.to_json(), indent=1) + "\n")
    print(f"wrote {out}")
    return 0
