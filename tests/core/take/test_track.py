"""Tracking a take: anchors, passes, blending, status, cancel, and bad input."""

import numpy as np
import pytest

from zoopraxis.core.body import fit3d
from zoopraxis.core.geometry import se3
from zoopraxis.core.synthetic import synth
from zoopraxis.core.files.initfile import InitResult
from zoopraxis.core.take import track as T
from zoopraxis.core.take import backgrounds as BG
from zoopraxis.core.trackers import differential as D
from zoopraxis.core.take import driver as DR
from zoopraxis.core.take import passes as P
from zoopraxis.core.take import status as S
from zoopraxis.core.take import workers as W
from zoopraxis.core.trackers import stepper as stepper_module
from zoopraxis.core.body.body import Pose
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import STANDARD_JOINTS
from zoopraxis.core.files.markers import Anchor

N = 8


@pytest.fixture(scope="module")
def take():
    from tests.conftest import slow_walk_take

    # a slow walk: frame-to-frame joint motion of about 2 cm
    scene, joints = slow_walk_take(N)
    body, poses, _ = fit3d.fit_sequence(joints)
    return scene, joints, body, poses


def anchors_at(scene, joints, frames):
    out = []
    for f in frames:
        out.append(Anchor(f, {c.name: dict(zip(STANDARD_JOINTS, map(tuple, c.project(joints[f]))))
                              for c in scene.cameras}))
    return out


def run(take, anchor_frames=(0,), **kw):
    scene, joints, body, poses = take
    cams = {c.name: c for c in scene.cameras}
    init = InitResult(body, {f: poses[f] for f in anchor_frames}, cams)
    return T.track(synth.scene_plates(scene), anchors_at(scene, joints, anchor_frames), cams,
                   init=init, **kw)


def test_tracks_a_short_walk(take):
    scene, joints, body, poses = take
    calls = []
    res = run(take, progress=lambda d, t: calls.append((d, t)))
    assert list(res.frames) == list(range(N)) and res.mode == "calibrated"
    error = np.linalg.norm(res.joints3d - joints, axis=2).mean()
    # two small views, a background from 8 frames: the benchmark measures real accuracy
    assert error < 0.045
    for c in scene.cameras:
        px = np.linalg.norm(res.joints2d[c.name] - c.project(joints), axis=2).mean()
        assert px < 4.0
        assert res.residual[c.name].shape == (N,) and np.all(res.residual[c.name][1:] > 0)
    assert res.status[0] == "ok" and set(res.status) <= {"ok", "uncertain", "lost"}
    # two rounds: the second with backgrounds that keep the first round's body out
    assert calls[-1] == (2 * (N - 1), 2 * (N - 1))
    assert all(b[0] >= a[0] and b[1] == calls[0][1] for a, b in zip(calls, calls[1:]))
    assert res.angles.shape == (N, body.n_dofs) and res.roots.shape == (N, 4, 4)


def test_the_limb_search_draws_broadly_in_the_last_round_only(take, monkeypatch):
    """The first of two rounds tracks the body for the second round's backgrounds; the
    search's broad draws of the arms (its dearest part) are left to the round that counts."""
    from zoopraxis.core.trackers.recover import LimbSearch
    DifferentialStepper = stepper_module.DifferentialStepper
    seen, broad = [], []
    begins, draw = DifferentialStepper.round_begins, LimbSearch._broad

    def record(self, index, rounds):
        begins(self, index, rounds)
        seen.append((index, rounds, self.tracker.search.broad))
        broad.append(0)

    def count(self, *args, **kwargs):
        broad[-1] += 1
        return draw(self, *args, **kwargs)
    monkeypatch.setattr(DifferentialStepper, "round_begins", record)
    monkeypatch.setattr(LimbSearch, "_broad", count)
    run(take)
    assert seen == [(0, 2, False), (1, 2, True)]
    assert broad[0] == 0 and broad[1] > 0


