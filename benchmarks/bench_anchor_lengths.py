"""The lengths and pose that the calibrated initialization fits to the clicks of a realistic
set's first frame, against the truth.

For every set of ``../shared/bench/sets`` (and ``--extra-sets``) seen in two views or more, and
every seed of the clicks' noise, the true 2D joints of frame 0 plus ``--noise-px`` of noise (as
``run_set.py`` writes them) are fitted by ``initialize`` (calibrated); the table gives frame 0's
MPJPE and each limb length's error (fitted minus the performer's, mean and spread over the
seeds), and last the root-mean-square length errors over all sets and seeds.

    .venv/bin/python benchmarks/bench_anchor_lengths.py [--extra-sets DIR] [--seeds 7,8,9]
        [--noise-px 2] [--sigma 0.05] [--learned thigh,shank|all|none]

``--sigma`` sets the spread of the lengths' prior in several views
(``initialize.run.SEVERAL_VIEWS_DIMS_SIGMA``) for the run, to compare; ``--learned`` the lengths
whose prior is centred on the captured performers' mean proportion instead of the template's
(``initialize.run.SEVERAL_VIEWS_LEARNED_LENGTHS``). The proportions prior is always the shipped
one without the set's performer (the subject of the CMU take in the set's ``about.json``): the
performers judged are ones it has not seen.
"""

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_realistic import bench_dir, performer  # noqa: E402

LIMBS = ("thigh", "shank", "upper_arm", "forearm")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--extra-sets", help="a folder of more sets (each with gt.npz)")
    parser.add_argument("--seeds", default="7,8,9,10,11,12")
    parser.add_argument("--noise-px", type=float, default=2.0)
    parser.add_argument("--sigma", type=float, help="the lengths' prior spread in several views")
    parser.add_argument("--learned", help="lengths centred on the learned proportions: "
                        "comma-separated names of body.LENGTH_DIMS, 'all' or 'none'")
    args = parser.parse_args()
    sys.path.insert(0, str(bench_dir()))
    import run_set
    from zoopraxis.core.body import fit3d
    from zoopraxis.core.files.calibfile import read_calibration
    from zoopraxis.core.files.markers import read_markers
    from zoopraxis.core.initialize import run as init_run

    from zoopraxis.core.body.body import LENGTH_DIMS
    from zoopraxis.core.priors.proportions import ProportionsPrior

    if args.sigma is not None:
        init_run.SEVERAL_VIEWS_DIMS_SIGMA = args.sigma
    if args.learned is not None:
        names = {"all": LENGTH_DIMS, "none": ()}.get(args.learned,
                                                     tuple(args.learned.split(",")))
        unknown = sorted(set(names) - set(LENGTH_DIMS))
        if unknown:
            parser.error(f"--learned: not lengths of the body: {', '.join(unknown)}")
        init_run.SEVERAL_VIEWS_LEARNED_LENGTHS = names
    seeds = [int(s) for s in args.seeds.split(",")]
    roots = [bench_dir() / "sets"] + ([Path(args.extra_sets)] if args.extra_sets else [])
    sets = sorted((d for root in roots for d in root.iterdir() if (d / "gt.npz").exists()),
                  key=lambda d: d.name)
    print(f"{'set':14} {'frame 0 mm':>10} " + " ".join(f"{n + ' mm':>14}" for n in LIMBS))
    errors = []
    for d in sets:
        gt = run_set.load_gt(d)
        if len(gt["cams"]) < 2:
            continue
        true = fit3d.dims_from_joints(gt["j3"])
        # the proportions prior of the performers other than this set's
        held_out = ProportionsPrior.load(exclude=[performer(d) or ""])
        rows, frame0 = [], []
        for seed in seeds:
            with tempfile.TemporaryDirectory() as tmp:
                run_set.write_inputs(gt, d, Path(tmp), args.noise_px, 0, False, seed=seed)
                result = init_run.initialize(read_markers(Path(tmp) / "markers.json"),
                                             read_calibration(Path(tmp) / "calibration.json"),
                                             proportions=held_out)
            rows.append([1000 * (result.body.dims[n] - true[n]) for n in LIMBS])
            frame0.append(1000 * np.linalg.norm(result.joints3d(0) - gt["j3"][0], axis=1).mean())
        rows = np.array(rows)
        errors.append(rows)
        print(f"{d.name:14} {np.mean(frame0):10.1f} " + " ".join(
            f"{m:+7.1f} ({s:4.1f})" for m, s in zip(rows.mean(0), rows.std(0))), flush=True)
    rms = np.sqrt((np.concatenate(errors) ** 2).mean(0))
    print(f"{'rms, all':14} {'':10} " + " ".join(f"{x:14.1f}" for x in rms))


if __name__ == "__main__":
    main()
