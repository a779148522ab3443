"""Limb recovery: a silhouette search for a limb the image-motion step left behind.

Gauss-Newton on image motion only follows what moves a few pixels at the coarsest level. A kick
or a fast arm swing moves a shin further than that, and once the model's leg is left behind the
frame-to-frame motion cannot bring it back: the appearance under it is now the background or
the other leg. Bregler & Malik call for a coarse search in front of the differential step; this
is the cheapest one that works from the plates themselves.

For each limb (each leg, each arm) in turn, with the rest of the body held, poses of the limb's
joints are drawn around the current ones and scored on the foreground silhouettes of all views:
points sampled inside the limb's primitives should project inside the foreground (by the signed
distance), and into foreground that the rest of the body, or the limb's own first segment, do
not already explain (a shank folded behind its thigh explains nothing the thigh does not). A
knee is folded no further than one frame's reach from where the step left it, straightened any
amount (``FLEX_SPEED_DEG_S``, at the take's rate: :meth:`LimbSearch.frame_rate`). Drawing is
done in two rounds (wide, then narrow around the best), after a broad round of the whole limb
(:meth:`LimbSearch._broad`, unless ``LimbSearch.broad`` is off: the first of two tracking
rounds): thousands of draws over its range scored on a few points each, the best refined on
all of them. Everything is vectorized over draws and points. When a limb's best draw clearly
beats its current pose, the tracker refines from it (:meth:`DifferentialTracker.step`).

On colour plates an arm is also drawn by its hand's colour (``END_BONUS``), and searched when
its hand is not on that colour (``END_SEEN``), never into the other arm: the one cue that finds
an arm lost in front of the trunk, where the silhouettes say nothing.
"""

from dataclasses import dataclass

import cv2
import numpy as np

from ..body.primitives import CYLINDER

# Standard deviations of the first round of draws, radians, by joint.
WIDTHS = {"hip": 0.5, "knee": 0.7, "ankle": 0.3, "shoulder": 0.6, "elbow": 0.7}
POINTS_PER_PRIMITIVE = 48
SHRINK = 0.6            # points lie this far out towards the surface (robust to other builds)
SDF_SCALE = 3.0         # pixels of signed distance for a full +-1 score
# credit for foreground that the rest of the body, or the limb's own first segment, covers
SHARED_CREDIT = 0.4
# A view judges a limb (:meth:`LimbSearch.fit`) if it shows at least this share of its points.
MIN_JUDGED = 1.0 / 3.0
# Search a limb scoring below this. A leg that fits scores 0.75-1; one left behind by a kick
# with its thigh still in place scores 0.3-0.6 (measured on bench_track's walk3, where such a
# leg stayed 0.5 m off for 70 frames under a lower threshold). An arm in front of or behind
# the torso in most views scores low even where it belongs (its points fall on the rest of the
# body): search arms only when they are mostly outside the silhouettes.
POOR = {"leg": 0.6, "arm": 0.0}
PROBE_DRAWS = 48        # draws of the quick check before a full search of a fitting limb
# An arm is first drawn broadly: this many poses of all its joints at once, uniform over their
# ranges, each scored on a few of its points (``BROAD_POINTS`` per primitive); the best
# ``BROAD_KEEP``, and ``BROAD_LOCAL`` draws around each (``BROAD_WIDTHS[0]`` radians), are
# scored on all of them, then the best ``BROAD_KEEP // 2`` again (``BROAD_WIDTHS[1]``). Stage by
# stage, an arm whose upper arm lies inside the trunk's silhouette cannot be found (every
# shoulder angle scores alike there), nor by a few draws of the whole limb: the nearest of a
# thousand uniform draws is still about 70 mm from a given elbow and wrist. The broad round
# also decides whether a fitting limb is searched. Legs too: in a kick's snap (kick135) the
# hip's stage scores the thigh with the shank still folded (benchmarks/README.md).
BROAD_DRAWS = 2048
BROAD_POINTS = 6
BROAD_KEEP = 24
BROAD_LOCAL = 7
BROAD_WIDTHS = (0.15, 0.05)
BROAD_KINDS = ("arm", "leg")
UNEXPLAINED_BONUS = 0.6  # extra credit for foreground that no part of the model covers
UNEXPLAINED_MIN_PX = 5  # unexplained foreground thinner than this is the build, not a limb
# Limbs are drawn only to unexplained foreground this many arm widths away from the model's
# trunk: right beside it, foreground the model leaves is more often a trunk wider than the
# model's (a heavier build, loose clothes) than an arm, and an arm held to the side (hands on
# the hips) would be drawn into that gap. In front of it, it is as often an arm the model
# lost: a leg drawn there folds up into the trunk (punch02, one set of clicks: the right
# ankle 1.4 m off for 40 frames, and the second round's backgrounds, made without the real
# leg, took the standing leg for background and called those frames ok).
ARM_WIDTHS_AWAY = 1.0
# Credit for a point of an arm's end (the hand) on a foreground pixel of the hand's colour at
# the anchor frame (full credit within the colour's spread): an arm lost in front of the trunk
# lies inside the silhouettes, where only its look tells where it is, and a bare hand differs
# from the clothes more than any other part does.
END_BONUS = 0.6
# A limb whose end finds less than this of its colour (mean credit, 0-1, over the end's points
# in the views that know the colour) is searched whatever its silhouette says.
END_SEEN = 0.3
TRUNK_SEGMENTS = ("pelvis", "abdomen", "chest", "head")
# How fast a joint's flexion can change (degrees per second): the search folds a limb's joints
# within one frame's reach of where the step left them (the step and refit are not bounded). A
# knee: the fastest of 80 CMU captures of 19 performers (kicks, runs, dance) flexed or
# straightened 60 degrees in a thirtieth of a second (99.99 % of their frames under 50).
# Unbounded, a search folded a dancer's straight standing leg to its limit in one frame
# (dance05_hard: 12 -> 150 degrees, the ankle 0.87 m off for the rest of the take), the foot
# hidden behind the thigh where every point of the shank lies inside the silhouettes. Only
# folding is bounded (a leg folded up is what scores falsely well): bounded both ways, a run's
# leg folded to 149 degrees stayed so for 16 frames (benchmarks/README.md). Elbows are not
# bounded: an arm lost in front of the trunk is found again by broad draws.
FLEX_SPEED_DEG_S = {"knee_flex": 2000.0}


