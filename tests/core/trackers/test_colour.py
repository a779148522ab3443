"""Colour plates: the anchor's chromaticity holds what the grey image cannot tell apart."""

import numpy as np
import pytest

from zoopraxis.core.body import primitives
from zoopraxis.core.body.body import make_body
from zoopraxis.core.body.joints import JOINT_INDEX
from zoopraxis.core.geometry import se3
from zoopraxis.core.geometry.camera import ring_of_cameras
from zoopraxis.core.imaging.background import signed_distance
from zoopraxis.core.imaging.render import render
from zoopraxis.core.imaging import plates
from zoopraxis.core.synthetic import synth
from zoopraxis.core.trackers import differential as D
from zoopraxis.core.trackers.frames import chromaticity, prepare_images
from zoopraxis.core.trackers.light import measure, relit
from zoopraxis.core.trackers.recover import LimbSearch

# Two flat materials of one luma (0.299 R + 0.587 G + 0.114 B = 0.33), BGR: a blue shirt and
# skin-coloured arms.
SHIRT = (0.6, 0.3, 0.3)
SKIN = (0.2, 0.25, 0.55)


def test_chromaticity_is_the_colour_without_its_brightness(rng):
    colour = rng.uniform(0.2, 1.0, (8, 8, 3)).astype(np.float32)
    bright, dim = chromaticity(colour), chromaticity(0.6 * colour)
    assert len(bright) == 2
    assert np.allclose(bright[0], dim[0], atol=0.05) and np.allclose(bright[1], dim[1], atol=0.05)
    red = np.zeros((4, 4, 3), np.uint8)
    red[..., 2] = 200
    assert chromaticity(red)[0].min() > 0.7      # r of pure red
    grey = np.repeat(rng.integers(0, 255, (6, 6, 1), dtype=np.uint8), 3, axis=2)
    assert chromaticity(grey) is None and chromaticity(grey[..., 0]) is None


def _arm_over_the_shirt(monkeypatch, body, poses, cams):
    """Plates of ``body`` under flat light, in a flat shirt and flat skin-coloured arms of the
    shirt's grey level, before a wall of the shirt's colour: in grey, nothing but a flat image."""
    monkeypatch.setitem(synth._MATERIALS, "flat_shirt", (SHIRT, 0.0, 1.0, 0.0))
    monkeypatch.setitem(synth._MATERIALS, "flat_skin", (SKIN, 0.0, 1.0, 0.0))
    arms = [k for k, n in enumerate(body.segment_names) if n.endswith(("upper_arm", "forearm"))]
    materials = ["flat_skin" if k in arms else "flat_shirt" for k in range(body.n_segments)]
    sb = synth.SynthBody(list(body.segment_names), materials, body.primitives(),
                         np.stack([body.seg2world(p) for p in poses]))
    # behind, a wall of the shirt's colour as it is lit (the light comes from behind the body)
    bgs = [np.full((240, 320, 3), 0.35 * np.array(SHIRT), np.float32) for _ in cams]
    scene = synth.Scene(sb, cams, bgs, light=np.array([0.0, 1.0, 0.0]))
    return [[scene.render_frame(f, c) for c in range(len(cams))] for f in range(len(poses))]


def _anchored(body, settings, frame, cams, right, wrong):
    """A tracker anchored at pose ``right`` on ``frame`` (colour plates and their labels, one
    per camera), the frame's prepared images, and the states at ``right`` and ``wrong``."""
    images = [prepare_images(plates.to_gray_float(image), settings.levels,
                             settings.smooth_sigma, label >= 0, colour=image)
              for image, label in frame]
    tracker = D.DifferentialTracker(body, True, settings)
    V = len(cams)
    at_right = D.State(np.stack([right.root] * V), right.angles.copy(), list(cams))
    at_wrong = D.State(np.stack([right.root] * V), wrong.angles.copy(), list(cams))
    tracker.set_anchor(at_right, images, tracker.render_views(at_right))
    return tracker, images, at_right, at_wrong


