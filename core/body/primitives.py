"""Shape primitives of the body model: ellipsoids and elliptic cone frustums with flat caps
(cylinders), each rigidly attached to one segment, and the functions that make them
(``ellipsoid``, ``cylinder``, ``capsule``). The renderer (imaging.render) casts rays against them;
body.shapes builds them from a body's dimensions.

Convention: each primitive lives in its segment's reference frame (metres); a primitive's
``norm2seg`` maps its normalised frame (the unit sphere, or the unit cylinder along z from 0 to 1)
into the segment.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import ZoopraxisError

ELLIPSOID = 0
CYLINDER = 1

_ORTHONORMAL_TOL = 1e-6
# Labels and primitive indices are stored as int16 images.
_MAX_LABEL = np.iinfo(np.int16).max


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
