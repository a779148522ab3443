"""Tests of core.geometry.camera: the pinhole camera, what both camera models share (through
both), look_at and ring_of_cameras. The scaled orthographic camera alone is in test_ortho."""

import dataclasses

import cv2
import numpy as np
import pytest

from zoopraxis.core.geometry import camera, lens
from zoopraxis.core.geometry.camera import PinholeCamera, look_at, ring_of_cameras
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files.calibfile import camera_from_dict

# Realistic lens: barrel distortion of a wide consumer lens, slight decentring.
LENS = [-0.2, 0.05, 1e-3, 1e-3, 0.0]
# Unequal tangential terms and a k3, to tell p1 from p2 and exercise every coefficient.
LENS_ASYMMETRIC = [-0.25, 0.08, 2e-3, -1e-3, -0.01]
TARGET = np.array([0.3, -0.2, 1.0])


def make_pinhole(dist=None, image_size=(160, 120), focal=150.0):
    R, t = look_at([4.0, -3.0, 1.8], TARGET)
    w, h = image_size
    K = [[focal, 0.0, (w - 1) / 2 + 1.5], [0.0, focal * 1.02, (h - 1) / 2 - 2.0], [0, 0, 1]]
    return PinholeCamera("cam0", image_size, K, dist, R, t)


def make_ortho(image_size=(160, 120), kappa=0.0):
    R, t = look_at([4.0, -3.0, 1.8], TARGET)
    return ScaledOrthoCamera("side", image_size, 60.0, R, t, c=(81.0, 57.5), kappa=kappa)


CAMERAS = {
    "pinhole": lambda: make_pinhole(),
    "pinhole_distorted": lambda: make_pinhole(LENS),
    "pinhole_asymmetric_lens": lambda: make_pinhole(LENS_ASYMMETRIC),
    "ortho": lambda: make_ortho(),
    "ortho_near": lambda: make_ortho(kappa=0.12),
}


def points_in_view(rng, n=20):
    """World points around the target, inside the view of the test cameras."""
    return TARGET + rng.uniform(-0.6, 0.6, size=(n, 3))


@pytest.fixture(params=list(CAMERAS))
def any_camera(request):
    return CAMERAS[request.param]()


# --- smoke ----------------------------------------------------------------------------------------

def test_pinhole_defaults_and_padding():
    cam = PinholeCamera("a", (64, 48), np.diag([50.0, 50.0, 1.0]), dist=[0.1, 0, 0, 0])
    assert cam.image_size == (64, 48) and isinstance(cam.image_size[0], int)
    np.testing.assert_array_equal(cam.dist, [0.1, 0, 0, 0, 0])
    np.testing.assert_array_equal(cam.R, np.eye(3))
    np.testing.assert_array_equal(cam.t, np.zeros(3))
    assert "a" in repr(cam)


def test_cameras_are_immutable(any_camera):
    with pytest.raises(dataclasses.FrozenInstanceError):
        any_camera.t = np.zeros(3)
    with pytest.raises(ValueError, match="read-only"):
        any_camera.R[0, 0] = 2.0


def test_replace_checks_again_and_does_not_share_the_ray_cache():
    cam = make_pinhole(LENS)
    _, dirs = cam.pixel_rays()
    turned = cam.replace(R=cam.R @ cv2.Rodrigues(np.array([0.0, 0.0, 0.3]))[0])
    assert not np.allclose(turned.pixel_rays()[1], dirs)
    with pytest.raises(ZoopraxisError, match="camera 'cam0': R is not a rotation"):
        cam.replace(R=2 * np.eye(3))


def test_rotation_is_snapped_to_the_nearest_rotation():
    R, t = look_at([3.0, 1.0, 2.0], [0, 0, 1])
    cam = PinholeCamera("c", (64, 48), np.diag([50.0, 50.0, 1.0]), R=np.round(R, 5), t=t)
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(cam.R, R, atol=1e-5)


