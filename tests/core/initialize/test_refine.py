"""Model fine-tuning from joints (core/initialize/refine.py, §2.7)."""

import numpy as np
import pytest

from zoopraxis.core.body import body as bm
from zoopraxis.core.initialize.refine import refine_dims
from zoopraxis.core.geometry import se3
from zoopraxis.core.synthetic import synth
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX

NOISE_PX = 2.0
from tests.core.initialize.test_initialize import mpjpe, ring, NOISE_PX, SEGMENTS


def test_refine_dims_recovers_true_dims_from_a_noisy_sequence(rng):
    """Tracked 2D joints of 16 frames in 3 views, 2 px noise; poses and dims start off."""
    truth = synth.random_subject(rng)
    cams = ring(3, rng)
    poses = {f: synth.everyday_pose(truth, rng) for f in range(16)}
    obs = {f: {c.name: c.project(truth.joints(p)) + rng.normal(0, NOISE_PX, (17, 2))
               for c in cams} for f, p in poses.items()}
    obs[5]["cam0"][JOINT_INDEX["head"]] = np.nan              # a joint the tracker lost
    start = {f: bm.Pose(se3.exp_se3(rng.normal(0, 0.02, 6)) @ p.root,
                        p.angles + rng.normal(0, 0.05, p.angles.size)) for f, p in poses.items()}
    result = refine_dims(bm.make_body("full"), start, obs, {c.name: c for c in cams})
    for name in SEGMENTS:
        assert abs(result.body.dims[name] / truth.dims[name] - 1) < 0.02, name
    for name in ("hip_width", "shoulder_width"):                # short: 2 px is 1 % of them
        assert abs(result.body.dims[name] / truth.dims[name] - 1) < 0.04, name
    errors = [mpjpe(result.body.joints(result.poses[f]), truth.joints(p))
              for f, p in poses.items()]
    assert np.mean(errors) < 0.015
    assert max(result.rms.values()) < 1.5 * NOISE_PX


def test_refine_dims_weights_silence_bad_observations(rng):
    """A tracker failure it knows about (weight 0) counts as unobserved; unweighted, the
    robust loss bounds its pull but it still pulls."""
    truth = synth.random_subject(rng)
    cams = {c.name: c for c in ring(2, rng)}
    poses = {f: synth.everyday_pose(truth, rng) for f in range(4)}
    obs = {f: {n: c.project(truth.joints(p)) + rng.normal(0, NOISE_PX, (17, 2))
               for n, c in cams.items()} for f, p in poses.items()}
    obs[2]["cam1"][JOINT_INDEX["l_ankle"]] = np.nan
    clean = refine_dims(truth, poses, obs, cams)
    obs[2]["cam1"][JOINT_INDEX["l_ankle"]] = cams["cam1"].project(
        truth.joints(poses[2])[JOINT_INDEX["l_ankle"]]) + 80.0
    weights = {2: {"cam1": np.ones(17)}}
    weights[2]["cam1"][JOINT_INDEX["l_ankle"]] = 0.0
    silenced = refine_dims(truth, poses, obs, cams, weights=weights)
    heard = refine_dims(truth, poses, obs, cams)
    ankle = JOINT_INDEX["l_ankle"]

    def ankle_moved(result):
        return np.linalg.norm(result.body.joints(result.poses[2])[ankle]
                              - clean.body.joints(clean.poses[2])[ankle])

    assert ankle_moved(silenced) < 1e-5
    assert ankle_moved(heard) > 1e-2


def test_refine_dims_with_one_camera_per_frame_and_view(rng):
    """Bregler & Malik's uncalibrated mode: the scaled orthographic cameras of every frame are
    refined with the angles; the proportions come back (the size is the cameras' scale)."""
    truth = synth.random_subject(rng)
    cams = ring(2, rng, distance=10.0)
    poses = {f: synth.everyday_pose(truth, rng) for f in range(6)}
    cameras, obs = {}, {}
    for f, pose in poses.items():
        cameras[f] = {c.name: ScaledOrthoCamera(c.name, c.image_size, 200.0,
                                                R=c.R @ pose.root[:3, :3], t=[0.0, 0.0, 10.0])
                      for c in cams}
        Y = truth.joints(bm.Pose(np.eye(4), pose.angles))
        obs[f] = {n: c.project(Y) + rng.normal(0, NOISE_PX, (17, 2))
                  for n, c in cameras[f].items()}
    start = {f: bm.Pose(np.eye(4), p.angles + rng.normal(0, 0.05, p.angles.size))
             for f, p in poses.items()}
    result = refine_dims(bm.make_body("full"), start, obs, cameras)
    ratio = np.array([result.body.dims[n] / truth.dims[n] for n in SEGMENTS])
    assert np.abs(ratio / np.median(ratio) - 1).max() < 0.05
    assert isinstance(result.cameras[3]["cam1"], ScaledOrthoCamera)
    assert max(result.rms.values()) < 1.5 * NOISE_PX


def test_refine_dims_bad_input(rng):
    cams = {c.name: c for c in ring(1, rng)}
    body = bm.make_body("full")
    pose = body.rest_pose(se3.transform(p=[0, 0, 1]))
    with pytest.raises(ZoopraxisError, match="frame 7 has observations but no pose"):
        refine_dims(body, {0: pose}, {7: {"cam0": np.zeros((17, 2))}}, cams)
    with pytest.raises(ZoopraxisError, match="frame 0, view cam0: observations must have"):
        refine_dims(body, {0: pose}, {0: {"cam0": np.zeros((16, 2))}}, cams)
    with pytest.raises(ZoopraxisError, match="view cam5 has no camera"):
        refine_dims(body, {0: pose}, {0: {"cam5": np.zeros((17, 2))}}, cams)
