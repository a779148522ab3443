"""What a finished job leaves in the scene: result files, the baked take, the fit's preview.

A tracking run writes its result.json under a fresh name (never over an earlier run's), bakes
it onto a new armature with status and residual keyed per frame, and marks lost frames on the
timeline (see :mod:`bake`).
"""

import tempfile
from pathlib import Path

import bpy
import numpy as np

from ..core.body.joints import STANDARD_JOINTS
from ..core.files.result import TrackResult, write_result


def output_folder():
    """``//zoopraxis`` beside the saved .blend file, else a folder in the temporary directory."""
    if bpy.data.filepath:
        return Path(bpy.path.abspath("//zoopraxis"))
    return Path(tempfile.gettempdir()) / "zoopraxis"


def fresh_path(folder, stem="result", suffix=".json"):
    """``folder/stem.json``, or ``stem.001.json``, ... : the first name not taken."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"{stem}{suffix}"
    i = 0
    while path.exists():
        i += 1
        path = folder / f"{stem}.{i:03d}{suffix}"
    return path


def apply_result(context, result, cancelled=False, *, report=print):
    """Write a tracking result, bake it and return a one-line summary."""
    from .bake import bake

    settings = context.scene.zoopraxis
    path = fresh_path(output_folder())
    write_result(path, result)
    settings.result_path = str(path)
    obj, action = bake(context, result, name=path.stem, body_mesh=settings.body_mesh,
                       report=report)
    counts = {s: result.status.count(s) for s in ("ok", "uncertain", "lost")}
    done = "Stopped after" if cancelled else "Tracked"
    return (f"{done} {result.num_frames} frames: {counts['ok']} ok, {counts['uncertain']} "
            f"uncertain, {counts['lost']} lost -> {path.name}, action '{action.name}'")


def result_from_initial(init, take):
    """A result of the anchor frames of an initialization, to show the fitted body.

    Uncalibrated poses live in a body-centred frame: the preview stands at the origin.
    """
    body = init.body
    frames = sorted(init.poses)
    roots = np.stack([init.poses[f].root for f in frames])
    angles = np.stack([init.poses[f].angles for f in frames])
    X = body.joints(roots, angles)
    n, j = len(frames), len(STANDARD_JOINTS)
    views = list(take.plates) if take is not None else []
    return TrackResult(
        mode="calibrated" if init.calibrated else "uncalibrated",
        fps=getattr(take, "fps", 30.0), frames=np.array(frames), joints3d=X,
        joints2d={v: np.full((n, j, 2), np.nan) for v in views},
        residual={v: np.array([float(init.rms.get(v, 0.0))] * n) for v in views},
        status=["ok"] * n,
        body={"template": body.template, "shapes": body.shapes, "dims": dict(body.dims),
              "dof_names": list(body.dof_names)},
        roots=roots, angles=angles)
