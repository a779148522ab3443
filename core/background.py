"""Background model, foreground masks and silhouette distance images.

Frame-to-frame image motion drifts (Yamamoto et al. §4; Sidenbladh et al. §7). A persistent cue
against drift is the person's silhouette against the static background: the background is
estimated from the plates themselves as the per-pixel median of frames spread over the take (a
moving person leaves each pixel most of the time), and each frame's foreground is what differs
from it by more than the noise.

Convention: images are BGR uint8 or float32 in [0, 1], at the tracker's working resolution.
"""

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class BackgroundModel:
    """Per-pixel background colour and the noise level of its differences.

    Attributes
    ----------
    image : array, shape (H, W, 3) float32 in [0, 1]
    sigma : float
        Robust standard deviation of ``|frame - background|`` over background pixels.
    """

    image: np.ndarray
    sigma: float

    def difference(self, frame):
        """Colour distance of a frame from the background, (H, W) float32."""
        f = _as_float(frame)
        return np.linalg.norm(f - self.image, axis=2)

    def foreground(self, frame, *, k=4.0, min_level=0.06):
        """Foreground mask of a frame, (H, W) bool, cleaned of specks and small holes."""
        d = self.difference(frame)
        mask = (d > max(k * self.sigma, min_level)).astype(np.uint8)
        kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, kernel)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, kernel, iterations=2)
        return mask.astype(bool)


def _as_float(frame):
    frame = np.asarray(frame)
    if frame.dtype == np.uint8:
        frame = frame.astype(np.float32) / 255.0
    else:
        frame = frame.astype(np.float32)
    if frame.ndim == 2:
        frame = np.repeat(frame[:, :, None], 3, axis=2)
    return frame


def estimate_background(frames):
    """Median background of a list of frames of one static view.

    Parameters
    ----------
    frames : list of array, shape (H, W, 3)
        Frames spread over the take (10-30 are plenty).

    Returns
    -------
    BackgroundModel
    """
    stack = np.stack([_as_float(f) for f in frames])
    image = np.median(stack, axis=0).astype(np.float32)
    diffs = np.linalg.norm(stack - image, axis=3)
    # Most pixels are background in most frames: the median absolute difference is noise.
    sigma = float(1.4826 * np.median(diffs)) + 1e-3
    return BackgroundModel(image, sigma)


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
    # Boundary at the half-pixel between the two sides.
    return (outside - inside).astype(np.float32) - np.where(m > 0, -0.5, 0.5).astype(np.float32)


def silhouette_iou(model_mask, observed_mask):
    """Intersection over union of two masks (1.0 when both are empty)."""
    inter = np.logical_and(model_mask, observed_mask).sum()
    union = np.logical_or(model_mask, observed_mask).sum()
    return 1.0 if union == 0 else float(inter / union)


def model_coverage(model_mask, observed_mask):
    """Fraction of the model's silhouette that the foreground covers (how reliable a view's
    background is for this take: low when the person stood still and became background)."""
    n = model_mask.sum()
    return 0.0 if n == 0 else float(np.logical_and(model_mask, observed_mask).sum() / n)
