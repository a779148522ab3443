"""Background model, foreground masks and silhouette distance images.

Frame-to-frame image motion drifts (Yamamoto et al. §4; Sidenbladh et al. §7). A persistent cue
against drift is the person's silhouette against the static background: the background is
estimated from the plates themselves as each pixel's most consistent colour over frames spread
over the take (the person's moving, textured clothes don't repeat one colour at one pixel, the
background does), and each frame's foreground is what differs from it by more than the noise.

The performer's own shadow repeats too: where they stood for much of the take, the floor in
their shadow is the most consistent colour. Estimated again with the tracked body kept out, a
pixel whose consistent colour is a dimmed copy of another it also shows keeps both, the lit one
as the background and the shadow as a second colour (``BackgroundModel.shade``); a frame that
shows either is background there, so neither the shadow nor the lit floor after the performer
leaves is taken for them.

Convention: images are BGR uint8 or float32 in [0, 1], at the tracker's working resolution.
"""

from dataclasses import dataclass

import cv2
import numpy as np

# Cast shadows (BackgroundModel.shadow): brightness relative to the background, largest colour
# change left after dimming (relative to the background's brightness), and the texture
# correlation that lets a shadow on a textured floor change colour a little more. On the
# rendered benchmark scenes (hard sun and a coloured lamp) the shadows' brightness is 0.45-0.8
# and their colour change 0.01-0.05; the clothes' colour change is 0.05-0.35.
SHADOW_DARKEST, SHADOW_BRIGHTEST = 0.4, 0.95
SHADOW_CHROMA = 0.06
SHADOW_TEXTURE = 0.7
# A cast shadow only takes light away (estimate_background with the tracked body kept out):
# where a pixel's most consistent colour is a dimmed copy of another colour it also shows
# consistently, by a brightness factor in this range and with a colour change under
# ``LIT_CHROMA`` of the dimmed colour's brightness, the brighter is the background and the
# dimmer its second colour. Shadows in full sun on the rendered benchmark scenes are 0.25-0.4
# of the lit floor; a darker copy over the whole view (the exposure) is not a shadow.
LIT_DARKEST, LIT_BRIGHTEST = 0.2, 0.9
LIT_CHROMA = 0.08
# ... seen in samples where the tracked body, widened by this share of its height, is away.
LIT_AWAY = 0.1


