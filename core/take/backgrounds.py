"""The background models of a take, and the silhouette measures taken against them.

Frames spread over the take give each view's background (:func:`take_backgrounds`), with the
model's silhouette at the anchors kept out of it; after a first track the backgrounds are
estimated again with the tracked body kept out of every sampled frame
(:func:`tracked_backgrounds`), and the frames' measures can be taken again against them
(:func:`remeasure`).
"""

import cv2
import numpy as np

from ..imaging.background import estimate_background, model_coverage, silhouette_iou, widened
from ..trackers.frames import thread_pool
from .status import MIN_ANCHOR_FIT, silhouette_measures, unexplained_fraction

# How far beyond the model's silhouette at an anchor frame (a fraction of its height) the
# frame is taken to show the background: clothes and hair wider than the model stay inside.
SHOWN_MARGIN = 0.1


def take_backgrounds(tracker, source, views, frames, inside, state_at, log):
    """Background model per view, whether to use it, and the first anchor's silhouette fit,
    overlap and unexplained foreground (the references for the frames' status).

    Frames spread over the take give each view's background; the model's dilated silhouette at
    the anchors keeps the person out of it; a view whose foreground does not cover the model at
    the first anchor goes without silhouettes.
    """
    sample = sample_frames(frames)
    log(f"background: {len(sample)} frames per view")
    per_view = [[] for _ in views]
    for f in sample:
        for c, img in enumerate(source.colour(int(f))):
            per_view[c].append(img)
    exclude = [[] for _ in views]
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (9, 9))
    anchor_renders = [(a.frame, tracker.render_views(state_at(a.frame), want=()))
                      for a in inside]
    for frame, renders_a in anchor_renders:
        for c, img in enumerate(source.colour(frame)):
            mask = cv2.dilate((renders_a[c].label >= 0).astype(np.uint8), kernel) > 0
            exclude[c].append((img, mask))
    shown = anchors_shown(source, anchor_renders, len(views))
    # one view per thread: the estimate is whole-image numpy and OpenCV work, outside the GIL
    backgrounds = list(thread_pool("views", 2).map(
        lambda c: estimate_background(per_view[c], exclude=exclude[c], shown=shown[c],
                                      times=sample)
        if len(per_view[c]) >= 5 else None, range(len(views))))
    use_bg = [bg is not None for bg in backgrounds]
    a0, r0 = anchor_renders[0]
    colour0 = source.colour(a0)
    ref_fit = np.full(len(views), np.nan)
    ref_iou = np.full(len(views), np.nan)
    ref_unexplained = np.full(len(views), np.nan)
    for c in range(len(views)):
        if not use_bg[c]:
            continue
        bg = backgrounds[c]
        cov = model_coverage(r0[c].label >= 0, bg.foreground(colour0[c]) & bg.known, bg.known)
        if cov < 0.5:
            use_bg[c] = False
            log(f"view '{views[c]}': background model unreliable here "
                f"(covers {cov:.0%} of the body); silhouettes off")
            continue
        fg = bg.foreground(colour0[c])
        ref_fit[c] = model_coverage(r0[c].label >= 0, fg)
        ref_iou[c] = max(silhouette_iou(r0[c].label >= 0, fg), 0.05)
        if ref_fit[c] < MIN_ANCHOR_FIT:
            use_bg[c] = False
            log(f"view '{views[c]}': only {ref_fit[c]:.0%} of the model lies in the "
                "foreground at the anchor; silhouettes off")
            ref_fit[c] = ref_iou[c] = np.nan
            continue
        ref_unexplained[c] = unexplained_fraction(bg.person(colour0[c], fg), r0[c].label,
                                                  bg.known)
    return backgrounds, use_bg, ref_fit, ref_iou, ref_unexplained


def anchors_shown(source, anchors, n_views):
    """Per view, the anchor frames' ``(image, mask, frame)`` for
    :func:`~zoopraxis.core.imaging.background.estimate_background`'s ``shown``: outside the
    model's silhouette widened by ``SHOWN_MARGIN`` of its height, an anchor frame shows the
    background. ``anchors``: ``(frame, renders)`` of the model at each anchor."""
    shown = [[] for _ in range(n_views)]
    for frame, renders in anchors:
        for c, img in enumerate(source.colour(frame)):
            body = widened(renders[c].label >= 0, SHOWN_MARGIN, least=4)
            if body is not None:
                shown[c].append((img, body, frame))
    return shown


