"""The light on the body since the anchor frame.

The anchor's appearance (grey levels and, on colour plates, chromaticity) is compared with
every later frame. A performer who walks from sunlight into shade, or under a lamp, changes
both: the body turns darker and, in shade lit by the sky, bluer. Compared as it was, every
anchor point is then off by the light's change and the anchor's terms fall silent (on the real
side-on walk of ``benchmarks/bench_real.py`` the anchor's colour made 15 frames called lost
instead of 8).

The light's change is taken as a gain per colour channel (von Kries' diagonal model): each
surface's red, green and blue are scaled alike. A shift of the chromaticity would not do: the
same bluer light moves a skin's chromaticity by 0.10 and a blue shirt's by 0.06. The gains are
measured on the whole body at a tracked frame (medians over the anchor's visible points, so a
limb or two gone wrong do not move them) and the anchor's grey levels and chromaticities are
predicted under them (:func:`relit`).
"""

import numpy as np

from .frames import CHROMA_OFFSET

# OpenCV's luma weights, B, G, R (``plates.to_gray_float``).
LUMA = np.array([0.114, 0.587, 0.299])
# Fewer of the anchor's points visible than this leave a view's light as it was at the anchor.
MIN_POINTS = 50
# Channels darker than this say nothing of a gain.
DARK = 0.05
# The gains are held within [1 / MAX_GAIN, MAX_GAIN].
MAX_GAIN = 3.0


def colour_of(gray, chroma):
    """BGR in [0, 1] from the grey level and the two chromaticity channels
    (:func:`frames.chromaticity`, whose inverse it is)."""
    k = CHROMA_OFFSET
    r, g = np.asarray(chroma[0], float), np.asarray(chroma[1], float)
    b = 1.0 - r - g
    total = (np.asarray(gray, float) + k) / (LUMA[0] * b + LUMA[1] * g + LUMA[2] * r)
    return np.stack([b * total - k, g * total - k, r * total - k], axis=-1)


def measure(anchor_gray, anchor_chroma, gray, chroma):
    """The light's gains from the anchor's values at visible points to a frame's values at
    the same points of the body.

    Parameters
    ----------
    anchor_gray, gray : array, shape (n,)
    anchor_chroma, chroma : list of two arrays, shape (n,), or None
        None for grey plates.

    Returns
    -------
    gains : array, shape (3,) (BGR; colour plates) or (1,) (grey plates), or None with too
        few points.
    """
    if len(gray) < MIN_POINTS:
        return None
    if anchor_chroma is None or chroma is None:
        before, now = np.asarray(anchor_gray, float)[:, None], np.asarray(gray, float)[:, None]
    else:
        before, now = colour_of(anchor_gray, anchor_chroma), colour_of(gray, chroma)
    gains = np.ones(before.shape[1])
    for ch in range(before.shape[1]):
        lit = before[:, ch] > DARK
        if lit.sum() >= MIN_POINTS:
            gains[ch] = np.median(now[lit, ch] / before[lit, ch])
    return np.clip(gains, 1 / MAX_GAIN, MAX_GAIN)


def relit(anchor_gray, anchor_chroma, gains):
    """The anchor's grey levels and chromaticities (None on grey plates) under ``gains``
    (one gain: the grey levels')."""
    if len(gains) == 1:
        return np.asarray(anchor_gray, float) * gains[0], anchor_chroma
    colour = np.clip(colour_of(anchor_gray, anchor_chroma) * gains, 0.0, None)
    k = CHROMA_OFFSET
    total = colour.sum(axis=-1) + 3 * k
    return colour @ LUMA, [(colour[..., 2] + k) / total, (colour[..., 1] + k) / total]


__all__ = ["colour_of", "measure", "relit"]
