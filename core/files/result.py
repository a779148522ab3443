"""result.json: what ``track`` writes and ``bake`` reads (DESIGN, Files).

Required keys: ``format`` ("zoopraxis-track/1"), ``mode``, ``fps``, ``joints``, ``frames``,
``joints3d`` [frame][joint][xyz] world metres, ``views`` {view: {joints2d, residual}} and
``status`` per frame (ok | uncertain | lost). This module adds the body (template, dimensions,
DOF names), the root pose and joint angles per frame, and optional per-parameter spread, so the
result can be baked onto an armature without re-fitting.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ZoopraxisError
from .inputs import read_json
from ..body.joints import STANDARD_JOINTS
from .outputs import write_text

FORMAT = "zoopraxis-track/1"
STATUSES = ("ok", "uncertain", "lost")
MODES = ("calibrated", "uncalibrated")


@dataclass
class TrackResult:
    """A tracked take.

    Attributes
    ----------
    mode : {"calibrated", "uncalibrated"}
    fps : float
    frames : array of int, shape (F,)
    joints3d : array, shape (F, 17, 3)
    joints2d : dict of str to array, shape (F, 17, 2)
    residual : dict of str to array, shape (F,)
    status : list of str, length F
    body : dict, optional
        ``{"template", "shapes", "dims", "dof_names"}`` of the fitted body.
    roots : array, shape (F, 4, 4), optional
        ``world_from_pelvis`` per frame (calibrated; body-centred frame when uncalibrated).
    angles : array, shape (F, n_dofs), optional
    spread : array, shape (F, 6 + n_dofs), optional
        Posterior standard deviation per pose parameter (particle filter).
    extra : dict
        Anything else to keep in the file (tracker settings, timings).
    """

    mode: str
    fps: float
    frames: np.ndarray
    joints3d: np.ndarray
    joints2d: dict
    residual: dict
    status: list
    body: dict = None
    roots: np.ndarray = None
    angles: np.ndarray = None
    spread: np.ndarray = None
    extra: dict = field(default_factory=dict)

    @property
    def num_frames(self):
        return len(self.frames)

    def to_json(self):
        def r(a, nd):
            return np.round(np.asarray(a, float), nd).tolist()

        data = {"format": FORMAT, "mode": self.mode, "fps": float(self.fps),
                "joints": list(STANDARD_JOINTS),
                "frames": [int(f) for f in self.frames],
                "joints3d": r(self.joints3d, 5),
                "views": {v: {"joints2d": r(self.joints2d[v], 3),
                              "residual": r(self.residual[v], 6)} for v in self.joints2d},
                "status": list(self.status)}
        if self.body is not None:
            data["body"] = self.body
        if self.roots is not None:
            data["roots"] = r(self.roots, 7)
        if self.angles is not None:
            data["angles"] = r(self.angles, 6)
        if self.spread is not None:
            data["spread"] = r(self.spread, 6)
        data.update(self.extra)
        return data


def write_result(path, result, *, force=False):
    """Write result.json atomically (:func:`outputs.write_text`); refuses to replace a file
    unless ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    return write_text(path, json.dumps(result.to_json()))


def _require(data, key, path):
    if key not in data:
        raise ZoopraxisError(f"{path}: missing required key '{key}'")
    return data[key]


