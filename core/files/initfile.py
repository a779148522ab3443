"""The result of an initialization (:class:`InitResult`) and its file, init.json
(``zoopraxis-init/1``): written by ``zoopraxis init`` and the add-on, read to track from."""

from dataclasses import dataclass, field

import numpy as np

from ..body.body import LENGTH_DIMS, Pose, make_body
from ..body.joints import STANDARD_JOINTS
from ..errors import ZoopraxisError
from ..geometry.ortho import ScaledOrthoCamera


@dataclass
class InitResult:
    """An initialized take: what :func:`initialize.run.initialize` found, or the poses a track
    is started from (then only ``body``, ``poses`` and ``cameras`` need be given).

    Attributes
    ----------
    body : BodyModel
        The template with the fitted dimensions (lengths fitted; radii scaled with the size).
    poses : dict of int to Pose
        Per anchor frame. Calibrated: world poses. Uncalibrated: root at the identity (a
        body-centred frame) and the angles.
    cameras : dict of str to camera
        Calibrated: the given cameras. Uncalibrated: the fitted ScaledOrthoCamera of each view
        at the first anchor frame.
    view_cameras : dict of int to dict of str to ScaledOrthoCamera, or None
        Uncalibrated: the fitted camera of every view at every anchor frame (one pose per view).
    warnings : list of str
        One line each: swapped or outlying clicks, views left out, a mirrored pose that fits.
    errors : dict of int to dict of str to array, shape (17,)
        Click errors in pixels per frame and view, NaN where a joint was not clicked.
    rms : dict of str to float
        Root-mean-square click error per view over all anchors, pixels.
    ambiguous : bool
        A mirrored (depth-flipped) pose fits about as well for some anchor frame.
    calibrated : bool
        Perspective cameras known; by default, unless ``cameras`` are scaled orthographic.
    swapped : list of (int, str, str, str)
        ``(frame, view, joint, joint)`` click pairs fitted exchanged because they looked swapped.
    ambiguous_parts : dict of int to list of str
        Per anchor frame, the ``FLIP_PARTS`` that another depth would fit about as well: what
        the animator may flip (``initialize(..., flips=...)``) after judging the result by eye.
    flipped : dict of int to list of str
        The flips asked for and made, per anchor frame.
    notes : list of str
        One line each: what the animator may do for a better fit that is no fault of the
        clicks (``ONE_VIEW_LENGTHS_NOTE``).
    """

    body: object
    poses: dict
    cameras: dict
    view_cameras: dict = None
    warnings: list = field(default_factory=list)
    errors: dict = field(default_factory=dict)
    rms: dict = field(default_factory=dict)
    ambiguous: bool = False
    calibrated: bool = None
    swapped: list = field(default_factory=list)
    ambiguous_parts: dict = field(default_factory=dict)
    flipped: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def __post_init__(self):
        if self.calibrated is None:
            self.calibrated = not any(isinstance(c, ScaledOrthoCamera)
                                      for c in self.cameras.values())

    def flip_notes(self):
        """One line per anchor frame where parts were flipped in depth."""
        return [f"frame {frame}: flipped in depth: {', '.join(parts)}"
                for frame, parts in sorted(self.flipped.items())]

    def distance_note(self):
        """One line: each uncalibrated view's fitted camera distance at the first anchor
        (``perspective=True``; "far" where none was fitted)."""
        return "camera distance (m): " + ", ".join(
            f"{view} {1.0 / cam.kappa:.1f}" if getattr(cam, "kappa", 0.0) else f"{view} far"
            for view, cam in self.cameras.items())

    @property
    def dims(self):
        """Fitted lengths, ``{name: metres}`` over ``LENGTH_DIMS``."""
        return {name: self.body.dims[name] for name in LENGTH_DIMS}

    def joints3d(self, frame):
        """Model joints of an anchor frame, (17, 3): world (calibrated) or body frame."""
        return self.body.joints(self.poses[frame])

    def to_json(self):
        """The JSON object of an init.json file (``zoopraxis-init/1``)."""
        def clean(a):
            return [None if not np.isfinite(x) else round(float(x), 3) for x in a]

        cams = self.view_cameras or {f: self.cameras for f in self.poses}
        return {
            "format": "zoopraxis-init/1",
            "mode": "calibrated" if self.calibrated else "uncalibrated",
            "template": self.body.template,
            "dims": {k: round(float(v), 5) for k, v in self.body.dims.items()},
            "dof_names": list(self.body.dof_names),
            "joints": list(STANDARD_JOINTS),
            "anchors": [{
                "frame": int(f),
                "pose": [round(float(x), 6) for x in pose.to_vector()],
                "joints3d": np.round(self.joints3d(f), 5).tolist(),
                "views": {v: {"camera": cams[f][v].to_dict(),
                              "errors": clean(self.errors[f][v])}
                          for v in self.errors[f]},
            } for f, pose in sorted(self.poses.items())],
            "rms": {v: round(float(x), 3) for v, x in self.rms.items()},
            "warnings": list(self.warnings),
            "ambiguous": bool(self.ambiguous),
            "ambiguous_parts": {str(f): list(p) for f, p in sorted(self.ambiguous_parts.items())},
            "flipped": {str(f): list(p) for f, p in sorted(self.flipped.items())},
            "notes": list(self.notes),
        }