def test_later_anchor_pulls_the_end_back(take):
    scene, joints, body, poses = take
    res = run(take, anchor_frames=(0, N - 1))
    # anchor frames hold exactly the anchors' poses
    assert np.allclose(res.joints3d[N - 1], body.joints(poses[N - 1]), atol=1e-9)
    error = np.linalg.norm(res.joints3d - joints, axis=2).mean(axis=1)
    assert error.max() < 0.06
    # blended frames carry limb scores measured on the blended pose (they feed the status)
    blended = res.extra["limb_fit"][N // 2]
    assert set(blended) == {"left leg", "right leg", "left arm", "right arm"}
    assert all(-1.0 <= v <= 1.0 for v in blended.values())
    # ... and their unexplained foreground, with the anchor's as the reference
    assert 0.0 <= res.extra["unexplained"][N // 2][0] < 0.25
    assert all(0.0 <= u < 0.25 for u in res.extra["unexplained_anchor"])


def test_unexplained_foreground_flags_a_body_that_left_the_person(take):
    """A pose that covers the person well by overlap but leaves a limb's pixels unexplained:
    the measure rises well above the anchor's and the frame is not called ok."""
    scene, joints, body, poses = take
    from zoopraxis.core.trackers.differential import DifferentialTracker, State

    cams = [c for c in scene.cameras]
    tracker = DifferentialTracker(body, True)
    true = State(np.stack([poses[0].root] * len(cams)), poses[0].angles.copy(), cams)
    moved = true.copy()
    names = list(body.dof_names)
    for side in ("l", "r"):
        moved.angles[names.index(f"{side}_hip_flex")] += np.radians(90.0)
        moved.angles[names.index(f"{side}_shoulder_flex")] += np.radians(90.0)
    plates = synth.scene_plates(scene)
    colours = [plates[c.name].read(0) for c in cams]
    from zoopraxis.core.imaging.background import estimate_background

    backgrounds = [estimate_background([plates[c.name].read(f) for f in range(N)])
                   for c in cams]
    use = [True] * len(cams)
    fit0, iou0, u0, _ = S.silhouette_measures(tracker, true, colours, backgrounds, use)
    fit1, iou1, u1, _ = S.silhouette_measures(tracker, moved, colours, backgrounds, use)
    assert np.all(u0 < 0.1)
    assert np.max(u1 - u0) > S.UNEXPLAINED_UNCERTAIN
    assert S.frame_status(fit1 / fit0, iou1 / iou0, 1.0, None, u1 - u0) != "ok"
    assert S.frame_status([1.0] * len(cams), [1.0] * len(cams), 1.0, None, u1 - u0) \
        == "uncertain"
    assert S.frame_status(fit0 / fit0, iou0 / iou0, 1.0, None, u0 - u0) == "ok"


def test_a_limb_unexplained_in_two_views_makes_a_frame_uncertain():
    """A lost limb leaves a limb-sized blob unexplained in every view that sees it; one view's
    blob of that size alone (a sleeve, a shadow the background kept) does not."""
    ones = [1.0, 1.0, 1.0]
    limb = S.UNEXPLAINED_TWO_VIEWS * 1.5
    assert S.UNEXPLAINED_TWO_VIEWS * 1.5 < S.UNEXPLAINED_UNCERTAIN
    assert S.frame_status(ones, ones, 1.0, None, [limb, limb, 0.0]) == "uncertain"
    assert S.frame_status(ones, ones, 1.0, None, [limb, 0.0, 0.0]) == "ok"
    assert S.frame_status(ones, ones, 1.0, None, [limb, np.nan, np.nan]) == "ok"
    assert S.frame_status(ones, ones, 1.0, None, [0.5 * S.UNEXPLAINED_TWO_VIEWS] * 3) == "ok"


def test_unexplained_fraction_counts_thick_blobs_only():
    labels = np.full((60, 80), -1)
    labels[10:30, 10:30] = 0                                        # the model: 400 px
    fg = labels >= 0
    fg = fg.copy()
    fg[40:50, 50:70] = True                                         # a 10 x 20 blob: 200 px
    fg[5, :] = True                                                 # a one-pixel line: noise
    assert S.unexplained_fraction(fg, labels) == pytest.approx(0.5, abs=0.03)
    known = np.ones_like(fg)
    known[40:50, 50:70] = False                                     # never seen empty there
    assert S.unexplained_fraction(fg, labels, known) < 0.02


def test_tracks_backward_before_the_first_anchor(take):
    scene, joints, body, poses = take
    res = run(take, anchor_frames=(3,), frames=range(0, 6))
    assert list(res.frames) == list(range(6))
    assert np.linalg.norm(res.joints3d - joints[:6], axis=2).mean() < 0.05


def test_cancel_keeps_the_frames_done(take):
    done = []

    def progress(d, t):
        done.append(d)

    res = run(take, progress=progress, cancel=lambda: len(done) >= 3)
    assert list(res.frames) == [0, 1, 2, 3]
    assert res.extra["cancelled"] is True


class FrozenPlate:
    """A synthetic plate rendered once (the scene's sensor noise is drawn anew at every
    render), so that two runs see the same images."""

    def __init__(self, plate):
        self.name, self.path, self.fps = plate.name, plate.path, plate.fps
        self.image_size, self.num_frames = plate.image_size, plate.num_frames
        self.images = [plate.read(f) for f in range(plate.num_frames)]

    def __len__(self):
        return self.num_frames

    def read(self, frame, **_):
        return self.images[frame]


@pytest.mark.slow
def test_passes_in_worker_processes_give_the_same_track(take, monkeypatch):
    """Three anchors make five passes; forked workers track them side by side, and measure
    the silhouettes of the blended frames, and the result is the one tracking them in turn
    gives, progress included."""
    if not W._can_fork():
        pytest.skip("worker processes fork: Linux only")
    import os

    scene, joints, body, poses = take
    cams = {c.name: c for c in scene.cameras}
    frozen = {k: FrozenPlate(p) for k, p in synth.scene_plates(scene).items()}
    anchors = anchors_at(scene, joints, (0, 3, 6))
    init = InitResult(body, {f: poses[f] for f in (0, 3, 6)}, cams)
    parent = os.getpid()
    measured_here = []
    measure = S.silhouette_measures

    def counted(*args, **kw):
        if os.getpid() == parent:
            measured_here.append(1)
        return measure(*args, **kw)

    monkeypatch.setattr(DR, "silhouette_measures", counted)
    monkeypatch.setattr(BG, "silhouette_measures", counted)
    calls = {1: [], 2: []}
    here = {}
    res = {}
    for w in (1, 2):
        measured_here.clear()
        res[w] = T.track(frozen, anchors, cams, init=init, workers=w,
                         progress=lambda d, t, w=w: calls[w].append((d, t)))
        here[w] = len(measured_here)
    # the blended frames 1, 2, 4, 5 of each round: measured in the parent when in turn, in
    # the workers else; the first anchor is measured again in the parent against the second
    # round's backgrounds (its frames were measured against them as they were tracked)
    assert here == {1: 2 * 4 + 1, 2: 1}
    assert list(res[2].frames) == list(range(N))
    assert np.array_equal(res[1].angles, res[2].angles)
    assert np.array_equal(res[1].roots, res[2].roots)
    assert res[1].status == res[2].status
    for key in ("silhouette_fit", "silhouette_iou", "unexplained", "limb_fit"):
        assert repr(res[1].extra[key]) == repr(res[2].extra[key]), key
    # 2 + 2 + 2 + 2 + 1 frames tracked (blended stretches twice, the anchors not again)
    # in each of two rounds, all reported
    assert calls[1][-1] == calls[2][-1] == (18, 18)


def test_cancel_with_worker_processes_keeps_what_they_tracked(take):
    if not W._can_fork():
        pytest.skip("worker processes fork: Linux only")
    res = run(take, anchor_frames=(0, 6), workers=2, cancel=lambda: True)
    assert res.extra["cancelled"] is True
    assert {0, 6} <= set(res.frames)


def test_worker_processes_with_view_threads(take):
    """The parent's thread pools (views, next-frame images) exist before the fork; a child
    must make its own instead of waiting on threads it does not have."""
    if not W._can_fork():
        pytest.skip("worker processes fork: Linux only")
    from zoopraxis.core.trackers.differential import Settings

    res = run(take, anchor_frames=(0, 6), workers=2, settings=Settings(threads=2))
    assert list(res.frames) == list(range(N)) and not res.extra["cancelled"]


def test_an_error_in_a_worker_process_reaches_the_caller(take, monkeypatch):
    if not W._can_fork():
        pytest.skip("worker processes fork: Linux only")
    import os

    parent = os.getpid()
    prepare = stepper_module.prepare_images

    def failing(*args, **kw):
        if os.getpid() != parent:
            raise ZoopraxisError("view 'cam1', frame 4: cannot be prepared")
        return prepare(*args, **kw)

    monkeypatch.setattr(stepper_module, "prepare_images", failing)
    with pytest.raises(ZoopraxisError, match="frame 4: cannot be prepared"):
        run(take, anchor_frames=(0, 6), workers=2)


def test_uncalibrated_single_view(take):
    scene, joints, body, poses = take
    cam = scene.cameras[0]
    pose = poses[0]
    # The scaled-orthographic camera that best matches the perspective one near the body.
    depth = cam.depth(joints[0]).mean()
    body2world = pose.root
    R = cam.R @ body2world[:3, :3]
    t = cam.R @ body2world[:3, 3] + cam.t
    ortho = ScaledOrthoCamera(cam.name, cam.image_size, s=cam.K[0, 0] / depth, R=R, t=t,
                              c=cam.K[:2, 2])
    init = InitResult(body, {0: Pose(np.eye(4), pose.angles.copy())}, {cam.name: ortho})
    plates = {cam.name: synth.ScenePlate(scene, 0)}
    anchor = anchors_at(scene, joints, [0])[0]
    anchor.views = {cam.name: anchor.views[cam.name]}
    res = T.track(plates, [anchor], None, init=init)
    assert res.mode == "uncalibrated"
    px = np.linalg.norm(res.joints2d[cam.name] - cam.project(joints), axis=2).mean(axis=1)
    assert px.max() < 8.0
    # body-centred frame: the pelvis starts at the origin
    assert np.allclose(res.joints3d[0][0], 0.0, atol=1e-9)
    # one view does not see depth: only the anchor is ok
    assert res.status[0] == "ok" and "ok" not in res.status[1:]


def _near_camera(cam, pose):
    """The pinhole ``cam`` as a near ScaledOrthoCamera of a body-centred pose (``kappa`` the
    inverse depth of the pose's root), and as the scaled orthographic camera of the same
    scale."""
    R = cam.R @ pose.root[:3, :3]
    t = cam.R @ pose.root[:3, 3] + cam.t
    near = ScaledOrthoCamera(cam.name, cam.image_size, s=cam.K[0, 0] / t[2], R=R, t=t,
                             c=cam.K[:2, 2], kappa=1.0 / t[2])
    return near, near.replace(kappa=0.0)


def test_uncalibrated_near_view_tracks_through_its_perspective(take):
    """One view 2.3 m from the walker, anchored at both ends: given its perspective
    (``kappa``, as ``init --perspective`` fits it) the track follows the plate in pixels
    better than through the same camera made scaled orthographic, blending between anchors
    of two camera distances."""
    scene, joints, body, poses = take
    cam = scene.cameras[0]
    plates = {cam.name: synth.ScenePlate(scene, 0)}
    anchors = anchors_at(scene, joints, [0, N - 1])
    for anchor in anchors:
        anchor.views = {cam.name: anchor.views[cam.name]}
    px = {}
    for kind in (0, 1):
        per_frame = {f: {cam.name: _near_camera(cam, poses[f])[kind]} for f in (0, N - 1)}
        init = InitResult(body, {f: Pose(np.eye(4), poses[f].angles.copy()) for f in (0, N - 1)},
                         per_frame[0], per_frame)
        res = T.track(plates, anchors, None, init=init, blend_reach=None)
        px[kind] = np.linalg.norm(res.joints2d[cam.name] - cam.project(joints), axis=2)
        assert np.allclose(res.joints3d[0][0], 0.0, atol=1e-9)
    kappas = [_near_camera(cam, poses[f])[0].kappa for f in (0, N - 1)]
    assert abs(kappas[0] - kappas[1]) > 1e-3
    # the anchors themselves: 1-2 px through the perspective, 4 px without it
    assert px[0][[0, N - 1]].mean() < 2.0 < 3.0 < px[1][[0, N - 1]].mean()
    assert px[0].mean() < 0.6 * px[1].mean()


def test_bad_input(take):
    scene, joints, body, poses = take
    cams = {c.name: c for c in scene.cameras}
    plates = synth.scene_plates(scene)
    anchors = anchors_at(scene, joints, [0])
    init = InitResult(body, {0: poses[0]}, cams)
    with pytest.raises(ZoopraxisError, match="no camera for view 'cam1'"):
        T.track(plates, anchors, {"cam0": cams["cam0"]}, init=init)
    with pytest.raises(ZoopraxisError, match="outside the take"):
        T.track(plates, anchors, cams, init=init, frames=range(0, N + 5))
    with pytest.raises(ZoopraxisError, match="no marker anchor inside frames 4:8"):
        T.track(plates, anchors, cams, init=init, frames=range(4, N))
    small = cams["cam1"].scaled(0.5)
    with pytest.raises(ZoopraxisError, match="view 'cam1': calibration image size"):
        T.track(plates, anchors, {"cam0": cams["cam0"], "cam1": small}, init=init)
    missing = anchors_at(scene, joints, [0])
    for view in missing[0].views.values():
        view.pop("l_wrist")
    with pytest.raises(ZoopraxisError, match="joint 'l_wrist' is marked in no view"):
        T.track(plates, missing, cams, init=init)


def test_blend_states_interpolates():
    cams = [ScaledOrthoCamera("a", (10, 10), s=10.0)]
    a = D.State(np.eye(4)[None], np.zeros(3), cams)
    b = D.State(se3.exp_se3([0.2, 0, 0, 0, 0, 0.4])[None], np.ones(3), [cams[0].replace(s=40.0)])
    m = P.blend_states(a, b, 0.5)
    assert np.allclose(m.angles, 0.5)
    assert np.allclose(se3.log_se3(m.roots[0]), [0.1, 0, 0, 0, 0, 0.2])
    assert np.isclose(m.cameras[0].s, 20.0)


def test_blend_states_interpolates_a_near_cameras_distance():
    cams = [ScaledOrthoCamera("a", (10, 10), s=10.0, t=[0, 0, 2.0], kappa=0.5)]
    a = D.State(np.eye(4)[None], np.zeros(3), cams)
    b = D.State(np.eye(4)[None], np.ones(3), [cams[0].replace(s=40.0, kappa=0.25, t=[0, 0, 4])])
    m = P.blend_states(a, b, 0.5)
    assert np.isclose(m.cameras[0].s, 20.0) and np.isclose(m.cameras[0].kappa, 0.375)
    # the centre stays at depth 0, where the renderer has a pinhole's
    assert np.isclose(m.cameras[0].cam_from_world(m.cameras[0].center)[2], 0.0)
    # a camera fitted far (kappa 0) beside a near one: at its own end it is itself
    far = D.State(np.eye(4)[None], np.ones(3), [cams[0].replace(kappa=0.0, t=[0, 0, 10.0])])
    for w, kappa in ((0.0, 0.0), (0.5, 0.25), (1.0, 0.5)):
        m = P.blend_states(far, a, w)
        assert np.isclose(m.cameras[0].kappa, kappa)
        assert m.cameras[0].t[2] == (10.0 if w == 0.0 else 1.0 / kappa)


def test_frame_status_from_silhouettes_and_residuals():
    nan = np.nan
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0) == "ok"
    assert S.frame_status([1.0, 0.7], [1.0, 0.9], 1.0) == "uncertain"      # one view slips
    assert S.frame_status([0.5, 0.4], [1.0, 1.0], 1.0) == "lost"           # off the person
    assert S.frame_status([1.0, 1.0], [0.4, 0.5], 1.0) == "lost"           # shrunk into it
    assert S.frame_status([nan], [nan], 3.0) == "uncertain"                # no masks: residual
    assert S.frame_status([nan], [nan], 5.0) == "lost"
    # fast motion: a high residual with silhouettes that fit is uncertain, not lost
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 5.0) == "uncertain"
    assert S.frame_status([1.0, 0.95], [1.0, 0.55], 5.0) == "lost"
    # the body overlaps well but one limb lies outside the silhouettes
    limbs = {"left leg": 0.9, "right leg": 0.8, "left arm": 0.7, "right arm": 0.85}
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, limbs) == "ok"
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, {**limbs, "right leg": 0.3}) \
        == "uncertain"
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, {**limbs, "right leg": -0.6}) == "lost"
    # one view: a low score may be occlusion by the body; outside the silhouette is lost
    assert S.frame_status([1.0], [1.0], 1.0, {**limbs, "right leg": 0.3}) == "ok"
    assert S.frame_status([1.0], [1.0], 1.0, {**limbs, "right leg": -0.6}) == "lost"
    # the overlap holds but the person's own pixels are left unexplained in one view
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, None, [0.05, 0.1]) == "ok"
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, None, [0.05, 0.4]) == "uncertain"
    assert S.frame_status([1.0, 0.95], [1.0, 0.9], 1.0, None, [nan, nan]) == "ok"


