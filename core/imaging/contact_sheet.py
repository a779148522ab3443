"""Contact sheets: the fitted body drawn over the plates, a grid of frames by views.

Each cell shows one plate frame with the model's support map tinted over it, its outline, and
the stick figure of the 17 joints (left side blue, right side red, as usual in mocap tools),
with the frame number and status. It is how a person checks a track at a glance, and the
benchmark output kept for the real footage.
"""

import cv2
import numpy as np

from ..body.body import Pose, make_body
from ..body.joints import JOINT_INDEX, STICK_BONES
from .render import render

_STATUS_COLOUR = {"ok": (80, 200, 80), "uncertain": (0, 200, 255), "lost": (0, 0, 255)}


def _bone_colour(a, b):
    if a.startswith("l_") or b.startswith("l_"):
        return (255, 140, 40)
    if a.startswith("r_") or b.startswith("r_"):
        return (40, 40, 255)
    return (40, 230, 230)


def draw_overlay(image, joints2d, label=None, text=None, status=None):
    """Draw the fit over one image (BGR uint8; a copy is returned).

    Parameters
    ----------
    joints2d : array, shape (17, 2)
        In the image's pixels.
    label : array, shape (H, W), optional
        Rendered support map of the model in this view (-1 background).
    """
    out = image.copy()
    scale = max(1, round(max(out.shape[:2]) / 500))
    if label is not None:
        fg = label >= 0
        tint = np.zeros_like(out)
        tint[fg] = (0, 255, 255)
        out = np.where(fg[..., None], (0.65 * out + 0.35 * tint).astype(np.uint8), out)
        edge = fg & ~(cv2.erode(fg.astype(np.uint8), np.ones((3, 3), np.uint8)) > 0)
        out[edge] = (0, 255, 255)
    pts = np.asarray(joints2d, float)
    for a, b in STICK_BONES:
        pa, pb = pts[JOINT_INDEX[a]], pts[JOINT_INDEX[b]]
        if np.all(np.isfinite([pa, pb])):
            cv2.line(out, tuple(np.rint(pa).astype(int)), tuple(np.rint(pb).astype(int)),
                     _bone_colour(a, b), scale + 1, cv2.LINE_AA)
    for p in pts:
        if np.all(np.isfinite(p)):
            cv2.circle(out, tuple(np.rint(p).astype(int)), scale + 2, (255, 255, 255), -1,
                       cv2.LINE_AA)
    if text:
        colour = _STATUS_COLOUR.get(status, (255, 255, 255))
        cv2.putText(out, text, (6, 20 * scale), cv2.FONT_HERSHEY_SIMPLEX, 0.55 * scale,
                    (0, 0, 0), 3 * scale, cv2.LINE_AA)
        cv2.putText(out, text, (6, 20 * scale), cv2.FONT_HERSHEY_SIMPLEX, 0.55 * scale,
                    colour, scale, cv2.LINE_AA)
    return out


def _crop_box(points, image_size, margin=0.25, aspect=0.75):
    """Box around all given points (N, 2) with a margin, of a fixed height/width ratio."""
    pts = points[np.all(np.isfinite(points), axis=1)]
    w, h = image_size
    if len(pts) == 0:
        return 0, 0, w, h
    (x0, y0), (x1, y1) = pts.min(0), pts.max(0)
    bh = (y1 - y0) * (1 + 2 * margin) + 20
    bw = max((x1 - x0) * (1 + 2 * margin) + 20, bh / aspect * 0.5)
    bh = max(bh, bw * aspect)
    bw = bh / aspect
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    bw, bh = min(bw, w), min(bh, h)
    x0 = int(np.clip(cx - bw / 2, 0, w - bw))
    y0 = int(np.clip(cy - bh / 2, 0, h - bh))
    return x0, y0, int(x0 + bw), int(y0 + bh)


def contact_sheet(plates, result, *, cameras=None, frames=None, columns=6, cell_width=320,
                  offsets=None, crop=True):
    """Grid image of plates with the tracked body over them.

    Parameters
    ----------
    plates : dict of str to Plate
    result : TrackResult
    cameras : dict of str to camera, optional
        When given (calibrated takes), the model's support map is rendered and tinted.
    frames : list of int, optional
        Frames to show (default: ``columns`` evenly spread over the result).
    crop : bool or "each"
        Crop every cell of a view to the box around the body over the frames shown, or with
        "each", every cell to the body in its own frame (for a subject crossing the view).
    """
    offsets = offsets or {}
    if frames is None:
        idx = np.unique(np.linspace(0, result.num_frames - 1, columns).astype(int))
        frames = [int(result.frames[i]) for i in idx]
    index = {int(f): i for i, f in enumerate(result.frames)}
    body = None
    if cameras is not None and result.body is not None and result.angles is not None:
        body = make_body(result.body["template"], result.body["dims"],
                         shapes=result.body.get("shapes"))
    rows = []
    for view, plate in plates.items():
        box = None
        if crop and crop != "each":
            shown = np.concatenate([result.joints2d[view][index[f]] for f in frames])
            box = _crop_box(shown, plate.image_size)
        cells = []
        for f in frames:
            i = index[f]
            image = plate.read(f + offsets.get(view, 0))
            label = None
            if body is not None and view in cameras:
                pose = Pose(result.roots[i], result.angles[i])
                label = render(cameras[view], body.seg2world(pose), body.primitives(),
                               want=()).label
            status = result.status[i]
            cell = draw_overlay(image, result.joints2d[view][i], label, None, status)
            if crop == "each":
                box = _crop_box(result.joints2d[view][i], plate.image_size, margin=0.35)
            if box is not None:
                cell = cell[box[1]:box[3], box[0]:box[2]]
            cell = draw_overlay(cell, np.full((17, 2), np.nan), None, f"{view} {f} {status}",
                                status)
            h, w = cell.shape[:2]
            cells.append(cv2.resize(cell, (cell_width, int(round(h * cell_width / w))),
                                    interpolation=cv2.INTER_AREA))
        for k in range(0, len(cells), columns):
            row = cells[k:k + columns]
            while len(row) < min(columns, len(cells)):   # pad a short last row
                row.append(np.zeros_like(cells[0]))
            rows.append(np.hstack(row))
    return np.vstack(rows)
