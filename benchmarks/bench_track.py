"""Benchmark of the differential tracker on synthetic plates driven by real motion capture.

The plates do not flatter the tracker: the rendered body is built from capsules on the CMU
skeleton (another shape and build than the tracker's ellipsoid body), wears textured clothes,
is shaded, stands in front of a textured, cluttered background and carries sensor noise. The
tracker starts from the animator's clicks (markers with 2 px noise at the anchor frames, fitted
by the initialization) unless ``--init truth`` is given.

Prints one row per case: MPJPE and Procrustes-aligned MPJPE (mm) against the capture's joints,
knee and elbow flexion RMSE (degrees, measured on the joints), lost and uncertain frames by the
tracker's status, frames more than 150 mm off by the truth (">150mm"; Procrustes-aligned for one
view) and how many of those the status called ok ("of.ok"), frames where the silhouette limb search moved a limb ("recov"),
frames per second of tracking (wall clock, the whole run from PNG plates on disk: decoding,
background models, initialization and tracking; the plates are rendered before the clock
starts), peak memory and the largest limb overlap (mm, sphere proxies).

    .venv/bin/python benchmarks/bench_track.py            # all cases (several minutes)
    .venv/bin/python benchmarks/bench_track.py --quick    # 60 frames per case
    .venv/bin/python benchmarks/bench_track.py --cases walk3
    .venv/bin/python benchmarks/bench_track.py --cases walk3-anchors --whole-passes
"""

import argparse
import os
import resource
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

from zoopraxis.core.body import fit3d  # noqa: E402
from zoopraxis.core.synthetic import synth  # noqa: E402
from zoopraxis.core.body.joints import JOINT_INDEX, STANDARD_JOINTS  # noqa: E402
from zoopraxis.core.files.markers import Anchor  # noqa: E402
from zoopraxis.core.initialize.options import InitOptions  # noqa: E402

DATA = Path(os.environ.get("ZOOPRAXIS_SHARED_DATA",
                           Path(__file__).resolve().parents[2] / "shared" / "data"))

# name: (capture, first frame, frames, views, calibrated, noise, clutter, build, fps, anchor every)
# 131_02 is a slow walk (joints move 14 mm a frame on average at 30 fps); 131_03 is a brisk,
# stylised walk (29 mm, swinging feet up to 180 mm a frame), beyond what a differential
# tracker follows at 30 fps without a coarse search in front of it.
CASES = {
    "walk3": ("131_02.bvh", 0, 300, 3, True, 2.0, 8, "heavy", 30.0, 0),
    "walk3-anchors": ("131_02.bvh", 0, 300, 3, True, 2.0, 8, "heavy", 30.0, 100),
    "walk1": ("131_02.bvh", 150, 120, 1, True, 2.0, 8, "average", 30.0, 0),
    "walk2": ("131_02.bvh", 150, 120, 2, True, 2.0, 8, "average", 30.0, 0),
    "walk4": ("131_02.bvh", 150, 120, 4, True, 2.0, 8, "slim", 30.0, 0),
    "walk3-clean": ("131_02.bvh", 150, 120, 3, True, 0.0, 0, "average", 30.0, 0),
    "walk1-uncal": ("131_02.bvh", 150, 120, 1, False, 2.0, 8, "average", 30.0, 0),
    "walk1-near": ("131_02.bvh", 150, 120, 1, False, 2.0, 8, "average", 30.0, 0),
    "brisk3": ("131_03.bvh", 60, 120, 3, True, 2.0, 8, "average", 30.0, 0),
}

# Options of ``track`` beyond a case's spec: the views of these synthetic takes are 2-3 m from
# the walker, so "walk1-near" is "walk1-uncal" with the view's perspective fitted and tracked
# through (``track --perspective``, which the command line passes as the initialization's
# ``InitOptions(perspective=True)``; ``track`` tracks through the perspective it fitted).
CASE_OPTIONS = {"walk1-near": {"init_options": InitOptions(perspective=True)}}

# A frame more than this far off (mean over the joints) is lost, whatever its status says.
OFF_MM = 150.0


