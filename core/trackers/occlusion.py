"""Occlusion and silhouette coverage for the image likelihood: capsules around the primitives'
axes (:class:`Occluders`), whether a surface point hides behind a nearer limb's capsule (the
per-point occlusion test that refines eq. 11 of Sidenbladh, Black & Fleet 2000), and which drawn
foreground pixels the capsules cover (the two-sided silhouette cue).

Convention: world Z up, metres; cameras ``X_c = R @ X_w + t`` with OpenCV axes and pixels.
"""

from dataclasses import dataclass

import numpy as np

from ..body import primitives


@dataclass(frozen=True)
class Occluders:
    """Axes and cross-sections of the primitives: capsules for occlusion tests, and the
    frames of the camera-facing patches.

    Attributes
    ----------
    segment : array of int, shape (O,)
    kind : array of int, shape (O,)
        ``primitives.CYLINDER`` or ``primitives.ELLIPSOID``.
    ends : array, shape (O, 2, 4)
        The axis end points, homogeneous, in segment reference coordinates (a cylinder's base
        and top; an ellipsoid's capsule along its longest semi-axis).
    axes : array, shape (O, 2, 3)
        Cross-section axes (unit), segment reference coordinates.
    radii : array, shape (O, 2)
        Cross-section radii along those axes at the first end.
    taper : array, shape (O,)
        Radius at the second end over radius at the first (1 for ellipsoids).
    """

    segment: np.ndarray
    kind: np.ndarray
    ends: np.ndarray
    axes: np.ndarray
    radii: np.ndarray
    taper: np.ndarray

    @classmethod
    def from_primitives(cls, prims):
        segment, ends, axes, radii, taper = [], [], [], [], []
        for p in range(len(prims)):
            T = prims.prim2seg[p]
            size = prims.size[p]
            if prims.kind[p] == primitives.CYLINDER:
                a, b = T[:3, 3], T[:3, 3] + size[2] * T[:3, 2]
                ax, r, tp = T[:3, :2].T, size[:2], prims.taper[p]
            else:
                k = int(np.argmax(size))
                others = [i for i in range(3) if i != k]
                r = size[others]
                half = max(size[k] - r.max(), 0.0)
                a = T[:3, 3] - half * T[:3, k]
                b = T[:3, 3] + half * T[:3, k]
                ax, tp = T[:3, others].T, 1.0
            segment.append(prims.segment[p])
            ends.append(np.stack([np.append(a, 1.0), np.append(b, 1.0)]))
            axes.append(ax)
            radii.append(r)
            taper.append(tp)
        return cls(np.array(segment, int), np.array(prims.kind, int), np.array(ends),
                   np.array(axes), np.array(radii), np.array(taper, float))


