"""Background model: the fast paths of estimate_background give the straightforward values."""

import numpy as np
import pytest

from zoopraxis.core.imaging import background as bg


def walking_block(n, rng, size=(64, 48)):
    """A textured background and a textured block that crosses it, as uint8 frames."""
    W, H = size
    back = rng.integers(0, 256, (H, W, 3)).astype(np.uint8)
    frames, masks = [], []
    for f in range(n):
        frame = np.clip(back + rng.normal(0, 2, back.shape), 0, 255).astype(np.uint8)
        mask = np.zeros((H, W), bool)
        x = 4 + (f * 3) % (W - 20)
        mask[10:40, x:x + 14] = True
        frame[mask] = rng.integers(0, 256, (mask.sum(), 3))
        frames.append(frame)
        masks.append(mask)
    return frames, masks


@pytest.mark.parametrize("n", [5, 12, 25])
def test_agreement_counts_every_pair(n):
    rng = np.random.default_rng(n)
    frames, masks = walking_block(n, rng)
    samples = np.stack([bg._as_float(f) for f in frames])
    free = rng.uniform(size=samples.shape[:3]) > 0.2
    tol2 = np.float32(0.03)
    other = rng.uniform(size=samples.shape[:3]) > 0.5
    got, got_other = bg._agreement(samples, [free, other], tol2)
    # every pair measured from both ends
    expected = np.zeros(samples.shape[:3], np.int64)
    for i in range(n):
        d = samples - samples[i]
        close = np.einsum("...c,...c->...", d, d) < tol2
        expected[i] = (close & free).sum(axis=0)
    np.testing.assert_array_equal(got, expected)
    # a second mask's counts, from the same distances, are its own
    np.testing.assert_array_equal(got_other, bg._agreement(samples, [other], tol2)[0])


def test_estimate_background_finds_the_background_behind_a_mover():
    rng = np.random.default_rng(3)
    frames, masks = walking_block(12, rng)
    back = np.median(np.stack([f for f in frames]), axis=0)
    model = bg.estimate_background(frames, exclude=[(frames[0], masks[0])])
    seen = ~np.any(np.stack(masks), axis=0)
    # where the block never passed, the model is the noisy background's mean
    assert np.abs(model.image[seen] * 255 - back[seen]).max() < 6
    assert model.known[seen].mean() > 0.95
    fg = model.foreground(frames[5])
    assert (fg & masks[5]).sum() > 0.8 * masks[5].sum()
    assert (fg & seen).sum() < 0.02 * seen.sum()


def test_sorting_network_sorts():
    # 0-1 principle: a comparator network sorts everything iff it sorts every 0-1 input
    for n in range(1, 15):
        x = list(((np.arange(2 ** n)[:, None] >> np.arange(n)) & 1).T.astype(np.int8))
        expected = np.sort(np.array(x), axis=0)
        for i, j in bg._sorting_network(n):
            assert i < j
            x[i], x[j] = np.minimum(x[i], x[j]), np.maximum(x[i], x[j])
        np.testing.assert_array_equal(np.array(x), expected)


@pytest.mark.parametrize("n", [3, 4, 7, 10, 24, 25, 31, 40])
def test_median_over_frames_is_numpys(n):
    rng = np.random.default_rng(n)
    # quantised like images, so ties are common
    stack = (rng.integers(0, 256, (n, 9, 11, 3)) / np.float32(255)).astype(np.float32)
    got = bg._median_over_frames(stack)
    assert got.dtype == np.float32
    np.testing.assert_array_equal(got, np.median(stack, axis=0))
    before = stack.copy()
    continuous = rng.uniform(0, 1, (n, 9, 11, 3)).astype(np.float32)
    np.testing.assert_array_equal(bg._median_over_frames(continuous),
                                  np.median(continuous, axis=0))
    np.testing.assert_array_equal(stack, before)       # the input is left alone
    odd = stack.copy()
    odd[0, 0, 0, 0] = np.nan
    odd[1, 1, 1, 1] = -0.5
    np.testing.assert_array_equal(bg._median_over_frames(odd), np.median(odd, axis=0))


def shadow_scene(seed=0, size=(96, 72)):
    """A textured floor, the same floor with a cast shadow (dimmed to 55 %, slightly bluer
    light), a red block (clothes), and a near-black block (dark clothes)."""
    rng = np.random.default_rng(seed)
    W, H = size
    base = np.array([90, 120, 150], float)          # BGR: a beige floor
    back = np.clip(base * rng.uniform(0.7, 1.3, (H, W, 1)), 0, 255)
    frame = back.copy()
    shadow = np.zeros((H, W), bool)
    shadow[40:64, 5:60] = True
    frame[shadow] = back[shadow] * [0.6, 0.55, 0.52]
    clothes = np.zeros((H, W), bool)
    clothes[8:36, 30:50] = True
    frame[clothes] = [40, 40, 170]
    dark = np.zeros((H, W), bool)
    dark[8:36, 60:80] = True
    frame[dark] = [14, 15, 16]
    noisy = [np.clip(back + rng.normal(0, 2, back.shape), 0, 255).astype(np.uint8)
             for _ in range(6)]
    frame = np.clip(frame + rng.normal(0, 2, frame.shape), 0, 255).astype(np.uint8)
    return noisy, frame, shadow, clothes, dark