def procrustes_mpjpe(pred, true):
    """Mean joint error after the best similarity transform, per frame (mm)."""
    out = []
    for P, T in zip(pred, true):
        mp, mt = P.mean(0), T.mean(0)
        A, B = P - mp, T - mt
        U, S, Vt = np.linalg.svd(A.T @ B)
        d = np.sign(np.linalg.det(U @ Vt))
        D = np.diag([1, 1, d])
        R = U @ D @ Vt
        s = (S * np.diag(D)).sum() / (A ** 2).sum()
        out.append(np.linalg.norm(s * A @ R - B, axis=1).mean())
    return 1000 * np.array(out)


def flexion(joints, a, b, c):
    """Angle at b between the segments to a and c, as flexion (0 = straight), degrees."""
    u = joints[:, JOINT_INDEX[a]] - joints[:, JOINT_INDEX[b]]
    v = joints[:, JOINT_INDEX[c]] - joints[:, JOINT_INDEX[b]]
    cos = (u * v).sum(1) / np.linalg.norm(u, axis=1) / np.linalg.norm(v, axis=1)
    return 180.0 - np.degrees(np.arccos(np.clip(cos, -1, 1)))


def markers_from_truth(scene, joints, frames, noise, rng):
    anchors = []
    for f in frames:
        views = {}
        for cam in scene.cameras:
            uv = cam.project(joints[f]) + rng.normal(0, noise, size=(17, 2))
            views[cam.name] = {j: tuple(p) for j, p in zip(STANDARD_JOINTS, uv)}
        anchors.append(Anchor(f, views))
    return anchors


def write_plates(scene, folder):
    """Render a synthetic take into PNG image folders and open them as plates."""
    import cv2

    from zoopraxis.core.imaging.plates import open_plate

    out = {}
    for v, cam in enumerate(scene.cameras):
        (folder / cam.name).mkdir()
        for f in range(scene.num_frames):
            image, _ = scene.render_frame(f, v)
            cv2.imwrite(str(folder / cam.name / f"{f:06d}.png"), image,
                        [cv2.IMWRITE_PNG_COMPRESSION, 1])
        out[cam.name] = open_plate(folder / cam.name, name=cam.name, fps=30.0)
    return out