def _numbers(value, shape, what, path):
    """``value`` as a finite float array of ``shape`` (None: any), else one line naming it."""
    try:
        with np.errstate(all="ignore"):
            a = np.asarray(value, float)
    except (TypeError, ValueError, OverflowError):
        raise ZoopraxisError(f"{path}: {what} must be an array of numbers (no strings, "
                             "every row the same length)") from None
    if shape is not None and a.shape != shape:
        raise ZoopraxisError(f"{path}: {what} has shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        index = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise ZoopraxisError(f"{path}: {what} holds NaN or infinity (at {list(index)})")
    return a


def _strings(value, what, path):
    if not isinstance(value, list) or not all(isinstance(x, str) for x in value):
        raise ZoopraxisError(f"{path}: '{what}' must be a list of strings")
    return value


def _check_body(body, path):
    """The result's body: known template and shapes, finite lengths of a person."""
    from ..body.body import DIM_NAMES, TEMPLATES
    from .plausible import check_body_dims, finite_number

    if not isinstance(body, dict):
        raise ZoopraxisError(f"{path}: 'body' must be an object")
    template = body.get("template", "full")
    if template not in TEMPLATES:
        raise ZoopraxisError(f"{path}: body template {template!r:.40} is not one of "
                             f"{', '.join(TEMPLATES)}")
    if body.get("shapes", "ellipsoid") not in ("ellipsoid", "cylinder"):
        raise ZoopraxisError(f"{path}: body shapes {body['shapes']!r:.40} are not ellipsoid "
                             "or cylinder")
    dims = body.get("dims", {})
    if not isinstance(dims, dict):
        raise ZoopraxisError(f"{path}: body 'dims' must map names to metres")
    for name, value in dims.items():
        if name not in DIM_NAMES:
            raise ZoopraxisError(f"{path}: unknown body dimension '{name}'")
        if not finite_number(value) or value < 0:
            raise ZoopraxisError(f"{path}: body dimension '{name}' must be a positive number, "
                                 f"got {value!r:.40}")
    check_body_dims(dims, path)
    if "dof_names" in body:
        _strings(body["dof_names"], "body dof_names", path)
    return body


def read_result(path):
    """Read and validate result.json into a :class:`TrackResult`.

    Raises
    ------
    ZoopraxisError
        Whatever is wrong with the file, naming it and the key, view or frame: not a regular
        file, not JSON, a missing key, a value of the wrong type or shape, NaN or infinity,
        a frame rate that is not positive, a body outside human range.
    """
    from .plausible import finite_number

    path = Path(path)
    data = read_json(path, "result file")
    if not isinstance(data, dict):
        raise ZoopraxisError(f"{path}: expected a JSON object")
    fmt = _require(data, "format", path)
    if fmt != FORMAT:
        raise ZoopraxisError(f"{path}: format {fmt!r:.40} is not '{FORMAT}'")
    mode = _require(data, "mode", path)
    if mode not in MODES:
        raise ZoopraxisError(f"{path}: mode {mode!r:.40} is not one of {', '.join(MODES)}")
    fps = _require(data, "fps", path)
    if not finite_number(fps) or not 0 < fps <= 10000:
        raise ZoopraxisError(f"{path}: 'fps' must be a positive number of frames per second, "
                             f"got {fps!r:.40}")
    names = _strings(_require(data, "joints", path), "joints", path)
    missing = [j for j in STANDARD_JOINTS if j not in names]
    if missing:
        raise ZoopraxisError(f"{path}: joint '{missing[0]}' is missing from 'joints'")
    order = [names.index(j) for j in STANDARD_JOINTS]
    frames = _require(data, "frames", path)
    if not isinstance(frames, list) or not all(
            isinstance(f, int) and not isinstance(f, bool) and 0 <= f < 2 ** 31 for f in frames):
        raise ZoopraxisError(f"{path}: 'frames' must be a list of frame numbers >= 0")
    frames = np.asarray(frames, dtype=int).reshape(-1)
    F = len(frames)
    joints3d = _numbers(_require(data, "joints3d", path), (F, len(names), 3), "'joints3d'", path)
    status = _strings(_require(data, "status", path), "status", path)
    if len(status) != F:
        raise ZoopraxisError(f"{path}: 'status' has {len(status)} entries for {F} frames")
    bad = [s for s in status if s not in STATUSES]
    if bad:
        raise ZoopraxisError(f"{path}: unknown status {bad[0]!r:.40} (expected ok, uncertain "
                             "or lost)")
    views = _require(data, "views", path)
    if not isinstance(views, dict):
        raise ZoopraxisError(f"{path}: 'views' must map view names to their joints2d and "
                             "residual")
    joints2d, residual = {}, {}
    for view, d in views.items():
        where = f"view '{view}'"
        if not isinstance(d, dict):
            raise ZoopraxisError(f"{path}: {where} must be an object with joints2d and residual")
        uv = _numbers(_require(d, "joints2d", f"{path}: {where}"), (F, len(names), 2),
                      f"{where}: 'joints2d'", path)
        joints2d[view] = uv[:, order]
        residual[view] = _numbers(_require(d, "residual", f"{path}: {where}"), (F,),
                                  f"{where}: 'residual'", path)
    body = _check_body(data["body"], path) if data.get("body") is not None else None
    known = {"format", "mode", "fps", "joints", "frames", "joints3d", "views", "status", "body",
             "roots", "angles", "spread"}
    result = TrackResult(mode=mode, fps=float(fps), frames=frames,
                         joints3d=joints3d[:, order], joints2d=joints2d, residual=residual,
                         status=status, body=body,
                         extra={k: v for k, v in data.items() if k not in known})
    for key in ("roots", "angles", "spread"):
        if data.get(key) is not None:
            arr = _numbers(data[key], None, f"'{key}'", path)
            if arr.ndim != (3 if key == "roots" else 2) or len(arr) != F:
                raise ZoopraxisError(f"{path}: '{key}' has shape {arr.shape} for {F} frames")
            if key == "roots" and arr.shape[1:] != (4, 4):
                raise ZoopraxisError(f"{path}: 'roots' must hold a 4x4 matrix per frame")
            setattr(result, key, arr)
    names = (body or {}).get("dof_names")
    if result.angles is not None and names is not None and result.angles.shape[1] != len(names):
        raise ZoopraxisError(f"{path}: 'angles' has {result.angles.shape[1]} values per frame "
                             f"for {len(names)} body DOFs")
    return result
