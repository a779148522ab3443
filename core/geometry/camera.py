"""Cameras: the checks on camera parameters, the behaviour both camera models share, the
calibrated pinhole camera with lens distortion, and cameras placed by hand (``look_at``,
``ring_of_cameras``).

``PinholeCamera`` is the perspective camera of Yamamoto et al. (1998) and Sidenbladh, Black &
Fleet (2000), with OpenCV's lens distortion (:mod:`lens`); the scaled orthographic camera of the
uncalibrated mode is in :mod:`ortho`, and ``files.calibfile.camera_from_dict`` makes either from a
calibration.json entry.

Convention:
    World: right-handed, Z up, metres. Camera: OpenCV axes (x right, y down, z forward), and the
    extrinsics map world to camera, ``X_cam = R @ X_world + t``. Pixels: OpenCV, origin at the
    centre of the top-left pixel, u right, v down. Images are indexed ``image[v, u]``.

Cameras are frozen dataclasses whose arrays are read-only, so a camera never changes after it is
made and the rays cached by ``pixel_rays`` stay valid; derive a changed camera with
``camera.replace(t=...)``. Every method takes points of shape (..., 3) or pixels of shape (..., 2)
and keeps the leading shape.
"""

import dataclasses
from functools import cached_property
from typing import ClassVar

import numpy as np

from ..errors import ZoopraxisError
from .lens import no_distortion, distort, undistort

# How far R @ R.T may stray from the identity before R is refused as a rotation. Loose enough for
# matrices printed with 4-5 decimals in a calibration file, tight enough to catch real mistakes
# (a transposed or scaled matrix); accepted matrices are snapped to the nearest rotation.
ROTATION_TOLERANCE = 1e-4

# The two ways an image is resampled by a factor, for ``scaled``: an image pyramid (cv2.pyrDown,
# cv2.pyrUp) keeps pixel u at u * factor, cv2.resize keeps pixel corners: (u + 0.5) * factor - 0.5.
SAMPLINGS = ("pyramid", "resize")


# --- input checks -----------------------------------------------------------------------------

