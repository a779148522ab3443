"""markers.json: the animator's clicked joints, per anchor frame and view (DESIGN, Files).

.. code-block:: json

    {"anchors": [{"frame": 0, "views": {"cam0": {"l_knee": [412.5, 300.0]}}}]}

Pixels are OpenCV's (origin at the centre of the top-left pixel, y down). Any subset of the
17 standard joints may be given per view; a joint that is not clicked is simply absent.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ZoopraxisError
from .inputs import read_json
from ..body.joints import JOINT_INDEX, STANDARD_JOINTS
from .outputs import write_text


@dataclass
class Anchor:
    """Clicked joints of one frame.

    Attributes
    ----------
    frame : int
        Take frame index (0-based).
    views : dict of str to dict of str to (float, float)
        ``views[view][joint] = (u, v)`` in pixels.
    """

    frame: int
    views: dict = field(default_factory=dict)

    def array(self, view):
        """Clicked joints of one view as (17, 2) with NaN where a joint isn't clicked."""
        out = np.full((len(STANDARD_JOINTS), 2), np.nan)
        for name, uv in self.views.get(view, {}).items():
            out[JOINT_INDEX[name]] = uv
        return out

    def joint_count(self, view):
        return len(self.views.get(view, {}))


def _fail(path, message):
    raise ZoopraxisError(f"{path}: {message}")


# No camera has a pixel this far out; such a number is a broken file, not a click.
MAX_PIXEL = 1e6


def _pixel(uv, where, path):
    """A click ``[u, v]`` as two floats: a list of two real numbers (a string such as "12" is
    not two digits), finite and within :data:`MAX_PIXEL`."""
    numbers = isinstance(uv, list) and len(uv) == 2 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) for x in uv)
    if not numbers:
        _fail(path, f"{where}: expected [u, v] pixels, got {_short(uv)}")
    try:
        u, v = float(uv[0]), float(uv[1])
    except OverflowError:
        u = v = np.inf
    if not (np.isfinite(u) and np.isfinite(v)):
        _fail(path, f"{where}: not finite")
    if max(abs(u), abs(v)) > MAX_PIXEL:
        _fail(path, f"{where}: [{u:g}, {v:g}] is no pixel of any image")
    return u, v


def _short(value):
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def parse_markers(data, path="markers.json"):
    """Validate the decoded JSON of a markers file and return a list of :class:`Anchor`.

    Anchors come back sorted by frame; a frame given twice is an error.
    """
    if not isinstance(data, dict):
        _fail(path, "expected a JSON object with an 'anchors' list")
    if "anchors" not in data:
        _fail(path, "missing required key 'anchors'")
    anchors = data["anchors"]
    if not isinstance(anchors, list):
        _fail(path, "'anchors' must be a list")
    out = {}
    for i, a in enumerate(anchors):
        where = f"anchor {i}"
        if not isinstance(a, dict):
            _fail(path, f"{where} must be an object with 'frame' and 'views'")
        for key in ("frame", "views"):
            if key not in a:
                _fail(path, f"{where}: missing required key '{key}'")
        frame = a["frame"]
        if not isinstance(frame, int) or isinstance(frame, bool) or not 0 <= frame < 2 ** 31:
            _fail(path, f"{where}: 'frame' must be a whole number >= 0, got {_short(frame)}")
        if frame in out:
            _fail(path, f"frame {frame} has two anchors")
        views = {}
        if not isinstance(a["views"], dict):
            _fail(path, f"frame {frame}: 'views' must map view names to joints")
        for view, joints in a["views"].items():
            if not isinstance(joints, dict):
                _fail(path, f"frame {frame}, view '{view}': expected joint -> [u, v]")
            clicked = {}
            for name, uv in joints.items():
                if name not in JOINT_INDEX:
                    _fail(path, f"frame {frame}, view '{view}': unknown joint '{name}'")
                clicked[name] = _pixel(uv, f"frame {frame}, view '{view}', joint '{name}'",
                                       path)
            views[view] = clicked
        out[frame] = Anchor(frame, views)
    return [out[f] for f in sorted(out)]


def read_markers(path):
    """Read markers.json into a list of :class:`Anchor` sorted by frame."""
    path = Path(path)
    return parse_markers(read_json(path, "markers file"), path)


