"""Initialization from clicked joints (Bregler & Malik §2.6) and model fine-tuning (§2.7).

The animator clicks the 2D joints of one or more anchor frames in one or more views. This module
finds the body pose of each anchor frame, the joint angles and the body dimensions that put the
model's 17 standard joints where the clicks are: "minimizing the sum of squared differences
between the projected model joint locations and the user supplied model joint locations ... over
the poses, angles, and body dimensions" (§2.6). Left and right dimensions are one number each
(the body model ties them by construction), the angles are shared by all views of a frame, and
the dimensions by all anchors.

Two modes, as in the papers:

- calibrated (Yamamoto et al.; Sidenbladh et al.): perspective cameras known; one world pose
  (root) per anchor frame;
- uncalibrated (Bregler & Malik §2.3): one scaled orthographic camera per view and anchor frame
  ("the pose can be different" per view), the body root fixed at the identity, so the 3D result
  lives in a body-centred frame.

The problem is tri-linear (§2.6) and has mirror ambiguities, so it is solved from good starting
points (calibrated: triangulated joints, the trunk placed by Kabsch, inverse kinematics with
several starts per limb; uncalibrated: the body turned every 45 degrees, affine cameras for
the other views) by ``scipy.optimize.least_squares`` with analytic Jacobians, a robust loss on
the clicks, bounds for the joint limits and the dimensions, and priors of everyday angles and
of the template's proportions (what the clicks cannot see, e.g. the split of a bend between the
two spine joints, takes its likely value). In a frame clicked in one view, every limb is also
tried mirrored in depth, and the depth signs of the limbs' parts are chosen by the clicks
together with a pose prior learned from motion capture (:class:`PosePrior`, a kernel density
of joint angles per limb, ``core/priors/data/pose_prior.npz`` from ``tools/learn_pose_prior.py``).
The same prior, as a Gaussian mixture per limb (:meth:`PosePrior.mixture`), replaces the
everyday-angle prior in the least-squares fit of such a frame, so that it also sets the depth
of limbs nearly in the image plane, which the clicks leave almost free.
Clicks that look swapped left for right and outlying clicks are named in warnings and not
absorbed; a mirrored pose that fits (and is as likely) about as well is reported, with the
parts it moves (``InitResult.ambiguous_parts``). The animator, who sees the footage, may then
name limbs to turn to their other depth (``flips``; ``--flip`` on the command line, toggles in
the add-on's panel): each is fitted again from its reflected configurations.

:func:`refine_dims` is the joint-based form of model fine-tuning (§2.7): the same joint
problem over many frames with 2D joint observations; it is solved by blocks (Schur complement
on the shared dimensions, as in bundle adjustment). Fine-tuning on the images of a tracked take
(silhouettes and clicks) is ``finetune.py``.

Convention: world Z up, metres; OpenCV cameras and pixels (``X_c = R @ X_w + t``). Body
dimensions are the body model's ``LENGTH_DIMS`` (metres). Rotations in the parameter vectors
are increments ``exp(w) @ R_start`` on the left (spatial), like ``Pose.retract``.
"""

import numpy as np

from ..body.body import DEFAULT_DIMS, LENGTH_DIMS
from ..body.kinematics import kinematics
from ..errors import ZoopraxisError
from ..priors.pose import resolve_pose_prior
from .calibrated import _CalibratedFit
from .flips import check_flips
from .options import CAMERA_TILT_DEG, check_camera_tilt
from .problem import N_JOINTS
from .uncalibrated import _UncalibratedFit

# What a fit of the lengths to frames each clicked in one view adds to the result's notes. One
# view sees a length only through its bone's foreshortening, and a limb's depth hangs on it.
# Held-out CMU frames in one view, 1080p from afar, 2 px clicks (benchmarks/bench_initialize.py):
# 51 mm off (Procrustes-aligned) with the lengths fitted to the clicks, 35 mm with the
# performer's lengths from a three-view init kept. On 18 such frames: 60 mm fitted; 50 mm with
# the lengths' prior centred on each performer's own proportions (lengths then within 5 %);
# kept, the true lengths give 37 mm, with 1 % random error 39 mm, with 2 % 43 mm.
ONE_VIEW_LENGTHS_NOTE = (
    "the body lengths were fitted to frames each clicked in one view, which shows them poorly, "
    "and the depth of the limbs depends on them: if this performer was clicked in several "
    "views in another shot, keep the lengths fitted there (--dims-from, or Body Lengths From "
    "in the add-on)")
