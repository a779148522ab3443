"""Inputs that are well formed but cannot be right: refused (or warned about) by name."""

import json
import os
from pathlib import Path

import cv2
import numpy as np
import pytest

from zoopraxis import cli
from zoopraxis.core.files import calibfile, markers, plausible
from zoopraxis.core.imaging import plates
from zoopraxis.core.body.body import DEFAULT_DIMS
from zoopraxis.core.errors import ZoopraxisError

SAMPLE = Path(cli.__file__).parent / "samples" / "walk3"
VIEWS = ["cam0", "cam1", "cam2"]


@pytest.fixture(scope="module")
def take():
    return (json.loads((SAMPLE / "calibration.json").read_text()),
            markers.read_markers(SAMPLE / "markers.json"))


def cameras_of(data, tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    return calibfile.check_views(calibfile.read_calibration(path), VIEWS, path)


def changed(data, change):
    data = json.loads(json.dumps(data))
    change(data["cameras"])
    return data


def _millimetres(cams):
    for c in cams:
        c["t"] = [1000 * v for v in c["t"]]


def _swapped(cams):
    cams[0]["name"], cams[1]["name"] = cams[1]["name"], cams[0]["name"]


def _turned_away(cams):
    flip = np.diag([-1.0, 1.0, -1.0])          # same centre, looking the other way
    cams[2]["R"] = (flip @ np.array(cams[2]["R"])).tolist()
    cams[2]["t"] = (flip @ np.array(cams[2]["t"])).tolist()


def _wild_lens(cams):
    cams[1]["dist"] = [50.0, 0, 0, 0, 0]


def test_the_right_calibration_explains_the_clicks(take, tmp_path):
    data, anchors = take
    assert plausible.check_calibration(cameras_of(data, tmp_path), anchors, "cal.json") == []


@pytest.mark.parametrize("change, message", [
    (_millimetres, "triangulate to a body 1.3e\\+03 m across .* in metres"),
    (_swapped, "cannot explain the clicks: reprojection RMS 'cam\\d' \\d+ px"),
    (_turned_away, "camera 'cam2' has the subject behind it"),
    (_wild_lens, "reprojection RMS 'cam1' \\d+ px"),
])
def test_a_calibration_that_cannot_explain_the_clicks_is_refused(take, tmp_path, change,
                                                                  message):
    data, anchors = take
    cameras = cameras_of(changed(data, change), tmp_path)
    with pytest.raises(ZoopraxisError, match="cal.json: .*" + message):
        plausible.check_calibration(cameras, anchors, "cal.json")


def test_a_poor_camera_is_warned_about(take, tmp_path):
    data, anchors = take
    nudged = changed(data, lambda cams: cams[0].update(t=[cams[0]["t"][0] + 0.2,
                                                           *cams[0]["t"][1:]]))
    warnings = plausible.check_calibration(cameras_of(nudged, tmp_path), anchors, "cal.json")
    assert any("camera 'cam0' explains the clicks poorly" in w for w in warnings), warnings


def test_body_lengths_outside_human_range(tmp_path):
    plausible.check_body_dims(dict(DEFAULT_DIMS), "init.json")
    plausible.check_body_dims({"thigh": 0.30, "forearm": 0.20}, "init.json")
    # a shoulder drop is where the shoulders were clicked: near zero is a body too
    plausible.check_body_dims({"shoulder_drop": 0.005, "ankle_height": 0.01}, "init.json")
    for name, value, message in (("thigh", 50.0, "'thigh' of 50 m is outside the human range"),
                                 ("shank", 0.001, "'shank' of 0.001 m"),
                                 ("shoulder_drop", 50.0, "'shoulder_drop' of 50 m"),
                                 ("torso", float("nan"), "'torso' is not a number"),
                                 ("torso", 10 ** 400, "'torso' is not a number")):
        with pytest.raises(ZoopraxisError, match="init.json: body length " + message):
            plausible.check_body_dims({name: value}, "init.json")


def test_dims_from_a_50_m_thigh_is_refused(tmp_path, capsys):
    data = {"format": "zoopraxis-init/1", "template": "full",
            "dims": dict(DEFAULT_DIMS, thigh=50.0)}
    path = tmp_path / "init.json"
    path.write_text(json.dumps(data))
    plate = [a for v in VIEWS for a in ("--plate", f"{v}={SAMPLE / v}")]
    assert cli.main(["init"] + plate + ["--markers", str(SAMPLE / "markers.json"),
                                        "--dims-from", str(path),
                                        "--out", str(tmp_path / "i.json")]) == 2
    assert "body length 'thigh' of 50 m is outside the human range" in capsys.readouterr().err


def test_plates_of_different_frame_rates(tmp_path):
    plausible.check_frame_rates({"a": 30.0, "b": 29.97, "c": None})
    with pytest.raises(ZoopraxisError, match="plates 'a' \\(30 fps\\) and 'b' \\(25 fps\\)"):
        plausible.check_frame_rates({"a": 30.0, "b": 25.0})


def test_videos_of_different_frame_rates_are_refused_by_track(tmp_path, capsys):
    args = ["track"]
    for view, fps in (("cam0", 30), ("cam1", 25)):
        path = tmp_path / f"{view}.avi"
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (64, 48))
        for _ in range(3):
            writer.write(np.zeros((48, 64, 3), np.uint8))
        writer.release()
        args += ["--plate", f"{view}={path}"]
    args += ["--markers", str(SAMPLE / "markers.json"), "--out", str(tmp_path / "r.json")]
    assert cli.main(args) == 2
    assert "run at different frame rates" in capsys.readouterr().err


