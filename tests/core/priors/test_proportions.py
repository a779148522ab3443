"""The proportions prior: performers' lengths, their mean proportions and spread, leaving
performers out, and what it changes in a body fitted to one view."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.initialize.problem import DIMS_PRIOR_SIGMA
from zoopraxis.core.initialize.run import initialize
from zoopraxis.core.synthetic import synth
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files.markers import Anchor
from zoopraxis.core.geometry.camera import ring_of_cameras
from zoopraxis.core.body.joints import STANDARD_JOINTS
from zoopraxis.core.priors.proportions import MIN_SIGMA, ProportionsPrior

TEMPLATE = np.array([bm.DEFAULT_DIMS[n] for n in bm.LENGTH_DIMS])
K = {n: k for k, n in enumerate(bm.LENGTH_DIMS)}


def performers(proportions, sizes, rng, spread=0.0):
    """Lengths of performers of the given proportions (relative to the template) and sizes,
    each length off by a random relative ``spread``; ankle_height not measured."""
    lengths = np.array([s * TEMPLATE * proportions * (1 + rng.normal(0, spread, len(TEMPLATE)))
                        for s in sizes])
    lengths[:, K["ankle_height"]] = np.nan
    return ProportionsPrior([f"{k:02d}" for k in range(len(sizes))], lengths)


class TestMeanSigma:
    def test_proportions_without_the_size(self, rng):
        shape = np.ones(len(TEMPLATE))
        shape[K["shank"]], shape[K["forearm"]] = 1.15, 0.85
        mean, sigma = performers(shape, [0.9, 1.0, 1.1, 1.2], rng).mean_sigma()
        np.testing.assert_allclose(mean / TEMPLATE, shape, rtol=1e-9)
        assert np.all(sigma[np.arange(len(sigma)) != K["ankle_height"]] == MIN_SIGMA)
        assert sigma[K["ankle_height"]] == DIMS_PRIOR_SIGMA     # not measured

    def test_spread_across_performers(self, rng):
        prior = performers(np.ones(len(TEMPLATE)), np.linspace(0.9, 1.1, 40), rng, spread=0.08)
        mean, sigma = prior.mean_sigma()
        measured = np.arange(len(sigma)) != K["ankle_height"]
        assert np.all(np.abs(sigma[measured] - 0.08) < 0.03)
        np.testing.assert_allclose(mean[measured] / TEMPLATE[measured], 1.0, atol=0.05)


def test_file_round_trip_and_hold_out(tmp_path, rng):
    prior = performers(np.ones(len(TEMPLATE)), [0.9, 1.0, 1.1], rng, spread=0.05)
    path = tmp_path / "p.npz"
    prior.save(path)
    loaded = ProportionsPrior.load(path, exclude=["01"])
    assert loaded.subjects.tolist() == ["00", "02"]
    np.testing.assert_allclose(loaded.lengths, prior.lengths[[0, 2]], rtol=1e-6)
    with pytest.raises(ZoopraxisError, match="no performers left after leaving out 00, 01, 02"):
        ProportionsPrior.load(path, exclude=["00", "01", "02"])
    with pytest.raises(ZoopraxisError, match="not a proportions prior file"):
        ProportionsPrior.load(tmp_path / "missing.npz")


def test_shipped_prior_knows_cmu_performers():
    prior = ProportionsPrior.load()
    assert len(prior.subjects) >= 10 and "131" in prior.subjects
    mean, sigma = prior.mean_sigma()
    # CMU's shank is longer than its forearm by far more than the template's
    assert mean[K["shank"]] / mean[K["forearm"]] > 1.15 * TEMPLATE[K["shank"]] / TEMPLATE[
        K["forearm"]]


def test_one_view_lengths_follow_the_proportions_prior(rng):
    """A body whose proportions are far from the template's, clicked in one view: the fitted
    proportions come out closer to its own with a prior of performers built like it."""
    shape = np.ones(len(TEMPLATE))
    shape[K["shank"]], shape[K["forearm"]], shape[K["thigh"]] = 1.15, 0.82, 1.06
    prior = performers(shape, [0.95, 1.0, 1.05, 1.1], rng, spread=0.02)
    truth = bm.make_body("full", {n: bm.DEFAULT_DIMS[n] * shape[K[n]] for n in bm.LENGTH_DIMS})
    X = truth.joints(synth.everyday_pose(truth, rng))
    cam = ring_of_cameras(1, 100.0, 1.4, (0.0, 0.0, 1.0), (1920, 1080), 43000.0,
                          start_angle=0.7)[0]
    clicked = {cam.name: {j: tuple(p) for j, p in zip(
        STANDARD_JOINTS, cam.project(X) + rng.normal(0, 1.0, (17, 2)))}}
    errors = {}
    for label, proportions in (("template", None), ("learned", prior)):
        result = initialize([Anchor(0, clicked)], {cam.name: cam}, calibrated=False,
                                 pose_prior=None, proportions=proportions)
        fitted = np.array([result.body.dims[n] for n in bm.LENGTH_DIMS])
        ratio = fitted / (TEMPLATE * shape)
        ratio /= np.median(ratio)
        errors[label] = np.abs(ratio[[K["shank"], K["forearm"], K["thigh"]]] - 1).max()
    assert errors["learned"] < 0.05 < errors["template"]