@dataclass
class BackgroundModel:
    """Per-pixel background colour and the noise level of its differences.

    Attributes
    ----------
    image : array, shape (H, W, 3) float32 in [0, 1]
    sigma : float
        Robust standard deviation of ``|frame - background|`` over background pixels.
    known : array of bool, shape (H, W), optional
        Where the background was seen. Elsewhere (the person never left those pixels) the
        foreground mask says "foreground", so that a silhouette cue cannot push the model out.
    shade : array, shape (H, W, 3) float32, optional
        A second colour of the background where ``shaded``: the floor in the performer's
        shadow, where it lay for much of the take (``image`` is the lit floor there). A frame
        that shows either colour is background.
    shaded : array of bool, shape (H, W), optional
        Where ``shade`` holds (elsewhere it equals ``image``).
    """

    image: np.ndarray
    sigma: float
    known: np.ndarray = None
    shade: np.ndarray = None
    shaded: np.ndarray = None

    def difference2(self, frame):
        """Squared colour distance of a frame from the background (the nearer of its two
        colours where it has a ``shade``), (H, W) float32."""
        frame = _as_float(frame)
        ones = np.ones((1, 3), np.float32)
        d = cv2.subtract(frame, self.image)
        d2 = cv2.transform(cv2.multiply(d, d), ones)      # sum over the channels
        if self.shaded is not None:
            e = cv2.subtract(frame, self.shade)
            np.minimum(d2, cv2.transform(cv2.multiply(e, e), ones), out=d2, where=self.shaded)
        return d2

    def foreground(self, frame, *, k=4.0, min_level=0.06):
        """Foreground mask of a frame, (H, W) bool, cleaned of specks and small holes."""
        d2 = self.difference2(frame)
        mask = (d2 > np.float32(max(k * self.sigma, min_level) ** 2)).astype(np.uint8)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel, iterations=2)
        mask = mask.astype(bool)
        if self.known is not None:
            mask |= ~self.known
        return mask

    def shadow(self, frame, *, darkest=SHADOW_DARKEST, brightest=SHADOW_BRIGHTEST,
               chroma=SHADOW_CHROMA, texture=SHADOW_TEXTURE):
        """Cast shadow: pixels that are the background dimmed by a common factor, (H, W) bool.

        A shadow takes away some of the light falling on the floor or a wall; what is left
        has the background's colour and texture at a lower brightness. With ``I`` the frame
        and ``B`` the background (both smoothed over 5x5 pixels against sensor noise), the
        brightness ``a = I.B / B.B`` of a shadow lies between ``darkest`` and ``brightest``
        and the colour left over, ``|I - a B| / |B|``, is small: under ``chroma``, or under
        twice that where the background's texture shows through (a normalized
        cross-correlation of the grey images over 7x7 pixels above ``texture``). Clothes
        that are a darker shade of the floor's own colour pass the test too; the brightness
        floor keeps dark clothes (near black, ``a`` well below a sunlit shadow's 0.4-0.7)
        out of it.
        """
        ones = np.ones((1, 3), np.float32)
        raw = _as_float(frame)
        # the brightness pixel by pixel too: the smoothed one mixes a dark object's rim with
        # the floor beside it
        a_raw = (cv2.transform(raw * self.image, ones)
                 / (cv2.transform(self.image * self.image, ones) + np.float32(1e-6)))
        img = cv2.blur(raw, (5, 5))
        bg = cv2.blur(self.image, (5, 5))
        bb = cv2.transform(bg * bg, ones) + np.float32(1e-6)
        a = cv2.transform(img * bg, ones) / bb
        rest = img - a[..., None] * bg
        chroma2 = cv2.transform(rest * rest, ones) / bb
        gi = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        gb = cv2.cvtColor(bg, cv2.COLOR_BGR2GRAY)
        box = (7, 7)
        mi, mb = cv2.blur(gi, box), cv2.blur(gb, box)
        vi = cv2.blur(gi * gi, box) - mi * mi
        vb = cv2.blur(gb * gb, box) - mb * mb
        ncc = (cv2.blur(gi * gb, box) - mi * mb) / np.sqrt(np.maximum(vi * vb, 1e-10))
        c2 = np.float32(chroma * chroma)
        shadow = ((a > darkest) & (a < brightest) & (a_raw > darkest)
                  & ((chroma2 < c2) | ((ncc > texture) & (chroma2 < 4 * c2))))
        # a cast shadow is a broad patch of floor or wall; slivers are the smoothed rims of
        # objects against the background (and shading on the body), not shadow
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
        return cv2.morphologyEx(shadow.astype(np.uint8), cv2.MORPH_OPEN, kernel) > 0

    def person(self, frame, foreground=None):
        """Foreground without cast shadows (:meth:`shadow`), (H, W) bool: what the body
        itself covers, for measures that count foreground the model leaves unexplained.
        ``foreground`` is the frame's :meth:`foreground`, when already made."""
        fg = self.foreground(frame) if foreground is None else foreground
        mask = (fg & ~self.shadow(frame)).astype(np.uint8)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel) > 0
        if self.known is not None:
            mask |= ~self.known
        return mask


def _as_float(frame):
    frame = np.asarray(frame)
    if frame.dtype == np.uint8:
        frame = frame.astype(np.float32) / 255.0
    else:
        frame = frame.astype(np.float32)
    if frame.ndim == 2:
        frame = np.repeat(frame[:, :, None], 3, axis=2)
    return frame


def _sorting_network(n):
    """Compare-exchange pairs ``(i, j)``, ``i < j``, of Batcher's odd-even merge sort of n items."""
    pairs = []
    p = 1
    while p < n:
        k = p
        while k >= 1:
            for j in range(k % p, n - k, 2 * k):
                for i in range(min(k, n - j - k)):
                    if (i + j) // (2 * p) == (i + j + k) // (2 * p):
                        pairs.append((i + j, i + j + k))
            k //= 2
        p *= 2
    return pairs


