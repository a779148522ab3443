"""The joint least-squares problem of the initialization (core/initialize/problem.py)."""

import numpy as np
import pytest

from zoopraxis.core.body.kinematics import kinematics
from zoopraxis.core.body.body import LENGTH_DIMS
from zoopraxis.core.initialize.problem import _fit, _prior_residual, _Problem, _State
from zoopraxis.core.initialize.uncalibrated import DIMS_LOSS
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


@pytest.mark.parametrize("calibrated, learned_prior, dims_loss", [
    (True, False, None), (False, False, None), (False, True, None), (False, True, 1.0)])
def test_problem_jacobian_against_finite_differences(calibrated, learned_prior, dims_loss,
                                                     rng):
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
    if dims_loss is not None:   # the lengths' prior of one view, heavy-tailed
        prior.update(dims_loss=dims_loss)
    problem = _Problem(kin, obs, np.ones(obs.shape[:3]), state, free_root=calibrated,
                       free_cams=free_cams, calibrated=calibrated, **prior)
    x = problem.x0() + rng.normal(0, 0.02, problem.n_params)
    x = np.clip(x, *problem.bounds())
    J = problem.evaluate(x)[1]
    J_fd = _finite_difference(problem, x)
    assert np.abs(J - J_fd).max() < 1e-4 * max(1.0, np.abs(J_fd).max())


def test_prior_residual_is_gaussian_near_its_mean_and_soft_l1_beyond():
    z = np.linspace(-8.0, 8.0, 33)
    r, dr = _prior_residual(z, 1.0)
    # 0.5 r^2 is the soft L1 of the whitened residual: about 0.5 z^2 near the mean, about
    # |z| beyond a spread
    assert np.allclose(0.5 * r ** 2, np.sqrt(1.0 + z ** 2) - 1.0)
    assert np.allclose(np.sign(r), np.sign(z))
    assert abs(0.5 * _prior_residual(np.array([0.1]), 1.0)[0][0] ** 2 - 0.005) < 1e-4
    assert 0.5 * r[-1] ** 2 < 0.25 * 0.5 * z[-1] ** 2
    h = 1e-6
    numeric = (_prior_residual(z + h, 1.0)[0] - _prior_residual(z - h, 1.0)[0]) / (2 * h)
    assert np.allclose(dr, numeric, atol=1e-6)
    assert np.allclose(_prior_residual(np.zeros(2), 1.0)[1], 1.0)
    # without a scale the prior stays Gaussian
    r, dr = _prior_residual(z, None)
    assert np.array_equal(r, z) and np.all(dr == 1.0)


def test_one_view_heavy_tailed_lengths_prior_lets_the_clicks_narrow_the_shoulders(rng):
    """One scaled orthographic view, from the front, of a body whose shoulders are a third
    narrower than the template's (cgspeed's Daz figure of the CMU takes): fitted from the true
    pose, the uncalibrated fit's lengths prior (soft L1 beyond DIMS_LOSS spreads) lets the
    clicks narrow them; a Gaussian prior keeps them about a quarter too wide."""
    kin = kinematics("full")
    dims = kin.default_dims.copy()
    k = LENGTH_DIMS.index("shoulder_width")
    dims[k] *= 0.65
    pose = synth.everyday_pose(synth.random_subject(rng), rng)
    R = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    cam = ScaledOrthoCamera("front", (1920, 1080), 430.0, R=R, t=[0.0, 0.0, 10.0],
                            c=(959.5, 539.5))
    obs = cam.project(kin.forward(pose.angles[None], dims)[0][0])[None, None]
    state = _State(kin.default_dims.copy(), 1.0, np.eye(4)[None], pose.angles[None].copy(),
                   [[cam]])
    widths = {}
    for loss in (None, DIMS_LOSS):
        fitted, _, _ = _fit(kin, obs, np.ones(obs.shape[:3]), state, free_root=False,
                            free_cams=np.ones((1, 1), bool), calibrated=False, dims_loss=loss)
        widths[loss] = fitted.dims[k] / np.median(fitted.dims / dims)
    assert abs(widths[DIMS_LOSS] / dims[k] - 1.0) < 0.1
    assert widths[None] / dims[k] > 1.2
