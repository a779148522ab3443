"""Model renderer: support map, depth, surface points and normals by ray casting quadrics.

The body is a set of primitives (ellipsoids and elliptic cone frustums with flat caps, made in
body.primitives), each rigidly attached to one segment. For every pixel the renderer intersects
the camera ray with the primitives and keeps the nearest hit in a z-buffer, so self-occlusion
falls out. It gives:

- the support map (Bregler & Malik §2.4: "the projection of the ellipsoids into the image"),
  which is also Yamamoto et al.'s *region image* (§2.4, Fig. 4): the segment label per pixel;
- the *depth image* (Yamamoto et al. §2.4-2.5, Fig. 4): camera z of the visible surface;
- the 3D surface point ``q_c`` per pixel, "the solution of a quadratic equation" (Bregler &
  Malik §2.2, after eq. 14; step 1 of the recipe in §2.5);
- the outward surface normal, for Sidenbladh et al.'s weighting by surface orientation
  (§3.2, §5).

Each primitive only casts the rays inside the projection of its bounding box, vectorized over
that pixel rectangle in float32; points and normals are computed afterwards for the visible
pixels only. This module chooses the rays (the cached pixel rays of a camera, the
rectangle of each primitive) and keeps the nearest hit; the intersections themselves, and the
points and normals, are in raycast.

Convention: world right-handed, Z up, metres. Pixels OpenCV style (origin at the centre of the
top-left pixel, x right, y down). Camera axes OpenCV (x right, y down, z forward), extrinsics
world -> camera ``X_c = R @ X_w + t``; "depth" is the camera z of a surface point.
"""

from collections import OrderedDict
import math
import threading
from dataclasses import dataclass
import weakref

import numpy as np

from ..errors import ZoopraxisError
from ..body.primitives import CYLINDER, Primitives
from . import raycast

# Bounding rectangles grow by this many pixels so the rounding of projected corners (and mild
# lens distortion between projected corners and undistorted rays) cannot clip a silhouette.
_MARGIN_PX = 2.0

# Corners closer to the camera plane than this (metres) make the projected box unreliable: the
# primitive straddles the camera plane and is then cast against the whole window.
_NEAR_Z = 1e-6

_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])

# ---------------------------------------------------------------------------------------------
# Result
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class RenderResult:
    """Per-pixel rendering of a body in one view (or at a list of pixels).

    Attributes
    ----------
    label : array of int16, shape (H, W) or (N,)
        Segment label of the visible surface (the support map); -1 on background.
    prim : array of int16, same shape
        Index of the visible primitive; -1 on background.
    depth : array of float32, same shape
        Camera z of the visible surface point, metres; +inf on background.
    point : array of float32, shape (H, W, 3) or (N, 3), or None
        Visible surface point in world coordinates; NaN on background. None unless wanted.
    normal : array of float32, shape (H, W, 3) or (N, 3), or None
        Unit outward surface normal in world coordinates, facing the camera side; NaN on
        background. None unless wanted.
    """

    label: np.ndarray
    prim: np.ndarray
    depth: np.ndarray
    point: np.ndarray = None
    normal: np.ndarray = None

    def mask(self, segment):
        """Boolean support map of one segment, shape of ``label``."""
        return self.label == segment


# ---------------------------------------------------------------------------------------------
# Camera rays
# ---------------------------------------------------------------------------------------------

@dataclass(eq=False)
class _Rays:
    """A batch of camera rays: float32 components of any common shape ``S``.

    ``d`` (3, *S) is the world direction scaled to unit camera depth, so that along the ray
    ``X = o + s d`` the depth is ``depth0 + s``. A pinhole camera has one origin (``origin``,
    float64 (3,), the camera centre) and ``depth0 = 0``; a parallel projection has per-ray
    origins ``o`` (3, *S) and their camera depths ``depth0`` (*S).
    """

    d: np.ndarray
    origin: np.ndarray = None
    o: np.ndarray = None
    depth0: np.ndarray = None

    @property
    def pinhole(self):
        return self.origin is not None

    def take(self, index):
        """The rays at ``index``, flattened to shape (n,): a tuple of slices over the trailing
        axes, or an array of indices into the flattened trailing axes."""
        if isinstance(index, tuple):
            def pick(a, lead):
                return a[(slice(None),) * lead + index].reshape((3,) * lead + (-1,))
        else:
            def pick(a, lead):
                return np.take(a.reshape((3,) * lead + (-1,)), index, axis=lead)
        if self.pinhole:
            return _Rays(pick(self.d, 1), origin=self.origin)
        return _Rays(pick(self.d, 1), o=pick(self.o, 1), depth0=pick(self.depth0, 0))


