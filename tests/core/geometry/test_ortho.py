"""Tests of the scaled orthographic camera, alone and against the pinhole camera it becomes
with perspective; the behaviour both models share is tested in test_camera."""

import numpy as np
import pytest

from zoopraxis.core.geometry.camera import PinholeCamera, look_at
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.errors import ZoopraxisError

TARGET = np.array([0.3, -0.2, 1.0])


def make_ortho(image_size=(160, 120), kappa=0.0):
    R, t = look_at([4.0, -3.0, 1.8], TARGET)
    return ScaledOrthoCamera("side", image_size, 60.0, R, t, c=(81.0, 57.5), kappa=kappa)


def rotation_z90():
    return np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])


def test_ortho_default_principal_point_is_image_centre():
    cam = ScaledOrthoCamera("o", (101, 80), 10.0)
    np.testing.assert_array_equal(cam.c, [50.0, 39.5])
    assert cam.center is None


@pytest.mark.parametrize("changes, message", [
    ({"s": 0.0}, r"camera 'o': s \(pixels per metre\) must be positive"),
    ({"s": [1.0, 2.0]}, r"camera 'o': s must have shape \(\)"),
    ({"c": [1.0, 2.0, 3.0]}, r"camera 'o': c must have shape \(2,\)"),
    ({"R": np.ones((3, 3))}, r"camera 'o': R is not a rotation"),
    ({"kappa": -0.1}, r"camera 'o': kappa \(1 / distance in metres\) must be 0 or more"),
    ({"kappa": np.nan}, r"camera 'o': kappa contains NaN or infinity"),
])
def test_ortho_bad_input(changes, message):
    fields = {"name": "o", "image_size": (64, 48), "s": 10.0, **changes}
    with pytest.raises(ZoopraxisError, match=message):
        ScaledOrthoCamera(**fields)


def test_ortho_projection_by_hand():
    cam = ScaledOrthoCamera("o", (101, 81), 100.0, R=rotation_z90(), t=[0.1, 0.2, 3.0])
    # R X + t = (0.4, 0.3, 1) + (0.1, 0.2, 3) = (0.5, 0.5, 4); c = (50, 40).
    X = [0.3, -0.4, 1.0]
    np.testing.assert_allclose(cam.project(X), [100.0, 90.0], atol=1e-12)
    assert cam.depth(X) == pytest.approx(4.0)


def test_ortho_has_no_distortion(rng):
    cam = make_ortho()
    uv = rng.uniform(0, 100, size=(5, 2))
    np.testing.assert_array_equal(cam.undistort_points(uv), uv)
    np.testing.assert_array_equal(cam.distort_points(uv), uv)


def test_near_ortho_camera_is_the_pinhole_at_its_distance(rng):
    # kappa = 1 / distance: the pinhole of focal s / kappa whose centre sits that far in front
    # of the world origin along the view, seeing the origin's depth at s pixels per metre.
    near = ScaledOrthoCamera("n", (640, 480), 300.0, R=rotation_z90(), t=[0.2, -0.1, 7.0],
                             kappa=0.25)
    f, c = 300.0 / 0.25, near.c
    pinhole = PinholeCamera("n", (640, 480), [[f, 0, c[0]], [0, f, c[1]], [0, 0, 1]],
                            R=rotation_z90(), t=[0.2, -0.1, 4.0])
    X = rng.uniform(-1.0, 1.0, (30, 3))
    np.testing.assert_allclose(near.project(X), pinhole.project(X), atol=1e-9)
    np.testing.assert_allclose(near.center, pinhole.center, atol=1e-12)
    assert near.replace(kappa=0.0).center is None
    # The origin's depth keeps the scale of the scaled orthographic camera.
    flat = near.replace(kappa=0.0)
    on_plane = near.world_from_cam(np.c_[rng.uniform(-1, 1, (5, 2)), np.full(5, 7.0)])
    np.testing.assert_allclose(near.project(on_plane), flat.project(on_plane), atol=1e-9)
    origins, dirs = near.pixel_rays()
    np.testing.assert_allclose(origins, pinhole.center, atol=1e-12)
    np.testing.assert_allclose(dirs, pinhole.pixel_rays()[1], atol=1e-12)
    assert "kappa=0.25" in repr(near) and "kappa" not in repr(flat)
