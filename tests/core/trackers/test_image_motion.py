"""Image terms: per-segment normal equations equal the full Jacobian's, and are right."""

import numpy as np
import pytest

from zoopraxis.core.trackers import image_motion as im
from zoopraxis.core.geometry import se3
from zoopraxis.core.body.body import Pose, make_body
from zoopraxis.core.geometry.camera import PinholeCamera, look_at


from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
def smooth_image(rng, h=120, w=160):
    import cv2

    small = rng.uniform(0, 1, size=(h // 8 + 2, w // 8 + 2)).astype(np.float32)
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_CUBIC)


@pytest.fixture
def setup(rng):
    body = make_body("full")
    pose = Pose(se3.transform(p=[0, 0, 0.95]), np.zeros(body.n_dofs))
    pose.angles[body.dof_index("l_knee_flex")] = 0.4
    R, t = look_at([0.3, -3.0, 1.0], [0, 0, 0.8])
    cam = PinholeCamera("c", (160, 120), [[150, 0, 79.5], [0, 150, 59.5], [0, 0, 1]],
                        dist=[-0.1, 0.02, 0.001, -0.001, 0], R=R, t=t)
    n = 300
    seg = rng.integers(0, body.n_segments, size=n)
    ref = body.reference_point("pelvis") + rng.normal(0, 0.3, size=(n, 3))
    term = im.Term(0, seg, ref, rng.uniform(0, 1, n), rng.uniform(0.5, 1, n), 0.1, "flow")
    stack = im.image_with_gradients(smooth_image(rng))
    return body, pose, cam, term, stack


def residuals(body, pose, cam, term, stack):
    X = se3.apply(body.seg2world(pose)[term.segment], term.ref_points)
    vals, inside = im.sample(stack, cam.project(X))
    return vals[:, 0] - term.target, inside


def test_term_groups_points_by_segment(setup):
    _, _, _, term, _ = setup
    assert np.all(np.diff(term.segment) >= 0)
    for k, lo, hi in term.groups:
        assert np.all(term.segment[lo:hi] == k)


def test_normal_equations_equal_the_full_jacobian_products(setup):
    """Accumulating 6x6 blocks per segment gives exactly J^T W J and J^T W r of the full
    (pixels x parameters) Jacobian built row by row (eqs. 24-26)."""
    body, pose, cam, term, stack = setup
    seg2world, seg_jac = body.kinematics(pose)
    acc = im.accumulate(term, stack, cam, seg2world, body.n_segments, robust=False)
    P = body.n_params
    H, g = im.assemble(acc, seg_jac, root_cols=np.arange(6), angle_cols=np.arange(6, P),
                       n_params=P)
    X = se3.apply(seg2world[term.segment], term.ref_points)
    uv, Jp = cam.project_jacobian(X)
    vals, inside = im.sample_fast(stack, uv)       # the sampler accumulate uses
    rows = np.einsum("ni,nij,njk,nkp->np", vals[:, 1:3].astype(float), Jp,
                     se3.point_velocity_matrix(X), seg_jac[term.segment])
    w = term.weight * inside
    assert np.allclose(H, (rows * w[:, None]).T @ rows, rtol=1e-6, atol=1e-9)
    assert np.allclose(g, (rows * w[:, None]).T @ acc.residual, rtol=1e-6, atol=1e-9)


def test_linearisation_against_finite_differences(setup):
    """On a smooth image the analytic rows predict how residuals change with the pose."""
    body, pose, cam, term, _ = setup
    uu, vv = np.meshgrid(np.arange(160), np.arange(120))
    stack = im.image_with_gradients((np.sin(uu / 7.0) + np.cos(vv / 9.0)).astype(np.float32))
    seg2world, seg_jac = body.kinematics(pose)
    X = se3.apply(seg2world[term.segment], term.ref_points)
    uv, Jp = cam.project_jacobian(X)
    vals, inside = im.sample(stack, uv)
    rows = np.einsum("ni,nij,njk,nkp->np", vals[:, 1:3].astype(float), Jp,
                     se3.point_velocity_matrix(X), seg_jac[term.segment])
    P = body.n_params
    h = 1e-4
    for i in (0, 2, 4, 6 + body.dof_index("l_knee_flex"), 6 + body.dof_index("r_hip_abd")):
        d = np.zeros(P)
        d[i] = h
        rp, okp = residuals(body, pose.retract(d), cam, term, stack)
        rm, okm = residuals(body, pose.retract(-d), cam, term, stack)
        ok = inside & okp & okm & (np.abs(rows[:, i]) > 1e-3)
        fd = (rp - rm)[ok] / (2 * h)
        assert np.median(np.abs(fd - rows[ok, i]) / np.abs(rows[ok, i])) < 0.1


def test_scale_column_for_orthographic_views(rng):
    body = make_body("muybridge")
    pose = Pose(se3.transform(p=[0, 0, 5.0]), np.zeros(body.n_dofs))
    cam = ScaledOrthoCamera("o", (160, 120), s=60.0)
    n = 200
    term = im.Term(0, rng.integers(0, body.n_segments, n), rng.normal(0, 0.3, (n, 3)),
                   rng.uniform(0, 1, n), np.ones(n), 0.1)
    stack = im.image_with_gradients(smooth_image(rng))
    seg2world, seg_jac = body.kinematics(pose)
    acc = im.accumulate(term, stack, cam, seg2world, body.n_segments, with_scale=True,
                        robust=False)
    # d residual / d log s by finite differences of the camera scale
    h = 1e-3

    def res(s):
        X = se3.apply(seg2world[term.segment], term.ref_points)
        vals, _ = im.sample(stack, cam.replace(s=s).project(X))
        return vals[:, 0] - term.target

    d = (res(60.0 * np.exp(h)) - res(60.0 * np.exp(-h))) / (2 * h)
    b_scale = acc.b[:, 6].sum()
    assert np.isclose(b_scale, np.sum(d * acc.residual), rtol=0.05)


def test_hinge_terms_only_count_outside(rng):
    body = make_body("full")
    pose = body.rest_pose(se3.transform(p=[0, 0, 0.95]))
    cam = ScaledOrthoCamera("o", (160, 120), s=50.0, R=look_at([0, -5, 1], [0, 0, 1])[0],
                            t=look_at([0, -5, 1], [0, 0, 1])[1])
    stack = im.image_with_gradients(np.full((120, 160), -5.0, np.float32))  # all "inside"
    term = im.Term(0, np.zeros(10, int), np.zeros((10, 3)), np.zeros(10), np.ones(10), 3.0,
                   hinge=1.0)
    acc = im.accumulate(term, stack, cam, body.seg2world(pose), body.n_segments)
    assert acc.cost == 0.0 and np.allclose(acc.A, 0.0)


def test_geman_mcclure_downweights_outliers():
    w = im.geman_mcclure_weights(np.array([0.0, 0.1, 1.0]), 0.1)
    assert w[0] == 1.0 and 0 < w[2] < w[1] < 1


@pytest.mark.parametrize("model", ["pinhole", "ortho", "distorted"])
def test_gradient_pullback_equals_projection_jacobian(rng, model):
    R, t = look_at([0.3, -3.0, 1.0], [0, 0, 0.8])
    K = [[150, 0.5, 79.5], [0, 140, 59.5], [0, 0, 1]]
    cam = {"pinhole": PinholeCamera("c", (160, 120), K, R=R, t=t),
           "ortho": ScaledOrthoCamera("o", (160, 120), s=50.0, R=R, t=t),
           "distorted": PinholeCamera("d", (160, 120), K, dist=[-0.1, 0.01, 1e-3, 0, 0], R=R,
                                      t=t)}[model]
    X = rng.normal(0, 0.3, (50, 3)) + [0, 0, 0.9]
    grad = rng.normal(size=(50, 2))
    uv, pull = im._projection(cam, X)
    uv_ref, J = cam.project_jacobian(X)
    assert np.allclose(uv, uv_ref)
    assert np.allclose(pull(grad), np.einsum("ni,nij->nj", grad, J))


def test_fast_sampler_agrees_with_exact_bilinear(rng):
    """cv2.remap rounds positions to 1/32 px: on a smooth image the values agree to that, the
    inside flags agree exactly, and long lists (folded into rows) keep their order."""
    uu, vv = np.meshgrid(np.arange(160), np.arange(120))
    stack = im.image_with_gradients((np.sin(uu / 7.0) + np.cos(vv / 9.0)).astype(np.float32))
    uv = np.column_stack([rng.uniform(-5, 165, 5000), rng.uniform(-5, 125, 5000)])
    uv[7] = np.nan
    exact, ok = im.sample(stack, uv)
    fast, ok_fast = im.sample_fast(stack, uv)
    assert np.array_equal(ok, ok_fast) and not ok[7]
    assert ok.sum() > 4000
    # |dI/dx| <= 1/7 + ... : 1/32 px moves the value by well under 0.01
    assert np.abs(fast[ok] - exact[ok]).max() < 0.01
    few, _ = im.sample_fast(stack, uv[:3])
    assert np.allclose(few, fast[:3])


@pytest.mark.parametrize("with_scale", [False, True])
def test_stacked_accumulation_equals_a_point_by_point_reference(rng, with_scale):
    """accumulate_stacked over several views against the plain computation: each point's
    twist-space row from the camera's projection Jacobian, robust weights, hinges and EM
    weights, summed per segment."""
    body = make_body("full")
    pose = Pose(se3.transform(p=[0, 0, 0.95]), rng.uniform(-0.2, 0.2, body.n_dofs))
    seg2world = body.seg2world(pose)
    K = [[150, 0.5, 79.5], [0, 140, 59.5], [0, 0, 1]]
    cams, terms, images, extra = [], [], [], []
    for v, eye in enumerate(([0.3, -3.0, 1.0], [2.5, -1.5, 1.2], [-2.0, 2.0, 0.8])):
        R, t = look_at(eye, [0, 0, 0.8])
        cams.append(ScaledOrthoCamera("o", (160, 120), s=50.0, R=R, t=t) if with_scale
                    else PinholeCamera(f"c{v}", (160, 120), K, R=R, t=t))
        n = 200 + 50 * v
        seg = rng.integers(0, body.n_segments, size=n)
        ref = body.reference_point("pelvis") + rng.normal(0, 0.3, size=(n, 3))
        terms.append(im.Term(v, seg, ref, rng.uniform(0, 1, n), rng.uniform(0.5, 1, n),
                             0.1 + 0.05 * v, hinge=0.05 if v == 1 else None))
        images.append(im.image_with_gradients(smooth_image(rng)))
        extra.append(None if v == 2 else rng.uniform(0.5, 1.5, n))
    if with_scale:
        terms, images, cams, extra = terms[:1], images[:1], cams[:1], extra[:1]
    weights = [1.0, 0.7, 1.3][:len(terms)]
    total, parts = im.accumulate_stacked(im.Stack(terms), images, cams, weights, seg2world,
                                         body.n_segments, with_scale=with_scale,
                                         extra_weights=extra)
    A = np.zeros((body.n_segments, 7, 7))
    b = np.zeros((body.n_segments, 7))
    cost = count = 0.0
    for term, image, cam, pw, e, part in zip(terms, images, cams, weights, extra, parts):
        X = se3.apply(seg2world[term.segment], term.ref_points)
        uv, Jp = cam.project_jacobian(X)
        vals, inside = im.sample_fast(image, uv)
        if hasattr(cam, "K"):
            inside &= cam.cam_from_world(X)[:, 2] > 1e-3
        r = vals[:, 0].astype(float) - term.target
        grad = vals[:, 1:3].astype(float)
        if term.hinge is not None:
            r = r - term.hinge
            grad[r <= 0] = 0.0
            r[r <= 0] = 0.0
        base = term.weight * inside
        w = base * (1.0 if e is None else e) * im.geman_mcclure_weights(r, term.scale)
        rows = np.einsum("ni,nij,njk->nk", grad, Jp, se3.point_velocity_matrix(X))
        if with_scale:
            rows = np.column_stack([rows, np.sum(grad * (uv - cam.c), axis=1)])
        m = rows.shape[1]
        np.add.at(A[:, :m, :m], term.segment, pw * w[:, None, None] * rows[:, :, None]
                  * rows[:, None, :])
        np.add.at(b[:, :m], term.segment, pw * (w * r)[:, None] * rows)
        rho = base * r * r / (r * r + term.scale ** 2)
        cost += pw * rho.sum()
        count += pw * w.sum()
        assert np.allclose(part.residual, r, rtol=0, atol=1e-12)
        assert np.array_equal(part.inside, inside)
        assert np.isclose(part.cost, rho.sum(), rtol=1e-9)
        assert np.isclose(part.count, w.sum(), rtol=1e-9)
    scale = np.abs(A).max()
    assert scale > 0 and inside.any()
    assert np.allclose(total.A, A, rtol=0, atol=1e-9 * scale)
    assert np.allclose(total.b, b, rtol=0, atol=1e-9 * np.abs(b).max())
    assert np.isclose(total.cost, cost, rtol=1e-9)
    assert np.isclose(total.count, count, rtol=1e-9)


def test_parts_sharing_a_camera_sample_the_pixels_of_their_own_projection(rng):
    """Parts seen by one camera object are projected together (and the work arrays are
    reused between calls): each part's residuals, inside flags, cost and count are exactly
    those of the part accumulated alone, and the sums match the parts' sums."""
    body = make_body("full")
    pose = Pose(se3.transform(p=[0, 0, 0.95]), rng.uniform(-0.2, 0.2, body.n_dofs))
    seg2world = body.seg2world(pose)
    K = [[150, 0.5, 79.5], [0, 140, 59.5], [0, 0, 1]]
    terms, images, cams, extra = [], [], [], []
    for v, eye in enumerate(([0.3, -3.0, 1.0], [2.5, -1.5, 1.2])):
        R, t = look_at(eye, [0, 0, 0.8])
        cam = PinholeCamera(f"c{v}", (160, 120), K, R=R, t=t)
        for p in range(2):          # a "flow" and a "silhouette" part per view
            n = 150 + 40 * v + 30 * p
            seg = rng.integers(0, body.n_segments, size=n)
            ref = body.reference_point("pelvis") + rng.normal(0, 0.3, size=(n, 3))
            terms.append(im.Term(v, seg, ref, rng.uniform(0, 1, n), rng.uniform(0.5, 1, n),
                                 0.1 + 0.1 * p, hinge=0.05 if p else None))
            images.append(im.image_with_gradients(smooth_image(rng)))
            cams.append(cam)
            extra.append(None if p else rng.uniform(0.5, 1.5, n))
    weights = [1.0, 0.3, 1.0, 0.3]
    for stack_terms in (terms, terms[1:]):      # two sizes through the same work arrays
        k = len(terms) - len(stack_terms)
        total, parts = im.accumulate_stacked(
            im.Stack(stack_terms), images[k:], cams[k:], weights[k:], seg2world,
            body.n_segments, extra_weights=extra[k:])
        A = np.zeros_like(total.A)
        b = np.zeros_like(total.b)
        for term, image, cam, pw, e, part in zip(stack_terms, images[k:], cams[k:],
                                                 weights[k:], extra[k:], parts):
            alone = im.accumulate(term, image, cam, seg2world, body.n_segments,
                                  extra_weight=e)
            assert np.array_equal(part.residual, alone.residual)
            assert np.array_equal(part.inside, alone.inside)
            assert part.cost == alone.cost and part.count == alone.count
            A += pw * alone.A
            b += pw * alone.b
        assert np.allclose(total.A, A, rtol=0, atol=1e-12 * np.abs(A).max())
        assert np.allclose(total.b, b, rtol=0, atol=1e-12 * np.abs(b).max())


def test_segment_runs_equal_unique_on_sorted_segments(rng):
    for n in (0, 1, 2, 7, 500):
        for top in (1, 3, 20):
            seg = np.sort(rng.integers(0, top, size=n))
            segs, first = np.unique(seg, return_index=True)
            ref = list(zip(segs.tolist(), first.tolist(), first[1:].tolist() + [n]))
            assert im._segment_runs(seg) == ref
            if n:
                shuffled = rng.permutation(seg)
                term = im.Term(0, shuffled, np.zeros((n, 3)), np.zeros(n), np.ones(n), 1.0)
                assert term.groups == ref
                assert im.Stack([term, term]).groups == im._segment_runs(
                    np.sort(np.concatenate([seg, seg])))
