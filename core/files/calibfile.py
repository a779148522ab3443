"""Reading and writing camera calibration files: calibration.json, and Pose2Sim / anipose TOML.

calibration.json (DESIGN's format) holds ``{"cameras": [{"name", "image_size", "K", "dist", "R",
"t"}, ...]}``; an entry with ``"model": "scaled_orthographic"`` holds a ``ScaledOrthoCamera``
instead. The TOML files written by Pose2Sim and anipose hold one table per camera::

    [cam_01]
    name = "cam_01"
    size = [ 1920.0, 1080.0,]
    matrix = [ [ 1500.0, 0.0, 959.5,], [ 0.0, 1500.0, 539.5,], [ 0.0, 0.0, 1.0,],]
    distortions = [ -0.2, 0.05, 0.001, 0.001,]
    rotation = [ 0.1, -1.2, 0.3,]
    translation = [ 0.5, 0.2, 4.0,]
    fisheye = false

    [metadata]
    adjusted = false

Convention:
    Both formats store OpenCV cameras: ``X_cam = R @ X_world + t``, OpenCV camera axes and pixels.
    TOML ``rotation`` is a Rodrigues (axis-angle) vector of that same R. Translations are read as
    metres; a calibration made in millimetres must be rescaled before use.
"""

import json
import tomllib
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..geometry.camera import PinholeCamera
from ..geometry.ortho import ScaledOrthoCamera
from ..errors import ZoopraxisError
from .inputs import check_regular_file, read_json
from .outputs import write_text

FORMATS = {".json": "calibration.json", ".toml": "Pose2Sim / anipose TOML"}

# Keys of a Pose2Sim / anipose camera table that are required.
TOML_KEYS = ("size", "matrix", "distortions", "rotation", "translation")


# A video encoder codes whole blocks of this many pixels, and some tools record that coded size
# as the image's (Pose2Sim's demo: 1088 rows for 1080-row videos). The rows or columns past the
# decoded plate's are padding at the bottom or right, so the calibration holds for the plate.
CODED_BLOCK = 16

# The camera models a calibration.json entry may name in its "model" key.
CAMERA_MODELS = {cls.model: cls for cls in (PinholeCamera, ScaledOrthoCamera)}


def camera_from_dict(entry, source=None):
    """Make a camera of either model from a calibration.json entry.

    Parameters
    ----------
    entry : dict
        A pinhole entry (DESIGN's format, no ``"model"`` key or ``"model": "pinhole"``) or a
        scaled orthographic one (``"model": "scaled_orthographic"``).
    source : str, optional
        The file the entry comes from, named in error messages.

    Returns
    -------
    camera : PinholeCamera or ScaledOrthoCamera
    """
    model = entry.get("model", "pinhole") if isinstance(entry, dict) else "pinhole"
    if model not in CAMERA_MODELS:
        prefix = f"{source}: " if source else ""
        raise ZoopraxisError(f"{prefix}camera '{entry.get('name')}': unknown model {model!r} "
                             f"(expected one of {', '.join(CAMERA_MODELS)})")
    return CAMERA_MODELS[model].from_dict(entry, source)