@dataclass
class LimbGroup:
    """One limb: its joint angles and the segments they move."""

    name: str
    dofs: np.ndarray        # indices into the angles
    widths: np.ndarray      # first-round standard deviations, radians
    segments: np.ndarray    # segment indices of the limb
    stages: list = None     # (dofs, segments) searched in turn, proximal first


def limb_groups(body):
    """Each leg and each arm of ``body`` as a :class:`LimbGroup` (templates without a limb
    simply have fewer groups)."""
    groups = []
    for side in "lr":
        for limb, joints, segs in (("leg", ("hip", "knee", "ankle"), ("thigh", "shank", "foot")),
                                   ("arm", ("shoulder", "elbow"), ("upper_arm", "forearm"))):
            dofs, widths, stages = [], [], []
            for j, sname in zip(joints, segs):
                stage = [i for i, name in enumerate(body.dof_names)
                         if name.startswith(f"{side}_{j}")]
                seg = [k for k, n in enumerate(body.segment_names) if n == f"{side}_{sname}"]
                dofs += stage
                widths += [WIDTHS[j]] * len(stage)
                if stage and seg:
                    stages.append((np.array(stage), np.array(seg)))
            seg = [k for k, n in enumerate(body.segment_names)
                   if any(n == f"{side}_{s}" for s in segs)]
            if dofs and seg:
                # proximal joint first (the thigh alone), then the rest of the limb
                staged = stages[:1] + ([(np.concatenate([d for d, _ in stages[1:]]),
                                         np.concatenate([k for _, k in stages[1:]]))]
                                       if len(stages) > 1 else [])
                groups.append(LimbGroup(f"{'left' if side == 'l' else 'right'} {limb}",
                                        np.array(dofs), np.array(widths), np.array(seg),
                                        staged))
    return groups


def end_primitives(prims, groups, kinds=("arm",)):
    """The primitive at the end of each limb of ``kinds`` (an arm's hand) among the body's
    primitives ``prims``: of the limb's last segment, the one farthest from its first
    segment's primitives. Returns group name -> primitive index."""
    centres = prims.prim2seg[:, :3, 3]
    out = {}
    for g in groups:
        if g.name.split()[-1] not in kinds:
            continue
        first = np.flatnonzero(prims.segment == g.segments[0])
        last = np.flatnonzero(prims.segment == g.segments[-1])
        if len(g.segments) < 2 or not len(first) or not len(last):
            continue
        d = np.linalg.norm(centres[last] - centres[first].mean(axis=0), axis=1)
        out[g.name] = int(last[np.argmax(d)])
    return out


def interior_points(prims, n=POINTS_PER_PRIMITIVE, shrink=SHRINK, seed=0):
    """Points inside each primitive, in its segment's coordinates.

    Returns
    -------
    segment : array of int, shape (M,)
    points : array, shape (M, 3)
    """
    rng = np.random.default_rng(seed)
    segs, pts = [], []
    for p in range(len(prims)):
        size = prims.size[p]
        if prims.kind[p] == CYLINDER:
            z = rng.uniform(0.05, 0.95, n) * size[2]
            r = 1 + (prims.taper[p] - 1) * z / size[2]
            a = rng.uniform(0, 2 * np.pi, n)
            rad = shrink * np.sqrt(rng.uniform(0.2, 1.0, n))
            local = np.column_stack([size[0] * r * rad * np.cos(a),
                                     size[1] * r * rad * np.sin(a), z])
        else:
            d = rng.normal(size=(n, 3))
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            local = shrink * np.sqrt(rng.uniform(0.2, 1.0, n))[:, None] * d * size
        T = prims.prim2seg[p]
        pts.append(local @ T[:3, :3].T + T[:3, 3])
        segs.append(np.full(n, prims.segment[p]))
    return np.concatenate(segs), np.concatenate(pts)


