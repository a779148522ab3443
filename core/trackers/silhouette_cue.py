"""The silhouette cue of the particle filter's likelihood (:class:`likelihood.ImageLikelihood`):
the foreground masks a frame is weighed against, and the points along the limbs' axes that
must lie in them.

The cue itself is described in :mod:`likelihood`; this is its share of the likelihood's
state: per view, the softened mask the limbs' points are checked against and the pixels the
limbs must cover.
"""

import cv2
import numpy as np

from ..errors import ZoopraxisError

# The silhouette cue draws its foreground pixels from the mask eroded by this element, and
# checks the limbs' points against the mask dilated by it.
_ERODE = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))


class SilhouetteCue:
    """Mixed into :class:`likelihood.ImageLikelihood`, whose attributes it reads (cameras,
    silhouette, silhouette_points, silhouette_floor, rng, body, the axis points) and whose
    projection helpers it calls."""

    def set_foreground(self, masks, cover=None):
        """Foreground masks of the frame being weighed, for the silhouette cue.

        Parameters
        ----------
        masks : list of (array of bool, shape (H, W), or None), or None
            One per view (None: no cue in that view); None switches the cue off. Where the
            limbs' points may lie: what a background model cannot tell from the person
            (cast shadows, clothes the floor's shade, pixels it never saw free) belongs here.
        cover : list of (array of bool or None), optional
            Per view, the pixels the limbs must cover (the coverage half of the cue draws
            its pixels from these): only what is surely the person, without cast shadows or
            pixels the background model never saw; a limb drawn to cover those leaves the
            body. Default ``masks``.
        """
        if masks is None:
            self._foreground = [None] * len(self.cameras)
            return
        if len(masks) != len(self.cameras):
            raise ZoopraxisError(f"ImageLikelihood: {len(self.cameras)} views but "
                                 f"{len(masks)} foreground masks")
        if cover is not None and len(cover) != len(self.cameras):
            raise ZoopraxisError(f"ImageLikelihood: {len(self.cameras)} views but "
                                 f"{len(cover)} masks to cover")
        out = []
        for v, (cam, mask) in enumerate(zip(self.cameras, masks)):
            if mask is None or self.silhouette == 0:
                out.append(None)
                continue
            mask = np.asarray(mask, bool)
            drawn = mask if cover is None or cover[v] is None else np.asarray(cover[v], bool)
            if mask.shape != (cam.height, cam.width) or drawn.shape != mask.shape:
                raise ZoopraxisError(f"view '{cam.name}': foreground mask is {mask.shape[1]}x"
                                     f"{mask.shape[0]}, the camera expects "
                                     f"{cam.width}x{cam.height}")
            # Pixels drawn a few pixels inside the outline: the model's limbs are not the
            # person's, and a slightly wider person should not draw limbs sideways.
            inner = cv2.erode(drawn.astype(np.uint8), _ERODE) > 0
            rows, cols = np.nonzero(inner if inner.any() else drawn)
            if rows.size == 0:
                out.append(None)
                continue
            pick = self.rng.integers(0, rows.size, self.silhouette_points)
            # Grown and softened so that a point a few pixels off the outline (a model limb
            # a little wider than the person's) is not treated as far outside.
            soft = cv2.GaussianBlur(cv2.dilate(mask.astype(np.uint8), _ERODE).astype(
                np.float32), (0, 0), 1.5)
            out.append((soft, cols[pick].astype(np.float32), rows[pick].astype(np.float32)))
        self._foreground = out

    def _axis_term(self, cam, seg2world, mask):
        """The silhouette cue of the points along the primitives' axes (``axis_points``),
        summed per segment, (N, S); points outside the image count as on the foreground."""
        C = self._cam_from_seg(cam, seg2world)                     # (N, S, 3, 4)
        X = np.einsum("npij,pj->npi", C[:, self._axis_segment],
                      self._axis_points.astype(np.float32))
        z = X[..., 2]
        if cam.has_distortion:
            uv = cam.project(cam.world_from_cam(X.astype(float))).astype(np.float32)
            geometry = {"u": uv[..., 0], "v": uv[..., 1], "z": z}
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                uv = X @ cam.K.T.astype(np.float32)
                geometry = {"u": uv[..., 0] / z, "v": uv[..., 1] / z, "z": z}
        m, inside = self._sample(mask, geometry)
        m = np.where(inside, m, np.float32(1.0))
        floor = np.float32(self.silhouette_floor)
        logp = np.float32(self.silhouette) * np.log(floor + (1 - floor) * m)
        owner = np.zeros((len(self._axis_segment), self.body.n_segments), np.float32)
        owner[np.arange(len(self._axis_segment)), self._axis_segment] = 1.0
        return (logp @ owner).astype(np.float64)
