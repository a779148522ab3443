"""Argument helpers shared by the commands."""

import numpy as np

from ..errors import ZoopraxisError


def parse_view_values(items, what, convert=str):
    """``["cam0=PATH", ...]`` -> ordered dict of view name to value.

    Raises
    ------
    ZoopraxisError
        An item without ``=``, an empty name or value, a view named twice, or a value that
        ``convert`` refuses, in one line naming the option.
    """
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if not sep or not name or not value:
            raise ZoopraxisError(f"{what} must look like VIEW=VALUE (e.g. cam0=plates/cam0), "
                                 f"got '{item}'")
        if name in out:
            raise ZoopraxisError(f"{what}: view '{name}' is given twice")
        try:
            out[name] = convert(value)
        except ValueError:
            raise ZoopraxisError(f"{what} {item}: '{value}' is not valid") from None
    return out


def parse_flips(items):
    """``--flip FRAME:PART`` options as ``{frame: [part, ...]}`` (None when there are none).

    Raises
    ------
    ZoopraxisError
        An option that is not FRAME:PART with a known part.
    """
    out = {}
    for item in items or ():
        frame, part = parse_flip(item)
        if part not in out.setdefault(frame, []):
            out[frame].append(part)
    return out or None


def parse_flip(text):
    """``"80:left-leg"`` -> ``(80, "left leg")`` (the command line's ``--flip``).

    Raises
    ------
    ZoopraxisError
    """
    from ..initialize.flips import FLIP_PARTS, flip_part

    frame, _, part = str(text).partition(":")
    try:
        frame = int(frame)
    except ValueError:
        frame = None
    name = flip_part(part) if part else None
    if frame is None or name is None:
        raise ZoopraxisError(f"--flip '{text}': expected FRAME:PART, PART one of "
                             f"{', '.join(p.replace(' ', '-') for p in FLIP_PARTS)}")
    return frame, name


def add_flip_argument(parser):
    """``--flip FRAME:PART``: a body part turned to its other depth at a one-view anchor."""
    parser.add_argument("--flip", action="append", default=[], metavar="FRAME:PART",
                        help="at an anchor frame clicked in one view, turn a body part to its "
                             "other depth (PART: left-arm, right-arm, left-leg, right-leg or "
                             "body); repeat for more")


def add_camera_tilt_argument(parser):
    """``--camera-tilt DOWN[:SPREAD]`` for frames clicked in one uncalibrated view."""
    from ..initialize.options import CAMERA_TILT_DEG

    down, spread = CAMERA_TILT_DEG
    parser.add_argument("--camera-tilt", default=None, metavar="DOWN[:SPREAD]",
                        help="uncalibrated, at an anchor frame clicked in one view: how many "
                             "degrees the camera looks down at the (upright) subject, give or "
                             f"take SPREAD (default {down:g}:{spread:g}: about level); 'none' "
                             "for no such prior")


def add_perspective_argument(parser):
    """``--perspective``: fit the perspective of uncalibrated views filmed from near."""
    parser.add_argument("--perspective", action="store_true",
                        help="uncalibrated views near the body (a phone or a normal lens a few "
                             "metres away): fit each camera's perspective too (default: far or "
                             "telephoto views, scaled orthographic)")


def check_uncalibrated_options(args, calibrated):
    """Refuse ``--camera-tilt`` and ``--perspective`` with a calibration, which gives both, and
    ``--no-pose-basis`` with a calibration (the basis is for uncalibrated views only)."""
    for flag, given, what in (("--camera-tilt", args.camera_tilt is not None, "tilt"),
                              ("--perspective", args.perspective, "perspective")):
        if given and calibrated:
            raise ZoopraxisError(f"{flag} is for uncalibrated views: the calibration gives "
                                 f"the cameras' {what}")
    if getattr(args, "no_pose_basis", False) and calibrated:
        raise ZoopraxisError("--no-pose-basis is for uncalibrated views: with a calibration "
                             "the pose prior alone chooses a one-view frame's depths")


def add_pose_prior_arguments(parser):
    """``--pose-prior FILE``, ``--no-pose-prior`` and ``--no-pose-basis`` for frames clicked
    in one view, and ``--proportions-prior FILE``."""
    parser.add_argument("--pose-prior", default=None, metavar="FILE",
                        help="at an anchor frame clicked in one view, choose the limbs' depth "
                             "with this pose prior (from 'zoopraxis prior': takes of the kind "
                             "of motion at hand) instead of the shipped one")
    parser.add_argument("--no-pose-prior", action="store_true",
                        help="at an anchor frame clicked in one view, choose the limbs' depth "
                             "without a pose prior learned from motion capture (nor the pose "
                             "basis, which works beside it)")
    parser.add_argument("--no-pose-basis", action="store_true",
                        help="uncalibrated, at an anchor frame clicked in one view: without "
                             "the shipped basis of captured 3D poses (its fits to the clicks "
                             "as starts, its density beside everyday poses' in the choice of "
                             "the pose); the pose prior alone, a little better for poses "
                             "unlike any captured")
    parser.add_argument("--proportions-prior", default=None, metavar="FILE",
                        help="the body proportions the fitted lengths lean on: a file from "
                             "tools/learn_proportions_prior.py (other captures, or performers "
                             "held out) instead of the shipped one; uncalibrated, its mean and "
                             "spread replace the template's proportions")


