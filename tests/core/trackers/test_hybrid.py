"""Particle and hybrid trackers over a take: accuracy, spread, the coarse search, cancel, CLI."""

import os
import subprocess
import sys

import numpy as np
import pytest

from zoopraxis.core.body import fit3d
from zoopraxis.core.trackers import filter_stepper as FS
from zoopraxis.core.trackers import hybrid, particle
from zoopraxis.core.geometry import se3
from zoopraxis.core.synthetic import synth
from zoopraxis.core.files import result as result_io
from zoopraxis.core.files.initfile import InitResult
from zoopraxis.core.take import driver as DR
from zoopraxis.core.take import track as T
from zoopraxis.core.body.body import Pose
from zoopraxis.core.trackers.differential import State
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import STANDARD_JOINTS
from zoopraxis.core.files.markers import Anchor
from zoopraxis.core.priors.motion_prior import SmoothMotionPrior


def anchors_at(scene, joints, frames):
    return [Anchor(f, {c.name: dict(zip(STANDARD_JOINTS, map(tuple, c.project(joints[f]))))
                       for c in scene.cameras}) for f in frames]


def make_take(bvh, start, n, views=2, noise=1.0):
    from tests.conftest import shared_data_dir

    data = shared_data_dir()
    if data is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    scene, joints = synth.take_from_bvh(data / "cmu_mocap" / bvh, frames=slice(start, start + n),
                                        fps=30.0, views=views, image_size=(320, 240),
                                        noise=noise, clutter=4)
    body, poses, _ = fit3d.fit_sequence(joints)
    return scene, joints, body, poses


@pytest.fixture(scope="module")
def slow():
    """A slow walk, 6 frames: joints move about 2 cm a frame. Noise-free plates: a synthetic
    scene draws new sensor noise at every render, which would make results depend on the order
    the tests run in."""
    return make_take("131_02.bvh", 200, 6, noise=0.0)


@pytest.fixture(scope="module")
def brisk():
    """CMU 131_03's walking cycle at 30 fps: the swinging foot moves up to 15 cm a frame,
    beyond the differential tracker's reach from its constant-velocity prediction."""
    return make_take("131_03.bvh", 95, 14)


def run(take, tracker, anchor_frames=(0,), **kw):
    scene, joints, body, poses = take
    cams = {c.name: c for c in scene.cameras}
    init = InitResult(body, {f: poses[f] for f in anchor_frames}, cams)
    plates = synth.scene_plates(scene)
    anchors = anchors_at(scene, joints, anchor_frames)
    if tracker == "differential":
        return T.track(plates, anchors, cams, init=init, **kw)
    return T.track_filter(plates, anchors, cams, init=init, tracker=tracker, **kw)


def mpjpe(res, joints):
    return np.linalg.norm(res.joints3d - joints[res.frames], axis=2).mean(axis=1)


# -- the coarse search beats the differential tracker on fast motion ----------------------------


@pytest.fixture(scope="module")
def brisk_runs(brisk):
    return {"differential": run(brisk, "differential"),
            "hybrid": run(brisk, "hybrid", particles=500)}


@pytest.mark.slow
def test_hybrid_tracks_a_brisk_walk(brisk, brisk_runs):
    scene, joints, body, poses = brisk
    res = brisk_runs["hybrid"]
    error = mpjpe(res, joints)
    assert list(res.frames) == list(range(len(joints))) and res.mode == "calibrated"
    # Two 320x240 views, 500 particles; the benchmark measures the full-size case.
    assert error.mean() < 0.04 and error.max() < 0.06
    assert res.extra["tracker"] == "hybrid" and res.extra["particles"] == 500
    assert res.spread.shape == (len(joints), 6 + body.n_dofs)
    assert np.all(res.spread[0] == 0) and np.all(res.spread[1:, 6:].max(axis=1) > 0)
    for c in scene.cameras:
        assert np.all(res.residual[c.name][1:] > 0)


