"""The joint least-squares problem of the initialization (core/initialize/problem.py)."""

import numpy as np
import pytest

from zoopraxis.core.body.kinematics import kinematics
from zoopraxis.core.initialize.problem import _Problem, _State
from zoopraxis.core.priors.pose import default_pose_prior
from zoopraxis.core.synthetic import synth
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera

from tests.core.initialize.test_initialize import ring


def _finite_difference(problem, x, h=1e-6):
    r0 = problem.evaluate(x)[0]
    J = np.zeros((r0.size, x.size))
    for k in range(x.size):
        step = np.zeros_like(x)
        step[k] = h
        J[:, k] = (problem.evaluate(x + step)[0] - problem.evaluate(x - step)[0]) / (2 * h)
    return J


@pytest.mark.parametrize("calibrated, learned_prior", [(True, False), (False, False),
                                                       (False, True)])
def test_problem_jacobian_against_finite_differences(calibrated, learned_prior, rng):
    body = synth.random_subject(rng)
    kin = kinematics("full")
    cams = ring(2, rng)
    poses = [synth.everyday_pose(body, rng) for _ in range(2)]
    obs = np.stack([[c.project(body.joints(p)) for c in cams] for p in poses])
    obs[0, 1, 3] = np.nan                                      # an unclicked joint
    if calibrated:
        cameras = [list(cams)] * 2
        roots = np.stack([p.root for p in poses])
    else:
        cameras = [[ScaledOrthoCamera(c.name, c.image_size, 200.0,
                                      R=c.R @ p.root[:3, :3], t=[0.1, -0.2, 5.0], kappa=0.2)
                    for c in cams] for p in poses]
        roots = np.tile(np.eye(4), (2, 1, 1))
    state = _State(kin.default_dims * 1.05, 1.02, roots,
                        np.stack([p.angles for p in poses]), cameras)
    free_cams = None if calibrated else np.ones((2, 2), bool)
    prior = {}
    if learned_prior:       # the second frame's angles under the learned prior
        prior = dict(pose_prior=default_pose_prior("full").with_broad(kin.prior_mean,
                                                                           kin.prior_sigma),
                     prior_frames=[False, True])
    if not calibrated:      # the camera tilt prior on the frames seen in one view
        prior.update(tilt=(-0.1, 0.17), tilt_frames=[True, learned_prior])
    if not calibrated:      # the second frame's cameras' perspective
        prior.update(perspective=[False, True])
    problem = _Problem(kin, obs, np.ones(obs.shape[:3]), state, free_root=calibrated,
                            free_cams=free_cams, calibrated=calibrated, **prior)
    x = problem.x0() + rng.normal(0, 0.02, problem.n_params)
    x = np.clip(x, *problem.bounds())
    J = problem.evaluate(x)[1]
    J_fd = _finite_difference(problem, x)
    assert np.abs(J - J_fd).max() < 1e-4 * max(1.0, np.abs(J_fd).max())
