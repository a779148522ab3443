"""Tests of core.imaging.raycast's small linear-algebra helpers against numpy; the intersections
themselves are tested through the renderer (test_render)."""

import numpy as np

from zoopraxis.core.imaging import raycast


class TestHelpers:
    def test_cross_is_numpys(self, rng):
        for shape_a, shape_b in (((7, 3), (7, 3)), ((2, 5, 3), (5, 3)), ((3,), (4, 3))):
            a, b = rng.normal(size=shape_a), rng.normal(size=shape_b)
            np.testing.assert_array_equal(raycast._cross(a, b), np.cross(a, b))
        a32 = rng.normal(size=(9, 3)).astype(np.float32)
        out = raycast._cross(a32, a32[::-1])
        assert out.dtype == np.float32
        np.testing.assert_array_equal(out, np.cross(a32, a32[::-1]))

    def test_inverse_affine_and_determinants(self, rng):
        T = np.zeros((6, 4, 4))
        T[:, :3, :3] = rng.normal(size=(6, 3, 3))
        T[:, :3, 3] = rng.normal(size=(6, 3))
        T[:, 3, 3] = 1.0
        np.testing.assert_allclose(raycast._inv_affine(T), np.linalg.inv(T),
                                   rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(raycast.det3(T[:, :3, :3]),
                                   np.linalg.det(T[:, :3, :3]), rtol=1e-12, atol=1e-12)
