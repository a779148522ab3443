"""Tests of the model renderer: support map, depth, points and normals by ray casting."""

import itertools

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zoopraxis.core.geometry.camera import PinholeCamera, look_at

from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.body.primitives import Primitives, cylinder, ellipsoid
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.imaging.render import RenderResult, render, render_points, surface_points

ONE_SEGMENT = np.eye(4)[None]

# float32 ray casting leaves hit points this far (metres) from the true surface for primitives
# a few metres away: well under a hundredth of a pixel's footprint there.
SURFACE_TOL = 5e-5


def pinhole(size=(320, 240), f=300.0, eye=(0.0, -2.0, 0.0), target=(0.0, 0.0, 0.0),
            principal=None, dist=None):
    W, H = size
    cx, cy = ((W - 1) / 2, (H - 1) / 2) if principal is None else principal
    R, t = look_at(eye, target)
    return PinholeCamera("cam", size, [[f, 0, cx], [0, f, cy], [0, 0, 1]], dist=dist, R=R, t=t)


def translation(offset):
    T = np.eye(4)
    T[:3, 3] = offset
    return T


def march(camera, inside, near, far, window, n=300):
    """Independent reference: first depth sample along each pixel ray that is inside a solid.

    Returns the depth interval ``(z_before, z_inside)`` for the pixels of ``window`` (a pair of
    slices), inf where no sample is inside.
    """
    origins, dirs = camera.pixel_rays()
    dirs = dirs[window]
    z = np.linspace(near, far, n)
    per_depth = dirs / (dirs @ camera.R[2])[..., None]
    X = origins + per_depth[..., None, :] * z[:, None]
    hit = inside(X.reshape(-1, 3)).reshape(dirs.shape[:2] + (n,))
    first = np.where(hit.any(axis=2), hit.argmax(axis=2), n)
    z_ext = np.append(z, np.inf)
    return np.where(first > 0, z_ext[first - 1], -np.inf), z_ext[first]


def boundary_band(mask):
    """Pixels within one pixel of the mask's silhouette."""
    kernel = np.ones((3, 3), np.uint8)
    m = mask.astype(np.uint8)
    return (cv2.dilate(m, kernel) != cv2.erode(m, kernel))


def assert_matches_march(result, camera, inside, near, far, margin=8):
    """Support map and depth agree with ray marching, away from the silhouette.

    Marches the rays of the silhouette's bounding box grown by ``margin`` pixels, so a part of
    the silhouette the renderer lost at its edge would show up.
    """
    v, u = np.nonzero(result.label >= 0)
    window = (slice(max(v.min() - margin, 0), v.max() + margin + 1),
              slice(max(u.min() - margin, 0), u.max() + margin + 1))
    z_before, z_inside = march(camera, inside, near, far, window)
    hit = result.label[window] >= 0
    assert not (hit[0].any() or hit[-1].any() or hit[:, 0].any() or hit[:, -1].any())
    marched = np.isfinite(z_inside)
    disagree = hit != marched
    assert not np.any(disagree & ~boundary_band(hit)), "support map differs inside"
    assert disagree.sum() <= 0.02 * boundary_band(hit).sum()
    both = hit & marched
    assert both.sum() > 500
    # float32 rounding moves grazing hits along their rays by up to ~0.1 mm
    d = result.depth[window][both]
    assert np.all(d <= z_inside[both] + 1e-4) and np.all(d >= z_before[both] - 1e-4)


# ---------------------------------------------------------------------------------------------
# Geometry of single primitives
# ---------------------------------------------------------------------------------------------

