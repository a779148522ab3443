"""One frame of one view as the trackers use it: the grey pyramid with its gradients, the
colour's chromaticity, the foreground and its signed distance images; and the thread pools that
prepare frames and views while others are tracked."""

import os
from dataclasses import dataclass

import cv2
import numpy as np

from ..imaging.background import signed_distance
from .image_motion import image_with_gradients

_POOLS = {}
# a forked child has none of its parent's threads: it makes its own pools
os.register_at_fork(after_in_child=_POOLS.clear)


def thread_pool(name, workers):
    """A thread pool made on first use and shared by the trackers, one per purpose."""
    pool = _POOLS.get(name)
    if pool is None:
        from concurrent.futures import ThreadPoolExecutor

        pool = _POOLS[name] = ThreadPoolExecutor(max_workers=workers,
                                                 thread_name_prefix=f"zoopraxis-{name}")
    return pool


@dataclass
class ViewImages:
    """One view's frame at the tracker's working resolution.

    Attributes
    ----------
    gray : list of array (H_l, W_l) float32
        Gaussian pyramid of the smoothed grey image, level 0 first.
    stacks : list of array (H_l, W_l, 3) float32
        Each level with its gradients, for sampling.
    foreground : array of bool (H, W) or None
        Foreground mask from the background model (None when unreliable or absent).
    sdf : list of array (H_l, W_l, 3) or None
        Signed distance to the foreground boundary per level, with gradients.
    chroma : list of list of array (H_l, W_l, 3) or None
        Per chromaticity channel (:func:`chromaticity`), the pyramid with gradients, level 0
        first; None for grey plates.
    """

    gray: list
    stacks: list
    foreground: np.ndarray = None
    sdf: list = None
    known: np.ndarray = None      # where the background model has seen the background
    person: np.ndarray = None     # the foreground without cast shadows (what the body covers)
    chroma: list = None


# Added to each channel before the chromaticity's division: keeps the noise of dark pixels
# (where R + G + B is small) from passing for colour.
CHROMA_OFFSET = 0.06


def chromaticity(colour):
    """The two chromaticity channels ``(R + k) / (R + G + B + 3k)`` and ``(G + k) / (...)`` of
    a BGR image in [0, 1] (``k``: :data:`CHROMA_OFFSET`): its colour without its brightness,
    which shading and the light's strength change while a limb moves. Returns None for a grey
    image (one channel, or three equal ones)."""
    c = np.asarray(colour)
    if c.ndim != 3 or c.shape[2] < 3:
        return None
    if c.dtype == np.uint8:
        c = c[..., :3].astype(np.float32) * np.float32(1 / 255)
    elif c.dtype == np.uint16:
        c = c[..., :3].astype(np.float32) * np.float32(1 / 65535)
    else:
        c = np.clip(c[..., :3].astype(np.float32), 0.0, 1.0)
    b, g, r = c[..., 0], c[..., 1], c[..., 2]
    if np.array_equal(b, g) and np.array_equal(g, r):
        return None
    return chroma_channels(b, g, r)


def chroma_channels(b, g, r):
    """:func:`chromaticity`'s two channels of the colour channels ``b, g, r`` (arrays of one
    float type, which the result keeps)."""
    k = r.dtype.type(CHROMA_OFFSET)
    total = b + g + r + 3 * k
    return [(r + k) / total, (g + k) / total]


def _pyramid(image, levels, smooth_sigma):
    g = np.asarray(image, np.float32)
    if smooth_sigma > 0:
        g = cv2.GaussianBlur(g, (0, 0), smooth_sigma)
    pyr = [g]
    for _ in range(1, levels):
        pyr.append(cv2.pyrDown(pyr[-1]))
    return pyr


def prepare_images(gray, levels, smooth_sigma, foreground=None, known=None, person=None,
                   colour=None):
    """Pyramid, gradients and silhouette distance images of one frame of one view
    (``colour``: the frame in colour, BGR, for its chromaticity)."""
    pyr = _pyramid(gray, levels, smooth_sigma)
    stacks = [image_with_gradients(p) for p in pyr]
    chroma = None if colour is None else chromaticity(colour)
    if chroma is not None:
        chroma = [[image_with_gradients(p) for p in _pyramid(ch, levels, smooth_sigma)]
                  for ch in chroma]
    sdf = None
    if foreground is not None:
        sdf = []
        m = foreground.astype(np.float32)
        for level in range(levels):
            if level:
                m = cv2.pyrDown(m)
            sdf.append(image_with_gradients(signed_distance(m > 0.5)))
    return ViewImages(pyr, stacks, foreground, sdf, known,
                      foreground if person is None else person, chroma)
