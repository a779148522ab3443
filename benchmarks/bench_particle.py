"""Benchmark of the particle filter (Sidenbladh, Black & Fleet 2000) on synthetic plates.

    .venv/bin/python benchmarks/bench_particle.py [--quick] [--prior PATH] [--seed N] [--seeds N]

Three experiments, one table:

- ``arm``: their arm example (§7, Fig. 4). A body stands still and raises its left arm; the
  elbow stays straight for 10 frames, then bends. Only the 3 shoulder angles and the elbow are
  tracked (smooth-motion prior), and the upper-arm twist starts uniform over [-90, 90] degrees.
  The plates come from the renderer with a texture of rings on both arm segments (the paper's
  plain sleeve) and the paper's planar limb patches (``surface="patch"``), so a straight arm
  shows nothing of its twist: the twist's spread stays wide, then collapses once the elbow
  bends. Error: 3D distance of elbow and wrist from the truth.
- ``walk``: one view of CMU 131_03's walking cycle (frames 97-130 at 30 fps, the only steady
  forward cycle of that take) rendered by ``core.synthetic.synth`` (its own body, clothes, clutter and
  noise), tracked with the walking prior from the ground-truth pose of the first frame (the
  ``sidenbladh`` body fitted to the CMU joints). Error: MPJPE after a per-frame similarity
  (Procrustes) alignment. The honest rows use a prior that has not seen the walk tracked:
  learned from every walk of the other performers of cmu_more and cmu_mocap
  (``tools/learn_walk_prior.py --hold-out 131``: leave-subjects-out), from subject 131's
  other takes (``--takes 131_01 131_02 131_03 --exclude 131_03``, so from 131_01-02 only, a
  plainer walk than 131_03's stylised one), and, as a second walk, cycle 1
  of 131_02 (frames 129-156 at 30 fps) with a prior learned without that cycle
  (``--exclude 131_02:1``). The models are built on the first run and kept in
  ``benchmarks/output``. Each is tracked over several seeds (mean and worst), with the
  appearance likelihood alone and with the silhouette cue (foreground from a background model
  of the plate). The ``oracle`` rows are the best each prior can do: every frame's true
  angles fitted by the model's phase and coefficients. The shipped prior (learned from
  131_01-03, so it has seen 131_03's cycle) is tracked once for comparison (``--prior``
  takes another model).
- ``time``: seconds per frame of the walk against the number of particles, one view.

Columns: mean error (mm); spread (arm: twist standard deviation in degrees at frame 8, straight
arm, and at the end; walk: RMS posterior spread of the joints, mm); frames the filter reported
lost; seconds per frame; particles. Targets: 1e4 particles in one view within 1 s per frame;
the walk within 60 mm.
"""

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from zoopraxis.core.priors import motion_prior
from zoopraxis.core.priors import walking
from zoopraxis.core.trackers import particle
from zoopraxis.core.geometry import se3
from zoopraxis.core.synthetic import synth
from zoopraxis.core.imaging.background import estimate_background
from zoopraxis.core.body.body import Pose, make_body
from zoopraxis.core.geometry.camera import PinholeCamera, look_at

CMU = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu_mocap"
OUTPUT = Path(__file__).resolve().parent / "output"
WALK_FRAMES = slice(97, 131)
WALK_TAKE = "131_03"
# Held-out walks: label -> (take, frames at 30 fps, what the prior leaves out).
# "subject:S" leaves performer S out of a prior learned from every walk of cmu_more and
# cmu_mocap (leave-subjects-out); the others are learned from cmu_mocap's subject 131 alone.
HELD_OUT = {"131_03, subject 131 out": ("131_03", WALK_FRAMES, "subject:131"),
            "131_03, take out": ("131_03", WALK_FRAMES, "131_03"),
            "131_02 c1, cycle out": ("131_02", slice(129, 157), "131_02:1")}
FPS = 30.0
# Silhouette cue weight of the walk rows that use it (see core/trackers/likelihood.py).
SILHOUETTE = 3.0


