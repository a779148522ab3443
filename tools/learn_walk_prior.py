"""Learn the walking prior (Sidenbladh, Black & Fleet 2000, §6.2) from CMU walks.

    .venv/bin/python tools/learn_walk_prior.py [--data ../shared/data/cmu_mocap] \
        [--takes 131_01 131_02 131_03] [--exclude TAKE ...] [--out core/data/walk_prior.npz] \
        [--force]

``--exclude`` leaves takes out (leave-one-trial-out: ``benchmarks/bench_particle.py`` tracks
131_03's walk with a prior learned ``--exclude 131_03``, so that the prior has not seen it),
or single cycles, ``TAKE:K`` for the K-th cycle (from 0) found in TAKE (leave-one-cycle-out).
The CMU data beside the repository hold one subject's walks only (131_01-03; 01_01 is
jumps), about 7 cycles of steady forward walking in all.

This is how ``core/data/walk_prior.npz`` is built; run it again to rebuild it. Steps:

1. read each capture at 60 fps and take its 17 standard joints (``core.bvh``);
2. fit the ``sidenbladh`` body to the joints: lengths over a subset of frames of all takes
   (one subject), then every frame's root and 19 angles by least squares on ``body.joints``
   (``motion_prior.fit_body`` / ``fit_pose``);
3. cut the steady forward walking into gait cycles, each from the left foot passing the right
   to the next time it does (``motion_prior.find_gait_cycles``: forward speed, plausible
   duration, hips facing the direction of travel; this drops 131_01's standing start and
   crouch and the spins and side steps of 131_03);
4. resample each cycle to 64 phase samples: the angles, the forward speed, the pelvis sway
   and bob and its tilt relative to the direction of travel (``motion_prior.cycle_curves``);
   every cycle is added a second time mirrored (left and right swapped, half a cycle later);
5. PCA over the cycles, keeping 95% of the variance (``motion_prior.learn_walk_model``).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from zoopraxis.core import bvh, motion_prior
from zoopraxis.core.body import make_body

REPO = Path(__file__).resolve().parents[1]

FPS = 60.0
SAMPLES = 64


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=REPO.parent / "shared" / "data" / "cmu_mocap")
    parser.add_argument("--takes", nargs="+", default=["131_01", "131_02", "131_03"])
    parser.add_argument("--exclude", nargs="+", default=[], metavar="TAKE",
                        help="takes to leave out (held-out evaluation)")
    parser.add_argument("--out", type=Path, default=motion_prior.DEFAULT_WALK_PRIOR)
    parser.add_argument("--force", action="store_true", help="replace an existing output")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.force:
        sys.exit(f"learn_walk_prior: {args.out} exists (use --force to replace it)")

    left_out = {}                                     # take -> cycle indices left out
    for item in args.exclude:
        name, _, index = item.partition(":")
        if name not in args.takes or (index and not index.isdigit()):
            sys.exit(f"learn_walk_prior: --exclude {item}: expected TAKE or TAKE:K with TAKE "
                     f"among the takes ({' '.join(args.takes)})")
        left_out.setdefault(name, set()).add(int(index) if index else None)
    takes = {}
    for name in [t for t in args.takes if None not in left_out.get(t, ())]:
        path = args.data / f"{name}.bvh"
        if not path.is_file():
            sys.exit(f"learn_walk_prior: {path}: no such capture")
        takes[name] = bvh.standard_joints(bvh.load_cmu(path, fps=FPS))
        print(f"{name}: {len(takes[name])} frames at {FPS:g} fps", flush=True)

    body = make_body("sidenbladh")
    subset = np.concatenate([joints[::30] for joints in takes.values()])
    body, _, rms = motion_prior.fit_body(body, subset)
    print(f"body lengths fitted on {len(subset)} frames, joint RMS {1000 * rms.mean():.1f} mm",
          flush=True)

    cycles, durations = [], []
    for name, joints in takes.items():
        found, _ = motion_prior.find_gait_cycles(joints, FPS)
        print(f"{name}: cycles at "
              f"{[(round(a / FPS, 2), round(b / FPS, 2)) for a, b in found]} s", flush=True)
        if left_out.get(name):
            print(f"{name}: leaving out cycles {sorted(left_out[name])}", flush=True)
            found = [c for k, c in enumerate(found) if k not in left_out[name]]
        if not found:
            continue
        # Only the walking span needs poses (each frame starts from the previous one's fit).
        first = max(int(found[0][0]) - 3, 0)
        last = min(int(np.ceil(found[-1][1])) + 3, len(joints) - 1)
        poses, errors, pose = [], [], None
        for frame in joints[first:last + 1]:
            pose, err = motion_prior.fit_pose(body, frame, pose)
            poses.append(pose)
            errors.append(err)
        print(f"{name}: frames {first}-{last} fitted, median joint RMS "
              f"{1000 * np.median(errors):.1f} mm", flush=True)
        for start, end in found:
            curves = motion_prior.cycle_curves(body, poses, start - first, end - first, SAMPLES)
            cycles += [curves, motion_prior.mirror_curves(body, curves)]
            durations += [(end - start) / FPS] * 2
    if len(cycles) < 4:
        sys.exit(f"learn_walk_prior: only {len(cycles) // 2} walking cycles found")
    model = motion_prior.learn_walk_model(body, np.array(cycles),
                                          cycle_seconds=float(np.mean(durations)))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out)
    print(f"{len(cycles)} cycles (with mirrors) from {' '.join(takes)}, "
          f"{model.n_components} eigencurves, mean cycle {model.cycle_seconds:.2f} s -> {args.out}")
    return model


if __name__ == "__main__":
    main()
