"""Model renderer: support map, depth, surface points and normals by ray casting quadrics.

The body is a set of primitives (ellipsoids and elliptic cone frustums with flat caps), each
rigidly attached to one segment. For every pixel the renderer intersects the camera ray with
the primitives and keeps the nearest hit in a z-buffer, so self-occlusion falls out. It gives:

- the support map (Bregler & Malik §2.4: "the projection of the ellipsoids into the image"),
  which is also Yamamoto et al.'s *region image* (§2.4, Fig. 4): the segment label per pixel;
- the *depth image* (Yamamoto et al. §2.4-2.5, Fig. 4): camera z of the visible surface;
- the 3D surface point ``q_c`` per pixel, "the solution of a quadratic equation" (Bregler &
  Malik §2.2, after eq. 14; step 1 of the recipe in §2.5);
- the outward surface normal, for Sidenbladh et al.'s weighting by surface orientation
  (§3.2, §5).

Each primitive only casts the rays inside the projection of its bounding box, vectorized over
that pixel rectangle in float32; points and normals are computed afterwards for the visible
pixels only.

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

ELLIPSOID = 0
CYLINDER = 1

# Which surface of a primitive a ray hit: the quadric itself, or a cylinder's flat cap.
_CURVED, _BASE_CAP, _TOP_CAP = 0, 1, 2

# Bounding rectangles grow by this many pixels so the rounding of projected corners (and mild
# lens distortion between projected corners and undistorted rays) cannot clip a silhouette.
_MARGIN_PX = 2.0

# Corners closer to the camera plane than this (metres) make the projected box unreliable: the
# primitive straddles the camera plane and is then cast against the whole window.
_NEAR_Z = 1e-6

_ORTHONORMAL_TOL = 1e-6
# Labels and primitive indices are stored as int16 images.
_MAX_LABEL = np.iinfo(np.int16).max
_F32_INF = np.float32(np.inf)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


# ---------------------------------------------------------------------------------------------
# Primitives
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Primitives:
    """P primitives, each rigidly attached to one body segment.

    Parameters
    ----------
    segment : array of int, shape (P,)
        Segment label of each primitive, written into the support map (``>= 0``).
    kind : array of int, shape (P,)
        ``ELLIPSOID`` (0) or ``CYLINDER`` (1).
    prim2seg : array, shape (P, 4, 4)
        Rigid transform from primitive-local to segment-local coordinates.
    size : array, shape (P, 3)
        Ellipsoid: semi-axes ``(a, b, c)`` along local x, y, z. Cylinder: ``(rx, ry, length)``,
        the elliptic cross-section radii at the base (local z = 0) and the length of the axis,
        which runs along local +z up to z = length.
    taper : array, shape (P,)
        Cylinder only: the top radii are ``taper * (rx, ry)`` (1 = straight, otherwise a cone
        frustum). Both ends are closed by flat caps. Ignored for ellipsoids.

    Notes
    -----
    Arrays are copied, validated and made read-only on construction. Spheres are ellipsoids
    with equal semi-axes; a capsule is a cylinder plus two spheres with the same label (see
    :func:`capsule`).
    """

    segment: np.ndarray
    kind: np.ndarray
    prim2seg: np.ndarray
    size: np.ndarray
    taper: np.ndarray

    def __post_init__(self):
        segment = _as_int_array(self.segment, "segment")
        if segment.ndim != 1:
            raise ZoopraxisError(f"Primitives: segment must have shape (P,), got {segment.shape}")
        P = segment.shape[0]
        kind = _as_int_array(self.kind, "kind")
        prim2seg = np.array(self.prim2seg, dtype=float)
        size = np.array(self.size, dtype=float)
        taper = np.array(self.taper, dtype=float)
        for name, arr, shape in (("kind", kind, (P,)), ("prim2seg", prim2seg, (P, 4, 4)),
                                 ("size", size, (P, 3)), ("taper", taper, (P,))):
            if arr.shape != shape:
                raise ZoopraxisError(f"Primitives: {name} must have shape {shape} for "
                                     f"{P} primitives, got {arr.shape}")
        bad = np.flatnonzero((segment < 0) | (segment > _MAX_LABEL))
        if bad.size:
            raise ZoopraxisError(f"Primitives: segment[{bad[0]}] is {segment[bad[0]]}; "
                                 f"segment labels must be in 0..{_MAX_LABEL}")
        if P > _MAX_LABEL + 1:
            raise ZoopraxisError(f"Primitives: {P} primitives, at most {_MAX_LABEL + 1} allowed")
        bad = np.flatnonzero((kind != ELLIPSOID) & (kind != CYLINDER))
        if bad.size:
            raise ZoopraxisError(f"Primitives: kind[{bad[0]}] is {kind[bad[0]]}; expected "
                                 f"ELLIPSOID ({ELLIPSOID}) or CYLINDER ({CYLINDER})")
        for p in range(P):
            problem = _rigid_problem(prim2seg[p])
            if problem:
                raise ZoopraxisError(f"Primitives: prim2seg[{p}] is not a rigid transform "
                                     f"({problem})")
        bad = np.flatnonzero(~np.all(np.isfinite(size) & (size > 0), axis=1))
        if bad.size:
            raise ZoopraxisError(f"Primitives: size[{bad[0]}] = {size[bad[0]].tolist()}; "
                                 "sizes must be positive and finite")
        bad = np.flatnonzero(~np.isfinite(taper)
                             | ((kind == CYLINDER) & ~(taper > 0)))
        if bad.size:
            raise ZoopraxisError(f"Primitives: taper[{bad[0]}] = {taper[bad[0]]}; a cylinder's "
                                 "taper must be positive and finite")
        for name, arr in (("segment", segment), ("kind", kind), ("prim2seg", prim2seg),
                          ("size", size), ("taper", taper)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __len__(self):
        return self.segment.shape[0]

    @property
    def n_segments(self):
        """Smallest number of segments a ``seg2world`` needs: ``max(segment) + 1`` (0 if empty)."""
        return int(self.segment.max()) + 1 if len(self) else 0

    @staticmethod
    def concat(parts):
        """Join several :class:`Primitives` into one, in order.

        Parameters
        ----------
        parts : sequence of Primitives

        Returns
        -------
        Primitives
        """
        parts = list(parts)
        for i, part in enumerate(parts):
            if not isinstance(part, Primitives):
                raise ZoopraxisError(f"Primitives.concat: item {i} is a "
                                     f"{type(part).__name__}, not Primitives")
        if not parts:
            return Primitives(np.zeros(0, int), np.zeros(0, int), np.zeros((0, 4, 4)),
                              np.zeros((0, 3)), np.zeros(0))
        return Primitives(*(np.concatenate([getattr(p, name) for p in parts])
                            for name in ("segment", "kind", "prim2seg", "size", "taper")))


def _as_int_array(values, name):
    arr = np.asarray(values)
    if arr.size == 0 or (np.issubdtype(arr.dtype, np.integer) and arr.dtype != bool):
        return arr.astype(np.int64)
    if np.issubdtype(arr.dtype, np.floating) and np.all(np.isfinite(arr)) \
            and np.all(arr == np.round(arr)):
        return arr.astype(np.int64)
    raise ZoopraxisError(f"Primitives: {name} must hold integers, got {arr.dtype} values")


def _rigid_problem(T):
    """Why the 4x4 matrix ``T`` is not a proper rigid transform, or '' if it is one."""
    if not np.all(np.isfinite(T)):
        return "non-finite entries"
    if not np.allclose(T[3], (0.0, 0.0, 0.0, 1.0), atol=_ORTHONORMAL_TOL):
        return "last row must be [0, 0, 0, 1]"
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=_ORTHONORMAL_TOL):
        return "rotation part is not orthonormal"
    if np.linalg.det(R) < 0:
        return "rotation part is a reflection"
    return ""


def _vec3(value, name):
    v = np.asarray(value, dtype=float)
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise ZoopraxisError(f"{name} must be 3 finite numbers, got {np.shape(value)}")
    return v


def _positive(value, name):
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ZoopraxisError(f"{name} must be a number, got {value!r}") from None
    if not (np.isfinite(x) and x > 0):
        raise ZoopraxisError(f"{name} must be positive and finite, got {x}")
    return x


def _segment_label(segment):
    if isinstance(segment, (bool, np.bool_)) or not isinstance(segment, (int, np.integer)):
        raise ZoopraxisError(f"segment must be an integer label, got {segment!r}")
    if segment < 0:
        raise ZoopraxisError(f"segment must be >= 0, got {segment}")
    return int(segment)


def ellipsoid(segment, center, semi_axes, axes=np.eye(3)):
    """One ellipsoid attached to a segment.

    Parameters
    ----------
    segment : int
        Segment label.
    center : array, shape (3,)
        Centre in segment-local coordinates.
    semi_axes : array, shape (3,) or float
        Semi-axes along the ellipsoid's own x, y, z; a single number gives a sphere.
    axes : array, shape (3, 3)
        Rotation whose columns are the ellipsoid's x, y, z axes in segment coordinates.

    Returns
    -------
    Primitives
        One primitive.
    """
    segment = _segment_label(segment)
    center = _vec3(center, "ellipsoid center")
    semi = np.broadcast_to(np.asarray(semi_axes, dtype=float), (3,)) \
        if np.ndim(semi_axes) == 0 else np.asarray(semi_axes, dtype=float)
    if semi.shape != (3,) or not np.all(np.isfinite(semi) & (semi > 0)):
        raise ZoopraxisError(f"ellipsoid semi_axes must be 1 or 3 positive numbers, "
                             f"got {np.asarray(semi_axes).tolist()}")
    axes = np.asarray(axes, dtype=float)
    if axes.shape != (3, 3):
        raise ZoopraxisError(f"ellipsoid axes must be a 3x3 rotation, got shape {axes.shape}")
    prim2seg = np.eye(4)
    prim2seg[:3, :3] = axes
    prim2seg[:3, 3] = center
    problem = _rigid_problem(prim2seg)
    if problem:
        raise ZoopraxisError(f"ellipsoid axes must be a rotation ({problem})")
    return Primitives([segment], [ELLIPSOID], prim2seg[None], semi[None], [1.0])


def cylinder(segment, base, top, r_base, r_top=None, *, ry_ratio=1.0, x_dir=None):
    """One cylinder (or cone frustum, if ``r_top`` differs) attached to a segment.

    Parameters
    ----------
    segment : int
        Segment label.
    base, top : array, shape (3,)
        Centres of the base and top caps in segment-local coordinates; the axis runs from
        ``base`` to ``top``.
    r_base : float
        Cross-section radius along the local x axis at the base.
    r_top : float, optional
        Same radius at the top; defaults to ``r_base`` (a straight cylinder).
    ry_ratio : float
        Radius along local y over the radius along local x (elliptic cross-section).
    x_dir : array, shape (3,), optional
        Direction of the cross-section's local x axis in segment coordinates; only its part
        orthogonal to the axis counts. By default the segment axis least aligned with the
        cylinder axis, made orthogonal to it.

    Returns
    -------
    Primitives
        One primitive.
    """
    segment = _segment_label(segment)
    base = _vec3(base, "cylinder base")
    top = _vec3(top, "cylinder top")
    r_base = _positive(r_base, "cylinder r_base")
    r_top = r_base if r_top is None else _positive(r_top, "cylinder r_top")
    ry_ratio = _positive(ry_ratio, "cylinder ry_ratio")
    axis = top - base
    length = float(np.linalg.norm(axis))
    if not length > 0:
        raise ZoopraxisError("cylinder base and top are the same point")
    z = axis / length
    if x_dir is None:
        x = np.eye(3)[np.argmin(np.abs(z))]
    else:
        x = _vec3(x_dir, "cylinder x_dir")
        if not np.linalg.norm(x) > 0:
            raise ZoopraxisError("cylinder x_dir must not be zero")
        x = x / np.linalg.norm(x)
    x = x - (x @ z) * z
    if not np.linalg.norm(x) > 1e-9:
        raise ZoopraxisError("cylinder x_dir is parallel to the axis from base to top")
    x = x / np.linalg.norm(x)
    prim2seg = np.eye(4)
    prim2seg[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    prim2seg[:3, 3] = base
    size = [[r_base, r_base * ry_ratio, length]]
    return Primitives([segment], [CYLINDER], prim2seg[None], size, [r_top / r_base])


def capsule(segment, a, b, radius):
    """A capsule: a straight cylinder from ``a`` to ``b`` closed by two spheres.

    Parameters
    ----------
    segment : int
        Segment label of all three primitives.
    a, b : array, shape (3,)
        End points of the axis in segment-local coordinates (the sphere centres).
    radius : float

    Returns
    -------
    Primitives
        Three primitives: cylinder, sphere at ``a``, sphere at ``b``.
    """
    return Primitives.concat([cylinder(segment, a, b, radius),
                              ellipsoid(segment, a, radius), ellipsoid(segment, b, radius)])


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
# Ray-primitive intersection
# ---------------------------------------------------------------------------------------------

def _world2norm(seg2world, prims):
    """Affine maps between the world and each primitive's normalised frame.

    In the normalised frame an ellipsoid is the unit sphere and a cylinder is the cone
    frustum ``x^2 + y^2 <= (1 + (taper - 1) z)^2``, ``0 <= z <= 1``.

    Returns
    -------
    norm2world : array, shape (P, 4, 4)
    world2norm : array, shape (P, 4, 4)
    """
    scale = np.zeros((len(prims), 4, 4))
    scale[:, [0, 1, 2], [0, 1, 2]] = prims.size
    scale[:, 3, 3] = 1.0
    norm2world = seg2world[prims.segment] @ prims.prim2seg @ scale
    return norm2world, _inv_affine(norm2world)


def _cross(a, b):
    """Cross products of 3-vectors, shape (..., 3): the products and differences np.cross
    computes, in the same order (the same values), without its overhead."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def _det3(L):
    """Determinants of 3x3 matrices, shape (..., 3, 3) -> (...)."""
    return np.einsum("...i,...i->...", L[..., 0], _cross(L[..., 1], L[..., 2]))


