"""Learn the walking prior (Sidenbladh, Black & Fleet 2000, §6.2) from every walk in CMU captures.

    .venv/bin/python tools/learn_walk_prior.py [--data DIR ...] [--takes 02_01 35_01 ...] \
        [--hold-out SUBJECT ...] [--exclude TAKE[:K] ...] [--out core/priors/data/walk_prior.npz] \
        [--force]

By default every capture under ``../shared/data/cmu_more`` and ``../shared/data/cmu_mocap``
(every CMU convention, ``cmu.read_take``) is searched for steady forward walking; ``--takes``
names a few instead. ``--hold-out`` leaves whole performers out (leave-subjects-out: the
benchmarks track subject 131's walk with a prior learned ``--hold-out 131``); ``--exclude``
leaves takes out, or single cycles, ``TAKE:K`` for the K-th cycle (from 0) found in TAKE
(leave-one-cycle-out).

This is how ``core/priors/data/walk_prior.npz`` is built; run it again to rebuild it. Steps:

1. read each capture at 60 fps and take its 17 standard joints;
2. cut the steady forward walking into gait cycles, each from the left foot passing the right
   to the next time it does (``walking.find_gait_cycles``: forward speed, plausible
   duration, hips facing the direction of travel; this drops standing starts, crouches,
   spins and side steps), and keep only the cycles with a foot on the ground throughout
   (a run's flight phases lift both, FLIGHT_M);
3. fit the ``sidenbladh`` body to each performer's joints: lengths over a subset of the
   frames of all his takes, then every frame's root and 19 angles by least squares on
   ``body.joints`` (``motion_prior.fit_body`` / ``fit_pose``);
4. resample each cycle to 64 phase samples: the angles, the forward speed, the pelvis sway
   and bob and its tilt relative to the direction of travel (``walking.cycle_curves``),
   the distances scaled to the template body's leg length;
   every cycle is added a second time mirrored (left and right swapped, half a cycle later);
5. PCA over the cycles, keeping 95% of the variance (``walking.learn_walk_model``).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

from zoopraxis.core.files import cmu
from zoopraxis.core.priors import motion_prior
from zoopraxis.core.priors import walking
from zoopraxis.core.body.body import make_body
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX

REPO = Path(__file__).resolve().parents[1]
DATA = [REPO.parent / "shared" / "data" / "cmu_more", REPO.parent / "shared" / "data" / "cmu_mocap"]

FPS = 60.0
SAMPLES = 64
COMPONENTS = 8
# A walk has a heel or a toe on the ground throughout; a cycle in which the lowest of the
# ankles and toes rises this far above its lowest height in the cycle has a flight phase (a
# run or a skip). CMU walks stay within 4.1 cm, a jog (02_03) rises 14.
FLIGHT_M = 0.07


def grounded(joints, start, end):
    """Whether a cycle (fractional frames) keeps a foot down throughout (FLIGHT_M)."""
    span = joints[int(np.floor(start)):int(np.ceil(end)) + 1]
    feet = span[:, [JOINT_INDEX[j] for j in ("l_ankle", "r_ankle", "l_toe", "r_toe")], 2]
    lower = feet.min(axis=1)
    return bool(lower.max() - lower.min() < FLIGHT_M)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, nargs="+", default=DATA)
    parser.add_argument("--takes", nargs="+", default=None,
                        help="only these takes (default: every capture under --data)")
    parser.add_argument("--hold-out", nargs="*", default=[], metavar="SUBJECT",
                        help="CMU subjects to leave out (131, 35, ...)")
    parser.add_argument("--exclude", nargs="+", default=[], metavar="TAKE",
                        help="takes to leave out (held-out evaluation)")
    parser.add_argument("--components", type=int, default=COMPONENTS,
                        help=f"most eigencurves kept (default {COMPONENTS})")
    parser.add_argument("--out", type=Path, default=walking.DEFAULT_WALK_PRIOR)
    parser.add_argument("--force", action="store_true", help="replace an existing output")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.force:
        sys.exit(f"learn_walk_prior: {args.out} exists (use --force to replace it)")
    try:
        paths = {p.stem: p for p in cmu.capture_paths(*args.data, hold_out=args.hold_out)}
    except ZoopraxisError as error:
        sys.exit(f"learn_walk_prior: {error}")
    if args.takes is not None:
        missing = [t for t in args.takes if t not in paths]
        if missing:
            sys.exit(f"learn_walk_prior: --takes {missing[0]}: no such capture under "
                     f"{' '.join(map(str, args.data))} (or its subject is held out)")
        paths = {t: paths[t] for t in args.takes}

    left_out = {}                                     # take -> cycle indices left out
    for item in args.exclude:
        name, _, index = item.partition(":")
        if name not in paths or (index and not index.isdigit()):
            sys.exit(f"learn_walk_prior: --exclude {item}: expected TAKE or TAKE:K with TAKE "
                     f"among the takes ({' '.join(paths)})")
        left_out.setdefault(name, set()).add(int(index) if index else None)

    walks = {}                                        # subject -> [(name, joints, cycles)]
    for name, path in paths.items():
        if None in left_out.get(name, ()):
            continue
        take = cmu.read_take(path)
        joints = take.joints(FPS)
        found, _ = walking.find_gait_cycles(joints, FPS)
        if left_out.get(name):
            print(f"{name}: leaving out cycles {sorted(left_out[name])}", flush=True)
            found = [c for k, c in enumerate(found) if k not in left_out[name]]
        kept = [c for c in found if grounded(joints, *c)]
        if found:
            print(f"{name}: {len(kept)} walking cycles of {len(found)} at "
                  f"{[(round(a / FPS, 2), round(b / FPS, 2)) for a, b in kept]} s", flush=True)
        if kept:
            walks.setdefault(take.subject, []).append((name, joints, kept))

    reference = make_body("sidenbladh")
    cycles, durations = [], []
    for subject, takes in walks.items():
        subset = np.concatenate([joints[::30] for _, joints, _ in takes])
        body, _, rms = motion_prior.fit_body(reference, subset)
        # Distances (speed, sway, bob) scale with the leg: brought to the reference body's.
        scale = (reference.dims["thigh"] + reference.dims["shank"]) \
            / (body.dims["thigh"] + body.dims["shank"])
        print(f"subject {subject}: body lengths fitted on {len(subset)} frames, joint RMS "
              f"{1000 * rms.mean():.1f} mm", flush=True)
        for name, joints, found in takes:
            for start, end in found:
                # Only the cycle needs poses (each frame starts from the previous one's fit).
                first = max(int(start) - 1, 0)
                last = min(int(np.ceil(end)) + 1, len(joints) - 1)
                poses, pose = [], None
                for frame in joints[first:last + 1]:
                    pose, _ = motion_prior.fit_pose(body, frame, pose)
                    poses.append(pose)
                curves = walking.cycle_curves(body, poses, start - first, end - first,
                                                   SAMPLES)
                distances = [body.n_dofs + walking.ROOT_CURVES.index(name)
                             for name in ("speed", "sway", "bob")]
                curves[distances] *= scale
                cycles += [curves, walking.mirror_curves(body, curves)]
                durations += [(end - start) / FPS] * 2
    if len(cycles) < 4:
        sys.exit(f"learn_walk_prior: only {len(cycles) // 2} walking cycles found")
    model = walking.learn_walk_model(reference, np.array(cycles),
                                          cycle_seconds=float(np.mean(durations)),
                                          max_components=args.components)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out)
    print(f"{len(cycles)} cycles (with mirrors) of {len(walks)} performers "
          f"({' '.join(walks)}), {model.n_components} eigencurves, mean cycle "
          f"{model.cycle_seconds:.2f} s -> {args.out}")
    return model


if __name__ == "__main__":
    main()
