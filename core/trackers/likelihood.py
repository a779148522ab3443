"""Image likelihood of Sidenbladh, Black & Fleet (2000) §3.2 and §5, for many particles at once.

The appearance model is the previous image mapped onto the model at the previous estimate
(eq. 2): the model is rendered at the estimate of frame t-1 and points on the visible limb
surfaces keep their grey values from I(t-1), ``R_t = M(I_{t-1}, phi_{t-1})``. A particle moves
those points with its limbs and projects them into I(t) (``M^-1(R_t, phi_t, x)``). Brightness
constancy (eq. 3) says the two grey values agree up to noise, modelled as a Gaussian whose
variance grows as the surface turns away from the camera (eq. 4) mixed with uniform outliers
(eq. 10). Points hidden by nearer limbs, or seen edge-on, carry the constant ``p_occluded``
instead (eq. 11); limbs and views multiply (eq. 12), i.e. log-likelihoods add.

Which surface points: ``n`` pixels are drawn uniformly, with replacement, from each limb's
visible region in the render (§5), away from its rims. A point is kept from frame to frame while
the estimate keeps seeing it, so its grey value can also remember earlier frames
(``appearance_rate``, the "more persistent model of object appearance" the paper's §7 asks for).
How a point moves with its limb (``surface``):

- ``"attached"``: the point is fixed on the limb's surface (in segment coordinates), as texture
  is, so turning a limb about its own axis turns the points with it;
- ``"patch"``: the paper's planar approximation (Fig. 2): a primitive's appearance lives on
  the half of its surface that faces the camera, parameterized by the position along the axis
  and across the silhouette (a sphere's axis runs up the image); it follows the axis but not
  the turn about it, so the twist of a straight limb is invisible, as in the paper's arm
  example.

Two refinements of the printed equations, both in the paper's spirit:

- eq. (10) puts the outlier term outside the product over a limb's pixels; here the mixture is
  per pixel (the usual robust form), so one bad pixel does not veto a limb;
- occlusion (eq. 11) is decided per point rather than per limb, by testing each point against
  capsules around the nearer limbs (the refinement the paper suggests after eq. 11, cf. its
  [21]); ``q = cos(alpha)`` for visible points and 0 for hidden ones. The capsules and their
  tests are in :mod:`occlusion`.

Images are grey, 0..255, smoothed by a Gaussian of standard deviation sqrt(2) (§5).

An optional silhouette cue, not in the paper, anchors the appearance: the appearance is the
previous estimate's own image, so an estimate that slips a little is matched against where it
slipped to, and the error accumulates (drift). Given a foreground mask per view
(:meth:`ImageLikelihood.set_foreground`, from a background model), every compared point should
fall on the foreground, and foreground pixels drawn from the mask should fall inside some
limb's silhouette (the capsules of the occlusion test); each point and pixel contributes
``silhouette * log(floor + (1 - floor) m)``, ``m`` the (softened) mask value or whether a
capsule covers the pixel. The second half makes the cue two-sided: a limb the model misses
leaves foreground uncovered. Three options make it stricter where one view leaves limbs free
(the particle tracker turns them on for one view): points along every limb's axis are
checked too, whether its surface was seen or hidden at the reference (``axis_points``); a
point off the foreground counts as the background's, like a hidden point, instead of matching
its appearance (``background_points``); and the pixels to cover can be drawn from a stricter
mask than the one the points are checked against (``set_foreground``'s ``cover``).

Convention: world Z up, metres; cameras ``X_c = R @ X_w + t`` with OpenCV axes and pixels.
``seg2world`` arrays map each segment's reference-frame coordinates into the world (see
:mod:`body`). A point is a basis vector of 6 numbers that a (3, 6) matrix per limb and particle
maps into the camera frame: ``(x, y, z, 1, 0, 0)`` under ``cam_from_seg`` for attached points,
``(1, s, w, h, s w, s h)`` under the patch matrix for patch points.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from ..imaging import render
from ..errors import ZoopraxisError
from ..imaging.plates import to_gray_float
from .occlusion import CapsuleTests, Occluders
from .silhouette_cue import SilhouetteCue

SMOOTHING_SIGMA = np.sqrt(2.0)
SURFACES = ("attached", "patch")

# Particles per vectorized batch: large enough to amortize the per-limb Python loop, small
# enough that the (batch, points) temporaries stay in cache.
_CHUNK = 2048

# How far (metres) a point may lie off the rendered surface at the reference and still count
# as seen there; and how far in front of an occluder's axis a limb's points may lie and still
# be tested against it (a frame's motion in depth).
_DEPTH_MARGIN = 0.03

# cv2.remap takes maps of at most this many rows and columns.
_MAX_MAP = 32767

# Surface angles beyond this are treated as this in eq. (4), so sigma stays finite; q = cos
# alpha already makes such points nearly irrelevant.
_MIN_COS = 0.1

_BASIS = 6

_ATTACHED = -1


def prepare_image(image, smoothing=SMOOTHING_SIGMA):
    """Grey float32 image in 0..255, smoothed by a Gaussian (§5).

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, 3|4)
        Any format :func:`plates.to_gray_float` accepts (BGR colour is converted to grey).
    smoothing : float
        Standard deviation of the Gaussian in pixels; 0 for none.

    Returns
    -------
    gray : array of float32, shape (H, W)
    """
    gray = to_gray_float(image) * np.float32(255.0)
    if smoothing > 0:
        gray = cv2.GaussianBlur(gray, (0, 0), smoothing, borderType=cv2.BORDER_REPLICATE)
    return np.ascontiguousarray(gray, dtype=np.float32)


@dataclass
class SurfacePoints:
    """Where one view compares images: points on the limbs seen at the reference.

    Attributes
    ----------
    groups : tuple of (int, int)
        ``(segment, primitive)`` of each group of points; primitive -1 for attached points.
    slices : tuple of slice
        ``slices[i]`` are group i's points.
    basis : array of float32, shape (6, M)
        Each point's basis vector (see the module Convention).
    normal_basis : array of float32, shape (6, M)
        The same for the surface normal.
    values : array of float32, shape (M,)
        The appearance ``R_t``: each point's grey value.
    pairs : list of (int, array of int)
        ``(o, columns)``: the points ``columns`` are tested against occluder ``o``.
    """

    groups: tuple
    slices: tuple
    basis: np.ndarray
    normal_basis: np.ndarray
    values: np.ndarray
    pairs: list

    @property
    def n_points(self):
        return self.basis.shape[1]

    @property
    def segments(self):
        """Segment of every group."""
        return tuple(k for k, _ in self.groups)


@dataclass
class LikelihoodResult:
    """Log-likelihoods of a set of particles, and how well they explain the image.

    Attributes
    ----------
    log_likelihood : array, shape (N,)
        ``beta * sum log p`` over points and views (eqs. 10-12).
    inliers : array, shape (N,)
        Share of the compared points (weighted by ``q``) whose grey difference is within
        2.5 sigma: near 1 when the appearance moves with the particle, near 0 when lost.
    compared : array, shape (N,)
        Share of the points that were visible and inside the images (sum of ``q`` over points).
    per_segment : array, shape (N, S)
        The appearance terms of ``log_likelihood`` (with the silhouette cue of the limbs'
        points) split by the segment the points lie on (eq. 12's factors, summed over views).
    coverage : array, shape (N,)
        The silhouette cue's foreground-coverage term (0 without foreground masks);
        ``log_likelihood`` is ``per_segment.sum(axis=1) + coverage``.
    covered : array, shape (N,)
        Share of the drawn foreground pixels that the particle's limbs cover (NaN without
        foreground masks).
    on_foreground : array, shape (N, S)
        Per segment, the mean foreground mask value at its points (the share of them that
        fall on the foreground); NaN for segments without points or without masks.
    """

    log_likelihood: np.ndarray
    inliers: np.ndarray
    compared: np.ndarray
    per_segment: np.ndarray
    coverage: np.ndarray
    covered: np.ndarray
    on_foreground: np.ndarray


def _empty_pool():
    return {"segment": np.zeros(0, int), "prim": np.zeros(0, int),
            "basis": np.zeros((0, _BASIS)), "normal_basis": np.zeros((0, _BASIS)),
            "value": np.zeros(0, np.float32), "missed": np.zeros(0, int)}


class ImageLikelihood(SilhouetteCue, CapsuleTests):
    """Robust grey-value likelihood of articulated poses in calibrated views (§5).

    Parameters
    ----------
    body : BodyModel
    cameras : list of PinholeCamera
        The views; images are passed in the same order.
    sigma_image : float
        ``sigma_I``, the grey-level noise of a fronto-parallel surface point (0..255 scale).
    epsilon : float
        Outlier share ``epsilon`` of eq. (10); outliers are uniform over 256 grey levels.
    p_occluded : float, optional
        Constant likelihood of a hidden point (eq. 11). Default 1/256: a hidden point's grey
        value is explained by something else, any value alike. That is far below a good match
        (a pose does not gain by hiding its limbs) and above an outlier (a limb that truly
        disappears behind another is not punished as a mismatch).
    n_points : int
        Points per limb and view (drawn with replacement, §5).
    beta : float
        Exponent on the likelihood (1 = the paper's).
    surface : {"attached", "patch"}
        How points move with their limb (see the module docstring).
    min_pixels : int
        Limbs showing fewer pixels at the reference are left out of that view.
    min_cos : float
        Points are used only where the surface faces the camera at least this much
        (``cos(alpha)``): at the rims a small error of the estimate, or a body a little wider
        or narrower than the model, puts background into the appearance.
    appearance_rate : float
        Weight of I(t-1) in a point's grey value; the rest is the point's previous value.
        1 is the paper's appearance (eq. 2, the previous image only); below 1 the points keep
        an exponentially fading memory of their texture, which resists drift: a small error
        of one estimate no longer becomes the next frame's appearance in full.
    keep_frames : int
        References a point may go unseen (hidden, turned away) before it is dropped.
    occlusion_margin : float
        Pixels by which a limb must clear an occluder's silhouette at the reference before
        their occlusion test is skipped for all particles (particles stay near the reference).
    silhouette : float
        Weight of the silhouette cue per point and foreground pixel (module docstring); it
        applies only while foreground masks are set.
    silhouette_points : int
        Foreground pixels drawn per view and frame for the coverage half of the cue.
    silhouette_floor : float
        Likelihood of a point off the foreground (or an uncovered pixel) relative to one on it.
    axis_points : int
        Points along each primitive's axis that the silhouette cue also checks, seen or not
        (0: none). A limb hidden at the reference behind another has no surface points, yet
        its image lies inside the person's silhouette as much as a seen limb's does: without
        them one view's far leg, hidden as it passes behind the near one, is free to wander
        onto the background and stays there.
    background_points : bool
        Whether a point off the foreground counts as the background's (``p_occluded``, as a
        hidden point) rather than compared with its appearance: a limb that slid onto a
        static background matches it perfectly frame after frame, since the appearance is
        mapped at the estimate.
    seed : int
        Seed of the pixel draws.
    """

    def __init__(self, body, cameras, *, sigma_image=4.0, epsilon=0.1, p_occluded=None,
                 n_points=40, beta=1.0, surface="attached", min_pixels=12, min_cos=0.2,
                 appearance_rate=0.5, keep_frames=4, occlusion_margin=12.0, silhouette=0.5,
                 silhouette_points=200, silhouette_floor=0.1, axis_points=0,
                 background_points=False, seed=0):
        if not cameras:
            raise ZoopraxisError("ImageLikelihood: no cameras given")
        for cam in cameras:
            if not hasattr(cam, "K"):
                raise ZoopraxisError(f"camera '{cam.name}': the particle likelihood needs a "
                                     "calibrated perspective camera")
        if not sigma_image > 0 or not 0 <= epsilon <= 1 or not n_points >= 1 or not beta > 0:
            raise ZoopraxisError("ImageLikelihood: need sigma_image > 0, 0 <= epsilon <= 1, "
                                 "n_points >= 1 and beta > 0")
        if n_points * body.n_segments >= _MAX_MAP:
            raise ZoopraxisError(f"ImageLikelihood: n_points={n_points} per limb is too many "
                                 f"(at most {(_MAX_MAP - 1) // body.n_segments})")
        if surface not in SURFACES:
            raise ZoopraxisError(f"ImageLikelihood: surface must be one of "
                                 f"{', '.join(SURFACES)}, got {surface!r}")
        if not 0 < appearance_rate <= 1:
            raise ZoopraxisError(f"ImageLikelihood: appearance_rate must be in (0, 1], got "
                                 f"{appearance_rate}")
        self.body = body
        self.cameras = list(cameras)
        self.prims = body.primitives()
        self.occluders = Occluders.from_primitives(self.prims)
        self.sigma_image = float(sigma_image)
        self.epsilon = float(epsilon)
        self.p_occluded = 1.0 / 256.0 if p_occluded is None else float(p_occluded)
        self.n_points = int(n_points)
        self.beta = float(beta)
        self.surface = surface
        self.min_pixels = int(min_pixels)
        self.min_cos = float(min_cos)
        self.appearance_rate = float(appearance_rate)
        self.keep_frames = int(keep_frames)
        self.occlusion_margin = float(occlusion_margin)
        if not silhouette >= 0 or not 0 < silhouette_floor < 1 or silhouette_points < 1:
            raise ZoopraxisError("ImageLikelihood: need silhouette >= 0, 0 < silhouette_floor "
                                 "< 1 and silhouette_points >= 1")
        self.silhouette = float(silhouette)
        self.silhouette_points = int(silhouette_points)
        self.silhouette_floor = float(silhouette_floor)
        self.background_points = bool(background_points)
        if int(axis_points) != axis_points or axis_points < 0:
            raise ZoopraxisError(f"ImageLikelihood: axis_points must be a whole number >= 0, "
                                 f"got {axis_points!r}")
        occ = self.occluders
        f = (np.arange(int(axis_points)) + 0.5) / max(int(axis_points), 1)
        # (P, 4) homogeneous points in segment coordinates and their segments
        self._axis_points = (occ.ends[:, :1] * (1 - f)[None, :, None]
                             + occ.ends[:, 1:] * f[None, :, None]).reshape(-1, 4)
        self._axis_segment = np.repeat(occ.segment, len(f))
        self._foreground = [None] * len(self.cameras)
        self.rng = np.random.default_rng(seed)
        self._pools = None
        self.surfaces = None
        self._subsets = {}

    # -- the appearance: where to look and what to expect -----------------------------------

    def set_reference(self, seg2world, images):
        """Map the previous images onto the model at the previous estimate (eq. 2).

        Points already on the limbs whose render at the reference shows them (in view, facing
        the camera, not hidden) take their grey value from I(t-1), blended into their old value
        by ``appearance_rate``; points unseen for more than ``keep_frames`` references are
        dropped, and every visible limb is topped up to ``n_points`` fresh points drawn from
        its visible pixels. Only the points seen at the reference are compared.

        Parameters
        ----------
        seg2world : array, shape (S, 4, 4)
            The estimate of frame t-1.
        images : list of array, shape (H, W) float32
            I(t-1) per view, from :func:`prepare_image`.
        """
        if len(images) != len(self.cameras):
            raise ZoopraxisError(f"ImageLikelihood: {len(self.cameras)} views but "
                                 f"{len(images)} images")
        seg2world = np.asarray(seg2world, float)
        if self._pools is None:
            self._pools = [_empty_pool() for _ in self.cameras]
        self.surfaces = []
        for v, (cam, image) in enumerate(zip(self.cameras, images)):
            self._pools[v], surf = self._update_pool(cam, seg2world,
                                                     self._check_image(cam, image),
                                                     self._pools[v])
            self.surfaces.append(surf)
        self._subsets = {}

    def reset(self):
        """Forget the appearance (a new track starts from the next reference)."""
        self._pools = None
        self.surfaces = None
        self._foreground = [None] * len(self.cameras)

    @staticmethod
    def _check_image(cam, image):
        if image.shape != (cam.height, cam.width):
            raise ZoopraxisError(f"view '{cam.name}': image is {image.shape[1]}x"
                                 f"{image.shape[0]}, the camera expects {cam.width}x{cam.height}")
        return image

    def _update_pool(self, cam, seg2world, image, pool):
        """Refresh one view's pool of points at the reference; return the pool and the
        :class:`SurfacePoints` of the points seen there."""
        res = render.render(cam, seg2world, self.prims, want=("point", "normal"))
        H, W = image.shape
        seen = np.zeros(0, bool)
        if len(pool["segment"]):
            g = self._project(cam, seg2world[None], self._as_surface(pool), normals=True)
            u, v, z, cos = g["u"][0], g["v"][0], g["z"][0], g["cos"][0]
            col, row = np.rint(u), np.rint(v)
            inside = (col >= 0) & (col < W) & (row >= 0) & (row < H) & (z > 0)
            col = np.where(inside, col, 0).astype(int)
            row = np.where(inside, row, 0).astype(int)
            seen = inside & (res.label[row, col] == pool["segment"]) \
                & (np.abs(res.depth[row, col] - z) < _DEPTH_MARGIN) & (cos > self.min_cos)
            if seen.any():
                now = cv2.remap(image, u[seen][None], v[seen][None], cv2.INTER_LINEAR,
                                borderMode=cv2.BORDER_REPLICATE)[0]
                a = np.float32(self.appearance_rate)
                pool["value"][seen] = (1 - a) * pool["value"][seen] + a * now
            pool["missed"] = np.where(seen, 0, pool["missed"] + 1)
            keep = pool["missed"] <= self.keep_frames
            pool = {k: v[keep] for k, v in pool.items()}
            seen = seen[keep]
        fresh = self._fresh_points(cam, seg2world, image, res, pool)
        if len(fresh["segment"]):
            pool = {k: np.concatenate([pool[k], fresh[k]]) for k in pool}
            seen = np.concatenate([seen, np.ones(len(fresh["segment"]), bool)])
        order = np.lexsort((pool["prim"], pool["segment"]))
        pool = {k: v[order] for k, v in pool.items()}
        seen = seen[order]
        surf = self._as_surface({k: v[seen] for k, v in pool.items()})
        surf.pairs = self._pairs(cam, seg2world, surf)
        # Points the capsule test calls hidden although the z-buffer saw them lie where the
        # capsules are a poor fit; leave them out so the test agrees with the render here.
        hidden = self._occluded(cam, surf, self._project(cam, seg2world[None], surf,
                                                         normals=False))[0]
        if hidden.any():
            surf = self._subset(surf, ~hidden)
        return pool, surf

    def _fresh_points(self, cam, seg2world, image, res, pool):
        """New points for every visible limb with fewer than ``n_points`` in the pool."""
        labels = res.label.ravel()
        prim_of = res.prim.ravel()
        points = res.point.reshape(-1, 3).astype(float)
        normals = res.normal.reshape(-1, 3).astype(float)
        sight = points - cam.center
        facing = -np.sum(normals * sight, axis=1) > self.min_cos * np.linalg.norm(sight, axis=1)
        grey = image.ravel()
        world2seg = np.linalg.inv(seg2world)
        counts = np.bincount(pool["segment"], minlength=self.body.n_segments)
        C = self._cam_from_seg(cam, seg2world[None]).astype(float)
        fresh = {k: [] for k in pool}
        for k in range(self.body.n_segments):
            missing = self.n_points - counts[k]
            pixels = np.flatnonzero((labels == k) & facing)
            if missing <= 0 or pixels.size < self.min_pixels:
                continue
            pick = pixels[self.rng.integers(0, pixels.size, missing)]
            prim = prim_of[pick].astype(int)
            if self.surface != "patch":
                prim = np.full(missing, _ATTACHED)
            basis = np.zeros((missing, _BASIS))
            normal_basis = np.zeros((missing, _BASIS))
            R, t = world2seg[k, :3, :3], world2seg[k, :3, 3]
            basis[:, :3] = points[pick] @ R.T + t
            basis[:, 3] = 1.0
            normal_basis[:, :3] = normals[pick] @ R.T
            for p in np.unique(prim[prim >= 0]):
                sel = prim == p
                basis[sel] = self._patch_coordinates(C, p, points[pick[sel]] @ cam.R.T + cam.t)
                normal_basis[sel] = basis[sel]
            fresh["segment"].append(np.full(missing, k))
            fresh["prim"].append(prim)
            fresh["basis"].append(basis)
            fresh["normal_basis"].append(normal_basis)
            fresh["value"].append(grey[pick].astype(np.float32))
            fresh["missed"].append(np.zeros(missing, int))
        if not fresh["segment"]:
            return _empty_pool()
        return {k: np.concatenate(v) for k, v in fresh.items()}

    def _patch_coordinates(self, cam_from_seg, p, X_cam):
        """Patch basis ``(1, s, w, h, s w, s h)`` of camera-frame points on primitive ``p``."""
        M, _ = self._patch_matrices(cam_from_seg, p)
        M = M[0].astype(float)
        a, d, across, toward, taper_a = M[:, 0], M[:, 1], M[:, 2], M[:, 3], M[:, 4]
        s = np.clip((X_cam - a) @ d / (d @ d), 0.0, 1.0)
        # taper_a = (taper - 1) * across, so the radius at s is (1 + (taper - 1) s) times.
        scale = 1.0 + s * (taper_a @ across) / (across @ across)
        off = X_cam - a - s[:, None] * d
        w = np.clip(off @ across / (across @ across) / scale, -1.0, 1.0)
        h = np.sqrt(1.0 - w * w)
        return np.stack([np.ones_like(s), s, w, h, s * w, s * h], axis=1)

    def _as_surface(self, pool):
        """SurfacePoints of a pool (sorted by segment and primitive), without pairs."""
        keys = np.stack([pool["segment"], pool["prim"]], axis=1)
        if len(keys) == 0:
            return SurfacePoints((), (), np.zeros((_BASIS, 0), np.float32),
                                 np.zeros((_BASIS, 0), np.float32), np.zeros(0, np.float32), [])
        change = np.flatnonzero(np.any(keys[1:] != keys[:-1], axis=1)) + 1
        starts = np.concatenate([[0], change])
        ends = np.append(change, len(keys))
        return SurfacePoints(
            tuple((int(keys[a, 0]), int(keys[a, 1])) for a in starts),
            tuple(slice(int(a), int(b)) for a, b in zip(starts, ends)),
            pool["basis"].T.astype(np.float32), pool["normal_basis"].T.astype(np.float32),
            pool["value"].astype(np.float32), [])

    def _subset(self, surf, keep):
        groups, slices, start = [], [], 0
        for g, sl in zip(surf.groups, surf.slices):
            count = int(keep[sl].sum())
            if count:
                groups.append(g)
                slices.append(slice(start, start + count))
                start += count
        renumber = np.cumsum(keep) - 1
        pairs = []
        for o, cols in surf.pairs:
            cols = renumber[cols[keep[cols]]]
            if cols.size:
                pairs.append((o, cols))
        return SurfacePoints(tuple(groups), tuple(slices), surf.basis[:, keep],
                             surf.normal_basis[:, keep], surf.values[keep], pairs)

    def _pairs(self, cam, seg2world, surf):
        """(occluder, points) pairs whose occlusion can change near the reference.

        A point is tested against an occluder of another segment if it lies within
        ``occlusion_margin`` pixels of the occluder's silhouette and behind (or within
        ``_DEPTH_MARGIN`` in front of) its axis at the reference; particles stay near the
        reference, so other points cannot be hidden by it.
        """
        occ = self.occluders
        g = self._project(cam, seg2world[None], surf, normals=False)
        u, v, z = g["u"], g["v"], g["z"]
        segment = np.zeros(surf.n_points, int)
        for (k, _), sl in zip(surf.groups, surf.slices):
            segment[sl] = k
        pairs = []
        for o in range(len(occ.segment)):
            dist2, radius, z_axis = self._capsule_distance(
                self._capsule(cam, g["cam_from_seg"], o), u, v)
            near = (np.sqrt(dist2) - radius < self.occlusion_margin) \
                & (z > z_axis - _DEPTH_MARGIN)
            cols = np.flatnonzero(near[0] & (segment != occ.segment[o]))
            if cols.size:
                pairs.append((o, cols))
        return pairs

    # -- the geometry of many particles -----------------------------------------------------

    @staticmethod
    def _cam_from_seg(cam, seg2world):
        """``cam_from_seg`` (N, S, 3, 4) in float32 for a batch of particles."""
        Rt = np.hstack([cam.R, cam.t[:, None]])
        return (Rt @ seg2world).astype(np.float32)

    def _patch_matrices(self, cam_from_seg, p):
        """Camera-frame matrices (N, 3, 6) taking patch bases to points and to normals.

        The patch of primitive ``p`` is its half facing the camera, as if it were a cylinder
        along its capsule axis (:class:`Occluders`): ``X = a + s d + r(s) (w
        e_across + h e_toward)`` with ``a`` the base centre, ``d`` the axis, ``e_across``
        perpendicular to the axis and the line of sight, ``e_toward`` perpendicular to the
        axis towards the camera, and ``r(s)`` the cross-section's extent in those directions
        (an elliptic section seen from its side is narrower than from its face), growing
        linearly with the taper.
        """
        occ = self.occluders
        C = cam_from_seg[:, occ.segment[p]]                                   # (N, 3, 4)
        E = C @ occ.ends[p].T.astype(np.float32)                              # (N, 3, 2)
        a, d = E[:, :, 0], E[:, :, 1] - E[:, :, 0]
        if not np.any(occ.ends[p, 0] != occ.ends[p, 1]):
            # A sphere has no axis: take the one up the image, through its centre.
            length = 2.0 * np.float32(occ.radii[p].max())
            up = np.cross(a, np.array([1.0, 0.0, 0.0], np.float32))
            d = -length * up / np.linalg.norm(up, axis=1, keepdims=True)
            a = a - 0.5 * d
        mid = a + 0.5 * d
        dn = d / np.linalg.norm(d, axis=1, keepdims=True)
        across = np.cross(dn, mid)
        across /= np.maximum(np.linalg.norm(across, axis=1, keepdims=True), 1e-9)
        toward = np.cross(dn, across)
        sec = C[:, :, :3] @ occ.axes[p].T.astype(np.float32)                  # (N, 3, 2)
        dx = np.sum(mid * sec[:, :, 0], axis=1)
        dy = np.sum(mid * sec[:, :, 1], axis=1)
        rx, ry = occ.radii[p]
        dd = np.maximum(dx * dx + dy * dy, 1e-12)
        r_across = np.sqrt((rx * rx * dy * dy + ry * ry * dx * dx) / dd)[:, None]
        r_toward = np.sqrt((rx * rx * dx * dx + ry * ry * dy * dy) / dd)[:, None]
        grow = np.float32(occ.taper[p] - 1.0)
        A, T = r_across * across, r_toward * toward
        M = np.stack([a, d, A, T, grow * A, grow * T], axis=2).astype(np.float32)
        zero = np.zeros_like(a)
        Nm = np.stack([zero, zero, across, toward, zero, zero], axis=2).astype(np.float32)
        return M, Nm

    def _group_matrices(self, C, surf, normals):
        """Per group, the (N, 3, 6) matrices for points and (if wanted) normals."""
        out = []
        for k, p in surf.groups:
            if p == _ATTACHED:
                M = np.zeros(C.shape[:1] + (3, _BASIS), np.float32)
                M[:, :, :4] = C[:, k]
                Nm = None
                if normals:
                    Nm = np.zeros_like(M)
                    Nm[:, :, :3] = C[:, k, :, :3]
                out.append((M, Nm))
            else:
                M, Nm = self._patch_matrices(C, p)
                out.append((M, Nm if normals else None))
        return out

    def _project(self, cam, seg2world, surf, normals=True):
        """Camera depths, pixels and surface angles of the points for every particle.

        Returns
        -------
        geometry : dict
            ``cam_from_seg`` (N, S, 3, 4); ``z`` (N, M) camera depth; ``u``, ``v`` (N, M)
            pixels; ``cos`` (N, M) cosine of the angle between the normal and the line of
            sight (only if ``normals``). Separate contiguous arrays keep the elementwise work
            that follows at memory speed.
        """
        C = self._cam_from_seg(cam, seg2world)
        N, M = C.shape[0], surf.n_points
        x, y, z = (np.empty((N, M), np.float32) for _ in range(3))
        if normals:
            nx, ny, nz = (np.empty((N, M), np.float32) for _ in range(3))
        for (P, Pn), sl in zip(self._group_matrices(C, surf, normals), surf.slices):
            # Row r of the group's matrix times the bases: an (N, 6) @ (6, m) product per row.
            b = surf.basis[:, sl]
            x[:, sl], y[:, sl], z[:, sl] = P[:, 0] @ b, P[:, 1] @ b, P[:, 2] @ b
            if normals:
                n = surf.normal_basis[:, sl]
                nx[:, sl], ny[:, sl], nz[:, sl] = Pn[:, 0] @ n, Pn[:, 1] @ n, Pn[:, 2] @ n
        cos = -(nx * x + ny * y + nz * z) / np.sqrt(x * x + y * y + z * z) if normals else None
        if cam.has_distortion:
            X = np.stack([x, y, z], axis=-1).astype(float)
            uv = cam.project(cam.world_from_cam(X)).astype(np.float32)
            u, v = uv[..., 0], uv[..., 1]
        else:
            K = cam.K
            with np.errstate(divide="ignore", invalid="ignore"):
                x /= z
                y /= z
            u = K[0, 0] * x + K[0, 1] * y + K[0, 2]
            v = K[1, 1] * y + K[1, 2]
        return {"cam_from_seg": C, "z": z, "u": u, "v": v, "cos": cos}

    # -- the likelihood ---------------------------------------------------------------------

    def _surfaces_of(self, segments):
        """Per view, the compared points that lie on the given segments (cached per
        reference)."""
        key = tuple(sorted(int(k) for k in segments))
        if key not in self._subsets:
            subsets = []
            for surf in self.surfaces:
                keep = np.zeros(surf.n_points, bool)
                for (k, _), sl in zip(surf.groups, surf.slices):
                    keep[sl] = k in key
                subsets.append(self._subset(surf, keep))
            self._subsets[key] = subsets
        return self._subsets[key]

    def evaluate(self, images, seg2world, previous=None, segments=None, with_coverage=True):
        """Log-likelihood of every particle (eqs. 3, 4, 10-12).

        Parameters
        ----------
        images : list of array, shape (H, W) float32
            I(t) per view, from :func:`prepare_image`.
        seg2world : array, shape (N, S, 4, 4)
            Every particle's segments at t.
        previous : (list of array, array of shape (N, S, 4, 4)), optional
            I(t-1) per view and every particle's segments at t-1. Given, each particle reads
            its appearance from I(t-1) at its own previous pose, as the paper's filter does
            (§4.1: "for each state sample from time t-1, we compute R_t"); by default all
            particles share the appearance mapped at the reference (:meth:`set_reference`).
        segments : sequence of int, optional
            Compare only the points on these segments (the factors of eq. 12 that a change of
            some limbs' angles can alter); default all.
        with_coverage : bool
            Weigh the foreground coverage (False: ``coverage`` is 0 and ``covered`` NaN; a
            caller that keeps :meth:`capsule_hits` updates it itself).

        Returns
        -------
        LikelihoodResult
        """
        if self.surfaces is None:
            raise ZoopraxisError("ImageLikelihood: call set_reference before evaluate")
        if len(images) != len(self.cameras):
            raise ZoopraxisError(f"ImageLikelihood: {len(self.cameras)} views but "
                                 f"{len(images)} images")
        seg2world = np.asarray(seg2world)
        N = seg2world.shape[0]
        if previous is not None:
            images_prev, seg2world_prev = previous
            if np.shape(seg2world_prev) != seg2world.shape:
                raise ZoopraxisError(f"ImageLikelihood: {np.shape(seg2world_prev)} previous "
                                     f"poses for {seg2world.shape} particles")
        surfaces = self.surfaces if segments is None else self._surfaces_of(segments)
        per_segment = np.zeros((N, self.body.n_segments))
        coverage = np.zeros(N)
        covered = np.zeros(N)
        fg_sum = np.zeros((N, self.body.n_segments))
        fg_count = np.zeros(self.body.n_segments)
        n_fg = 0
        good = np.zeros(N)
        weight = np.zeros(N)
        total = 0
        for v, (cam, surf, image) in enumerate(zip(self.cameras, surfaces, images)):
            if surf.n_points == 0:
                continue
            self._check_image(cam, image)
            total += surf.n_points
            if self._foreground[v] is not None:
                fg_count += np.bincount(np.repeat(surf.segments, [sl.stop - sl.start
                                                                  for sl in surf.slices]),
                                        minlength=self.body.n_segments)
            for start in range(0, N, _CHUNK):
                part = slice(start, min(start + _CHUNK, N))
                prev = None if previous is None else \
                    (self._check_image(cam, images_prev[v]), seg2world_prev[part])
                a, b, c, m = self._view(cam, surf, image, seg2world[part], prev,
                                        self._foreground[v])
                per_segment[part] += a
                if m is not None:
                    fg_sum[part] += m
                good[part] += b
                weight[part] += c
        for cam, fg in zip(self.cameras, self._foreground):
            if fg is None or not len(self._axis_segment):
                continue
            for start in range(0, N, _CHUNK):
                part = slice(start, min(start + _CHUNK, N))
                per_segment[part] += self._axis_term(cam, seg2world[part], fg[0])
        for cam, fg in zip(self.cameras, self._foreground):
            if fg is None or not with_coverage:
                continue
            n_fg += len(fg[1])
            for start in range(0, N, _CHUNK):
                part = slice(start, min(start + _CHUNK, N))
                hit = self._covered(cam, seg2world[part], fg[1], fg[2])
                covered[part] += hit.sum(axis=1)
                floor = self.silhouette_floor
                coverage[part] += self.silhouette * np.log(floor + (1 - floor) * hit).sum(
                    axis=1, dtype=np.float64)
        inliers = good / np.maximum(weight, 1e-12)
        per_segment *= self.beta
        coverage *= self.beta
        covered = covered / n_fg if n_fg else np.full(N, np.nan)
        with np.errstate(invalid="ignore", divide="ignore"):
            on_foreground = np.where(fg_count > 0, fg_sum / fg_count, np.nan)
        return LikelihoodResult(per_segment.sum(axis=1) + coverage, inliers,
                                weight / max(total, 1), per_segment, coverage, covered,
                                on_foreground)

    @staticmethod
    def _sample(image, geometry):
        """Bilinear grey values at the projected points, and which points fell in the image."""
        H, W = image.shape
        u, v = geometry["u"], geometry["v"]
        inside = (geometry["z"] > 1e-3) & (u >= 0) & (u <= W - 1) & (v >= 0) & (v <= H - 1)
        mx = np.nan_to_num(u, nan=-1.0, posinf=-1.0, neginf=-1.0)
        my = np.nan_to_num(v, nan=-1.0, posinf=-1.0, neginf=-1.0)
        values = cv2.remap(image, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                           borderValue=0.0)
        return values, inside

    def _view(self, cam, surf, image, seg2world, previous=None, foreground=None):
        now = self._project(cam, seg2world, surf, normals=True)
        predicted, inside = self._sample(image, now)
        if previous is None:
            appearance = surf.values
        else:
            appearance, inside_prev = self._sample(
                previous[0], self._project(cam, previous[1], surf, normals=False))
            inside &= inside_prev
        diff = predicted - appearance
        cos = np.clip(now["cos"], 0.0, 1.0)
        hidden = self._occluded(cam, surf, now)
        q = np.where(inside & ~hidden, cos, np.float32(0.0))
        on_fg = None
        if foreground is not None:
            m, _ = self._sample(foreground[0], now)
            if self.background_points:
                # A point on the background is the background's, as a hidden point is a
                # nearer limb's: its grey value says nothing of the limb (p_occluded),
                # whether or not it matches.
                q = q * m
        # eq. (4): sigma = sigma_I / cos(alpha); eq. (10) per pixel; eq. (11) mixes in p_occ.
        inv_sigma = np.maximum(cos, _MIN_COS) / np.float32(self.sigma_image)
        r2 = (diff * inv_sigma) ** 2
        eps = self.epsilon
        gauss = np.float32((1.0 - eps) / np.sqrt(2.0 * np.pi)) * inv_sigma * np.exp(-0.5 * r2)
        p = q * (gauss + np.float32(eps / 256.0)) + (1.0 - q) * np.float32(self.p_occluded)
        logp = np.log(p)
        if foreground is not None:
            floor = np.float32(self.silhouette_floor)
            logp += np.float32(self.silhouette) * np.log(floor + (1 - floor) * m)
        # Sums per group of points, then per segment (a segment may have several groups).
        starts = [sl.start for sl in surf.slices]
        by_group = np.add.reduceat(logp, starts, axis=1, dtype=np.float64)
        owner = np.zeros((len(starts), self.body.n_segments))
        owner[np.arange(len(starts)), surf.segments] = 1.0
        if foreground is not None:
            on_fg = np.add.reduceat(m, starts, axis=1, dtype=np.float64) @ owner
        good = np.sum(q * (r2 < 6.25), axis=1, dtype=np.float64)
        return by_group @ owner, good, np.sum(q, axis=1, dtype=np.float64), on_fg


__all__ = ["ImageLikelihood", "LikelihoodResult", "SurfacePoints", "prepare_image",
           "SMOOTHING_SIGMA", "SURFACES"]
