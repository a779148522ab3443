"""``zoopraxis prior``: learn the pose prior of one-view initialization from takes of the kind
of motion at hand.

One uncalibrated view cannot see whether a limb points towards the camera or away from it;
the pose prior decides (``initialize``). The shipped prior knows 80 CMU takes of 18 performers
(``tools/learn_pose_prior.py``). A prior learned from captures of the motion being tracked
(CMU BVH or AMC files)
or from earlier tracks of it (result.json, say of a calibrated shoot of the same performer)
knows that motion better; ``init`` and ``track`` take it with ``--pose-prior``.
"""

import argparse
import sys
from pathlib import Path

from .common import check_output, check_template
from ..errors import ZoopraxisError


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis prior",
        description="Learn a pose prior for frames clicked in one view (--pose-prior of init "
                    "and track) from the poses of motion capture (CMU BVH) or of tracked takes "
                    "(result.json; lost frames left out), with their mirror images.")
    p.add_argument("takes", nargs="+", metavar="TAKE",
                   help="a capture with a CMU skeleton (BVH of any CMU naming, or AMC with its "
                        "ASF beside it), a Zoopraxis result.json or a truth.json of "
                        "'zoopraxis synth'")
    p.add_argument("--step", type=int, default=4,
                   help="use every STEP-th frame (BVH at 30 fps; default 4)")
    p.add_argument("--template", default="full", help="body template (default full)")
    p.add_argument("--out", required=True, help="the prior file to write (.npz)")
    p.add_argument("--force", action="store_true", help="replace an existing output")
    return p


def read_take_joints(path):
    """A take's 3D standard joints (F, 17, 3), world metres (NaN in a result's lost frames).

    Raises
    ------
    ZoopraxisError
        A missing or unreadable file, or one neither BVH nor result.json (naming it).
    """
    import numpy as np

    path = Path(path)
    if not path.is_file():
        raise ZoopraxisError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix in (".bvh", ".amc"):
        from ..files.cmu import read_take

        return read_take(path).joints(fps=30.0)
    if suffix == ".json":
        from ..files.inputs import read_json
        from ..body.joints import STANDARD_JOINTS
        from ..files.result import read_result

        data = read_json(path, "take")
        if isinstance(data, dict) and data.get("format") == "zoopraxis-truth/1":
            # zoopraxis synth's ground truth: the result.json layout without statuses
            try:
                order = [list(data["joints"]).index(j) for j in STANDARD_JOINTS]
                X = np.asarray(data["joints3d"], float)[:, order]
            except (KeyError, ValueError, IndexError, TypeError, OverflowError) as error:
                raise ZoopraxisError(f"{path}: malformed truth file ({error})") from None
            return X
        result = read_result(path)
        X = np.array(result.joints3d, float)
        X[np.array([s == "lost" for s in result.status], bool)] = np.nan
        return X
    raise ZoopraxisError(f"{path}: not a take (expected a .bvh or .amc capture, a result.json "
                         "or a truth.json)")


def main(argv):
    import numpy as np

    from ..priors.pose import PosePrior, take_angles
    from ..files.outputs import replacing

    args = build_parser().parse_args(argv)
    out = check_output(args.out, args.force,
                       inputs=[("take", take) for take in args.takes], suffixes=(".npz",))
    check_template(args.template)
    if args.step < 1:
        raise ZoopraxisError(f"--step {args.step}: give 1 or more")
    paths = [Path(t) for t in args.takes]
    names = {}
    for path in paths:
        capture = path.suffix.lower() in (".bvh", ".amc")
        name = path.stem if capture else path.parent.name + "/" + path.stem
        if name in names.values():
            name = str(path)
        names[path] = name
    joints = {path: read_take_joints(path) for path in paths}     # every file checked first
    angles = {}
    cancelled = False
    try:
        for k, path in enumerate(paths):
            a, rms = take_angles(joints[path], args.template, args.step)
            if not len(a):
                print(f"prior: {path}: no frame with all 17 joints; left out", file=sys.stderr)
                continue
            angles[names[path]] = a
            print(f"prior: {k + 1}/{len(paths)} {path}: {len(a)} poses, median joint fit "
                  f"{1000 * np.median(rms):.1f} mm", file=sys.stderr, flush=True)
    except KeyboardInterrupt:
        cancelled = True
        print(f"prior: cancelled after {len(angles)} of {len(paths)} takes", file=sys.stderr)
        if not angles:
            return 130
    prior = PosePrior.from_takes(angles, args.template)
    with replacing(out) as temporary:
        prior.save(temporary)
    takes = f"{len(angles)} take{'s' if len(angles) > 1 else ''}"
    print(f"prior: {len(prior.samples)} poses (with mirror images) of {takes} -> {out}")
    return 130 if cancelled else 0
