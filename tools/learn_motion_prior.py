"""Learn the general motion prior of the particle filter and the hybrid from CMU motion capture.

    .venv/bin/python tools/learn_motion_prior.py [--data DIR ...] [--hold-out 01,05,131] \
        [--windows 8] [--seconds 1] [--out core/priors/data/motion_prior.npz] [--force]

By default every capture under ``../shared/data/cmu_more`` and ``../shared/data/cmu_mocap`` is
used (76 + 4 takes of 18 performers: walks, runs, jumps, reaches, sport, swordplay, karate,
modern, salsa and Indian dance); ``--hold-out`` leaves whole performers out (the benchmarks
track subjects 01, 05 and 131 with a prior learned ``--hold-out 01,05,131``).

This is how ``core/priors/data/motion_prior.npz`` is built; run it again to rebuild it. Steps:

1. read each capture at 30 fps (``cmu.read_take``: every CMU convention, the manifest's frame
   rates, the T-pose frames dropped) and take its 17 standard joints;
2. fit the ``full`` body's lengths to the take's joints (``fit3d.dims_from_joints``), then the
   root and 29 angles of every frame of ``--windows`` runs of ``--seconds`` each, spread
   evenly over the take (each frame from the one before, ``fit3d.fit_pose``); a run with a
   frame the body misses by more than ``pose.TAKE_DROP_M`` is left out;
3. learn the damping and correlated noise of every angle and the pose space from the runs and
   their mirror images (``general.learn_motion_model``); how far poses may lie off the pose
   space is chosen by leaving each performer out in turn (``general.pose_rest_floor``).

Fitting every frame of every take would take an hour; a few seconds of each take give the
dynamics of all of them (about 4 minutes on one core).
"""

import argparse
import os
import sys
import time
from pathlib import Path

# The fits solve small systems one frame at a time: BLAS threads only fight over the cores
# (ten times slower on a busy machine).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402 (after the thread settings)

from zoopraxis.core.body.body import make_body  # noqa: E402
from zoopraxis.core.body.fit3d import dims_from_joints, fit_pose  # noqa: E402
from zoopraxis.core.errors import ZoopraxisError  # noqa: E402
from zoopraxis.core.files import cmu  # noqa: E402
from zoopraxis.core.priors import general  # noqa: E402
from zoopraxis.core.priors.motion_prior import REFERENCE_FPS  # noqa: E402
from zoopraxis.core.priors.pose import TAKE_DROP_M  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
DATA = [REPO.parent / "shared" / "data" / name for name in ("cmu_more", "cmu_mocap")]

TEMPLATE = "full"
# Levenberg-Marquardt steps of a run's first frame (from the rest pose) and of the others
# (from the frame before, one thirtieth of a second away: a few steps reach the same fit).
FIRST_ITERATIONS, NEXT_ITERATIONS = 60, 8


def fit_run(body, joints):
    """Roots (F, 4, 4) and angles (F, D) of consecutive frames, or None if one misses."""
    pose, roots, angles = None, [], []
    for frame in joints:
        pose, rms = fit_pose(body, frame, pose, prior=1e-3,
                             iterations=FIRST_ITERATIONS if pose is None else NEXT_ITERATIONS)
        if not rms <= TAKE_DROP_M:
            return None
        roots.append(pose.root)
        angles.append(pose.angles)
    return np.array(roots), np.array(angles)


def runs_of(joints, windows, length):
    """Start frames of ``windows`` runs of ``length`` frames spread evenly over a take."""
    F = len(joints)
    if F < length:
        return [0] if F >= 3 else []
    return sorted(set(np.linspace(0, F - length, windows).round().astype(int).tolist()))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, nargs="+", default=DATA)
    parser.add_argument("--hold-out", nargs="*", default=[], metavar="SUBJECTS",
                        help="CMU subjects to leave out, separated by spaces or commas "
                             "(01,05,131)")
    parser.add_argument("--windows", type=int, default=8, help="runs fitted per take")
    parser.add_argument("--seconds", type=float, default=1.0, help="length of a run")
    parser.add_argument("--out", type=Path, default=general.DEFAULT_MOTION_PRIOR)
    parser.add_argument("--force", action="store_true", help="replace an existing output")
    args = parser.parse_args(argv)
    if args.out.exists() and not args.force:
        sys.exit(f"learn_motion_prior: {args.out} exists (use --force to replace it)")
    if args.windows < 1 or not args.seconds * REFERENCE_FPS >= 3:
        sys.exit("learn_motion_prior: need --windows >= 1 and runs of 3 frames or more")
    held = [s for item in args.hold_out for s in item.split(",") if s]
    try:
        paths = cmu.capture_paths(*args.data, hold_out=held)
    except ZoopraxisError as error:
        sys.exit(f"learn_motion_prior: {error}")
    if not paths:
        sys.exit("learn_motion_prior: no capture left to learn from")
    length = int(round(args.seconds * REFERENCE_FPS))
    sequences, performers, t0 = [], [], time.time()
    for k, path in enumerate(paths):
        try:
            take = cmu.read_take(path)
        except ZoopraxisError as error:
            sys.exit(f"learn_motion_prior: {error}")
        joints = take.joints(REFERENCE_FPS)
        joints = joints[np.isfinite(joints).all(axis=(1, 2))]
        body = make_body(TEMPLATE, dims_from_joints(joints))
        kept = 0
        for start in runs_of(joints, args.windows, length):
            run = fit_run(body, joints[start:start + length])
            if run is not None:
                sequences.append(run)
                performers.append(take.subject)
                kept += 1
        print(f"[{k + 1}/{len(paths)}] {take.name}: {kept} runs of {length} frames "
              f"({time.time() - t0:.0f} s)", flush=True)
    if not sequences:
        sys.exit("learn_motion_prior: no run could be fitted")
    model = general.learn_motion_model(make_body(TEMPLATE).dof_names, sequences, REFERENCE_FPS,
                                       performers=performers)
    subjects = set(performers)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    model.save(args.out)
    print(f"{len(sequences)} runs of {len(subjects)} performers ({' '.join(sorted(subjects))}), "
          f"{model.frames} frames with mirror images: {len(model.pose_std)} pose components, "
          f"{len(model.noise_std)} noise components, rest off the pose space at least "
          f"{model.pose_rest.min():.3f} rad, {args.out.stat().st_size / 1024:.1f} kB "
          f"-> {args.out}")
    return model


if __name__ == "__main__":
    main()