class CapsuleTests:
    """The capsule tests of :class:`likelihood.ImageLikelihood`, which this class is a part of.

    It reads the likelihood's ``occluders`` (:class:`Occluders`), ``cameras``, ``_foreground``
    (per view None or ``(mask, u, v)`` of the drawn foreground pixels), ``silhouette``,
    ``silhouette_floor`` and ``beta``, and its ``_cam_from_seg``.
    """

    def _capsule(self, cam, cam_from_seg, o):
        """Image geometry of occluder ``o`` for a batch of poses, each array (N, 1).

        Returns ``(ax, ay, bx, by, inv_len2, za, dz, fw)``: the projected axis start and the
        vector to its end (pixels), the inverse squared length of that vector, the camera depth
        at the start and its change along the axis, and focal length times the silhouette
        half-width (so the radius in pixels at depth z is ``fw / z``).
        """
        occ = self.occluders
        Co = cam_from_seg[:, occ.segment[o]]                                  # (N, 3, 4)
        E = Co @ occ.ends[o].T.astype(np.float32)                             # (N, 3, 2)
        K = cam.K
        with np.errstate(divide="ignore", invalid="ignore"):
            u = K[0, 0] * E[:, 0] / E[:, 2] + K[0, 1] * E[:, 1] / E[:, 2] + K[0, 2]
            v = K[1, 1] * E[:, 1] / E[:, 2] + K[1, 2]
        bx, by = u[:, 1] - u[:, 0], v[:, 1] - v[:, 0]
        # Silhouette half-width of an elliptic cross-section seen along the line of sight: the
        # support function perpendicular to the view within the section plane.
        view = E.mean(axis=2)
        axes = Co[:, :, :3] @ occ.axes[o].T.astype(np.float32)                # (N, 3, 2)
        dx = np.sum(view * axes[:, :, 0], axis=1)
        dy = np.sum(view * axes[:, :, 1], axis=1)
        rx, ry = occ.radii[o] * 0.5 * (1.0 + occ.taper[o])
        dd = dx * dx + dy * dy
        along = dd <= 1e-6 * np.sum(view * view, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            width = np.where(along, max(rx, ry), np.sqrt((rx * rx * dy * dy + ry * ry * dx * dx)
                                                         / np.where(along, 1.0, dd)))
        f = 0.5 * (K[0, 0] + K[1, 1])
        return (u[:, 0:1], v[:, 0:1], bx[:, None], by[:, None],
                1.0 / np.maximum(bx * bx + by * by, 1e-6)[:, None], E[:, 2, 0:1],
                (E[:, 2, 1] - E[:, 2, 0])[:, None], (f * width)[:, None].astype(np.float32))

    @staticmethod
    def _capsule_distance(capsule, u, v):
        """Squared pixel distance of points (N, m) from a capsule's axis, its pixel radius there
        and the axis depth there, each (N, m)."""
        ax, ay, bx, by, inv_len2, za, dz, fw = capsule
        du, dv = u - ax, v - ay
        s = np.clip((du * bx + dv * by) * inv_len2, 0.0, 1.0)
        gx, gy = du - s * bx, dv - s * by
        z_axis = za + s * dz
        return gx * gx + gy * gy, fw / np.maximum(z_axis, 1e-3), z_axis

    def _occluded(self, cam, surf, geometry):
        """Points hidden behind a nearer limb's capsule, (N, M) bool."""
        C = geometry["cam_from_seg"]
        hidden = np.zeros(geometry["z"].shape, bool)
        u, v, z = geometry["u"], geometry["v"], geometry["z"]
        for o, cols in surf.pairs:
            dist2, radius, z_axis = self._capsule_distance(self._capsule(cam, C, o),
                                                           u[:, cols], v[:, cols])
            hidden[:, cols] |= (dist2 < radius * radius) & (z[:, cols] > z_axis)
        return hidden

    def coverage_of(self, seg2world):
        """Share of the drawn foreground pixels (all views) that the limbs of each pose cover.

        Parameters
        ----------
        seg2world : array, shape (N, S, 4, 4)

        Returns
        -------
        covered : array, shape (N,)
            NaN without foreground masks (:meth:`set_foreground`).
        """
        seg2world = np.asarray(seg2world)
        hits, count = np.zeros(seg2world.shape[0]), 0
        for cam, fg in zip(self.cameras, self._foreground):
            if fg is not None:
                hits += self._covered(cam, seg2world, fg[1], fg[2]).sum(axis=1)
                count += len(fg[1])
        return hits / count if count else np.full(len(hits), np.nan)

    def capsule_hits(self, seg2world, segments=None):
        """Which drawn foreground pixels each capsule covers, per view.

        Parameters
        ----------
        seg2world : array, shape (N, S, 4, 4)
        segments : sequence of int, optional
            Only the capsules of these segments (default all).

        Returns
        -------
        capsules : array of int
            The capsules (occluders) measured.
        hits : list of (array of bool, shape (N, len(capsules), K)) or None
            Per view (None where the view has no foreground mask).
        """
        occ = self.occluders
        caps = np.arange(len(occ.segment)) if segments is None else \
            np.flatnonzero(np.isin(occ.segment, segments))
        out = []
        for cam, fg in zip(self.cameras, self._foreground):
            if fg is None:
                out.append(None)
                continue
            C = self._cam_from_seg(cam, np.asarray(seg2world))
            hits = np.empty((C.shape[0], len(caps), len(fg[1])), bool)
            for i, o in enumerate(caps):
                dist2, radius, _ = self._capsule_distance(self._capsule(cam, C, o), fg[1][None],
                                                          fg[2][None])
                hits[:, i] = dist2 < radius * radius
            out.append(hits)
        return caps, out

    def coverage_from_hits(self, hits):
        """The coverage term and covered share from all capsules' hits (:meth:`capsule_hits`).

        Returns
        -------
        coverage, covered : array, shape (N,)
            As in :class:`LikelihoodResult`.
        """
        views = [h for h in hits if h is not None]
        if not views:
            return 0.0, np.nan
        floor = self.silhouette_floor
        coverage, covered, count = 0.0, 0.0, 0
        for h in views:
            any_hit = h.any(axis=1)
            covered = covered + any_hit.sum(axis=1)
            coverage = coverage + self.silhouette * np.where(any_hit, 0.0, np.log(floor)).sum(
                axis=1)
            count += h.shape[2]
        return self.beta * coverage, covered / count

    def _covered(self, cam, seg2world, u, v):
        """Whether some limb's capsule covers each pixel, (N, K) float32."""
        C = self._cam_from_seg(cam, seg2world)
        hit = np.zeros((C.shape[0], len(u)), bool)
        for o in range(len(self.occluders.segment)):
            dist2, radius, _ = self._capsule_distance(self._capsule(cam, C, o), u[None],
                                                      v[None])
            hit |= dist2 < radius * radius
        return hit.astype(np.float32)