def unexplained_foreground(foreground, labels, known=None, min_px=UNEXPLAINED_MIN_PX):
    """Foreground that the model's support map does not cover, in blobs at least ``min_px``
    thick (a thin rim is a body of another build than the model's, not a missing limb), where
    the background is known (elsewhere "foreground" only means "never seen empty")."""
    model = cv2.dilate((labels >= 0).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
    rest = foreground & ~model
    if known is not None:
        rest &= known
    rest = rest.astype(np.uint8)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (min_px, min_px))
    return cv2.morphologyEx(rest, cv2.MORPH_OPEN, kernel) > 0


def unexplained_share(unexplained, labels):
    """Unexplained foreground (a mask from :func:`unexplained_foreground`) as a fraction of
    the model's area in its support map ``labels``."""
    return float(unexplained.sum() / max(int((labels >= 0).sum()), 1))


def _transform_points(T, points, out):
    """``out[n, m] = T[n] @ points[m]`` (rigid transforms (N, 4, 4), points (M, 3)).

    Each coordinate is summed as ``(r0 x + r2 z) + r1 y``, the order numpy's einsum takes for
    this three-term product: the values of ``np.einsum("nij,mj->nmi", ...)`` exactly, faster.
    """
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    for i in range(3):
        c = T[:, i, 0, None] * x
        c += T[:, i, 2, None] * z
        c += T[:, i, 1, None] * y
        c += T[:, i, 3, None]
        out[..., i] = c


class _RestOfBody:
    """The pixels the model covers with segments other than a limb's, looked up at the
    scored points only (``rest[v, u]``), not formed as a full mask."""

    def __init__(self, labels, segments):
        self.labels = labels
        n = max(int(labels.max()) + 2, int(np.max(segments)) + 2)
        self.table = np.ones(n, bool)
        self.table[0] = False                   # background (-1)
        self.table[np.asarray(segments) + 1] = False

    def __getitem__(self, index):
        return self.table[self.labels[index] + 1]

    def flat_take(self, flat):
        """``self[v, u]`` for the flat pixel indices ``v * W + u``."""
        labels = np.take(self.labels, flat)
        labels += 1
        return np.take(self.table, labels)


def _rest_of_body(labels, group):
    """Per view, the pixels the model covers with segments other than the limb's."""
    return [None if lab is None else _RestOfBody(lab, group.segments) for lab in labels]


