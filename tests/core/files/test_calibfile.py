"""Tests of core.calibfile: calibration.json and Pose2Sim / anipose TOML."""

import json
import re

import cv2
import numpy as np
import pytest

from zoopraxis.core.files.calibfile import (camera_for_plate, camera_from_dict,
                                             cameras_for_plates, check_views,
                                             read_calibration, write_calibration)
from zoopraxis.core.geometry.camera import PinholeCamera, look_at
from zoopraxis.core.geometry.ortho import ScaledOrthoCamera
from zoopraxis.core.errors import ZoopraxisError

LENS = [-0.2, 0.05, 1e-3, 1e-3, 0.0]

POSE2SIM_TOML = """\
[cam_01]
name = "cam_01"
size = [ 1920.0, 1080.0,]
matrix = [ [ 1500.0, 0.0, 959.5,], [ 0.0, 1490.0, 539.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.2, 0.05, 0.001, 0.001,]
rotation = [ 0.1, -1.2, 0.3,]
translation = [ 0.5, 0.2, 4.0,]
fisheye = false

[side]
size = [ 640, 480,]
matrix = [ [ 600.0, 0.0, 319.5,], [ 0.0, 600.0, 239.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.01, 0.0, 0.0, 0.0, -0.003,]
rotation = [ 1.5, 0.2, -0.4,]
translation = [ -1.0, 0.3, 5.0,]
fisheye = false

[metadata]
adjusted = false
error = 0.0
"""


def make_cameras():
    R, t = look_at([4.0, -3.0, 1.8], [0.0, 0.0, 1.0])
    K = [[800.0, 0.0, 320.5], [0.0, 805.0, 238.0], [0.0, 0.0, 1.0]]
    return [PinholeCamera("zeta", (640, 480), K, LENS, R, t),
            PinholeCamera("alpha", (640, 480), K, None, *look_at([-3.0, 3.0, 2.0], [0, 0, 1])),
            ScaledOrthoCamera("muybridge", (400, 300), 80.0, R, t)]


def write_json(path, data):
    path.write_text(json.dumps(data), encoding="utf-8")
    return path


# --- smoke and round trips ------------------------------------------------------------------------

def test_json_round_trip_keeps_cameras_and_file_order(tmp_path):
    cameras = make_cameras()
    path = tmp_path / "calibration.json"
    write_calibration(path, cameras)
    back = read_calibration(path)
    assert list(back) == ["zeta", "alpha", "muybridge"]
    for original in cameras:
        read = back[original.name]
        assert type(read) is type(original) and read.image_size == original.image_size
        for field in ("K", "dist", "R", "t", "s", "c"):
            if hasattr(original, field):
                np.testing.assert_array_equal(getattr(read, field), getattr(original, field))


def test_write_accepts_a_dict_of_cameras(tmp_path):
    cameras = {camera.name: camera for camera in make_cameras()}
    path = tmp_path / "calibration.json"
    write_calibration(path, cameras)
    assert list(read_calibration(path)) == list(cameras)


def test_json_unknown_keys_are_ignored(tmp_path):
    entry = make_cameras()[0].to_dict()
    entry["serial"] = "A123"
    path = write_json(tmp_path / "calib.json", {"cameras": [entry], "date": "2024-05-01"})
    np.testing.assert_array_equal(read_calibration(path)["zeta"].K, entry["K"])


def test_toml_reads_pose2sim_cameras(tmp_path):
    path = tmp_path / "Calib_board.toml"
    path.write_text(POSE2SIM_TOML, encoding="utf-8")
    cameras = read_calibration(path)
    assert list(cameras) == ["cam_01", "side"]
    first, side = cameras["cam_01"], cameras["side"]
    assert first.image_size == (1920, 1080) and side.image_size == (640, 480)
    np.testing.assert_array_equal(first.K, [[1500.0, 0, 959.5], [0, 1490.0, 539.5], [0, 0, 1]])
    np.testing.assert_array_equal(first.dist, [-0.2, 0.05, 0.001, 0.001, 0.0])
    np.testing.assert_array_equal(side.dist, [0.01, 0.0, 0.0, 0.0, -0.003])
    np.testing.assert_allclose(first.R, cv2.Rodrigues(np.array([0.1, -1.2, 0.3]))[0], atol=1e-12)
    np.testing.assert_allclose(side.R, cv2.Rodrigues(np.array([1.5, 0.2, -0.4]))[0], atol=1e-12)
    np.testing.assert_array_equal(side.t, [-1.0, 0.3, 5.0])


def test_check_views_returns_the_plate_cameras_in_view_order(tmp_path):
    cameras = {camera.name: camera for camera in make_cameras()}
    views = check_views(cameras, ["muybridge", "zeta"], tmp_path / "calibration.json")
    assert list(views) == ["muybridge", "zeta"]
    assert views["zeta"] is cameras["zeta"]


