"""``zoopraxis calibrate``: cameras from a checkerboard or ChArUco board seen in the plates."""

import argparse

from .common import add_output_arguments, check_output, open_plates, parse_view_values
from ..errors import ZoopraxisError
from ..progress import ConsoleProgress


def parse_plate_options(values):
    """``--plate NAME=PATH`` options as an ordered dict of view name to path."""
    paths = parse_view_values(values, "--plate")
    if not paths:
        raise ZoopraxisError("give at least one --plate NAME=PATH")
    return paths


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis calibrate",
        description="Calibrate the cameras of a take from a board seen in its plates: the lens "
                    "of each view, then where the views are, through frames where several see "
                    "the board at once. The board of the world frame must lie face up on the "
                    "floor: it defines world Z up, the floor z = 0 and the origin (its first "
                    "inner corner).")
    p.add_argument("--plate", action="append", metavar="NAME=PATH", required=True,
                   help="a view: video file or folder of images (repeat for every view)")
    p.add_argument("--board", required=True,
                   help="checkerboard:COLSxROWS:SQUARE_M (inner corners, e.g. 9x6:0.04) or "
                        "charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT] (squares)")
    p.add_argument("--frames", default=None, help="START:END, END excluded (default all)")
    p.add_argument("--step", type=int, default=1, help="search every N-th frame (default 1)")
    p.add_argument("--world-frame", type=int, default=None,
                   help="frame whose board lies on the floor (default: the first frame seen by "
                        "the most cameras)")
    p.add_argument("--max-rms", type=float, default=None,
                   help="refuse a camera whose reprojection RMS is above this, pixels (1.0)")
    add_output_arguments(p, "calibration.json")
    return p


def main(argv):
    from ..calibration import calibrate as cal
    from ..files.calibfile import write_calibration
    from ..imaging.plates import parse_frame_range

    args = build_parser().parse_args(argv)
    out = check_output(args.out, args.force, suffixes=(".json",),
                       inputs=[(f"--plate {view}", path)
                               for view, path in parse_view_values(args.plate, "--plate").items()])
    board = cal.parse_board(args.board)
    max_rms = cal.MAX_RMS_PX if args.max_rms is None else args.max_rms
    if not max_rms > 0:
        raise ZoopraxisError(f"--max-rms must be positive, got {args.max_rms}")
    plates = open_plates(parse_plate_options(args.plate))
    frames = parse_frame_range(args.frames, min(p.num_frames for p in plates.values()))
    result = cal.calibrate(plates, board, frames, step=args.step, world_frame=args.world_frame,
                           max_rms=max_rms,
                           progress=ConsoleProgress("calibrate: searching for the board",
                                                    "images"))
    for name, camera in result.cameras.items():
        x, y, z = camera.center
        print(f"{name}: board in {result.views[name]} frames, fx {camera.K[0, 0]:.1f} px, "
              f"fy {camera.K[1, 1]:.1f} px, centre ({x:.3f}, {y:.3f}, {z:.3f}) m, "
              f"reprojection RMS {result.rms[name]:.3f} px")
    print(f"world: the board of frame {result.world_frame} (on the floor, origin at its first "
          "inner corner)")
    for warning in result.warnings:
        print(f"warning: {warning}")
    write_calibration(out, result.cameras, force=args.force)
    print(f"wrote {out}")
    return 0
