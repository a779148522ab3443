"""Image terms of the differential tracker: residuals and normal equations per segment.

A *term* is a set of model points, each fixed on one segment, with a target value: the grey
level it had in the previous frame (image motion, Bregler & Malik eq. 3), in an anchor frame
(persistent appearance), or zero on a signed-distance image (silhouette contour). At a candidate
pose the points move with their segments (product of exponentials, eq. 21), project through the
view's camera, and sample the image; the residual is ``image(x') - target``.

Linearising in the pose increment ``delta = [root twist (6), angle changes]`` (eqs. 15, 24)

.. math:: r_i + \\nabla I(x_i)^T \\, \\frac{\\partial \\pi}{\\partial X}(X_i)\\,
          [I \\;|\\; -\\hat X_i] \\, J_{k(i)} \\, \\delta = 0,

with ``J_k`` the 6 x P spatial Jacobian of segment k (eq. 22). The first three factors give each
pixel a 6-vector ``g_i`` in twist space, so the normal equations are accumulated per segment,
``A_k = sum g g^T`` and ``b_k = sum g r`` (6 x 6 and 6), and only then mapped to the pose
parameters: ``H = sum_k J_k^T A_k J_k``. Time therefore grows with the number of pixels times 36,
not with pixels times degrees of freedom (the weighted form of eq. 26 and 29).

Convention: model points are stored in the body *reference* frame of their segment (see
:mod:`body`), so the world point at a pose is ``seg2world[segment] @ point``.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from . import se3


@dataclass
class Term:
    """Model points with targets, observed in one view.

    Attributes
    ----------
    view : int
        Index of the view (camera) the points are observed in.
    segment : array of int, shape (N,)
    ref_points : array, shape (N, 3)
        Points in the body reference frame of their segment.
    target : array, shape (N,)
        Value the image should have at the projected point.
    weight : array, shape (N,)
        Per-point weight (support map probability times any term weight).
    scale : float
        Robust scale of the residual (same unit as the image): residuals much larger than this
        are down-weighted (Geman-McClure).
    name : str
    uv : array, shape (N, 2), optional
        Pixels the points were taken from (template terms), for the EM background layer.
    hinge : float, optional
        Make the residual one-sided: only ``value - target > hinge`` counts (silhouettes: a
        model contour point outside the observed silhouette by more than a margin).
    """

    view: int
    segment: np.ndarray
    ref_points: np.ndarray
    target: np.ndarray
    weight: np.ndarray
    scale: float
    name: str = ""
    uv: np.ndarray = None
    hinge: float = None

    def __post_init__(self):
        # Keep points grouped by segment, so the per-segment sums use contiguous slices.
        seg = np.asarray(self.segment)
        if len(seg) and np.any(seg[1:] < seg[:-1]):
            order = np.argsort(seg, kind="stable")
            self.segment = seg[order]
            self.ref_points = self.ref_points[order]
            self.target = self.target[order]
            self.weight = self.weight[order]
            if self.uv is not None:
                self.uv = self.uv[order]
        segs, first = np.unique(self.segment, return_index=True)
        self.groups = list(zip(segs.tolist(), first.tolist(),
                               first[1:].tolist() + [len(self.segment)]))

    def __len__(self):
        return len(self.segment)

    @staticmethod
    def concat(terms, name=""):
        """One term from several observed in the same view with the same image and scale."""
        terms = [t for t in terms if t is not None and len(t)]
        if not terms:
            return None
        uv = None
        if all(t.uv is not None for t in terms):
            uv = np.concatenate([t.uv for t in terms])
        return Term(terms[0].view, np.concatenate([t.segment for t in terms]),
                    np.concatenate([t.ref_points for t in terms]),
                    np.concatenate([t.target for t in terms]),
                    np.concatenate([t.weight for t in terms]), terms[0].scale,
                    name or terms[0].name, uv, terms[0].hinge)

    def subset(self, keep):
        return Term(self.view, self.segment[keep], self.ref_points[keep], self.target[keep],
                    self.weight[keep], self.scale, self.name,
                    None if self.uv is None else self.uv[keep], self.hinge)


def image_with_gradients(image):
    """Stack an image with its x and y derivatives for one-call bilinear sampling.

    Parameters
    ----------
    image : array, shape (H, W) float32

    Returns
    -------
    stack : array, shape (H, W, 3) float32
        ``[I, dI/dx, dI/dy]`` with central differences (per pixel, x right, y down).
    """
    image = np.ascontiguousarray(image, dtype=np.float32)
    gx = cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3, scale=1 / 8, borderType=cv2.BORDER_REPLICATE)
    gy = cv2.Sobel(image, cv2.CV_32F, 0, 1, ksize=3, scale=1 / 8, borderType=cv2.BORDER_REPLICATE)
    return np.dstack([image, gx, gy])


def sample(stack, uv):
    """Bilinear samples of a (H, W, C) float32 image at pixels ``uv`` (N, 2).

    Exact bilinear interpolation in numpy (cv2.remap quantises positions to 1/32 pixel, which
    would cap the sub-pixel precision of the tracker).

    Returns
    -------
    values : array, shape (N, C) float32
    inside : array of bool, shape (N,)
        False where the point falls outside the image (values there are meaningless).
    """
    h, w, C = stack.shape
    u = uv[:, 0]
    v = uv[:, 1]
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)   # NaN compares False
    u = np.where(inside, u, 0.0)
    v = np.where(inside, v, 0.0)
    u0 = np.minimum(u.astype(np.int64), w - 2)
    v0 = np.minimum(v.astype(np.int64), h - 2)
    fu = (u - u0).astype(np.float32)[:, None]
    fv = (v - v0).astype(np.float32)[:, None]
    flat = stack.reshape(-1, C)
    i00 = v0 * w + u0
    top = flat[i00] * (1 - fu) + flat[i00 + 1] * fu
    bottom = flat[i00 + w] * (1 - fu) + flat[i00 + w + 1] * fu
    return top * (1 - fv) + bottom * fv, inside


def geman_mcclure_weights(r, scale):
    """IRLS weights of the Geman-McClure estimator ``rho(r) = r^2 / (r^2 + s^2)``."""
    s2 = scale * scale
    return (s2 / (r * r + s2)) ** 2


class _Pullback:
    """Maps image gradients (N, 2) to world gradients (N, 3) through the projection:
    ``grad^T d uv / d X``, without forming the (N, 2, 3) Jacobians where the camera model
    allows (the common distortion-free pinhole and scaled orthographic cases)."""

    def __init__(self, fn, depth):
        self.fn = fn
        self.depth = depth

    def __call__(self, grad):
        return self.fn(grad)


def _projection(camera, X):
    """Pixels of world points and the pull-back of image gradients to world gradients.

    Convention: world to OpenCV pixels through the camera's own model; for a pinhole without
    distortion ``d uv / d X = K_2x2 [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]] R``.
    """
    R = camera.R
    Xc = X @ R.T + camera.t
    if hasattr(camera, "K") and not getattr(camera, "has_distortion", True):
        K = camera.K
        z = Xc[:, 2]
        inv_z = 1.0 / np.where(np.abs(z) < 1e-12, 1e-12, z)
        x, y = Xc[:, 0] * inv_z, Xc[:, 1] * inv_z
        uv = np.column_stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]])

        def pull(grad):
            gu = grad[:, 0] * K[0, 0]
            gv = grad[:, 0] * K[0, 1] + grad[:, 1] * K[1, 1]
            gc = np.column_stack([gu * inv_z, gv * inv_z, -(gu * x + gv * y) * inv_z])
            return gc @ R

        return uv, _Pullback(pull, z)
    if not hasattr(camera, "K"):
        s = camera.s
        uv = s * Xc[:, :2] + camera.c

        def pull(grad):
            return (s * grad) @ R[:2]

        return uv, _Pullback(pull, Xc[:, 2])
    uv, Jp = camera.project_jacobian(X)
    return uv, _Pullback(lambda grad: np.einsum("ni,nij->nj", grad, Jp), Xc[:, 2])


@dataclass
class Accumulated:
    """Normal equations of one term, per segment.

    A : array, shape (S, 7, 7)
        ``sum w g g^T`` per segment; index 6 is the image-scale column used by scaled
        orthographic views (zero otherwise).
    b : array, shape (S, 7)
    cost : float
        Sum of robust costs.
    count : float
        Sum of weights of points inside the image.
    residual : array, shape (N,)
    inside : array of bool, shape (N,)
    """

    A: np.ndarray
    b: np.ndarray
    cost: float
    count: float
    residual: np.ndarray
    inside: np.ndarray


def accumulate(term, stack, camera, seg2world, n_segments, *, with_scale=False, robust=True,
               extra_weight=None):
    """Residuals and per-segment normal equations of one term at one pose.

    Parameters
    ----------
    term : Term
    stack : array, shape (H, W, 3) float32
        The observed image with its gradients (:func:`image_with_gradients`), at the pyramid
        level the camera describes.
    camera : PinholeCamera or ScaledOrthoCamera
    seg2world : array, shape (S, 4, 4)
        Segment transforms at the candidate pose.
    with_scale : bool
        Add the derivative with respect to the log of the orthographic scale (Bregler & Malik's
        ``s'``, eq. 14) as a seventh column.
    extra_weight : array, shape (N,), optional
        Multiplies the term's weights (EM ownership of the support maps).

    Returns
    -------
    Accumulated
    """
    X = se3.apply(seg2world[term.segment], term.ref_points)
    uv, pullback = _projection(camera, X)
    vals, inside = sample(stack, uv)
    if hasattr(camera, "K"):
        inside &= pullback.depth > 1e-3
    r = (vals[:, 0] - term.target).astype(np.float64)
    grad = vals[:, 1:3].astype(np.float64)
    if term.hinge is not None:
        # one-sided: only values above the target by more than the hinge margin count
        r = r - term.hinge
        active = r > 0
        r = np.where(active, r, 0.0)
        grad = grad * active[:, None]
    w = term.weight * inside
    if extra_weight is not None:
        w = w * extra_weight
    if robust:
        w = w * geman_mcclure_weights(r, term.scale)
    # g = grad^T dpi/dX [I | -X^]: the row of the linear system in twist coordinates
    gp = pullback(grad)                                        # (N, 3) = dI/dX
    g = np.empty((len(r), 7))
    g[:, :3] = gp
    g[:, 3:6] = np.cross(X, gp)                                # -X^ applied, transposed
    g[:, 6] = (grad * (uv - camera.c)).sum(axis=1) if with_scale else 0.0
    S = n_segments
    A = np.zeros((S, 7, 7))
    b = np.zeros((S, 7))
    gw = g * w[:, None]
    for k, lo, hi in term.groups:
        A[k] = gw[lo:hi].T @ g[lo:hi]
        b[k] = gw[lo:hi].T @ r[lo:hi]
    s2 = term.scale ** 2
    cost = float(np.sum(term.weight * inside * (r * r / (r * r + s2) if robust else r * r)))
    return Accumulated(A, b, cost, float(w.sum()), r, inside)


def assemble(acc, seg_jac, *, root_cols, angle_cols, n_params, scale_col=None):
    """Map per-segment normal equations to the parameters of the whole problem.

    Parameters
    ----------
    acc : Accumulated
    seg_jac : array, shape (S, 6, 6 + n_dofs)
        Spatial segment Jacobians of the view's pose (:meth:`BodyModel.segment_jacobians`).
    root_cols : array of int, shape (6,)
        Where this view's root twist sits in the global parameter vector.
    angle_cols : array of int, shape (n_dofs,)
        Where the (shared) angles sit.
    scale_col : int, optional
        Where this view's log-scale parameter sits (scaled orthographic views).

    Returns
    -------
    H : array, shape (n_params, n_params)
    g : array, shape (n_params,)
    """
    S, _, P = seg_jac.shape
    # Extend each segment Jacobian with the scale row/column: 7 x (P + 1).
    Jx = np.zeros((S, 7, P + 1))
    Jx[:, :6, :P] = seg_jac
    Jx[:, 6, P] = 1.0
    Hl = np.tensordot(Jx, np.matmul(acc.A, Jx), axes=([0, 1], [0, 1]))
    gl = np.tensordot(Jx, acc.b, axes=([0, 1], [0, 1]))
    cols = np.concatenate([root_cols, angle_cols])
    H = np.zeros((n_params, n_params))
    g = np.zeros(n_params)
    H[np.ix_(cols, cols)] = Hl[:P, :P]
    g[cols] = gl[:P]
    if scale_col is not None:
        H[scale_col, cols] = Hl[P, :P]
        H[cols, scale_col] = Hl[:P, P]
        H[scale_col, scale_col] = Hl[P, P]
        g[scale_col] = gl[P]
    return H, g
