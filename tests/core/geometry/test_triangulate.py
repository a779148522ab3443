"""Triangulation and similarity of point sets (core/geometry/triangulate.py)."""

import numpy as np

from zoopraxis.core.geometry.triangulate import procrustes_mpjpe, similarity_from_points, triangulate
from zoopraxis.core.geometry import se3

from tests.core.initialize.test_initialize import ring


def test_triangulate_recovers_points(rng):
    cams = ring(3, rng)
    X = rng.uniform(-0.5, 0.5, (17, 3)) + [0, 0, 1]
    uv = np.stack([c.project(X) for c in cams])
    uv[0, :5] = np.nan                                         # seen by two views only
    uv[1:, 5] = np.nan                                         # seen by one view only
    Xt = triangulate(cams, uv)
    assert np.isnan(Xt[5]).all()
    ok = np.isfinite(Xt).all(axis=1)
    assert ok.sum() == 16 and np.abs(Xt[ok] - X[ok]).max() < 1e-9


def test_similarity_from_points_recovers_transform(rng):
    A = rng.normal(size=(10, 3))
    R = se3.exp_so3(rng.normal(size=3))
    B = 1.3 * A @ R.T + [1.0, 2.0, 3.0]
    R_fit, t, s = similarity_from_points(A, B)
    assert np.allclose(R_fit, R) and np.isclose(s, 1.3) and np.allclose(t, [1, 2, 3])
    assert procrustes_mpjpe(A, B) < 1e-12