class TestSphere:
    d, r, f = 2.0, 0.25, 300.0

    @pytest.fixture
    def scene(self):
        # The principal point on a pixel centre puts the optical axis through pixel (160, 120).
        camera = pinhole(f=self.f, eye=(0.0, -self.d, 0.0), principal=(160.0, 120.0))
        return camera, render(camera, ONE_SEGMENT, ellipsoid(0, (0, 0, 0), self.r))

    def test_outputs(self, scene):
        _, res = scene
        assert isinstance(res, RenderResult)
        assert res.label.shape == res.prim.shape == res.depth.shape == (240, 320)
        assert res.point.shape == res.normal.shape == (240, 320, 3)
        assert (res.label.dtype, res.prim.dtype) == (np.int16, np.int16)
        assert res.depth.dtype == res.point.dtype == res.normal.dtype == np.float32
        bg = res.label < 0
        assert np.all(res.prim[bg] == -1) and np.all(np.isinf(res.depth[bg]))
        assert np.all(np.isnan(res.point[bg])) and np.all(np.isnan(res.normal[bg]))
        np.testing.assert_array_equal(res.mask(0), res.label == 0)

    def test_silhouette_area(self, scene):
        # The tangent cone has half-angle asin(r/d): an image disc of radius f r / sqrt(d^2-r^2).
        _, res = scene
        area = np.pi * self.r**2 * self.f**2 / (self.d**2 - self.r**2)
        assert res.mask(0).sum() == pytest.approx(area, rel=0.005)

    def test_centre_depth(self, scene):
        _, res = scene
        assert res.depth[120, 160] == pytest.approx(self.d - self.r, abs=1e-6)
        assert res.depth[res.mask(0)].min() == pytest.approx(self.d - self.r, abs=1e-6)

    def test_points_on_sphere_and_on_their_rays(self, scene):
        camera, res = scene
        m = res.mask(0)
        X = res.point[m].astype(float)
        np.testing.assert_allclose(np.linalg.norm(X, axis=1), self.r, atol=SURFACE_TOL)
        v, u = np.nonzero(m)
        np.testing.assert_allclose(camera.project(X), np.stack([u, v], axis=1), atol=1e-3)
        np.testing.assert_allclose(camera.depth(X), res.depth[m], rtol=1e-6)

    def test_normals_unit_outward_facing_camera(self, scene):
        camera, res = scene
        m = res.mask(0)
        N = res.normal[m].astype(float)
        X = res.point[m].astype(float)
        np.testing.assert_allclose(np.linalg.norm(N, axis=1), 1.0, atol=1e-6)
        np.testing.assert_allclose(N, X / np.linalg.norm(X, axis=1, keepdims=True), atol=1e-4)
        view = X - camera.center
        assert np.all(np.einsum("ij,ij->i", N, view) < 1e-3)

    def test_want_skips_outputs(self, scene):
        camera, full = scene
        res = render(camera, ONE_SEGMENT, ellipsoid(0, (0, 0, 0), self.r), want=())
        assert res.point is None and res.normal is None
        np.testing.assert_array_equal(res.depth, full.depth)
        res = render(camera, ONE_SEGMENT, ellipsoid(0, (0, 0, 0), self.r), want=["normal"])
        assert res.point is None
        np.testing.assert_array_equal(res.normal, full.normal)

    def test_camera_inside_sees_the_inner_side(self):
        camera = pinhole(eye=(0.0, 0.0, 0.0), target=(0.0, 1.0, 0.0))
        res = render(camera, ONE_SEGMENT, ellipsoid(0, (0.1, 0.0, 0.0), 3.0))
        assert np.all(res.label == 0)
        X = res.point.reshape(-1, 3).astype(float)
        np.testing.assert_allclose(np.linalg.norm(X - (0.1, 0, 0), axis=1), 3.0, atol=1e-4)
        N = res.normal.reshape(-1, 3)
        assert np.all(np.einsum("ij,ij->i", N, X) < 0)  # facing the camera: inward