def test_shadow_is_the_background_dimmed_not_clothes():
    frames, frame, shadow, clothes, dark = shadow_scene()
    model = bg.estimate_background(frames)
    fg = model.foreground(frame)
    # the foreground holds the shadow: a plain difference cannot tell it from the body
    assert fg[shadow].mean() > 0.9
    found = model.shadow(frame)
    inner = shadow.copy()
    inner[[40, 63], :] = False
    assert found[inner].mean() > 0.9
    assert found[clothes].mean() < 0.05
    assert found[dark].mean() < 0.02          # darker than any shadow the light leaves
    person = model.person(frame, fg)
    assert person[clothes].mean() > 0.9 and person[dark].mean() > 0.9
    assert person[shadow].mean() < 0.1


def _person_over_frames(rng, place, darkest=0, shade=lambda f: False):
    """15 frames of a textured 64x48 background (values from ``darkest``) with a textured
    30x14 person at column ``place(f)``; where ``shade(f)``, a patch at x=18-24 is dimmed
    by half (a shadow). Returns the background and the frames and person masks (uint8)."""
    W, H = 64, 48
    back = rng.integers(darkest, 256, (H, W, 3)).astype(np.uint8)
    person = rng.integers(0, 256, (30, 14, 3)).astype(np.uint8)
    frames, masks = [], []
    for f in range(15):
        frame = np.clip(back + rng.normal(0, 2, back.shape), 0, 255).astype(np.uint8)
        mask = np.zeros((H, W), bool)
        x = place(f)
        mask[10:40, x:x + 14] = True
        frame[mask] = person.reshape(-1, 3)
        if shade(f):
            frame[30:40, 18:24] = (frame[30:40, 18:24] * 0.5).astype(np.uint8)
        frames.append(frame)
        masks.append(mask)
    return back, frames, masks


def _off(model, where, truth):
    """Mean over the pixels ``where`` of the background's largest channel error from
    ``truth`` (their colours, 0-1)."""
    return np.abs(model.image[where] - truth).max(axis=1).mean()


def _estimates(seed, place, box, **kw):
    """:func:`_person_over_frames` and its backgrounds without and with the body's masks:
    ``frames, region, truth, plain, tracked``, ``region`` the pixels of ``box`` and ``truth``
    the background's colours there."""
    back, frames, masks = _person_over_frames(np.random.default_rng(seed), place, **kw)
    region = np.zeros(masks[0].shape, bool)
    region[box] = True
    return (frames, region, back[region].astype(float) / 255, bg.estimate_background(frames),
            bg.estimate_background(frames, masks=np.stack(masks)))


def test_tracked_masks_keep_a_person_who_stood_still_out_of_the_background():
    # still for 9 of 15 frames
    frames, still, truth, plain, tracked = _estimates(
        5, lambda f: 25 if 3 <= f < 12 else 4 + 3 * f % 40, np.s_[10:40, 25:39])
    # the person's own colours win the plain estimate where they stood
    assert _off(plain, still, truth) > 0.2
    assert _off(tracked, still, truth) < 0.03
    assert tracked.foreground(frames[6])[still].mean() > 0.9
    assert plain.foreground(frames[6])[still].mean() < 0.2


def _still_after_the_anchor(rng, shadow=False):
    """A person at x=4 in the anchor frame 0, then still at x=25 for frames 3-11 of 15 (the
    background behind them seen in frames 0-2 and 12-14); with ``shadow``, a dark patch beside
    the anchor's person (x=18-24) in frames 0-3 only."""
    return _person_over_frames(rng, lambda f: 4 if f < 3 else 25 if f < 12 else 45, darkest=40,
                               shade=lambda f: shadow and f <= 3)


def test_an_anchor_frame_shows_the_background_beside_the_person():
    """A person who stood still elsewhere for most of the take is the most consistent colour
    there; the anchor frame, which shows the background there, gives it back when the same
    colour is seen again far from it."""
    back, frames, masks = _still_after_the_anchor(np.random.default_rng(7))
    still = np.zeros(masks[0].shape, bool)
    still[10:40, 25:39] = True
    truth = back[still].astype(float) / 255
    anchor = np.zeros(masks[0].shape, bool)
    anchor[8:42, 2:20] = True                      # the model's silhouette, widened
    times = np.arange(15)
    plain = bg.estimate_background(frames, exclude=[(frames[0], masks[0])])
    shown = bg.estimate_background(frames, exclude=[(frames[0], masks[0])],
                                   shown=[(frames[0], anchor, 0)], times=times)
    assert _off(plain, still, truth) > 0.2
    assert _off(shown, still, truth) < 0.03
    assert shown.foreground(frames[6])[still].mean() > 0.9
    # inside the anchor's silhouette, and where the anchor's colour is not seen again far
    # from it, nothing changes
    np.testing.assert_array_equal(shown.image[anchor], plain.image[anchor])