def markers_to_json(anchors):
    """The JSON object of a markers file for a list of anchors."""
    return {"anchors": [{"frame": int(a.frame),
                         "views": {v: {j: [round(float(u), 3), round(float(w), 3)]
                                       for j, (u, w) in joints.items()}
                                   for v, joints in a.views.items()}}
                        for a in sorted(anchors, key=lambda a: a.frame)]}


def write_markers(path, anchors, *, force=False):
    """Write markers.json; refuses to replace an existing file unless ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    write_text(path, json.dumps(markers_to_json(anchors), indent=1))


def check_markers(anchors, view_names, num_frames=None, path="markers.json", min_joints=6,
                  image_sizes=None):
    """Check markers against the take: known views, frames inside it, enough joints, and
    (given ``image_sizes``, view -> (width, height)) clicks on or near the images.

    Every joint must be clicked in at least one view of the first anchor, and at least one
    view must have ``min_joints`` joints there to pose the body (DESIGN). A joint may be
    clicked a little outside its image (a hand leaving the frame), not half an image away.
    """
    if not anchors:
        raise ZoopraxisError(f"{path}: no anchors: click the joints on a first frame")
    views = set(view_names)
    for a in anchors:
        for view in a.views:
            if view not in views:
                raise ZoopraxisError(f"{path}: frame {a.frame}: view '{view}' is not one of "
                                     f"the plates ({', '.join(view_names)})")
        if num_frames is not None and a.frame >= num_frames:
            raise ZoopraxisError(f"{path}: anchor frame {a.frame} is outside the take "
                                 f"(frames 0-{num_frames - 1})")
        for view, joints in a.views.items():
            if image_sizes is None or view not in image_sizes:
                continue
            w, h = image_sizes[view]
            for name, (u, v) in joints.items():
                if not (-w / 2 <= u <= 1.5 * w and -h / 2 <= v <= 1.5 * h):
                    raise ZoopraxisError(
                        f"{path}: frame {a.frame}, view '{view}', joint '{name}': "
                        f"({u:g}, {v:g}) is far outside the {w}x{h} image")
    first = anchors[0]
    if max((first.joint_count(v) for v in view_names), default=0) < min_joints:
        raise ZoopraxisError(f"{path}: frame {first.frame}: no view has at least {min_joints} "
                             "joints clicked, too few to pose the body")
    seen = set()
    for v in view_names:
        seen |= set(first.views.get(v, {}))
    missing = [j for j in STANDARD_JOINTS if j not in seen]
    if missing:
        raise ZoopraxisError(f"{path}: frame {first.frame}: joint '{missing[0]}' is marked in "
                             "no view")


def uncalibrated_views(anchors, view_names, path="markers.json", min_joints=4):
    """The views an uncalibrated track can follow, and warnings about the others.

    Without a calibration each view's camera is placed from its own clicks, so a view needs
    ``min_joints`` joints clicked at the first anchor (a view where the person is hidden there
    is left out, with a warning) and, once kept, at every later anchor.

    Returns
    -------
    views : list of str
        The views to track, in the order given.
    warnings : list of str

    Raises
    ------
    ZoopraxisError
        No view can be placed, or a kept view has too few joints at a later anchor, naming
        the frame and the view.
    """
    first = anchors[0]
    kept = [v for v in view_names if first.joint_count(v) >= min_joints]
    if not kept:
        raise ZoopraxisError(f"{path}: frame {first.frame}: no view has {min_joints} joints "
                             "clicked, too few to place an uncalibrated view")
    warnings = [f"{path}: frame {first.frame}: view '{v}' has {first.joint_count(v)} joints "
                f"clicked (an uncalibrated view needs {min_joints}); it is left out of the track"
                for v in view_names if v not in kept]
    for anchor in anchors[1:]:
        for v in kept:
            if anchor.joint_count(v) < min_joints:
                raise ZoopraxisError(
                    f"{path}: frame {anchor.frame}: view '{v}' has {anchor.joint_count(v)} "
                    f"joints clicked; an uncalibrated view needs {min_joints} at every anchor "
                    "(click the joints you can place there)")
    return kept, warnings


def only_views(anchors, views):
    """The anchors with the clicks of ``views`` only."""
    return [Anchor(a.frame, {v: dict(j) for v, j in a.views.items() if v in views})
            for a in anchors]