class TestEllipsoid:
    def test_rotated_ellipsoid_quadric_normals_and_silhouette(self):
        Q = Rotation.random(random_state=2345).as_matrix()
        semi = np.array([0.3, 0.15, 0.08])
        centre = np.array([0.05, -0.02, 0.03])
        camera = pinhole(eye=(0.4, -2.5, 0.6))
        res = render(camera, ONE_SEGMENT, ellipsoid(0, centre, semi, Q))
        m = res.mask(0)
        X = res.point[m].astype(float)
        local = (X - centre) @ Q / semi
        grad = local / semi
        distance = np.abs((local**2).sum(axis=1) - 1) / (2 * np.linalg.norm(grad, axis=1))
        assert distance.max() < SURFACE_TOL
        normal = grad @ Q.T
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        np.testing.assert_allclose(res.normal[m], normal, atol=1e-5)

        def inside(P):
            return (((P - centre) @ Q / semi) ** 2).sum(axis=1) <= 1

        assert_matches_march(res, camera, inside, 2.0, 3.3)


class TestCylinder:
    @pytest.mark.parametrize("taper, tilt, eye", [
        (0.6, (15, 25), (0.6, -2.0, 1.6)),   # narrowing towards the camera: top cap visible
        (1.4, (15, 25), (0.6, -2.0, -1.6)),  # widening, seen from below: base cap visible
        (1.0, (0, 0), (0.3, -2.2, 0.0)),     # upright, camera between the cap planes: no cap
    ])
    def test_cone_frustum_surface_and_caps(self, taper, tilt, eye):
        rot = Rotation.from_euler("xz", tilt, degrees=True).as_matrix()
        base = np.array([0.02, 0.0, -0.25])
        top = base + rot @ np.array([0.0, 0.0, 0.5])
        rx, ry_ratio = 0.12, 0.7
        p = cylinder(0, base, top, rx, rx * taper, ry_ratio=ry_ratio)
        camera = pinhole(eye=eye)
        res = render(camera, ONE_SEGMENT, p)
        m = res.mask(0)
        T = p.prim2seg[0]
        length = 0.5
        local = (res.point[m].astype(float) - T[:3, 3]) @ T[:3, :3]
        x, y, z = local.T / np.array([rx, rx * ry_ratio, length])[:, None]
        k = taper - 1.0
        radius = 1.0 + k * z
        on_base = np.abs(local[:, 2]) < SURFACE_TOL
        on_top = np.abs(local[:, 2] - length) < SURFACE_TOL
        on_side = ~on_base & ~on_top
        assert np.all(x[on_base]**2 + y[on_base]**2 <= 1 + 1e-4)
        assert np.all(x[on_top]**2 + y[on_top]**2 <= taper**2 + 1e-4)
        assert np.all((z[on_side] >= -1e-6) & (z[on_side] <= 1 + 1e-6))
        # distance to the side surface from its implicit function and gradient (metres)
        F = x**2 + y**2 - radius**2
        grad = np.stack([2 * x / rx, 2 * y / (rx * ry_ratio), -2 * k * radius / length])
        distance = np.abs(F) / np.linalg.norm(grad, axis=0)
        assert distance[on_side].max() < SURFACE_TOL
        cap_pixels = on_top.sum() if taper < 1 else on_base.sum()
        if eye[2] != 0.0:
            assert cap_pixels > 100
        else:
            assert on_base.sum() + on_top.sum() == 0

        # normals: the side's gradient, the caps' axis (either one on the rim)
        expected = (grad / np.linalg.norm(grad, axis=0)).T @ T[:3, :3].T
        expected[on_base] = -T[:3, 2]
        expected[on_top] = T[:3, 2]
        rim = (on_base | on_top) & (distance < SURFACE_TOL)
        assert rim.sum() < 0.05 * m.sum()
        np.testing.assert_allclose(res.normal[m][~rim], expected[~rim], atol=1e-4)

        def inside(P):
            q = (P - T[:3, 3]) @ T[:3, :3] / np.array([rx, rx * ry_ratio, length])
            return ((q[:, 2] >= 0) & (q[:, 2] <= 1)
                    & (q[:, 0]**2 + q[:, 1]**2 <= (1 + k * q[:, 2])**2))

        dist = np.linalg.norm(np.asarray(eye))
        assert_matches_march(res, camera, inside, dist - 0.6, dist + 0.6)


