"""Image likelihood (Sidenbladh et al. §5): it peaks at the true motion, vectorizes over particles,
models occlusion and the twist-blind limb patches, and refuses bad input."""

import cv2
import numpy as np
import pytest

from zoopraxis.core.trackers import likelihood
from zoopraxis.core.imaging import render
from zoopraxis.core.geometry import se3
from zoopraxis.core.synthetic import synth
from zoopraxis.core.body.body import make_body
from zoopraxis.core.geometry.camera import PinholeCamera, look_at
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.trackers.particle import BatchKinematics


def camera_at(azimuth, size=(240, 180), distance=2.2, target=(0.1, 0.0, 1.15)):
    R, t = look_at([distance * np.cos(azimuth), distance * np.sin(azimuth), 1.4], target)
    f = 1.1 * size[0]
    return PinholeCamera(f"cam{azimuth:.2f}", size,
                         [[f, 0, (size[0] - 1) / 2], [0, f, (size[1] - 1) / 2], [0, 0, 1]],
                         R=R, t=t)


def _waves(rng, n=12, frequency=25.0):
    k = rng.normal(size=(n, 3))
    k *= (2 * np.pi * frequency * rng.uniform(0.5, 1.5, n) / np.linalg.norm(k, axis=1))[:, None]
    phase = rng.uniform(0, 2 * np.pi, n)
    return lambda p: np.sqrt(2.0) * np.sin(p @ k.T + phase).mean(axis=1)


