"""The differential tracker's anchor: the appearance of an anchor frame, kept for the whole
pass and compared with every frame (grey levels and, on colour plates, chromaticity), under the
light of the frame before (:mod:`light`)."""

import numpy as np

from ..geometry import se3
from .image_motion import Term
from .light import measure, relit


class Anchor:
    """Mixed into :class:`differential.DifferentialTracker`, whose templates, settings,
    visibility test and cameras it uses."""

    def set_anchor(self, state, images, renders):
        """Keep the appearance of an anchor frame as a persistent template (per view).

        Stored per level as terms whose targets are the anchor's grey levels; they are checked
        against occlusion at every frame.
        """
        self.anchor_terms = self.template_terms(state, images, renders)
        for per_view in self.anchor_terms:
            for t in per_view or []:
                t.name = "anchor"
        # and its chromaticity at the same points, where the plates are in colour
        self.chroma_terms = None
        if self.settings.chroma_weight > 0 and all(im.chroma is not None for im in images):
            self.chroma_terms = [None if per_view is None else
                                 [self._chroma_anchor(t, images[t.view].chroma, level)
                                  for t in per_view]
                                 for level, per_view in enumerate(self.anchor_terms)]

    def _chroma_anchor(self, term, chroma, level):
        """Terms of the anchor's chromaticity channels at the points of its grey term."""
        u = term.uv[:, 0].astype(np.intp)
        v = term.uv[:, 1].astype(np.intp)
        return [Term(term.view, term.segment, term.ref_points, ch[level][v, u, 0].astype(float),
                     term.weight, self.settings.chroma_scale, f"chroma{k}",
                     np.full((len(term), 2), np.nan)) for k, ch in enumerate(chroma)]

    def _relight(self, state, renders, images):
        """Per view, the light's gains since the anchor frame (:func:`light.measure`) at a
        tracked frame, ``state`` on ``images``; None per view with too few points."""
        if self.anchor_terms is None or not self.settings.relight:
            return None
        level = min(self.settings.finest, self.settings.levels - 1)
        if self.anchor_terms[level] is None:
            return None
        out = []
        for c, at in enumerate(self.anchor_terms[level]):
            seen = self._visible(at, state, level, renders)
            gray = images[c].gray[level]
            _, gu, gv = self.anchor_pixels(state, c, level, seen, gray.shape)
            chroma = None if self.chroma_terms is None or images[c].chroma is None else \
                [ch[level][gv, gu, 0] for ch in images[c].chroma]
            out.append(measure(*self.anchor_targets(c, level, seen, lit=False),
                               gray[gv, gu], chroma))
        return out

    def anchor_pixels(self, state, c, level, select, shape):
        """View ``c``'s anchor points ``select`` at ``state``, projected at ``level``: their
        image positions, and the rows and columns of their nearest pixels in an image of
        ``shape`` (clipped to it)."""
        at = self.anchor_terms[level][c]
        X = se3.apply(self._seg2world(state, c)[at.segment[select]], at.ref_points[select])
        uv = self._camera_at(state.cameras[c], level).project(X)
        gu = np.clip(np.rint(uv[:, 0]).astype(np.intp), 0, shape[1] - 1)
        gv = np.clip(np.rint(uv[:, 1]).astype(np.intp), 0, shape[0] - 1)
        return uv, gu, gv

    def anchor_targets(self, c, level, select, lit=True):
        """View ``c``'s anchor targets at ``level`` for the points ``select``: grey levels and
        chromaticities (None on grey plates), under the light measured last (``lit``)."""
        gray = self.anchor_terms[level][c].target[select]
        chroma = None if self.chroma_terms is None else \
            [t.target[select] for t in self.chroma_terms[level][c]]
        gains = None if not lit or self.light is None else self.light[c]
        return (gray, chroma) if gains is None else relit(gray, chroma, gains)


__all__ = ["Anchor"]