# --- bad input ------------------------------------------------------------------------------------

K_OK = [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]]


@pytest.mark.parametrize("changes, message", [
    ({"R": 2 * np.eye(3)}, r"camera 'cam0': R is not a rotation matrix"),
    ({"R": np.diag([1.0, 1.0, -1.0])}, r"camera 'cam0': R is a reflection"),
    ({"R": np.eye(2)}, r"camera 'cam0': R must have shape \(3, 3\), got shape \(2, 2\)"),
    ({"R": [[1, 0, 0], [0, 1], [0, 0, 1]]}, r"camera 'cam0': R must be numbers"),
    ({"K": [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 2]]}, r"K must be upper triangular"),
    ({"K": [[100.0, 0, 50], [3, 100.0, 40], [0, 0, 1]]}, r"K must be upper triangular"),
    ({"K": [[-100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]]}, r"K must have positive focal lengths"),
    ({"K": np.eye(4)}, r"camera 'cam0': K must have shape \(3, 3\)"),
    ({"dist": [0.1, 0.0, 0.0]}, r"dist must have 4 or 5 coefficients .*got 3 values"),
    ({"dist": np.zeros(8)}, r"dist must have 4 or 5 coefficients .*got 8 values"),
    ({"dist": np.zeros((5, 1))}, r"dist must have 4 or 5 coefficients"),
    ({"image_size": (0, 48)}, r"camera 'cam0': image_size must be two positive whole numbers"),
    ({"image_size": (64.5, 48)}, r"image_size must be two positive whole numbers"),
    ({"image_size": (64, 48, 3)}, r"image_size must have shape \(2,\)"),
    ({"t": [0.0, np.nan, 1.0]}, r"camera 'cam0': t contains NaN or infinity"),
    ({"name": ""}, r"camera name must be a non-empty string"),
])
def test_pinhole_bad_input(changes, message):
    fields = {"name": "cam0", "image_size": (64, 48), "K": K_OK, **changes}
    with pytest.raises(ZoopraxisError, match=message):
        PinholeCamera(**fields)


def test_points_of_wrong_shape_are_refused(any_camera):
    with pytest.raises(ZoopraxisError, match=r"points must have shape \(\.\.\., 3\)"):
        any_camera.project(np.zeros((4, 2)))
    with pytest.raises(ZoopraxisError, match=r"pixels must have shape \(\.\.\., 2\)"):
        any_camera.undistort_points(np.zeros((4, 3)))


@pytest.mark.parametrize("factor, sampling, message", [
    (0.0, "pyramid", "scale factor must be positive"),
    (-0.5, "pyramid", "scale factor must be positive"),
    (0.5, "nearest", "sampling must be one of pyramid, resize"),
])
def test_scaled_bad_input(any_camera, factor, sampling, message):
    with pytest.raises(ZoopraxisError, match=message):
        any_camera.scaled(factor, sampling)


def test_look_at_bad_input():
    with pytest.raises(ZoopraxisError, match="look_at: eye and target are the same point"):
        look_at([1, 2, 3], [1, 2, 3])
    with pytest.raises(ZoopraxisError, match="look_at: the viewing direction is parallel to up"):
        look_at([0, 0, 5], [0, 0, 1])
    with pytest.raises(ZoopraxisError, match=r"look_at: eye must have shape \(3,\)"):
        look_at([0, 5], [0, 0, 1])


@pytest.mark.parametrize("kwargs, message", [
    ({"n": 0}, "n must be a positive whole number"),
    ({"n": 2.5}, "n must be a positive whole number"),
    ({"radius": 0.0}, "radius must be positive"),
    ({"focal_px": -1.0}, "focal_px must be positive"),
    ({"image_size": (640, 0)}, "ring_of_cameras: image_size must be two positive"),
])
def test_ring_of_cameras_bad_input(kwargs, message):
    args = {"n": 3, "radius": 4.0, "height": 1.5, "target": [0, 0, 1], "image_size": (64, 48),
            "focal_px": 60.0, **kwargs}
    with pytest.raises(ZoopraxisError, match=message):
        ring_of_cameras(**args)