def test_blend_weights_trust_the_pass_that_holds():
    from zoopraxis.core.trackers.differential import StepReport

    def reports(residuals, ious):
        return [StepReport(np.array([r, r]), np.array([i, i]), 0.0, 1)
                for r, i in zip(residuals, ious)]

    n = 9
    good = reports([3.0] * n, [0.7] * n)
    w = P.blend_weights(good, reports([3.0] * n, [0.7] * n))
    np.testing.assert_allclose(w, np.arange(1, n + 1) / (n + 1))   # by distance alone
    # the backward pass lost the body over the first frames: the blend keeps the forward one
    lost = reports([12.0] * 5 + [3.0] * 4, [0.3] * 5 + [0.7] * 4)
    w = P.blend_weights(good, lost)
    assert np.all(w[:3] < 0.02)
    assert w[-1] > 0.85
    # and the other way round
    w = P.blend_weights(lost, good)
    assert np.all(w[:3] > 0.9)
    # no silhouettes (no background model): residuals alone decide
    w = P.blend_weights(reports([3.0] * n, [np.nan] * n),
                        reports([12.0] * n, [np.nan] * n))
    assert np.all(w[:5] < 0.05) and np.all(w < 0.35)


@pytest.mark.slow
def test_passes_between_anchors_meet_past_the_middle(take):
    """Each pass tracks a little past the middle; the two are blended there, and each frame
    outside that stretch comes from its nearer anchor's pass."""
    scene, joints, body, poses = take
    assert P.blend_stretch(0, 100, 8) == (42, 58)
    assert P.blend_stretch(0, 7, None) == (1, 6) and P.blend_stretch(0, 7, 15) == (1, 6)
    passes, total = P.plan_passes([10, 100, 200], range(0, 300), 8)
    assert passes == [(10, 0, None), (10, 100, (47, 63)), (100, 200, (142, 158)),
                      (200, 299, None)]
    assert total == 10 + (53 + 53) + (58 + 58) + 99
    calls = []
    res = run(take, anchor_frames=(0, N - 1), blend_reach=1,
              progress=lambda d, t: calls.append((d, t)))
    # forward 1..4, backward 6..2: 4 + 5 frames instead of 6 + 6, in each of two rounds
    assert calls[-1] == (18, 18)
    assert list(res.frames) == list(range(N))
    error = np.linalg.norm(res.joints3d - joints, axis=2).mean(axis=1)
    assert error.max() < 0.06
    # blended frames carry limb scores measured on the blended pose; the others their pass's
    assert all(res.extra["limb_fit"][f] for f in (2, 3, 4))
    # adjacent anchors have nothing between them: 2..7 alone is tracked, 3..6 both ways
    calls = []
    res = run(take, anchor_frames=(0, 1, 2, N - 1), progress=lambda d, t: calls.append((d, t)))
    assert calls[-1] == (16, 16) and list(res.frames) == list(range(N))