def procrustes_mpjpe(X, Y):
    """Mean joint distance after the similarity transform that best maps X (J, 3) onto Y."""
    Xc, Yc = X - X.mean(axis=0), Y - Y.mean(axis=0)
    U, S, Vt = np.linalg.svd(Xc.T @ Yc)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    scale = np.trace(np.diag(S) @ D) / np.sum(Xc ** 2)
    return float(np.mean(np.linalg.norm(scale * Xc @ R - Yc, axis=1)))


# -- the arm example ----------------------------------------------------------------------------


def _sinusoids(rng, n, frequency):
    """A smooth random texture: n plane waves of about ``frequency`` cycles per metre."""
    k = rng.normal(size=(n, 3))
    k *= (2 * np.pi * frequency * rng.uniform(0.5, 1.5, n) / np.linalg.norm(k, axis=1))[:, None]
    phase = rng.uniform(0, 2 * np.pi, n)
    return lambda p: np.sqrt(2.0) * np.sin(p @ k.T + phase).mean(axis=1)


def arm_take(frames=40, twist=0.6, size=(320, 240), seed=2345):
    """Plates of a standing body raising its left arm, from the renderer with texture.

    Returns
    -------
    body : BodyModel
        The tracker's body (the plates show one with thicker arms and chest).
    camera : PinholeCamera
    images : list of array (H, W) uint8
    roots, angles : arrays (F, 4, 4), (F, n_dofs)
        The true motion.
    """
    rng = np.random.default_rng(seed)
    body = make_body("sidenbladh")
    shown = body.with_dims({"upper_arm_r": 0.05, "forearm_r": 0.042, "chest_rx": 0.17})
    prims = shown.primitives()
    t = np.arange(frames)
    angles = np.zeros((frames, body.n_dofs))
    angles[:, body.dof_index("l_shoulder_flex")] = 0.3 + 0.5 * np.clip(t / 30, 0, 1)
    angles[:, body.dof_index("l_shoulder_abd")] = 0.35 + 0.1 * np.sin(t / 8)
    angles[:, body.dof_index("l_shoulder_rot")] = twist
    angles[:, body.dof_index("l_elbow_flex")] = 1.4 * np.clip((t - 10) / 20, 0, 1)
    roots = np.broadcast_to(se3.transform(None, [0.0, 0.0, 0.95]), (frames, 4, 4))
    azimuth = -np.pi / 2 + 0.7
    R, tc = look_at([2.2 * np.cos(azimuth), 2.2 * np.sin(azimuth), 1.4], [0.1, 0.0, 1.15])
    f = 1.1 * size[0]
    camera = PinholeCamera("cam0", size, [[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2],
                                          [0, 0, 1]], R=R, t=tc)
    noise = rng.uniform(-1, 1, (size[1] // 8 + 2, size[0] // 8 + 2)).astype(np.float32)
    background = 110 + 60 * cv2.resize(noise, size, interpolation=cv2.INTER_CUBIC)
    textures = []
    for name in body.segment_names:
        base = 150 if "arm" in name or name == "head" else 120
        if name.endswith(("upper_arm", "forearm")):
            # Rings around the arm: a plain sleeve, no cue to its twist.
            textures.append(lambda p, b=base: b * (1 + 0.35 * np.sin(2 * np.pi * 14 * p[:, 2])))
        else:
            tex = _sinusoids(rng, 12, 25.0)
            textures.append(lambda p, b=base, tex=tex: b * (1 + 0.35 * tex(p)))
    light = np.array([0.3, -0.6, 0.75]) / np.linalg.norm([0.3, -0.6, 0.75])
    images = []
    for k in range(frames):
        images.append(synth.textured_grey(camera, shown.seg2world(roots[k], angles[k]), prims,
                                          textures, background, light, rng))
    return body, camera, images, roots, angles


def run_arm(n_particles, seed, frames):
    body, camera, images, roots, angles = arm_take(frames)
    active = ["l_shoulder_flex", "l_shoulder_abd", "l_shoulder_rot", "l_elbow_flex"]
    prior = motion_prior.SmoothMotionPrior(body, active=active)
    pf = particle.ParticleFilter(body, [camera], prior, n_particles=n_particles, seed=seed,
                                 surface="patch")
    step = pf.start([images[0]], Pose(roots[0].copy(), angles[0].copy()),
                    uniform={"l_shoulder_rot": (-np.pi / 2, np.pi / 2)})
    twist = 6 + body.dof_index("l_shoulder_rot")
    joints = [4, 5]                                              # l_elbow, l_wrist
    print(f"arm: twist {np.degrees(angles[0, twist - 6]):.0f} deg; frame, twist mean and "
          "spread (deg), elbow error (deg)")
    errors, seconds, lost, spread_straight = [], [], 0, None
    for k in range(1, frames):
        start = time.perf_counter()
        step = pf.step([images[k]])
        seconds.append(time.perf_counter() - start)
        truth = body.joints(roots[k], angles[k])
        errors.append(np.mean(np.linalg.norm(step.joints[joints] - truth[joints], axis=1)))
        lost += step.status == "lost"
        if k == 8:
            spread_straight = np.degrees(step.spread[twist])
        if k % 4 == 0 or k == frames - 1:
            elbow = body.dof_index("l_elbow_flex")
            print(f"  {k:3d}  {np.degrees(step.pose.angles[twist - 6]):6.1f} "
                  f"{np.degrees(step.spread[twist]):5.1f}  "
                  f"{np.degrees(step.pose.angles[elbow] - angles[k, elbow]):6.1f}", flush=True)
    spread = f"{spread_straight:.0f} -> {np.degrees(step.spread[twist]):.0f} deg"
    return 1000 * np.mean(errors), spread, lost, np.median(seconds)


# -- the walk -----------------------------------------------------------------------------------


def heldout_model(test=WALK_TAKE):
    """The walking model learned without a take or cycle (built once, then read)."""
    path = OUTPUT / f"walk_prior_without_{test.replace(':', '_cycle')}.npz"
    if not path.is_file():
        sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
        import learn_walk_prior

        OUTPUT.mkdir(exist_ok=True)
        print(f"learning the walking prior without {test} -> {path}", flush=True)
        if test.startswith("subject:"):
            learn_walk_prior.main(["--data", str(CMU.parent / "cmu_more"), str(CMU),
                                   "--hold-out", test.split(":")[1], "--out", str(path)])
        else:
            learn_walk_prior.main(["--data", str(CMU), "--takes", "131_01", "131_02",
                                   "131_03", "--exclude", test, "--out", str(path)])
    return walking.WalkModel.load(path)


def walk_take(take=WALK_TAKE, frames=WALK_FRAMES, size=(640, 480)):
    scene, joints = synth.take_from_bvh(CMU / f"{take}.bvh", frames=frames, fps=FPS,
                                        views=1, image_size=size, noise=2.0, clutter=4)
    images = [scene.render_frame(k, 0)[0] for k in range(scene.num_frames)]
    body, poses, _ = motion_prior.fit_body(make_body("sidenbladh"), joints)
    masks = [m.foreground(im) for m in [estimate_background(images[::2])] for im in images]
    return body, scene.cameras[0], images, joints, poses, masks


def oracle_walk(take, model):
    """PA-MPJPE of the model's closest cycle pose to every true pose (its best case)."""
    body, _, _, joints, poses, _ = take
    prior = walking.WalkingPrior(body, model, fps=FPS)
    errors = []
    for k, pose in enumerate(poses):
        phase, c, _ = prior.fit_pose(pose)
        state = prior.init_state(pose, 1, np.random.default_rng(0), phase=phase,
                                 coefficients=c, spread={name: 0.0 for name in "phase c rate t r"
                                                         .split()})
        roots, angles = prior.poses(state)
        errors.append(procrustes_mpjpe(body.joints(Pose(roots[0], angles[0])), joints[k]))
    return 1000 * np.mean(errors)


def run_walk(take, n_particles, seed, model, frames=None, silhouette=0.0, layers=0):
    body, camera, images, joints, poses, masks = take
    frames = len(images) if frames is None else frames
    prior = walking.WalkingPrior(body, model, fps=FPS)
    pf = particle.ParticleFilter(body, [camera], prior, n_particles=n_particles, seed=seed,
                                 silhouette=silhouette, layers=layers)
    pf.start([images[0]], poses[0])
    errors, spreads, seconds, lost = [], [], [], 0
    for k in range(1, frames):
        start = time.perf_counter()
        step = pf.step([images[k]], [masks[k]] if silhouette else None)
        seconds.append(time.perf_counter() - start)
        errors.append(procrustes_mpjpe(step.joints, joints[k]))
        spreads.append(np.sqrt(np.mean(step.joint_spread ** 2)))
        lost += step.status == "lost"
    return (1000 * np.mean(errors), f"{1000 * np.mean(spreads):.0f} mm", lost,
            np.median(seconds))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer frames and particles")
    parser.add_argument("--prior", type=Path, help="walking model npz (default: the shipped)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--seeds", type=int, default=3, help="seeds of the held-out walk rows")
    args = parser.parse_args(argv)
    if not CMU.is_dir():
        sys.exit(f"bench_particle: {CMU}: no CMU captures")
    model = walking.WalkModel.load(args.prior)
    rows = []
    arm_particles = 1000 if args.quick else 2000
    rows.append(("arm (4 DOF, smooth)", arm_particles,
                 *run_arm(arm_particles, args.seed, 30 if args.quick else 40)))
    walk_particles = 1000 if args.quick else 2000
    seeds = range(args.seed, args.seed + (1 if args.quick else args.seeds))
    for name, (take_name, frames, leave_out) in HELD_OUT.items():
        take = walk_take(take_name, frames)
        heldout = heldout_model(leave_out)
        rows.append((f"walk {name}: oracle", 0, oracle_walk(take, heldout), "-", 0, 0.0))
        for label, silhouette in (("appearance", 0.0), ("silhouette", SILHOUETTE)):
            runs = [run_walk(take, walk_particles, s, heldout, silhouette=silhouette)
                    for s in seeds]
            errors = [r[0] for r in runs]
            rows.append((f"walk {name}: {label}", walk_particles, np.mean(errors),
                         f"{runs[0][1]}; worst {max(errors):.0f}", sum(r[2] for r in runs),
                         np.median([r[3] for r in runs])))
            print(rows[-1], flush=True)
    take = walk_take()
    rows.append(("walk 131_03, shipped prior", walk_particles,
                 *run_walk(take, walk_particles, args.seed, model)))
    for n in (100, 1000, 10000):
        error, spread, lost, seconds = run_walk(take, n, args.seed, model, frames=6)
        rows.append(("time, 1 view, 5 frames", n, error, spread, lost, seconds))
    error, spread, lost, seconds = run_walk(take, 10000, args.seed, model, frames=6,
                                            silhouette=SILHOUETTE)
    rows.append(("time, silhouette, 5 frames", 10000, error, spread, lost, seconds))
    error, spread, lost, seconds = run_walk(take, 2000, args.seed, model, frames=6, layers=1)
    rows.append(("time, 1 layer, 5 frames", 2000, error, spread, lost, seconds))
    print()
    print(f"{'experiment':38s} {'particles':>9s} {'error mm':>9s} {'spread':>16s} "
          f"{'lost':>5s} {'s/frame':>8s}")
    for name, n, error, spread, lost, seconds in rows:
        print(f"{name:38s} {n:9d} {error:9.1f} {spread:>16s} {lost:5d} {seconds:8.3f}")
    print(f"held-out rows: mean over {len(seeds)} seeds (worst in the spread column); "
          "lost summed over the seeds")
    print("targets: walk (held-out prior) < 60 mm; 10000 particles < 1 s per frame")


if __name__ == "__main__":
    main()
