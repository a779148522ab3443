"""Time the model renderer on a 15-primitive body filling a good part of the view.

Run as ``.venv/bin/python benchmarks/bench_render.py``. Prints the median (and minimum) time
per view of 20 runs after a warm-up, for the support map and depth only and for all outputs
(points and normals too), at 640x480 and 320x240, plus ``render_points`` on 2000 pixels.
"""

import time

import numpy as np

from zoopraxis.core.geometry.camera import PinholeCamera, look_at
from zoopraxis.core.body.primitives import Primitives, cylinder, ellipsoid
from zoopraxis.core.imaging.render import render, render_points

RUNS = 20


def body():
    """Pelvis, torso, head and two arms and legs with hands and feet: 15 primitives, 15 labels.

    Each segment's primitive is given in the segment frame; the segment frames sit at the
    joints, so ``seg2world`` is a translation per segment (a standing pose, arms a little
    forward), like a body model posing its segments.
    """
    prims, joints = [], []

    def add(prim, joint):
        prims.append(prim)
        joints.append(joint)

    add(ellipsoid(0, (0, 0, 0), (0.17, 0.11, 0.12)), (0.0, 0.0, 0.95))                 # pelvis
    add(cylinder(1, (0, 0, 0), (0, 0, 0.5), 0.15, 0.17, ry_ratio=0.65), (0, 0, 1.0))   # torso
    add(ellipsoid(2, (0, 0, 0), (0.09, 0.1, 0.12)), (0.0, 0.0, 1.68))                  # head
    label = 3
    for side in (1.0, -1.0):
        shoulder = np.array([0.2 * side, 0.0, 1.45])
        elbow = shoulder + (0.06 * side, -0.08, -0.27)
        wrist = elbow + (0.02 * side, -0.2, -0.16)
        hip = np.array([0.09 * side, 0.0, 0.92])
        knee = hip + (0.01 * side, -0.04, -0.42)
        ankle = knee + (0.0, 0.03, -0.42)
        for a, b, r0, r1 in ((shoulder, elbow, 0.05, 0.04), (elbow, wrist, 0.04, 0.03),
                             (hip, knee, 0.08, 0.055), (knee, ankle, 0.055, 0.04)):
            add(cylinder(label, (0, 0, 0), b - a, r0, r1), a)
            label += 1
        add(ellipsoid(label, (0, -0.05, 0), (0.03, 0.06, 0.02)), wrist)                # hand
        add(ellipsoid(label + 1, (0, -0.06, -0.04), (0.045, 0.11, 0.04)), ankle)       # foot
        label += 2
    seg2world = np.stack([np.eye(4)] * len(prims))
    seg2world[:, :3, 3] = joints
    return Primitives.concat(prims), seg2world


def camera(width, height):
    f = 460.0 * width / 640
    R, t = look_at((0.7, -1.9, 1.0), (0.0, 0.0, 0.9))
    K = [[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]]
    return PinholeCamera(f"cam{width}", (width, height), K, R=R, t=t)


def timing(fn):
    """Median and minimum milliseconds per call; the minimum shows the cost on a quiet
    machine when other work shares the cores."""
    fn()
    times = []
    for _ in range(RUNS):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return f"{1e3 * np.median(times):6.2f} ({1e3 * np.min(times):5.2f})"


def main():
    prims, seg2world = body()
    rng = np.random.default_rng(2345)
    print(f"render(): {len(prims)} primitives; ms per view, median (min) of {RUNS} runs")
    print(f"{'view':>9} {'covered px':>11} {'label+depth':>15} {'all outputs':>15} "
          f"{'2000 points':>15}")
    for width, height in ((640, 480), (320, 240)):
        cam = camera(width, height)
        covered = int((render(cam, seg2world, prims, want=()).label >= 0).sum())
        basic = timing(lambda: render(cam, seg2world, prims, want=()))
        full = timing(lambda: render(cam, seg2world, prims))
        uv = rng.uniform((0, 0), (width - 1, height - 1), size=(2000, 2))
        sparse = timing(lambda: render_points(cam, seg2world, prims, uv))
        print(f"{width:>4}x{height:<4} {covered:>11} {basic:>15} {full:>15} {sparse:>15}")


if __name__ == "__main__":
    main()