@pytest.mark.parametrize("chroma_weight", [0.5, 0.0])
def test_the_anchors_colour_tells_an_arm_from_a_shirt_of_its_grey(monkeypatch, chroma_weight):
    """A forearm across the belly, skin-coloured on a shirt of the same grey level. Moved to
    another place over the shirt, it looks as much like itself in grey as where it is; the
    anchor's chromaticity tells the two apart: in the appearance that judges the limb search's
    moves, and in the step, which brings the arm back."""
    body = make_body("full")
    p0 = body.rest_pose(se3.transform(p=[0, 0, 0.95]))
    for name, value in (("l_shoulder_flex", 0.3), ("l_elbow_flex", 1.6), ("l_shoulder_rot", 1.0)):
        p0.angles[body.dof_index(name)] = value
    wrong = p0.copy()
    wrong.angles[body.dof_index("l_shoulder_rot")] = 0.7     # the forearm higher on the belly
    cams = sorted(ring_of_cameras(8, 3.5, 1.3, [0, 0, 0.9], (320, 240), 350),
                  key=lambda c: (c.R.T @ -c.t)[1])[:2]         # the two facing the body
    settings = D.Settings(chroma_weight=chroma_weight, limb_search=False)
    (frame,) = _arm_over_the_shirt(monkeypatch, body, [p0], cams)
    tracker, images, right, moved = _anchored(body, settings, frame, cams, p0, wrong)
    arm = np.array([body.segment_names.index(n) for n in ("l_upper_arm", "l_forearm")])
    shift = 1000 * np.linalg.norm(body.joints(wrong) - body.joints(p0), axis=1).max()
    assert shift > 60
    looks = [tracker.limb_appearance(s, tracker.render_views(s), images, arm)
             for s in (right, moved)]
    assert min(n for _, n in looks) > 50
    assert looks[0][0] < 0.05
    # a step on this frame from the wrong arm: the image motion says "stay", the grey
    # anchor nothing; the colour brings the arm back
    state, _ = tracker.step(moved, images, images)
    err = 1000 * np.linalg.norm(body.joints(state.pose()) - body.joints(p0), axis=1).max()
    if chroma_weight > 0:
        assert looks[1][0] > looks[0][0] + 0.1
        assert err < 25
    else:
        assert looks[1][0] < looks[0][0] + 0.05
        assert err > 40


@pytest.mark.parametrize("relight", [True, False])
def test_the_anchor_follows_the_light_on_the_body(monkeypatch, relight):
    """The performer walks from sunlight into shade after the anchor frame: the body is
    darker and bluer. The step measures the light's change on the whole body at the frame
    before (the grey levels' gain, the chromaticity's shift beyond the darkening's) and
    compares the anchor with the frame under it, so its colour still brings a wrongly moved
    arm back. Compared as it was, every point of the anchor is off by the light's change and
    the arm is pulled further off."""
    body = make_body("full")
    p0 = body.rest_pose(se3.transform(p=[0, 0, 0.95]))
    for name, value in (("l_shoulder_flex", 0.3), ("l_elbow_flex", 1.6), ("l_shoulder_rot", 1.0)):
        p0.angles[body.dof_index(name)] = value
    wrong = p0.copy()
    wrong.angles[body.dof_index("l_shoulder_rot")] = 0.7
    cams = sorted(ring_of_cameras(8, 3.5, 1.3, [0, 0, 0.9], (320, 240), 350),
                  key=lambda c: (c.R.T @ -c.t)[1])[:2]
    settings = D.Settings(limb_search=False, relight=relight)
    (frame,) = _arm_over_the_shirt(monkeypatch, body, [p0], cams)

    def prepared(images):
        return [prepare_images(plates.to_gray_float(image), settings.levels,
                               settings.smooth_sigma, label >= 0, colour=image)
                for image, (_, label) in zip(images, frame)]

    sun = prepared([image for image, _ in frame])
    # shade: 60 % of the light, bluer (BGR gains)
    shade = prepared([np.rint(image * np.float32([0.8, 0.6, 0.45])).astype(np.uint8)
                      for image, _ in frame])
    tracker = D.DifferentialTracker(body, True, settings)
    right = D.State(np.stack([p0.root] * 2), p0.angles.copy(), list(cams))
    moved = D.State(np.stack([p0.root] * 2), wrong.angles.copy(), list(cams))
    tracker.set_anchor(right, sun, tracker.render_views(right))
    state, _ = tracker.step(moved, shade, shade)
    err = 1000 * np.linalg.norm(body.joints(state.pose()) - body.joints(p0), axis=1).max()
    if relight:
        # measured on the body: 60 % of the light, and a chromaticity less red than the
        # darkening alone makes it
        gain, red, _ = tracker.light[0]
        assert 0.55 < gain < 0.65 and red < -0.03
        assert err < 25
    else:
        assert tracker.light is None
        assert err > 40