_MIN_FRAME_JOINTS = 6      # joints a frame needs in its best view to pose the body

# Lengths whose prior, when every anchor is clicked in one view, is centred on the captured
# performers' mean proportion (the learned proportions prior, priors/proportions.py) instead of
# the template's, in calibrated views. One view bounds a length only from below: a longer bone
# fits the same clicks turned in depth, so the prior's centre decides the length, and the
# limb's depth with it. The
# template's forearm is 0.9 of its upper arm; the captured performers' is 0.64 (0.213 of the
# template's size, spread 12 %; anthropometric tables give 0.79), and the rendered one-view
# sets' performers' 0.65-0.77. Fitted from one calibrated side view, the forearm came out
# 210-250 mm against 185-202 true, its far end turned 90-130 mm in depth at the clicked frame
# (walk02_single: the wrist 170-200 mm off there after alignment). Centred on the learned mean
# (three sets of clicks): walk131_single 72.5 -> 66.0 mm after alignment, walk02_single 56.3
# -> 50.4, nav09_single 47.7 -> 46.7. The learned mean of every length did worse (74.3, 54.8,
# 54.3: its shank, 1.07 of the thigh, is longer than these performers' 0.95-1.02), and so did
# its spreads with it (73.9, 51.9, 57.3). Uncalibrated views keep the template's: bodies of the
# template's build (tests, synthetic takes) went from under 40 mm to 58 there, and the rendered
# sets (clicks of seed 7) moved by +1.7, -18.0 and +4.9 mm.
ONE_VIEW_LEARNED_LENGTHS = ("forearm",)
# Spread of the lengths about the template's proportions when calibrated views see the anchor's
# joints from several directions, and the clicks measure the bones. Real bodies' proportions
# spread more than the 5 % (DIMS_PRIOR_SIGMA) that one view needs: 6-12 % for the limbs across
# the captured performers (priors/proportions.py), a shank 0.95-1.21 of the thigh. Held at 5 %,
# the fit of the exact clicks of eight rendered performers in 3-4 views put the shank 3-26 mm
# short and the forearm 0-26 mm long (benchmarks/bench_anchor_lengths.py with the sets of
# benchmarks/README.md), and short legs straighten the tracked knee; with 2 px clicks the
# lengths' error fell from 7.0, 14.1, 18.1 and 19.7 mm (thigh, shank, upper arm, forearm) to
# 5.1, 10.2, 16.8 and 14.5 at 10 %.
SEVERAL_VIEWS_DIMS_SIGMA = 0.10
# The lengths whose prior, in several calibrated views, is centred on the captured performers'
# mean proportion (the proportions prior) rather than the template's: all of them. The
# performers' shank is 16 % longer than the template's proportion, the upper arm 14 % longer,
# the forearm 18 % shorter. With each rendered set's performer left out of the prior, 2 px
# clicks of eight sets, six seeds (bench_anchor_lengths.py --learned none|all), the lengths'
# error went from 5.1, 10.2, 16.8 and 14.5 mm (thigh, shank, upper arm, forearm) to 5.3, 8.5,
# 14.5 and 11.7; 7 % or 14 % wide about that centre did no better (5.8/5.2, 7.9/9.0,
# 13.7/15.2, 11.5/12.7).
SEVERAL_VIEWS_LEARNED_LENGTHS = LENGTH_DIMS


def _observations(anchors, views):
    """Clicks as an array (F, V, 17, 2), NaN where not clicked."""
    obs = np.full((len(anchors), len(views), N_JOINTS, 2), np.nan)
    for f, anchor in enumerate(anchors):
        for v, view in enumerate(views):
            obs[f, v] = anchor.array(view)
    return obs


def _check_anchors(anchors, views):
    if not anchors:
        raise ZoopraxisError("no anchor frames: click the joints on a first frame")
    for a in anchors:
        best = max((a.joint_count(v) for v in views), default=0)
        if best < _MIN_FRAME_JOINTS and _seen_twice(a, views) < _MIN_FRAME_JOINTS:
            raise ZoopraxisError(
                f"frame {a.frame}: at most {best} joints clicked in one view; click at least "
                f"{_MIN_FRAME_JOINTS} joints in one view to pose the body")