# Prepared float32 ray grids, keyed by the identity of the camera's cached ``pixel_rays``
# arrays: converting 640x480 rays costs a few milliseconds, as much as rendering.
_GRID_CACHE = OrderedDict()
_GRID_CACHE_SIZE = 16
_GRID_LOCK = threading.Lock()      # views may be rendered from several threads


def _check_camera(camera):
    for name in ("image_size", "R", "t", "project", "pixel_rays", "cam_from_world"):
        if not hasattr(camera, name):
            raise ZoopraxisError(f"render: camera has no '{name}' "
                                 f"(got a {type(camera).__name__})")


def _camera_grid(camera):
    """The camera's pixel rays as :class:`_Rays` of shape (H, W), and the image size (W, H)."""
    _check_camera(camera)
    W, H = (int(v) for v in camera.image_size)
    R = np.asarray(camera.R, dtype=float)
    t = np.asarray(camera.t, dtype=float)
    origins, dirs = camera.pixel_rays()
    key = (id(dirs), id(origins))
    with _GRID_LOCK:
        entry = _GRID_CACHE.get(key)
        if entry is not None:
            dirs_ref, origins_ref, R0, t0, size0, rays = entry
            if dirs_ref() is dirs and origins_ref() is origins and (W, H) == size0 \
                    and np.array_equal(R0, R) and np.array_equal(t0, t):
                _GRID_CACHE.move_to_end(key)
                return rays, (W, H)
    rays = _prepare_grid(origins, dirs, R, t, W, H)
    try:
        refs = (weakref.ref(dirs), weakref.ref(origins))
        # The entry goes when the camera's rays go, so ids are never reused stale.
        weakref.finalize(dirs, _forget_grid, key)
    except TypeError:  # not weak-referenceable: recompute next time
        return rays, (W, H)
    with _GRID_LOCK:
        _GRID_CACHE[key] = refs + (R.copy(), t.copy(), (W, H), rays)
        while len(_GRID_CACHE) > _GRID_CACHE_SIZE:
            _GRID_CACHE.popitem(last=False)
    return rays, (W, H)


def _forget_grid(key):
    with _GRID_LOCK:
        _GRID_CACHE.pop(key, None)


def _prepare_grid(origins, dirs, R, t, W, H):
    dirs = np.asarray(dirs, dtype=float)
    origins = np.asarray(origins, dtype=float)
    if dirs.shape != (H, W, 3):
        raise ZoopraxisError(f"render: camera.pixel_rays() directions have shape {dirs.shape}, "
                             f"expected (H, W, 3) = ({H}, {W}, 3) from image_size")
    if origins.shape not in ((3,), (H, W, 3)):
        raise ZoopraxisError(f"render: camera.pixel_rays() origins have shape {origins.shape}, "
                             f"expected (3,) or ({H}, {W}, 3)")
    return _prepare_rays(origins, dirs, R, t)


def _prepare_rays(origins, dirs, R, t):
    """Camera rays (origins (3,) or (..., 3), unit dirs (..., 3), world) as :class:`_Rays`.

    The same elementwise arithmetic for a whole grid and for single pixels keeps
    :func:`render_points` equal to :func:`render` at pixel centres.
    """
    # Camera z per unit of ray length; NaN rays (past the fold of a lens model) stay NaN and
    # never hit anything.
    ray_depth = dirs[..., 0] * R[2, 0] + dirs[..., 1] * R[2, 1] + dirs[..., 2] * R[2, 2]
    if np.any(ray_depth <= 0):
        raise ZoopraxisError("render: camera rays must point in front of the camera "
                             "(positive camera z)")
    d = np.moveaxis(dirs / ray_depth[..., None], -1, 0)
    d = np.ascontiguousarray(d, dtype=np.float32)
    if origins.shape == (3,):
        return _Rays(d, origin=origins.copy())
    origins = np.broadcast_to(origins, dirs.shape)
    o = np.ascontiguousarray(np.moveaxis(origins, -1, 0), dtype=np.float32)
    depth0 = origins[..., 0] * R[2, 0] + origins[..., 1] * R[2, 1] + origins[..., 2] * R[2, 2]
    depth0 += t[2]
    return _Rays(d, o=o, depth0=depth0.astype(np.float32))


# ---------------------------------------------------------------------------------------------
# Public entry points
# ---------------------------------------------------------------------------------------------