# --- bad input ------------------------------------------------------------------------------------

def test_write_refuses_to_overwrite_unless_forced(tmp_path):
    path = tmp_path / "calibration.json"
    path.write_text("keep me", encoding="utf-8")
    with pytest.raises(ZoopraxisError, match=r"calibration\.json: already exists; pass force"):
        write_calibration(path, make_cameras())
    assert path.read_text(encoding="utf-8") == "keep me"
    write_calibration(path, make_cameras(), force=True)
    assert list(read_calibration(path)) == ["zeta", "alpha", "muybridge"]


@pytest.mark.parametrize("name, cameras, message", [
    ("calibration.toml", None, r"calibration\.toml: calibration is written as JSON"),
    ("c.json", "duplicate", r"c\.json: two cameras are named 'zeta'"),
    ("c.json", "misfiled", r"c\.json: camera 'zeta' is stored under the key 'cam0'"),
])
def test_write_bad_input(tmp_path, name, cameras, message):
    zeta = make_cameras()[0]
    cameras = {None: make_cameras(), "duplicate": [zeta, zeta], "misfiled": {"cam0": zeta}}[cameras]
    with pytest.raises(ZoopraxisError, match=message):
        write_calibration(tmp_path / name, cameras)
    assert not (tmp_path / name).exists()


def json_entry(**changes):
    entry = make_cameras()[0].to_dict()
    entry.update(changes)
    return entry


@pytest.mark.parametrize("data, message", [
    ({"cams": []}, r"calib\.json: missing key 'cameras'"),
    ([1, 2], r"calib\.json: expected a JSON object with key 'cameras'"),
    ({"cameras": {"zeta": {}}}, r"calib\.json: 'cameras' must be a list"),
    ({"cameras": []}, r"calib\.json: no cameras in calibration file"),
    ({"cameras": [{k: v for k, v in json_entry().items() if k != "dist"}]},
     r"calib\.json: camera 'zeta': missing key 'dist'"),
    ({"cameras": [json_entry(), json_entry()]}, r"calib\.json: two cameras are named 'zeta'"),
    ({"cameras": [json_entry(R=(2 * np.eye(3)).tolist())]},
     r"calib\.json: camera 'zeta': R is not a rotation"),
    ({"cameras": [json_entry(dist=[0.1, 0.2])]},
     r"calib\.json: camera 'zeta': dist must have 4 or 5 coefficients"),
])
def test_json_bad_content(tmp_path, data, message):
    path = write_json(tmp_path / "calib.json", data)
    with pytest.raises(ZoopraxisError, match=message):
        read_calibration(path)


def test_malformed_json_names_file_and_line(tmp_path):
    path = tmp_path / "calib.json"
    path.write_text('{"cameras": [\n  {"name": "cam0",\n   "K": [1, 2,,]}\n]}', encoding="utf-8")
    with pytest.raises(ZoopraxisError, match=r"calib\.json: not valid JSON \(.* at line 3,"):
        read_calibration(path)


def test_unknown_extension_lists_accepted_ones(tmp_path):
    path = tmp_path / "calib.yaml"
    path.write_text("cameras: []", encoding="utf-8")
    with pytest.raises(ZoopraxisError, match=re.escape(
            "calib.yaml: unknown calibration format '.yaml' (accepted: .json")) as error:
        read_calibration(path)
    assert ".toml" in str(error.value)


def test_missing_file(tmp_path):
    with pytest.raises(ZoopraxisError, match=r"nowhere\.json: no such calibration file"):
        read_calibration(tmp_path / "nowhere.json")


def toml_with(old, new):
    assert old in POSE2SIM_TOML
    return POSE2SIM_TOML.replace(old, new, 1)


@pytest.mark.parametrize("text, message", [
    (toml_with("fisheye = false", "fisheye = true"),
     r"calib\.toml: camera 'cam_01': fisheye cameras are not supported"),
    (toml_with("matrix = [ [ 600.0", "matrix_ = [ [ 600.0"),
     r"calib\.toml: camera 'side': missing key 'matrix'"),
    (toml_with("rotation = [ 0.1, -1.2, 0.3,]", "rotation = [[1, 0], [0, 1]]"),
     r"calib\.toml: camera 'cam_01': rotation must be a Rodrigues vector"),
    (toml_with("distortions = [ -0.2, 0.05, 0.001, 0.001,]", "distortions = [ -0.2, 0.05,]"),
     r"calib\.toml: camera 'cam_01': dist must have 4 or 5 coefficients"),
    (toml_with("size = [ 640, 480,]", "size = [ 640, -480,]"),
     r"calib\.toml: camera 'side': image_size must be two positive whole numbers"),
    (toml_with('name = "cam_01"', 'name = "side"'), r"calib\.toml: two cameras are named 'side'"),
    (toml_with("translation = [ 0.5", "translation = [ 0.5 0.1"),
     r"calib\.toml: malformed TOML: .*line 7"),
    ("[metadata]\nadjusted = false\n", r"calib\.toml: no cameras in calibration file"),
])
def test_toml_bad_content(tmp_path, text, message):
    path = tmp_path / "calib.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ZoopraxisError, match=message):
        read_calibration(path)


