"""Learn the proportions prior of bodies fitted from one view from CMU motion capture.

    .venv/bin/python tools/learn_proportions_prior.py [--data DIR ...] [--hold-out 02 35] \
        [--out core/priors/data/proportions_prior.npz] [--force]

This is how ``core/priors/data/proportions_prior.npz`` is built; run it again to rebuild it. Each
performer's lengths (``body.LENGTH_DIMS``, ``fit3d.dims_from_joints``) are measured on the
standard joints of all his captures (``cmu.read_take``: every CMU convention, ASF/AMC too),
a frame every third of a second. Captures on cgspeed's Daz figure are left out: every
performer there has that one figure's lengths. ``--hold-out`` leaves performers out
altogether (the shipped file has them all; ``ProportionsPrior.load(exclude=...)`` does the
same at load time, which is how the benchmarks judge it on performers it has not seen).
"""

import sys

import numpy as np

from _learning import learning_parser
from zoopraxis.core.files import cmu
from zoopraxis.core.body.body import LENGTH_DIMS
from zoopraxis.core.commands.common import check_output
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.priors.proportions import DEFAULT_PROPORTIONS_PRIOR, ProportionsPrior

FPS = 3.0       # frames a second measured: lengths are the same in every frame


def main(argv=None):
    parser = learning_parser(__doc__, DEFAULT_PROPORTIONS_PRIOR)
    args = parser.parse_args(argv)
    try:
        out = check_output(args.out, args.force)
        joints = {}
        for path in cmu.capture_paths(*args.data, hold_out=args.hold_out):
            take = cmu.read_take(path)
            if take.skeleton == "cmu_daz":
                continue
            joints.setdefault(take.subject, []).append(take.joints(FPS))
        prior = ProportionsPrior.from_joints({s: np.concatenate(j) for s, j in joints.items()})
        prior.save(out)
    except ZoopraxisError as error:
        print(f"learn_proportions_prior: error: {error}", file=sys.stderr)
        return 2
    mean, sigma = prior.mean_sigma()
    print(f"{len(prior.subjects)} performers ({', '.join(prior.subjects)}) -> {out}")
    for name, m, s in zip(LENGTH_DIMS, mean, sigma):
        print(f"  {name:15s} {m:.3f} m  +- {100 * s:.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