def test_the_light_measured_on_the_body_predicts_the_anchor_under_it(rng):
    """A darker light changes the chromaticity too (its offset for dark pixels weighs more):
    the gain alone predicts that exactly; a tint is the median shift beyond it."""
    colour = rng.uniform(0.05, 0.9, (1, 400, 3)).astype(np.float32)

    def values(c):
        return plates.to_gray_float(c)[0], [ch[0] for ch in chromaticity(c)]

    anchor = values(colour)
    for gains, tinted in (((0.5, 0.5, 0.5), False), ((0.55, 0.5, 0.45), True)):
        now = values(colour * np.float32(gains))
        light = measure(*anchor, *now)
        gray, chroma = relit(*anchor, light)
        assert np.allclose(gray, now[0], rtol=0.1)
        worst = max(np.abs(c - n).max() for c, n in zip(chroma, now[1]))
        assert worst < (0.02 if tinted else 1e-4)
        # as it was, the anchor's chromaticity is further off than the robust scale
        assert max(np.abs(c - n).max() for c, n in zip(anchor[1], now[1])) > 0.04
    assert measure(anchor[0][:10], None, anchor[0][:10], None) is None     # too few points


def _bare_hands(monkeypatch, body, pose, cams, bare=()):
    """Plates of ``body`` at ``pose`` in a flat shirt with long sleeves and bare,
    skin-coloured hands, before a grey wall, under flat light; the segments named in ``bare``
    are bare too, the hands of the arms not in it gloved in the shirt's colour if ``bare``
    names any."""
    monkeypatch.setitem(synth._MATERIALS, "flat_shirt", (SHIRT, 0.0, 1.0, 0.0))
    monkeypatch.setitem(synth._MATERIALS, "flat_skin", (SKIN, 0.0, 1.0, 0.0))
    prims = body.primitives()
    search = LimbSearch(body)
    hands = list(search.ends.values())
    # each hand its own painted part, moving with its forearm
    segment = prims.segment.copy()
    S = body.n_segments
    for k, p in enumerate(hands):
        segment[p] = S + k
    painted = primitives.Primitives(segment, prims.kind, prims.prim2seg, prims.size,
                                    prims.taper)
    T = body.seg2world(pose)
    T = np.concatenate([T, T[[prims.segment[p] for p in hands]]])[None]
    materials = (["flat_skin" if n in bare else "flat_shirt" for n in body.segment_names]
                 + ["flat_skin" if not bare or body.segment_names[prims.segment[p]] in bare
                    else "flat_shirt" for p in hands])
    sb = synth.SynthBody(list(body.segment_names) + ["hand"] * len(hands), materials, painted,
                         T)
    bgs = [np.full((240, 320, 3), 0.5, np.float32) for _ in cams]
    scene = synth.Scene(sb, cams, bgs, light=np.array([0.0, 1.0, 0.0]))
    return [scene.render_frame(0, c) for c in range(len(cams))]