# ---------------------------------------------------------------------------------------------
# Several primitives and segments
# ---------------------------------------------------------------------------------------------

def overlapping_scene():
    """Five primitives on three segments that overlap and interpenetrate in the image."""
    prims = Primitives.concat([
        cylinder(0, (-0.3, 0.1, -0.2), (0.3, -0.1, 0.25), 0.12, 0.08, ry_ratio=0.8),
        ellipsoid(1, (0.0, -0.05, 0.0), (0.1, 0.15, 0.2)),
        ellipsoid(2, (0.1, 0.3, 0.05), 0.25),
        cylinder(2, (-0.2, -0.2, 0.3), (0.25, 0.1, -0.3), 0.05),
        ellipsoid(0, (0.3, -0.1, 0.27), 0.085),
    ])
    seg2world = np.stack([np.eye(4)] * 3)
    return prims, seg2world


class TestOcclusion:
    def test_nearer_wins_whatever_the_order(self):
        prims, seg2world = overlapping_scene()
        camera = pinhole(eye=(0.5, -2.0, 0.4))
        ref = render(camera, seg2world, prims)
        assert len(np.unique(ref.label)) == 4  # three segments and background
        for perm in list(itertools.permutations(range(len(prims))))[1::23]:
            perm = list(perm)
            shuffled = Primitives(prims.segment[perm], prims.kind[perm], prims.prim2seg[perm],
                                  prims.size[perm], prims.taper[perm])
            res = render(camera, seg2world, shuffled)
            np.testing.assert_array_equal(res.label, ref.label)
            np.testing.assert_array_equal(res.depth, ref.depth)
            fg = ref.label >= 0
            np.testing.assert_array_equal(np.asarray(perm)[res.prim[fg]], ref.prim[fg])
            np.testing.assert_allclose(res.normal[fg], ref.normal[fg], atol=1e-6)

    def test_z_buffer_is_the_minimum_of_single_renders(self):
        prims, seg2world = overlapping_scene()
        camera = pinhole(eye=(-0.8, -1.8, -0.3))
        alone = []
        for j in range(len(prims)):
            one = Primitives(*(getattr(prims, n)[j:j + 1]
                               for n in ("segment", "kind", "prim2seg", "size", "taper")))
            alone.append(render(camera, seg2world, one, want=()).depth)
        alone = np.stack(alone)
        res = render(camera, seg2world, prims, want=())
        np.testing.assert_array_equal(res.depth, alone.min(axis=0))
        fg = np.isfinite(res.depth)
        np.testing.assert_array_equal(res.prim[fg], alone.argmin(axis=0)[fg])
        np.testing.assert_array_equal(res.label[fg], prims.segment[res.prim[fg]])
        # some pixels really are contested
        assert (np.isfinite(alone).sum(axis=0) >= 2).sum() > 1000

    def test_surface_codes_follow_the_winner(self):
        """An ellipsoid drawn over a cylinder's cap takes the pixel's surface code back to the
        curved side: its normals are its own, not the cap's."""
        prims = Primitives.concat([
            cylinder(0, (0.0, 0.0, -0.3), (0.0, 0.0, 0.1), 0.2),
            ellipsoid(1, (0.05, -0.05, 0.12), 0.12),
            ellipsoid(2, (-0.1, -0.3, -0.1), 0.06)])
        seg2world = np.stack([np.eye(4)] * 3)
        camera = pinhole(eye=(0.3, -1.5, 1.2))
        res = render(camera, seg2world, prims)
        fg = res.label >= 0
        for j in range(len(prims)):
            one = Primitives(*(getattr(prims, n)[j:j + 1]
                               for n in ("segment", "kind", "prim2seg", "size", "taper")))
            alone = render(camera, seg2world, one)
            won = res.prim == j
            assert won.sum() > 100
            np.testing.assert_allclose(res.normal[won], alone.normal[won], atol=1e-6)
        # the cap is seen, and partly covered by the sphere drawn after it
        cap = fg & (res.prim == 0) & (np.abs(res.normal[..., 2] - 1.0) < 1e-6)
        assert cap.sum() > 100

    def test_behind_and_straddling_the_camera(self):
        camera = pinhole(eye=(0.0, -2.0, 0.0))
        prims = Primitives.concat([
            ellipsoid(0, (0.0, -3.0, 0.0), 0.3),                  # behind the camera
            cylinder(1, (0.3, -3.0, 0.0), (0.3, 1.0, 0.0), 0.1),  # passes beside the camera
            ellipsoid(2, (-0.3, -2.0, 0.0), (0.1, 1.5, 0.1)),     # half behind, half in front
        ])
        res = render(camera, np.stack([np.eye(4)] * 3), prims)
        assert not np.any(res.label == 0)
        assert res.mask(1).sum() > 1000 and res.mask(2).sum() > 1000
        assert np.all(res.depth[res.label >= 0] > 0)
        X = res.point[res.mask(1)].astype(float)
        np.testing.assert_allclose(np.hypot(X[:, 0] - 0.3, X[:, 2]), 0.1, atol=SURFACE_TOL)
        X = res.point[res.mask(2)].astype(float)
        q = (X - (-0.3, -2.0, 0.0)) / (0.1, 1.5, 0.1)
        np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-3)

    def test_camera_inside_a_tube(self):
        # Looking down a tube from inside: the far cap ahead, the wall all around, nothing
        # from the near cap behind the camera.
        camera = pinhole(eye=(0.0, 0.0, 0.0), target=(0.0, 1.0, 0.0), f=150.0)
        tube = cylinder(0, (0.0, -0.5, 0.0), (0.0, 2.0, 0.0), 0.6, 0.4)
        res = render(camera, ONE_SEGMENT, tube)
        assert np.all(res.label == 0)
        X = res.point.reshape(-1, 3).astype(float)
        N = res.normal.reshape(-1, 3)
        far_cap = np.abs(X[:, 1] - 2.0) < SURFACE_TOL
        assert 1000 < far_cap.sum() < X.shape[0] - 1000
        np.testing.assert_allclose(N[far_cap], np.tile((0.0, -1.0, 0.0), (far_cap.sum(), 1)),
                                   atol=1e-6)
        wall = ~far_cap
        radius = 0.6 - 0.2 * (X[wall, 1] + 0.5) / 2.5
        np.testing.assert_allclose(np.hypot(X[wall, 0], X[wall, 2]), radius, atol=SURFACE_TOL)
        assert np.all(X[:, 1] > 0)
        # inward normals, facing the camera
        assert np.all(np.einsum("ij,ij->i", N, X) < 0)