def _inv_affine(T):
    """Inverses of affine 4x4 transforms, shape (..., 4, 4), by the adjugate.

    LAPACK's batched inverse costs a millisecond for a dozen 4x4 matrices on a busy machine,
    more than casting the rays of a small limb.
    """
    L = T[..., :3, :3]
    cols = L[..., 0], L[..., 1], L[..., 2]
    adj = np.stack([_cross(cols[1], cols[2]), _cross(cols[2], cols[0]),
                    _cross(cols[0], cols[1])], axis=-2)
    inv = np.zeros_like(T)
    inv[..., :3, :3] = adj / _det3(L)[..., None, None]
    inv[..., :3, 3] = -np.einsum("...ij,...j->...i", inv[..., :3, :3], T[..., :3, 3])
    inv[..., 3, 3] = 1.0
    return inv


def _read_only(*arrays):
    for a in arrays:
        a.flags.writeable = False
    return arrays


# The unit sphere's quadric, made once (it is asked for at every ellipsoid of every render).
_UNIT_SPHERE = _read_only(np.ones(3, np.float32), np.zeros(3, np.float32)) + (np.float32(-1),)

# Corners of the normalised bounding box of a primitive (cube [-1, 1]^3), for _prim_rects.
_CUBE = _read_only(np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                            float))[0]


