"""Plausibility of inputs that are well formed but cannot be right for a take.

A calibration in millimetres, two camera names swapped, a camera turned away from the subject,
a wild lens distortion, a 50 m thigh, plates at different frame rates or a working size of a
few pixels all read without a structural error and then give results metres off with every
frame called ok. These checks put the inputs against each other (the clicks against the
cameras, the lengths against people, the plates against each other) and refuse what cannot
be a take, naming the camera, length or view at fault.
"""

import math

import numpy as np

from ..body.body import DEFAULT_DIMS, LENGTH_DIMS
from ..geometry.camera import PinholeCamera
from ..errors import ZoopraxisError
from ..body.joints import STANDARD_JOINTS

# Body lengths of people, as multiples of the template's adult defaults: wider than the fit's
# own bounds (initialize.DIMS_RANGE) so any fitted body passes, far narrower than a unit slip.
HUMAN_LENGTH_RANGE = (0.4, 2.5)
# Lengths whose default is under this (metres) are only held below the range's top.
SHORT_LENGTH = 0.15

# The clicked joints of one frame span at most this many metres (a tall person reaching up)
# and at least this many (a child curled up); outside it the cameras are in the wrong units.
BODY_SPAN_M = (0.25, 4.0)

# Reprojection RMS of triangulated clicks above which a camera cannot explain the clicks:
# pixels, or this share of the image diagonal, whichever is larger. Hand clicks are a few
# pixels off; a camera of another view or a wrong lens is tens to hundreds.
CLICK_RMS_REFUSE = (25.0, 0.04)
CLICK_RMS_WARN = (8.0, 0.015)

# Frame rates closer than this (relative) are one rate: containers round 29.97 differently.
FPS_TOLERANCE = 0.01

# The person must be this many working pixels tall in some view for the tracker to follow it.
MIN_BODY_PX = 32
# --max-size below this is refused outright, whatever the clicks.
MIN_MAX_SIZE = 32