class TestSegmentMotion:
    def test_seg2world_composes_with_prim2seg(self, rng):
        prims, _ = overlapping_scene()
        seg2world = np.stack([np.eye(4)] * 3)
        for s in range(3):
            seg2world[s, :3, :3] = Rotation.random(random_state=rng).as_matrix()
            seg2world[s, :3, 3] = rng.normal(scale=0.05, size=3)
        camera = pinhole(eye=(0.3, -2.2, 0.5))
        moved = render(camera, seg2world, prims)
        # the same primitives placed directly in the world
        baked = Primitives(prims.segment, prims.kind,
                           seg2world[prims.segment] @ prims.prim2seg, prims.size, prims.taper)
        direct = render(camera, np.stack([np.eye(4)] * 3), baked)
        differ = moved.label != direct.label
        assert differ.sum() <= 5 and not np.any(differ & ~boundary_band(direct.label >= 0))
        same = ~differ & (moved.label >= 0)
        np.testing.assert_allclose(moved.depth[same], direct.depth[same], rtol=1e-5)

    def test_orthographic_shift_is_exact(self):
        camera = ScaledOrthoCamera("o", (160, 120), 200.0, R=look_at((0, -1, 0), (0, 0, 0))[0])
        prims, seg2world = overlapping_scene()
        ref = render(camera, seg2world, prims, want=())
        # 7 pixels right and 4 down: camera x and y in the world, over the scale
        shift = (7 * camera.R[0] + 4 * camera.R[1]) / camera.s
        moved = seg2world @ translation(shift)
        res = render(camera, moved, prims, want=())
        np.testing.assert_array_equal(res.label[4:, 7:], ref.label[:-4, :-7])
        np.testing.assert_allclose(res.depth[4:, 7:], ref.depth[:-4, :-7], atol=1e-6)

    def test_perspective_silhouette_follows_the_projection(self):
        camera = pinhole(eye=(0.0, -3.0, 0.0))
        prims = ellipsoid(0, (0, 0, 0), 0.1)
        centre = np.array([0.2, 0.0, 0.1])
        shifts = [np.zeros(3), np.array([0.15, 0.1, -0.2])]
        for step in shifts:
            T = translation(centre + step)
            m = render(camera, T[None], prims, want=()).mask(0)
            v, u = np.nonzero(m)
            expected = camera.project(centre + step)
            # a small off-axis sphere projects to an ellipse centred near its centre's image
            np.testing.assert_allclose((u.mean(), v.mean()), expected, atol=0.3)