def _check_inputs(seg2world, prims, want):
    if not isinstance(prims, Primitives):
        raise ZoopraxisError(f"render: prims must be Primitives, got {type(prims).__name__}")
    seg2world = np.asarray(seg2world, dtype=float)
    if seg2world.ndim != 3 or seg2world.shape[1:] != (4, 4):
        raise ZoopraxisError(f"render: seg2world must have shape (S, 4, 4), "
                             f"got {seg2world.shape}")
    if seg2world.shape[0] < prims.n_segments:
        raise ZoopraxisError(f"render: seg2world has {seg2world.shape[0]} segments but the "
                             f"primitives use label {prims.n_segments - 1}")
    if not np.all(np.isfinite(seg2world)):
        bad = np.flatnonzero(~np.all(np.isfinite(seg2world), axis=(1, 2)))[0]
        raise ZoopraxisError(f"render: seg2world[{bad}] has non-finite entries")
    # np.isclose's test (all entries are finite here), without its overhead
    bad = np.flatnonzero(~np.all(np.abs(seg2world[:, 3] - _LAST_ROW) <= 1e-8 + 1e-5 * _LAST_ROW,
                                 axis=1))
    if bad.size:
        raise ZoopraxisError(f"render: seg2world[{bad[0]}] must have last row [0, 0, 0, 1]")
    dets = raycast.det3(seg2world[:, :3, :3])
    bad = np.flatnonzero(~(np.abs(dets) > 1e-12))
    if bad.size:
        raise ZoopraxisError(f"render: seg2world[{bad[0]}] is singular")
    if isinstance(want, str):
        want = (want,)
    want = tuple(want)
    unknown = [w for w in want if w not in ("point", "normal")]
    if unknown:
        raise ZoopraxisError(f"render: unknown output(s) {unknown} in want; "
                             "choose from 'point', 'normal'")
    return seg2world, want


def _prim_rects(camera, norm2world, prims, pinhole):
    """Projected bounding box of each primitive, in continuous pixel coordinates.

    Returns
    -------
    rects : array, shape (P, 4)
        ``(u_min, v_min, u_max, v_max)`` grown by the margin; ``-inf/+inf`` bounds for a
        primitive straddling the camera plane, NaN for one wholly behind the camera.
    """
    P = len(prims)
    corners = np.broadcast_to(raycast.CUBE, (P, 8, 3)).copy()
    cyl = prims.kind == CYLINDER
    reach = np.maximum(1.0, prims.taper[cyl])
    corners[cyl, :, :2] *= reach[:, None, None]
    corners[cyl, :, 2] = (corners[cyl, :, 2] + 1.0) / 2.0
    world = corners @ norm2world[:, :3, :3].transpose(0, 2, 1) + norm2world[:, None, :3, 3]
    world = world.reshape(-1, 3)
    uv = np.asarray(camera.project(world), dtype=float).reshape(P, 8, 2)
    rects = np.concatenate([uv.min(axis=1) - _MARGIN_PX, uv.max(axis=1) + _MARGIN_PX], axis=1)
    unreliable = ~np.all(np.isfinite(rects), axis=1)
    if pinhole:
        z = np.asarray(camera.cam_from_world(world), dtype=float)[:, 2].reshape(P, 8)
        behind = np.all(z <= _NEAR_Z, axis=1)
        unreliable |= np.any(z <= _NEAR_Z, axis=1)
    else:
        behind = np.zeros(P, bool)
    rects[unreliable] = (-np.inf, -np.inf, np.inf, np.inf)
    rects[behind] = np.nan
    return rects


def _window(bbox, W, H):
    if bbox is None:
        return 0, 0, W, H
    try:
        x0, y0, x1, y1 = (float(v) for v in bbox)
    except (TypeError, ValueError):
        raise ZoopraxisError(f"render: bbox must be (x0, y0, x1, y1), got {bbox!r}") from None
    if not all(np.isfinite((x0, y0, x1, y1))) or x1 <= x0 or y1 <= y0:
        raise ZoopraxisError(f"render: bbox (x0, y0, x1, y1) must be finite with x1 > x0 and "
                             f"y1 > y0, got {tuple(bbox)}")
    x0, y0 = max(int(np.floor(x0)), 0), max(int(np.floor(y0)), 0)
    x1, y1 = min(int(np.ceil(x1)), W), min(int(np.ceil(y1)), H)
    return x0, y0, max(x1, x0), max(y1, y0)


def _pixel_box(rect, window, W, H):
    """The pixels ``(r0, r1, c0, c1)`` whose centres lie in ``rect``, within the window."""
    u0, v0, u1, v1 = rect
    x0, y0, x1, y1 = window
    # Pixel i covers [i - 0.5, i + 0.5]; keep those whose centre lies in the rect.
    c0 = max(x0, math.ceil(max(u0, -1.0)))
    r0 = max(y0, math.ceil(max(v0, -1.0)))
    c1 = min(x1, math.floor(min(u1, W)) + 1)
    r1 = min(y1, math.floor(min(v1, H)) + 1)
    return r0, r1, c0, c1


