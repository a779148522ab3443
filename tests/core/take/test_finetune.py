"""Model fine-tuning (Bregler & Malik §2.7): limb lengths from silhouettes, re-tracking."""

import numpy as np
import pytest

from zoopraxis.core.take import finetune as FT
from zoopraxis.core.body import fit3d
from zoopraxis.core.synthetic import synth

from zoopraxis.core.body.body import make_body
from zoopraxis.core.geometry.camera import ring_of_cameras
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files.initfile import InitResult
from zoopraxis.core.initialize.run import initialize
from zoopraxis.core.body.joints import STANDARD_JOINTS
from zoopraxis.core.files.markers import Anchor
from zoopraxis.core.imaging.render import render

N = 10
WRONG = 1.09        # every length of the starting body is 9 % too long


def limb_errors(body, truth):
    return np.array([body.dims[n] / truth.dims[n] - 1 for n in FT.REFINED_DIMS])


@pytest.fixture(scope="module")
def take():
    from tests.conftest import slow_walk_take

    scene, joints = slow_walk_take(N)
    truth, _, _ = fit3d.fit_sequence(joints)
    wrong = truth.with_dims({n: WRONG * truth.dims[n] for n in FT.LENGTH_DIMS})
    cams = {c.name: c for c in scene.cameras}
    rng = np.random.default_rng(2345)
    anchors = [Anchor(0, {c.name: dict(zip(STANDARD_JOINTS, map(tuple, c.project(joints[0])
                                                                + rng.normal(0, 2.0, (17, 2)))))
                          for c in scene.cameras})]
    # the anchor posed from its (2 px) clicks with the wrong lengths held
    start = initialize(anchors, cams, dims=wrong.dims, fit_dims=False).poses[0]
    # clean plates (the empty set): ten frames of a slow walk leave the background behind
    # the person unseen, and there the silhouette cannot speak
    clean = {c.name: bg for c, bg in zip(scene.cameras, scene.backgrounds)}
    return scene, joints, truth, wrong, start, cams, anchors, clean


def test_silhouettes_give_the_limb_lengths():
    """The model's own silhouettes (no tracking): the lengths come closer to the truth."""
    rng = np.random.default_rng(2345)
    truth = make_body("full")
    cams = ring_of_cameras(3, 4.0, 1.3, (0.0, 0.0, 1.0), (320, 240), 350.0)
    poses, masks = [], []
    for _ in range(4):
        pose = truth.rest_pose()
        pose.root[:3, 3] = [0.0, 0.0, 1.0]
        pose.angles = truth.clamp(rng.normal(0.0, 0.35, truth.n_dofs))
        poses.append(pose)
        prims, T_ = truth.primitives(), truth.seg2world(pose)
        masks.append([render(c, T_, prims, want=()).label >= 0 for c in cams])
    wrong = truth.with_dims({n: truth.dims[n] * f for n, f in
                             zip(FT.REFINED_DIMS, (1.08, 0.93, 0.92))})
    starts = [fit3d.fit_pose(wrong, truth.joints(p))[0] for p in poses]
    fit = FT.fit_body_to_images(wrong, starts, cams, masks, iterations=30)
    before = np.abs(limb_errors(wrong, truth))
    after = np.abs(limb_errors(fit.body, truth))
    assert before.min() > 0.065
    # every length comes closer; the poses of a few frames absorb part of a length's change
    # (a longer thigh, a lower pelvis and a deeper knee bend look much alike)
    assert np.all(after < before - 0.005) and after.mean() < 0.65 * before.mean(), after
    assert fit.cost_after < fit.cost_before and fit.contour_rms[1] < fit.contour_rms[0]
    error = [np.linalg.norm(fit.body.joints(p) - truth.joints(q), axis=1).mean()
             for p, q in zip(fit.poses, poses)]
    assert np.mean(error) < 0.015
    # the trunk is the clicks' business: untouched
    assert fit.body.dims["torso"] == wrong.dims["torso"]


