"""Learn the pose prior of single-view initialization from CMU motion capture.

    .venv/bin/python tools/learn_pose_prior.py [--data DIR ...] [--hold-out 02 35] \
        [--step 8] [--out core/priors/data/pose_prior.npz] [--force]

This is how ``core/priors/data/pose_prior.npz`` is built; run it again to rebuild it. Steps:

1. read every capture under the data folders (by default ``../shared/data/cmu_more``, 76
   takes of 17 performers in every CMU convention, and ``../shared/data/cmu_mocap``) at 30 fps
   and take its 17 standard joints (``core.files.cmu.read_take``: the manifest's frame rates, the
   T-pose frames dropped), leaving out the performers of ``--hold-out``;
2. fit the ``full`` body to every ``step``-th frame (``initialize.take_angles``: the lengths
   measured on the joints, then each frame's root and angles), as ``zoopraxis prior`` does
   (this script runs it on the takes);
3. keep the joint angles of every frame and their mirror image (left and right swapped), each
   labelled with its take (CMU's ``SUBJECT_TRIAL``), so that a benchmark can leave takes or
   performers out (``initialize.PosePrior.load(..., exclude=..., exclude_subjects=...)``).

The prior is a kernel density over these angle vectors, per body part
(``initialize.PosePrior``); initialization uses it to choose the depth sign of limbs that one
uncalibrated view cannot see (Bregler & Malik §2.6) and, summarised as a Gaussian mixture per
body part when it is loaded, as the angle prior of the least-squares fit of such a frame.
"""

import sys

from _learning import learning_parser
from zoopraxis import cli
from zoopraxis.core.files import cmu
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.priors.pose import DEFAULT_POSE_PRIOR



def main(argv=None):
    parser = learning_parser(__doc__, DEFAULT_POSE_PRIOR)
    parser.add_argument("--step", type=int, default=8, help="use every STEP-th frame at 30 fps")
    args = parser.parse_args(argv)
    try:
        paths = cmu.capture_paths(*args.data, hold_out=args.hold_out)
    except ZoopraxisError as error:
        print(f"learn_pose_prior: error: {error}", file=sys.stderr)
        return 2
    args.out.parent.mkdir(parents=True, exist_ok=True)
    # the same work as ``zoopraxis prior`` (core/commands/prior.py), which names takes by file stem
    command = ["prior", *map(str, paths), "--step", str(args.step), "--out", str(args.out)] \
        + ["--force"] * args.force
    return cli.main(command)


if __name__ == "__main__":
    sys.exit(main())
