"""Background model, foreground masks and silhouette distance images.

Frame-to-frame image motion drifts (Yamamoto et al. §4; Sidenbladh et al. §7). A persistent cue
against drift is the person's silhouette against the static background: the background is
estimated from the plates themselves as each pixel's most consistent colour over frames spread
over the take (the person's moving, textured clothes don't repeat one colour at one pixel, the
background does), and each frame's foreground is what differs from it by more than the noise.

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
    known : array of bool, shape (H, W), optional
        Where the background was seen. Elsewhere (the person never left those pixels) the
        foreground mask says "foreground", so that a silhouette cue cannot push the model out.
    """

    image: np.ndarray
    sigma: float
    known: np.ndarray = None

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
        mask = mask.astype(bool)
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


def estimate_background(frames, *, tolerance=None, exclude=()):
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

    Returns
    -------
    BackgroundModel
    """
    stack = np.stack([_as_float(f) for f in frames])                 # (N, H, W, 3)
    median = np.median(stack, axis=0)
    noise = float(1.4826 * np.median(np.linalg.norm(stack - median, axis=3))) + 1e-3
    tol = max(4.0 * noise, 0.05) if tolerance is None else tolerance
    person = np.zeros(stack.shape[:3], bool)                          # (N, H, W)
    for image, mask in exclude:
        ref = _as_float(image)
        person |= mask[None] & (np.linalg.norm(stack - ref, axis=3) < tol)
    best_count = np.zeros(stack.shape[1:3], np.int32)
    best_sum = median.copy()
    for i in range(len(stack)):
        close = (np.linalg.norm(stack - stack[i], axis=3) < tol) & ~person   # (N, H, W)
        count = np.where(person[i], 0, close.sum(axis=0))
        better = count > best_count
        if np.any(better):
            mean = (stack * close[..., None]).sum(axis=0) / np.maximum(count, 1)[..., None]
            best_sum[better] = mean[better]
            best_count[better] = count[better]
    image = best_sum.astype(np.float32)
    known = best_count >= max(2, len(stack) // 8)
    diffs = np.linalg.norm(stack - image, axis=3)[:, known]
    sigma = float(1.4826 * np.median(diffs)) + 1e-3 if diffs.size else noise
    return BackgroundModel(image, sigma, known)


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


def model_coverage(model_mask, observed_mask, known=None):
    """Fraction of the model's silhouette that the foreground covers, over pixels where the
    background is known (how reliable a view's background is for this take)."""
    if known is not None:
        model_mask = model_mask & known
    n = model_mask.sum()
    return 0.0 if n == 0 else float(np.logical_and(model_mask, observed_mask).sum() / n)