def _quadric(kind, taper):
    """The surface ``x^T diag(D) x + 2 f.x + g = 0`` of a primitive in its normalised frame.

    Returns
    -------
    D : array of float32, shape (3,)
    f : array of float32, shape (3,)
    g : float32
    """
    if kind == ELLIPSOID:
        return _UNIT_SPHERE
    # x^2 + y^2 - (1 + k z)^2 = x^2 + y^2 - k^2 z^2 - 2 k z - 1
    k = taper - 1.0
    return (np.array([1.0, 1.0, -k * k], np.float32), np.array([0.0, 0.0, -k], np.float32),
            np.float32(-1))


def _ray_quadratic(rays, world2norm, kind, taper):
    """Coefficients of ``A s^2 + 2 b s + C = 0`` for the rays against one primitive.

    Substituting the ray ``x = p + s e`` (normalised frame) into the quadric gives
    ``A = e^T D e``, ``b = e.(D p + f)``, ``C = p.(D p + f) + f.p + g``.

    Returns
    -------
    p : array of float32, shape (3,) (pinhole) or (3, n)
        Ray origins in the normalised frame.
    e : array of float32, shape (3, n)
        Ray directions in the normalised frame.
    A, b : arrays of float32, shape (n,)
    C : float32 or array of float32, shape (n,)
    shift : array of float32, shape (n,), or None
        Parallel rays only: how far along the ray ``p`` is from the given origin; the roots
        ``s`` count from ``p``.
    """
    M = world2norm[:3, :3]
    m = M.astype(np.float32)
    D, f, g = _quadric(kind, taper)
    e = m @ rays.d
    A = np.einsum("ij,ij->j", e * D[:, None], e) if kind == CYLINDER \
        else np.einsum("ij,ij->j", e, e)
    if rays.pinhole:
        # One origin: its terms are scalars, worth computing in float64.
        p = M @ rays.origin + world2norm[:3, 3]
        h = D.astype(float) * p + f
        C = np.float32(p @ h + f @ p + g)
        p, h = p.astype(np.float32), h.astype(np.float32)
        return p, e, A, h @ e, C, None
    p = m @ rays.o
    p += world2norm[:3, 3].astype(np.float32)[:, None]
    # The whole line of sight of a parallel ray counts, and its origin may be far from the
    # primitive, where b^2 - A C cancels: restart each ray at its closest approach to the
    # primitive's centre.
    shift = np.einsum("ij,ij->j", p, e)
    shift /= np.einsum("ij,ij->j", e, e)
    np.negative(shift, out=shift)
    p += shift * e
    h = p * D[:, None]
    h += f[:, None]
    b = np.einsum("ij,ij->j", h, e)
    C = np.einsum("ij,ij->j", p, h)
    C += f @ p
    C += g
    return p, e, A, b, C, shift


