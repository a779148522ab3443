"""``zoopraxis synth``: render synthetic plates from motion capture, with ground truth."""

import argparse

from ..errors import ZoopraxisError
from ..progress import ConsoleProgress


def _size(text):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, got '{text}'") from None
    return w, h


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis synth",
        description="Render a textured body driven by a BVH capture into calibrated views, "
                    "with calibration.json, truth.json and markers.json beside the plates.")
    p.add_argument("--bvh", required=True, help="motion capture (CMU skeleton)")
    p.add_argument("--out", required=True, help="output folder (one image folder per view)")
    p.add_argument("--views", type=int, default=3, help="number of cameras (default 3)")
    p.add_argument("--frames", default=None,
                   help="START:END over the resampled capture, END excluded (default all)")
    p.add_argument("--fps", type=float, default=30.0, help="plate frame rate (default 30)")
    p.add_argument("--size", type=_size, default=(480, 360), help="WIDTHxHEIGHT (480x360)")
    p.add_argument("--build", default="average", help="slim, average, heavy or a radius scale")
    p.add_argument("--noise", type=float, default=2.0, help="sensor noise, grey levels (2)")
    p.add_argument("--clutter", type=int, default=8, help="clutter shapes per background (8)")
    p.add_argument("--marker-noise", type=float, default=0.0,
                   help="click noise of the markers written, pixels (0)")
    p.add_argument("--anchors", default="0", help="comma-separated anchor frames (0)")
    p.add_argument("--format", default="png", choices=("png", "jpg"))
    p.add_argument("--seed", type=int, default=2345)
    p.add_argument("--force", action="store_true", help="write into a non-empty folder")
    return p


def main(argv):
    from ..synthetic import synth
    from ..imaging.plates import parse_frame_range

    args = build_parser().parse_args(argv)
    if args.views < 1 or args.views > 8:
        raise ZoopraxisError(f"--views must be between 1 and 8, got {args.views}")
    from ..files import cmu

    motion = cmu.load_cmu(args.bvh, fps=args.fps)
    frames = parse_frame_range(args.frames, motion.num_frames)
    sel = list(frames)
    joints = cmu.standard_joints(motion, frames=sel)
    jframes = cmu.standard_joint_frames(motion, frames=sel)
    scene = synth.make_scene(joints, jframes, views=args.views, image_size=args.size,
                             build=args.build, noise=args.noise, clutter=args.clutter,
                             seed=args.seed)
    anchors = [int(a) for a in args.anchors.split(",") if a.strip()]
    written = synth.write_take(args.out, scene, joints, fps=args.fps, image_format=args.format,
                               marker_noise=args.marker_noise, anchors=anchors,
                               source=str(args.bvh), force=args.force,
                               progress=ConsoleProgress("synth", "images"))
    print(f"wrote {written} frames x {args.views} views to {args.out}")
    return 0