class LimbSearch:
    """Silhouette search over each limb's joint angles (see the module notes).

    Parameters
    ----------
    body : BodyModel
    draws : int
        Draws per round and limb (the current pose is always one of them).
    margin : float
        How much better (in the score's units, -1..1 per point) a limb's best draw must be
        than its current pose to be proposed.
    poor : dict of str to float, optional
        Per limb kind ("leg", "arm"), the score below which a limb is searched (a limb inside
        the silhouettes is left to the image-motion step, which is more precise). Default
        :data:`POOR`.
    attract : tuple of str
        Limbs ("leg", "arm") that are also searched, and drawn, towards foreground no part of
        the model explains. Both by default. An arm the tracker lost in front of or beside
        the trunk lies inside the silhouettes and scores above its threshold, so only the
        person's own arm, left unexplained, can call it away (a dancer's arm swung past the
        image motion's reach, a punch). The cost: an arm held close to a trunk wider than the
        model's (hands on the hips) is sometimes drawn into the gap; over three sets of clicks
        each, dance05_hard went from 134.7 to 110.8 mm, punch02 50.0 -> 35.0, sword02 42.6 ->
        33.4, and walk131_hard, that walk with hands on hips, 39.5 -> 45.3.
    seed : int
    broad : bool
        Draw the limbs of ``BROAD_KINDS`` broadly before their stages (:meth:`_broad`).
    """

    def __init__(self, body, draws=160, margin=0.08, poor=None, seed=0,
                 attract=("leg", "arm"), broad=True):
        self.body = body
        self.broad = broad
        self.poor = dict(POOR if poor is None else poor)
        self.attract = attract
        self.draws = draws
        self.margin = margin
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.groups = limb_groups(body)
        self.prims = prims = body.primitives()
        self.point_segment, self.points = interior_points(prims)
        self.point_prim = np.repeat(np.arange(len(prims)), POINTS_PER_PRIMITIVE)
        self.ends = end_primitives(prims, self.groups)
        self.trunk = np.array([k for k, n in enumerate(body.segment_names)
                               if n in TRUNK_SEGMENTS], int)
        self._blocks = {}
        self._chains = {}
        self._fit_at = None     # (roots, angles, sdfs, labels, scores) of the last search
        # the most a DOF may change in one frame (radians): see FLEX_SPEED_DEG_S
        self.reach = np.full(body.n_dofs, np.inf)

    def frame_rate(self, fps):
        """Bound the draws' joints to one frame's reach at ``fps`` (FLEX_SPEED_DEG_S)."""
        self.reach = np.full(self.body.n_dofs, np.inf)
        if fps and fps > 0:
            for k, name in enumerate(self.body.dof_names):
                speed = FLEX_SPEED_DEG_S.get(name[2:] if name[:2] in ("l_", "r_") else name)
                if speed is not None:
                    self.reach[k] = np.radians(speed) / fps

    def _bounds(self, angles):
        """Where draws from ``angles`` may go: the limits, folding within a frame's reach."""
        return (self.body.lower, np.minimum(self.body.upper, angles + self.reach))

    def reseed(self, key=()):
        """Restart the draws from a seed made of the search's own and ``key`` (non-negative
        ints, e.g. a tracking pass's first and last frame), so a pass draws the same samples
        whatever ran before it."""
        self.rng = np.random.default_rng([self.seed, *(int(k) for k in key)])

    def _chain(self, key):
        """The segments ``key`` of one limb with the limb's segments before them (root first)
        for :meth:`score`: the chain's segments (whose transforms place the points), the main
        primitive of its first (centre and half-axis in the segment's frame, radius, and
        whether it is a cylinder) and the position of each of ``key`` in the chain. None for
        segments outside the limbs."""
        if key not in self._chains:
            limb = next((g.segments for g in self.groups if key[0] in g.segments), None)
            chain = None
            if limb is not None and set(key) <= set(int(k) for k in limb):
                order = [int(k) for k in limb]
                segs = tuple(order[:max(order.index(k) for k in key) + 1])
                prims = self.prims
                mine = np.flatnonzero(prims.segment == segs[0])
                q = mine[np.argmax(np.prod(prims.size[mine], axis=1))]
                T, size = prims.prim2seg[q], prims.size[q]
                if prims.kind[q] == CYLINDER:
                    # from its base (the frame's origin) along +z, tapered at the top
                    half = T[:3, 2] * size[2] / 2
                    first = (T[:3, 3] + half, half,
                             float(max(size[0], size[1]) * max(1.0, prims.taper[q])), True)
                else:
                    first = (T[:3, 3].copy(), T[:3, 2] * size[2],
                             float(max(size[0], size[1])), False)
                chain = segs, first, [segs.index(k) for k in key]
            self._chains[key] = chain
        return self._chains[key]

    def _own_cover(self, first, T, uv, cam, ranges):
        """Which points (N, M) of a limb's draws fall, in one view, on the limb's first
        segment (a thigh, an upper arm: inside its main primitive's outline about its
        projected axis, an ellipse's profile or a cylinder's band): foreground the limb
        explains twice, credited as foreground the rest of the body covers (``SHARED_CREDIT``).
        A leg folded so that the shank lies behind the thigh would otherwise score every point
        of both as well as a leg that covers its own pixels. ``first`` is the first segment's
        main primitive (:meth:`_chain`), ``T`` (N, S, 4, 4) the chain's transforms, ``ranges``
        the points' (position in the chain, first index, last + 1)."""
        out = np.zeros(uv.shape[:2], bool)
        outer = [(lo, hi) for pos, lo, hi in ranges if pos > 0 and hi > lo]
        if not outer or not hasattr(cam, "K"):
            return out
        centre, half, radius, cylinder = first
        R, t = T[:, 0, :3, :3], T[:, 0, :3, 3]
        ends = np.stack([R @ (centre - half) + t, R @ (centre + half) + t], axis=1)
        e = cam.project(ends.reshape(-1, 3)).reshape(-1, 2, 2)               # (N, 2, 2)
        depth = np.maximum(cam.depth(ends), 1e-6)                           # (N, 2)
        width2 = (radius * float(cam.K[0, 0]) / depth.mean(axis=1)) ** 2    # (N,) pixels^2
        d = e[:, 1] - e[:, 0]
        dd = np.maximum((d * d).sum(axis=1), 1e-9)[:, None]
        for lo, hi in outer:
            px = uv[:, lo:hi, 0] - e[:, None, 0, 0]
            py = uv[:, lo:hi, 1] - e[:, None, 0, 1]
            along = px * d[:, None, 0] + py * d[:, None, 1]                  # a * dd
            # off the axis squared (|p|^2 - a^2 dd), times dd^2 > 0, under the outline's
            # half-width squared at a (0..1 along the axis): an ellipse's width^2 4 a (1 - a),
            # a cylinder's width^2 between its ends
            off = ((px * px + py * py) * dd - along * along) * dd
            if cylinder:
                out[:, lo:hi] = (off < width2[:, None] * dd * dd) & (along >= 0) & (along <= dd)
            else:
                out[:, lo:hi] = off < 4.0 * width2[:, None] * along * (dd - along)
        return out

    def score(self, roots, angles, segments, cameras, sdfs, rest, unexplained=None,
              plain=False, colour=None, sparse=False, views=False):
        """Silhouette score of a batch of poses for one limb, mean over points and views.

        Parameters
        ----------
        roots : array, shape (V, 4, 4)
            The root of each view (the same world root when calibrated).
        angles : array, shape (N, n_dofs)
        segments : array of int
            The segments whose points are scored.
        cameras : list of camera
        sdfs : list of array (H, W) or None
            Signed distance to the foreground (negative inside) per view; None skips a view.
        rest : list of array of bool (H, W) or None
            Pixels the rest of the body covers (the limb's own first segment, where its
            outer segments' points fall on it, counts alike: :meth:`_own_cover`).
        unexplained : list of array of bool (H, W) or None, optional
            Foreground that no part of the model covers (thick blobs only): where a limb
            left behind has gone.

        plain : bool
            Also return the score without the credit for unexplained foreground or colour,
            over the points each view shows (:meth:`fit`'s measure): a point on a pixel
            where the model shows another part (the limb is behind it) says nothing of the
            limb in that view, in the foreground or out of it (a trunk of the background's
            colour); a view showing fewer than ``MIN_JUDGED`` of the points is left out (every
            view left out: all points count, as in the score).
        colour : tuple, optional
            ``(primitive, per_view, ...)``: the points of that primitive (a hand) earn
            ``END_BONUS`` on foreground pixels of its colour; ``per_view[c]`` is None or
            ``(channels, target, spread, elsewhere)``: the chromaticity images (H, W) of view
            ``c``, the colour's chromaticity and spread, and the pixels that earn nothing (the
            other arm, the face) (:meth:`LimbRefit.end_colours`).
        sparse : bool
            Score on ``BROAD_POINTS`` points per primitive only (a broad round's many draws).
        views : bool
            With ``plain``: also each view's plain score (N, V) (over all points where it shows
            under ``MIN_JUDGED`` of them; NaN: no silhouette) and whether it shows that many.

        Returns
        -------
        score : array, shape (N,)
        plain_score : array, shape (N,)
            With ``plain`` only; then ``view_scores, view_shown`` with ``views``.
        """
        key = tuple(int(k) for k in segments)
        blocks = self._blocks.get((key, sparse))
        if blocks is None:
            # the limb's points, segment by segment: (position in segments, points, their
            # primitives); sparse: the first of each primitive's (they are drawn at random)
            use = (np.arange(len(self.points)) % POINTS_PER_PRIMITIVE < BROAD_POINTS
                   if sparse else np.ones(len(self.points), bool))
            blocks = self._blocks[(key, sparse)] = [
                (i, self.points[(self.point_segment == k) & use],
                 self.point_prim[(self.point_segment == k) & use]) for i, k in enumerate(key)]
        m = sum(len(pts) for _, pts, _ in blocks)
        chain = self._chain(key)
        if chain is not None:
            ranges, lo = [], 0
            for (i, pts, _), pos in zip(blocks, chain[2]):
                ranges.append((pos, lo, lo + len(pts)))
                lo += len(pts)
        end = None
        if colour is not None and any(x is not None for x in colour[1]):
            end = np.concatenate([p == colour[0] for _, _, p in blocks])
            end = end if end.any() else None
        n = len(angles)
        total = np.zeros(n)
        total_plain = np.zeros(n) if plain else None
        plain_views = np.zeros(n) if plain else None
        fallback = np.zeros(n) if plain else None
        view_scores = np.full((n, len(cameras)), np.nan) if plain and views else None
        view_shown = np.zeros(view_scores.shape, bool) if view_scores is not None else None
        used = 0
        T = None
        for c, cam in enumerate(cameras):
            if sdfs[c] is None:
                continue
            if T is None or not np.array_equal(roots[c], roots[c - 1]):
                # only the limb's chain moves its points
                T = self.body.seg2world_of(roots[c][None], angles,
                                           key if chain is None else chain[0])
                X = np.empty((n, m, 3))
                lo = 0
                for i, pts, _ in blocks:
                    _transform_points(T[:, i if chain is None else chain[2][i]], pts,
                                      X[:, lo:lo + len(pts)])
                    lo += len(pts)
            uv = cam.project(X.reshape(-1, 3)).reshape(n, -1, 2)
            h, w = sdfs[c].shape
            u = np.clip(np.rint(uv[..., 0]), 0, w - 1).astype(np.intp)
            v = np.clip(np.rint(uv[..., 1]), 0, h - 1).astype(np.intp)
            off = (uv[..., 0] < 0) | (uv[..., 0] > w - 1) | (uv[..., 1] < 0) | (uv[..., 1] > h - 1)
            flat = v
            flat *= w
            flat += u
            s = np.take(sdfs[c], flat)
            s /= -SDF_SCALE
            np.clip(s, -1.0, 1.0, out=s)
            s[off] = -1.0
            shared = None
            judged = None
            if rest is not None and rest[c] is not None:
                covered = rest[c].flat_take(flat) if isinstance(rest[c], _RestOfBody) \
                    else np.take(rest[c], flat)
                if plain:
                    judged = ~covered | off
                shared = s > 0
                shared &= covered
            if chain is not None and len(chain[0]) > 1:
                own = self._own_cover(chain[1], T, uv, cam, ranges)
                shared = own if shared is None else shared | own
                shared &= s > 0
            if shared is not None:
                s[shared] *= SHARED_CREDIT
            if plain:
                mean = s.mean(axis=1)
                fallback += mean
                if judged is None:
                    total_plain += mean
                    plain_views += 1
                    view_mean, seen = mean, True
                else:
                    count = judged.sum(axis=1)
                    seen = count >= MIN_JUDGED * s.shape[1]
                    view_mean = np.where(judged, s, 0.0).sum(axis=1) / np.maximum(count, 1)
                    total_plain += np.where(seen, view_mean, 0.0)
                    plain_views += seen
                if view_scores is not None:
                    view_scores[:, c] = np.where(seen, view_mean, mean)
                    view_shown[:, c] = seen
            if unexplained is not None and unexplained[c] is not None:
                bonus = np.take(unexplained[c], flat)
                bonus &= ~off
                s = s + UNEXPLAINED_BONUS * bonus       # float64 from here on
            if end is not None and colour[1][c] is not None:
                channels, target, spread, elsewhere = colour[1][c]
                at = flat[:, end]
                d2 = np.zeros(at.shape)
                for ch, t in zip(channels, target):
                    d2 += ((np.take(ch, at) - t) / spread) ** 2
                like = np.exp(-0.5 * np.maximum(d2 - 1.0, 0.0))
                like *= np.take(sdfs[c], at) < 0
                like *= ~np.take(elsewhere, at)
                like[off[:, end]] = 0.0
                s[:, end] += END_BONUS * like
            total += s.mean(axis=1)
            used += 1
        if plain:
            plain_score = np.where(plain_views > 0, total_plain / np.maximum(plain_views, 1),
                                   fallback / max(used, 1))
            extra = (view_scores, view_shown) if views else ()
            return (total / max(used, 1), plain_score, *extra)
        return total / max(used, 1)

    def search(self, state, sdfs, rest_labels, known=None, person=None, colours=None):
        """Best pose of each limb in turn; returns the new angles and the limbs that moved.

        Parameters
        ----------
        state : differential.State
        sdfs : list of array (H, W) or None
            Per view at the cameras' resolution.
        rest_labels : list of array of int (H, W) or None
            The model's support map at ``state`` per view (segment labels, -1 background).
        known : list of array of bool (H, W) or None, optional
            Where each view's background model has seen the background.
        person : list of array of bool (H, W) or None, optional
            The foreground without cast shadows, where a limb may be drawn to (default: the
            foreground of ``sdfs``).
        colours : dict of str to list, optional
            Per limb (an arm), per view, the colour of its end (the hand) to draw it to:
            None or ``(channels, target, spread, elsewhere)`` (see :meth:`score`).

        Returns
        -------
        angles : array, shape (n_dofs,)
        moved : list of (str, float)
            Limbs whose draw won, with the score gained.
        """
        angles = state.angles.copy()
        moved = []
        self.last_scores = {}
        plain_scores = {}
        known = known or [None] * len(sdfs)
        person = person or [None] * len(sdfs)
        unexplained = [None if d is None or lab is None else
                       unexplained_foreground(d < 0 if p is None else p, lab, k)
                       for d, lab, k, p in zip(sdfs, rest_labels, known, person)]
        self.last_unexplained = unexplained     # of the pose searched from, for the caller
        # what limbs are drawn to: the unexplained foreground an arm's width away from the
        # trunk (beside it, it is more likely a trunk wider than the model's, or in front of
        # it an arm the model lost: a leg drawn there folds up into the trunk)
        away = [None if u is None else self._away_from_trunk(u, lab, cam, root)
                for u, lab, cam, root in zip(unexplained, rest_labels, state.cameras,
                                             state.roots)]
        for group in self.groups:
            rest = _rest_of_body(rest_labels, group)
            colour = (colours or {}).get(group.name)
            colour = None if colour is None or group.name not in self.ends \
                or all(x is None for x in colour) else (self.ends[group.name], colour)
            if colour is not None:
                # the other arms where they are now: a hand drawn to its colour must not go
                # into another arm (bare arms have the hands' colour)
                colour = colour + (self._arm_points(state.roots[0], angles, group),)
            best, gain = self._search_group(state.roots, angles, group, state.cameras, sdfs,
                                            rest, away, plain_scores, colour)
            if gain > self.margin:
                angles = best
                moved.append((group.name, float(gain)))
                # what this limb now covers is explained: other limbs must not go there too
                unexplained, away = self._clear((unexplained, away), state.roots, angles,
                                                group, state.cameras)
        # Nothing moved: every limb was scored at ``state``, which is what :meth:`fit` asks
        # for next (with the same silhouettes and support maps).
        self._fit_at = None if moved else (state.roots.tobytes(), state.angles.tobytes(),
                                           list(sdfs), list(rest_labels), plain_scores)
        return angles, moved

    def _arm_points(self, root, angles, group):
        """Interior points (world) of the arms with an end other than ``group``, at
        ``angles``."""
        others = [g for g in self.groups if g.name in self.ends and g is not group]
        if not others:
            return np.zeros((0, 3))
        segs = np.concatenate([g.segments for g in others])
        T = self.body.seg2world(root, angles)
        sel = np.isin(self.point_segment, segs)
        T = T[self.point_segment[sel]]
        return np.einsum("mij,mj->mi", T[:, :3, :3], self.points[sel]) + T[:, :3, 3]

    def _into_other_arm(self, root, trial, colour):
        """Which draws ``trial`` (N, n_dofs) put the end (``colour[0]``, a hand) into another
        arm (``colour[2]``, its interior points): closer to one of its points than the hand's
        and the forearm's radii."""
        end, _, others = colour
        if not len(others):
            return np.zeros(len(trial), bool)
        prims = self.prims
        T = self.body.seg2world_of(root[None], trial, (int(prims.segment[end]),))[:, 0]
        centre = T[:, :3, :3] @ prims.prim2seg[end][:3, 3] + T[:, :3, 3]
        reach = self.body.dims["hand_r"] + self.body.dims["forearm_r"]
        d2 = ((centre[:, None, :] - others[None]) ** 2).sum(axis=2).min(axis=1)
        return d2 < reach ** 2

    def _away_from_trunk(self, unexplained, labels, camera, root):
        """``unexplained`` without what lies within an arm's width (``ARM_WIDTHS_AWAY``) of
        the model's trunk in ``labels``; the width in pixels at the root's depth."""
        trunk = np.isin(labels, self.trunk)
        if not trunk.any() or not unexplained.any():
            return unexplained
        depth = float(camera.depth(root[None, :3, 3])[0])
        if not depth > 0:
            return unexplained
        width = ARM_WIDTHS_AWAY * 2 * self.body.dims["upper_arm_r"] * camera.K[0, 0] / depth
        distance = cv2.distanceTransform((~trunk).astype(np.uint8), cv2.DIST_L2, 3)
        return unexplained & (distance > width)

    def _clear(self, masks, roots, angles, group, cameras, radius=4):
        """Each list of per-view masks in ``masks`` (None where a view has none) without what
        ``group``'s points cover at ``angles``, dilated by ``radius`` pixels."""
        sel = np.isin(self.point_segment, group.segments)
        out = [[] for _ in masks]
        for c, cam in enumerate(cameras):
            shape = next((m[c].shape for m in masks if m[c] is not None), None)
            if shape is None:
                for o in out:
                    o.append(None)
                continue
            T = self.body.seg2world(roots[c], angles)[self.point_segment[sel]]
            X = np.einsum("mij,mj->mi", T[:, :3, :3], self.points[sel]) + T[:, :3, 3]
            uv = np.rint(cam.project(X)).astype(np.intp)
            h, w = shape
            ok = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
            hit = np.zeros((h, w), np.uint8)
            hit[uv[ok, 1], uv[ok, 0]] = 1
            k = 2 * radius + 1
            hit = cv2.dilate(hit, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
            for o, m in zip(out, masks):
                o.append(None if m[c] is None else m[c] & (hit == 0))
        return out

    def fit(self, state, sdfs, labels):
        """Silhouette score of every limb at ``state`` (see :meth:`search` for the inputs).

        Returns
        -------
        dict of str to float
            Limb name -> mean score in [-1, 1]: near 1 when the limb lies inside the
            foreground of every view, below 0 when it lies mostly outside; each view judges
            the points it shows (``plain`` in :meth:`score`).
        """
        def same(xs, ys):
            return len(xs) == len(ys) and all(x is y for x, y in zip(xs, ys))

        known = self._fit_at
        if (known is not None and known[0] == state.roots.tobytes()
                and known[1] == state.angles.tobytes()
                and same(known[2], sdfs) and same(known[3], labels)):
            return dict(known[4])       # the search scored these limbs at this pose
        out = {}
        for group in self.groups:
            rest = _rest_of_body(labels, group)
            out[group.name] = float(self.score(state.roots, state.angles[None], group.segments,
                                               state.cameras, sdfs, rest, plain=True)[1][0])
        return out

    def _broad(self, roots, angles, group, cameras, sdfs, rest, unexplained, colour, lower,
               upper):
        """The broad round (``BROAD_DRAWS``, within ``lower`` and ``upper``): the best draw of
        the whole limb and its score (on all points)."""
        dofs = group.dofs
        trial = np.repeat(angles[None], BROAD_DRAWS, axis=0)
        trial[1:, dofs] = self.rng.uniform(lower[dofs], upper[dofs],
                                           size=(BROAD_DRAWS - 1, len(dofs)))
        s = self.score(roots, trial, group.segments, cameras, sdfs, rest, unexplained,
                       colour=colour, sparse=True)
        top = trial[np.argsort(s)[-2 * BROAD_KEEP:]]
        if colour is not None:
            # (judged on the best only: the hand's place costs a chain's kinematics per draw)
            top = top[~self._into_other_arm(roots[0], top, colour)]
            if not len(top):
                return angles, -np.inf
        for keep, width in zip((BROAD_KEEP, BROAD_KEEP // 2), BROAD_WIDTHS):
            top = top[-keep:]
            near = np.repeat(top, BROAD_LOCAL, axis=0)
            near[:, dofs] += self.rng.normal(size=(len(near), len(dofs))) * width
            top = np.clip(np.concatenate([top, near]), lower, upper)
            full = self.score(roots, top, group.segments, cameras, sdfs, rest, unexplained,
                              colour=colour)
            if colour is not None:
                full[self._into_other_arm(roots[0], top, colour)] = -np.inf
            order = np.argsort(full)
            top, full = top[order], full[order]
        return top[-1], float(full[-1])

    def _search_group(self, roots, angles, group, cameras, sdfs, rest, unexplained,
                      plain_scores=None, colour=None):
        """Best pose of one limb and the score it gains; ``plain_scores`` (dict), if given,
        gets the limb's score at ``angles`` without the credit for unexplained foreground.
        With the ``colour`` of its end (:meth:`score`) every stage is scored on the whole limb,
        whose end each stage moves. Draws stay within one frame's reach (``reach``) of
        ``angles``."""
        lower, upper = self._bounds(angles)
        if not group.name.endswith(self.attract):
            unexplained = [None] * len(unexplained)
        current, current_plain = self.score(roots, angles[None], group.segments, cameras, sdfs,
                                            rest, unexplained, plain=True, colour=colour)
        current = current[0]
        if plain_scores is not None:
            plain_scores[group.name] = float(current_plain[0])
        self.last_scores[group.name] = current
        poor = self.poor.get(group.name.split()[-1], 0.0)
        centre = angles
        lost_end = False
        if colour is not None:
            # how much of its end's colour the limb finds where it is (0-1): a hand not on its
            # colour in the views that know it is searched for, as a poorly fitting limb is
            bare = self.score(roots, angles[None], group.segments, cameras, sdfs, rest,
                              unexplained)[0]
            share = np.mean(self.point_prim[np.isin(self.point_segment, group.segments)]
                            == colour[0])
            seen = [d is not None for d in sdfs]
            share *= sum(x is not None and s for x, s in zip(colour[1], seen)) / max(sum(seen), 1)
            lost_end = share > 0 and (current - bare) / (END_BONUS * share) < END_SEEN
        fits = current >= poor and not lost_end
        if fits and colour is None and not any(u is not None and u.any() for u in unexplained):
            return angles, 0.0
        broad = None
        if self.broad and group.name.endswith(BROAD_KINDS):
            # The whole limb drawn broadly: a fitting one is searched only when that finds a
            # better pose (only unexplained foreground or its end's colour could call it
            # away); the stages start from the better of the two.
            broad, broad_score = self._broad(roots, angles, group, cameras, sdfs, rest,
                                             unexplained, colour, lower, upper)
            if fits and broad_score - current < 0.5 * self.margin:
                return angles, 0.0
            if broad_score > current:
                centre = broad
        elif fits:
            # The limb fits; only unexplained foreground could call it away. A cheap probe
            # (few draws, the whole limb at once) decides whether a full search is worth it.
            probe = np.repeat(angles[None], PROBE_DRAWS, axis=0)
            probe[1:, group.dofs] = self.rng.uniform(lower[group.dofs], upper[group.dofs],
                                                     size=(PROBE_DRAWS - 1, len(group.dofs)))
            gain = self.score(roots, probe, group.segments, cameras, sdfs, rest, unexplained,
                              colour=colour).max() - current
            if gain < 0.5 * self.margin:
                return angles, 0.0
        # Each stage: half the draws uniform over the joints' range (within one frame's
        # reach), half around the current pose; then a narrower round around the stage's best.
        for dofs, segs in group.stages:
            if colour is not None:
                segs = group.segments
            best = self.score(roots, centre[None], segs, cameras, sdfs, rest, unexplained,
                              colour=colour)[0]
            width = np.array([group.widths[list(group.dofs).index(d)] for d in dofs])
            for spread in (1.0, 0.3):
                trial = np.repeat(centre[None], self.draws, axis=0)
                noise = self.rng.normal(size=(self.draws - 1, len(dofs))) * width * spread
                trial[1:, dofs] += noise
                if spread == 1.0:
                    half = self.draws // 2
                    trial[half:, dofs] = self.rng.uniform(lower[dofs], upper[dofs],
                                                          size=(self.draws - half, len(dofs)))
                trial = np.clip(trial, lower, upper)
                s = self.score(roots, trial, segs, cameras, sdfs, rest, unexplained,
                               colour=colour)
                if colour is not None:
                    s[self._into_other_arm(roots[0], trial, colour)] = -np.inf
                k = int(np.argmax(s))
                if s[k] > best:
                    centre, best = trial[k], s[k]
        final = self.score(roots, centre[None], group.segments, cameras, sdfs, rest,
                           unexplained, colour=colour)[0]
        if broad is not None and broad_score > final:
            # a stage scores part of the limb: it may trade the whole limb's fit away
            centre, final = broad, broad_score
        return centre, final - current


__all__ = ["LimbSearch", "LimbGroup", "limb_groups", "interior_points"]
