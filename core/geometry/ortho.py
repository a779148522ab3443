"""The scaled orthographic camera of Bregler & Malik (1998), eq. (11), optionally with a weak
perspective (``kappa``): the camera of the uncalibrated mode, fitted to one view of a body.

Conventions are those of :mod:`camera` (OpenCV camera axes and pixels,
``X_cam = R @ X_world + t``); the behaviour shared with the pinhole camera (world/camera
transforms, cached pixel rays, ``replace``) is ``camera._Camera``.
"""

import dataclasses
from typing import ClassVar

import numpy as np

from ..errors import ZoopraxisError
from .camera import (_Camera, _as_array, _as_points, _frozen, _from_dict, _scale_pixel,
                     check_image_size, check_rotation)


@dataclasses.dataclass(frozen=True, eq=False, repr=False)
class ScaledOrthoCamera(_Camera):
    """Scaled orthographic camera of Bregler & Malik (1998), eq. (11), with a principal point.

    .. math:: (u, v)^T = s\\,[R X + t]_{xy} + c

    Parameters
    ----------
    name : str
        View name.
    image_size : (int, int)
        Width and height in pixels.
    s : float
        Scale, pixels per metre.
    R : array_like, shape (3, 3), optional
        Rotation world -> camera; default identity.
    t : array_like, shape (3,), optional
        Translation world -> camera; its z component only shifts ``depth``. Default zero.
    c : array_like, shape (2,), optional
        Principal point in pixels; default the image centre ``((w - 1) / 2, (h - 1) / 2)``.
    kappa : float, optional
        Perspective, as the inverse distance (1/m) from the camera to the world origin along
        ``forward``; default 0 (scaled orthographic). With ``kappa > 0`` the camera is a
        pinhole of focal length ``s / kappa`` pixels, with ``s`` the scale at the origin's
        depth: :math:`(u, v)^T = s\\,[R X + t]_{xy} / (1 + \\kappa\\,(R X)_z) + c`. One
        uncalibrated view of a near body fits it (:mod:`initialize`).

    Convention:
        Camera axes are OpenCV's. ``depth`` is the camera z, ``(R @ X + t)[2]``, and may be
        negative. With ``kappa = 0`` rays are parallel, along the camera +z axis (``forward``),
        and the camera has no centre (it is at infinity): ``center`` is None. With
        ``kappa > 0`` they meet at ``center``, at depth ``t[2] - 1 / kappa``.
    """

    model: ClassVar[str] = "scaled_orthographic"

    name: str
    image_size: tuple
    s: float
    R: np.ndarray = None
    t: np.ndarray = None
    c: np.ndarray = None
    kappa: float = 0.0

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise ZoopraxisError(f"camera name must be a non-empty string, got {self.name!r}")
        where = f"camera '{self.name}'"
        set_ = object.__setattr__
        kappa = float(_as_array(self.kappa, (), f"{where}: kappa"))
        if kappa < 0.0:
            raise ZoopraxisError(f"{where}: kappa (1 / distance in metres) must be 0 or more, "
                                 f"got {kappa:g}")
        set_(self, "kappa", kappa)
        size = check_image_size(self.image_size, f"{where}: image_size")
        set_(self, "image_size", size)
        s = float(_as_array(self.s, (), f"{where}: s"))
        if s <= 0:
            raise ZoopraxisError(f"{where}: s (pixels per metre) must be positive, got {s:g}")
        set_(self, "s", s)
        set_(self, "R", _frozen(np.eye(3) if self.R is None
                                else check_rotation(self.R, f"{where}: R")))
        set_(self, "t", _frozen(np.zeros(3) if self.t is None
                                else _as_array(self.t, (3,), f"{where}: t")))
        c = ((size[0] - 1) / 2, (size[1] - 1) / 2) if self.c is None else self.c
        set_(self, "c", _frozen(_as_array(c, (2,), f"{where}: c")))

    def __repr__(self):
        kappa = f", kappa={self.kappa:.6g}" if self.kappa else ""
        return self._short_repr(f"s={self.s:.6g}, c=({self.c[0]:.6g}, {self.c[1]:.6g}){kappa}")

    @property
    def center(self):
        """None when ``kappa`` is 0: the camera is at infinity (use ``forward``,
        ``pixel_rays``). Else the centre of projection in world coordinates, shape (3,)."""
        if not self.kappa:
            return None
        return self.world_from_cam([0.0, 0.0, self.t[2] - 1.0 / self.kappa])

    def project(self, X):
        """Project world points to pixels, eq. (11) with a principal point (and the
        perspective divide of ``kappa``).

        Convention: world (Z up, metres) to OpenCV pixels.

        Parameters
        ----------
        X : array_like, shape (..., 3)

        Returns
        -------
        uv : array, shape (..., 2)
        """
        X = _as_points(X, 3)
        if self.kappa:
            Xc = X @ self.R.T
            return self.s * (Xc[..., :2] + self.t[:2]) / (1.0 + self.kappa * Xc[..., 2:]) \
                + self.c
        return self.s * (X @ self.R[:2].T + self.t[:2]) + self.c

    def project_jacobian(self, X):
        """Project world points and return ``d uv / d X_world`` for each point (``s * R[:2]``
        when ``kappa`` is 0).

        Parameters
        ----------
        X : array_like, shape (..., 3)

        Returns
        -------
        uv : array, shape (..., 2)
        J : array, shape (..., 2, 3)
        """
        if self.kappa:
            Xc = _as_points(X, 3) @ self.R.T
            d = 1.0 + self.kappa * Xc[..., 2]
            num = Xc[..., :2] + self.t[:2]
            J = self.s * (self.R[:2] / d[..., None, None]
                          - (num * self.kappa / d[..., None]**2)[..., None] * self.R[2])
            return self.s * num / d[..., None] + self.c, J
        uv = self.project(X)
        return uv, np.broadcast_to(self.s * self.R[:2], uv.shape[:-1] + (2, 3)).copy()

    def undistort_points(self, uv):
        """Identity (a copy): the scaled orthographic model has no lens distortion."""
        return _as_points(uv, 2).copy()

    def distort_points(self, uv_ideal):
        """Identity (a copy): the scaled orthographic model has no lens distortion."""
        return _as_points(uv_ideal, 2).copy()

    def rays(self, uv):
        """Viewing rays through pixels, in world coordinates.

        Convention: OpenCV pixels to world rays; ``origin + d * dir`` projects back to ``uv``
        for every ``d > 0``. With ``kappa`` 0 the origin is on the plane ``z_cam = 0`` (and
        ``d`` may be negative too); else it is the camera centre, as for a pinhole.

        Parameters
        ----------
        uv : array_like, shape (..., 2)

        Returns
        -------
        origins : array, shape (..., 3), or (3,) when ``kappa`` is not 0
        dirs : array, shape (..., 3)
            Unit directions: all equal to ``forward`` when ``kappa`` is 0.
        """
        if self.kappa:
            center = self.center
            d = self.unproject(uv, self.t[2]) - center
            return center, d / np.linalg.norm(d, axis=-1, keepdims=True)
        origins = self.unproject(uv, 0.0)
        return origins, np.broadcast_to(self.R[2], origins.shape).copy()

    def unproject(self, uv, depth):
        """World points at a given camera depth on the rays through pixels.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
        depth : array_like, shape (...) or scalar
            Camera z of the wanted points.

        Returns
        -------
        X : array, shape (..., 3)
            World points with ``project(X) == uv`` and ``depth(X) == depth``.
        """
        xy = (_as_points(uv, 2) - self.c) / self.s
        z = np.broadcast_to(np.asarray(depth, dtype=np.float64), xy.shape[:-1])
        if self.kappa:
            xy = xy * (1.0 + self.kappa * (z - self.t[2]))[..., None]
        return self.world_from_cam(np.concatenate([xy, z[..., None]], axis=-1))

    def scaled(self, factor, sampling="pyramid"):
        """The camera that sees the same scene in the image resampled by ``factor``.

        Parameters
        ----------
        factor : float
            0.5 for one ``cv2.pyrDown`` level.
        sampling : {"pyramid", "resize"}
            As for ``PinholeCamera.scaled``.

        Returns
        -------
        camera : ScaledOrthoCamera
            ``s`` times ``factor``, principal point moved with the pixels (``kappa`` kept).
        """
        size = self._check_scaling(factor, sampling)
        return self.replace(image_size=size, s=self.s * factor,
                            c=_scale_pixel(self.c, factor, sampling))

    def to_dict(self):
        """The camera as a calibration.json entry, marked ``"model": "scaled_orthographic"``
        (``kappa`` only when not 0)."""
        entry = {"model": self.model, "name": self.name, "image_size": list(self.image_size),
                 "s": self.s, "R": self.R.tolist(), "t": self.t.tolist(), "c": self.c.tolist()}
        if self.kappa:
            entry["kappa"] = self.kappa
        return entry

    @classmethod
    def from_dict(cls, entry, source=None):
        """Make a camera from its calibration.json entry (``c`` and ``kappa`` optional; unknown
        keys ignored).

        Parameters
        ----------
        entry : dict
            With keys ``name``, ``image_size``, ``s``, ``R``, ``t`` and optionally ``c`` and
            ``kappa``.
        source : str, optional
            The file the entry comes from, named in error messages.

        Returns
        -------
        camera : ScaledOrthoCamera
        """
        return _from_dict(cls, entry, ("name", "image_size", "s", "R", "t"), source,
                          ("c", "kappa"))