@pytest.mark.slow
def test_a_pass_goes_on_where_its_partner_lost_the_body(take, monkeypatch):
    scene, joints, body, poses = take
    cams = {c.name: c for c in scene.cameras}
    frozen = {k: FrozenPlate(p) for k, p in synth.scene_plates(scene).items()}
    anchors = anchors_at(scene, joints, (0, N - 1))
    init = InitResult(body, {f: poses[f] for f in (0, N - 1)}, cams)
    # without the limb search: a pass that goes on draws its samples anew, and where a draw
    # moves a limb the two tracks part
    quiet = D.Settings(limb_search=False)
    full = T.track(frozen, anchors, cams, init=init, blend_reach=None, settings=quiet)
    asked = []

    def lost_early(forward, backward, lo, hi, reach, **kw):
        asked.append((sorted(forward), sorted(backward), lo, hi))
        return N - 2, 1         # both passes must reach the other anchor
    monkeypatch.setattr(DR, "extend_passes", lost_early)
    calls, said = [], []
    res = T.track(frozen, anchors, cams, init=init, blend_reach=1, settings=quiet,
                  progress=lambda d, t: calls.append((d, t)), log=said.append)
    assert asked == [([1, 2, 3, 4], [2, 3, 4, 5, 6], 2, 4)] * 2     # once a round
    assert "frames 0-7: 2 passes go on where the other lost the body" in said
    assert calls[-1] == (24, 24)
    assert all(b[0] >= a[0] for a, b in zip(calls, calls[1:]))
    # the passes went on from where they stopped: the poses of whole passes, blended over
    # the whole stretch
    np.testing.assert_allclose(res.joints3d, full.joints3d, atol=1e-4)
    if W._can_fork():
        # in worker processes the passes that go on start as soon as their pair is done
        calls = []
        forked = T.track(frozen, anchors, cams, init=init, blend_reach=1, workers=2,
                         settings=quiet, progress=lambda d, t: calls.append((d, t)))
        assert calls[-1] == (24, 24)
        assert np.array_equal(forked.joints3d, res.joints3d)