@pytest.mark.parametrize("hands", [True, False])
def test_a_hand_lost_in_front_of_the_shirt_is_found_by_its_colour(monkeypatch, hands):
    """A forearm across the belly, its sleeve of the shirt's colour and the hand bare. The
    model's arm was left higher up the chest, beyond the step's reach: the silhouettes are
    the same either way and the sleeve looks like the shirt. The hand's colour at the anchor
    frame (the colour both hands share) draws the limb search to where the hand is."""
    body = make_body("full")
    p0 = body.rest_pose(se3.transform(p=[0, 0, 0.95]))
    for name, value in (("l_shoulder_flex", 0.3), ("l_elbow_flex", 1.6), ("l_shoulder_rot", 1.0)):
        p0.angles[body.dof_index(name)] = value
    wrong = p0.copy()
    wrong.angles[body.dof_index("l_shoulder_rot")] = 0.2     # the forearm up the chest
    cams = sorted(ring_of_cameras(8, 3.5, 1.3, [0, 0, 0.9], (320, 240), 350),
                  key=lambda c: (c.R.T @ -c.t)[1])[:3]
    settings = D.Settings(hands=hands)
    frame = _bare_hands(monkeypatch, body, p0, cams)
    tracker, images, _, moved = _anchored(body, settings, frame, cams, p0, wrong)
    wrist = JOINT_INDEX["l_wrist"]
    shift = 1000 * np.linalg.norm(body.joints(wrong)[wrist] - body.joints(p0)[wrist])
    assert shift > 150
    state, _ = tracker.step(moved, images, images)
    err = 1000 * np.linalg.norm(body.joints(state.pose())[wrist] - body.joints(p0)[wrist])
    if hands:
        assert err < 40
    else:
        assert err > 100


@pytest.mark.parametrize("guarded", [True, False])
def test_a_hand_is_not_drawn_into_the_other_arm(monkeypatch, guarded):
    """Bare arms have the hands' colour, and a model's arm a little off the real one leaves
    some of it free. Here the only pixels of the hands' colour are the left forearm's, across
    the belly, and the model's support map leaves them free; the right arm is somewhere in
    front of the chest, where the silhouettes cannot tell, and the model's hangs where there
    is none. The search must not draw the right hand into the left arm."""
    body = make_body("full")
    true = body.rest_pose(se3.transform(p=[0, 0, 0.95]))
    for name, value in (("l_shoulder_flex", 0.3), ("l_elbow_flex", 1.6), ("l_shoulder_rot", 1.0),
                        ("r_shoulder_flex", 0.9), ("r_elbow_flex", 1.6), ("r_shoulder_rot", 1.0)):
        true.angles[body.dof_index(name)] = value
    model = true.copy()
    for name in ("r_shoulder_flex", "r_elbow_flex", "r_shoulder_rot"):
        model.angles[body.dof_index(name)] = 0.0
    cams = sorted(ring_of_cameras(8, 3.5, 1.3, [0, 0, 0.9], (320, 240), 350),
                  key=lambda c: (c.R.T @ -c.t)[1])[:3]
    search = LimbSearch(body, seed=3)
    if not guarded:
        monkeypatch.setattr(LimbSearch, "_into_other_arm",
                            lambda self, root, trial, colour: np.zeros(len(trial), bool))
    groups = {g.name: g for g in search.groups}
    person = [render(cam, body.seg2world(true), body.primitives(), want=()).label >= 0
              for cam in cams]
    forearm = body.segment_names.index("l_forearm")
    labels = [render(cam, body.seg2world(model), body.primitives(), want=()).label
              for cam in cams]
    free = [lab == forearm for lab in labels]
    labels = [np.where(f, -1, lab) for f, lab in zip(free, labels)]
    sdfs = [signed_distance(p) for p in person]
    # one flat colour everywhere, credited only on the left forearm
    flat = [np.zeros((240, 320)), np.zeros((240, 320))]
    colours = {"right arm": [(flat, np.zeros(2), 0.02, ~f) for f in free]}
    state = D.State(np.stack([model.root] * 3), model.angles.copy(), list(cams))
    angles, moved = search.search(state, sdfs, labels, None, person, colours)
    end = search.ends["right arm"]
    found = model.copy()
    found.angles = angles
    T = body.seg2world(found)[search.prims.segment[end]]
    hand = T[:3, :3] @ search.prims.prim2seg[end][:3, 3] + T[:3, 3]
    left = search._arm_points(model.root, model.angles, groups["right arm"])
    near = 1000 * np.sqrt(((left - hand) ** 2).sum(axis=1).min())
    reach = 1000 * (body.dims["hand_r"] + body.dims["forearm_r"])
    assert "right arm" in [name for name, _ in moved]      # out of the air, into the chest
    if guarded:
        assert near > reach         # drawn to the left arm's edge, not into it (82.6 mm)
    else:
        assert near < reach         # into the left arm (38 mm)