def test_hybrid_follows_fast_motion_as_the_differential_tracker_does(brisk, brisk_runs):
    scene, joints, body, poses = brisk
    alone = mpjpe(brisk_runs["differential"], joints)
    guided = mpjpe(brisk_runs["hybrid"], joints)
    # The differential tracker's second round, with backgrounds that keep its first round's
    # body out, and its silhouette search follow the swinging leg too (it was over 10 cm off
    # with the first round's backgrounds alone). Since its root turns about the pelvis it is
    # 2.3 cm off on average, 4.1 at worst (3.3 and 4.8 before); the hybrid's coarse search 2.8
    # and 4.3.
    assert alone.mean() < 0.03 and alone.max() < 0.06
    assert guided.mean() < 0.035 and guided.max() < 0.06


@pytest.mark.slow
def test_the_same_seed_gives_the_same_track(slow):
    a, b = (run(slow, "hybrid", particles=100, frames=range(0, 3)) for _ in range(2))
    np.testing.assert_array_equal(a.joints3d, b.joints3d)
    np.testing.assert_array_equal(a.spread, b.spread)


@pytest.mark.slow
def test_hybrid_with_the_walking_prior(slow):
    scene, joints, body, poses = slow
    res = run(slow, "hybrid", particles=200, prior="walk")
    assert res.extra["motion_prior"] == "walk"
    assert mpjpe(res, joints).max() < 0.04


@pytest.mark.slow
def test_particle_and_hybrid_with_the_general_prior(slow):
    # The default prior, named. The filter alone's bound is the one that catches a filter gone
    # astray (test_particle_mode_writes_spread_and_status); the hybrid's is the walking prior's.
    scene, joints, body, poses = slow
    for tracker, bound in (("particle", 0.1), ("hybrid", 0.04)):
        res = run(slow, tracker, particles=200, prior="general")
        assert res.extra["motion_prior"] == "general"
        assert mpjpe(res, joints).max() < bound


# -- the particle filter alone ------------------------------------------------------------------


@pytest.mark.slow
def test_particle_mode_writes_spread_and_status(slow, tmp_path):
    scene, joints, body, poses = slow
    calls = []
    res = run(slow, "particle", particles=300, progress=lambda d, t: calls.append((d, t)))
    assert calls[-1] == (5, 5)
    assert res.extra["tracker"] == "particle" and len(res.extra["filter_status"]) == 6
    # The filter alone hardly follows even this walk: a few hundred draws in 35 dimensions
    # rarely move every limb the right way at once, and its tempered weights keep the mean near
    # the prediction (standing still is 2 cm off after a frame and 9 cm after five;
    # benchmarks/bench_hybrid.py measures it). A bound that catches a filter gone astray.
    error = mpjpe(res, joints)
    assert error[1] < 0.03 and error.max() < 0.1
    # The posterior spread is wider in angles than a refined pose is off, and zero at the anchor.
    assert res.spread.shape == (6, 6 + body.n_dofs)
    assert np.all(res.spread[0] == 0)
    angle_spread = np.degrees(np.sqrt(np.mean(res.spread[1:, 6:] ** 2, axis=1)))
    assert np.all((angle_spread > 0.2) & (angle_spread < 20))
    assert set(res.status) <= {"ok", "uncertain", "lost"}
    for c in scene.cameras:
        assert np.all(res.residual[c.name][1:] > 0) and np.all(res.residual[c.name] < 60)
    path = tmp_path / "result.json"
    result_io.write_result(path, res)
    back = result_io.read_result(path)
    np.testing.assert_allclose(back.spread, res.spread, atol=1e-6)
    assert back.extra["filter_status"] == res.extra["filter_status"]


@pytest.mark.slow
def test_blends_passes_between_anchors_and_tracks_before_the_first(slow):
    scene, joints, body, poses = slow
    res = run(slow, "particle", anchor_frames=(2, 5), particles=200)
    assert list(res.frames) == list(range(6))
    # Anchor frames hold the anchors' poses exactly; the frames between are blended.
    np.testing.assert_allclose(res.joints3d[5], body.joints(poses[5]), atol=1e-9)
    assert np.all(res.spread[[2, 5]] == 0) and np.all(res.spread[[0, 1, 3, 4]].max(axis=1) > 0)
    assert mpjpe(res, joints).max() < 0.05


