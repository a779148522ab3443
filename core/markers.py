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

from .errors import ZoopraxisError
from .joints import JOINT_INDEX, STANDARD_JOINTS


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
        if not isinstance(frame, int) or isinstance(frame, bool) or frame < 0:
            _fail(path, f"{where}: 'frame' must be a whole number >= 0, got {frame!r}")
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
                try:
                    u, v = (float(x) for x in uv)
                except (TypeError, ValueError):
                    _fail(path, f"frame {frame}, view '{view}', joint '{name}': "
                                f"expected [u, v] pixels, got {uv!r}")
                if not (np.isfinite(u) and np.isfinite(v)):
                    _fail(path, f"frame {frame}, view '{view}', joint '{name}': not finite")
                clicked[name] = (u, v)
            views[view] = clicked
        out[frame] = Anchor(frame, views)
    return [out[f] for f in sorted(out)]


def read_markers(path):
    """Read markers.json into a list of :class:`Anchor` sorted by frame."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such markers file") from None
    except OSError as exc:
        raise ZoopraxisError(f"{path}: cannot read ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ZoopraxisError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    return parse_markers(data, path)


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
    path.write_text(json.dumps(markers_to_json(anchors), indent=1))


def check_markers(anchors, view_names, num_frames=None, path="markers.json", min_joints=6):
    """Check markers against the take: known views, frames inside it, enough joints.

    Every joint must be clicked in at least one view of the first anchor, and at least one
    view must have ``min_joints`` joints there to pose the body (DESIGN).
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