def sample_frames(frames):
    """The frames spread over the take that the background models are estimated from."""
    return np.unique(np.linspace(frames.start, frames.stop - 1,
                                 min(25, len(frames))).astype(int))


def tracked_backgrounds(tracker, source, views, frames, states, use_bg, anchors=()):
    """Background models estimated again with the tracked body kept out of them.

    The first estimate knows where the person is at the anchor frames only; a person who
    stands still for a third of the take or more (a crouch before a jump, a turn on the spot)
    is taken for background there, and the foreground loses them. With the tracked poses,
    every sampled frame's (dilated) model silhouette is kept out.

    Returns
    -------
    list of BackgroundModel or None
        Per view; None where the view's background is not used.
    """
    sample = [int(f) for f in sample_frames(frames) if int(f) in states]
    shown = anchors_shown(source, [(a, tracker.render_views(states[a], want=()))
                                   for a in anchors if a in states], len(views))
    return backgrounds_without_body(
        source, sample,
        lambda f: [r.label >= 0 for r in tracker.render_views(states[f], want=())],
        [u and len(sample) >= 5 for u in use_bg], shown=shown)


def backgrounds_without_body(source, frames, silhouettes, wanted, margin=9, shown=None):
    """Each view's background from ``frames``, with where the body is in each frame kept out.

    Parameters
    ----------
    source : FrameSource
    frames : list of int
    silhouettes : callable(frame) -> list of array of bool
        The body's silhouette in each view at a frame (dilated here by ``margin`` pixels).
    wanted : list of bool
        Per view: estimate it (else None).
    shown : list of list, optional
        Per view, the anchor frames that show the background outside the body
        (:func:`anchors_shown`).

    Returns
    -------
    list of BackgroundModel or None
    """
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (margin, margin))
    per_view = [[] for _ in wanted]
    masks = [[] for _ in wanted]
    for f in frames:
        for c, (img, body) in enumerate(zip(source.colour(f), silhouettes(f))):
            per_view[c].append(img)
            masks[c].append(cv2.dilate(body.astype(np.uint8), kernel) > 0)
    return list(thread_pool("views", 2).map(
        lambda c: estimate_background(per_view[c], masks=np.stack(masks[c]),
                                      shown=shown[c] if shown else (), times=frames)
        if wanted[c] else None, range(len(wanted))))


def remeasure(tracker, source, states, reports, anchor_frames, backgrounds, use_bg, limbs):
    """The silhouette measures of every tracked frame and of the first anchor against new
    background models (:func:`tracked_backgrounds`), in place of the reports' own.

    Returns
    -------
    ref_fit, ref_iou, ref_unexplained : array, shape (V,)
        The first anchor's, the references of the frames' status.
    """
    usable = [u and bg is not None for u, bg in zip(use_bg, backgrounds)]
    for f, rep in reports.items():
        if rep is None or f in anchor_frames:
            continue
        rep.coverage, rep.iou, rep.unexplained, limb_fit = silhouette_measures(
            tracker, states[f], source.colour(f), backgrounds, usable, limbs=limbs)
        if limb_fit is not None:
            rep.limb_fit = limb_fit
    return anchor_references(tracker, source, states, anchor_frames, backgrounds, use_bg)


def anchor_references(tracker, source, states, anchor_frames, backgrounds, use_bg):
    """The first anchor's silhouette fit, overlap and unexplained foreground against
    ``backgrounds``, where ``use_bg``: the references of the frames' status."""
    a0 = anchor_frames[0]
    usable = [u and bg is not None for u, bg in zip(use_bg, backgrounds)]
    fit, iou, unexplained, _ = silhouette_measures(tracker, states[a0], source.colour(a0),
                                                   backgrounds, usable)
    return fit, np.maximum(iou, 0.05), unexplained