# ---------------------------------------------------------------------------------------------
# Sparse rendering, sub-windows and cameras
# ---------------------------------------------------------------------------------------------

class TestRenderPoints:
    def test_equals_render_at_pixel_centres(self, rng):
        prims, seg2world = overlapping_scene()
        camera = pinhole(eye=(0.5, -2.0, 0.4))
        full = render(camera, seg2world, prims)
        uv = np.stack([rng.integers(90, 230, 3000), rng.integers(50, 190, 3000)], axis=1)
        res = render_points(camera, seg2world, prims, uv.astype(float))
        u, v = uv.T
        assert res.label.shape == (3000,) and res.point.shape == (3000, 3)
        np.testing.assert_array_equal(res.label, full.label[v, u])
        np.testing.assert_array_equal(res.prim, full.prim[v, u])
        np.testing.assert_allclose(res.depth, full.depth[v, u], rtol=1e-6)
        np.testing.assert_allclose(res.point, full.point[v, u], atol=1e-6)
        np.testing.assert_allclose(res.normal, full.normal[v, u], atol=1e-6)
        assert (res.label >= 0).sum() > 600

    @pytest.mark.parametrize("lens", ["plain", "distorted", "orthographic"])
    def test_surface_points_equal_the_point_image(self, rng, lens):
        prims, seg2world = overlapping_scene()
        if lens == "orthographic":
            R, t = look_at((0.5, -2.0, 0.4), (0.0, 0.0, 0.0))
            camera = ScaledOrthoCamera("o", (320, 240), 250.0, R=R, t=t)
        else:
            camera = pinhole(eye=(0.5, -2.0, 0.4),
                             dist=(-0.2, 0.05, 0.001, -0.002, 0.0) if lens == "distorted"
                             else None)
        full = render(camera, seg2world, prims, want=("point",))
        bare = render(camera, seg2world, prims, want=())
        np.testing.assert_array_equal(bare.depth, full.depth)
        vv, uu = np.nonzero(full.label >= 0)
        pick = rng.permutation(len(vv))[:2000]
        points = surface_points(camera, bare.depth, vv[pick], uu[pick])
        assert points.dtype == np.float32 and points.shape == (len(pick), 3)
        assert len(pick) > 500
        np.testing.assert_array_equal(points, full.point[vv[pick], uu[pick]])
        assert surface_points(camera, bare.depth, vv[:0], uu[:0]).shape == (0, 3)

    def test_subpixel_points_lie_on_their_rays(self, rng):
        camera = pinhole(eye=(0.0, -2.0, 0.0), dist=(-0.2, 0.05, 0.001, -0.002, 0.0))
        uv = rng.uniform((130, 90), (190, 150), size=(500, 2))
        res = render_points(camera, ONE_SEGMENT, ellipsoid(0, (0, 0, 0), 0.3), uv)
        assert np.all(res.label == 0)
        np.testing.assert_allclose(camera.project(res.point.astype(float)), uv, atol=1e-3)
        np.testing.assert_allclose(np.linalg.norm(res.point, axis=1), 0.3, atol=SURFACE_TOL)

    def test_empty(self):
        res = render_points(pinhole(), ONE_SEGMENT, ellipsoid(0, (0, 0, 0), 0.3),
                            np.zeros((0, 2)))
        assert res.label.shape == (0,) and res.point.shape == (0, 3)


