"""``zoopraxis demo``: the whole pipeline on the bundled sample, headless.

Markers (the sample's clicked joints) -> initialization -> tracking -> bake into a .blend, BVH and
FBX -> a contact sheet of the fitted body over the plates, all into one output folder, and the
accuracy against the sample's ground truth printed at the end.
"""

import argparse
import importlib
import subprocess
import sys
from pathlib import Path

from ..errors import ZoopraxisError

SAMPLE = Path(__file__).resolve().parents[2] / "samples" / "walk3"


def build_parser():
    p = argparse.ArgumentParser(
        prog="zoopraxis demo",
        description="Track the bundled three-camera sample and bake it: writes result.json, "
                    "take.blend, take.bvh, take.fbx and contact_sheet.png.")
    p.add_argument("--sample", default=str(SAMPLE), help="take folder (default: the bundled "
                                                         "samples/walk3)")
    p.add_argument("--out", default="out/sample", help="output folder (default out/sample)")
    p.add_argument("--force", action="store_true", help="replace the outputs of an earlier run")
    return p


def main(argv):
    import cv2
    import numpy as np

    from . import track as cli_track
    from ..imaging import plates
    from ..synthetic import synth
    from ..files.calibfile import read_calibration
    from ..imaging.contact_sheet import contact_sheet
    from ..files.result import read_result

    args = build_parser().parse_args(argv)
    sample = Path(args.sample)
    for name in ("calibration.json", "markers.json"):
        if not (sample / name).is_file():
            raise ZoopraxisError(f"{sample}: not a take folder (no {name})")
    cameras = read_calibration(sample / "calibration.json")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    outputs = {k: out / v for k, v in (("result", "result.json"), ("blend", "take.blend"),
                                       ("bvh", "take.bvh"), ("fbx", "take.fbx"),
                                       ("sheet", "contact_sheet.png"))}
    if not args.force:
        for path in outputs.values():
            if path.exists():
                raise ZoopraxisError(f"{path}: exists from an earlier run (use --force)")
    force = ["--force"] if args.force else []

    print(f"demo: tracking {sample} ({len(cameras)} views)", flush=True)
    argv_track = [a for v in cameras for a in ("--plate", f"{v}={sample / v}")]
    argv_track += ["--markers", str(sample / "markers.json"),
                   "--calibration", str(sample / "calibration.json"),
                   "--out", str(outputs["result"])] + force
    code = cli_track.main(argv_track)
    if code:
        return code

    print("demo: baking onto an armature and exporting", flush=True)
    argv_bake = ["--result", str(outputs["result"]), "--blend", str(outputs["blend"]),
                 "--bvh", str(outputs["bvh"]), "--fbx", str(outputs["fbx"])] + force
    package = __package__.rsplit(".", 2)[0]  # the package above core.commands
    if "bpy" in sys.modules:
        # Inside Blender: the bake command runs here, through the root command table (core never
        # imports the add-on itself).
        code = importlib.import_module(package + ".cli").main(["bake", *argv_bake])
    else:
        # A fresh process: importing bpy starts a whole Blender session, kept apart from ours.
        code = subprocess.call([sys.executable, "-m", package, "bake", *argv_bake])
    if code:
        return code

    result = read_result(outputs["result"])
    opened = {v: plates.open_plate(sample / v, name=v) for v in cameras}
    sheet = contact_sheet(opened, result, cameras=cameras, columns=6, cell_width=240)
    cv2.imwrite(str(outputs["sheet"]), sheet)
    print(f"demo: contact sheet -> {outputs['sheet']}")

    truth_path = sample / "truth.json"
    if truth_path.is_file():
        truth = synth.read_truth(truth_path)
        true = truth["joints3d"][result.frames]
        err = 1000 * np.linalg.norm(result.joints3d - true, axis=2)
        print(f"demo: against the ground truth: MPJPE {err.mean():.1f} mm "
              f"(worst frame {err.mean(axis=1).max():.1f} mm), "
              f"{result.status.count('lost')} lost frames")
    print("demo: wrote " + ", ".join(str(p) for p in outputs.values()))
    return 0
