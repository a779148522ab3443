"""The differential tracker's use of the limb search (:mod:`recover`): when the silhouette
search moves a limb, the frame is solved again from there, and the new pose is kept only if
the frame is explained better, no view's silhouette is spoiled to fill the others'
(``Settings.refit_view_drop``), every moved limb still looks like itself, and no moved leg
has left the person in a view that showed it there (``LEG_LEAVES_VIEW``).

The silhouettes alone cannot tell a lost limb from a wider body. A performer in loose clothes
fills more of the foreground than the model's trunk does, and an arm drawn into that gap
raises the silhouettes' overlap while leaving the arm's own pixels (walk131_hard, one set of
clicks: a wrist 50 mm off drawn 260-400 mm away, for the rest of the take). What the arm looked
like at the anchor frame says which is which: at its true place its points sample the sleeve
and the hand they sampled then; drawn into the gap, they sample the trunk's clothes. So a moved
limb is kept only when the anchor's appearance of its visible points fits the new frame no
worse than at the pose the search started from (an arm: hardly worse, ``APPEARANCE_SLACK``).

The search draws an arm whose hand has lost its colour back to it (``Settings.hands``,
:meth:`LimbRefit.end_colours`): in front of the trunk the silhouettes say nothing of an arm,
and a bare hand differs from the clothes more than any other part.

The same way, a frame is solved again from a second start when the body turns fast about the
vertical (:meth:`LimbRefit._whole_turn`), and the start that explains it better is kept.
"""

import numpy as np

from ..geometry import se3
from .image_motion import shown_in_render
from .light import relit
from .recover import _rest_of_body, unexplained_foreground, unexplained_share

# Fewer visible points of a limb than this, at either pose, leave its appearance unjudged.
APPEARANCE_MIN_POINTS = 20
# How much worse (in the cost of :meth:`LimbRefit.limb_appearance`) a moved limb may look than
# before and still be kept. Legs keep their look: on the renders a leg drawn wrong looks
# 0.3-0.7 worse, one drawn right within 0.03. An arm turns and is thin: judged in grey alone a
# good arm move looked up to 0.13 worse and a bad one as little as 0.05; with the anchor's
# colour (``frames.chromaticity``) good moves look at most 0.015 worse (one 0.04), bad ones
# 0.04-0.3. Over click seeds 7-12, an arm's slack of 0.02 against 0.1: dance05_hard 72.3 /
# 71.2 mm, jumps01_hard 19.1 / 24.1 (0.1 let a right arm 0.05 worse-looking go 300 mm wrong),
# punch02 32.4 / 31.1, sword02 28.6 / 28.2, walk131_hard 34.7 / 36.3.
APPEARANCE_SLACK = {"leg": 0.0, "arm": 0.02}
# A moved leg is not kept when a view that showed it on the person no longer does: its
# silhouette score there (:meth:`recover.LimbSearch.fit`'s, view by view: 1 inside, -1 outside)
# falls by more than this, in a view that shows a third of the leg after the move (before it, a
# view showing less scores all of the leg's points: the leg was behind the other one). A leg is
# thick and its foreground sure; an arm is thin, and good arm moves fall that far in a view
# (0.66, to -0.5). Hooked over eight runs of six sets, the refits kept 9 leg moves: the 4 that
# brought a leg nearer the truth fell by at most 0.05 in any view; the 3 that put
# dance05_hard's left leg 0.36-0.41 m off in its last frames fell by 0.87-1.22, to -0.45 to
# -0.69, in the one view that saw background there (the overlap that the other leg, moved with
# it, gained in that view hid the loss from ``Settings.refit_view_drop``).
LEG_LEAVES_VIEW = 0.5


# A second start for the step when the pelvis turns about the vertical: the prediction keeps
# part of the last frame's turn (``settings.velocity``, ``root_carry``); when keeping all of it
# would turn the body this much further (degrees), the step runs from there too.
TURN_HYPOTHESIS_DEG = 2.0

# An arm's end is drawn to its colour (``recover.END_BONUS``) in the views where at least this
# many anchor points of the hand were seen; the colour's spread is at least the chromaticity's
# robust scale.
END_MIN_POINTS = 8
# ... and only if at most this share of the trunk's and legs' anchor points is within the
# chromaticity's robust scale of the hands' colour (hands in gloves of the trousers' colour say
# nothing). Bare arms and the face may share it: the search keeps a hand out of the other arm
# and away from the head (:meth:`LimbRefit.end_colours`).
END_SHARED = 0.1


