"""The passes of a take between its anchors, and how two passes are blended.

Between two anchors the take is tracked forward from the first and backward from the second,
each pass to a little past the middle (:func:`plan_passes`, :func:`blend_stretch`); the two are
blended there with weights that fall off with the distance from their anchor and with a pass's
loss of the body (:func:`blend_weights`), and a pass goes further when the other one lost the
body on its way (:func:`extend_passes`). Before the first anchor the take is tracked backward,
after the last forward.
"""

import numpy as np

from ..geometry import se3

# Between two anchors the forward pass tracks to BLEND_REACH frames past the middle and the
# backward pass as far before it, and the two are blended over that stretch: each frame is
# tracked from its nearer anchor, and far fewer frames are tracked than with two whole passes.
# A pass whose quality (see blend_weights) falls below POOR_PASS before the stretch calls its
# partner on towards its anchor. bench_track's walk3-anchors (anchors every 100 frames, 2
# processes), runs alternated: whole passes (--whole-passes) 29.0 mm at 5.6-7.2 fps, 8 frames
# 28.0 mm at 10.3-12.0 fps. 15 frames gave 28.1 mm; 4 frames 25.6 mm, but left a jump at a
# seam: a joint acceleration of 50 mm per frame^2, where the walk's own reaches 22.
BLEND_REACH = 8
POOR_PASS = 0.5


def _blend_camera(a, b, w):
    """Uncalibrated cameras between two states: the scale geometrically, the perspective
    linearly (w: 0 -> a)."""
    s = float(np.exp((1 - w) * np.log(a.s) + w * np.log(b.s)))
    if not (a.kappa or b.kappa):
        return a.replace(s=s)
    kappa = (1 - w) * a.kappa + w * b.kappa
    if not kappa > 0.0:         # at the far one of a far and a near camera
        return (b if w >= 0.5 else a).replace(s=s)
    return a.replace(s=s, kappa=kappa, t=[0.0, 0.0, 1.0 / kappa])


def blend_states(a, b, w):
    """Pose between two states: angles linearly, roots along the SE(3) geodesic (w: 0 -> a)."""
    out = a.copy()
    out.angles = (1 - w) * a.angles + w * b.angles
    for c in range(len(a.roots)):
        rel = se3.log_se3(b.roots[c] @ se3.invert(a.roots[c]))
        out.roots[c] = se3.exp_se3(w * rel) @ a.roots[c]
    if hasattr(a.cameras[0], "s"):
        out.cameras = [_blend_camera(ca, cb, w) for ca, cb in zip(a.cameras, b.cameras)]
    return out


def plan_passes(anchor_frames, frames, reach=BLEND_REACH):
    """The tracking passes of a take: from the first anchor back to the take's start, between
    each two anchors (forward, then backward, to be blended), and from the last anchor to the
    end.

    Parameters
    ----------
    anchor_frames : list of int
        Sorted anchor frames inside ``frames``.
    frames : range
    reach : int or None
        Between two anchors, how far past the middle each pass tracks at first
        (:func:`blend_stretch`).

    Returns
    -------
    passes : list of (int, int, (int, int) or None)
        ``(start, stop, stretch)``, both ends included. Between two anchors ``start < stop``
        and ``stretch`` is the blended stretch ``(lo, hi)``: the forward pass tracks to
        ``hi``, the backward one to ``lo``. None for a single pass.
    total : int
        Frames the passes track at first: for progress.
    """
    passes = []
    if anchor_frames[0] > frames.start:
        passes.append((anchor_frames[0], frames.start, None))
    for a, b in zip(anchor_frames[:-1], anchor_frames[1:]):
        passes.append((a, b, blend_stretch(a, b, reach)))
    if anchor_frames[-1] < frames.stop - 1:
        passes.append((anchor_frames[-1], frames.stop - 1, None))
    total = sum(abs(b - a) if st is None else st[1] - a + b - st[0] for a, b, st in passes)
    return passes, total


def _pass_quality(reports):
    """Each frame's largest grey residual over the views and mean silhouette overlap."""
    r = np.array([np.max(rep.residual) for rep in reports], float)
    iou = np.array([np.nanmean(rep.iou) if np.isfinite(rep.iou).any() else np.nan
                    for rep in reports], float)
    return r, iou


