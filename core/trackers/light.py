"""The light on the body since the anchor frame.

The anchor's appearance (grey levels and, on colour plates, chromaticity) is compared with
every later frame. A performer who walks from sunlight into shade, or under a lamp, changes
both: the body turns darker and, in shade lit by the sky, bluer. Compared as it was, every
anchor point is then off by the light's change and the anchor's terms fall silent or pull the
wrong way (on the real side-on walk of ``benchmarks/bench_real.py`` the anchor's colour made
15 frames called lost instead of 8).

The change is measured on the whole body at a tracked frame, as medians over the anchor's
visible points (a limb or two gone wrong do not move them): a gain of the grey levels and a
shift of each chromaticity channel, and the anchor is compared under them (:func:`relit`).
A gain per colour channel (von Kries' model, with the chromaticity predicted per point) was
worse on that walk: 18 and 36 frames lost (shipped prior, prior of walks) against 8 and 10
with the shift.
"""

import numpy as np

from .frames import CHROMA_OFFSET, chroma_channels


# OpenCV's luma weights, B, G, R (``plates.to_gray_float``).
LUMA = np.array([0.114, 0.587, 0.299])
# Fewer of the anchor's points visible than this leave a view's light as it was at the anchor.
MIN_POINTS = 50
# Grey levels darker than this say nothing of a gain.
DARK = 0.05
# The gain is held within [1 / MAX_GAIN, MAX_GAIN], the shifts within +-MAX_SHIFT.
MAX_GAIN = 3.0
MAX_SHIFT = 0.1


def _colour_of(gray, chroma):
    """BGR in [0, 1] from the grey level and the two chromaticity channels (the inverse of
    :func:`frames.chromaticity` with ``plates.to_gray_float``'s luma)."""
    k = CHROMA_OFFSET
    r, g = np.asarray(chroma[0], float), np.asarray(chroma[1], float)
    b = 1.0 - r - g
    total = (np.asarray(gray, float) + k) / (LUMA[0] * b + LUMA[1] * g + LUMA[2] * r)
    return np.stack([b * total - k, g * total - k, r * total - k], axis=-1)


def _darkened(anchor_gray, anchor_chroma, gain):
    """The anchor's chromaticity under a light ``gain`` times as bright: the same colours,
    but the chromaticity's offset for dark pixels weighs more in a darker one."""
    colour = np.clip(_colour_of(anchor_gray, anchor_chroma) * gain, 0.0, None)
    return chroma_channels(colour[..., 0], colour[..., 1], colour[..., 2])


def measure(anchor_gray, anchor_chroma, gray, chroma):
    """The light's change from the anchor's values at visible points of the body to a
    frame's values at the same points.

    Parameters
    ----------
    anchor_gray, gray : array, shape (n,)
    anchor_chroma, chroma : list of two arrays, shape (n,), or None
        None for grey plates.

    Returns
    -------
    light : array, shape (3,) (the grey levels' gain, the two chromaticity channels' shifts
        beyond the gain's; colour plates) or (1,) (grey plates), or None with too few points.
    """
    anchor_gray, gray = np.asarray(anchor_gray, float), np.asarray(gray, float)
    lit = anchor_gray > DARK
    if lit.sum() < MIN_POINTS:
        return None
    gain = np.clip(np.median(gray[lit] / anchor_gray[lit]), 1 / MAX_GAIN, MAX_GAIN)
    if anchor_chroma is None or chroma is None:
        return np.array([gain])
    shifts = [np.clip(np.median(np.asarray(now, float) - before), -MAX_SHIFT, MAX_SHIFT)
              for before, now in zip(_darkened(anchor_gray, anchor_chroma, gain), chroma)]
    return np.array([gain, *shifts])


def relit(anchor_gray, anchor_chroma, light):
    """The anchor's grey levels and chromaticities (None on grey plates) under ``light``
    (:func:`measure`)."""
    gray = np.asarray(anchor_gray, float) * light[0]
    if anchor_chroma is None or len(light) == 1:
        return gray, anchor_chroma
    return gray, [c + shift for c, shift in
                  zip(_darkened(anchor_gray, anchor_chroma, light[0]), light[1:])]


__all__ = ["measure", "relit"]