def _seen_twice(anchor, views):
    count = {}
    for v in views:
        for j in anchor.views.get(v, {}):
            count[j] = count.get(j, 0) + 1
    return sum(1 for c in count.values() if c >= 2)


def initialize(anchors, cameras, *, template="full", calibrated=True, dims=None, fit_dims=True,
               views=None, pose_prior="default", flips=None, camera_tilt=CAMERA_TILT_DEG,
               perspective=False, proportions=None, pose_basis="default"):
    """Pose, angles and body dimensions from the clicked joints of anchor frames (§2.6).

    Parameters
    ----------
    anchors : list of markers.Anchor
        Clicked joints per anchor frame and view (pixels).
    cameras : dict of str to camera
        Calibrated: the perspective cameras of the views. Uncalibrated: only their image sizes
        are used (a camera or a ``(width, height)`` per view); may be None, then the clicks set
        the principal point.
    template : str
        Body template (``body.TEMPLATES``).
    calibrated : bool
        Calibrated perspective views with one world pose per anchor, or Bregler & Malik's
        uncalibrated mode with one scaled orthographic camera per view and anchor.
    dims : dict, optional
        Starting body dimensions (metres); defaults to the template's.
    fit_dims : bool
        Fit the lengths (shared by all anchors); otherwise keep ``dims``.
    views : list of str, optional
        The views to use; default all views of ``cameras`` (calibrated) or with clicks.
    pose_prior : PosePrior, "default", path or None
        In frames clicked in one view, chooses the depth sign of each limb (the mirror
        ambiguity) and, uncalibrated, is the angle prior of the fit (weight PRIOR_WEIGHT):
        the shipped prior learned from motion capture (``"default"``, if there is one for the
        template), a given one or the file of one (``zoopraxis prior``: learned from takes of
        the kind of motion at hand), or none (then the angle prior of everyday poses alone
        decides).
    flips : dict of int to list of str, optional
        Per anchor frame clicked in one view, body parts (``FLIP_PARTS``: "left arm", ...,
        "body") to turn to their other depth: the best fitting pose in which that limb lies
        otherwise in depth (or the whole body's mirror image), even if it fits a little worse.
        The animator's answer to a reported ambiguity (``InitResult.ambiguous_parts``).
    camera_tilt : (float, float) or None
        Uncalibrated, in frames clicked in one view: how far (degrees) the camera is expected
        to look down at the upright body, and give or take how much (a Gaussian prior on the
        depth lean one view cannot see; ``CAMERA_TILT_DEG``: level, 10 degrees). None: no
        prior. A camera looking up has a negative tilt.
    perspective : bool
        Uncalibrated: the views are near the body (a phone or a normal lens a few metres away,
        at least 1 / KAPPA_MAX), so each camera's perspective is fitted too
        (``ScaledOrthoCamera.kappa``). Default: far or telephoto views, scaled orthographic.
    proportions : proportions.ProportionsPrior or None
        The proportions of the performers' bodies (``priors/proportions.py``,
        ``tools/learn_proportions_prior.py``); None: the shipped prior where the fit leans on
        learned proportions. Calibrated, when the lengths are fitted: the centre of the lengths'
        prior (``several_views_dims_prior``, ``one_view_dims_prior``). Uncalibrated, only when
        given: its mean and spread are the lengths' prior instead of the template's proportions
        within DIMS_PRIOR_SIGMA. Not the uncalibrated default: on held-out CMU performers in one
        view the shipped one was 72.6 mm off instead of 64.2 (36 frames; 60.1 instead of 57.2
        for those with their own lengths, 88.2 instead of 72.9 for those on cgspeed's Daz
        figure), and random bodies of the template's proportions came out 75 mm off instead
        of under 40 (benchmarks/bench_initialize.py --only held-out-subjects).
    pose_basis : basis.PoseBasis, "default", path or None
        Uncalibrated, in frames clicked in one view with a pose prior: a basis of captured 3D
        joint sets (``priors/basis.py``, ``tools/learn_pose_basis.py``) fitted to the clicks
        gives more starts (with the lengths measured on them, their prior centred there) and
        its density of the 3D joints, mixed half and half with a Gaussian of the body's
        everyday poses (``PoseBasis.with_broad``, as the pose prior's), joins the pose prior
        in choosing the limbs' depth signs and the search. ``"default"`` (the default): the
        shipped one; None: without (``--no-pose-basis``, the add-on's *Pose Basis*). On
        held-out CMU performers in one view it takes the error from 56.1 mm to 49.5 (36
        frames, Procrustes-aligned; performers and basis held out alike), on random everyday
        poses of the body model from 42.6 to 45.3 (30 poses, median 36.5 to 34.9). Without
        the everyday Gaussian (the basis alone) it was 46.0 and 58.4: poses unlike the
        captures' were turned towards the captures' depths (benchmarks/README.md).

    Returns
    -------
    result : InitResult

    Raises
    ------
    ZoopraxisError
        No anchors, a view without a camera, a frame with too few clicks, a flip of an unknown
        part or of a frame that is not an anchor, perspective asked of calibrated views.
    """
    if perspective and calibrated:
        raise ZoopraxisError("perspective is fitted for uncalibrated views only (calibrated "
                             "cameras have their own)")
    anchors = sorted(anchors, key=lambda a: a.frame)
    flips = check_flips(flips, [a.frame for a in anchors])
    frames = [a.frame for a in anchors]
    if len(set(frames)) != len(frames):
        raise ZoopraxisError(f"frame {next(f for f in frames if frames.count(f) > 1)} has two "
                             "anchors")
    clicked = []
    for a in anchors:
        clicked += [v for v in a.views if a.joint_count(v) and v not in clicked]
    if calibrated:
        cameras = cameras or {}
        for a in anchors:
            for v in a.views:
                if a.joint_count(v) and v not in cameras and (views is None or v in views):
                    raise ZoopraxisError(
                        f"frame {a.frame}: view '{v}' has no camera in the calibration "
                        f"(cameras: {', '.join(cameras) or 'none'})")
        views = list(views) if views is not None else list(cameras)
        missing = [v for v in views if v not in cameras]
        if missing:
            raise ZoopraxisError(f"view '{missing[0]}' has no camera in the calibration "
                                 f"(cameras: {', '.join(cameras) or 'none'})")
    else:
        views = list(views) if views is not None else \
            list(cameras or {}) + [v for v in clicked if v not in (cameras or {})]
    if not views:
        raise ZoopraxisError("no views: give the cameras or click joints in some view")
    _check_anchors(anchors, views)
    kin = kinematics(template)
    dims0 = kin.default_dims.copy() if not dims else \
        np.array([float(dims.get(n, DEFAULT_DIMS[n])) for n in LENGTH_DIMS])
    obs = _observations(anchors, views)
    weights = np.ones(obs.shape[:3])
    warnings = []
    # every anchor clicked in one view (its lengths seen only through foreshortening)
    one_view = all(_seen_twice(a, views) < _MIN_FRAME_JOINTS for a in anchors)
    if calibrated:
        fit = _CalibratedFit(kin, obs, weights, [cameras[v] for v in views], views, anchors,
                             dims0, fit_dims, warnings)
    else:
        sizes = [_image_size(cameras, v, obs[:, i]) for i, v in enumerate(views)]
        fit = _UncalibratedFit(kin, obs, weights, sizes, views, anchors, dims0, fit_dims,
                               warnings)
        if camera_tilt is not None:
            down, spread = check_camera_tilt(camera_tilt)
            # A camera looking down sees the body's up axis turned away from it.
            fit.tilt = (-np.sin(np.radians(down)), np.sin(np.radians(spread)))
        fit.perspective = bool(perspective)
        if proportions is not None:
            fit.dims_prior = proportions.mean_sigma()
            if not dims:
                # start from the proportions' mean (at the template's size)
                fit.dims0 = fit.dims_prior[0].copy()
    if calibrated and fit_dims:
        if one_view:
            fit.dims_prior = one_view_dims_prior(kin, proportions)
        else:
            fit.dims_prior = several_views_dims_prior(kin, proportions)
    pose_prior = resolve_pose_prior(pose_prior, template)
    fit.prior = None if pose_prior is None else \
        pose_prior.with_broad(kin.prior_mean, kin.prior_sigma)
    if not calibrated and fit.prior is not None:
        from ..priors.basis import everyday_joint_sets, resolve_pose_basis

        fit.basis = resolve_pose_basis(pose_basis)
        if fit.basis is not None and fit.basis.broad is None:
            # as the pose prior: poses unlike the captures' fall back on everyday ones
            fit.basis = fit.basis.with_broad(everyday_joint_sets(kin))
    fit.flips = flips
    result = fit.run()
    if calibrated:
        from ..files.plausible import fit_rms_warnings

        result.warnings.extend(fit_rms_warnings(result.rms, {v: cameras[v] for v in views}))
    if fit_dims and one_view:
        result.notes.append(ONE_VIEW_LENGTHS_NOTE)
    return result