def _cast_window(grid, rects, window, prims, world2norm, depth, prim, label, surface):
    """Cast each primitive's rays in its rectangle and keep the nearer hits, in place.

    Parameters
    ----------
    grid : _Rays, shape (H, W)
    rects : array, shape (P, 4)
        From :func:`_prim_rects`.
    window : (x0, y0, x1, y1)
        Pixel window to render, half-open.
    depth, prim, label, surface : arrays, shape (H, W)
        The z-buffer, updated in place.
    """
    H, W = depth.shape
    # Plain Python numbers: the per-primitive bookkeeping costs as much as a small limb's rays.
    kinds, tapers = prims.kind.tolist(), prims.taper.tolist()
    segments = prims.segment.astype(np.int16)
    capped = False          # whether a cap code is in ``surface`` yet (it starts all CURVED)
    for j, rect in enumerate(rects.tolist()):
        if rect[0] != rect[0]:      # NaN: behind the camera
            continue
        r0, r1, c0, c1 = _pixel_box(rect, window, W, H)
        if c1 <= c0 or r1 <= r0:
            continue
        pixels = (slice(r0, r1), slice(c0, c1))
        rays = grid.take(pixels)
        s, code = raycast.intersect(rays, world2norm[j], kinds[j], tapers[j])
        if not grid.pinhole:
            s += rays.depth0
        s = s.reshape(r1 - r0, c1 - c0)
        zbuf = depth[pixels]
        closer = s < zbuf
        np.copyto(zbuf, s, where=closer)
        np.copyto(prim[pixels], np.int16(j), where=closer)
        np.copyto(label[pixels], segments[j], where=closer)
        if code is not None:
            np.copyto(surface[pixels], code.reshape(s.shape), where=closer)
            capped = True
        elif capped:
            np.copyto(surface[pixels], raycast.CURVED, where=closer)


def _cast_points(rays, uv, rects, prims, world2norm, depth, prim, surface):
    """Cast rays through arbitrary pixels and keep the nearer hits, in place.

    Parameters
    ----------
    rays : _Rays, shape (N,)
    uv : array, shape (N, 2)
        The pixels of the rays, tested against each primitive's rectangle.
    rects : array, shape (P, 4)
        From :func:`_prim_rects`.
    depth, prim, surface : arrays, shape (N,)
        The z-buffer, updated in place.
    """
    for j in range(len(prims)):
        u0, v0, u1, v1 = rects[j]
        if np.isnan(u0):
            continue
        inside = np.flatnonzero((uv[:, 0] >= u0) & (uv[:, 0] <= u1)
                                & (uv[:, 1] >= v0) & (uv[:, 1] <= v1))
        if inside.size == 0:
            continue
        sub = rays.take(inside)
        s, code = raycast.intersect(sub, world2norm[j], prims.kind[j], prims.taper[j])
        if not rays.pinhole:
            s += sub.depth0
        closer = s < depth[inside]
        hit = inside[closer]
        depth[hit] = s[closer]
        prim[hit] = j
        surface[hit] = raycast.CURVED if code is None else code[closer]


def render(camera, seg2world, prims, *, bbox=None, want=("point", "normal")):
    """Render support map, depth, surface points and normals of a posed body in one view.

    Every pixel's ray is intersected with the primitives (a quadratic per primitive, Bregler &
    Malik §2.2) and the nearest hit wins (z-buffer), giving Yamamoto et al.'s region and depth
    images (§2.4, Fig. 4) and the 3D points behind them.

    Parameters
    ----------
    camera : camera
        Needs ``image_size`` (W, H), ``R`` (3, 3), ``t`` (3,), ``project``, ``cam_from_world``
        and ``pixel_rays()`` (see :mod:`zoopraxis.core.geometry.camera`).
    seg2world : array, shape (S, 4, 4)
        Segment-local -> world transform of each segment, ``S >= max(prims.segment) + 1``.
    prims : Primitives
    bbox : (x0, y0, x1, y1), optional
        Only render pixels with ``x0 <= x < x1`` and ``y0 <= y < y1`` (pixel indices; clipped
        to the image). Pixels outside are background.
    want : iterable of {"point", "normal"}
        Optional outputs; label and depth are always computed.

    Returns
    -------
    RenderResult
        Arrays of shape (H, W) (and (H, W, 3) for point and normal).

    Convention: ``seg2world`` maps segment-local to world coordinates; depth is the camera z
    ``(R @ X + t)[2]`` of the hit; points and normals are in world coordinates.
    """
    seg2world, want = _check_inputs(seg2world, prims, want)
    grid, (W, H) = _camera_grid(camera)
    x0, y0, x1, y1 = _window(bbox, W, H)

    depth = np.full((H, W), np.inf, dtype=np.float32)
    prim = np.full((H, W), -1, dtype=np.int16)
    label = np.full((H, W), -1, dtype=np.int16)
    surface = np.zeros((H, W), dtype=np.int8)
    world2norm = None
    if len(prims) and x1 > x0 and y1 > y0:
        norm2world, world2norm = raycast.world2norm(seg2world, prims)
        rects = _prim_rects(camera, norm2world, prims, grid.pinhole)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            _cast_window(grid, rects, (x0, y0, x1, y1), prims, world2norm, depth, prim,
                         label, surface)

    point = normal = None
    if want:
        point, normal = raycast.fill_geometry(grid, depth, prim, surface, prims, world2norm, want)
    return RenderResult(label, prim, depth, point, normal)


