"""Tests of core.body.primitives: the ellipsoid, cylinder and capsule builders and the checks on
a set of primitives."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zoopraxis.core.body.primitives import (CYLINDER, ELLIPSOID, Primitives, capsule, cylinder,
                                            ellipsoid)
from zoopraxis.core.errors import ZoopraxisError


class TestPrimitives:
    def test_ellipsoid_builder(self):
        Q = Rotation.from_euler("xyz", [10, 20, 30], degrees=True).as_matrix()
        p = ellipsoid(3, (0.1, 0.2, 0.3), (0.3, 0.2, 0.1), Q)
        assert len(p) == 1 and p.segment[0] == 3 and p.kind[0] == ELLIPSOID
        np.testing.assert_allclose(p.prim2seg[0, :3, :3], Q)
        np.testing.assert_allclose(p.prim2seg[0, :3, 3], (0.1, 0.2, 0.3))
        np.testing.assert_allclose(p.size[0], (0.3, 0.2, 0.1))

    def test_sphere_from_one_radius(self):
        np.testing.assert_allclose(ellipsoid(0, (0, 0, 0), 0.2).size[0], (0.2, 0.2, 0.2))

    def test_cylinder_builder_frame(self):
        base, top = np.array([0.1, 0.0, 1.0]), np.array([0.1, 0.3, 0.6])
        p = cylinder(2, base, top, 0.05, 0.04, ry_ratio=0.5, x_dir=(1.0, 0.0, 1.0))
        T = p.prim2seg[0]
        axis = (top - base) / 0.5
        np.testing.assert_allclose(T[:3, 2], axis, atol=1e-12)
        np.testing.assert_allclose(T[:3, 3], base)
        # local x is x_dir made orthogonal to the axis
        x_dir = np.array([1.0, 0.0, 1.0])
        x = x_dir - (x_dir @ axis) * axis
        np.testing.assert_allclose(T[:3, 0], x / np.linalg.norm(x), atol=1e-12)
        np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12)
        assert np.linalg.det(T[:3, :3]) > 0
        np.testing.assert_allclose(p.size[0], (0.05, 0.025, 0.5))
        np.testing.assert_allclose(p.taper[0], 0.8)
        assert p.kind[0] == CYLINDER

    def test_cylinder_default_cross_section_is_orthogonal(self, rng):
        for _ in range(5):
            base, top = rng.normal(size=(2, 3))
            T = cylinder(0, base, top, 0.1).prim2seg[0]
            np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
            np.testing.assert_allclose(T[:3, 2] * np.linalg.norm(top - base), top - base)

    def test_capsule_is_three_primitives_of_one_segment(self):
        p = capsule(4, (0, 0, 0), (0, 0, 0.3), 0.05)
        assert len(p) == 3 and set(p.segment) == {4}
        assert list(p.kind) == [CYLINDER, ELLIPSOID, ELLIPSOID]
        np.testing.assert_allclose(p.prim2seg[2, :3, 3], (0, 0, 0.3))

    def test_concat_keeps_order_and_is_read_only(self):
        a = ellipsoid(0, (0, 0, 0), 0.1)
        b = cylinder(1, (0, 0, 0), (0, 0, 1), 0.1)
        p = Primitives.concat([a, b, a])
        assert list(p.segment) == [0, 1, 0] and p.n_segments == 2
        assert len(Primitives.concat([])) == 0
        with pytest.raises(ValueError):
            p.size[0, 0] = 1.0

    @pytest.mark.parametrize("change, match", [
        (dict(segment=[-1]), "segment"),
        (dict(kind=[2]), "kind"),
        (dict(kind=[0.5]), "integers"),
        (dict(size=[[0.1, 0.0, 0.1]]), "size"),
        (dict(size=[[0.1, 0.1]]), "shape"),
        (dict(taper=[0.0]), "taper"),
        (dict(prim2seg=[np.diag([1.0, 1.0, 2.0, 1.0])]), "rigid"),
        (dict(prim2seg=[np.diag([1.0, 1.0, -1.0, 1.0])]), "reflection"),
    ])
    def test_bad_primitives(self, change, match):
        fields = dict(segment=[0], kind=[CYLINDER], prim2seg=[np.eye(4)],
                      size=[[0.1, 0.1, 0.5]], taper=[1.0])
        fields.update(change)
        with pytest.raises(ZoopraxisError, match=match):
            Primitives(**fields)

    def test_bad_builder_input(self):
        with pytest.raises(ZoopraxisError, match="same point"):
            cylinder(0, (0, 0, 1), (0, 0, 1), 0.1)
        with pytest.raises(ZoopraxisError, match="parallel"):
            cylinder(0, (0, 0, 0), (0, 0, 1), 0.1, x_dir=(0, 0, 2))
        with pytest.raises(ZoopraxisError, match="r_base"):
            cylinder(0, (0, 0, 0), (0, 0, 1), -0.1)
        with pytest.raises(ZoopraxisError, match="rotation"):
            ellipsoid(0, (0, 0, 0), 0.1, axes=np.diag([1.0, 1.0, -1.0]))
        with pytest.raises(ZoopraxisError, match="semi_axes"):
            ellipsoid(0, (0, 0, 0), (0.1, 0.2))
        with pytest.raises(ZoopraxisError, match="Primitives"):
            Primitives.concat([ellipsoid(0, (0, 0, 0), 0.1), "head"])