def run_case(name, spec, *, quick, init_mode, anchor_every, workers=1, whole_passes=False):
    from zoopraxis.core.files.initfile import InitResult
    from zoopraxis.core.take import track as T

    bvh, start, n, views, calibrated, noise, clutter, build, fps, every = spec
    anchor_every = anchor_every or every
    if quick:
        n = min(n, 60)
    scene, joints = synth.take_from_bvh(DATA / "cmu_mocap" / bvh, frames=slice(start, start + n),
                                        fps=fps, views=views, image_size=(480, 360),
                                        noise=noise, clutter=clutter, build=build)
    # The plates go to disk first, as the animator's would be: fps counts decoding them,
    # not the synthetic renderer.
    folder = tempfile.TemporaryDirectory(prefix="zoopraxis-bench-")
    plates = write_plates(scene, Path(folder.name))
    rng = np.random.default_rng(2345)
    anchor_frames = [0] if not anchor_every else list(range(0, n, anchor_every))
    anchors = markers_from_truth(scene, joints, anchor_frames, 2.0, rng)
    cams = {c.name: c for c in scene.cameras} if calibrated else None
    init = None
    if init_mode == "truth":
        body, poses, _ = fit3d.fit_sequence(joints[anchor_frames])
        if not calibrated:
            raise SystemExit("--init truth needs calibrated cases")
        init = InitResult(body, {f: p for f, p in zip(anchor_frames, poses)}, cams)
    t0 = time.perf_counter()
    reach = {"blend_reach": None} if whole_passes else {}
    res = T.track(plates, anchors, cams, init=init, workers=workers, **reach,
                  **CASE_OPTIONS.get(name, {}))
    elapsed = time.perf_counter() - t0
    for plate in plates.values():
        plate.close()
    folder.cleanup()
    pred = res.joints3d
    true = joints[res.frames]
    mpjpe = 1000 * np.linalg.norm(pred - true, axis=2).mean() if calibrated else float("nan")
    pa = procrustes_mpjpe(pred, true).mean()
    knee = np.concatenate([flexion(pred, f"{s}_hip", f"{s}_knee", f"{s}_ankle")
                           - flexion(true, f"{s}_hip", f"{s}_knee", f"{s}_ankle")
                           for s in "lr"])
    elbow = np.concatenate([flexion(pred, f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist")
                            - flexion(true, f"{s}_shoulder", f"{s}_elbow", f"{s}_wrist")
                            for s in "lr"])
    tracked = len(res.frames) - len(anchor_frames)
    # One view leaves the depth of the whole body to the body's size: judge those frames (and
    # uncalibrated ones) after a similarity alignment.
    per_frame = 1000 * np.linalg.norm(pred - true, axis=2).mean(axis=1) \
        if calibrated and views > 1 else procrustes_mpjpe(pred, true)
    return {"case": name, "views": views, "anchors": len(anchor_frames), "mode": "cal" if calibrated else "uncal",
            "frames": len(res.frames), "mpjpe": mpjpe, "pa": pa,
            "knee": float(np.sqrt(np.mean(knee ** 2))), "elbow": float(np.sqrt(np.mean(elbow ** 2))),
            "lost": res.status.count("lost"), "uncertain": res.status.count("uncertain"),
            # frames whose error says lost, whatever the status says; and how many of them
            # the status passed off as ok
            "off": int((per_frame > OFF_MM).sum()),
            "off_ok": int(sum(1 for e, s in zip(per_frame, res.status) if e > OFF_MM and s == "ok")),
            "recovered": sum(1 for r in res.extra.get("recovered_limbs", []) if r),
            "fps": tracked / elapsed,
            "overlap": float(np.max(res.extra["limb_overlap_mm"])),
            "mem": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--quick", action="store_true", help="60 frames per case")
    p.add_argument("--cases", default=",".join(CASES), help="comma-separated case names")
    p.add_argument("--init", choices=("markers", "truth"), default="markers",
                   help="start from the clicked markers (default) or from the true pose")
    p.add_argument("--anchor-every", type=int, default=0,
                   help="add marker anchors every N frames (default: frame 0 only)")
    p.add_argument("--workers", type=int, default=0,
                   help="processes for the passes of takes with several anchors (default: one "
                        "per core, at most 4, as `zoopraxis track`)")
    p.add_argument("--whole-passes", action="store_true",
                   help="track both passes between two anchors from anchor to anchor (the "
                        "default stops each a little past the middle, track.BLEND_REACH)")
    args = p.parse_args(argv)
    from zoopraxis.core.take.track import default_workers

    workers = args.workers or default_workers()
    print(f"{os.cpu_count()} cores; passes of multi-anchor takes in {workers} processes")
    if not (DATA / "cmu_mocap").is_dir():
        sys.exit(f"no motion capture at {DATA / 'cmu_mocap'} (set ZOOPRAXIS_SHARED_DATA)")
    header = (f"{'case':<14}{'views':>5} {'mode':>5}{'anch':>5}{'frames':>7}{'MPJPE':>8}{'PA-MPJPE':>9}"
              f"{'knee°':>7}{'elbow°':>7}{'lost':>5}{'uncert':>7}{'>150mm':>7}{'of.ok':>6}"
              f"{'recov':>6}{'fps':>6}{'MB':>7}{'overlap':>8}")
    print(header)
    print("-" * len(header))
    for name in args.cases.split(","):
        r = run_case(name, CASES[name], quick=args.quick, init_mode=args.init,
                     anchor_every=args.anchor_every, workers=workers,
                     whole_passes=args.whole_passes)
        print(f"{r['case']:<14}{r['views']:>5} {r['mode']:>5}{r['anchors']:>5}{r['frames']:>7}{r['mpjpe']:>8.1f}"
              f"{r['pa']:>9.1f}{r['knee']:>7.1f}{r['elbow']:>7.1f}{r['lost']:>5}"
              f"{r['uncertain']:>7}{r['off']:>7}{r['off_ok']:>6}{r['recovered']:>6}"
              f"{r['fps']:>6.1f}{r['mem']:>7.0f}{r['overlap']:>8.1f}",
              flush=True)


if __name__ == "__main__":
    main()