class TestWindowAndCameras:
    def test_bbox_restricts(self):
        prims, seg2world = overlapping_scene()
        camera = pinhole(eye=(0.5, -2.0, 0.4))
        full = render(camera, seg2world, prims)
        res = render(camera, seg2world, prims, bbox=(120, 80, 200, 150))
        inner = (slice(80, 150), slice(120, 200))
        np.testing.assert_array_equal(res.label[inner], full.label[inner])
        np.testing.assert_array_equal(res.depth[inner], full.depth[inner])
        np.testing.assert_array_equal(res.normal[inner], full.normal[inner])
        outside = np.ones(full.label.shape, bool)
        outside[inner] = False
        assert np.all(res.label[outside] == -1) and np.all(np.isinf(res.depth[outside]))
        assert (full.label[outside] >= 0).sum() > 1000
        # a window off the image is all background, not an error
        assert np.all(render(camera, seg2world, prims, bbox=(400, 0, 500, 10)).label == -1)

    def test_orthographic_sphere(self):
        # t = 0 puts the plane z_cam = 0 through the sphere: the whole line of sight counts.
        R, _ = look_at((0.3, -1.0, 0.2), (0, 0, 0))
        camera = ScaledOrthoCamera("o", (160, 120), 300.0, R=R, c=(80.0, 60.0))
        r = 0.1
        res = render(camera, ONE_SEGMENT, ellipsoid(0, (0, 0, 0), r))
        m = res.mask(0)
        assert m.sum() == pytest.approx(np.pi * (camera.s * r) ** 2, rel=0.005)
        assert res.depth[60, 80] == pytest.approx(-r, abs=1e-6)
        X = res.point[m].astype(float)
        np.testing.assert_allclose(np.linalg.norm(X, axis=1), r, atol=SURFACE_TOL)
        np.testing.assert_allclose(res.normal[m], X / r, atol=1e-3)
        assert np.all(res.normal[m] @ camera.forward < 1e-3)
        np.testing.assert_allclose(camera.depth(X), res.depth[m], atol=1e-6)

    def test_parallel_rays_from_other_origins(self):
        # The same lines of sight from origins moved along them: the same images.
        R, _ = look_at((0.3, -1.0, 0.2), (0, 0, 0))
        camera = ScaledOrthoCamera("o", (160, 120), 300.0, R=R, t=(0.02, -0.01, 1.5))
        prims, seg2world = overlapping_scene()
        ref = render(camera, seg2world, prims)

        class MovedOrigins:
            image_size, R, t = camera.image_size, camera.R, camera.t
            project, cam_from_world = camera.project, camera.cam_from_world
            origins, dirs = camera.pixel_rays()
            shift = np.linspace(-2.0, 3.0, 160)[None, :, None] * dirs
            rays_ = (origins + shift, dirs)

            def pixel_rays(self):
                return self.rays_

        res = render(MovedOrigins(), seg2world, prims)
        np.testing.assert_array_equal(res.label, ref.label)
        fg = ref.label >= 0
        np.testing.assert_allclose(res.depth[fg], ref.depth[fg], atol=SURFACE_TOL)
        np.testing.assert_allclose(res.point[fg], ref.point[fg], atol=SURFACE_TOL)
        assert ref.depth[fg].min() > 1.0  # t_z shifts the depths

    def test_orthographic_render_points(self, rng):
        R, _ = look_at((0.3, -1.0, 0.2), (0, 0, 0))
        camera = ScaledOrthoCamera("o", (160, 120), 300.0, R=R)
        prims, seg2world = overlapping_scene()
        full = render(camera, seg2world, prims)
        uv = np.stack([rng.integers(0, 160, 1000), rng.integers(0, 120, 1000)], axis=1)
        res = render_points(camera, seg2world, prims, uv.astype(float))
        np.testing.assert_array_equal(res.label, full.label[uv[:, 1], uv[:, 0]])
        np.testing.assert_allclose(res.depth, full.depth[uv[:, 1], uv[:, 0]], atol=1e-6)

    def test_lens_distortion(self):
        # Strong barrel distortion, the sphere near a corner where it bends the most.
        camera = pinhole(eye=(0.0, -2.0, 0.0), dist=(-0.3, 0.08, 0.0, 0.0, 0.0))
        centre = np.array([0.75, 0.0, -0.5])
        res = render(camera, ONE_SEGMENT, ellipsoid(0, centre, 0.2))
        m = res.mask(0)
        v, u = np.nonzero(m)
        X = res.point[m].astype(float)
        np.testing.assert_allclose(camera.project(X), np.stack([u, v], axis=1), atol=1e-3)
        np.testing.assert_allclose(np.linalg.norm(X - centre, axis=1), 0.2, atol=SURFACE_TOL)

        def inside(P):
            return np.linalg.norm(P - centre, axis=1) <= 0.2

        assert_matches_march(res, camera, inside, 1.5, 2.6)

    def test_no_primitives(self):
        res = render(pinhole(), ONE_SEGMENT, Primitives.concat([]))
        assert np.all(res.label == -1) and np.all(np.isnan(res.point))


