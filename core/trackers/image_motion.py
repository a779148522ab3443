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

import threading
from dataclasses import dataclass

import cv2
import numpy as np


def _segment_runs(seg):
    """``(segment, first, end)`` of each run of equal values in a sorted segment array: what
    ``np.unique(seg, return_index=True)`` gives for sorted input, without sorting again."""
    n = len(seg)
    if n == 0:
        return []
    first = np.flatnonzero(seg[1:] != seg[:-1])
    first += 1
    starts = [0] + first.tolist()
    return list(zip(seg[starts].tolist(), starts, starts[1:] + [n]))


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
        self.groups = _segment_runs(np.asarray(self.segment))

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
    return cv2.merge([image, gx, gy])        # np.dstack, the same array, faster


def sample(stack, uv):
    """Bilinear samples of a (H, W, C) float32 image at pixels ``uv`` (N, 2).

    Exact bilinear interpolation in numpy, for tests and finite differences (see
    :func:`sample_fast` for the tracker's inner loop).

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


_REMAP_ROW = 1024       # cv2.remap maps are images: at most 32767 wide, so fold long lists


def sample_fast(stack, uv):
    """:func:`sample` through ``cv2.remap``: four times faster, positions rounded to 1/32 px.

    The rounding (about 0.2 mm on a body 4 m from a 500 px camera) is far below what the
    tracker resolves, and the Gauss-Newton rows use the sampled gradients, not differences of
    samples; keep :func:`sample` for finite-difference checks.
    """
    h, w, C = stack.shape
    n = len(uv)
    u = uv[:, 0]
    v = uv[:, 1]
    inside = (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)   # NaN compares False
    rows = -(-n // _REMAP_ROW) if n > _REMAP_ROW else 1
    width = _REMAP_ROW if n > _REMAP_ROW else max(n, 1)
    m = np.zeros((rows * width, 2), np.float32)
    m[:n] = uv
    m[:n][~inside] = 0.0
    out = cv2.remap(stack, m.reshape(rows, width, 2), None, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(-1, C)[:n], inside


def shown_in_render(segment, uv, label, level):
    """Which points the render shows: those whose pixel ``uv`` (at pyramid ``level``, the
    render ``label`` at level 0) is labelled with their own ``segment`` (inside the image, in
    front of every other segment)."""
    scale = 2 ** level
    u = np.rint(uv[:, 0] * scale).astype(int)
    v = np.rint(uv[:, 1] * scale).astype(int)
    h, w = label.shape
    ok = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    lab = np.full(len(u), -1)
    lab[ok] = label[v[ok], u[ok]]
    return ok & (lab == segment)


def geman_mcclure(r2, s2, rho_out=None, weight_out=None):
    """The Geman-McClure estimator ``rho = r^2 / (r^2 + s^2)`` and its IRLS weights
    ``(s^2 / (r^2 + s^2))^2`` from squared residuals ``r2`` and squared scales ``s2``
    (written to the ``out`` arrays if given)."""
    den = np.add(r2, s2, out=weight_out)
    rho = np.divide(r2, den, out=rho_out)
    weight = np.divide(s2, den, out=den)
    np.square(weight, out=weight)
    return rho, weight


def geman_mcclure_weights(r, scale):
    """IRLS weights of the Geman-McClure estimator ``rho(r) = r^2 / (r^2 + s^2)``."""
    return geman_mcclure(r * r, scale * scale)[1]


class _Pullback:
    """Maps image gradients (N, 2) to world gradients (N, 3) through the projection:
    ``grad^T d uv / d X``, without forming the (N, 2, 3) Jacobians where the camera model
    allows (the common distortion-free pinhole and scaled orthographic cases)."""

    def __init__(self, fn, depth):
        self.fn = fn
        self.depth = depth

    def __call__(self, grad, out=None):
        """World gradients of image gradients ``grad`` (N, 2), written to ``out`` if given."""
        return self.fn(grad, out)


def _projection(camera, X):
    """Pixels of world points and the pull-back of image gradients to world gradients.

    Convention: world to OpenCV pixels through the camera's own model; for a pinhole without
    distortion ``d uv / d X = K_2x2 [[1/z, 0, -x/z^2], [0, 1/z, -y/z^2]] R``.
    """
    R = camera.R
    Xc = X @ R.T
    t = camera.t
    for j in range(3):          # the same sums as ``+ t``, without a loop over 3-long rows
        Xc[:, j] += t[j]
    if hasattr(camera, "K") and not getattr(camera, "has_distortion", True):
        K = camera.K
        z = Xc[:, 2]
        inv_z = 1.0 / np.where(np.abs(z) < 1e-12, 1e-12, z)
        x, y = Xc[:, 0] * inv_z, Xc[:, 1] * inv_z
        fx, skew, cx, fy, cy = K[0, 0], K[0, 1], K[0, 2], K[1, 1], K[1, 2]
        uv = np.empty((len(z), 2))
        uv[:, 0] = fx * x + skew * y + cx
        uv[:, 1] = fy * y + cy

        def pull(grad, out=None):
            g0, g1 = grad[:, 0], grad[:, 1]
            gu = g0 * fx
            gv = g0 * skew + g1 * fy
            gc = np.empty((len(gu), 3))
            np.multiply(gu, inv_z, out=gc[:, 0])
            np.multiply(gv, inv_z, out=gc[:, 1])
            gu *= x
            gv *= y
            gu += gv
            gu *= inv_z
            np.negative(gu, out=gc[:, 2])
            return np.matmul(gc, R, out=out)

        return uv, _Pullback(pull, z)
    if not hasattr(camera, "K") and not camera.kappa:
        s = camera.s
        uv = s * Xc[:, :2] + camera.c

        def pull(grad, out=None):
            return np.matmul(s * grad, R[:2], out=out)

        return uv, _Pullback(pull, Xc[:, 2])
    uv, Jp = camera.project_jacobian(X)
    return uv, _Pullback(lambda grad, out=None: np.einsum("ni,nij->nj", grad, Jp, out=out),
                         Xc[:, 2])


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
    layout = getattr(term, "_stack", None)
    if layout is None or layout.parts[0] is not term:
        layout = term._stack = Stack([term])
    total, (part,) = accumulate_stacked(layout, [stack], [camera], [1.0], seg2world,
                                        n_segments, with_scale=with_scale, robust=robust,
                                        extra_weights=[extra_weight])
    return Accumulated(total.A, total.b, part.cost, part.count, part.residual, part.inside)


class Stack:
    """Terms of several views that share one set of segment transforms (calibrated views),
    laid out once for :func:`accumulate_stacked`: points concatenated part after part, and
    the order that groups them by segment for the per-segment sums. The layout copies the
    terms' targets, weights and scales: terms are not changed once laid out.

    Parameters
    ----------
    parts : list of Term
    """

    def __init__(self, parts):
        self.parts = parts
        sizes = [len(t) for t in parts]
        self.bounds = np.concatenate([[0], np.cumsum(sizes)]).astype(int)
        if not parts:
            parts = [Term(0, np.zeros(0, int), np.zeros((0, 3)), np.zeros(0), np.zeros(0), 1.0)]
        seg = np.concatenate([t.segment for t in parts])
        self.order = np.argsort(seg, kind="stable")
        self.unorder = np.empty_like(self.order)
        self.unorder[self.order] = np.arange(len(seg))
        self.groups = _segment_runs(seg[self.order])
        self.ref_sorted = np.concatenate([t.ref_points for t in parts])[self.order]
        self.target = np.concatenate([t.target for t in parts]).astype(np.float64)
        self.weight = np.concatenate([t.weight for t in parts]).astype(np.float64)
        self.scale = np.concatenate([np.full(len(t), float(t.scale)) for t in parts])
        hinged = [t.hinge is not None for t in parts]
        self.hinged = np.repeat(hinged, [len(t) for t in parts])
        self.hinge = np.concatenate([np.full(len(t), t.hinge if t.hinge is not None else 0.0)
                                     for t in parts])
        self.any_hinge = any(hinged)
        self.scale2 = self.scale * self.scale
        self._part_weights = (None, None)

    def part_weights(self, weights):
        """Each point's part weight, ``np.repeat(weights, part sizes)`` (kept for the last
        weights asked for)."""
        key = tuple(float(x) for x in weights)
        if self._part_weights[0] != key:
            self._part_weights = (key, np.repeat(np.asarray(weights, float),
                                                 np.diff(self.bounds)))
        return self._part_weights[1]


class _Workspace(threading.local):
    """Work arrays of :func:`accumulate_stacked`, kept between calls (per thread).

    A fresh array of a few hundred kilobytes comes from the system as untouched pages (the
    allocator hands large blocks back when they are freed), and touching them costs as much
    as the arithmetic: the same buffers are reused instead. Their contents are undefined, and
    nothing that leaves :func:`accumulate_stacked` lives in them.
    """

    def __init__(self):
        self.buffers = {}

    def get(self, name, n, width=1, dtype=np.float64):
        """A C-contiguous work array of shape (n,) or (n, width)."""
        key = (name, width, np.dtype(dtype).char)
        buf = self.buffers.get(key)
        size = n * width
        if buf is None or buf.size < size:
            buf = self.buffers[key] = np.empty(size + size // 4 + 1024, dtype)
        view = buf[:size]
        return view if width == 1 and name not in _WIDE else view.reshape(n, width)


_KEEP = object()        # accumulate_stacked's normal equations: keep the EM weights given
_WIDE = frozenset(("X", "Xs", "vals", "grad", "gp", "gp_sorted", "G", "GW"))
_WORKSPACE = _Workspace()


def _camera_runs(bounds, cameras):
    """Runs of consecutive parts with the same camera object: ``(lo, hi, first, last)``
    with the runs' point range and parts ``first`` to ``last - 1``."""
    runs = []
    first = 0
    for i in range(1, len(cameras) + 1):
        if i == len(cameras) or cameras[i] is not cameras[first]:
            runs.append((int(bounds[first]), int(bounds[i]), first, i))
            first = i
    return runs