def arm_take(frames=30, twist=0.6, size=(240, 180), azimuths=(-np.pi / 2 + 0.7,), seed=2345):
    """A standing body raising its left arm (elbow straight for 8 frames, then bending), drawn
    by the renderer with texture: rings on both arm segments (no cue to their twist), smooth
    random texture elsewhere, Lambert shading, a textured static background and noise.

    Returns the tracker's body, the cameras, images per frame and view, and the true roots and
    angles. The drawn body has thicker arms and chest than the tracker's.
    """
    rng = np.random.default_rng(seed)
    body = make_body("sidenbladh")
    shown = body.with_dims({"upper_arm_r": 0.05, "forearm_r": 0.042, "chest_rx": 0.17})
    prims = shown.primitives()
    t = np.arange(frames)
    angles = np.zeros((frames, body.n_dofs))
    angles[:, body.dof_index("l_shoulder_flex")] = 0.3 + 0.5 * np.clip(t / 24, 0, 1)
    angles[:, body.dof_index("l_shoulder_abd")] = 0.35 + 0.1 * np.sin(t / 8)
    angles[:, body.dof_index("l_shoulder_rot")] = twist
    angles[:, body.dof_index("l_elbow_flex")] = 1.4 * np.clip((t - 8) / 16, 0, 1)
    roots = np.broadcast_to(se3.transform(None, [0.0, 0.0, 0.95]), (frames, 4, 4))
    cameras = [camera_at(a, size) for a in azimuths]
    textures = []
    for name in body.segment_names:
        base = 150 if "arm" in name or name == "head" else 120
        if name.endswith(("upper_arm", "forearm")):
            textures.append(lambda p, b=base: b * (1 + 0.35 * np.sin(2 * np.pi * 14 * p[:, 2])))
        else:
            textures.append(lambda p, b=base, tex=_waves(rng): b * (1 + 0.35 * tex(p)))
    light = np.array([0.3, -0.6, 0.75]) / np.linalg.norm([0.3, -0.6, 0.75])
    backgrounds = []
    for _ in cameras:
        noise = rng.uniform(-1, 1, (size[1] // 8 + 2, size[0] // 8 + 2)).astype(np.float32)
        backgrounds.append(110 + 60 * cv2.resize(noise, size, interpolation=cv2.INTER_CUBIC))
    images = []
    for k in range(frames):
        seg2world = shown.seg2world(roots[k], angles[k])
        images.append([synth.textured_grey(cam, seg2world, prims, textures, background, light,
                                           rng) for cam, background in zip(cameras, backgrounds)])
    return body, cameras, images, roots, angles


@pytest.fixture(scope="module")
def take():
    return arm_take(frames=20, azimuths=(-np.pi / 2 + 0.7, 0.3))


def evaluate(lik, take, frame, angles, views=(0,), roots=None, reference=None):
    """Log-likelihoods of poses at ``frame``, appearance mapped at the truth of frame - 1."""
    body, cameras, images, true_roots, true_angles = take
    kin = BatchKinematics(body)
    ref = true_angles[frame - 1] if reference is None else reference
    lik.reset()
    lik.set_reference(kin.seg2world(true_roots[:1], ref[None])[0],
                      [likelihood.prepare_image(images[frame - 1][v]) for v in views])
    angles = np.atleast_2d(angles)
    roots = np.broadcast_to(true_roots[frame], (len(angles), 4, 4)) if roots is None else roots
    return lik.evaluate([likelihood.prepare_image(images[frame][v]) for v in views],
                        kin.seg2world(roots, angles))


# -- images -------------------------------------------------------------------------------------


def test_prepare_image_gives_smoothed_grey_levels(rng):
    colour = rng.integers(0, 256, size=(40, 50, 3), dtype=np.uint8)
    grey = likelihood.prepare_image(colour)
    raw = likelihood.prepare_image(colour, smoothing=0)
    assert grey.shape == (40, 50) and grey.dtype == np.float32
    assert 0 <= raw.min() and raw.max() <= 255
    expected = cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY).astype(float)
    np.testing.assert_allclose(raw, expected, atol=1.0)
    assert grey.std() < 0.6 * raw.std()                 # sigma sqrt(2) removes pixel noise


# -- the likelihood peaks at the truth ----------------------------------------------------------


@pytest.mark.parametrize("dof", ["l_shoulder_flex", "l_shoulder_abd", "l_elbow_flex"])
def test_likelihood_peaks_at_the_true_motion(take, dof):
    body, _, _, _, angles = take
    lik = likelihood.ImageLikelihood(body, take[1][:1], seed=1)
    offsets = np.radians([-8, -4, -2, 0, 2, 4, 8])
    frame = 14
    trial = np.repeat(angles[frame][None], len(offsets), axis=0)
    trial[:, body.dof_index(dof)] += offsets
    ll = evaluate(lik, take, frame, trial).log_likelihood
    assert np.argmax(ll) == 3
    assert ll[3] - max(ll[0], ll[-1]) > 20.0            # 8 degrees off is clearly worse


def test_likelihood_peaks_at_the_true_position(take):
    body, _, _, roots, angles = take
    lik = likelihood.ImageLikelihood(body, take[1][:1], seed=2)
    shifts = np.linspace(-0.04, 0.04, 5)
    trial_roots = np.repeat(roots[5][None], len(shifts), axis=0)
    trial_roots[:, 0, 3] += shifts
    ll = evaluate(lik, take, 5, np.repeat(angles[5][None], 5, 0), roots=trial_roots)
    assert np.argmax(ll.log_likelihood) == 2
    assert ll.inliers[2] > 0.9 and ll.inliers[0] < ll.inliers[2]


def test_likelihood_is_the_same_in_batches_and_alone(take, rng):
    body, _, _, _, angles = take
    lik = likelihood.ImageLikelihood(body, take[1][:1], seed=3)
    trial = angles[10] + rng.normal(0, 0.05, (5000, body.n_dofs))
    batch = evaluate(lik, take, 10, trial).log_likelihood
    kin = BatchKinematics(body)
    image = [likelihood.prepare_image(take[2][10][0])]
    for k in (0, 2047, 2048, 4999):                      # across chunk boundaries
        alone = lik.evaluate(image, kin.seg2world(take[3][:1], trial[k][None])).log_likelihood
        assert abs(alone[0] - batch[k]) < 1e-3 * abs(batch[k])


def test_views_multiply(take):
    """Depth along one camera's line of sight barely shows in it; a second view sees it."""
    body, cameras, _, roots, angles = take
    frame = 6
    ray = cameras[0].forward
    trial_roots = np.repeat(roots[frame][None], 2, axis=0)
    trial_roots[1, :3, 3] += 0.06 * ray
    both = likelihood.ImageLikelihood(body, cameras, seed=4)
    one = likelihood.ImageLikelihood(body, cameras[:1], seed=4)
    two_views = evaluate(both, take, frame, np.repeat(angles[frame][None], 2, 0), views=(0, 1),
                         roots=trial_roots).log_likelihood
    one_view = evaluate(one, take, frame, np.repeat(angles[frame][None], 2, 0),
                        roots=trial_roots).log_likelihood
    assert two_views[0] > two_views[1]
    assert (two_views[0] - two_views[1]) > 3 * (one_view[0] - one_view[1])


def test_own_previous_pose_as_appearance(take):
    """With each particle's own previous pose as the appearance (§4.1), moving with the arm
    beats standing still."""
    body, cameras, images, roots, angles = take
    kin = BatchKinematics(body)
    lik = likelihood.ImageLikelihood(body, cameras[:1], seed=5)
    frame = 14
    prev = [likelihood.prepare_image(images[frame - 1][0])]
    lik.set_reference(kin.seg2world(roots[:1], angles[frame - 1][None])[0], prev)
    before = kin.seg2world(roots[:2], np.repeat(angles[frame - 1][None], 2, 0))
    after = kin.seg2world(roots[:2], np.stack([angles[frame], angles[frame - 1]]))
    ll = lik.evaluate([likelihood.prepare_image(images[frame][0])], after,
                      previous=(prev, before)).log_likelihood
    assert ll[0] > ll[1] + 10.0


# -- occlusion and the limb surface -------------------------------------------------------------


def test_limbs_hidden_behind_another_compare_less(take):
    """Bringing the raised arm down across the chest hides torso points seen at the reference."""
    body, cameras, _, _, angles = take
    lik = likelihood.ImageLikelihood(body, cameras[:1], occlusion_margin=80.0, seed=6)
    frame = 19
    lowered = angles[frame - 1].copy()
    lowered[body.dof_index("l_shoulder_flex")] = 0.2
    lowered[body.dof_index("l_shoulder_abd")] = 0.0
    lowered[body.dof_index("l_elbow_flex")] = 1.6          # the forearm across the chest
    poses = np.stack([angles[frame - 1], lowered])
    result = evaluate(lik, take, frame, poses)
    no_occlusion = likelihood.ImageLikelihood(body, cameras[:1], occlusion_margin=-1e9, seed=6)
    plain = evaluate(no_occlusion, take, frame, poses)
    # At the reference's own pose nothing seen there is hidden; the lowered arm hides some.
    assert abs(plain.compared[0] - result.compared[0]) < 0.01
    assert plain.compared[1] > result.compared[1] + 0.02


def test_patches_do_not_see_the_twist_of_a_straight_arm(take):
    body, cameras, _, _, angles = take
    frame = 4                                            # elbow still straight
    twists = angles[frame] + np.outer(np.radians([-60, -20, 0, 20, 60]),
                                      np.eye(body.n_dofs)[body.dof_index("l_shoulder_rot")])
    patch = likelihood.ImageLikelihood(body, cameras[:1], surface="patch", seed=7)
    ll = evaluate(patch, take, frame, twists).log_likelihood
    assert np.ptp(ll) < 1e-3 * abs(ll[2])
    attached = likelihood.ImageLikelihood(body, cameras[:1], surface="attached", seed=7)
    ll = evaluate(attached, take, frame, twists).log_likelihood
    assert np.argmax(ll) == 2 and ll[2] - ll[0] > 5.0
    # Once the elbow bends the twist shows, with patches too.
    bent = 16
    twists = angles[bent] + np.outer(np.radians([-60, -20, 0, 20, 60]),
                                     np.eye(body.n_dofs)[body.dof_index("l_shoulder_rot")])
    ll = evaluate(patch, take, bent, twists).log_likelihood
    assert np.argmax(ll) == 2 and ll[2] - max(ll[0], ll[-1]) > 20.0


def test_appearance_memory_blends_frames(take):
    body, cameras, images, roots, angles = take
    kin = BatchKinematics(body)
    seg2world = kin.seg2world(roots[:1], angles[:1])[0]
    lik = likelihood.ImageLikelihood(body, cameras[:1], appearance_rate=0.5, seed=8)
    grey = likelihood.prepare_image(images[0][0])
    lik.set_reference(seg2world, [grey])
    first = lik.surfaces[0].values.copy()
    lik.set_reference(seg2world, [grey + 20.0])          # the same pose, 20 grey levels lighter
    np.testing.assert_allclose(lik.surfaces[0].values, first + 10.0, atol=1e-3)


# -- bad input ----------------------------------------------------------------------------------


def test_bad_settings_and_inputs(take):
    body, cameras, images, roots, angles = take
    with pytest.raises(ZoopraxisError, match="no cameras"):
        likelihood.ImageLikelihood(body, [])
    with pytest.raises(ZoopraxisError, match="surface must be one of"):
        likelihood.ImageLikelihood(body, cameras, surface="skin")
    with pytest.raises(ZoopraxisError, match="appearance_rate must be in"):
        likelihood.ImageLikelihood(body, cameras, appearance_rate=0.0)
    with pytest.raises(ZoopraxisError, match="n_points=5000 per limb is too many"):
        likelihood.ImageLikelihood(body, cameras, n_points=5000)
    lik = likelihood.ImageLikelihood(body, cameras[:1])
    T = BatchKinematics(body).seg2world(roots[:1], angles[:1])
    with pytest.raises(ZoopraxisError, match="call set_reference before evaluate"):
        lik.evaluate([likelihood.prepare_image(images[0][0])], T)
    with pytest.raises(ZoopraxisError, match=r"view 'cam-0.87': image is 120x90, the camera "
                                             r"expects 240x180"):
        lik.set_reference(T[0], [np.zeros((90, 120), np.float32)])
    with pytest.raises(ZoopraxisError, match="1 views but 2 images"):
        lik.set_reference(T[0], [np.zeros((180, 240), np.float32)] * 2)


# -- limbs one by one, and the silhouette -------------------------------------------------------


def test_per_segment_terms_add_up_and_subsets_match(take, rng):
    body, _, _, _, angles = take
    lik = likelihood.ImageLikelihood(body, take[1][:1], seed=9)
    trial = angles[12] + rng.normal(0, 0.05, (50, body.n_dofs))
    full = evaluate(lik, take, 12, trial)
    np.testing.assert_allclose(full.per_segment.sum(axis=1), full.log_likelihood, rtol=1e-12)
    arm = [body.segment_names.index(n) for n in ("l_upper_arm", "l_forearm")]
    assert np.all(full.per_segment[:, arm] < 0)
    kin = BatchKinematics(body)
    part = lik.evaluate([likelihood.prepare_image(take[2][12][0])],
                        kin.seg2world(np.broadcast_to(take[3][12], (50, 4, 4)), trial),
                        segments=arm)
    np.testing.assert_allclose(part.per_segment[:, arm], full.per_segment[:, arm], rtol=1e-5)
    others = np.setdiff1d(np.arange(body.n_segments), arm)
    assert np.all(part.per_segment[:, others] == 0)


def silhouette(body, camera, root, angles):
    """Foreground mask of a pose, as a background model would find it."""
    res = render.render(camera, body.seg2world(root, angles), body.primitives(), want=())
    return res.label >= 0


def test_silhouette_cue_is_two_sided(take):
    """Points off the foreground and foreground left uncovered both lower the likelihood."""
    body, cameras, _, roots, angles = take
    frame = 12
    raised = angles[frame].copy()
    raised[body.dof_index("l_shoulder_abd")] = 1.4           # the arm out to the side
    raised[body.dof_index("l_elbow_flex")] = 0.0
    lowered = raised.copy()
    lowered[body.dof_index("l_shoulder_abd")] = 0.1          # the arm down along the body
    shifted = roots[frame].copy()
    shifted[:3, 3] += 0.08 * cameras[0].R[0]                 # 8 cm sideways in the image
    poses = np.stack([raised, lowered, raised])
    trial_roots = np.stack([roots[frame], roots[frame], shifted])
    mask = silhouette(body, cameras[0], roots[frame], raised)
    lik = likelihood.ImageLikelihood(body, cameras[:1], silhouette=1.0, seed=10)
    plain = evaluate(lik, take, frame, poses, roots=trial_roots)
    assert np.all(plain.coverage == 0) and np.all(np.isnan(plain.covered))
    lik.set_foreground([mask])
    kin = BatchKinematics(body)
    cue = lik.evaluate([likelihood.prepare_image(take[2][frame][0])],
                       kin.seg2world(trial_roots, poses))
    covered = lik.coverage_of(kin.seg2world(trial_roots, poses))
    np.testing.assert_allclose(covered, cue.covered)
    assert covered[0] > 0.95                                 # the capsules fill the render
    assert covered[1] < covered[0] - 0.1                     # the arm's pixels are bare
    assert covered[2] < covered[0] - 0.15
    gain = cue.log_likelihood - plain.log_likelihood
    assert np.argmax(gain) == 0 and gain[0] > gain[1] + 30 and gain[0] > gain[2] + 150
    with pytest.raises(ZoopraxisError, match=r"view 'cam-0.87': foreground mask is 10x10"):
        lik.set_foreground([np.zeros((10, 10), bool)])


def test_capsule_hits_give_the_coverage_term(take, rng):
    body, cameras, _, roots, angles = take
    lik = likelihood.ImageLikelihood(body, cameras, silhouette=1.0, seed=11)
    masks = [silhouette(body, c, roots[5], angles[5]) for c in cameras]
    lik.set_foreground(masks)
    kin = BatchKinematics(body)
    T = kin.seg2world(np.broadcast_to(roots[5], (20, 4, 4)),
                      angles[5] + rng.normal(0, 0.2, (20, body.n_dofs)))
    res = evaluate(lik, take, 5, angles[5][None], views=(0, 1))   # sets the reference
    lik.set_foreground(masks)
    full = lik.evaluate([likelihood.prepare_image(take[2][5][v]) for v in (0, 1)], T)
    caps, hits = lik.capsule_hits(T)
    coverage, covered = lik.coverage_from_hits(hits)
    np.testing.assert_allclose(coverage, full.coverage, rtol=1e-5)
    np.testing.assert_allclose(covered, full.covered)
    assert np.ptp(covered) > 0.05
    arm = [body.segment_names.index("l_forearm")]
    some, part = lik.capsule_hits(T, arm)
    assert 0 < len(some) < len(caps)
    np.testing.assert_array_equal(part[1], hits[1][:, some])
    assert res.coverage.shape == (1,)


def test_limbs_off_the_foreground_gain_nothing_and_their_axes_count_unseen(take):
    """A limb on a static background matches it perfectly from frame to frame; with a
    foreground mask its points count as the background's (no better than hidden ones), and its
    axis points, compared whether its surface was seen or not, fall off the silhouette too."""
    body, cameras, _, roots, angles = take
    frame = 12
    raised = angles[frame].copy()
    raised[body.dof_index("l_shoulder_abd")] = 1.4           # the arm out over the background
    raised[body.dof_index("l_elbow_flex")] = 0.0
    mask = silhouette(body, cameras[0], roots[frame], angles[frame])    # where the arm truly is
    arm = [body.segment_names.index(s) for s in ("l_upper_arm", "l_forearm")]
    floor, weight = 0.1, 1.0
    per_point = []
    for axis_points in (0, 5):
        lik = likelihood.ImageLikelihood(body, cameras[:1], silhouette=weight, seed=12,
                                         axis_points=axis_points, background_points=True)
        # the appearance mapped at the raised arm: it sees the static background
        plain = evaluate(lik, take, frame, raised[None], reference=raised)
        lik.set_foreground([mask])
        kin = BatchKinematics(body)
        cue = lik.evaluate([likelihood.prepare_image(take[2][frame][0])],
                           kin.seg2world(roots[frame][None], raised[None]))
        n = sum(sl.stop - sl.start for (k, _), sl in zip(lik.surfaces[0].groups,
                                                            lik.surfaces[0].slices) if k in arm)
        assert n > 20
        # Matched against the background, the arm's points explain their grey values well...
        assert plain.per_segment[0, arm].sum() / n > np.log(1 / 256) + 1.0
        per_point.append(cue.per_segment[0, arm].sum())
        if axis_points == 0:
            # ...but on the background they are the background's: p_occluded and off the mask
            bound = n * (np.log(1 / 256) + weight * np.log(floor) + 1.0)
            assert per_point[0] < bound
    off = likelihood.ImageLikelihood(body, cameras[:1], silhouette=weight, seed=12)
    evaluate(off, take, frame, raised[None], reference=raised)
    off.set_foreground([mask])
    compared = off.evaluate([likelihood.prepare_image(take[2][frame][0])],
                            BatchKinematics(body).seg2world(roots[frame][None], raised[None]))
    assert compared.per_segment[0, arm].sum() > per_point[0] + n
    # the axis points add about weight * log(floor) each (the arm's capsules lie off the mask)
    caps = int(np.isin(lik.occluders.segment, arm).sum())
    assert caps >= 2
    assert per_point[1] - per_point[0] < 0.8 * 5 * caps * weight * np.log(floor)
    # at the true pose the axes lie inside the silhouette: they cost next to nothing
    lik.set_foreground([mask])
    true = lik.evaluate([likelihood.prepare_image(take[2][frame][0])],
                        BatchKinematics(body).seg2world(roots[frame][None], angles[frame][None]))
    lik0 = likelihood.ImageLikelihood(body, cameras[:1], silhouette=weight, seed=12,
                                      axis_points=0, background_points=True)
    evaluate(lik0, take, frame, raised[None], reference=raised)
    lik0.set_foreground([mask])
    true0 = lik0.evaluate([likelihood.prepare_image(take[2][frame][0])],
                          BatchKinematics(body).seg2world(roots[frame][None],
                                                          angles[frame][None]))
    assert abs(true.per_segment[0, arm].sum() - true0.per_segment[0, arm].sum()) < 2.0
    with pytest.raises(ZoopraxisError, match="axis_points must be a whole number"):
        likelihood.ImageLikelihood(body, cameras[:1], axis_points=-1)


def test_coverage_draws_only_the_pixels_given_to_cover(take):
    """Pixels the background model cannot vouch for (never seen free, cast shadows) may hold
    limbs but do not draw them: the coverage half of the cue draws from ``cover`` only."""
    body, cameras, _, roots, angles = take
    frame = 12
    raised = angles[frame].copy()
    raised[body.dof_index("l_shoulder_abd")] = 1.4
    raised[body.dof_index("l_elbow_flex")] = 0.0
    lowered = raised.copy()
    lowered[body.dof_index("l_shoulder_abd")] = 0.1
    mask = silhouette(body, cameras[0], roots[frame], raised)
    # the person as the render shows them with the raised arm, but the arm's pixels not vouched
    arm_only = mask & ~silhouette(body, cameras[0], roots[frame], lowered)
    cover = mask & ~cv2.dilate(arm_only.astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert cover.sum() < mask.sum() - 50
    kin = BatchKinematics(body)
    T = kin.seg2world(np.broadcast_to(roots[frame], (2, 4, 4)), np.stack([raised, lowered]))
    lik = likelihood.ImageLikelihood(body, cameras[:1], silhouette=1.0, seed=13)
    lik.set_foreground([mask])
    both = lik.coverage_of(T)
    assert both[1] < both[0] - 0.05                # the lowered arm leaves the arm's pixels bare
    lik.set_foreground([mask], [cover])
    only = lik.coverage_of(T)
    assert abs(only[1] - only[0]) < 0.02 and only[0] > 0.95
    with pytest.raises(ZoopraxisError, match="1 views but 2 masks to cover"):
        lik.set_foreground([mask], [cover, cover])