def test_extend_passes_follows_the_lost_pass():
    from zoopraxis.core.trackers.differential import StepReport

    def rep(r, iou):
        return StepReport(np.array([r, r]), np.array([iou, iou]), 0.0, 1)

    a, b, lo, hi, reach = 0, 60, 26, 34, 4
    good = {f: rep(3.0, 0.7) for f in range(a + 1, b)}
    forward = {f: good[f] for f in range(a + 1, hi + 1)}
    backward = {f: good[f] for f in range(lo, b)}
    assert P.extend_passes(forward, backward, lo, hi, reach) == (hi, lo)
    assert P.extend_passes({}, {}, 8, 7, reach) == (7, 8)       # anchors at 7 and 8
    # the forward pass lost the body from frame 12 to 20 and found it again
    lost_fwd = {f: rep(12.0, 0.3) if 12 <= f <= 20 else r for f, r in forward.items()}
    forward_to, backward_to = P.extend_passes(lost_fwd, backward, lo, hi, reach)
    assert forward_to == hi and 12 - reach - 2 <= backward_to <= 12 - reach + 2
    # the backward pass lost it near its anchor
    lost_bwd = {f: rep(12.0, 0.3) if f >= 50 else r for f, r in backward.items()}
    forward_to, backward_to = P.extend_passes(forward, lost_bwd, lo, hi, reach)
    assert backward_to == lo and forward_to == b - 1