def accumulate_stacked(stack_terms, images, cameras, weights, seg2world, n_segments, *,
                       with_scale=False, robust=True, extra_weights=None, lazy=False):
    """:func:`accumulate` over several terms at once, summed per segment into one system.

    Valid when every term moves with the same ``seg2world`` (calibrated views share the world
    pose): the per-segment normal equations of all views add up before they are mapped to the
    pose parameters, and everything but the projection and the image sampling runs once over
    all points (Yamamoto et al.'s stacked system, eqs. 8-12).

    Parameters
    ----------
    stack_terms : Stack
    images : list of array (H, W, 3)
        Per part, the image with gradients it samples.
    cameras : list of camera
        Per part, at the image's resolution.
    weights : list of float
        Per part, the term weight.
    with_scale : bool
        Fill the seventh column: the derivative in the log of a scaled-orthographic view's
        scale (one view's terms only: the scale is the view's own parameter).
    robust : bool
        Geman-McClure weights and costs (False: plain least squares).
    extra_weights : list of array or None, optional
        Per part, EM ownership weights.
    lazy : bool
        Return the cost at once and the normal equations on demand: a Levenberg-Marquardt
        step that raises the cost needs only the cost. Ask for them before the next call (the
        two share work arrays). The function takes other ``extra_weights`` (same form): the
        costs and residuals do not depend on them, so an EM step re-weighs the equations
        without projecting and sampling again.

    Returns
    -------
    total : Accumulated
        Summed A (S, 7, 7), b and cost; ``residual``/``inside`` are None. With ``lazy``, a
        function that returns it instead.
    parts : list of Accumulated
        Per part: cost, count, residual and inside (``A``/``b`` None).
    """
    st = stack_terms
    bounds = st.bounds
    n = int(bounds[-1])
    work = _WORKSPACE
    # world points of all parts: one product per segment, then back to the parts' order
    Xs = work.get("Xs", n, 3)
    for k, lo, hi in st.groups:
        T = seg2world[k]
        np.matmul(st.ref_sorted[lo:hi], T[:3, :3].T, out=Xs[lo:hi])
        Xs[lo:hi] += T[:3, 3]
    X = np.take(Xs, st.unorder, axis=0, out=work.get("X", n, 3), mode="clip")
    vals = work.get("vals", n, 3, np.float32)
    inside = np.empty(n, bool)
    pulls = []
    centred = np.empty((n, 2)) if with_scale else None     # pixels about the scale's centre
    # Consecutive parts seen by the same camera object (a view's flow and silhouette terms)
    # are projected together, and each part samples its own image from the shared pixels:
    # the projection is row by row, so the pixels are the same as part by part.
    for lo, hi, first, last in _camera_runs(bounds, cameras):
        camera = cameras[first]
        uv, pullback = _projection(camera, X[lo:hi])
        for i in range(first, last):
            a, z = bounds[i], bounds[i + 1]
            vals[a:z], inside[a:z] = sample_fast(images[i], uv[a - lo:z - lo])
        if hasattr(camera, "K"):
            inside[lo:hi] &= pullback.depth > 1e-3
        if with_scale:
            centred[lo:hi] = uv - camera.c
        pulls.append((lo, hi, pullback))
    r = vals[:, 0].astype(np.float64)
    r -= st.target
    grad = work.get("grad", n, 2)
    np.copyto(grad, vals[:, 1:3])
    if st.any_hinge:
        r -= st.hinge
        off = st.hinged & (r <= 0)
        r[off] = 0.0
        grad[off] = 0.0
    part_w = st.part_weights(weights)
    base = np.multiply(st.weight, inside, out=work.get("base", n))
    r2 = np.multiply(r, r, out=work.get("r2", n))
    if robust:
        rho, gm = geman_mcclure(r2, st.scale2, work.get("rho", n), work.get("den", n))
    else:
        rho, gm = r2, None

    def weights_with(extra):
        """The points' weights: term weight and inside, EM ownership, robust weight."""
        w = base
        if extra is not None and any(e is not None for e in extra):
            ew = work.get("extra", n)
            for i, e in enumerate(extra):
                ew[bounds[i]:bounds[i + 1]] = 1.0 if e is None else e
            w = np.multiply(base, ew, out=ew)
        if gm is not None:
            w = np.multiply(w, gm, out=work.get("w", n))
        return w

    w = weights_with(extra_weights)
    # The costs do not depend on the EM weights (they weigh the normal equations only).
    brho = np.multiply(base, rho, out=work.get("brho", n))
    out = []
    for i in range(len(st.parts)):
        lo, hi = bounds[i], bounds[i + 1]
        out.append(Accumulated(None, None, float(brho[lo:hi].sum()), float(w[lo:hi].sum()),
                               r[lo:hi], inside[lo:hi]))
    cost = float(part_w @ brho)

    def normal_equations(extra_weights=_KEEP):
        nonlocal w
        if extra_weights is not _KEEP:
            # the same residuals under other EM weights (the parts' counts follow)
            w = weights_with(extra_weights)
            for i, acc in enumerate(out):
                acc.count = float(w[bounds[i]:bounds[i + 1]].sum())
        # The rows g_i = [world gradient, X x world gradient] go straight into segment order:
        # only the world gradients are gathered, the points are already sorted (Xs).
        gp = work.get("gp", n, 3)
        for lo, hi, pull in pulls:
            pull(grad[lo:hi], out=gp[lo:hi])
        order = st.order
        gp = np.take(gp, order, axis=0, out=work.get("gp_sorted", n, 3), mode="clip")
        m = 7 if with_scale else 6
        G = work.get("G", n, m)
        G[:, :3] = gp
        t1, t2 = work.get("t1", n), work.get("t2", n)
        for col, (i, j) in ((3, (1, 2)), (4, (2, 0)), (5, (0, 1))):
            # (X x gradient)_col = X_i g_j - X_j g_i
            np.multiply(Xs[:, i], gp[:, j], out=t1)
            np.multiply(Xs[:, j], gp[:, i], out=t2)
            np.subtract(t1, t2, out=G[:, col])
        if with_scale:
            G[:, 6] = np.take(grad[:, 0] * centred[:, 0] + grad[:, 1] * centred[:, 1], order)
        W = np.multiply(part_w, w, out=t1)
        R = np.take(r, order, out=work.get("R", n), mode="clip")
        W = np.take(W, order, out=t2, mode="clip")
        A = np.zeros((n_segments, 7, 7))
        b = np.zeros((n_segments, 7))
        GW = work.get("GW", n, m)
        for j in range(m):
            np.multiply(G[:, j], W, out=GW[:, j])
        for k, lo, hi in st.groups:
            A[k, :m, :m] = GW[lo:hi].T @ G[lo:hi]
            b[k, :m] = GW[lo:hi].T @ R[lo:hi]
        return Accumulated(A, b, cost, float(W.sum()), None, None)

    if lazy:
        normal_equations.cost = cost
        return normal_equations, out
    return normal_equations(), out


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