@pytest.mark.slow
def test_passes_between_anchors_meet_past_the_middle(slow, monkeypatch):
    """Each pass tracks to a little past the middle, and goes on when its partner lost the
    body: passes advance in turn, each with its own anchor appearance and search draws, so
    going on gives what whole passes give."""
    scene, joints, body, poses = slow
    calls = []
    res = run(slow, "hybrid", anchor_frames=(0, 5), particles=100, blend_reach=0,
              progress=lambda d, t: calls.append((d, t)))
    # forward 1..2, backward 4..2
    assert calls[-1] == (5, 5) and list(res.frames) == list(range(6))
    assert mpjpe(res, joints).max() < 0.05
    whole = run(slow, "hybrid", anchor_frames=(0, 5), particles=100, blend_reach=None)
    monkeypatch.setattr(DR, "extend_passes", lambda *a, **kw: (4, 1))
    calls, said = [], []
    res = run(slow, "hybrid", anchor_frames=(0, 5), particles=100, blend_reach=0,
              progress=lambda d, t: calls.append((d, t)), log=said.append)
    assert calls[-1] == (8, 8)
    assert "frames 0-5: 2 passes go on where the other lost the body" in said
    np.testing.assert_allclose(res.joints3d, whole.joints3d, atol=1e-9)


def test_cancel_keeps_the_frames_done(slow):
    done = []
    res = run(slow, "hybrid", particles=100, progress=lambda d, t: done.append(d),
              cancel=lambda: len(done) >= 2)
    assert list(res.frames) == [0, 1, 2]
    assert res.extra["cancelled"] is True and res.spread.shape[0] == 3


def test_bad_input(slow):
    scene, joints, body, poses = slow
    cams = {c.name: c for c in scene.cameras}
    plates = synth.scene_plates(scene)
    anchors = anchors_at(scene, joints, [0])
    init = InitResult(body, {0: poses[0]}, cams)
    with pytest.raises(ZoopraxisError, match="hybrid tracker needs a calibration"):
        T.track_filter(plates, anchors, None, init=init)
    with pytest.raises(ZoopraxisError, match="unknown tracker 'kalman'"):
        T.track_filter(plates, anchors, cams, init=init, tracker="kalman")
    with pytest.raises(ZoopraxisError, match="number of particles"):
        T.track_filter(plates, anchors, cams, init=init, particles=0)
    with pytest.raises(ZoopraxisError, match="unknown motion prior 'run'"):
        T.track_filter(plates, anchors, cams, init=init, prior="run")
    with pytest.raises(ZoopraxisError, match="no camera for view 'cam1'"):
        T.track_filter(plates, anchors, {"cam0": cams["cam0"]}, init=init)
    with pytest.raises(ZoopraxisError, match="outside the take"):
        T.track_filter(plates, anchors, cams, init=init, frames=range(0, 50))
    with pytest.raises(ZoopraxisError, match="no marker anchor inside frames 3:6"):
        T.track_filter(plates, anchors, cams, init=init, frames=range(3, 6))
    with pytest.raises(ZoopraxisError, match="view 'cam1': calibration image size"):
        T.track_filter(plates, anchors, {"cam0": cams["cam0"], "cam1": cams["cam1"].scaled(0.5)},
                     init=init)


# -- the pieces: the guided refinement and the filter's feedback --------------------------------


def test_guided_tracker_starts_from_the_proposal(slow):
    scene, joints, body, poses = slow
    tracker = hybrid.GuidedTracker(body, True)
    a = State(np.stack([poses[0].root] * 2), poses[0].angles.copy(), list(scene.cameras))
    b = State(np.stack([poses[3].root] * 2), poses[3].angles.copy(), list(scene.cameras))
    assert np.allclose(tracker.predict(b, a).angles,
                       body.clamp(b.angles + 0.5 * (b.angles - a.angles)))
    tracker.proposal = a
    assert np.array_equal(tracker.predict(b, a).angles, a.angles)


def test_search_groups_cover_every_parameter_once(slow):
    scene, joints, body, poses = slow
    groups = hybrid.search_groups(body, fps=60.0)
    cols = np.concatenate([c for c, _ in groups])
    assert sorted(cols) == list(range(6 + body.n_dofs))
    # Half the time between frames, half the motion to search.
    assert groups[0][1][0] == pytest.approx(0.5 * hybrid.SEARCH_WIDTHS["root"][0])