class TestBadInput:
    @pytest.fixture
    def setup(self):
        return pinhole(), ellipsoid(1, (0, 0, 0), 0.2)

    def test_seg2world(self, setup):
        camera, prims = setup
        with pytest.raises(ZoopraxisError, match=r"shape \(S, 4, 4\)"):
            render(camera, np.eye(4), prims)
        with pytest.raises(ZoopraxisError, match="label 1"):
            render(camera, ONE_SEGMENT, prims)
        bad = np.stack([np.eye(4)] * 2)
        bad[1, 0, 0] = np.nan
        with pytest.raises(ZoopraxisError, match=r"seg2world\[1\]"):
            render(camera, bad, prims)
        bad[1] = 0.0
        bad[1, 3, 3] = 1.0
        with pytest.raises(ZoopraxisError, match="singular"):
            render(camera, bad, prims)

    def test_options(self, setup):
        camera, prims = setup
        seg2world = np.stack([np.eye(4)] * 2)
        with pytest.raises(ZoopraxisError, match="want"):
            render(camera, seg2world, prims, want=("points",))
        with pytest.raises(ZoopraxisError, match="bbox"):
            render(camera, seg2world, prims, bbox=(10, 10, 5, 20))
        with pytest.raises(ZoopraxisError, match="bbox"):
            render(camera, seg2world, prims, bbox=(10, 10))
        with pytest.raises(ZoopraxisError, match="Primitives"):
            render(camera, seg2world, [prims])
        with pytest.raises(ZoopraxisError, match="camera has no"):
            render(object(), seg2world, prims)
        with pytest.raises(ZoopraxisError, match=r"uv must have shape \(N, 2\)"):
            render_points(camera, seg2world, prims, np.zeros((4, 3)))
        with pytest.raises(ZoopraxisError, match="non-finite"):
            render_points(camera, seg2world, prims, [[1.0, np.nan]])