def support_weights(terms_by_view, stacks, accs, scale, flow_weight):
    """One EM step on the support maps (B&M §2.4): ownership against a static background.

    For each template pixel, the segment's motion predicts ``I(t+1)`` at the moved point
    (residual ``r_fg``); a static background predicts ``I(t+1)`` at the pixel itself
    (``r_bg``). The posterior of the segment layer, with the foreground mask as its prior,
    replaces the pixel's weight. Cameras are assumed static (the background's dominant
    motion is zero).

    Parameters
    ----------
    terms_by_view : list of list of (str, Term, float)
        Each view's terms at one level; the first is the image motion's.
    stacks : list of Stack
        ``I(t+1)`` of each view at that level.
    accs : dict
        The accumulated residuals by ``(view, name)``.
    scale : float
        The grey residuals' scale (``Settings.flow_scale``).
    flow_weight : float
        The image motion's weight: template pixels weighed less start from a lower prior.

    Returns
    -------
    weights : dict of (int, str) to array
    """
    sig2 = scale ** 2
    out = {}
    for c, terms in enumerate(terms_by_view):
        key = (c, "flow")
        term = terms[0][1]
        acc = accs.get(key)
        if acc is None or term.uv is None:
            continue
        # Anchor points carry NaN pixels: they keep their weight.
        vals, ok = sample_fast(stacks[c], np.nan_to_num(term.uv, nan=-1.0))
        r_bg = vals[:, 0] - term.target
        prior = np.where(term.weight >= flow_weight, 0.8, 0.3)
        p_fg = prior * np.exp(-0.5 * acc.residual ** 2 / sig2)
        p_bg = (1.0 - prior) * np.exp(-0.5 * r_bg ** 2 / sig2)
        own = p_fg / (p_fg + p_bg + 1e-300)
        fg_prior = np.where(term.weight >= flow_weight, 1.0, 0.25)
        out[key] = np.where(ok, own / fg_prior, 1.0)
    return out
