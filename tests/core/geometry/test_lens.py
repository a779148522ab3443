"""Tests of core.geometry.lens: OpenCV's distortion model, its Jacobian and its inverse."""

import cv2
import numpy as np

from zoopraxis.core.geometry import lens

# Barrel distortion of a wide consumer lens with unequal tangential terms and a k3.
LENS = np.array([-0.25, 0.08, 2e-3, -1e-3, -0.01])


def test_distort_matches_opencv(rng):
    xy = rng.uniform(-0.6, 0.6, (50, 2))
    points = np.c_[xy, np.ones(len(xy))]
    expected, _ = cv2.projectPoints(points, np.zeros(3), np.zeros(3), np.eye(3), LENS)
    np.testing.assert_allclose(lens.distort(xy, LENS), expected[:, 0], atol=1e-12)


def test_distort_jacobian_matches_finite_differences(rng):
    xy = rng.uniform(-0.5, 0.5, (20, 2))
    _, J = lens.distort(xy, LENS, jacobian=True)
    h = 1e-7
    for k in range(2):
        step = np.zeros(2)
        step[k] = h
        numeric = (lens.distort(xy + step, LENS) - lens.distort(xy - step, LENS)) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], numeric, atol=1e-7)


def test_undistort_inverts_distort(rng):
    xy = rng.uniform(-0.5, 0.5, (100, 2))
    np.testing.assert_allclose(lens.undistort(lens.distort(xy, LENS), LENS), xy, atol=1e-12)
    # Without distortion the inverse is a copy.
    plain = lens.undistort(xy, np.zeros(5))
    assert plain is not xy and np.array_equal(plain, xy)


def test_undistort_is_nan_past_the_fold():
    # k1 = -0.5: the radial map r (1 - 0.5 r^2) turns back at r_d = 0.544.
    dist = np.array([-0.5, 0.0, 0.0, 0.0, 0.0])
    xy = lens.undistort([[0.5, 0.0], [0.6, 0.0]], dist)
    assert np.all(np.isfinite(xy[0])) and np.all(np.isnan(xy[1]))
