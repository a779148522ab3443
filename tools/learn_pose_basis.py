"""Learn the pose basis of single-view initialization from CMU motion capture.

    .venv/bin/python tools/learn_pose_basis.py [--data DIR ...] [--hold-out 02 35] \
        [--step 8] [--out core/priors/data/pose_basis.npz] [--force]

This is how ``core/priors/data/pose_basis.npz`` is built; run it again to rebuild it. Every
capture under the data folders (``cmu.read_take``: every CMU convention, the manifest's frame
rates, T-pose frames dropped) gives its 17 standard joints at 30 fps, every ``step``-th frame
(as ``tools/learn_pose_prior.py``), centred on the pelvis, turned to face a canonical heading
and scaled by the performer's size in that take (``basis.canonical_joints``,
``basis.body_size``). The file keeps these joint sets (float16) with their takes' names, so that
``PoseBasis.load(exclude_subjects=...)`` can leave performers out; the mean and principal
components (with the mirror images) are computed at load time.
"""

import sys

from _learning import learning_parser
from zoopraxis.core.commands.common import check_output
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files import cmu
from zoopraxis.core.priors.basis import DEFAULT_POSE_BASIS, PoseBasis



def main(argv=None):
    parser = learning_parser(__doc__, DEFAULT_POSE_BASIS)
    parser.add_argument("--step", type=int, default=8, help="use every STEP-th frame at 30 fps")
    args = parser.parse_args(argv)
    try:
        out = check_output(args.out, args.force)
        takes = {}
        for path in cmu.capture_paths(*args.data, hold_out=args.hold_out):
            takes[path.stem] = cmu.read_take(path).joints(30)[::max(1, args.step)]
        basis = PoseBasis.from_takes(takes)
        basis.save(out)
    except ZoopraxisError as error:
        print(f"learn_pose_basis: error: {error}", file=sys.stderr)
        return 2
    explained = basis.variances.sum() / (basis.variances.sum() + 3 * basis.residual.sum())
    print(f"{len(basis.joints)} joint sets of {len(takes)} takes -> {out}; "
          f"{len(basis.variances)} components explain {100 * explained:.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