def read_init(path):
    """Read an init.json file into an :class:`InitResult` (:func:`init_from_json`).

    Raises
    ------
    ZoopraxisError
        Not a regular file, not JSON, or not a well-formed init.json, naming the file.
    """
    from ..files.inputs import read_json

    return init_from_json(read_json(path, "init file"), path)


def init_from_json(data, path="init.json"):
    """Rebuild an :class:`InitResult` from the JSON object of an init.json file.

    Raises
    ------
    ZoopraxisError
        A missing key, a wrong format or a value of the wrong type, naming the file.
    """
    try:
        return _init_from_json(data, path)
    except ZoopraxisError as error:
        if str(error).startswith(str(path)):
            raise
        raise ZoopraxisError(f"{path}: {error}") from None
    except (TypeError, ValueError, AttributeError, KeyError, IndexError, OverflowError) as error:
        raise ZoopraxisError(f"{path}: malformed init file ({type(error).__name__}: "
                             f"{str(error)[:80]})") from None


def _init_from_json(data, path):
    from .calibfile import camera_from_dict
    from ..files.plausible import check_body_dims

    if not isinstance(data, dict) or data.get("format") != "zoopraxis-init/1":
        raise ZoopraxisError(f"{path}: not a zoopraxis-init/1 file")
    for key in ("mode", "template", "dims", "anchors"):
        if key not in data:
            raise ZoopraxisError(f"{path}: missing required key '{key}'")
    if not isinstance(data["dims"], dict) or not isinstance(data["anchors"], list):
        raise ZoopraxisError(f"{path}: 'dims' must be an object and 'anchors' a list")
    check_body_dims(data["dims"], path)
    body = make_body(data["template"], data["dims"])
    poses, view_cameras, errors = {}, {}, {}
    for a in data["anchors"]:
        for key in ("frame", "pose", "views"):
            if key not in a:
                raise ZoopraxisError(f"{path}: an anchor misses key '{key}'")
        f = int(a["frame"])
        vector = np.asarray(a["pose"], float)
        if not np.all(np.isfinite(vector)):
            raise ZoopraxisError(f"{path}: frame {f}: pose holds NaN or infinity")
        if vector.shape != (6 + body.n_dofs,):
            raise ZoopraxisError(f"{path}: frame {f}: pose has {vector.size} numbers, the "
                                 f"'{body.template}' body needs {6 + body.n_dofs}")
        poses[f] = Pose.from_vector(vector)
        view_cameras[f] = {v: camera_from_dict(d["camera"], str(path))
                           for v, d in a["views"].items()}
        errors[f] = {v: np.array([np.nan if e is None else e for e in d.get("errors", [])],
                                 float) for v, d in a["views"].items()}
    calibrated = data["mode"] == "calibrated"
    first = min(poses) if poses else None
    return InitResult(body=body, poses=poses,
                      cameras=view_cameras[first] if first is not None else {},
                      view_cameras=None if calibrated else view_cameras, errors=errors,
                      rms=dict(data.get("rms", {})), warnings=list(data.get("warnings", [])),
                      ambiguous=bool(data.get("ambiguous", False)), calibrated=calibrated,
                      ambiguous_parts={int(f): list(p) for f, p in
                                       dict(data.get("ambiguous_parts", {})).items()},
                      flipped={int(f): list(p) for f, p in dict(data.get("flipped", {})).items()},
                      notes=[str(n) for n in data.get("notes", [])])
