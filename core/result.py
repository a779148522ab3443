"""result.json: what ``track`` writes and ``bake`` reads (DESIGN, Files).

Required keys: ``format`` ("zoopraxis-track/1"), ``mode``, ``fps``, ``joints``, ``frames``,
``joints3d`` [frame][joint][xyz] world metres, ``views`` {view: {joints2d, residual}} and
``status`` per frame (ok | uncertain | lost). This module adds the body (template, dimensions,
DOF names), the root pose and joint angles per frame, and optional per-parameter spread, so the
result can be baked onto an armature without re-fitting.
"""

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import ZoopraxisError
from .joints import STANDARD_JOINTS

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
    """Write result.json atomically; refuses to replace a file unless ``force``."""
    path = Path(path)
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    tmp.write_text(json.dumps(result.to_json()))
    os.replace(tmp, path)


def _require(data, key, path):
    if key not in data:
        raise ZoopraxisError(f"{path}: missing required key '{key}'")
    return data[key]


def read_result(path):
    """Read and validate result.json into a :class:`TrackResult`."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such result file") from None
    except json.JSONDecodeError as exc:
        raise ZoopraxisError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(data, dict):
        raise ZoopraxisError(f"{path}: expected a JSON object")
    fmt = _require(data, "format", path)
    if fmt != FORMAT:
        raise ZoopraxisError(f"{path}: format '{fmt}' is not '{FORMAT}'")
    mode = _require(data, "mode", path)
    if mode not in MODES:
        raise ZoopraxisError(f"{path}: mode '{mode}' is not one of {', '.join(MODES)}")
    fps = float(_require(data, "fps", path))
    names = _require(data, "joints", path)
    missing = [j for j in STANDARD_JOINTS if j not in names]
    if missing:
        raise ZoopraxisError(f"{path}: joint '{missing[0]}' is missing from 'joints'")
    order = [names.index(j) for j in STANDARD_JOINTS]
    frames = np.asarray(_require(data, "frames", path), dtype=int)
    F = len(frames)
    joints3d = np.asarray(_require(data, "joints3d", path), float)
    if joints3d.shape != (F, len(names), 3):
        raise ZoopraxisError(f"{path}: 'joints3d' has shape {joints3d.shape}, expected "
                             f"({F}, {len(names)}, 3)")
    status = list(_require(data, "status", path))
    if len(status) != F:
        raise ZoopraxisError(f"{path}: 'status' has {len(status)} entries for {F} frames")
    bad = [s for s in status if s not in STATUSES]
    if bad:
        raise ZoopraxisError(f"{path}: unknown status '{bad[0]}' (expected ok, uncertain or lost)")
    joints2d, residual = {}, {}
    for view, d in _require(data, "views", path).items():
        uv = np.asarray(_require(d, "joints2d", f"{path}: view '{view}'"), float)
        if uv.shape != (F, len(names), 2):
            raise ZoopraxisError(f"{path}: view '{view}': 'joints2d' has shape {uv.shape}")
        joints2d[view] = uv[:, order]
        res = np.asarray(_require(d, "residual", f"{path}: view '{view}'"), float)
        if res.shape != (F,):
            raise ZoopraxisError(f"{path}: view '{view}': 'residual' has {res.size} values "
                                 f"for {F} frames")
        residual[view] = res
    known = {"format", "mode", "fps", "joints", "frames", "joints3d", "views", "status", "body",
             "roots", "angles", "spread"}
    result = TrackResult(mode=mode, fps=fps, frames=frames, joints3d=joints3d[:, order],
                         joints2d=joints2d, residual=residual, status=status,
                         body=data.get("body"),
                         extra={k: v for k, v in data.items() if k not in known})
    for key in ("roots", "angles", "spread"):
        if key in data:
            arr = np.asarray(data[key], float)
            if len(arr) != F:
                raise ZoopraxisError(f"{path}: '{key}' has {len(arr)} entries for {F} frames")
            setattr(result, key, arr)
    return result