def parse_pose_prior(args, template):
    """``initialize``'s ``pose_prior`` from ``--pose-prior`` / ``--no-pose-prior``: the file
    read and checked against the template, None, or "default".

    Raises
    ------
    ZoopraxisError
        Both options, or a missing, unreadable or mismatched file (naming it).
    """
    from ..priors.pose import resolve_pose_prior

    if args.pose_prior is not None and args.no_pose_prior:
        raise ZoopraxisError("give --pose-prior or --no-pose-prior, not both")
    if args.no_pose_prior:
        return None
    if args.pose_prior is None:
        return "default"
    return resolve_pose_prior(args.pose_prior, template)


def parse_camera_tilt(text):
    """``--camera-tilt`` as ``(down, spread)`` degrees (the default one if ``text`` is None),
    or None for 'none'.

    Raises
    ------
    ZoopraxisError
        Not DOWN or DOWN:SPREAD in range.
    """
    from ..initialize.options import CAMERA_TILT_DEG, check_camera_tilt

    if text is None:
        return CAMERA_TILT_DEG
    if text.strip().lower() == "none":
        return None
    parts = text.split(":")
    try:
        values = [float(x) for x in parts]
    except ValueError:
        values = []
    if len(parts) not in (1, 2) or len(values) != len(parts) \
            or not all(np.isfinite(values)):
        raise ZoopraxisError(f"--camera-tilt {text}: expected DOWN or DOWN:SPREAD in degrees "
                             "(say 15:10), or none")
    return check_camera_tilt((values[0], values[1] if len(values) == 2 else CAMERA_TILT_DEG[1]),
                             f"--camera-tilt {text}")


def parse_init_options(args, calibrated, fit_dims=True):
    """The :class:`InitOptions` of the command line's initialization options (``--template``,
    ``--flip``, ``--camera-tilt``, ``--perspective``, ``--pose-prior`` / ``--no-pose-prior``,
    ``--no-pose-basis``, ``--proportions-prior``, ``--dims-from``), each checked.

    Raises
    ------
    ZoopraxisError
        As the parsers of each option; ``--camera-tilt`` or ``--perspective`` with a
        calibration.
    """
    from ..initialize.options import InitOptions

    flips = parse_flips(args.flip)
    camera_tilt = parse_camera_tilt(args.camera_tilt)
    check_uncalibrated_options(args, calibrated)
    pose_prior = parse_pose_prior(args, args.template)
    dims = read_dims(args.dims_from, args.template) if args.dims_from else None
    proportions = None
    if args.proportions_prior is not None:
        from ..priors.proportions import ProportionsPrior

        proportions = ProportionsPrior.load(args.proportions_prior)
    return InitOptions(template=args.template, flips=flips, pose_prior=pose_prior,
                       pose_basis=None if args.no_pose_basis else "default", dims=dims,
                       fit_dims=fit_dims, camera_tilt=camera_tilt,
                       perspective=args.perspective, proportions=proportions)


def add_output_arguments(parser, what):
    """``--out`` (the file to write, described by ``what``) and ``--force``."""
    parser.add_argument("--out", required=True, help=f"{what} to write")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")


def check_template(name):
    """``--template``: a body template's name, else a one-line error listing them."""
    from ..body.body import TEMPLATES

    if name not in TEMPLATES:
        raise ZoopraxisError(f"--template: unknown body template '{name}' (expected one of "
                             f"{', '.join(TEMPLATES)})")
    return name


def check_output(path, force, inputs=(), suffixes=None):
    """``--out`` as a Path, checked before any work (:func:`outputs.check_output`): not a
    folder, none of ``inputs`` (``(option, path)`` pairs), writable, and an existing file
    replaced only with --force."""
    from ..files import outputs

    return outputs.check_output(path, force, inputs=inputs, suffixes=suffixes)


def open_plates(paths, fps=None):
    """Open ``{view: path}`` plates; returns ``{view: Plate}`` (one-line errors per path)."""
    from ..imaging.plates import open_plate
    from ..files.plausible import check_frame_rates

    if not paths:
        raise ZoopraxisError("give at least one --plate VIEW=PATH")
    plates = {name: open_plate(path, name=name, fps=fps) for name, path in paths.items()}
    check_frame_rates({name: plate.fps for name, plate in plates.items()})
    return plates


def add_dims_argument(parser):
    """``--dims-from``, read by :func:`read_dims`."""
    parser.add_argument("--dims-from", default=None, metavar="FILE",
                        help="keep the body lengths of the same performer fitted before: an "
                             "init.json or result.json of a shot seen in several views (one "
                             "view alone sees the lengths poorly)")


def read_dims(path, template):
    """The body lengths of an init.json or result.json, for ``--dims-from``.

    Raises
    ------
    ZoopraxisError
        An unreadable file, one without a body, or a body of another template.
    """
    from pathlib import Path

    from ..body.body import LENGTH_DIMS
    from ..files.inputs import read_json
    from ..files.plausible import check_body_dims

    path = Path(path)
    data = read_json(path, "file")
    # init.json keeps the body's template and lengths at the top, result.json under "body"
    body = data.get("body", data) if isinstance(data, dict) else None
    if not isinstance(body, dict) or data.get("format") not in ("zoopraxis-init/1",
                                                                "zoopraxis-track/1") \
            or not isinstance(body.get("dims"), dict):
        raise ZoopraxisError(f"{path}: not an init.json or result.json with body dimensions")
    if body.get("template", "full") != template:
        raise ZoopraxisError(f"{path}: dimensions of the '{body.get('template', 'full')}' "
                             f"body, not of '{template}'")
    dims = {name: body["dims"][name] for name in LENGTH_DIMS if name in body["dims"]}
    if not dims:
        raise ZoopraxisError(f"{path}: no body lengths")
    check_body_dims(dims, path)
    return {name: float(value) for name, value in dims.items()}