def read_calibration(path):
    """Read the cameras of a calibration file, chosen by its extension (.json or .toml).

    Parameters
    ----------
    path : str or Path
        A calibration.json file (DESIGN's format) or a Pose2Sim / anipose TOML file.

    Returns
    -------
    cameras : dict of str to PinholeCamera or ScaledOrthoCamera
        Cameras by name, in file order.

    Raises
    ------
    ZoopraxisError
        If the file is missing, unreadable, malformed (naming the line), has an unknown extension,
        misses a required key (naming the key and the camera), holds an invalid camera, a fisheye
        camera, or two cameras with one name.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in FORMATS:
        accepted = ", ".join(f"{ext} ({what})" for ext, what in FORMATS.items())
        raise ZoopraxisError(
            f"{path}: unknown calibration format '{path.suffix}' (accepted: {accepted})")
    if suffix == ".json":
        cameras = _read_json(read_json(path, "calibration file"), path)
    else:
        check_regular_file(path, "calibration file")
        try:
            text = path.read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as error:
            raise ZoopraxisError(f"{path}: cannot read calibration file ({error})") from None
        cameras = _read_toml(text, path)
    if not cameras:
        raise ZoopraxisError(f"{path}: no cameras in calibration file")
    by_name = {}
    for camera in cameras:
        if camera.name in by_name:
            raise ZoopraxisError(f"{path}: two cameras are named '{camera.name}'")
        by_name[camera.name] = camera
    return by_name


def _read_json(data, path):
    if not isinstance(data, dict):
        raise ZoopraxisError(f"{path}: expected a JSON object with key 'cameras'")
    if "cameras" not in data:
        raise ZoopraxisError(f"{path}: missing key 'cameras'")
    entries = data["cameras"]
    if not isinstance(entries, list):
        raise ZoopraxisError(f"{path}: 'cameras' must be a list of camera objects")
    return [camera_from_dict(entry, str(path)) for entry in entries]


def _read_toml(text, path):
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        # tomllib's message already ends with "(at line L, column C)".
        raise ZoopraxisError(f"{path}: malformed TOML: {error}") from None
    except RecursionError:
        raise ZoopraxisError(f"{path}: malformed TOML: nested too deep") from None
    cameras = []
    for table_name, table in data.items():
        if table_name == "metadata" or not isinstance(table, dict):
            continue
        cameras.append(_camera_from_toml_table(table_name, table, path))
    return cameras


def _camera_from_toml_table(table_name, table, path):
    name = table.get("name", table_name)
    if not isinstance(name, str) or not name:
        raise ZoopraxisError(f"{path}: [{table_name}]: 'name' must be a non-empty string")
    where = f"{path}: camera '{name}'"
    for key in TOML_KEYS:
        if key not in table:
            raise ZoopraxisError(f"{where}: missing key '{key}'")
    if table.get("fisheye", False):
        raise ZoopraxisError(
            f"{where}: fisheye cameras are not supported (fisheye = true); calibrate with the "
            "pinhole model")
    try:
        rotvec = np.array(table["rotation"], dtype=np.float64)
    except (TypeError, ValueError):
        rotvec = None
    if rotvec is None or rotvec.shape != (3,) or not np.all(np.isfinite(rotvec)):
        raise ZoopraxisError(
            f"{where}: rotation must be a Rodrigues vector of 3 numbers, got {table['rotation']!r}")
    R = Rotation.from_rotvec(rotvec).as_matrix()
    try:
        return PinholeCamera(name, table["size"], table["matrix"], table["distortions"], R,
                             table["translation"])
    except ZoopraxisError as error:
        raise ZoopraxisError(f"{path}: {error}") from None


def write_calibration(path, cameras, *, force=False):
    """Write cameras to a calibration.json file (DESIGN's format).

    Parameters
    ----------
    path : str or Path
        Output file; must end in .json.
    cameras : dict of str to camera, or iterable of cameras
        PinholeCamera or ScaledOrthoCamera; written in the given order. A dict's keys must
        equal the cameras' names.
    force : bool
        Overwrite an existing file.

    Raises
    ------
    ZoopraxisError
        If the file exists and not ``force``, the extension is not .json, names are duplicated or
        disagree with the dict keys, or the file cannot be written.
    """
    path = Path(path)
    if path.suffix.lower() != ".json":
        raise ZoopraxisError(f"{path}: calibration is written as JSON; use a .json file name")
    if isinstance(cameras, dict):
        for key, camera in cameras.items():
            if key != camera.name:
                raise ZoopraxisError(
                    f"{path}: camera '{camera.name}' is stored under the key '{key}'")
        cameras = list(cameras.values())
    else:
        cameras = list(cameras)
    names = [camera.name for camera in cameras]
    duplicates = sorted({name for name in names if names.count(name) > 1})
    if duplicates:
        raise ZoopraxisError(f"{path}: two cameras are named '{duplicates[0]}'")
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: already exists; pass force to overwrite it")
    text = json.dumps({"cameras": [camera.to_dict() for camera in cameras]}, indent=2)
    write_text(path, text + "\n")


def check_views(cameras, view_names, path):
    """Check that every plate view has a camera in the calibration.

    Parameters
    ----------
    cameras : dict of str to camera
        As returned by ``read_calibration``.
    view_names : iterable of str
        The view names of the plates (``--plate NAME=PATH``).
    path : str or Path
        The calibration file, named in the error.

    Returns
    -------
    cameras : dict of str to camera
        The cameras of the views, in the order of ``view_names``; other cameras are left out.

    Raises
    ------
    ZoopraxisError
        Naming the views without a camera, the file and the cameras it has.
    """
    view_names = list(view_names)
    missing = [name for name in view_names if name not in cameras]
    if missing:
        views = ", ".join(f"'{name}'" for name in missing)
        known = ", ".join(cameras) or "none"
        raise ZoopraxisError(f"{path}: no camera for view{'s' if len(missing) > 1 else ''} "
                             f"{views} (cameras in the file: {known})")
    return {name: cameras[name] for name in view_names}


def camera_for_plate(camera, plate_size, path):
    """The camera of a view for its plate's size, and what was done to it (None: nothing).

    A calibration made at another size still holds where the plate is the calibrated image
    scaled (a proxy or an export at half size: the camera is scaled, pixel corners with the
    image, as ``cv2.resize``) or where the two differ by a video encoder's padding (one size
    the other rounded up to a multiple of CODED_BLOCK: the camera is kept as it is).

    Raises
    ------
    ZoopraxisError
        Any other size, naming the file, the camera and both sizes.
    """
    cw, ch = (int(x) for x in camera.image_size)
    pw, ph = (int(x) for x in plate_size)
    if (cw, ch) == (pw, ph):
        return camera, None
    said = f"{path}: camera '{camera.name}' is {cw}x{ch} but its plate is {pw}x{ph}"

    def padded(c, p):
        return c == p or (abs(c - p) < CODED_BLOCK and max(c, p) % CODED_BLOCK == 0)

    if padded(cw, pw) and padded(ch, ph):
        return camera.replace(image_size=(pw, ph)), \
            f"{said}: the difference taken for a video encoder's padding, the camera kept"
    factor = pw / cw
    if isinstance(camera, PinholeCamera) and round(cw * factor) == pw and \
            abs(ch * factor - ph) <= 0.5:
        return camera.scaled(factor, "resize"), \
            f"{said}: the plate taken for the calibrated image scaled by {factor:.4g}"
    raise ZoopraxisError(f"{said} (neither the calibrated image scaled nor a video encoder's "
                         "padding of it)")


def cameras_for_plates(cameras, plate_sizes, path):
    """:func:`camera_for_plate` for every view of ``plate_sizes`` (view name to (w, h)) that
    has a camera; returns the cameras (the others unchanged) and the notes, one line each."""
    out, notes = dict(cameras), []
    for name, size in plate_sizes.items():
        if name in out:
            out[name], note = camera_for_plate(out[name], size, path)
            if note:
                notes.append(note)
    return out, notes