# --- shapes ---------------------------------------------------------------------------------------

def test_shapes_keep_leading_dimensions(any_camera, rng):
    X = points_in_view(rng, 12).reshape(3, 4, 3)
    assert any_camera.cam_from_world(X).shape == (3, 4, 3)
    assert any_camera.project(X).shape == (3, 4, 2)
    assert any_camera.project(X[0, 0]).shape == (2,)
    assert any_camera.depth(X).shape == (3, 4)
    uv, J = any_camera.project_jacobian(X)
    assert uv.shape == (3, 4, 2) and J.shape == (3, 4, 2, 3)
    assert any_camera.undistort_points(uv).shape == (3, 4, 2)
    assert any_camera.unproject(uv, 2.0).shape == (3, 4, 3)


def test_pixel_rays_shapes_and_cache(any_camera):
    w, h = any_camera.image_size
    origins, dirs = any_camera.pixel_rays()
    assert dirs.shape == (h, w, 3) and dirs.dtype == np.float64
    expected_origins = (3,) if any_camera.center is not None else (h, w, 3)
    assert origins.shape == expected_origins
    assert any_camera.pixel_rays()[1] is dirs
    assert not dirs.flags.writeable
    np.testing.assert_allclose(np.linalg.norm(dirs, axis=-1), 1.0, atol=1e-12)


# --- numerical correctness ------------------------------------------------------------------------

def rotation_z90():
    return np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_pinhole_projection_by_hand():
    # R X + t = (-1, 0.5, 2) + (0.1, 0.2, 2) = (-0.9, 0.7, 4): x = -0.225, y = 0.175.
    K = [[100.0, 0.0, 50.0], [0.0, 200.0, 40.0], [0.0, 0.0, 1.0]]
    cam = PinholeCamera("h", (101, 81), K, R=rotation_z90(), t=[0.1, 0.2, 2.0])
    X = [0.5, 1.0, 2.0]
    np.testing.assert_allclose(cam.project(X), [27.5, 75.0], atol=1e-12)
    assert cam.depth(X) == pytest.approx(4.0)
    # k1 = 0.1: r^2 = 0.08125, radial factor 1.008125.
    distorted = cam.replace(dist=[0.1, 0, 0, 0, 0])
    np.testing.assert_allclose(distorted.project(X), [27.3171875, 75.284375], atol=1e-12)
    np.testing.assert_allclose(cam.center, -rotation_z90().T @ [0.1, 0.2, 2.0])
    np.testing.assert_allclose(cam.forward, [0.0, 0.0, 1.0])


@pytest.mark.parametrize("dist", [LENS, LENS_ASYMMETRIC])
def test_pinhole_projection_matches_opencv(dist, rng):
    cam = make_pinhole(dist)
    X = points_in_view(rng)
    rvec = cv2.Rodrigues(cam.R)[0]
    expected = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)[0][:, 0]
    np.testing.assert_allclose(cam.project(X), expected, atol=1e-9)


def test_project_jacobian_matches_finite_differences(any_camera, rng):
    X = points_in_view(rng)
    uv, J = any_camera.project_jacobian(X)
    np.testing.assert_allclose(uv, any_camera.project(X), atol=1e-12)
    h = 1e-6
    J_numeric = np.stack([(any_camera.project(X + h * e) - any_camera.project(X - h * e)) / (2 * h)
                          for e in np.eye(3)], axis=-1)
    np.testing.assert_allclose(J, J_numeric, rtol=1e-6, atol=1e-6 * np.abs(J).max())