def _references(forward, backward):
    """The better pass's typical residual and overlap over the frames both tracked (a whole
    pass may be lost)."""
    rf, iou_f = _pass_quality(forward)
    rb, iou_b = _pass_quality(backward)
    r_ref = min(np.median(rf), np.median(rb)) + 1e-9
    medians = [np.nanmedian(i) for i in (iou_f, iou_b) if np.isfinite(i).any()]
    return r_ref, (max(medians) if medians else np.nan)


def _goodness(reports, references, smooth):
    """Per frame, 1 for a pass as good as the reference, towards 0 for one that has lost the
    body (a grey residual above the reference, or a poorer overlap); a running mean over
    ``smooth`` frames keeps it from jumping."""
    r_ref, iou_ref = references
    r, iou = _pass_quality(reports)
    g = np.exp(-np.maximum(r / r_ref - 1.0, 0.0))
    if np.isfinite(iou_ref):
        g *= np.clip(np.nan_to_num(iou, nan=iou_ref) / iou_ref, 0.05, 1.0) ** 2
    n = len(g)
    if smooth > 1 and n > 1:
        kernel = np.ones(min(smooth, n)) / min(smooth, n)
        g = np.convolve(np.pad(g, len(kernel) // 2, mode="edge"), kernel, "valid")[:n]
    return g


def blend_weights(forward, backward, smooth=5):
    """How much of the backward pass each frame of a blended stretch takes (0: all forward).

    By distance, the nearer anchor's pass counts more; by quality, a pass that has lost the
    body (a grey residual well above the two passes' median, or a poorer silhouette overlap)
    counts less, so that a blend does not drag a good pass towards a lost one.

    Parameters
    ----------
    forward, backward : list of StepReport
        The two passes' reports at the frames of the stretch, in frame order.
    smooth : int
        Frames of the running mean that keeps the weights from jumping.

    Returns
    -------
    array, shape (n,)
    """
    n = len(forward)
    if n == 0:
        return np.zeros(0)
    w = np.arange(1, n + 1) / (n + 1)
    refs = _references(forward, backward)
    gf, gb = _goodness(forward, refs, smooth), _goodness(backward, refs, smooth)
    return w * gb / ((1 - w) * gf + w * gb + 1e-12)


def blend_stretch(a, b, reach=None):
    """The frames between anchors ``a < b`` that both passes track at first: ``reach`` frames
    either side of the middle (all of them when ``reach`` is None or the anchors are close).

    Returns
    -------
    lo, hi : int
        The forward pass tracks ``a+1 .. hi``, the backward pass ``lo .. b-1``.
    """
    if reach is None:
        return a + 1, b - 1
    mid = (a + b) // 2
    return max(a + 1, mid - reach), min(b - 1, mid + reach)


def extend_passes(forward, backward, lo, hi, reach, poor=POOR_PASS, smooth=5):
    """How far the two passes between two anchors must go on after their first stretch.

    A pass that lost the body before the blended stretch ``lo .. hi`` began leaves frames that
    only it has tracked: its partner goes on towards the first anchor, to ``reach`` frames
    before the first frame where the lost pass's quality (:func:`_goodness`, against the two
    passes' references over the stretch) falls below ``poor``.

    Parameters
    ----------
    forward : dict of int to StepReport
        Frames ``a+1 .. hi``.
    backward : dict of int to StepReport
        Frames ``lo .. b-1``.

    Returns
    -------
    forward_to : int
        The last frame the forward pass must reach (``hi`` when it need not go on).
    backward_to : int
        The first frame the backward pass must reach (``lo`` when it need not go on).
    """
    stretch = range(lo, hi + 1)
    if not stretch:
        return hi, lo       # adjacent anchors: nothing between them
    refs = _references([forward[f] for f in stretch], [backward[f] for f in stretch])
    backward_to, forward_to = lo, hi
    early = sorted(f for f in forward if f < lo)
    if early:
        g = _goodness([forward[f] for f in early], refs, smooth)
        bad = [f for f, x in zip(early, g) if x < poor]
        if bad:
            backward_to = max(early[0], bad[0] - reach)
    late = sorted(f for f in backward if f > hi)
    if late:
        g = _goodness([backward[f] for f in late], refs, smooth)
        bad = [f for f, x in zip(late, g) if x < poor]
        if bad:
            forward_to = min(late[-1], bad[-1] + reach)
    return forward_to, backward_to
