"""Model fine-tuning from joints (§2.7): the initialization's joint problem over many frames,
lengths shared, solved by blocks (:func:`refine_dims`)."""

from dataclasses import dataclass

import numpy as np

from ..body.body import LENGTH_DIMS, RADIUS_DIMS, Pose
from ..body.kinematics import kinematics
from ..errors import ZoopraxisError
from ..geometry.ortho import ScaledOrthoCamera
from .problem import DIMS_RANGE, LOSS_SCALE_PX, N_JOINTS, _fit, _State


@dataclass
class RefineResult:
    """What :func:`refine_dims` found.

    Attributes
    ----------
    body : BodyModel
        With the refined lengths.
    poses : dict of int to Pose
    cameras : dict
        As given, or per frame with the refined scaled orthographic cameras.
    rms : dict of str to float
        Root-mean-square observation error per view, pixels (unweighted).
    """

    body: object
    poses: dict
    cameras: dict
    rms: dict


def refine_dims(body, poses_by_frame, observations, cameras, *, weights=None, fit_poses=True,
                loss_scale=LOSS_SCALE_PX, dims_range=DIMS_RANGE):
    """Refine the body dimensions (and the poses) over many frames: model fine-tuning (§2.7).

    One joint problem over all frames: the lengths are shared, every frame has its own pose,
    and the projected model joints should meet the 2D joint observations (the tracker's
    projected joints, the anchors' clicks) with the given weights.

    Parameters
    ----------
    body : BodyModel
        Current model; its lengths are the start, its template is kept.
    poses_by_frame : dict of int to Pose
    observations : dict of int to dict of str to array, shape (17, 2)
        2D joints per frame and view, pixels; NaN where not observed.
    cameras : dict of str to camera, or dict of int to dict of str to camera
        Static cameras per view: the roots and angles are refined. Or cameras per frame and
        view (Bregler & Malik's one pose per view): scaled orthographic ones are refined with
        the angles and the roots stay as given.
    weights : dict of int to dict of str to array, shape (17,), optional
        Confidence of each observation (default 1).
    fit_poses : bool
        Refine the poses too; otherwise only the dimensions move.
    loss_scale : float
        Robust loss scale, pixels.
    dims_range : (float, float)
        Bounds of the lengths as multiples of the template's defaults.

    Returns
    -------
    result : RefineResult

    Raises
    ------
    ZoopraxisError
        A frame without a pose, a view without a camera, a wrongly shaped observation.
    """
    frames = sorted(observations)
    if not frames:
        raise ZoopraxisError("refine_dims: no observations")
    per_frame = all(isinstance(k, (int, np.integer)) for k in cameras) and bool(cameras)
    views = []
    for f in frames:
        if f not in poses_by_frame:
            raise ZoopraxisError(f"refine_dims: frame {f} has observations but no pose")
        views += [v for v in observations[f] if v not in views]
    obs = np.full((len(frames), len(views), N_JOINTS, 2), np.nan)
    w = np.ones(obs.shape[:3])
    cams = []
    for i, f in enumerate(frames):
        row = []
        for k, v in enumerate(views):
            if v in observations[f]:
                a = np.asarray(observations[f][v], float)
                if a.shape != (N_JOINTS, 2):
                    raise ZoopraxisError(f"refine_dims: frame {f}, view {v}: observations must "
                                         f"have shape (17, 2), got {a.shape}")
                obs[i, k] = a
                if weights is not None and f in weights and v in weights[f]:
                    w[i, k] = np.asarray(weights[f][v], float)
            source = cameras.get(f, {}) if per_frame else cameras
            if v not in source and np.isfinite(obs[i, k]).any():
                where = f"frame {f}, " if per_frame else ""
                raise ZoopraxisError(f"refine_dims: {where}view {v} has no camera")
            row.append(source.get(v))
        cams.append(row)
    kin = kinematics(body.template)
    dims = body.dims_vector(LENGTH_DIMS)
    size = float(np.median(dims / kin.default_dims))
    state = _State(dims, size, np.array([poses_by_frame[f].root for f in frames]),
                   np.array([poses_by_frame[f].angles for f in frames]), cams)
    free_cams = np.array([[per_frame and isinstance(c, ScaledOrthoCamera) and fit_poses
                           for c in row] for row in cams])
    calibrated = not free_cams.any()
    fitted, _, problem = _fit(kin, obs, w, state, free_root=fit_poses and not free_cams.any(),
                              free_angles=fit_poses, free_cams=free_cams, fit_dims=True,
                              calibrated=calibrated, loss_scale=loss_scale,
                              dims_range=dims_range)
    lengths = dict(zip(LENGTH_DIMS, fitted.dims))
    radii = {n: body.dims[n] * fitted.size / size for n in RADIUS_DIMS}
    new_body = body.with_dims({**lengths, **radii})
    poses = {f: Pose(fitted.roots[i].copy(), new_body.clamp(fitted.angles[i]))
             for i, f in enumerate(frames)}
    err = problem.errors(fitted)
    rms = {v: float(np.sqrt(np.nanmean(err[:, k] ** 2))) for k, v in enumerate(views)
           if np.isfinite(err[:, k]).any()}
    if per_frame:
        out_cams = {f: {v: fitted.cameras[i][k] for k, v in enumerate(views)
                        if fitted.cameras[i][k] is not None} for i, f in enumerate(frames)}
    else:
        out_cams = dict(cameras)
    return RefineResult(new_body, poses, out_cams, rms)