def test_undistort_and_distort_are_inverse():
    cam = make_pinhole(LENS)
    w, h = cam.image_size
    grid = camera._pixel_grid((w, h))[::7, ::9]
    ideal = cam.undistort_points(grid)
    np.testing.assert_allclose(cam.distort_points(ideal), grid, atol=1e-9)
    # Barrel distortion pulls the corners inward, so undistorting pushes them out.
    corner = cam.undistort_points([0.0, 0.0])
    assert np.all(corner < 0.0)
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    expected = cv2.undistortPointsIter(grid.reshape(-1, 1, 2), cam.K, cam.dist, None, cam.K,
                                       criteria)
    np.testing.assert_allclose(ideal.reshape(-1, 2), expected[:, 0], atol=1e-6)


def test_undistort_points_gives_the_ideal_pinhole_image(rng):
    cam = make_pinhole(LENS)
    X = points_in_view(rng)
    ideal = cam.replace(dist=None).project(X)
    np.testing.assert_allclose(cam.undistort_points(cam.project(X)), ideal, atol=1e-9)


def test_undistort_marks_pixels_past_the_fold_of_the_lens():
    # With k1 = -0.5 the radial map r (1 - 0.5 r^2) turns back at r = 0.816 (r_d = 0.544):
    # distorted radii beyond that are seen by no ray.
    cam = PinholeCamera("f", (200, 200), [[100.0, 0, 99.5], [0, 100.0, 99.5], [0, 0, 1]],
                        dist=[-0.5, 0, 0, 0, 0])
    ideal = cam.undistort_points([[99.5 + 50.0, 99.5], [99.5 + 60.0, 99.5]])
    assert np.all(np.isfinite(ideal[0])) and np.all(np.isnan(ideal[1]))


def test_points_along_pixel_rays_project_back_to_their_pixel(any_camera, rng):
    w, h = any_camera.image_size
    origins, dirs = any_camera.pixel_rays()
    grid = camera._pixel_grid((w, h))
    origins = np.broadcast_to(origins, dirs.shape)
    distance = rng.uniform(2.0, 8.0, size=(h, w, 1))
    np.testing.assert_allclose(any_camera.project(origins + distance * dirs), grid, atol=1e-8)
    if any_camera.model == "scaled_orthographic" and not any_camera.kappa:
        # Parallel rays: behind the origin plane too.
        np.testing.assert_allclose(any_camera.project(origins - distance * dirs), grid, atol=1e-8)


def test_pinhole_rays_leave_the_centre_and_ortho_rays_are_parallel():
    pinhole, ortho = make_pinhole(LENS), make_ortho()
    origins, dirs = pinhole.pixel_rays()
    np.testing.assert_allclose(origins, pinhole.center, atol=1e-12)
    assert np.all(pinhole.depth(origins + dirs) > 0)
    origins, dirs = ortho.pixel_rays()
    np.testing.assert_allclose(dirs, np.broadcast_to(ortho.forward, dirs.shape), atol=1e-15)
    np.testing.assert_allclose(ortho.depth(origins), 0.0, atol=1e-12)


def test_unproject_inverts_project(any_camera, rng):
    X = points_in_view(rng)
    np.testing.assert_allclose(any_camera.unproject(any_camera.project(X), any_camera.depth(X)),
                               X, atol=1e-9)


def render_dot(cam, X, sigma=2.0):
    """A float image of a Gaussian dot centred on the projection of X."""
    u0, v0 = cam.project(X)
    w, h = cam.image_size
    v, u = np.mgrid[0:h, 0:w]
    return np.exp(-((u - u0) ** 2 + (v - v0) ** 2) / (2 * sigma ** 2))


def centroid(image):
    v, u = np.mgrid[0:image.shape[0], 0:image.shape[1]]
    return np.array([(image * u).sum(), (image * v).sum()]) / image.sum()


@pytest.mark.parametrize("levels", [1, 2])
@pytest.mark.parametrize("image_size", [(161, 121), (160, 120)])
def test_scaled_agrees_with_pyrdown(image_size, levels, rng):
    for cam in (make_pinhole(LENS, image_size), make_ortho(image_size)):
        X = TARGET + rng.uniform(-0.3, 0.3, size=3)
        image = render_dot(cam, X)
        for _ in range(levels):
            image = cv2.pyrDown(image)
        small = cam.scaled(0.5 ** levels)
        assert small.image_size == (image.shape[1], image.shape[0])
        np.testing.assert_allclose(centroid(image), small.project(X), atol=0.05)


