"""The fit of anchor frames to their clicks, shared by the calibrated and the uncalibrated
mode (:class:`_Fit`): each frame from its starting points, the limbs tried at their other depth
and judged with the pose prior, the animator's flips, then all frames together, and the checks
of swapped and outlying clicks."""

import numpy as np

from ..body.body import DEFAULT_DIMS, LENGTH_DIMS, RADIUS_DIMS, Pose, make_body
from ..body.joints import JOINT_INDEX, STANDARD_JOINTS
from ..files.initfile import InitResult
from ..geometry.triangulate import similarity_from_points
from .flips import (_AMBIGUOUS_M, _EXPLORE_NFEV, _FLIP_LIMBS, _MIN_FLIP_M, AMBIGUOUS_COST,
                    BODY_PARTS, LIMB_FLIPS, LR_PAIRS)
from .problem import (_CAM_PARAMS, CLICK_SIGMA_PX, LOSS_SCALE_PX, _fit, _Problem, _rho_px,
                      _robust_cost, _State)
from .starts import _TORSO, _fit_3d

# A joint this many pixels (and this many times the view's median error) off the fit is named.
OUTLIER_PX = 4.0 * LOSS_SCALE_PX
OUTLIER_RATIO = 5.0
# Combinations of limb signs fitted in full: at most this many, within this many nats of the
# best before fitting.
PRIOR_REFITS = 4
PRIOR_MARGIN = 6.0