def _as_array(value, shape, what):
    """``value`` as a finite float64 array of ``shape``, or ZoopraxisError naming ``what``."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ZoopraxisError(f"{what} must be numbers, got {value!r:.80}") from None
    if shape is not None and a.shape != shape:
        raise ZoopraxisError(f"{what} must have shape {shape}, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ZoopraxisError(f"{what} contains NaN or infinity")
    return a


def check_rotation(R, what="R"):
    """Check that ``R`` is a rotation matrix and return it as exactly orthonormal float64.

    Parameters
    ----------
    R : array_like, shape (3, 3)
        Rotation matrix; ``R @ R.T`` may differ from the identity by ``ROTATION_TOLERANCE``.
    what : str
        How to name ``R`` in the error message (e.g. ``"camera 'cam0': R"``).

    Returns
    -------
    R : array, shape (3, 3)
        ``R`` itself if orthonormal to round-off, else the nearest rotation matrix (by SVD), so
        that downstream algebra sees an exact rotation.

    Raises
    ------
    ZoopraxisError
        If ``R`` is not 3x3, not finite, not orthonormal, or a reflection (det -1).
    """
    R = _as_array(R, (3, 3), what)
    error = np.abs(R @ R.T - np.eye(3)).max()
    if error > ROTATION_TOLERANCE:
        raise ZoopraxisError(
            f"{what} is not a rotation matrix: R @ R.T differs from the identity by {error:.2g}")
    if np.linalg.det(R) < 0:
        raise ZoopraxisError(f"{what} is a reflection (determinant -1), not a rotation")
    if error <= 1e-12:
        # Already a rotation to round-off: keep the numbers, so that files round-trip exactly.
        return R
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def check_intrinsics(K, what="K"):
    """Check a pinhole intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]``.

    Parameters
    ----------
    K : array_like, shape (3, 3)
        Intrinsics in pixels; focal lengths positive, last row ``[0, 0, 1]``.
    what : str
        How to name ``K`` in the error message.

    Returns
    -------
    K : array, shape (3, 3)
        ``K`` as float64.
    """
    K = _as_array(K, (3, 3), what)
    if K[1, 0] != 0 or np.any(K[2] != (0, 0, 1)):
        raise ZoopraxisError(
            f"{what} must be upper triangular with last row [0, 0, 1], got {K.tolist()}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ZoopraxisError(
            f"{what} must have positive focal lengths, got fx={K[0, 0]:g}, fy={K[1, 1]:g}")
    return K


def check_distortion(dist, what="dist"):
    """Check OpenCV distortion coefficients ``[k1, k2, p1, p2(, k3)]`` and return 5 of them.

    Parameters
    ----------
    dist : array_like, shape (4,) or (5,)
        Radial ``k1, k2`` and tangential ``p1, p2`` coefficients, optionally ``k3``.
    what : str
        How to name ``dist`` in the error message.

    Returns
    -------
    dist : array, shape (5,)
        ``[k1, k2, p1, p2, k3]``, with ``k3 = 0`` when only four were given.
    """
    a = _as_array(dist, None, what)
    flat = a.ravel()
    if a.ndim != 1 or flat.size not in (4, 5):
        count = f"{flat.size} values" if a.ndim == 1 else f"shape {a.shape}"
        raise ZoopraxisError(
            f"{what} must have 4 or 5 coefficients [k1, k2, p1, p2, k3], got {count} "
            "(OpenCV's rational, thin-prism and fisheye models are not supported)")
    return np.concatenate([flat, np.zeros(5 - flat.size)])


def check_image_size(image_size, what="image_size"):
    """Check an image size (width, height) in pixels and return it as a tuple of two ints.

    Parameters
    ----------
    image_size : array_like, shape (2,)
        Width and height, positive whole numbers (``1920.0`` is accepted).
    what : str
        How to name the size in the error message.

    Returns
    -------
    image_size : tuple of int
        ``(width, height)``.
    """
    size = _as_array(image_size, (2,), what)
    if np.any(size != np.round(size)) or np.any(size < 1):
        raise ZoopraxisError(
            f"{what} must be two positive whole numbers (width, height), got {size.tolist()}")
    return int(size[0]), int(size[1])


def _frozen(a):
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


def _as_points(X, last):
    X = np.asarray(X, dtype=np.float64)
    if X.ndim == 0 or X.shape[-1] != last:
        raise ZoopraxisError(
            f"{'points' if last == 3 else 'pixels'} must have shape (..., {last}), "
            f"got shape {X.shape}")
    return X


# From this many rows on, elementwise work on (..., k) points goes column by column: numpy's
# broadcast loops over k-long rows cost several times more per element.
_BY_COLUMNS = 1000


def _plus_row(P, v):
    """``P + v`` for points ``P`` (..., k) and one vector ``v`` (k,): the same sums."""
    if P.size < _BY_COLUMNS * P.shape[-1]:
        return P + v
    out = np.empty(P.shape, np.result_type(P, v))
    for i in range(P.shape[-1]):
        np.add(P[..., i], v[i], out=out[..., i])
    return out


def _perspective_divide(X_cam):
    """``X_cam[..., :2] / X_cam[..., 2:]``, the same quotients (call under np.errstate)."""
    if X_cam.size < _BY_COLUMNS * 3:
        return X_cam[..., :2] / X_cam[..., 2:]
    xy = np.empty(X_cam.shape[:-1] + (2,), np.result_type(X_cam))
    np.divide(X_cam[..., 0], X_cam[..., 2], out=xy[..., 0])
    np.divide(X_cam[..., 1], X_cam[..., 2], out=xy[..., 1])
    return xy


def _pixel_grid(image_size):
    """Pixel centres of a whole image, shape (H, W, 2), as (u, v)."""
    width, height = image_size
    u, v = np.meshgrid(np.arange(width, dtype=np.float64), np.arange(height, dtype=np.float64))
    return np.stack([u, v], axis=-1)


def _scaled_size(image_size, factor, sampling):
    if sampling == "pyramid":
        # cv2.pyrDown gives ceil(w / 2); repeated levels compose to ceil(w * factor).
        return tuple(int(np.ceil(n * factor - 1e-9)) for n in image_size)
    return tuple(max(1, int(np.round(n * factor))) for n in image_size)


def _check_scaling(factor, sampling):
    if sampling not in SAMPLINGS:
        raise ZoopraxisError(f"sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    if not np.isfinite(factor) or factor <= 0:
        raise ZoopraxisError(f"scale factor must be positive, got {factor!r}")


def _scale_pixel(coord, factor, sampling):
    """Where pixel coordinate ``coord`` lands after resampling by ``factor``."""
    if sampling == "pyramid":
        # cv2.pyrDown's output pixel i is centred on input pixel 2 i (the 5-tap kernel is
        # centred there), so pixel centres scale about pixel 0, not about the image corner.
        return coord * factor
    return (coord + 0.5) * factor - 0.5


# --- common behaviour ---------------------------------------------------------------------------

class _Camera:
    """Behaviour shared by both camera models (they define ``R`` and ``t``)."""

    model: ClassVar[str]

    def replace(self, **changes):
        """Return a copy of the camera with some fields changed (and checked again).

        Parameters
        ----------
        **changes
            Field names and new values, e.g. ``t=(0, 0, 5)`` or ``name="cam3"``.

        Returns
        -------
        camera : same type as self
        """
        return dataclasses.replace(self, **changes)

    def cam_from_world(self, X):
        """Transform world points into the camera frame.

        Convention: world (Z up) to camera (OpenCV: x right, y down, z forward),
        ``X_cam = R @ X_world + t``.

        Parameters
        ----------
        X : array_like, shape (..., 3)
            Points in world coordinates, metres.

        Returns
        -------
        X_cam : array, shape (..., 3)
        """
        return _plus_row(_as_points(X, 3) @ self.R.T, self.t)

    def world_from_cam(self, X_cam):
        """Transform camera-frame points into the world, the inverse of ``cam_from_world``.

        Convention: camera (OpenCV axes) to world (Z up), ``X_world = R.T @ (X_cam - t)``.

        Parameters
        ----------
        X_cam : array_like, shape (..., 3)

        Returns
        -------
        X : array, shape (..., 3)
        """
        return (_as_points(X_cam, 3) - self.t) @ self.R

    def depth(self, X):
        """Depth of world points along the viewing direction: the camera z coordinate.

        Parameters
        ----------
        X : array_like, shape (..., 3)

        Returns
        -------
        z : array, shape (...)
            ``(R @ X + t)[2]``; positive in front of a pinhole camera.
        """
        return _as_points(X, 3) @ self.R[2] + self.t[2]

    @property
    def forward(self):
        """Unit viewing direction (the camera +z axis) in world coordinates, shape (3,)."""
        return self.R[2].copy()

    @property
    def width(self):
        return self.image_size[0]

    @property
    def height(self):
        return self.image_size[1]

    def pixel_rays(self):
        """Rays through the centres of all pixels of the image, in world coordinates.

        Cached on the camera: the arrays are shared and read-only.

        Returns
        -------
        origins : array, shape (3,) or (H, W, 3)
            Pinhole: the camera centre, shape (3,), broadcastable against ``dirs``.
            Scaled orthographic: the points on the plane ``z_cam = 0`` that project to each pixel.
        dirs : array, shape (H, W, 3)
            Unit directions in world coordinates, ``dirs[v, u]`` for pixel (u, v). Pinhole:
            through the undistorted pixel (NaN past the fold of extreme lens models); scaled
            orthographic: all equal to ``forward``.
        """
        return self._pixel_rays

    @cached_property
    def _pixel_rays(self):
        origins, dirs = self.rays(_pixel_grid(self.image_size))
        for a in (origins, dirs):
            a.setflags(write=False)
        return origins, dirs

    def _check_scaling(self, factor, sampling):
        _check_scaling(factor, sampling)
        return _scaled_size(self.image_size, factor, sampling)

    def _short_repr(self, extra):
        center = self.center
        where = "" if center is None else f", center={np.round(center, 3).tolist()}"
        return (f"{type(self).__name__}(name={self.name!r}, image_size={self.image_size}, "
                f"{extra}{where}, forward={np.round(self.forward, 3).tolist()})")


# --- the pinhole camera -------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class PinholeCamera(_Camera):
    """Calibrated perspective camera with OpenCV's 5-coefficient lens distortion.

    .. math:: X_c = R X + t,\\quad (x, y) = (X_c / Z_c, Y_c / Z_c),\\quad
              (u, v, 1)^T = K\\, (\\mathrm{distort}(x, y), 1)^T

    Parameters
    ----------
    name : str
        View name, as used by the plates, markers and calibration files.
    image_size : (int, int)
        Width and height in pixels.
    K : array_like, shape (3, 3)
        Intrinsics ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist : array_like, shape (5,) or (4,), optional
        ``[k1, k2, p1, p2, k3]`` (``k3 = 0`` if four are given); default no distortion.
    R : array_like, shape (3, 3), optional
        Rotation world -> camera; default identity.
    t : array_like, shape (3,), optional
        Translation world -> camera in metres; default zero.

    Convention:
        ``X_cam = R @ X_world + t`` with OpenCV camera axes; pixels have their origin at the
        centre of the top-left pixel. The camera centre in the world is ``-R.T @ t``.
    """

    model: ClassVar[str] = "pinhole"

    name: str
    image_size: tuple
    K: np.ndarray
    dist: np.ndarray = None
    R: np.ndarray = None
    t: np.ndarray = None

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ZoopraxisError(f"camera name must be a non-empty string, got {self.name!r}")
        where = f"camera '{self.name}'"
        set_ = object.__setattr__
        set_(self, "image_size", check_image_size(self.image_size, f"{where}: image_size"))
        set_(self, "K", _frozen(check_intrinsics(self.K, f"{where}: K")))
        set_(self, "dist", _frozen(np.zeros(5) if self.dist is None
                                   else check_distortion(self.dist, f"{where}: dist")))
        set_(self, "R", _frozen(np.eye(3) if self.R is None
                                else check_rotation(self.R, f"{where}: R")))
        set_(self, "t", _frozen(np.zeros(3) if self.t is None
                                else _as_array(self.t, (3,), f"{where}: t")))

    def __repr__(self):
        fx, fy, cx, cy = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2]
        return self._short_repr(f"f=({fx:.6g}, {fy:.6g}), c=({cx:.6g}, {cy:.6g})")

    @property
    def center(self):
        """Camera centre (optical centre) in world coordinates, shape (3,): ``-R.T @ t``."""
        return -self.R.T @ self.t

    @property
    def P(self):
        """Projection matrix ``K @ [R | t]``, shape (3, 4), ignoring lens distortion."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def has_distortion(self):
        return bool(np.any(self.dist))

    def _pixels_from_normalized(self, xy):
        return _plus_row(xy @ self.K[:2, :2].T, self.K[:2, 2])

    def _normalized_from_pixels(self, uv):
        K = self.K
        y = (uv[..., 1] - K[1, 2]) / K[1, 1]
        x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def project(self, X):
        """Project world points to (distorted) pixels.

        Convention: world (Z up, metres) to OpenCV pixels. Points at or behind the camera plane
        (``depth <= 0``) give meaningless or infinite pixels; check ``depth`` first.

        Parameters
        ----------
        X : array_like, shape (..., 3)
            Points in world coordinates.

        Returns
        -------
        uv : array, shape (..., 2)
            Pixel coordinates including lens distortion.
        """
        X_cam = self.cam_from_world(X)
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = _perspective_divide(X_cam)
        if no_distortion(self.dist):
            # the lens model's sums would be x + 0 and y + 0: the same pixels (a point on the
            # camera plane keeps its infinite pixel, where the model's 0 * inf made it NaN)
            return self._pixels_from_normalized(xy)
        return self._pixels_from_normalized(distort(xy, self.dist))

    def project_jacobian(self, X):
        """Project world points and return the derivative of the pixels by the world point.

        Convention: world (Z up, metres) to OpenCV pixels; the derivative includes distortion:

        .. math:: \\frac{\\partial uv}{\\partial X} = K_{2\\times2}\\,
                  \\frac{\\partial x_d}{\\partial x}\\,
                  \\frac{1}{Z_c}\\begin{bmatrix}1 & 0 & -x\\\\ 0 & 1 & -y\\end{bmatrix} R

        Parameters
        ----------
        X : array_like, shape (..., 3)

        Returns
        -------
        uv : array, shape (..., 2)
            Same as ``project(X)``.
        J : array, shape (..., 2, 3)
            ``d uv / d X_world``, pixels per metre.
        """
        X_cam = self.cam_from_world(X)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv_z = 1.0 / X_cam[..., 2]
            xy = X_cam[..., :2] * inv_z[..., None]
        xy_d, J_dist = distort(xy, self.dist, jacobian=True)
        J_norm = np.zeros(X_cam.shape[:-1] + (2, 3))
        J_norm[..., 0, 0] = inv_z
        J_norm[..., 1, 1] = inv_z
        J_norm[..., :, 2] = -xy * inv_z[..., None]
        J = self.K[:2, :2] @ J_dist @ J_norm @ self.R
        return self._pixels_from_normalized(xy_d), J

    def undistort_points(self, uv):
        """Remove lens distortion from pixels: where an ideal pinhole with the same K puts them.

        Inverse of ``distort_points``: ``undistort_points(project(X))`` equals
        ``K @ (X_c / Z_c)`` without distortion. Like ``cv2.undistortPoints(uv, K, dist, P=K)``
        solved to convergence.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Observed (distorted) pixels.

        Returns
        -------
        uv_ideal : array, shape (..., 2)
            Undistorted pixels; NaN where the lens model has no valid inverse (beyond its fold).
        """
        uv = _as_points(uv, 2)
        return self._pixels_from_normalized(undistort(self._normalized_from_pixels(uv), self.dist))

    def distort_points(self, uv_ideal):
        """Apply lens distortion to ideal pinhole pixels (the inverse of ``undistort_points``).

        Parameters
        ----------
        uv_ideal : array_like, shape (..., 2)

        Returns
        -------
        uv : array, shape (..., 2)
        """
        uv_ideal = _as_points(uv_ideal, 2)
        return self._pixels_from_normalized(
            distort(self._normalized_from_pixels(uv_ideal), self.dist))

    def rays(self, uv):
        """Viewing rays through pixels, in world coordinates.

        Convention: OpenCV pixels to world rays; ``origin + d * dir`` projects back to ``uv`` for
        every ``d > 0``.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Observed (distorted) pixels.

        Returns
        -------
        origins : array, shape (3,)
            The camera centre, broadcastable against ``dirs``.
        dirs : array, shape (..., 3)
            Unit directions in world coordinates.
        """
        xy = undistort(self._normalized_from_pixels(_as_points(uv, 2)), self.dist)
        d_cam = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
        d_cam /= np.linalg.norm(d_cam, axis=-1, keepdims=True)
        return self.center, d_cam @ self.R

    def unproject(self, uv, depth):
        """World points at a given camera depth on the rays through pixels.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Observed (distorted) pixels.
        depth : array_like, shape (...) or scalar
            Camera z of the wanted points (not the distance along the ray).

        Returns
        -------
        X : array, shape (..., 3)
            World points with ``project(X) == uv`` and ``depth(X) == depth``.
        """
        xy = undistort(self._normalized_from_pixels(_as_points(uv, 2)), self.dist)
        z = np.broadcast_to(np.asarray(depth, dtype=np.float64), xy.shape[:-1])
        return self.world_from_cam(np.concatenate([xy * z[..., None], z[..., None]], axis=-1))

    def scaled(self, factor, sampling="pyramid"):
        """The camera that sees the same scene in the image resampled by ``factor``.

        Parameters
        ----------
        factor : float
            Resampling factor: 0.5 for one ``cv2.pyrDown`` level, 0.25 for two, 2 for ``pyrUp``.
        sampling : {"pyramid", "resize"}
            ``"pyramid"`` (cv2.pyrDown / pyrUp): pixel centres scale about pixel 0,
            ``u' = u * factor``, size ``ceil(w * factor)`` (``(w + 1) // 2`` for 0.5).
            ``"resize"`` (cv2.resize with ``fx=fy=factor``): pixel corners scale,
            ``u' = (u + 0.5) * factor - 0.5``, size ``round(w * factor)``.

        Returns
        -------
        camera : PinholeCamera
            Same name, pose and distortion; focal lengths and skew times ``factor``.
        """
        size = self._check_scaling(factor, sampling)
        K = self.K.copy()
        K[:2, :2] *= factor
        K[:2, 2] = _scale_pixel(K[:2, 2], factor, sampling)
        return self.replace(image_size=size, K=K)

    def to_dict(self):
        """The camera as a calibration.json entry (DESIGN's format).

        Returns
        -------
        entry : dict
            ``{"name", "image_size", "K", "dist", "R", "t"}`` with plain lists.
        """
        return {"name": self.name, "image_size": list(self.image_size), "K": self.K.tolist(),
                "dist": self.dist.tolist(), "R": self.R.tolist(), "t": self.t.tolist()}

    @classmethod
    def from_dict(cls, entry, source=None):
        """Make a camera from a calibration.json entry; unknown keys are ignored.

        Parameters
        ----------
        entry : dict
            With keys ``name``, ``image_size``, ``K``, ``dist``, ``R``, ``t``.
        source : str, optional
            The file the entry comes from, named in error messages.

        Returns
        -------
        camera : PinholeCamera
        """
        return _from_dict(cls, entry, ("name", "image_size", "K", "dist", "R", "t"), source)