def finite_number(value):
    """Whether a decoded JSON value is a finite number (not a bool, not an integer too big
    for a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def check_body_dims(dims, where):
    """Refuse body lengths outside the range of people.

    Parameters
    ----------
    dims : dict of str to float
        Body dimensions in metres (lengths checked; radii as given).
    where : str
        The file or option the lengths come from, named in the error.

    Raises
    ------
    ZoopraxisError
        A length that is not a finite number, or outside :data:`HUMAN_LENGTH_RANGE` times the
        adult default, naming the length and the range.
    """
    lo, hi = HUMAN_LENGTH_RANGE
    for name in LENGTH_DIMS:
        if name not in dims:
            continue
        value = dims[name]
        if not finite_number(value):
            raise ZoopraxisError(f"{where}: body length '{name}' is not a number: {value!r:.40}")
        # short lengths (shoulder drop, ankle height, ...) are set by where joints are
        # clicked and may come out near zero
        low = lo * DEFAULT_DIMS[name] if DEFAULT_DIMS[name] >= SHORT_LENGTH else 0.0
        high = hi * DEFAULT_DIMS[name]
        if not low <= value <= high:
            raise ZoopraxisError(f"{where}: body length '{name}' of {value:g} m is outside the "
                                 f"human range ({low:.2f}-{high:.2f} m); are the lengths in "
                                 "metres?")


def check_frame_rates(rates):
    """Refuse plates of one take that run at different frame rates.

    Parameters
    ----------
    rates : dict of str to float or None
        Frames per second by view; None (an image folder) is not compared.

    Raises
    ------
    ZoopraxisError
        Two rates further apart than :data:`FPS_TOLERANCE`, naming the views and rates.
    """
    rates = {view: fps for view, fps in rates.items() if fps}
    if len(rates) < 2:
        return
    slow = min(rates, key=rates.get)
    fast = max(rates, key=rates.get)
    if rates[fast] > rates[slow] * (1 + FPS_TOLERANCE):
        raise ZoopraxisError(
            f"plates '{fast}' ({rates[fast]:g} fps) and '{slow}' ({rates[slow]:g} fps) run at "
            "different frame rates, so their frames are not simultaneous; convert them to one "
            "rate (or give --fps to read all at one rate)")


def check_working_size(anchors, image_sizes, max_size, option="--max-size"):
    """Refuse a working size at which the person is too small to track.

    Parameters
    ----------
    anchors : list of Anchor
        The clicks; the first anchor's give the person's height in each view.
    image_sizes : dict of str to (int, int)
        Plate sizes (width, height) by view.
    max_size : int
        Longest side of the working images, pixels.

    Returns
    -------
    warnings : list of str
        Views in which the person is smaller than :data:`MIN_BODY_PX` working pixels while
        another view is large enough.

    Raises
    ------
    ZoopraxisError
        ``max_size`` below :data:`MIN_MAX_SIZE`, or the person smaller than
        :data:`MIN_BODY_PX` working pixels in every view, with the size that would do.
    """
    if max_size < MIN_MAX_SIZE:
        raise ZoopraxisError(f"{option} {max_size}: give at least {MIN_MAX_SIZE} pixels "
                             "(default 960)")
    heights, needed = {}, {}
    first = anchors[0] if anchors else None
    for view, (w, h) in image_sizes.items():
        clicks = np.array(list(first.views.get(view, {}).values())) if first else np.empty(0)
        if len(clicks) < 2:
            continue
        span = float(np.max(np.ptp(clicks, axis=0)))
        factor = min(1.0, max_size / max(w, h))
        heights[view] = span * factor
        needed[view] = math.ceil(MIN_BODY_PX / max(span, 1e-9) * max(w, h))
    small = [v for v in heights if heights[v] < MIN_BODY_PX]
    if heights and len(small) == len(heights):
        view = max(heights, key=heights.get)
        raise ZoopraxisError(f"{option} {max_size}: the person is only {heights[view]:.0f} px "
                             f"tall in view '{view}' at that size, too small to track; give "
                             f"{option} {needed[view]} or more")
    return [f"at {option} {max_size} the person is only {heights[v]:.0f} px tall in view "
            f"'{v}': that view will hardly help" for v in small]


def _triangulate(cameras, uv):
    """One point from its pixels in two or more pinhole views (linear, rows normalized).

    ``cameras`` and ``uv`` are matched lists; pixels are undistorted first. Returns None
    when the lens model cannot undo a click or the system has no finite solution.
    """
    rows = []
    for cam, p in zip(cameras, uv):
        x = cam.undistort_points(np.asarray(p, float))
        if not np.all(np.isfinite(x)):
            return None
        n = np.linalg.solve(cam.K, [x[0], x[1], 1.0])
        Rt = np.hstack([cam.R, cam.t[:, None]])
        for row in (n[0] * Rt[2] - Rt[0], n[1] * Rt[2] - Rt[1]):
            scale = np.linalg.norm(row)
            if not np.isfinite(scale) or scale == 0:
                return None
            rows.append(row / scale)
    try:
        _, _, vt = np.linalg.svd(np.array(rows))
    except np.linalg.LinAlgError:
        return None
    X = vt[-1]
    if not np.all(np.isfinite(X)) or abs(X[3]) < 1e-12 * np.linalg.norm(X):
        return None
    return X[:3] / X[3]


def _threshold(rule, camera):
    pixels, share = rule
    return max(pixels, share * math.hypot(*camera.image_size))


def check_calibration(cameras, anchors, path):
    """Refuse a calibration that cannot explain the clicks; warn about a doubtful one.

    The joints clicked in two or more calibrated views of an anchor frame are triangulated
    (linear, on undistorted clicks) and projected back into every view. A camera with most of
    the joints behind it, a body spanning more or less than :data:`BODY_SPAN_M` (millimetres
    taken for metres), or a reprojection RMS far above the clicks' noise is refused.

    Parameters
    ----------
    cameras : dict of str to camera
        The take's cameras by view (other camera models are left out).
    anchors : list of Anchor
    path : str
        The calibration file, named in messages.

    Returns
    -------
    warnings : list of str
        Cameras whose RMS is above :data:`CLICK_RMS_WARN` but not refused.

    Raises
    ------
    ZoopraxisError
        Naming the camera (or the body's span) and the file.
    """
    pinholes = {v: c for v, c in cameras.items() if isinstance(c, PinholeCamera)}
    errors = {v: [] for v in pinholes}
    behind = {v: 0 for v in pinholes}
    seen = {v: 0 for v in pinholes}
    for anchor in anchors:
        points = {}
        for joint in STANDARD_JOINTS:
            views = [v for v in pinholes if joint in anchor.views.get(v, {})]
            if len(views) < 2:
                continue
            X = _triangulate([pinholes[v] for v in views],
                             [anchor.views[v][joint] for v in views])
            if X is None:
                bad = ", ".join(f"'{v}'" for v in views)
                raise ZoopraxisError(f"{path}: cameras {bad} cannot place joint '{joint}' "
                                     f"of frame {anchor.frame} (a lens distortion past its "
                                     "fold, or numbers far too big)")
            points[joint] = X
            for v in views:
                seen[v] += 1
                if pinholes[v].depth(X) <= 0:
                    behind[v] += 1
                with np.errstate(all="ignore"):
                    uv = pinholes[v].project(X)
                d = float(np.hypot(*(np.asarray(uv) - anchor.views[v][joint])))
                errors[v].append(d if math.isfinite(d) else 1e9)
        if len(points) >= 4:
            X = np.array(list(points.values()))
            span = float(np.max(np.linalg.norm(X[:, None] - X[None], axis=-1)))
            lo, hi = BODY_SPAN_M
            if not lo <= span <= hi:
                raise ZoopraxisError(
                    f"{path}: the joints clicked at frame {anchor.frame} triangulate to a body "
                    f"{span:.3g} m across (a person is {lo}-{hi} m): are the camera "
                    "translations in metres? (millimetres make it 1000 times too big)")
    for v in pinholes:
        if seen[v] and behind[v] > seen[v] / 2:
            raise ZoopraxisError(f"{path}: camera '{v}' has the subject behind it "
                                 f"({behind[v]} of {seen[v]} clicked joints): check its R "
                                 "and t (X_cam = R @ X_world + t, OpenCV axes)")
    rms = {v: math.sqrt(np.mean(np.square(e))) for v, e in errors.items() if e}
    refused = sorted((v for v in rms if rms[v] > _threshold(CLICK_RMS_REFUSE, pinholes[v])),
                     key=rms.get, reverse=True)
    if refused:
        listed = ", ".join(f"'{v}' {rms[v]:.0f} px" for v in refused)
        raise ZoopraxisError(
            f"{path}: the cameras cannot explain the clicks: reprojection RMS {listed} (clicks "
            "are a few px off); is a camera named after another view, or its lens or pose "
            "wrong?")
    return [f"{path}: camera '{v}' explains the clicks poorly (reprojection RMS "
            f"{rms[v]:.1f} px); check its calibration and the clicks in that view"
            for v in rms if rms[v] > _threshold(CLICK_RMS_WARN, pinholes[v])]


def fit_rms_warnings(rms, cameras):
    """Warnings about calibrated views whose clicks the fitted body misses by far more than
    the clicks' noise (the calibration, or the clicks, of that view are off).

    Parameters
    ----------
    rms : dict of str to float
        Reprojection RMS of the fit per view, pixels.
    cameras : dict of str to camera
        The views' cameras (pinhole ones are judged).

    Returns
    -------
    warnings : list of str
    """
    return [f"view '{v}': the fitted body misses the clicks by {error:.0f} px RMS (clicks are "
            f"a few px off): check camera '{v}' of the calibration, and the clicks in that view"
            for v, error in rms.items()
            if isinstance(cameras.get(v), PinholeCamera)
            and error > _threshold(CLICK_RMS_WARN, cameras[v])]