def test_tracked_backgrounds_keep_the_body_out(take):
    """Eight frames of a slow walk: the first backgrounds hold the walker where they lingered;
    with the tracked body kept out of every sampled frame, the background behind the body is
    the scene's own or left unknown."""
    from zoopraxis.core.imaging.background import estimate_background
    from zoopraxis.core.trackers.differential import DifferentialTracker, State

    scene, joints, body, poses = take
    cams = list(scene.cameras)
    views = [c.name for c in cams]
    plates = synth.scene_plates(scene)
    source = DR.FrameSource(plates, views, {}, dict.fromkeys(views, 1.0))
    tracker = DifferentialTracker(body, True)
    states = {f: State(np.stack([poses[f].root] * len(cams)), poses[f].angles.copy(), cams)
              for f in range(N)}
    first = [estimate_background([plates[v].read(f) for f in range(N)]) for v in views]
    refined = BG.tracked_backgrounds(tracker, source, views, range(N), states, [True, False])
    assert refined[1] is None           # a view without silhouettes gets none
    clean = scene.backgrounds[0].astype(np.float32) / 255.0
    covered = np.zeros(clean.shape[:2], bool)
    for f in range(N):
        covered |= tracker.render_views(states[f])[0].label >= 0
    wrong_first = np.abs(first[0].image - clean).max(axis=2) > 0.15
    wrong_refined = np.abs(refined[0].image - clean).max(axis=2) > 0.15
    # behind the body the first estimate is often the walker; the refined one where it knows
    assert (wrong_first & covered & first[0].known).sum() > 0.1 * covered.sum()
    assert (wrong_refined & covered & refined[0].known).sum() \
        < 0.3 * (wrong_first & covered & first[0].known).sum()