def _roots(A, b, C, disc):
    """Both roots of ``A s^2 + 2 b s + C = 0`` in the numerically stable form (NaN or inf
    where undefined); ``disc = b^2 - A C``."""
    sq = np.sqrt(np.maximum(disc, 0))
    q = -(b + np.copysign(sq, b))
    return q / A, C / q


def _hit_ellipsoid(rays, world2norm):
    """Ray parameter of the first hit on an ellipsoid (inf: miss), shape (n,).

    In the normalised frame the ellipsoid is the unit sphere ``|p + s e|^2 = 1``. The near
    root is taken as ``C / q`` with ``q = -b + sqrt(b^2 - A C)``, which does not cancel when the
    camera is far away (Bregler & Malik §2.2: ``q_c`` "is the solution of a quadratic
    equation").
    """
    p, e, A, b, C, shift = _ray_quadratic(rays, world2norm, ELLIPSOID, 1.0)
    disc = b * b
    disc -= A * C
    if np.ndim(C) == 0 and C > 0:
        # From outside, the ellipsoid is ahead iff the ray heads towards it (b < 0), and then
        # both roots are positive.
        miss = disc < 0
        miss |= b >= 0
        np.maximum(disc, 0, out=disc)
        q = np.sqrt(disc, out=disc)
        q -= b
        s = np.divide(C, q, out=q)
        s[miss] = _F32_INF
        return s
    r1, r2 = _roots(A, b, C, disc)
    s = np.minimum(r1, r2)
    if rays.pinhole:
        # From inside the ellipsoid the near root is behind the camera.
        s = np.where(s > 0, s, np.maximum(r1, r2))
        s[~(s > 0)] = _F32_INF
    else:
        s += shift
    s[~(disc >= 0)] = _F32_INF
    return s