class LimbRefit:
    """Mixed into :class:`differential.DifferentialTracker`, whose search, settings, anchor
    terms and steps it uses."""

    def limb_appearance(self, state, renders, images, segments):
        """How far the anchor's appearance of ``segments`` is from ``images`` at ``state``.

        Parameters
        ----------
        state : State
        renders : list of RenderResult
            The model rendered at ``state`` (which points are visible).
        images : list of ViewImages
        segments : array of int

        Returns
        -------
        cost : float
            Mean robust (Geman-McClure) residual in [0, 1) of the segments' anchor points
            visible at ``state``, over all views, in grey and (colour plates) chromaticity
            alike; NaN without an anchor.
        n : int
            Points visible.
        """
        if self.anchor_terms is None:
            return float("nan"), 0
        level = min(self.settings.finest, self.settings.levels - 1)
        total, n = 0.0, 0
        for c, at in enumerate(self.anchor_terms[level]):
            sel = np.isin(at.segment, segments)
            if not sel.any():
                continue
            seg = at.segment[sel]
            uv, gu, gv = self.anchor_pixels(state, c, level, sel, images[c].gray[level].shape)
            visible = shown_in_render(seg, uv, renders[c].label, level)
            if not visible.any():
                continue
            # the grey anchor and, on colour plates, its chromaticity, under the light the
            # step follows (``anchor_targets``)
            gray, chroma = self.anchor_targets(c, level, np.flatnonzero(sel)[visible])
            channels = [(gray, images[c].gray[level], at.scale)]
            if chroma is not None and images[c].chroma is not None:
                channels += [(target, ch[level][..., 0], t.scale) for target, ch, t in
                             zip(chroma, images[c].chroma, self.chroma_terms[level][c])]
            gu, gv = gu[visible], gv[visible]
            for target, image, scale in channels:
                r = (image[gv, gu] - target) / scale
                r *= r
                total += float(np.sum(r / (1.0 + r))) / len(channels)
            n += int(visible.sum())
        return (total / n if n else float("nan")), n

    def _end_points(self, level):
        """Per arm with an end (``search.ends``), per view, the anchor points (indices into
        the view's anchor term at ``level``) on that end's surface where its colour is worth
        drawing the arm to, else None.

        The hands as seen at the anchor frame, on the person's foreground, in at least
        ``END_MIN_POINTS`` points: the colour (chromaticity) that most of these views agree on
        is the hands' (a hand the anchor pose put a little off samples the sleeve or the
        background in some views, never one colour in all of them). A view is used for a hand
        whose points there have that colour; where a view saw neither hand in it, the points
        of the others stand for it (a tuple of their grey levels and chromaticities instead of
        indices). No view is used if the trunk and legs have the colour too
        (``END_SHARED``)."""
        key = (id(self.anchor_terms), level)
        if getattr(self, "_end_cache", (None,))[0] == key:
            return self._end_cache[1]
        prims = self.search.prims
        terms, chroma = self.anchor_terms[level] or [], self.chroma_terms[level] or []
        scale = self.settings.chroma_scale
        names = self.body.segment_names
        arms = np.concatenate([g.segments for g in self.search.groups
                               if g.name in self.search.ends] + [[]]).astype(int)
        # the trunk and legs (the head and arms may be bare skin)
        nohead = [at.segment != names.index("head") if "head" in names else
                  np.ones(len(at.segment), bool) for at in terms]
        trunk_legs = [~np.isin(at.segment, arms) & k for at, k in zip(terms, nohead)]
        points, colours, counts = {}, [], []
        for name, p in self.search.ends.items():
            R, c, size = prims.prim2seg[p][:3, :3], prims.prim2seg[p][:3, 3], prims.size[p]
            per_view = []
            for v, (at, ch) in enumerate(zip(terms, chroma)):
                local = (at.ref_points - c) @ R / size
                # on the hand, and seen on the person's foreground (``template_terms``' weights)
                on = ((at.segment == prims.segment[p]) & (np.linalg.norm(local, axis=1) < 1.1)
                      & (at.weight >= 1.0))
                per_view.append(np.flatnonzero(on))
                if on.sum() >= END_MIN_POINTS:
                    colours.append([np.median(t.target[on]) for t in ch])
                    counts.append(on.sum())
            points[name] = per_view
        out = {name: [None] * len(terms) for name in points}
        if not colours:
            return self._cache_ends(key, out)
        colours = np.array(colours)
        close = np.linalg.norm(colours[:, None] - colours[None], axis=2) < scale
        best = close[np.argmax(close.sum(axis=1))]
        hand = np.median(colours[best], axis=0)
        shared = np.concatenate([np.linalg.norm(np.stack([t.target[r] for t in ch], axis=1)
                                                - hand, axis=1) < scale
                                 for ch, r in zip(chroma, trunk_legs)])
        if (np.sum(np.array(counts)[best]) < 2 * END_MIN_POINTS
                or (len(shared) and shared.mean() > END_SHARED)):
            return self._cache_ends(key, out)
        pooled = []
        for name, per_view in points.items():
            for v, sel in enumerate(per_view):
                if len(sel) >= END_MIN_POINTS and np.linalg.norm(
                        [np.median(t.target[sel]) for t in chroma[v]] - hand) < scale:
                    out[name][v] = sel
                    pooled.append((terms[v].target[sel], [t.target[sel] for t in chroma[v]]))
        # where a view saw neither hand in that colour, the others' points stand for it
        gray = np.concatenate([g for g, _ in pooled])
        pooled = (gray, [np.concatenate([ch[k] for _, ch in pooled]) for k in range(2)])
        for name, per_view in out.items():
            out[name] = [pooled if sel is None else sel for sel in per_view]
        return self._cache_ends(key, out)

    def _cache_ends(self, key, ends):
        self._end_cache = (key, ends)
        return ends

    def end_colours(self, state, images, labels, person=None):
        """What :meth:`recover.LimbSearch.search` draws each arm's end (the hand) to: per arm,
        per view, None or ``(channels, target, spread, elsewhere)``, the view's chromaticity
        images at full resolution, the hand's chromaticity at the anchor frame under the light
        measured last and its spread, and the pixels that earn nothing: off the ``person``
        (per view, the foreground without cast shadows; a shadow on a wooden floor is often
        of a skin's colour) and where the model's head or other arm is (bare arms and the face
        have the hands' colour). :meth:`_end_points` says where the colour is worth it."""
        if (self.anchor_terms is None or self.chroma_terms is None
                or not getattr(self.search, "ends", None)):
            return None
        level = min(self.settings.finest, self.settings.levels - 1)
        if self.anchor_terms[level] is None:
            return None
        ends = self._end_points(level)
        names = self.body.segment_names
        groups = {g.name: g for g in self.search.groups}
        out = {}
        planes = {}     # per view, its chromaticity channels made contiguous once (for gathers)
        for name, per_view in ends.items():
            others = [int(k) for o in ends if o != name for k in groups[o].segments]
            if "head" in names:
                others.append(names.index("head"))
            colours = []
            for c, sel in enumerate(per_view):
                im = images[c]
                if sel is None or im.chroma is None or labels[c] is None:
                    colours.append(None)
                    continue
                if isinstance(sel, tuple):
                    gains = None if self.light is None else self.light[c]
                    chroma = sel[1] if gains is None else relit(*sel, gains)[1]
                else:
                    _, chroma = self.anchor_targets(c, level, sel)
                target = np.array([np.median(t) for t in chroma])
                spread = max(self.settings.chroma_scale, float(np.median(
                    [1.4826 * np.median(np.abs(t - m)) for t, m in zip(chroma, target)])))
                # the other arm (bare arms have the hands' colour) and the head
                elsewhere = np.isin(labels[c], others)
                if person is not None and person[c] is not None:
                    elsewhere |= ~person[c]
                if c not in planes:
                    planes[c] = [np.ascontiguousarray(ch[0][..., 0]) for ch in im.chroma]
                colours.append((planes[c], target, spread, elsewhere))
            out[name] = colours
        return out

    def _looks_like_itself(self, group, state, renders, state2, renders2, images):
        """Whether limb ``group`` at ``state2`` fits its anchor appearance no worse than at
        ``state``, give or take its kind's ``APPEARANCE_SLACK`` (too few visible points at
        either pose: not judged, True)."""
        before, n1 = self.limb_appearance(state, renders, images, group.segments)
        after, n2 = self.limb_appearance(state2, renders2, images, group.segments)
        if min(n1, n2) < APPEARANCE_MIN_POINTS:
            return True
        return after <= before + APPEARANCE_SLACK.get(group.name.split()[-1], 0.0)

    def _leaves_a_view(self, group, state, renders, state2, renders2, sdfs):
        """Whether leg ``group`` at ``state2`` has left the person in a view that showed it
        there at ``state`` (``LEG_LEAVES_VIEW``); False for an arm. ``sdfs``: the search's."""
        if group.name.split()[-1] != "leg":
            return False

        def view_fit(st, rends):        # each view's score (recover.LimbSearch.fit's)
            rest = _rest_of_body([r.label for r in rends], group)
            out = self.search.score(st.roots, st.angles[None], group.segments, st.cameras,
                                    sdfs, rest, plain=True, views=True)
            return out[2][0], out[3][0]

        # a view that shows too little of the leg after the move (behind the other leg)
        # does not judge it: hidden points score at most recover.SHARED_CREDIT there
        (before, _), (after, shown) = view_fit(state, renders), view_fit(state2, renders2)
        with np.errstate(invalid="ignore"):
            return bool(np.any(shown & (before - after > LEG_LEAVES_VIEW)))

    def _whole_turn(self, state, report, state_t, images_t, images_t1, previous, renders_t,
                    flow):
        """The step again from a prediction that keeps the pelvis's whole last turn about the
        vertical, when that differs enough from the damped one; the pose that explains the
        frame better (its least-squares cost) is kept.

        A dancer's turn speeds up over a few frames and keeps on (a pirouette: 10-13 degrees
        a frame); the damped prediction falls behind by half a frame's turn at every frame,
        and a body seen from all sides fits its outline nearly as well turned a little wrong.
        A walker's turns are slower and come and go; there the damped start is kept when it
        explains the frame better."""
        if previous is None or not self.calibrated:
            return state, report
        turn = se3.log_so3(state_t.roots[0][:3, :3] @ previous.roots[0][:3, :3].T)[2]
        carry = self.settings.velocity if self.root_carry is None else self.root_carry[5]
        extra = (1.0 - carry) * turn
        if abs(np.degrees(extra)) < TURN_HYPOTHESIS_DEG:
            return state, report
        start = self.predict(state_t, previous)
        spin = se3.exp_so3(np.array([0.0, 0.0, extra]))
        for c in range(len(start.roots)):
            start.roots[c][:3, :3] = spin @ start.roots[c][:3, :3]
        state2, report2 = self._step(state_t, images_t, images_t1, previous, renders_t, start,
                                     flow)
        if (self.frame_cost(state2, state_t, images_t1, renders_t, flow)
                < self.frame_cost(state, state_t, images_t1, renders_t, flow)):
            return state2, report2
        return state, report

    def _search_limbs(self, state, report, state_t, images_t, images_t1, previous, renders_t,
                      flow):
        """The limb search after a step (:meth:`DifferentialTracker.step`), and the refit
        from what it moved when that explains the frame better; returns the frame's state and
        report, with the limbs' silhouette fit and the foreground left unexplained."""
        # contiguous: the search gathers from them at thousands of points per draw batch, and
        # a gather from a strided view copies the whole image first
        sdfs = [None if im.sdf is None else np.ascontiguousarray(im.sdf[0][..., 0])
                for im in images_t1]
        if all(d is None for d in sdfs):
            return state, report
        labels = [r.label for r in report.renders]
        known = [im.known for im in images_t1]
        person = [None if d is None else (d < 0 if im.person is None else im.person)
                  for d, im in zip(sdfs, images_t1)]
        unexplained = None      # per view, at ``state``: from the search when it ran
        # One view's silhouette leaves a limb's depth free (and scaled-orthographic views
        # fit perspective plates only roughly): the search needs two calibrated views.
        if (self.settings.limb_search and self.calibrated
                and sum(d is not None for d in sdfs) >= 2):
            colours = (self.end_colours(state, images_t1, labels, person)
                       if self.settings.hands else None)
            angles, moved = self.search.search(state, sdfs, labels, known, person, colours)
            unexplained = self.search.last_unexplained
            if moved:
                refit = self._refit(state, report, angles, [name for name, _ in moved], sdfs,
                                    state_t, images_t, images_t1, previous, renders_t, flow)
                if refit is not None:
                    state, report = refit
                    labels = [r.label for r in report.renders]
                    unexplained = None
        report.limb_fit = self.search.fit(state, sdfs, labels)
        if unexplained is None:
            unexplained = [None if p is None else unexplained_foreground(p, lab, k)
                           for p, lab, k in zip(person, labels, known)]
        report.unexplained = np.array([
            np.nan if u is None else unexplained_share(u, lab)
            for u, lab in zip(unexplained, labels)])
        return state, report

    def _refit(self, state, report, angles, moved, sdfs, state_t, images_t, images_t1, previous,
               renders_t, flow):
        """The frame solved again from ``state`` with the ``moved`` limbs at ``angles``
        (``sdfs``: the search's silhouettes); ``(state, report)`` if kept, else None."""
        groups = {g.name: g for g in self.search.groups}

        def solve(names, look=None):
            proposal = state.copy()
            for name in names:
                dofs = groups[name].dofs
                proposal.angles[dofs] = angles[dofs]
            return self._step(state_t, images_t, images_t1, previous, renders_t, proposal,
                              flow, look)

        def looking(state2, renders2):
            return [name for name in moved
                    if self._looks_like_itself(groups[name], state, report.renders, state2,
                                               renders2, images_t1)]

        # A limb drawn into foreground that is not it (a wider trunk, another limb) no longer
        # looks like the limb of the anchor frame. Half the refits end so, and the pose the
        # coarser levels reach already says it: when no moved limb looks like itself there,
        # the finest level is not solved (of 296 refits of four sets, 149 were turned down
        # there, 4 of them refits that the finest level's look would have let on).
        state2, report2 = solve(moved, lambda st: bool(looking(st, self.render_views(st))))
        if state2 is None:
            return None

        def staying(names, state2, report2):
            return [name for name in names
                    if not self._leaves_a_view(groups[name], state, report.renders, state2,
                                               report2.renders, sdfs)]

        kept = staying(looking(state2, report2.renders), state2, report2)
        # solved again without the limbs turned down, the others move too: a leg may then
        # leave a view it had kept to (dance05_hard's last frames, clicks 7)
        tried = moved
        while kept and len(kept) < len(tried):
            tried = kept
            state2, report2 = solve(kept)
            kept = staying(kept, state2, report2)
        if not kept:
            return None
        # Keep the refit only if the whole frame is explained better: the silhouettes overlap
        # more, and the least-squares cost (image motion, anchor appearance, contours) is not
        # higher. The moved limbs' image motion compares them with where they were at t,
        # which the search found wrong: both poses are judged without it (a limb the tracker
        # had wrong would otherwise always stay wrong).
        # Nor may any one view's overlap fall by more than ``refit_view_drop``: a limb put
        # right in 3D does not spoil one view's silhouette to fill the others' (a limb drawn
        # onto a shadow or a ghost of the background in some views, which another view sees
        # as background).
        segments = np.concatenate([groups[name].segments for name in kept])
        drop = np.asarray(report.iou, float) - np.asarray(report2.iou, float)
        if (np.nanmean(report2.iou) > np.nanmean(report.iou)
                and not np.any(drop > self.settings.refit_view_drop)
                and self.frame_cost(state2, state_t, images_t1, renders_t, flow, segments)
                < (1 + self.settings.refit_tolerance)
                * self.frame_cost(state, state_t, images_t1, renders_t, flow, segments)):
            report2.recovered = kept
            # the moved limbs' change is a correction, not motion to carry into the next frame
            state2.corrected = np.concatenate([groups[name].dofs for name in kept])
            return state2, report2
        return None


__all__ = ["LimbRefit", "APPEARANCE_MIN_POINTS", "APPEARANCE_SLACK", "LEG_LEAVES_VIEW",
           "TURN_HYPOTHESIS_DEG"]
