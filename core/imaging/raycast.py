"""Ray casting against the body's primitives: the intersection of camera rays with ellipsoids and
capped elliptic cone frustums ("the solution of a quadratic equation", Bregler & Malik §2.2),
in each primitive's normalised frame, in float32 over a window of rays, and the surface points
and outward normals of the hits. The renderer (render) decides which rays each primitive casts
and keeps the nearest hit.

Convention: rays and points in world coordinates (right-handed, Z up, metres); a primitive's
normalised frame is the unit sphere, or the unit cylinder along z from 0 to 1.
"""

import numpy as np

from ..body.primitives import CYLINDER, ELLIPSOID

# Which surface of a primitive a ray hit: the quadric itself, or a cylinder's flat cap.
CURVED, BASE_CAP, TOP_CAP = 0, 1, 2

_F32_INF = np.float32(np.inf)


def world2norm(seg2world, prims):
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


def det3(L):
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
    inv[..., :3, :3] = adj / det3(L)[..., None, None]
    inv[..., :3, 3] = -np.einsum("...ij,...j->...i", inv[..., :3, :3], T[..., :3, 3])
    inv[..., 3, 3] = 1.0
    return inv


def _read_only(*arrays):
    for a in arrays:
        a.flags.writeable = False
    return arrays


# The unit sphere's quadric, made once (it is asked for at every ellipsoid of every render).
_UNIT_SPHERE = _read_only(np.ones(3, np.float32), np.zeros(3, np.float32)) + (np.float32(-1),)

# Corners of the normalised bounding box of a primitive (cube [-1, 1]^3), for render._prim_rects.
CUBE = _read_only(np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
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
        ``CURVED``, ``BASE_CAP`` or ``TOP_CAP``.
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
    caps = ((BASE_CAP, zero, one), (TOP_CAP, one, f32(taper)))
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


def intersect(rays, world2norm, kind, taper):
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
            grad[:, code == BASE_CAP] = ((0.0,), (0.0,), (-1.0,))
            grad[:, code == TOP_CAP] = ((0.0,), (0.0,), (1.0,))
        # Normals transform with the inverse transpose of norm2world, which is M^T. From
        # inside a primitive the camera sees its inner side: flip to face the camera.
        M_T = -M.T if rays.pinhole and _contains(world2norm[j], prims.kind[j],
                                                prims.taper[j], rays.origin) else M.T
        np.matmul(M_T, grad, out=normal[:, a:b])
    normal /= np.sqrt(np.einsum("ij,ij->j", normal, normal))
    point = X.astype(np.float32) if "point" in want else None
    return point, normal.astype(np.float32)


def fill_geometry(rays, depth, prim, surface, prims, world2norm, want):
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