def surface_points(camera, depth, rows, cols):
    """World points of a render's visible surface at some pixels, from its depth image.

    Equal, bit for bit, to ``render(camera, ...).point[rows, cols]`` of the render that gave
    ``depth``, without filling the point image for every pixel (the silhouette terms want the
    points of the contour only).

    Parameters
    ----------
    camera : camera
        The camera the depth image was rendered with.
    depth : array of float32, shape (H, W)
        ``RenderResult.depth``.
    rows, cols : arrays of int, shape (N,)
        Pixels on the body (finite depth).

    Returns
    -------
    point : array of float32, shape (N, 3)
    """
    grid, (W, H) = _camera_grid(camera)
    if depth.shape != (H, W):
        raise ZoopraxisError(f"surface_points: depth has shape {depth.shape}, the camera's "
                             f"image is ({H}, {W})")
    flat = np.ravel_multi_index((np.asarray(rows), np.asarray(cols)), (H, W))
    sub = grid.take(flat)
    s = depth.reshape(-1)[flat]
    if not grid.pinhole:
        s = s - sub.depth0
    # The arithmetic of _surface_geometry, pixel by pixel.
    X = sub.d.astype(float)
    X *= s
    X += sub.origin[:, None] if sub.pinhole else sub.o
    return np.ascontiguousarray(X.T.astype(np.float32))


def render_points(camera, seg2world, prims, uv, *, want=("point", "normal")):
    """Render the body at arbitrary pixel positions (sparse sampling, particle likelihoods).

    Casts the camera's rays through ``uv`` (``camera.rays``); at pixel centres the result
    equals :func:`render` there.

    Parameters
    ----------
    camera, seg2world, prims, want
        As for :func:`render`; the camera also needs ``rays(uv) -> (origins, dirs)``.
    uv : array, shape (N, 2)
        Pixel positions (x right, y down, origin at the centre of the top-left pixel).

    Returns
    -------
    RenderResult
        Arrays of shape (N,) (and (N, 3) for point and normal).
    """
    seg2world, want = _check_inputs(seg2world, prims, want)
    uv = np.asarray(uv, dtype=float)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ZoopraxisError(f"render_points: uv must have shape (N, 2), got {uv.shape}")
    if not np.all(np.isfinite(uv)):
        raise ZoopraxisError("render_points: uv has non-finite entries")
    _check_camera(camera)
    if not hasattr(camera, "rays"):
        raise ZoopraxisError(f"render_points: camera has no 'rays' "
                             f"(got a {type(camera).__name__})")
    origins, dirs = camera.rays(uv)
    rays = _prepare_rays(np.asarray(origins, dtype=float), np.asarray(dirs, dtype=float),
                         np.asarray(camera.R, dtype=float), np.asarray(camera.t, dtype=float))
    N = uv.shape[0]

    depth = np.full(N, np.inf, dtype=np.float32)
    prim = np.full(N, -1, dtype=np.int16)
    surface = np.zeros(N, dtype=np.int8)
    world2norm = None
    if len(prims) and N:
        norm2world, world2norm = raycast.world2norm(seg2world, prims)
        rects = _prim_rects(camera, norm2world, prims, rays.pinhole)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            _cast_points(rays, uv, rects, prims, world2norm, depth, prim, surface)

    label = np.append(prims.segment, -1).astype(np.int16)[prim]
    point = normal = None
    if want:
        point, normal = raycast.fill_geometry(rays, depth, prim, surface, prims, world2norm, want)
    return RenderResult(label, prim, depth, point, normal)