def test_scaled_resize_agrees_with_cv2_resize(rng):
    for cam in (make_pinhole(LENS), make_ortho()):
        X = TARGET + rng.uniform(-0.3, 0.3, size=3)
        image = cv2.resize(render_dot(cam, X), None, fx=0.5, fy=0.5,
                           interpolation=cv2.INTER_LINEAR)
        small = cam.scaled(0.5, sampling="resize")
        assert small.image_size == (image.shape[1], image.shape[0])
        np.testing.assert_allclose(centroid(image), small.project(X), atol=0.05)


def test_scaled_up_and_down_is_the_same_camera(any_camera, rng):
    X = points_in_view(rng)
    back = any_camera.scaled(0.25).scaled(4.0)
    np.testing.assert_allclose(back.project(X), any_camera.project(X), atol=1e-9)


@pytest.mark.parametrize("eye", [[4.0, -3.0, 1.8], [-2.0, 0.5, 0.2], [0.1, 6.0, 4.0]])
def test_look_at_centres_the_target_with_up_upward(eye):
    R, t = look_at(eye, TARGET)
    K = [[500.0, 0.0, 319.5], [0.0, 500.0, 239.5], [0.0, 0.0, 1.0]]
    cam = PinholeCamera("c", (640, 480), K, R=R, t=t)
    np.testing.assert_allclose(cam.project(TARGET), [319.5, 239.5], atol=1e-9)
    np.testing.assert_allclose(cam.center, eye, atol=1e-12)
    np.testing.assert_allclose(cam.forward, (TARGET - eye) / np.linalg.norm(TARGET - eye))
    above = cam.project(TARGET + [0.0, 0.0, 0.1])
    assert above[1] < 239.5 and abs(above[0] - 319.5) < 1e-9
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_ring_of_cameras_surrounds_the_target():
    target = np.array([0.5, -1.0, 1.0])
    cams = ring_of_cameras(4, 5.0, 1.5, target, (64, 48), 60.0, start_angle=np.pi / 2)
    assert [c.name for c in cams] == ["cam0", "cam1", "cam2", "cam3"]
    centers = np.array([c.center for c in cams])
    np.testing.assert_allclose(centers[:, 2], 1.5)
    np.testing.assert_allclose(np.linalg.norm(centers[:, :2] - target[:2], axis=1), 5.0)
    np.testing.assert_allclose(centers[0], [0.5, 4.0, 1.5], atol=1e-12)
    np.testing.assert_allclose(centers[1], [-4.5, -1.0, 1.5], atol=1e-12)
    for cam in cams:
        np.testing.assert_allclose(cam.project(target), [31.5, 23.5], atol=1e-9)
        np.testing.assert_array_equal(cam.dist, np.zeros(5))


def test_dict_round_trip(any_camera, rng):
    entry = any_camera.to_dict()
    assert ("model" in entry) == (any_camera.model != "pinhole")
    back = camera_from_dict(entry)
    assert type(back) is type(any_camera) and back.name == any_camera.name
    assert back.image_size == any_camera.image_size
    X = points_in_view(rng)
    np.testing.assert_array_equal(back.project(X), any_camera.project(X))


def test_pinhole_dict_is_designs_format():
    entry = make_pinhole(LENS).to_dict()
    assert set(entry) == {"name", "image_size", "K", "dist", "R", "t"}
    assert entry["dist"] == LENS and len(entry["K"]) == 3