def _hit_cylinder(rays, world2norm, taper):
    """First hit on a capped cone frustum: ray parameter and surface code, shapes (n,).

    In the normalised frame the side is ``x^2 + y^2 = (1 + k z)^2`` with ``k = taper - 1`` and
    ``0 <= z <= 1`` (Sidenbladh et al. §3.1 use straight cylinders, ``k = 0``); the caps are the
    discs ``z = 0, x^2 + y^2 <= 1`` and ``z = 1, x^2 + y^2 <= taper^2``. The nearest valid
    candidate among both side roots and the caps is kept.

    Returns
    -------
    s : array of float32
        Ray parameter, inf on a miss.
    surface : array of int8
        ``_CURVED``, ``_BASE_CAP`` or ``_TOP_CAP``.
    """
    p, e, A, b, C, shift = _ray_quadratic(rays, world2norm, CYLINDER, taper)
    f32 = np.float32
    zero, one = f32(0), f32(1)
    px, py, pz = p
    ex, ey, ez = e
    disc = b * b
    disc -= A * C
    s = np.full(A.shape, _F32_INF, dtype=f32)
    real = disc >= 0
    for r in _roots(A, b, C, disc):
        z = r * ez
        z += pz
        ok = z >= zero
        ok &= z <= one
        ok &= real
        ok &= r < s
        if rays.pinhole:
            ok &= r > zero
        np.copyto(s, r, where=ok)
    surface = np.zeros(A.shape, dtype=np.int8)
    caps = ((_BASE_CAP, zero, one), (_TOP_CAP, one, f32(taper)))
    if np.ndim(C) == 0 and (C > 0 or not 0 <= pz <= 1):
        # A camera outside the solid enters it through the side or through the one cap
        # that faces it; from between the cap planes a cap can only be an exit.
        caps = caps[:1] if pz < 0 else caps[1:] if pz > 1 else ()
    for code, z_cap, r_cap in caps:
        r = (z_cap - pz) / ez
        x = r * ex
        x += px
        y = r * ey
        y += py
        x *= x
        y *= y
        x += y
        ok = x <= r_cap * r_cap
        ok &= r < s
        if rays.pinhole:
            ok &= r > zero
        np.copyto(s, r, where=ok)
        surface[ok] = code
    if shift is not None:
        s += shift
    return s, surface