class _Fit:
    """Shared driver: starting points per anchor, the joint problem, checks of the clicks."""

    calibrated = True

    def __init__(self, kin, obs, weights, views, anchors, dims0, fit_dims, warnings):
        self.kin = kin
        self.obs = obs
        self.weights = weights
        self.views = views
        self.anchors = anchors
        self.frames = [a.frame for a in anchors]
        self.dims0 = dims0
        self.fit_dims = fit_dims
        self.warnings = warnings
        self.ambiguous = False
        self.swapped = []
        self.prior = None       # PosePrior: the angle prior of frames seen in one view
        self.flips = {}         # anchor frame -> FLIP_PARTS the animator turned
        self.ambiguous_parts = {}
        self.flipped = {}

    # Subclasses give start(f) -> _State of one frame (F = 1), options(state, f, fit_dims) ->
    # _Problem options, depth_direction(state, f) and mirrored(state, f) for frames seen in one
    # view (else None), and _cameras(state) -> (cameras, view_cameras).

    def run(self):
        states = [self._apply_flips(self._frame(f), f) for f in range(len(self.frames))]
        state = self._merge(states)
        state, cost = self._solve_all(state)
        state = self._check_swaps(state, cost)
        self._check_outliers(state)
        return self._result(state)

    def _frame(self, f):
        """Best fit of one anchor frame alone; alternatives that fit as well are reported."""
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        state = self.start(f)
        state, cost, _ = _fit(self.kin, obs, w, state,
                              **self.options(state, f, fit_dims=self.fit_dims))
        state, cost, rivals = self._explore_limbs(state, cost, f)
        mirrored = self.mirrored(state, f)
        if mirrored is not None:
            alt, alt_cost, _ = _fit(self.kin, obs, w, mirrored,
                                    **self.options(mirrored, f, fit_dims=self.fit_dims))
            if self.prior is not None and self.depth_direction(state, f) is not None:
                # One view: the fit and its whole-body mirror, each limb at either depth
                # sign, judged by the clicks and the learned prior together.
                return self._choose_by_prior([state, alt], f)
            if alt_cost < cost:
                rivals.append((state, cost))
                state, cost = alt, alt_cost
            else:
                rivals.append((alt, alt_cost))
        seen = []
        for alt, alt_cost in rivals:
            if alt_cost > cost + 4 * AMBIGUOUS_COST or not self._moved_parts(state, alt):
                continue
            # Rivals come from short fits: converge the close ones before judging them.
            alt, alt_cost, _ = _fit(self.kin, obs, w, alt,
                                    **self.options(alt, f, fit_dims=self.fit_dims))
            if alt_cost > cost + AMBIGUOUS_COST:
                continue
            moved = self._moved_parts(state, alt)
            if moved and moved not in seen:
                seen.append(moved)
                self.ambiguous = True
                self._note_ambiguous(f, moved)
                self.warnings.append(
                    f"frame {self.frames[f]}: a pose with {_join(moved)} mirrored in depth "
                    f"fits about as well (cost {alt_cost:.1f} vs {cost:.1f} px^2); the 3D pose "
                    "is uncertain there: click this frame in another view")
        return state

    def _limb_variants(self, state, f):
        """Each limb's angles with its upper and lower part at either depth sign (§2.6's
        ambiguity of one view), posed by inverse kinematics on the reflected joints.

        Returns
        -------
        variants : list (limbs) of list of (angles of the limb's DOFs, flips)
            The first variant of each limb is the state's own.
        dofs : list (limbs) of array of int
        """
        kin = self.kin
        normal = self.depth_direction(state, f)
        names = kin.structure.dof_names
        Y = kin.forward(state.angles, state.dims)[0][0]
        X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
        variants, dofs = [], []
        for pivot, middle, upper, lower, prefixes in _FLIP_LIMBS:
            moved = np.array([k for k, n in enumerate(names) if n.startswith(prefixes)])
            own = [(state.angles[0, moved].copy(), ())]
            for flips in (("upper",), ("lower",), ("upper", "lower")):
                target = X.copy()
                shifted = 0.0
                for part, (centre, rows) in zip(("upper", "lower"),
                                                ((pivot, upper), (middle, lower))):
                    if part not in flips:
                        continue
                    rows = [JOINT_INDEX[j] for j in rows]
                    p = target[JOINT_INDEX[centre]]
                    n = normal(p)
                    shift = 2.0 * ((target[rows] - p) @ n)[:, None] * n
                    target[rows] -= shift
                    shifted = max(shifted, np.abs(shift).max())
                if shifted < _MIN_FLIP_M:
                    continue    # that part lies in the image plane: its mirror is itself
                angles = state.angles[0].copy()
                angles[moved] = kin.prior_mean[moved]
                _, angles, _ = _fit_3d(kin, target, state.dims, state.roots[0], angles,
                                       free_root=False, dofs=moved)
                own.append((angles[moved], flips))
            variants.append(own)
            dofs.append(moved)
        return variants, dofs

    def _click_costs(self, state, f, angles):
        """Robust click cost (px^2) of a frame's state with each row of ``angles`` (B, n)."""
        kin = self.kin
        Y = kin.forward(angles, state.dims)[0]                                # (B, 17, 3)
        X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
        costs = np.zeros(len(angles))
        for v, cam in enumerate(self._frame_cameras(state)):
            uv = self.obs[f, v]
            seen = np.isfinite(uv).all(axis=-1) & (self.weights[f, v] > 0)
            if cam is None or not seen.any():
                continue
            err = np.linalg.norm(cam.project(X[:, seen]) - uv[seen], axis=-1)  # (B, m)
            costs += np.sum(_rho_px(err), axis=1)
        return costs

    def _score(self, state, f, angles):
        """Negative log posterior (nats, up to a constant) of a frame's state with each row of
        ``angles``: the clicks under CLICK_SIGMA_PX noise, the learned pose prior and the
        camera tilt prior."""
        return self._click_costs(state, f, angles) / CLICK_SIGMA_PX**2 + self.prior.cost(angles) \
            + self._tilt_cost(state)

    def _tilt_cost(self, state):
        """Prior cost (nats) of how the camera of a one-view frame looks at the body."""
        return 0.0

    def _choose_by_prior(self, starts, f):
        """Choose the depth sign of every limb by the clicks and the learned pose prior.

        Every combination of the limbs' variants (:meth:`_limb_variants`) of every start (the
        fit and its whole-body mirror) is scored without refitting (reflected limbs project
        alike), the best is fitted, and the best combination that differs in some body part
        is fitted and scored too: if it is within one nat, the prior cannot decide between
        them and a warning names the parts.
        """
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        pool = []
        for k, state in enumerate(starts):
            variants, dofs = self._limb_variants(state, f)
            grids = np.meshgrid(*[np.arange(len(v)) for v in variants], indexing="ij")
            picks = np.stack([g.ravel() for g in grids], axis=1)            # (B, limbs)
            angles = np.repeat(state.angles, len(picks), axis=0)
            for i, (own, moved) in enumerate(zip(variants, dofs)):
                table = np.array([a for a, _ in own])
                angles[:, moved] = table[picks[:, i]]
            scores = self._score(state, f, angles)
            pool += [(float(sc), k, a) for sc, a in zip(scores, angles)]
        pool.sort(key=lambda t: t[0])

        def fitted(entry):
            _, k, angles = entry
            trial = starts[k].copy()
            trial.angles[0] = angles
            trial, _, _ = _fit(self.kin, obs, w, trial,
                               **self.options(trial, f, fit_dims=self.fit_dims))
            return trial, float(self._score(trial, f, trial.angles)[0])

        # The few best combinations that differ from each other are fitted and scored
        # again: a reflected limb posed by inverse kinematics can miss its clicks a little.
        chosen = []
        for entry in pool:
            if entry[0] > pool[0][0] + PRIOR_MARGIN or len(chosen) == PRIOR_REFITS:
                break
            trial = starts[entry[1]].copy()
            trial.angles[0] = entry[2]
            if all(self._moved_parts(other, trial) for other, _ in chosen):
                chosen.append((trial, entry))
        results = sorted((fitted(entry) for _, entry in chosen), key=lambda t: t[1])
        best, best_score = results[0]
        for alt, alt_score in results[1:]:
            moved = self._moved_parts(best, alt)
            if moved and alt_score < best_score + 1.0:
                self.ambiguous = True
                self._note_ambiguous(f, moved)
                self.warnings.append(
                    f"frame {self.frames[f]}: a pose with {_join(moved)} mirrored in depth "
                    f"fits about as well (clicks and pose prior: {alt_score:.1f} vs "
                    f"{best_score:.1f} nats); the 3D pose is uncertain there: click this frame "
                    "in another view")
                break
        return best

    def _frame_cameras(self, state):
        """The cameras of a one-frame state, per view (None where none)."""
        return list(state.cameras[0])

    def _explore_limbs(self, state, cost, f):
        """Try each limb (and each lower limb) turned to its depth mirror image, §2.6's
        ambiguity of a single view: a bone pointing towards the camera projects like one
        pointing away. Local fits cannot cross between the two, so each is started by inverse
        kinematics from the reflected joints and kept if it fits better (clicks and prior).

        Returns
        -------
        state : _State
        cost : float
        rivals : list of (_State, float)
            The alternatives met, for the ambiguity report.
        """
        rivals = []
        normal = self.depth_direction(state, f)
        if normal is None:
            return state, cost, rivals
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        names = self.kin.structure.dof_names
        for _ in range(2):
            improved = False
            for pivot, distal in LIMB_FLIPS:
                Y = self.kin.forward(state.angles, state.dims)[0][0]
                X = Y @ state.roots[0, :3, :3].T + state.roots[0, :3, 3]
                p = X[JOINT_INDEX[pivot]]
                n = normal(p)
                target = X.copy()
                rows = [JOINT_INDEX[j] for j in distal]
                shift = 2.0 * ((X[rows] - p) @ n)[:, None] * n
                if np.abs(shift).max() < _MIN_FLIP_M:
                    continue        # the limb lies in the image plane: its mirror is itself
                target[rows] -= shift
                moved = [k for k, name in enumerate(names)
                         if name.startswith((pivot + "_",) + tuple(j + "_" for j in distal))]
                angles = state.angles[0].copy()
                angles[moved] = self.kin.prior_mean[moved]
                root, angles, _ = _fit_3d(self.kin, target, state.dims, state.roots[0], angles,
                                          free_root=False, dofs=moved)
                trial = state.copy()
                trial.roots[0], trial.angles[0] = root, angles
                # A short fit tells the basins apart; the winner is refined below.
                trial, trial_cost, _ = _fit(self.kin, obs, w, trial, max_nfev=_EXPLORE_NFEV,
                                            **self.options(trial, f, fit_dims=self.fit_dims))
                if trial_cost < cost - 1e-6:
                    rivals.append((state, cost))
                    state, cost, improved = trial, trial_cost, True
                else:
                    rivals.append((trial, trial_cost))
            if not improved:
                break
            state, cost, _ = _fit(self.kin, obs, w, state,
                                  **self.options(state, f, fit_dims=self.fit_dims))
        return state, cost, rivals

    def _moved_parts(self, a, b):
        """Body parts (``BODY_PARTS`` names) whose joints differ by more than _AMBIGUOUS_M
        between two poses of a frame, with the trunks aligned."""
        Ya = self.kin.forward(a.angles, a.dims)[0][0]
        Yb = self.kin.forward(b.angles, b.dims)[0][0]
        R, t, scale = similarity_from_points(Ya[_TORSO], Yb[_TORSO])
        apart = np.linalg.norm(scale * Ya @ R.T + t - Yb, axis=-1)
        return [part for part, joints in BODY_PARTS.items()
                if apart[[JOINT_INDEX[j] for j in joints]].max() > _AMBIGUOUS_M]

    def _note_ambiguous(self, f, moved):
        """Remember the parts (``FLIP_PARTS``) another depth of frame ``f`` moves."""
        parts = self.ambiguous_parts.setdefault(self.frames[f], [])
        whole = any(m in ("the trunk", "the head") for m in moved)
        for name in ["body"] if whole else [m[len("the "):] for m in moved]:
            if name not in parts:
                parts.append(name)

    def _posterior(self, state, f):
        """Clicks (and the learned prior, if any, and the camera tilt prior) of a one-frame
        state, nats."""
        clicks = float(self._click_costs(state, f, state.angles)[0]) / CLICK_SIGMA_PX**2
        prior = 0.0 if self.prior is None else float(self.prior.cost(state.angles)[0])
        return clicks + prior + self._tilt_cost(state)

    def _apply_flips(self, state, f):
        """Turn the parts the animator named for frame ``f`` to their other depth."""
        frame = self.frames[f]
        for part in self.flips.get(frame, ()):
            if self.depth_direction(state, f) is None:
                self.warnings.append(f"frame {frame}: clicked in more than one view, so its "
                                     f"depth is seen; the flip of the {part} is ignored")
                continue
            flipped = self._flip(state, f, part)
            if flipped is None:
                self.warnings.append(f"frame {frame}: the {part} lies across the view (its "
                                     "other depth is the same pose); nothing to flip")
                continue
            before = float(self._click_costs(state, f, state.angles)[0])
            after = float(self._click_costs(flipped, f, flipped.angles)[0])
            clicks = int(np.isfinite(self.obs[f]).all(axis=-1).sum())
            if after > 2.0 * before + clicks * CLICK_SIGMA_PX ** 2:
                self.warnings.append(
                    f"frame {frame}: no pose with the {part} at its other depth fits the "
                    f"clicks (mean click error {np.sqrt(after / clicks):.1f} px against "
                    f"{np.sqrt(before / clicks):.1f} px); not flipped")
                continue
            state = flipped
            self.flipped.setdefault(frame, []).append(part)
        return state

    def _flip(self, state, f, part):
        """The best fitting pose of a one-view frame with ``part`` at its other depth: the
        limb's other depth configurations (upper part, lower part, both; posed by inverse
        kinematics on the reflected joints) or the whole body's mirror, each fitted; None if
        no such pose differs from ``state`` there."""
        obs, w = self.obs[f:f + 1], self.weights[f:f + 1]
        if part == "body":
            wanted = None
            trials = [self.mirrored(state, f)]
            if trials[0] is not None and self.prior is not None:
                # the mirror's limbs at either depth, chosen as for the fit itself (its notes
                # of ambiguity are about the mirror, not the pose returned: left out)
                kept, ambiguous = len(self.warnings), self.ambiguous
                parts = {k: list(v) for k, v in self.ambiguous_parts.items()}
                trial, _, _ = _fit(self.kin, obs, w, trials[0],
                                   **self.options(trials[0], f, fit_dims=self.fit_dims))
                trials.append(self._choose_by_prior([trial], f))
                del self.warnings[kept:]
                self.ambiguous, self.ambiguous_parts = ambiguous, parts
        else:
            side, limb = part.split()
            pivot = f"{side[0]}_{'shoulder' if limb == 'arm' else 'hip'}"
            variants, dofs = self._limb_variants(state, f)
            i = [limb_[0] for limb_ in _FLIP_LIMBS].index(pivot)
            trials, wanted = [], f"the {part}"
            for angles, _ in variants[i][1:]:
                trial = state.copy()
                trial.angles[0, dofs[i]] = angles
                trials.append(trial)
        best = None
        for trial in trials:
            if trial is None:
                continue
            trial, _, _ = _fit(self.kin, obs, w, trial,
                               **self.options(trial, f, fit_dims=self.fit_dims))
            moved = self._moved_parts(state, trial)
            if not moved or (wanted is not None and wanted not in moved):
                continue        # the fit went back to the pose it came from
            score = self._posterior(trial, f)
            if best is None or score < best[0]:
                best = (score, trial)
        return None if best is None else best[1]

    def _merge(self, states):
        dims = np.median([s.dims for s in states], axis=0)
        size = float(np.median([s.size for s in states]))
        return _State(dims, size, np.concatenate([s.roots for s in states]),
                      np.concatenate([s.angles for s in states]),
                      [s.cameras[0] for s in states])

    def _solve_all(self, state, obs=None):
        obs = self.obs if obs is None else obs
        # The lengths stay as the frames' fits left them where the animator flipped a part:
        # with the lengths free (and their prior heavy-tailed in one view) a flipped limb comes
        # back to its first depth through a shorter bone.
        fit_dims = self.fit_dims and not self.flipped
        state, cost, _ = _fit(self.kin, obs, self.weights, state,
                              **self.options(state, None, fit_dims=fit_dims))
        return state, cost

    def _check_swaps(self, state, cost):
        """Find click pairs that look exchanged (left for right) in one view, §2.6's clicks.

        A pair is a suspect when its clicks lie off the fit, each nearer the other's
        projection. A frame clicked in one view only bends towards wrong clicks, so there
        every pair is a suspect once some click lies far off. A suspect is confirmed when
        fitting with the pair exchanged removes most of what the pair costs; the fit then keeps
        the exchanged clicks and a warning names them.
        """
        for f in range(len(self.frames)):
            clicked = [v for v in range(len(self.views)) if np.isfinite(self.obs[f, v]).any()]
            for v in clicked:
                for _ in range(2):       # a second exchanged pair in the same view
                    err = self._errors(state)
                    found = self._best_swap(state, cost, err, f, v, single=len(clicked) == 1)
                    if found is None:
                        break
                    (left, right), alt, alt_cost, obs, before = found
                    alt_err = _Problem(self.kin, obs, self.weights, alt, free_root=False,
                                       free_angles=False, fit_dims=False).errors()
                    pair = [JOINT_INDEX[left], JOINT_INDEX[right]]
                    self.warnings.append(
                        f"frame {self.frames[f]}, view {self.views[v]}: {left} and {right} look "
                        f"swapped ({before:.1f} px from the fit, "
                        f"{np.nanmax(alt_err[f, v, pair]):.1f} px if exchanged); fitted them "
                        "exchanged: check the clicks")
                    self.swapped.append((self.frames[f], self.views[v], left, right))
                    self.obs, state, cost = obs, alt, alt_cost
        return state

    def _best_swap(self, state, cost, err, f, v, single):
        """The exchanged pair of view ``v`` in frame ``f`` that lowers the cost most, if any
        lowers it enough: ``((left, right), state, cost, obs, error before)`` or None."""
        o = self.obs[f, v]
        proj = self._projections(state)[f, v]
        far_off = np.nanmax(err[f, v]) > OUTLIER_PX
        best = None
        for left, right in LR_PAIRS:
            a, b = JOINT_INDEX[left], JOINT_INDEX[right]
            if not (np.isfinite(o[a]).all() and np.isfinite(o[b]).all()):
                continue
            apart = np.linalg.norm(o[a] - o[b])
            if apart < 2 * LOSS_SCALE_PX:
                continue
            e_now = err[f, v, a] ** 2 + err[f, v, b] ** 2
            e_swap = np.sum((proj[a] - o[b]) ** 2) + np.sum((proj[b] - o[a]) ** 2)
            off = np.sqrt(e_now / 2)
            suspect = (off > 3 * LOSS_SCALE_PX and off > 0.5 * apart and e_swap < 0.8 * e_now) \
                or (single and far_off)
            if not suspect:
                continue
            obs = self.obs.copy()
            obs[f, v, [a, b]] = obs[f, v, [b, a]]
            alt, alt_cost = self._solve_all(state, obs)
            # Exchanging must remove most of what the pair costs now.
            pair_cost = _robust_cost(err[f, v, [a, b]])
            gain = cost - alt_cost
            if gain > max(0.5 * pair_cost, 2 * LOSS_SCALE_PX ** 2) and \
                    (best is None or alt_cost < best[2]):
                best = ((left, right), alt, alt_cost, obs, off)
        return best

    def _check_outliers(self, state):
        err = self._errors(state)
        for f in range(len(self.frames)):
            for v in range(len(self.views)):
                e = err[f, v]
                if not np.isfinite(e).any():
                    continue
                typical = np.nanmedian(e)
                for j in np.flatnonzero(e > max(OUTLIER_PX, OUTLIER_RATIO * typical)):
                    self.warnings.append(
                        f"frame {self.frames[f]}, view {self.views[v]}: {STANDARD_JOINTS[j]} is "
                        f"{e[j]:.1f} px from the fitted pose (view median {typical:.1f} px): "
                        "check the click")

    def _errors(self, state):
        return _Problem(self.kin, self.obs, self.weights, state, free_root=False,
                        free_angles=False, fit_dims=False).errors()

    def _projections(self, state):
        problem = _Problem(self.kin, self.obs, np.ones_like(self.weights), state,
                           free_root=False, free_angles=False, fit_dims=False)
        x = problem.x0()
        X, _, _ = problem._joints(x)
        return problem._project(X, x[problem.off_cam:].reshape(-1, _CAM_PARAMS))[0]

    def _body(self, state):
        lengths = dict(zip(LENGTH_DIMS, state.dims))
        radii = {n: DEFAULT_DIMS[n] * state.size for n in RADIUS_DIMS}
        return make_body(self.kin.template, {**lengths, **radii})

    def _result(self, state):
        err = self._errors(state)
        body = self._body(state)
        errors = {}
        for f, frame in enumerate(self.frames):
            errors[frame] = {view: err[f, v] for v, view in enumerate(self.views)
                             if np.isfinite(err[f, v]).any()}
        rms = {}
        for v, view in enumerate(self.views):
            e = err[:, v]
            if np.isfinite(e).any():
                rms[view] = float(np.sqrt(np.nanmean(e ** 2)))
        poses = {frame: Pose(state.roots[f].copy(), body.clamp(state.angles[f]))
                 for f, frame in enumerate(self.frames)}
        cameras, view_cameras = self._cameras(state)
        return InitResult(body=body, poses=poses, cameras=cameras, view_cameras=view_cameras,
                          errors=errors, rms=rms, warnings=self.warnings,
                          ambiguous=self.ambiguous, calibrated=self.calibrated,
                          swapped=self.swapped,
                          ambiguous_parts={k: list(v) for k, v in self.ambiguous_parts.items()
                                           if v},
                          flipped={k: list(v) for k, v in self.flipped.items()})


def _join(words):
    """'a', 'a and b', 'a, b and c'."""
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