@pytest.mark.parametrize("dist", [None, [0.0, -0.0, 0.0, 0.0, 0.0]])
def test_projection_without_distortion_equals_the_full_model(dist, rng):
    """Zero coefficients skip the distortion polynomial: the pixels are the model's to the
    bit, signs of zero and the non-finite pixels of points on the camera plane included."""
    cam = make_pinhole(dist)
    X_cam = np.concatenate([rng.normal(0, 1, (200, 3)) + [0, 0, 3],
                            [[0.0, 0.0, 2.0], [-0.0, 0.5, 1.0], [0.5, -0.0, 1.0],
                             [1.0, 1.0, 0.0], [0.0, 0.0, 0.0], [1e160, 1.0, 1.0],
                             [1.0, -1.0, -2.0]]])
    X = cam.world_from_cam(X_cam)
    X_cam = cam.cam_from_world(X)
    with np.errstate(all="ignore"):
        xy = X_cam[:, :2] / X_cam[:, 2:]
        x_d, y_d = lens.distort_xy(xy[:, 0], xy[:, 1], cam.dist)
        expected = cam._pixels_from_normalized(np.stack([x_d, y_d], axis=-1))
        uv = cam.project(X)
    assert np.array_equal(np.isnan(uv), np.isnan(expected))
    assert np.isfinite(uv).sum() >= 400
    ok = ~np.isnan(expected)
    assert np.array_equal(uv[ok].view(np.int64), expected[ok].view(np.int64))
    # the normalised coordinates themselves, signed zeros and non-finite ones included
    xy = np.concatenate([xy, [[np.inf, 0.0], [0.0, -np.inf], [np.nan, 1.0], [1e200, 1.0],
                              [-0.0, -0.0], [-0.0, 2.0]]])
    with np.errstate(all="ignore"):
        x_d, y_d = lens.distort_xy(xy[:, 0], xy[:, 1], cam.dist)
        plain = lens.distort(xy, cam.dist)
    both = np.stack([x_d, y_d], axis=-1)
    fin = ~np.isnan(both)
    assert np.array_equal(np.isnan(plain), ~fin)
    assert np.array_equal(plain[fin].view(np.int64), both[fin].view(np.int64))
    # finite coordinates alone (the shortcut, when the coefficients are all +0)
    finite = np.all(np.abs(xy) < 1e100, axis=1)
    assert np.array_equal(lens.distort(xy[finite], cam.dist).view(np.int64),
                          both[finite].view(np.int64))
    assert (xy[finite] == 0).any() and np.signbit(xy[finite][xy[finite] == 0]).any()


@pytest.mark.parametrize("shape", [(5,), (50, 3), (4000,), (3, 900), (2, 3, 700)])
def test_large_point_sets_project_to_the_same_bits(shape, rng):
    """Many points go column by column through the rigid transform, the perspective divide and
    the intrinsics: the same sums and quotients as the broadcast expressions."""
    cam = make_pinhole()
    X = points_in_view(rng, int(np.prod(shape))).reshape(shape + (3,))
    X[..., 0, :] = cam.center + [0.1, 0.0, 0.0]          # on the camera plane: inf or nan
    X_cam = X @ cam.R.T + cam.t
    got_cam = cam.cam_from_world(X)
    assert got_cam.shape == X.shape
    assert np.array_equal(got_cam.view(np.int64), X_cam.view(np.int64))
    with np.errstate(all="ignore"):
        xy = X_cam[..., :2] / X_cam[..., 2:]
        uv = cam.project(X)
    expected = lens.distort(xy, cam.dist) @ cam.K[:2, :2].T + cam.K[:2, 2]
    assert uv.shape == shape + (2,)
    fin = ~np.isnan(expected)
    assert np.array_equal(np.isnan(uv), ~fin)
    assert np.array_equal(uv[fin].view(np.int64), expected[fin].view(np.int64))
    # a strided (non-contiguous) input
    Xs = np.concatenate([X, X], axis=-1)[..., ::2][..., :3]
    assert np.array_equal(cam.cam_from_world(Xs).view(np.int64),
                          (Xs @ cam.R.T + cam.t).view(np.int64))