def test_what_only_the_anchors_time_shows_is_not_taken_for_background():
    """A shadow beside the anchor's person, gone a few frames later, is seen near the anchor
    only: the background stays the floor without it."""
    back, frames, masks = _still_after_the_anchor(np.random.default_rng(8), shadow=True)
    anchor = np.zeros(masks[0].shape, bool)
    anchor[8:42, 2:17] = True
    shown = bg.estimate_background(frames, exclude=[(frames[0], masks[0])],
                                   shown=[(frames[0], anchor, 0)], times=np.arange(15))
    patch = back[30:40, 18:24].astype(float) / 255
    assert np.abs(shown.image[30:40, 18:24] - patch).max(axis=-1).mean() < 0.03


def test_a_shadow_cast_for_most_of_the_take_is_a_second_colour_of_the_floor():
    """The performer's shadow lay on a patch for 10 of 15 frames (a crouch before a jump): its
    dimmed floor is the most consistent colour there. With the body kept out, the lit floor
    the patch shows in the other frames is the background (a shadow only takes light away)
    and the shadow its second colour: neither is foreground, and the lit floor is what the
    shadow test measures against."""
    frames, patch, lit, plain, tracked = _estimates(
        9, lambda f: 40, np.s_[30:40, 18:24], darkest=60, shade=lambda f: 3 <= f < 13)
    # without the body's masks the shadow stays the background (a still performer's shaded
    # side would be taken for a shadow too)
    assert _off(plain, patch, lit) > 0.1
    assert plain.shaded is None
    assert _off(tracked, patch, lit) < 0.03
    assert tracked.shaded[patch].mean() > 0.9 and tracked.shaded.mean() < 0.05
    np.testing.assert_allclose(tracked.shade[patch], lit * 0.5, atol=0.03)
    # lit (the anchor's frame 0) or in the shadow, the patch is background
    assert tracked.foreground(frames[0])[patch].mean() < 0.05
    assert tracked.foreground(frames[5])[patch].mean() < 0.05
    # something else over it is not
    other = frames[5].copy()
    other[patch] = 255 - other[patch]
    assert tracked.foreground(other)[patch].mean() > 0.9
    # a shadow where the floor is lit in most frames is measured against the lit floor
    assert tracked.shadow(frames[5])[patch].mean() > 0.9


def test_a_darker_exposure_over_the_whole_view_is_not_a_shadow():
    """Two thirds of the frames are darker all over (the camera's exposure): the brighter
    third is not the lit floor of a shadow, and the background stays the darker frames'."""
    back, frames, masks = _person_over_frames(np.random.default_rng(10), lambda f: 40,
                                              darkest=60)
    frames = [(f * 0.6).astype(np.uint8) if i < 10 else f for i, f in enumerate(frames)]
    tracked = bg.estimate_background(frames, masks=np.stack(masks))
    free = ~masks[0]
    assert tracked.foreground(frames[5])[free].mean() < 0.05
    np.testing.assert_allclose(tracked.image[free], frames[5][free] / 255, atol=0.04)


@pytest.mark.parametrize("away", [True, False])
def test_light_clothes_beside_the_mask_are_not_the_lit_floor(monkeypatch, away):
    """A grey sleeve lighter than a grey floor shows just outside the tracked body's mask in 4
    of 15 frames (the model is narrower than the clothes): the floor there is a dimmed copy of
    it, hue and all. Counted only where the body, widened by a tenth of its height, is away,
    the sleeve is not the lit floor, and stays foreground. The control counts it next to the
    mask: the sleeve becomes the background."""
    if not away:
        monkeypatch.setattr(bg, "widened", lambda mask, share, least=1: mask)
    rng = np.random.default_rng(11)
    H, W = 48, 64
    frames, masks = [], []
    sleeve = np.zeros((H, W), bool)
    sleeve[12:30, 35:38] = True
    for f in range(15):
        frame = np.clip(110 + rng.normal(0, 2, (H, W, 3)), 0, 255).astype(np.uint8)
        mask = np.zeros((H, W), bool)
        mask[10:40, 20:34] = True
        frame[mask] = rng.integers(0, 256, (int(mask.sum()), 3)).astype(np.uint8)
        if f % 4 == 1:
            frame[sleeve] = 220
        frames.append(frame)
        masks.append(mask)
    tracked = bg.estimate_background(frames, masks=np.stack(masks))
    shown = tracked.foreground(frames[5])[sleeve].mean()
    if away:
        assert shown > 0.9
        assert tracked.shaded is None or not tracked.shaded[sleeve].any()
    else:
        assert shown < 0.5