class QuadraticScore:
    """A stand-in for the filter: log-likelihood peaked at a known pose (1 cm, 0.02 rad)."""

    def __init__(self, body, target):
        self.body, self.target = body, target

    def score(self, roots, angles):
        return -(np.sum((roots[:, :3, 3] - self.target.root[:3, 3]) ** 2, axis=1) / 0.01 ** 2
                 + np.sum((angles - self.target.angles) ** 2, axis=1) / 0.02 ** 2)


def test_partitioned_search_finds_each_limb(slow, rng):
    scene, joints, body, poses = slow
    target = poses[0]
    start = target.copy()
    start.root = se3.transform(None, [0.03, -0.02, 0.0]) @ start.root
    knee, elbow = body.dof_index("l_knee_flex"), body.dof_index("r_elbow_flex")
    start.angles[knee] += 0.25
    start.angles[elbow] -= 0.3
    score = QuadraticScore(body, target)
    found = hybrid.partitioned_search(score, start, hybrid.search_groups(body), 500, rng)
    # One pass of 500 draws per group is a coarse search: it removes much of each offset (the
    # refinement does the rest), and never makes the pose worse.
    assert np.linalg.norm(found.root[:3, 3] - target.root[:3, 3]) < 0.5 * 0.036
    assert abs(found.angles[knee] - target.angles[knee]) < 0.6 * 0.25
    assert abs(found.angles[elbow] - target.angles[elbow]) < 0.4 * 0.3
    before, after = (score.score(p.root[None], p.angles[None])[0] for p in (start, found))
    assert after > before
    # What was already right stays exactly so: the current pose is always among the draws.
    others = [body.dof_index(n) for n in ("l_shoulder_flex", "r_knee_flex", "neck_flex")]
    np.testing.assert_array_equal(found.angles[others], target.angles[others])


def test_filter_scores_poses_like_its_particles(slow):
    scene, joints, body, poses = slow
    images = [[scene.render_frame(k, v)[0] for v in range(2)] for k in range(2)]
    pf = particle.ParticleFilter(body, scene.cameras, SmoothMotionPrior(body), n_particles=50,
                                 seed=1)
    pf.start(images[0], poses[0])
    with pytest.raises(ZoopraxisError, match="score\\(\\) needs a frame weighed by step"):
        pf.score(poses[1].root[None], poses[1].angles[None])
    step = pf.step(images[1])
    np.testing.assert_allclose(pf.score(step.roots[:5], step.angles[:5]),
                               step.log_likelihood[:5], rtol=1e-6)
    # The true pose explains the frame better than a pose 5 cm off.
    off = se3.transform(None, [0.05, 0.0, 0.0]) @ poses[1].root
    ll = pf.score(np.stack([poses[1].root, off]), np.stack([poses[1].angles] * 2))
    assert ll[0] > ll[1]


def test_recentre_moves_particles_onto_the_refined_pose(slow, rng):
    scene, joints, body, poses = slow
    images = [scene.render_frame(0, v)[0] for v in range(2)]
    prior = SmoothMotionPrior(body)
    pf = particle.ParticleFilter(body, scene.cameras, prior, n_particles=400, seed=1)
    pf.start(images, poses[0])
    refined = Pose(se3.transform(None, [0.3, 0.0, 0.0]) @ poses[0].root, poses[0].angles)
    pf.recentre(refined, 0.25, previous=poses[0], spread=np.zeros(6 + body.n_dofs))
    moved = np.isclose(pf.state["t"][:, 0], refined.root[0, 3])
    assert moved.sum() == 100
    # The fresh particles carry the motion from the previous pose as their velocity.
    np.testing.assert_allclose(pf.state["dt"][moved, 0].mean(), 0.3, atol=0.01)
    np.testing.assert_allclose(pf.weights, 1.0 / 400)
    assert np.array_equal(pf.pose.root, refined.root)
    with pytest.raises(ZoopraxisError, match="recentre fraction must be in"):
        pf.recentre(refined, 1.5)


# -- the command line -------------------------------------------------------------------------