@pytest.mark.slow
def test_finetune_brings_the_limbs_closer_and_the_track_no_worse(take):
    scene, joints, truth, wrong, start, cams, anchors, clean = take
    lines, calls = [], []
    out = FT.finetune(synth.scene_plates(scene), anchors, cams, backgrounds=clean,
                      init=InitResult(wrong, {0: start}, cams), log=lines.append,
                      progress=lambda d, t: calls.append((d, t)))
    before = np.abs(limb_errors(out.body_before, truth))
    after = np.abs(limb_errors(out.body_after, truth))
    assert np.allclose(before, WRONG - 1)
    # thigh and shank recover about half of their error or more (9 % -> 4.6 and 2.4 % since
    # the legs are predicted with their learned carry, 3.8 and 1.3 % with half their velocity);
    # the forearm of this slow walk's hanging arms does not (10.6 %): every frame is tracked
    # ok, so all ten are fitted, and in most of them the forearm lies against the trunk in both
    # views (thigh, shank and forearm came to 1.3, 1.0 and 2.3 % when frames 3-7 were wrongly
    # called lost and left out)
    assert after[:2].max() < 0.55 * (WRONG - 1), after
    assert after.mean() < 0.7 * (WRONG - 1), after
    assert len(out.samples) >= 3 and out.samples[0] == 0
    # what fine-tuning returns tracks the take no worse than the first track
    first = np.linalg.norm(out.first.joints3d - joints, axis=2).mean()
    final = np.linalg.norm(out.result.joints3d - joints, axis=2).mean()
    assert final <= first + 0.003, (first, final)
    # the re-track is kept exactly when the tracker's measures say it is better
    assert out.kept == FT.is_better(out.measures["after"], out.measures["before"])
    assert out.result is (out.retrack if out.kept else out.first)
    assert out.result.body["dims"]["thigh"] == pytest.approx(
        (out.body_after if out.kept else out.body_before).dims["thigh"], abs=1e-5)
    assert any(line.startswith("fine-tune: lengths") and "thigh" in line for line in lines)
    assert any("keeping the" in line for line in lines)
    done, total = zip(*calls)
    assert max(done) == total[-1] and all(np.diff(done) >= 0)
    assert out.lengths()["shank"][1] == out.body_after.dims["shank"]


def test_cancel_keeps_what_was_tracked(take):
    scene, joints, truth, wrong, start, cams, anchors, _ = take
    polls = []

    def cancel():
        polls.append(1)
        return len(polls) > 3

    out = FT.finetune(synth.scene_plates(scene), anchors, cams,
                      init=InitResult(wrong, {0: start}, cams), frames=range(0, 6), cancel=cancel)
    assert out.cancelled and not out.kept and out.retrack is None
    assert out.result is out.first and out.result.extra["cancelled"]
    assert 1 <= out.result.num_frames < 6


def test_bad_input(take):
    scene, joints, truth, wrong, start, cams, anchors, _ = take
    with pytest.raises(ZoopraxisError, match="calibration"):
        FT.finetune(synth.scene_plates(scene), anchors, None)
    with pytest.raises(ZoopraxisError, match="camera for view 'cam1'"):
        FT.finetune(synth.scene_plates(scene), anchors, {"cam0": cams["cam0"]})
    with pytest.raises(ZoopraxisError, match="2 frames x 2 views"):
        FT.fit_body_to_images(wrong, [start, start], list(cams.values()), [[None, None]])


def test_keep_rule_judges_by_the_grey_residual():
    before = {"iou": 0.49, "fit": 0.64, "residual": 3.03, "ok": 2, "uncertain": 7, "lost": 11}
    # lengths fixed: the appearance is explained better though longer limbs overlapped more
    after = {**before, "iou": 0.485, "residual": 2.94, "uncertain": 8, "lost": 10}
    assert FT.is_better(after, before)
    assert not FT.is_better({**after, "residual": 3.1}, before)
    # never more frames lost, nor more lost and uncertain together
    assert not FT.is_better({**after, "lost": 12, "uncertain": 5}, before)
    assert not FT.is_better({**after, "uncertain": 9}, before)
    # without residuals the overlap decides
    nan = float("nan")
    assert FT.is_better({**after, "residual": nan, "iou": 0.5}, {**before, "residual": nan})
    assert not FT.is_better({**after, "residual": nan}, {**before, "residual": nan})