def several_views_dims_prior(kin, proportions=None):
    """``(mean, relative sigma)`` of the lengths fitted to anchors whose joints calibrated views
    see from several directions: the captured performers' mean proportion (``proportions``, the
    shipped prior by default) for ``SEVERAL_VIEWS_LEARNED_LENGTHS`` and the template's for the
    others, each within ``SEVERAL_VIEWS_DIMS_SIGMA``."""
    return _learned_centre(kin, SEVERAL_VIEWS_LEARNED_LENGTHS, proportions), \
        np.full(len(kin.default_dims), SEVERAL_VIEWS_DIMS_SIGMA)


def one_view_dims_prior(kin, proportions=None):
    """``(mean, relative sigma)`` of the lengths (``kin``'s ``LENGTH_DIMS``) fitted to frames
    each clicked in one view: the template's proportions within ``DIMS_PRIOR_SIGMA``, with the
    captured performers' mean proportion (``proportions``, the shipped prior by default) for
    ``ONE_VIEW_LEARNED_LENGTHS`` (see there)."""
    from .problem import DIMS_PRIOR_SIGMA

    return _learned_centre(kin, ONE_VIEW_LEARNED_LENGTHS, proportions), \
        np.full(len(kin.default_dims), DIMS_PRIOR_SIGMA)