def _from_dict(cls, entry, required, source, optional=()):
    prefix = f"{source}: " if source else ""
    if not isinstance(entry, dict):
        raise ZoopraxisError(f"{prefix}a camera entry must be an object, got {entry!r:.60}")
    name = entry.get("name")
    who = f"camera '{name}'" if isinstance(name, str) and name else "a camera without a name"
    for key in required:
        if key not in entry:
            raise ZoopraxisError(f"{prefix}{who}: missing key '{key}'")
    try:
        return cls(**{key: entry[key] for key in required + optional if key in entry})
    except ZoopraxisError as error:
        raise ZoopraxisError(f"{prefix}{error}") from None


# --- building cameras ---------------------------------------------------------------------------

def look_at(eye, target, up=(0.0, 0.0, 1.0)):
    """Extrinsics of a camera at ``eye`` looking at ``target``, with ``up`` upward in the image.

    Convention: returns world -> camera extrinsics in OpenCV axes: camera z points from ``eye``
    to ``target``, camera y (image down) is the projection of ``-up``, and x = y cross z (image
    right). World up therefore appears up in the image: v decreases going up.

    Parameters
    ----------
    eye : array_like, shape (3,)
        Camera centre in world coordinates.
    target : array_like, shape (3,)
        The point that lands on the principal point.
    up : array_like, shape (3,)
        World direction that should point up in the image; default +Z.

    Returns
    -------
    R : array, shape (3, 3)
        Rotation world -> camera.
    t : array, shape (3,)
        Translation world -> camera, ``-R @ eye``.
    """
    eye = _as_array(eye, (3,), "look_at: eye")
    target = _as_array(target, (3,), "look_at: target")
    up = _as_array(up, (3,), "look_at: up")
    z = target - eye
    if np.linalg.norm(z) == 0:
        raise ZoopraxisError("look_at: eye and target are the same point")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9 * max(np.linalg.norm(up), 1e-300):
        raise ZoopraxisError("look_at: the viewing direction is parallel to up")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye


