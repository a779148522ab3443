"""Real footage: the side-on walk of sports2d/walk_and_jumps.mp4, one uncalibrated view.

The markers in benchmarks/real/walk_markers.json were placed once on frame 80, by eye, as an
animator would. The walker crosses the view from right to left in frames 80-175. Prints a
table (frames, status counts, silhouette fit, frames per second) with the shipped pose prior
and with one learned from CMU walks (``zoopraxis prior``; it decides the depth of the limbs at
the one-view anchor), and writes a contact sheet of the fitted body (shipped prior) over the
plate to benchmarks/output/real_walk_sheet.png.

    .venv/bin/python benchmarks/bench_real.py
"""

import os
import sys
import tempfile
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from zoopraxis.core.files import markers  # noqa: E402
from zoopraxis.core.imaging import plates  # noqa: E402
from zoopraxis.core.imaging.contact_sheet import contact_sheet  # noqa: E402
from zoopraxis.core.take.track import track  # noqa: E402

HERE = Path(__file__).resolve().parent
DATA = Path(os.environ.get("ZOOPRAXIS_SHARED_DATA", HERE.parents[1] / "shared" / "data"))
FRAMES = range(80, 176)


def _ranges(frames):
    """'3-5, 9' from [3, 4, 5, 9]."""
    out, start = [], None
    for i, f in enumerate(frames):
        if start is None:
            start = f
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            out.append(f"{start}" if start == f else f"{start}-{f}")
            start = None
    return ", ".join(out) or "none"


def walking_prior(folder):
    """The pose prior file ``zoopraxis prior`` writes from subject 131's walks (131_01-03),
    for frames clicked in one view: what an animator with a library of walks would use."""
    from zoopraxis import cli

    path = Path(folder) / "walks.npz"
    takes = [str(DATA / "cmu_mocap" / f"{name}.bvh") for name in ("131_01", "131_02", "131_03")]
    if cli.main(["prior", *takes, "--out", str(path)]) != 0:
        sys.exit("zoopraxis prior failed (see above)")
    return path


def main():
    video = DATA / "sports2d" / "walk_and_jumps.mp4"
    if not video.is_file():
        sys.exit(f"no footage at {video} (set ZOOPRAXIS_SHARED_DATA)")
    plate = plates.open_plate(video, name="cam0")
    anchors = markers.read_markers(HERE / "real" / "walk_markers.json")
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for label, prior in (("walk side-on", "default"),
                             ("+ prior of walks", walking_prior(folder))):
            t0 = time.perf_counter()
            run = track({"cam0": plate}, anchors, None, frames=FRAMES, log=print,
                        pose_prior=prior)
            elapsed = time.perf_counter() - t0
            fit = np.array(run.extra["silhouette_fit"])[:, 0]
            print(f"{label}:")
            for status in ("lost", "uncertain"):
                frames = [int(f) for f, s in zip(run.frames, run.status) if s == status]
                print(f"  {status}: {_ranges(frames)}")
            fit = fit[fit >= 0]
            rows.append(f"{label:<18}{run.num_frames:>7}{run.status.count('ok'):>5}"
                        f"{run.status.count('uncertain'):>7}{run.status.count('lost'):>5}"
                        f"{fit.mean():>6.2f}{run.num_frames / elapsed:>6.1f}")
            if prior == "default":
                result = run
    print(f"{'footage':<18}{'frames':>7}{'ok':>5}{'uncert':>7}{'lost':>5}{'fit':>6}{'fps':>6}")
    print("\n".join(rows))
    out = HERE / "output"
    out.mkdir(exist_ok=True)
    sheet = contact_sheet({"cam0": plate}, result, frames=list(FRAMES)[::8], columns=6,
                          cell_width=200, crop="each")
    cv2.imwrite(str(out / "real_walk_sheet.png"), sheet)
    print(f"contact sheet: {out / 'real_walk_sheet.png'}")


if __name__ == "__main__":
    main()
