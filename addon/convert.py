"""Scene <-> core conversions: clip marker coordinates and Blender cameras.

Both directions of every conversion live here, side by side, so the conventions meet in one
place (DESIGN, Conventions):

- Clip markers are normalized to the frame, origin at the bottom-left *corner* of the image, y
  up; Blender's tracker puts pixel centre ``i`` at ``(i + 0.5) / width``. OpenCV pixels have
  their origin at the centre of the top-left pixel, y down.
- A Blender camera looks down its local -Z with +Y up; OpenCV camera axes are x right, y down,
  z forward, and extrinsics map world to camera, ``X_cam = R @ X_world + t``.

Only plain numbers cross into ``core``: matrices are converted to numpy at once.
"""

import numpy as np

from ..core.geometry.camera import PinholeCamera
from ..core.errors import ZoopraxisError

# The camera-axis flip between Blender (-Z forward, +Y up) and OpenCV (+z forward, y down).
CV_FROM_BLENDER_CAMERA = np.diag([1.0, -1.0, -1.0])

# Custom properties on a camera object: what Blender's camera cannot hold itself.
PROP_VIEW = "zoopraxis_view"
PROP_IMAGE_SIZE = "zoopraxis_image_size"
PROP_K = "zoopraxis_K"
PROP_DIST = "zoopraxis_dist"

# How far the stored K may stray from the one Blender's lens, sensor and shift give before the
# user is taken to have edited the camera (then Blender's values win).
_K_TOLERANCE_PX = 0.01


# --- clip markers ---------------------------------------------------------------------------

def pixels_from_clip(co, image_size):
    """OpenCV pixels of normalized clip marker positions.

    Convention: clip (normalized, origin bottom-left corner, y up) to OpenCV pixels (origin at
    the centre of the top-left pixel, y down):

    .. math:: u = x W - 1/2,\\quad v = (1 - y) H - 1/2

    Parameters
    ----------
    co : array_like, shape (..., 2)
        ``MovieTrackingMarker.co`` values.
    image_size : (int, int)
        Width and height of the clip in pixels.

    Returns
    -------
    uv : array, shape (..., 2)
    """
    co = np.asarray(co, dtype=float)
    w, h = image_size
    return np.stack([co[..., 0] * w - 0.5, (1.0 - co[..., 1]) * h - 0.5], axis=-1)


def clip_from_pixels(uv, image_size):
    """Normalized clip marker positions of OpenCV pixels; the inverse of :func:`pixels_from_clip`.

    Parameters
    ----------
    uv : array_like, shape (..., 2)
    image_size : (int, int)

    Returns
    -------
    co : array, shape (..., 2)
    """
    uv = np.asarray(uv, dtype=float)
    w, h = image_size
    return np.stack([(uv[..., 0] + 0.5) / w, 1.0 - (uv[..., 1] + 0.5) / h], axis=-1)


# --- cameras --------------------------------------------------------------------------------

def _sensor_fit(data, image_size, pixel_aspect):
    """``(fit, sensor)``: which image side the sensor spans and the sensor size in mm.

    Blender's AUTO fit spans the longer side (pixel aspect included) with ``sensor_width``.
    """
    w, h = image_size
    ax, ay = pixel_aspect
    fit = data.sensor_fit
    if fit == 'AUTO':
        return ('HORIZONTAL' if ax * w >= ay * h else 'VERTICAL'), data.sensor_width
    return fit, (data.sensor_height if fit == 'VERTICAL' else data.sensor_width)


def intrinsics_from_blender(data, image_size, pixel_aspect=(1.0, 1.0)):
    """Pinhole intrinsics of a Blender perspective camera.

    Convention: Blender's view plane (``BKE_camera_params_compute_viewplane``) in OpenCV pixels.
    With ``ycor = aspect_y / aspect_x`` and ``s`` the side the sensor spans in pixel widths
    (``W``, or ``ycor H`` for a vertical fit):

    .. math:: f_x = \\frac{\\mathrm{lens}\\, s}{\\mathrm{sensor}},\\quad f_y = f_x / ycor,\\quad
              c_x = \\frac{W}{2} - \\mathrm{shift}_x s - \\frac12,\\quad
              c_y = \\frac{H}{2} + \\mathrm{shift}_y s / ycor - \\frac12

    Parameters
    ----------
    data : bpy.types.Camera
    image_size : (int, int)
    pixel_aspect : (float, float)
        The scene's ``render.pixel_aspect_x``, ``pixel_aspect_y``.

    Returns
    -------
    K : array, shape (3, 3)
    """
    if data.type != 'PERSP':
        raise ZoopraxisError(f"camera '{data.name}' is {data.type.lower()}, not perspective")
    w, h = image_size
    ycor = pixel_aspect[1] / pixel_aspect[0]
    fit, sensor = _sensor_fit(data, image_size, pixel_aspect)
    span = w if fit == 'HORIZONTAL' else ycor * h
    fx = data.lens * span / sensor
    fy = fx / ycor
    cx = w / 2 - data.shift_x * span - 0.5
    cy = h / 2 + data.shift_y * span / ycor - 0.5
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def extrinsics_from_matrix(matrix_world):
    """World -> OpenCV camera extrinsics of a Blender camera object's world matrix.

    Convention: Blender camera (local -Z forward, +Y up) to OpenCV (x right, y down, z
    forward); ``R = diag(1, -1, -1) @ R_world_from_local.T``, ``t = -R @ centre``. Scale in the
    object matrix is ignored.

    Parameters
    ----------
    matrix_world : array_like, shape (4, 4)

    Returns
    -------
    R : array, shape (3, 3)
    t : array, shape (3,)
    """
    M = np.array(matrix_world, dtype=float)
    axes = M[:3, :3] / np.linalg.norm(M[:3, :3], axis=0)
    R = CV_FROM_BLENDER_CAMERA @ axes.T
    return R, -R @ M[:3, 3]