def test_command_line_runs_the_hybrid(tmp_path):
    from tests.conftest import shared_data_dir

    data = shared_data_dir()
    if data is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    take = tmp_path / "take"
    scene, joints = synth.take_from_bvh(data / "cmu_mocap" / "131_02.bvh",
                                        frames=slice(200, 204), views=2, image_size=(320, 240),
                                        noise=1.0, clutter=4)
    synth.write_take(take, scene, joints, marker_noise=1.0)
    out = tmp_path / "result.json"
    args = ["track", "--plate", f"cam0={take / 'cam0'}", "--plate", f"cam1={take / 'cam1'}",
            "--markers", take / "markers.json", "--calibration", take / "calibration.json",
            "--tracker", "hybrid", "--particles", "150", "--out", out]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    run_ = subprocess.run([sys.executable, "-m", "zoopraxis", *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=300)
    assert run_.returncode == 0, run_.stderr
    assert "track: 4 frames" in run_.stdout
    res = result_io.read_result(out)
    assert res.extra["tracker"] == "hybrid" and res.spread.shape[0] == 4
    assert np.linalg.norm(res.joints3d - joints, axis=2).mean() < 0.05
    # Uncalibrated plates: a one-line reason, no traceback.
    bad = subprocess.run([sys.executable, "-m", "zoopraxis", *map(str, args[:7]), "--tracker",
                          "particle", "--out", tmp_path / "other.json"],
                         capture_output=True, text=True, env=env, timeout=300)
    assert bad.returncode != 0 and "needs a calibration" in bad.stderr
    assert len(bad.stderr.strip().splitlines()) == 1


# -- status from the silhouette -----------------------------------------------------------------


def test_coverage_status_thresholds():
    drop, limb = FS.COVERAGE_DROP, FS.LIMB_ON_FOREGROUND
    assert FS.coverage_status(0.9, 0.9) == "ok"
    assert FS.coverage_status(0.9 - 1.5 * drop, 0.9) == "uncertain"
    assert FS.coverage_status(0.9 - 2.5 * drop, 0.9) == "lost"
    assert FS.coverage_status(float("nan"), 0.9) == "ok"
    assert FS.coverage_status(0.9, 0.9, 0.9) == "ok"
    assert FS.coverage_status(0.9, 0.9, 0.8 * limb) == "uncertain"
    assert FS.coverage_status(0.9, 0.9, 0.4 * limb) == "lost"


def test_a_pose_off_the_silhouette_is_not_ok(slow):
    """The refinement can fit the image motion of limbs that slid off the body; their points
    on the background, or the foreground they no longer cover, flag the frame."""
    from zoopraxis.core.imaging import render

    scene, joints, body, poses = slow
    pf = particle.ParticleFilter(body, scene.cameras, SmoothMotionPrior(body), n_particles=10,
                                 silhouette=1.0)
    masks = [render.render(c, body.seg2world(poses[3]), body.primitives(), want=()).label >= 0
             for c in scene.cameras]
    pf.start([scene.render_frame(2, c)[0] for c in range(len(scene.cameras))], poses[2])
    pf.step([scene.render_frame(3, c)[0] for c in range(len(scene.cameras))], masks)
    reference = FS.covered_at(pf, poses[3])
    assert reference > 0.9
    covered, limb = FS.silhouette_fit(pf, poses[3])
    assert covered == reference and limb > 0.8
    assert FS.coverage_status(covered, reference, limb) == "ok"
    arms_off = poses[3].copy()
    for dof in ("l_shoulder_abd", "r_shoulder_abd"):
        arms_off.angles[body.dof_index(dof)] += 0.9
    for dof in ("l_shoulder_flex", "r_shoulder_flex"):
        arms_off.angles[body.dof_index(dof)] += 0.6
    covered, limb = FS.silhouette_fit(pf, arms_off)
    assert limb < 0.5 and FS.coverage_status(covered, reference, limb) != "ok"
    away = poses[3].copy()
    away.root[:3, 3] += [0.25, 0.25, 0.0]
    covered, limb = FS.silhouette_fit(pf, away)
    assert FS.coverage_status(covered, reference, limb) == "lost"
