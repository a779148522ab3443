"""Background model: the fast paths of estimate_background give the straightforward values."""

import numpy as np
import pytest

from zoopraxis.core import background as bg


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
    got = bg._agreement(samples, free, tol2)
    # every pair measured from both ends
    expected = np.zeros(samples.shape[:3], np.int64)
    for i in range(n):
        d = samples - samples[i]
        close = np.einsum("...c,...c->...", d, d) < tol2
        expected[i] = (close & free).sum(axis=0)
    np.testing.assert_array_equal(got, expected)


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
