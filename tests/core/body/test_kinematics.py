"""The forward kinematics of the standard joints (core/body/kinematics.py) against the body model."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.body.kinematics import kinematics


@pytest.mark.parametrize("template", bm.TEMPLATES)
def test_kinematics_equal_the_body_model(template, rng):
    kin = kinematics(template)
    dims = kin.default_dims * rng.uniform(0.8, 1.2, len(bm.LENGTH_DIMS))
    body = bm.make_body(template, dict(zip(bm.LENGTH_DIMS, dims)))
    angles = rng.uniform(body.lower, body.upper, size=(3, body.n_dofs))
    Y, J_angles, J_dims = kin.forward(angles, dims)
    for b in range(3):
        pose = bm.Pose(np.eye(4), angles[b])
        X, J = body.joints_jacobian(pose)
        assert np.allclose(Y[b], X, atol=1e-12)
        assert np.allclose(J_angles[b], J[..., 6:], atol=1e-12)
        assert np.allclose(J_dims[b], body.joints_dims_jacobian(pose), atol=1e-12)
