"""The options of an initialization from clicked joints, in one object (:class:`InitOptions`):
what the command line, the add-on and the trackers pass to :func:`run.initialize_take`."""

from dataclasses import dataclass

from ..errors import ZoopraxisError
from .flips import FLIP_PARTS, flip_part

# A camera that alone sees an anchor frame, uncalibrated, is taken to look at the upright body
# from about level: its line of sight this many degrees below the body's horizontal, give or
# take the second number (a camera's pitch and the pelvis's own lean together; CMU walks lean
# their pelvis 4-10 degrees). One view cannot see how the pelvis leans towards or away from
# it: without this the fit tilts the whole body by up to 19 degrees in depth to make its
# angles likelier.
CAMERA_TILT_DEG = (0.0, 10.0)


def check_camera_tilt(camera_tilt, what=None):
    """``(down, spread)`` degrees as floats (``initialize``'s ``camera_tilt``).

    Raises
    ------
    ZoopraxisError
        A tilt outside -90..90 degrees or a spread outside 0 (excluded)..90, named by
        ``what`` (default: the values).
    """
    down, spread = (float(x) for x in camera_tilt)
    if not (abs(down) < 90.0 and 0.0 < spread <= 90.0):
        raise ZoopraxisError(f"{what or f'camera tilt {down:g}:{spread:g}'}: the tilt must lie "
                             "between -90 and 90 degrees and the spread between 0 (excluded) "
                             "and 90")
    return down, spread


@dataclass(frozen=True)
class InitOptions:
    """How to fit the body to the clicked joints of a take's anchor frames.

    Attributes
    ----------
    template : str
        Body template (``body.TEMPLATES``).
    flips : dict of int to list of str, optional
        Per anchor frame clicked in one view, the body parts (``FLIP_PARTS``) to turn to their
        other depth (:func:`run.initialize`).
    pose_prior : PosePrior, "default", path or None
        The pose prior of anchor frames clicked in one view: the shipped one, a given one, the
        file of one, or none.
    pose_basis : PoseBasis, "default", path or None
        Uncalibrated, at anchor frames clicked in one view: the basis of captured 3D joint
        sets that gives more starts and joins the choice of the pose (:func:`run.initialize`):
        the shipped one (the default), a given one, the file of one, or none.
    dims : dict, optional
        The performer's body lengths (metres), kept instead of fitted.
    fit_dims : bool
        Without ``dims``: fit the lengths to the clicks (default), or keep the template's.
    camera_tilt : (float, float) or None
        Uncalibrated, in frames clicked in one view: how far (degrees) the camera looks down
        at the subject, give or take how much (``CAMERA_TILT_DEG``); None: no such prior.
        Calibrated views ignore it.
    perspective : bool
        Uncalibrated: fit each view's perspective (views near the body).
    proportions : proportions.ProportionsPrior, optional
        The performers' proportions the fitted lengths lean on, instead of the shipped prior
        (:func:`run.initialize`).

    Raises
    ------
    ZoopraxisError
        A camera tilt out of range or a flip of an unknown body part.
    """

    template: str = "full"
    flips: dict = None
    pose_prior: object = "default"
    pose_basis: object = "default"
    dims: dict = None
    fit_dims: bool = True
    camera_tilt: tuple = CAMERA_TILT_DEG
    perspective: bool = False
    proportions: object = None

    def __post_init__(self):
        if self.camera_tilt is not None:
            object.__setattr__(self, "camera_tilt", check_camera_tilt(self.camera_tilt))
        for frame, parts in (self.flips or {}).items():
            for part in ([parts] if isinstance(parts, str) else parts):
                if flip_part(part) is None:
                    raise ZoopraxisError(f"depth flip at frame {frame}: unknown body part "
                                         f"'{part}' (one of: {', '.join(FLIP_PARTS)})")

    @property
    def fits_dims(self):
        """Whether the lengths are fitted: ``fit_dims`` and no ``dims`` given."""
        return bool(self.fit_dims and not self.dims)