def test_check_views_names_the_missing_views_and_file():
    cameras = {camera.name: camera for camera in make_cameras()}
    with pytest.raises(ZoopraxisError, match=re.escape(
            "calibration.json: no camera for view 'cam9' (cameras in the file: zeta, alpha, "
            "muybridge)")):
        check_views(cameras, ["zeta", "cam9"], "calibration.json")
    with pytest.raises(ZoopraxisError, match=r"no camera for views 'cam8', 'cam9'"):
        check_views(cameras, ["cam8", "cam9"], "calibration.json")


K_OK = [[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]]


@pytest.mark.parametrize("entry, message", [
    ({"name": "cam3", "image_size": [64, 48], "dist": [0] * 5, "R": np.eye(3).tolist(),
      "t": [0, 0, 0]}, r"calib\.json: camera 'cam3': missing key 'K'"),
    ({"image_size": [64, 48]}, r"calib\.json: a camera without a name: missing key 'name'"),
    ({"model": "fisheye", "name": "f"}, r"calib\.json: camera 'f': unknown model 'fisheye'"),
    ({"model": "scaled_orthographic", "name": "o", "image_size": [64, 48], "R": np.eye(3).tolist(),
      "t": [0, 0, 0]}, r"calib\.json: camera 'o': missing key 's'"),
    ("cam0", r"calib\.json: a camera entry must be an object"),
    ({"name": "cam3", "image_size": [64, 48], "K": K_OK, "dist": [0] * 5, "R": np.eye(3).tolist(),
      "t": [0, 0]}, r"calib\.json: camera 'cam3': t must have shape \(3,\)"),
])
def test_camera_from_dict_bad_input(entry, message):
    with pytest.raises(ZoopraxisError, match=message):
        camera_from_dict(entry, "calib.json")


def _hd_camera(size=(1920, 1080)):
    R, t = look_at([0.3, -4.0, 1.5], [0.0, 0.0, 1.0])
    w, h = size
    return PinholeCamera("cam0", size, [[1500.0, 0, (w - 1) / 2 + 7], [0, 1490.0, (h - 1) / 2 - 5],
                                        [0, 0, 1]], LENS, R, t)


def test_a_plate_at_another_scale_gets_the_calibration_scaled():
    """A plate exported at half the calibrated size (a proxy): the camera for it projects
    every point where the calibrated one does, scaled with the image's pixel corners."""
    camera = _hd_camera()
    X = np.random.default_rng(0).normal([0, 0, 1], 0.5, (20, 3))
    half, note = camera_for_plate(camera, (960, 540), "calib.toml")
    assert tuple(half.image_size) == (960, 540)
    assert np.allclose(half.project(X), (camera.project(X) + 0.5) * 0.5 - 0.5, atol=1e-9)
    assert "calib.toml: camera 'cam0' is 1920x1080 but its plate is 960x540" in note
    assert "scaled by 0.5" in note
    same, none = camera_for_plate(camera, (1920, 1080), "calib.toml")
    assert same is camera and none is None


def test_a_video_encoders_padding_keeps_the_camera():
    """Pose2Sim's demo calibrates 1088x1920 for videos that decode at 1080x1920: the rows past
    the plate's are the encoder's padding at the bottom, the camera holds as it is."""
    camera = _hd_camera((1088, 1920))
    plate, note = camera_for_plate(camera, (1080, 1920), "Calib.toml")
    assert tuple(plate.image_size) == (1080, 1920)
    assert np.array_equal(plate.K, camera.K) and np.array_equal(plate.R, camera.R)
    assert "padding" in note and "1088x1920 but its plate is 1080x1920" in note


@pytest.mark.parametrize("plate", [(1280, 1024), (1920, 1000), (1900, 1080), (1080, 1920)])
def test_a_plate_of_another_shape_is_refused_naming_both_sizes(plate):
    with pytest.raises(ZoopraxisError, match=re.escape(
            f"calib.json: camera 'cam0' is 1920x1080 but its plate is {plate[0]}x{plate[1]}")):
        camera_for_plate(_hd_camera(), plate, "calib.json")


def test_cameras_for_plates_leaves_views_without_a_plate_alone():
    cameras = {"cam0": _hd_camera(), "cam1": _hd_camera().replace(name="cam1")}
    out, notes = cameras_for_plates(cameras, {"cam0": (960, 540)}, "c.json")
    assert tuple(out["cam0"].image_size) == (960, 540) and out["cam1"] is cameras["cam1"]
    assert len(notes) == 1 and "cam0" in notes[0]