def _median_network(n):
    """The pairs of :func:`_sorting_network` that the middle item(s) depend on, in order."""
    wanted = {(n - 1) // 2, n // 2}
    kept = []
    for i, j in reversed(_sorting_network(n)):
        if i in wanted or j in wanted:
            kept.append((i, j))
            wanted |= {i, j}
    return kept[::-1]


def _median_over_frames(stack):
    """``np.median(stack, axis=0)``, the same values.

    numpy selects the median of each of the H*W*3 lanes separately, a call per lane; a sorting
    network over the N frames does the selection with whole-image minima and maxima. The middle
    sample (or the mean of the middle two, by np.mean as np.median takes it) is the same value
    whichever way it is selected. NaNs and negative numbers (signed zeros) go to np.median.
    """
    n = len(stack)
    if n < 3 or np.isnan(stack).any() or np.signbit(stack).any():
        return np.median(stack, axis=0)
    items = list(stack.copy())
    for i, j in _median_network(n):
        low = np.minimum(items[i], items[j])
        np.maximum(items[i], items[j], out=items[j])
        items[i] = low
    return np.mean(np.stack(items[(n - 1) // 2:n // 2 + 1]), axis=0)


def _dist2(a, b):
    d = a - b
    return np.einsum("...c,...c->...", d, d)


def _agreement(samples, frees, tol2):
    """For each sample (N, H, W, 3) of each pixel, how many of the pixel's samples that are
    free (each of ``frees``, (N, H, W) bool) lie within squared colour distance ``tol2`` of it
    (itself included); one count per mask of ``frees``.

    Agreement is symmetric (the distance of a pair is the same either way round, to the bit),
    so each pair is measured once, for every mask, and counted for both of its samples.
    """
    N = len(samples)
    agrees = [np.zeros(samples.shape[:3], np.int64) for _ in frees]
    for i in range(N):
        close = _dist2(samples[i:], samples[i]) < tol2       # samples i, i+1, ... against i
        for agree, free in zip(agrees, frees):
            agree[i] += (close & free[i:]).sum(axis=0)
            agree[i + 1:] += close[1:] & free[i]
    return agrees


def widened(mask, share, least=1):
    """A body's mask (H, W) dilated by ``share`` of its height (the rows it spans), by at
    least ``least`` pixels; None for an empty mask."""
    rows = np.flatnonzero(mask.any(axis=1))
    if not len(rows):
        return None
    r = max(least, int(round(share * (rows[-1] - rows[0] + 1))))
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    return cv2.dilate(mask.astype(np.uint8), kernel) > 0


def _lit_colours(small, centre, agree, free, least):
    """Which of each pixel's samples (N, H, W, 3) is the lit colour of which its ``centre``
    (H, W, 3) is a shadow: a sample that is ``free`` and agrees with at least ``least``
    samples, of which the centre is a dimmed copy (:data:`LIT_DARKEST` to
    :data:`LIT_BRIGHTEST`, colour change under :data:`LIT_CHROMA`); the one with the most
    agreement where several are. Each sample is first scaled by its exposure against the
    centre over the whole view: light that changes everywhere (a camera's exposure, a cloud)
    is not a shadow.

    Returns
    -------
    found : array of bool, shape (H, W)
    which, count : array of int, shape (H, W)
        The lit sample and its agreement where ``found``.
    """
    cc = np.einsum("hwc,hwc->hw", centre, centre) + np.float32(1e-6)
    ss = np.einsum("nhwc,nhwc->nhw", small, small) + np.float32(1e-6)
    cs = np.einsum("nhwc,hwc->nhw", small, centre)
    gain = np.median(cs / cc, axis=(1, 2))[:, None, None].astype(np.float32)
    # the centre against the exposure-scaled sample s / gain: factor a, colour left |c - a s|^2
    b = cs / ss
    a = b * gain
    rest2 = cc[None] - 2 * b * cs + b * b * ss
    lit = ((a > LIT_DARKEST) & (a < LIT_BRIGHTEST) & (rest2 < np.float32(LIT_CHROMA ** 2) * cc)
           & free & (agree >= least))
    score = np.where(lit, agree, 0)
    which = np.argmax(score, axis=0)
    count = np.take_along_axis(score, which[None], axis=0)[0]
    return count > 0, which, count


def estimate_background(frames, *, tolerance=None, exclude=(), masks=None, shown=(), times=None):
    """Background of a static view from frames spread over the take.

    A per-pixel median fails where the person lingers for more than half the frames (a slow
    walk, a turn on the spot). The background is instead the most *consistent* value of each
    pixel: the sample with the most other samples within ``tolerance`` of it, averaged with
    them. A background pixel seen in a third of the frames still wins, because the person's
    textured, moving clothes do not repeat one colour at one pixel.

    Parameters
    ----------
    frames : list of array, shape (H, W, 3)
        Frames spread over the take (10-30 are plenty).
    tolerance : float, optional
        Colour distance (0-1 units) under which two samples agree; default from the noise.
    exclude : sequence of (image, mask)
        Frames where the person's silhouette is known (anchor frames, from the model): inside
        the mask, samples that look like that frame are the person, not the background.
    masks : array of bool, shape (N, H, W), optional
        Where the person is in each of ``frames`` (a tracked body's silhouettes): those
        samples are never taken for the background, so that a person who stood still for
        much of the take is not.
    shown : sequence of (image, mask, time)
        Frames where the person is known to be inside ``mask`` (an anchor frame's silhouette,
        widened): outside it the frame shows the background. Where that colour is seen again
        far from ``time`` (a quarter of the take or more away, in at least an eighth of the
        samples), it is the background, however many samples agree on another colour: a
        performer who stood still elsewhere for most of the take is not taken for it (a kick
        held in a lunge), nor the floor beside them. Near ``time`` alone it may be the
        person's own shadow or reflection, and the most consistent colour is kept.
    times : sequence of float, optional
        The take's frame numbers of ``frames`` (needed with ``shown``).

    Returns
    -------
    BackgroundModel
    """
    stack = np.stack([_as_float(f) for f in frames])                 # (N, H, W, 3)
    N, H, W, _ = stack.shape
    median = _median_over_frames(stack)
    noise = float(1.4826 * np.median(np.sqrt(((stack[::3] - median) ** 2).sum(axis=3)))) + 1e-3
    tol = max(4.0 * noise, 0.05) if tolerance is None else tolerance
    tol2 = np.float32(tol * tol)

    dist2 = _dist2

    # Choose each pixel's centre sample on a half-resolution copy (the choice varies slowly
    # across the image), then average at full resolution.
    small = np.stack([cv2.pyrDown(f) for f in stack])
    person_s = np.zeros(small.shape[:3], bool)
    person = np.zeros(stack.shape[:3], bool)
    for image, mask in exclude:
        ref = _as_float(image)
        person |= mask[None] & (dist2(stack, ref) < tol2)
    if masks is not None:
        person |= np.asarray(masks, bool)
    if exclude or masks is not None:
        person_s = np.stack([cv2.resize(p.astype(np.uint8), (small.shape[2], small.shape[1]),
                                        interpolation=cv2.INTER_NEAREST) > 0 for p in person])
    least = max(2, N // 8)      # samples that make a colour the background's
    frees = [~person_s]
    if masks is not None:
        # the lit colour of a shadow (below) is counted only in samples where the body,
        # widened by a share of its height, is away: clothes lighter than the floor and of its
        # hue, at the edge of a mask that misses them (or a lost limb held still), are not
        # the lit floor
        near = [widened(p, LIT_AWAY) for p in person_s]
        frees.append(~np.stack([p if w is None else w for p, w in zip(person_s, near)]))
    counts = _agreement(small, frees, tol2)
    agree = counts[0]
    best_count = np.zeros(small.shape[1:3], np.int32)
    best_index = np.zeros(small.shape[1:3], np.int64)
    for i in range(N):
        count = np.where(person_s[i], 0, agree[i])
        better = count > best_count
        best_count[better] = count[better]
        best_index[better] = i
    # the samples of the frames that show the background outside the person (index N + k)
    references, references_s, taken = [], [], np.zeros(small.shape[1:3], bool)
    if shown:
        if times is None:
            raise ValueError("estimate_background: 'shown' needs the frames' 'times'")
        times = np.asarray(times, float)
        span = max(float(np.ptp(times)), 1.0)
        for image, mask, time in shown:
            ref = _as_float(image)
            ref_s = cv2.pyrDown(ref)
            outside = cv2.resize((~np.asarray(mask, bool)).astype(np.uint8),
                                 (small.shape[2], small.shape[1]),
                                 interpolation=cv2.INTER_NEAREST) > 0
            far = np.abs(times - time) >= span / 4
            agrees = (dist2(small, ref_s) < tol2) & ~person_s
            chosen = outside & ~taken & (agrees[far].sum(axis=0) >= least)
            best_index[chosen] = N + len(references)
            best_count[chosen] = agrees.sum(axis=0)[chosen]
            taken |= chosen
            references.append(ref)
            references_s.append(ref_s)
    shaded_s = None
    if masks is not None:
        # With the body kept out, a pixel whose most consistent colour is the performer's
        # shadow (cast where they stood for much of the take) has the lit floor it also shows
        # for its background, and the shadow for a second colour (not without the masks: a
        # performer who stood still shows a lit and a shaded side of their clothes).
        shaded_s, which, count = _lit_colours(
            small, _centre(small, best_index, references_s), counts[1], frees[1], least)
        shade_index = best_index.copy()
        best_index[shaded_s] = which[shaded_s]
        best_count[shaded_s] = count[shaded_s]
    image, n_close = _consistent_colour(stack, person, best_index, references, tol2)
    image = np.where((n_close > 0)[..., None], image, median).astype(np.float32)
    count_full = cv2.resize(best_count.astype(np.float32), (W, H),
                            interpolation=cv2.INTER_NEAREST)
    known = np.minimum(n_close, count_full.astype(np.int64)) >= least
    shade = shaded = None
    if shaded_s is not None and shaded_s.any():
        shade, n_shade = _consistent_colour(stack, person, shade_index, references, tol2)
        shaded = (cv2.resize(shaded_s.astype(np.uint8), (W, H),
                             interpolation=cv2.INTER_NEAREST) > 0) & (n_shade >= least)
        shade = np.where(shaded[..., None], shade, image).astype(np.float32)
    model = BackgroundModel(image, noise, known, shade, shaded)
    diffs = np.sqrt(np.stack([model.difference2(f) for f in stack[::3]]))[:, known]
    model.sigma = float(1.4826 * np.median(diffs)) + 1e-3 if diffs.size else noise
    return model


def _centre(samples, index, references):
    """Each pixel's sample (N, H, W, 3) that ``index`` (H, W) names; N + k: ``references[k]``
    (H, W, 3)."""
    N = len(samples)
    centre = np.take_along_axis(samples, np.minimum(index, N - 1)[None, :, :, None], axis=0)[0]
    for k, ref in enumerate(references):
        at = index == N + k
        centre[at] = ref[at]
    return centre


def _consistent_colour(stack, person, index_small, references, tol2):
    """The mean of each pixel's samples (N, H, W, 3), not ``person``, within ``tol2`` of the
    sample ``index_small`` names (half resolution; N + k: ``references[k]``), and their
    count."""
    N, H, W, _ = stack.shape
    index = cv2.resize(index_small.astype(np.float32), (W, H),
                       interpolation=cv2.INTER_NEAREST).astype(np.int64)
    close = (_dist2(stack, _centre(stack, index, references)) < tol2) & ~person
    n_close = close.sum(axis=0)
    mean = (stack * close[..., None]).sum(axis=0) / np.maximum(n_close, 1)[..., None]
    return mean, n_close


def signed_distance(mask):
    """Signed distance to a mask's boundary in pixels: positive outside, negative inside.

    Parameters
    ----------
    mask : array of bool, shape (H, W)

    Returns
    -------
    sdf : array, shape (H, W) float32
    """
    m = mask.astype(np.uint8)
    if not m.any():
        return np.full(mask.shape, 1e3, np.float32)
    outside = cv2.distanceTransform(1 - m, cv2.DIST_L2, 5)
    inside = cv2.distanceTransform(m, cv2.DIST_L2, 5)
    # Boundary at the half-pixel between the two sides (float32 throughout).
    sdf = np.subtract(outside, inside, out=outside)
    sdf -= np.where(m > 0, np.float32(-0.5), np.float32(0.5))
    return sdf


def silhouette_iou(model_mask, observed_mask):
    """Intersection over union of two masks (1.0 when both are empty)."""
    inter = np.logical_and(model_mask, observed_mask).sum()
    union = np.logical_or(model_mask, observed_mask).sum()
    return 1.0 if union == 0 else float(inter / union)


def model_coverage(model_mask, observed_mask, known=None):
    """Fraction of the model's silhouette that the foreground covers, over pixels where the
    background is known (how reliable a view's background is for this take)."""
    if known is not None:
        model_mask = model_mask & known
    n = model_mask.sum()
    return 0.0 if n == 0 else float(np.logical_and(model_mask, observed_mask).sum() / n)