def ring_of_cameras(n, radius, height, target, image_size, focal_px, start_angle=0.0):
    """Distortion-free pinhole cameras evenly spaced on a horizontal circle, all facing a target.

    Parameters
    ----------
    n : int
        Number of cameras, named ``cam0`` .. ``cam{n-1}``.
    radius : float
        Horizontal distance from the target, metres.
    height : float
        World z of the cameras, metres (absolute, not relative to the target).
    target : array_like, shape (3,)
        The point every camera looks at; it lands on each camera's principal point.
    image_size : (int, int)
        Width and height in pixels; the principal point is the image centre.
    focal_px : float
        Focal length in pixels (square pixels).
    start_angle : float
        Azimuth of ``cam0`` in radians, counter-clockwise from world +X seen from above;
        camera i is at ``start_angle + 2 pi i / n``.

    Returns
    -------
    cameras : list of PinholeCamera
    """
    if int(n) != n or n < 1:
        raise ZoopraxisError(f"ring_of_cameras: n must be a positive whole number, got {n!r}")
    if not radius > 0:
        raise ZoopraxisError(f"ring_of_cameras: radius must be positive, got {radius!r}")
    if not focal_px > 0:
        raise ZoopraxisError(f"ring_of_cameras: focal_px must be positive, got {focal_px!r}")
    target = _as_array(target, (3,), "ring_of_cameras: target")
    width, height_px = check_image_size(image_size, "ring_of_cameras: image_size")
    K = [[focal_px, 0.0, (width - 1) / 2], [0.0, focal_px, (height_px - 1) / 2], [0, 0, 1]]
    cameras = []
    for i in range(int(n)):
        angle = start_angle + 2 * np.pi * i / n
        eye = [target[0] + radius * np.cos(angle), target[1] + radius * np.sin(angle), height]
        R, t = look_at(eye, target)
        cameras.append(PinholeCamera(f"cam{i}", (width, height_px), K, R=R, t=t))
    return cameras
