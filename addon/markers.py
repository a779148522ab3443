"""Joint markers as clip tracks: a stick figure to drag into place, anchors, markers.json.

Each view's clip holds one track per standard joint, named by the joint, in the clip's camera
tracking object. Keyed, unmuted markers are anchors: the first frame poses the body, later ones
correct the tracker. Tracks the user made are never changed; a joint track that exists is kept.

Convention: take frame ``f`` of a view with offset ``o`` is plate frame ``f + o``, which is clip
frame ``f + o + 1`` (Blender numbers clip frames from 1). Marker positions are converted with
:func:`convert.clip_from_pixels` / :func:`convert.pixels_from_clip`.
"""

import numpy as np

from ..core.body.body import make_body
from ..core.errors import ZoopraxisError
from ..core.body.joints import JOINT_INDEX, STANDARD_JOINTS
from ..core.files.markers import Anchor, read_markers, write_markers
from . import convert

# Height of the stick figure laid out for dragging, as a fraction of the frame height.
_FIGURE_HEIGHT = 0.6


def clip_frame(view, take_frame):
    return int(take_frame) + view.offset + 1


def take_frame(view, frame_of_clip):
    return int(frame_of_clip) - 1 - view.offset


def stick_figure(image_size, center=(0.5, 0.5)):
    """Normalized clip positions of the 17 joints of a standing figure facing the camera.

    The default body's reference configuration seen from the front (the subject's left on
    the image right), its arms spread a little so no marker hides another.

    Returns
    -------
    co : dict of str to (float, float)
    """
    body = make_body("full")
    pts = {j: body.reference_point(j) for j in STANDARD_JOINTS}
    for side, sx in (("l", 1.0), ("r", -1.0)):
        shoulder = pts[f"{side}_shoulder"]
        for j, k in (("elbow", 1.0), ("wrist", 2.0)):
            pts[f"{side}_{j}"] = pts[f"{side}_{j}"] + [sx * 0.12 * k, 0, 0.02 * k]
        pts[f"{side}_shoulder"] = shoulder
        pts[f"{side}_toe"] = pts[f"{side}_ankle"] + [sx * 0.08, 0, -0.06]
    xz = np.array([[pts[j][0], pts[j][2]] for j in STANDARD_JOINTS])
    lo, hi = xz.min(axis=0), xz.max(axis=0)
    w, h = image_size
    scale = _FIGURE_HEIGHT / (hi[1] - lo[1])              # in units of frame height
    mid = (lo + hi) / 2
    x = center[0] + (xz[:, 0] - mid[0]) * scale * h / w
    y = center[1] + (xz[:, 1] - mid[1]) * scale
    return {j: (float(a), float(b)) for j, a, b in zip(STANDARD_JOINTS, x, y)}


def add_joint_tracks(clip, frame, *, report=print):
    """Add the joint tracks missing from ``clip``, with a marker at clip frame ``frame``.

    Returns
    -------
    added, kept : list of str
        Joints given a new track, and joints whose track was there already (left as it is).
    """
    tracks = clip.tracking.tracks
    layout = stick_figure(tuple(clip.size))
    added, kept = [], []
    for joint in STANDARD_JOINTS:
        if tracks.get(joint) is not None:
            kept.append(joint)
            continue
        track = tracks.new(name=joint, frame=frame)
        track.markers.find_frame(frame).co = layout[joint]
        added.append(joint)
    report(f"clip '{clip.name}': added {len(added)} joint tracks at frame {frame}"
           + (f", kept {len(kept)} existing" if kept else ""))
    return added, kept


def _keyed_markers(track):
    return [m for m in track.markers if m.is_keyed and not m.mute]


def read_anchors(settings):
    """Anchors from the joint tracks of every view's clip, sorted by take frame.

    Returns
    -------
    anchors : list of Anchor
    """
    frames = {}
    for view in settings.views:
        clip = view.clip
        if clip is None:
            continue
        size = tuple(clip.size)
        for track in clip.tracking.tracks:
            if track.name not in JOINT_INDEX:
                continue
            for marker in _keyed_markers(track):
                f = take_frame(view, marker.frame)
                if f < 0:
                    continue
                u, v = convert.pixels_from_clip(marker.co, size)
                frames.setdefault(f, {}).setdefault(view.name, {})[track.name] = (
                    float(u), float(v))
    return [Anchor(f, frames[f]) for f in sorted(frames)]


def placement(settings, joint, frame):
    """Per view: 'KEY' a keyed marker at scene ``frame``, 'ELSEWHERE' keyed at other frames,
    'NONE' no marker of this joint."""
    out = []
    for view in settings.views:
        state = 'NONE'
        clip = view.clip
        track = clip.tracking.tracks.get(joint) if clip is not None else None
        if track is not None:
            keyed = _keyed_markers(track)
            if keyed:
                here = clip_frame(view, frame - settings.first_frame)
                state = 'KEY' if any(m.frame == here for m in keyed) else 'ELSEWHERE'
        out.append((view.name, state))
    return out


def export_markers(context, filepath, *, force=False, report=print):
    """Write the anchors of all views to markers.json."""
    settings = context.scene.zoopraxis
    anchors = read_anchors(settings)
    if not anchors:
        raise ZoopraxisError("no joint markers placed in any view: add the joint markers in "
                             "the Movie Clip Editor first")
    write_markers(filepath, anchors, force=force)
    settings.markers_path = str(filepath)
    report(f"wrote {len(anchors)} anchor frame(s) to {filepath}")
    return anchors


def import_markers(context, filepath, *, report=print):
    """Add the anchors of markers.json as keyed markers on the views' joint tracks.

    A joint with a keyed marker at that frame already keeps it (reported as skipped); views of
    the file that are not loaded are left out (and named in the report).

    Returns
    -------
    added, skipped : int
    """
    settings = context.scene.zoopraxis
    anchors = read_markers(filepath)
    named = sorted({v for a in anchors for v in a.views})
    loaded = [v for v in named if settings.view(v) is not None and settings.view(v).clip]
    if not loaded:
        raise ZoopraxisError(f"{filepath}: none of its views ({', '.join(named)}) is loaded "
                             f"(views: {', '.join(v.name for v in settings.views) or 'none'})")
    added = skipped = 0
    for a in anchors:
        for view_name, joints in a.views.items():
            if view_name not in loaded:
                continue
            view = settings.view(view_name)
            clip = view.clip
            size = tuple(clip.size)
            frame = clip_frame(view, a.frame)
            for joint, uv in joints.items():
                co = tuple(convert.clip_from_pixels(uv, size).tolist())
                track = clip.tracking.tracks.get(joint)
                if track is None:
                    track = clip.tracking.tracks.new(name=joint, frame=frame)
                    track.markers.find_frame(frame).co = co
                    added += 1
                    continue
                existing = track.markers.find_frame(frame)
                if existing is not None and existing.is_keyed:
                    skipped += 1
                    continue
                track.markers.insert_frame(frame, co=co)
                added += 1
    settings.markers_path = str(filepath)
    unloaded = [v for v in named if v not in loaded]
    report(f"imported {added} marker(s) from {filepath}"
           + (f"; kept {skipped} already placed" if skipped else "")
           + (f"; views not loaded: {', '.join(unloaded)}" if unloaded else ""))
    return added, skipped