def _contains(world2norm, kind, taper, X):
    """Whether the world point ``X`` (3,) lies inside the primitive."""
    x, y, z = world2norm[:3, :3] @ X + world2norm[:3, 3]
    if kind == ELLIPSOID:
        return x * x + y * y + z * z < 1.0
    return 0.0 <= z <= 1.0 and x * x + y * y < (1.0 + (taper - 1.0) * z) ** 2


def _intersect(rays, world2norm, kind, taper):
    """Ray parameter of the first hit (inf: miss) and the surface code (None: all curved).

    Misses divide by zero and take square roots of negatives on purpose: call under
    ``np.errstate(divide="ignore", invalid="ignore", over="ignore")``.
    """
    if kind == ELLIPSOID:
        return _hit_ellipsoid(rays, world2norm), None
    return _hit_cylinder(rays, world2norm, taper)


def _surface_geometry(rays, s, prim, surface, prims, world2norm, want):
    """World points and outward normals of hits sorted by primitive.

    Parameters
    ----------
    rays : _Rays, shape (N,)
    s : array, shape (N,)
        Ray parameters of the hits.
    prim : array of int, shape (N,)
        Primitive index of each hit, sorted ascending.
    surface : array of int8, shape (N,)
        Surface code of each hit.

    Returns
    -------
    point, normal : arrays of float32, shape (3, N), or None when not wanted
    """
    X = rays.d.astype(float)
    X *= s
    X += rays.origin[:, None] if rays.pinhole else rays.o
    if "normal" not in want:
        return X.astype(np.float32), None
    normal = np.empty_like(X)
    bounds = np.searchsorted(prim, np.arange(len(prims) + 1))
    for j in range(len(prims)):
        a, b = bounds[j], bounds[j + 1]
        if a == b:
            continue
        M = world2norm[j, :3, :3]
        # Gradient of the normalised quadric, ``D x + f``, at the normalised point x.
        grad = M @ X[:, a:b]
        grad += world2norm[j, :3, 3, None]
        if prims.kind[j] == CYLINDER:
            k = prims.taper[j] - 1.0
            grad[2] *= -k * k
            grad[2] -= k
            code = surface[a:b]
            grad[:, code == _BASE_CAP] = ((0.0,), (0.0,), (-1.0,))
            grad[:, code == _TOP_CAP] = ((0.0,), (0.0,), (1.0,))
        # Normals transform with the inverse transpose of norm2world, which is M^T. From
        # inside a primitive the camera sees its inner side: flip to face the camera.
        M_T = -M.T if rays.pinhole and _contains(world2norm[j], prims.kind[j],
                                                prims.taper[j], rays.origin) else M.T
        np.matmul(M_T, grad, out=normal[:, a:b])
    normal /= np.sqrt(np.einsum("ij,ij->j", normal, normal))
    point = X.astype(np.float32) if "point" in want else None
    return point, normal.astype(np.float32)