def test_working_size_too_small_to_track(take):
    _, anchors = take
    sizes = {v: (480, 360) for v in VIEWS}
    assert plausible.check_working_size(anchors, sizes, 960) == []
    with pytest.raises(ZoopraxisError, match="--max-size 0: give at least 32"):
        plausible.check_working_size(anchors, sizes, 0)
    with pytest.raises(ZoopraxisError, match="--max-size 40: the person is only \\d+ px tall "
                                             "in view 'cam\\d'.*give --max-size \\d+ or more"):
        plausible.check_working_size(anchors, sizes, 40)
    needed = int(str(pytest.raises(ZoopraxisError, plausible.check_working_size, anchors,
                                   sizes, 40).value).split("give --max-size ")[1].split()[0])
    plausible.check_working_size(anchors, sizes, needed)        # the size it asks for does


def test_named_pipe_and_device_plates_are_refused_without_opening(tmp_path):
    pipe = tmp_path / "cam0.mp4"
    os.mkfifo(pipe)
    for path in (pipe, Path("/dev/zero")):
        with pytest.raises(ZoopraxisError, match="is not a regular file or folder"):
            plates.open_plate(path)


def test_a_jpeg_cut_short_is_named(tmp_path):
    folder = tmp_path / "cam1"
    folder.mkdir()
    for f in sorted((SAMPLE / "cam1").iterdir())[:3]:
        (folder / f.name).write_bytes(f.read_bytes())
    cut = sorted(folder.iterdir())[1]
    data = cut.read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    with pytest.raises(ZoopraxisError, match=f"image .*{cut.name} \\(frame 1\\) is cut off"):
        plates.open_plate(folder)
    cut.write_bytes(b"")
    with pytest.raises(ZoopraxisError, match=f"image .*{cut.name} \\(frame 1\\) is empty"):
        plates.open_plate(folder)


def test_uncalibrated_view_without_clicks_is_left_out(take):
    _, anchors = take
    hidden = markers.only_views(anchors, ["cam0", "cam2"])
    hidden[0].views["cam1"] = dict(list(anchors[0].views["cam1"].items())[:3])
    kept, warnings = markers.uncalibrated_views(hidden, VIEWS, "m.json")
    assert kept == ["cam0", "cam2"]
    assert warnings == ["m.json: frame 0: view 'cam1' has 3 joints clicked (an uncalibrated "
                        "view needs 4); it is left out of the track"]
    later = markers.only_views(anchors, VIEWS)
    later[-1].views["cam2"] = {}
    with pytest.raises(ZoopraxisError, match=f"frame {later[-1].frame}: view 'cam2' has 0 "
                                             "joints clicked"):
        markers.uncalibrated_views(later, VIEWS, "m.json")


def test_uncalibrated_track_with_a_hidden_view(tmp_path, capsys):
    data = json.loads((SAMPLE / "markers.json").read_text())
    data["anchors"][0]["views"].pop("cam1")
    path = tmp_path / "m.json"
    path.write_text(json.dumps(data))
    plate = [a for v in VIEWS for a in ("--plate", f"{v}={SAMPLE / v}")]
    out = tmp_path / "r.json"
    assert cli.main(["track"] + plate + ["--markers", str(path), "--frames", "0:2",
                                         "--workers", "1", "--out", str(out)]) == 0
    assert "view 'cam1' has 0 joints clicked" in capsys.readouterr().out
    assert sorted(json.loads(out.read_text())["views"]) == ["cam0", "cam2"]


def test_initialization_warns_about_a_view_it_cannot_fit(take, tmp_path):
    from zoopraxis.core.initialize.run import initialize

    data, anchors = take
    cameras = cameras_of(changed(data, _wild_lens), tmp_path)
    result = initialize(anchors[:1], cameras, views=VIEWS, pose_prior=None)
    assert any(w.startswith("view 'cam1': the fitted body misses the clicks by")
               for w in result.warnings), result.warnings
    good = initialize(anchors[:1], cameras_of(data, tmp_path), views=VIEWS, pose_prior=None)
    assert not any("misses the clicks" in w for w in good.warnings)
