"""Real footage: the side-on walk of sports2d/walk_and_jumps.mp4, one uncalibrated view.

The markers in benchmarks/real/walk_markers.json were placed once on frame 80, by eye, as an
animator would. The walker crosses the view from right to left in frames 80-175. Prints a
table (frames, status counts, silhouette fit, frames per second) and writes a contact sheet of
the fitted body over the plate to benchmarks/output/real_walk_sheet.png.

    .venv/bin/python benchmarks/bench_real.py
"""

import os
import sys
import time
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from zoopraxis.core import markers, plates  # noqa: E402
from zoopraxis.core.contact_sheet import contact_sheet  # noqa: E402
from zoopraxis.core.track import track  # noqa: E402

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


def main():
    video = DATA / "sports2d" / "walk_and_jumps.mp4"
    if not video.is_file():
        sys.exit(f"no footage at {video} (set ZOOPRAXIS_SHARED_DATA)")
    plate = plates.open_plate(video, name="cam0")
    anchors = markers.read_markers(HERE / "real" / "walk_markers.json")
    t0 = time.perf_counter()
    result = track({"cam0": plate}, anchors, None, frames=FRAMES, log=print)
    elapsed = time.perf_counter() - t0
    fit = np.array(result.extra["silhouette_fit"])[:, 0]
    for status in ("lost", "uncertain"):
        frames = [int(f) for f, s in zip(result.frames, result.status) if s == status]
        print(f"{status}: {_ranges(frames)}")
    fit = fit[fit >= 0]
    print(f"{'footage':<16}{'frames':>7}{'ok':>5}{'uncert':>7}{'lost':>5}{'fit':>6}{'fps':>6}")
    print(f"{'walk side-on':<16}{result.num_frames:>7}{result.status.count('ok'):>5}"
          f"{result.status.count('uncertain'):>7}{result.status.count('lost'):>5}"
          f"{fit.mean():>6.2f}{result.num_frames / elapsed:>6.1f}")
    out = HERE / "output"
    out.mkdir(exist_ok=True)
    sheet = contact_sheet({"cam0": plate}, result, frames=list(FRAMES)[::8], columns=6,
                          cell_width=200, crop="each")
    cv2.imwrite(str(out / "real_walk_sheet.png"), sheet)
    print(f"contact sheet: {out / 'real_walk_sheet.png'}")


if __name__ == "__main__":
    main()