def matrix_from_extrinsics(R, t):
    """Blender camera object world matrix of OpenCV extrinsics (inverse of the above).

    Returns
    -------
    matrix_world : array, shape (4, 4)
    """
    R = np.asarray(R, float)
    M = np.eye(4)
    M[:3, :3] = R.T @ CV_FROM_BLENDER_CAMERA
    M[:3, 3] = -R.T @ np.asarray(t, float)
    return M


def image_size_of(obj, scene=None):
    """The image size a camera object stands for: its stored size, else the scene's resolution."""
    size = obj.get(PROP_IMAGE_SIZE)
    if size is not None and len(size) == 2:
        return int(size[0]), int(size[1])
    if scene is None:
        raise ZoopraxisError(f"camera '{obj.name}' has no image size; load its plate first")
    return scene.render.resolution_x, scene.render.resolution_y


def pixel_aspect_of(scene):
    if scene is None:
        return (1.0, 1.0)
    return (scene.render.pixel_aspect_x, scene.render.pixel_aspect_y)


def pinhole_from_object(obj, *, name=None, image_size=None, scene=None):
    """A :class:`PinholeCamera` from a Blender camera object.

    Blender's lens, sensor, shift and world matrix are the truth. What a Blender camera cannot
    express (unequal focal lengths, skew, lens distortion) comes from the object's custom
    properties, written by :func:`apply_pinhole`; the stored K is used only while it still
    agrees with Blender's own to ``_K_TOLERANCE_PX``.

    Parameters
    ----------
    obj : bpy.types.Object
        A camera object.
    name : str, optional
        View name; defaults to the object's ``zoopraxis_view`` property, else its name.
    image_size : (int, int), optional
        Defaults to the object's stored size, else the scene's render resolution.
    scene : bpy.types.Scene, optional
        For the pixel aspect and the fallback size.

    Returns
    -------
    camera : PinholeCamera
    """
    if obj is None or obj.type != 'CAMERA':
        raise ZoopraxisError(f"'{getattr(obj, 'name', None)}' is not a camera object")
    size = tuple(image_size) if image_size is not None else image_size_of(obj, scene)
    K = intrinsics_from_blender(obj.data, size, pixel_aspect_of(scene))
    stored = obj.get(PROP_K)
    if stored is not None and len(stored) == 9:
        K_stored = np.array(stored, float).reshape(3, 3)
        if (abs(K_stored[0, 0] - K[0, 0]) <= _K_TOLERANCE_PX
                and np.all(np.abs(K_stored[:2, 2] - K[:2, 2]) <= _K_TOLERANCE_PX)):
            K = K_stored
    dist = obj.get(PROP_DIST)
    dist = np.zeros(5) if dist is None else np.array(dist, float)
    R, t = extrinsics_from_matrix(obj.matrix_world)
    view = name or obj.get(PROP_VIEW) or obj.name
    return PinholeCamera(str(view), size, K, dist, R, t)


def apply_pinhole(obj, camera, scene=None):
    """Set a Blender camera object to show what a :class:`PinholeCamera` sees.

    The lens spans the image width (sensor fit HORIZONTAL, the sensor width kept) and
    ``lens = fx * sensor / W``; shift places the principal point. The camera's K,
    distortion, image size and view name are stored as custom properties, so
    :func:`pinhole_from_object` gives the same camera back.

    Parameters
    ----------
    obj : bpy.types.Object
        A camera object; its world matrix is set (a parent, if any, is taken into account).
    camera : PinholeCamera
    scene : bpy.types.Scene, optional
        For the pixel aspect (square pixels without it).
    """
    import mathutils

    w, h = camera.image_size
    ax, ay = pixel_aspect_of(scene)
    ycor = ay / ax
    data = obj.data
    data.type = 'PERSP'
    data.sensor_fit = 'HORIZONTAL'
    K = camera.K
    data.lens = K[0, 0] * data.sensor_width / w
    data.shift_x = (w / 2 - 0.5 - K[0, 2]) / w
    data.shift_y = (K[1, 2] + 0.5 - h / 2) * ycor / w
    obj.matrix_world = mathutils.Matrix(matrix_from_extrinsics(camera.R, camera.t).tolist())
    obj[PROP_VIEW] = camera.name
    obj[PROP_IMAGE_SIZE] = [int(w), int(h)]
    obj[PROP_K] = [float(x) for x in K.ravel()]
    obj[PROP_DIST] = [float(x) for x in camera.dist]
