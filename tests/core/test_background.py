"""Background model: the fast paths of estimate_background give the straightforward values."""

import cv2
import numpy as np
import pytest

from zoopraxis.core import background as bg


def reference_background(frames, tolerance=None, exclude=()):
    """estimate_background written plainly: np.median, and every pair of samples measured."""
    stack = np.stack([bg._as_float(f) for f in frames])
    N, H, W, _ = stack.shape
    median = np.median(stack, axis=0)
    noise = float(1.4826 * np.median(np.sqrt(((stack[::3] - median) ** 2).sum(axis=3)))) + 1e-3
    tol = max(4.0 * noise, 0.05) if tolerance is None else tolerance
    tol2 = np.float32(tol * tol)

    def dist2(a, b):
        d = a - b
        return np.einsum("...c,...c->...", d, d)

    small = np.stack([cv2.pyrDown(f) for f in stack])
    person_s = np.zeros(small.shape[:3], bool)
    person = np.zeros(stack.shape[:3], bool)
    for image, mask in exclude:
        person |= mask[None] & (dist2(stack, bg._as_float(image)) < tol2)
    if exclude:
        person_s = np.stack([cv2.resize(p.astype(np.uint8), (small.shape[2], small.shape[1]),
                                        interpolation=cv2.INTER_NEAREST) > 0 for p in person])
    best_count = np.zeros(small.shape[1:3], np.int32)
    best_index = np.zeros(small.shape[1:3], np.int64)
    for i in range(N):
        close = (dist2(small, small[i]) < tol2) & ~person_s
        count = np.where(person_s[i], 0, close.sum(axis=0))
        better = count > best_count
        best_count[better] = count[better]
        best_index[better] = i
    index = cv2.resize(best_index.astype(np.float32), (W, H),
                       interpolation=cv2.INTER_NEAREST).astype(np.int64)
    count_full = cv2.resize(best_count.astype(np.float32), (W, H),
                            interpolation=cv2.INTER_NEAREST)
    centre = np.take_along_axis(stack, index[None, :, :, None], axis=0)[0]
    close = (dist2(stack, centre) < tol2) & ~person
    n_close = close.sum(axis=0)
    best_sum = np.where((n_close > 0)[..., None],
                        (stack * close[..., None]).sum(axis=0) / np.maximum(n_close, 1)[..., None],
                        median)
    best_count = np.minimum(n_close, count_full.astype(np.int64))
    image = best_sum.astype(np.float32)
    known = best_count >= max(2, N // 8)
    diffs = np.sqrt(dist2(stack[::3], image))[:, known]
    sigma = float(1.4826 * np.median(diffs)) + 1e-3 if diffs.size else noise
    return image, sigma, known


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
def test_estimate_background_equals_the_plain_computation(n):
    rng = np.random.default_rng(n)
    frames, masks = walking_block(n, rng)
    for exclude in ((), [(frames[0], masks[0])]):
        model = bg.estimate_background(frames, exclude=exclude)
        image, sigma, known = reference_background(frames, exclude=exclude)
        np.testing.assert_array_equal(model.image, image)
        assert model.sigma == sigma
        np.testing.assert_array_equal(model.known, known)


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