def test_first_backgrounds_see_a_body_that_stood_still_away_from_its_anchor(shared_data):
    """The body at one place at the anchor frame, then still 0.7 m away for most of the take
    (a step into a lunge held): the most consistent colour there is the body's own, but the
    anchor frame shows the background there, seen again at the end of the take; the first
    backgrounds see the standing body as foreground."""
    from zoopraxis.core.files import cmu
    from zoopraxis.core.trackers.differential import DifferentialTracker, State

    motion = cmu.load_cmu(shared_data / "cmu_mocap" / "131_02.bvh", fps=30.0)
    n = 12
    sel = np.full(n, 200)
    joints = cmu.standard_joints(motion, frames=sel)
    jframes = cmu.standard_joint_frames(motion, frames=sel)
    shift = np.zeros((n, 3))
    shift[2:10, 0] = 0.7                     # still at +0.7 m in frames 2-9
    shift[10:, 0] = 1.4                      # and on again
    joints = joints + shift[:, None, :]
    jframes = jframes.copy()
    jframes[..., :3, 3] += shift[:, None, :]
    scene = synth.make_scene(joints, jframes, views=2, image_size=(320, 240), noise=1.0,
                             clutter=4)
    body, poses, _ = fit3d.fit_sequence(joints)
    cams = list(scene.cameras)
    views = [c.name for c in cams]
    source = DR.FrameSource(synth.scene_plates(scene), views, {}, dict.fromkeys(views, 1.0))
    tracker = DifferentialTracker(body, True)

    def state_at(f):
        return State(np.stack([poses[f].root] * len(cams)), poses[f].angles.copy(), cams)

    backgrounds, use_bg, *_ = BG.take_backgrounds(
        tracker, source, views, range(n), anchors_at(scene, joints, [0]), state_at,
        lambda message: None)
    for c in range(len(cams)):
        assert use_bg[c]
        body_at_5 = tracker.render_views(state_at(5))[c].label >= 0
        away = body_at_5 & ~(tracker.render_views(state_at(0))[c].label >= 0)
        seen = backgrounds[c].person(source.colour(5)[c])
        assert seen[away].mean() > 0.8