def _learned_centre(kin, names, proportions):
    """The template's lengths with the performers' mean proportion (``proportions``, else the
    shipped prior; none without its file) for ``names``."""
    from ..priors.proportions import default_proportions_prior

    mean = kin.default_dims.copy()
    prior = proportions if proportions is not None else default_proportions_prior()
    if names and prior is not None:
        index = [LENGTH_DIMS.index(name) for name in names]
        mean[index] = prior.mean_sigma()[0][index]
    return mean


def _image_size(cameras, view, uv):
    if cameras and view in cameras:
        entry = cameras[view]
        return tuple(int(x) for x in getattr(entry, "image_size", entry))
    pts = uv[np.isfinite(uv).all(axis=-1)]
    if len(pts) == 0:
        return (640, 480)
    # Without a size, centre the principal point on the clicks (it is redundant with the
    # camera's image shift anyway).
    return tuple(int(np.ceil(2 * x + 1)) for x in pts.mean(axis=0))


def initialize_take(anchors, views, plates, cameras, options, log=None):
    """The initialization of a take from its markers, as the trackers, fine-tuning, the
    add-on and the command line make it: :func:`initialize` with ``options``, its flips, camera
    distances (``options.perspective``) and notes logged.

    Parameters
    ----------
    anchors : list of markers.Anchor
        The anchor frames to fit (those inside the frames to track).
    views : list of str
    plates : dict of str to Plate
        Their image sizes are the uncalibrated views' sizes.
    cameras : dict of str to camera, or None
        Calibrated mode when given.
    options : InitOptions
    log : callable(str), optional

    Returns
    -------
    InitResult
    """
    log = log or (lambda msg: None)
    calibrated = cameras is not None
    sizes = cameras if calibrated else {v: tuple(plates[v].image_size) for v in views}
    result = initialize(anchors, sizes,
                        template=options.template, calibrated=calibrated, views=list(views),
                        flips=options.flips, camera_tilt=options.camera_tilt,
                        pose_prior=options.pose_prior, pose_basis=options.pose_basis,
                        dims=options.dims, proportions=options.proportions,
                        fit_dims=options.fits_dims, perspective=options.perspective)
    for note in result.flip_notes() + ([result.distance_note()] if options.perspective else []):
        log(note)
    for note in result.notes:
        log(f"note: {note}")
    return result