def _fill_geometry(rays, depth, prim, surface, prims, world2norm, want):
    """Point and normal images (or lists) from the z-buffer.

    Parameters
    ----------
    rays : _Rays, shape S
    depth, prim, surface : arrays, shape S
        The z-buffer: depth, primitive index (-1: background) and surface code.

    Returns
    -------
    point, normal : arrays of float32, shape S + (3,) (NaN on background), or None
    """
    shape = prim.shape
    prim = prim.reshape(-1)
    flat = np.flatnonzero(prim >= 0)
    # Sorted by primitive, each primitive works on a contiguous block.
    flat = flat[np.argsort(prim[flat], kind="stable")]
    sub = rays.take(flat)
    s = depth.reshape(-1)[flat]
    if not rays.pinhole:
        s = s - sub.depth0
    values = _surface_geometry(sub, s, prim[flat], surface.reshape(-1)[flat], prims,
                               world2norm, want)
    out = []
    for v in values:
        if v is None:
            out.append(None)
            continue
        image = np.full((prim.size, 3), np.nan, dtype=np.float32)
        # One 12-byte item per pixel scatters much faster than rows of three floats.
        rows = np.ascontiguousarray(v.T).view(np.void(12)).reshape(-1)
        image.view(np.void(12)).reshape(-1)[flat] = rows
        out.append(image.reshape(shape + (3,)))
    return out


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
    dets = _det3(seg2world[:, :3, :3])
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
    corners = np.broadcast_to(_CUBE, (P, 8, 3)).copy()
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
    capped = False          # whether a cap code is in ``surface`` yet (it starts all _CURVED)
    for j, rect in enumerate(rects.tolist()):
        if rect[0] != rect[0]:      # NaN: behind the camera
            continue
        r0, r1, c0, c1 = _pixel_box(rect, window, W, H)
        if c1 <= c0 or r1 <= r0:
            continue
        pixels = (slice(r0, r1), slice(c0, c1))
        rays = grid.take(pixels)
        s, code = _intersect(rays, world2norm[j], kinds[j], tapers[j])
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
            np.copyto(surface[pixels], _CURVED, where=closer)


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
        s, code = _intersect(sub, world2norm[j], prims.kind[j], prims.taper[j])
        if not rays.pinhole:
            s += sub.depth0
        closer = s < depth[inside]
        hit = inside[closer]
        depth[hit] = s[closer]
        prim[hit] = j
        surface[hit] = _CURVED if code is None else code[closer]


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
        norm2world, world2norm = _world2norm(seg2world, prims)
        rects = _prim_rects(camera, norm2world, prims, grid.pinhole)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            _cast_window(grid, rects, (x0, y0, x1, y1), prims, world2norm, depth, prim,
                         label, surface)

    point = normal = None
    if want:
        point, normal = _fill_geometry(grid, depth, prim, surface, prims, world2norm, want)
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
        norm2world, world2norm = _world2norm(seg2world, prims)
        rects = _prim_rects(camera, norm2world, prims, rays.pinhole)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            _cast_points(rays, uv, rects, prims, world2norm, depth, prim, surface)

    label = np.append(prims.segment, -1).astype(np.int16)[prim]
    point = normal = None
    if want:
        point, normal = _fill_geometry(rays, depth, prim, surface, prims, world2norm, want)
    return RenderResult(label, prim, depth, point, normal)
