"""Camera calibration from a board seen in the plates: detection, intrinsics, extrinsics,
refusals and the ``calibrate`` command, on synthetic board images with known cameras."""

import json

import cv2
import numpy as np
import pytest

from zoopraxis import cli
from zoopraxis.core.calibration import calibrate as cal
from zoopraxis.core.geometry import se3
from zoopraxis.core.geometry.camera import PinholeCamera, look_at
from zoopraxis.core.errors import ZoopraxisError

BOARD = "checkerboard:9x6:0.1"


def true_cameras():
    """Three cameras 120 degrees apart looking down at the floor, each with its own lens."""
    cams = []
    for i, azimuth in enumerate(np.radians([20.0, 140.0, 260.0])):
        R, t = look_at([2.2 * np.cos(azimuth), 2.2 * np.sin(azimuth), 1.9], [0.0, 0.0, 0.4])
        f = 820.0 + 20 * i
        K = [[f, 0.0, 319.5 + 5 * i], [0.0, f, 239.5 - 3 * i], [0.0, 0.0, 1.0]]
        cams.append(PinholeCamera(f"cam{i}", (640, 480), K,
                                  [-0.12 + 0.02 * i, 0.05, 0.001, -0.001, 0.0], R, t))
    return cams


def board_poses(board, rng, n=13):
    """Frame 0: the board on the floor at the world origin; then tilted and lifted."""
    half = board.object_points().max(axis=0) / 2
    poses = {0: se3.transform(cal.WORLD_FROM_BOARD)}
    for f in range(1, n):
        axis = np.append(rng.normal(size=2), 0.0)
        axis /= np.linalg.norm(axis)
        R = se3.exp_so3([0.0, 0.0, rng.uniform(-np.pi, np.pi)]) \
            @ se3.exp_so3(axis * np.radians(rng.uniform(15, 40))) @ cal.WORLD_FROM_BOARD
        centre = [rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), rng.uniform(0.2, 0.7)]
        poses[f] = se3.transform(R, centre - R @ half)
    return poses


@pytest.fixture(scope="module")
def scene():
    """Rendered board images (blur and noise) of every camera and frame, and detections."""
    rng = np.random.default_rng(2345)
    board = cal.parse_board(BOARD)
    cams = true_cameras()
    poses = board_poses(board, rng)
    images = {c.name: {f: cal.render_board(c, T, board, blur=0.7, noise=2.0, rng=rng)
                       for f, T in poses.items()} for c in cams}
    detections = {c.name: {} for c in cams}
    for c in cams:
        for f, image in images[c.name].items():
            found = cal.detect_board(image, board)
            if found is not None:
                detections[c.name][f] = found
    return board, cams, poses, images, detections


def sizes(cams):
    return {c.name: c.image_size for c in cams}


# -- boards ------------------------------------------------------------------------------------

def test_parse_board():
    board = cal.parse_board("checkerboard:9x6:0.04")
    assert (board.kind, board.cols, board.rows, board.square) == ("checkerboard", 9, 6, 0.04)
    assert board.object_points().shape == (54, 3)
    assert np.allclose(board.object_points()[10], [0.04, 0.04, 0.0])
    charuco = cal.parse_board("charuco:7x5:0.04:0.03:4x4_50")
    assert charuco.n_corners == 24 and charuco.dictionary == "4X4_50"
    assert np.allclose(charuco.object_points()[0], 0.0)


@pytest.mark.parametrize("text, message", [
    ("chess:9x6:0.04", "--board must be checkerboard"),
    ("checkerboard:9x6", "--board must be checkerboard"),
    ("checkerboard:9by6:0.04", "--board must be checkerboard"),
    ("checkerboard:9x6:-1", "square side must be positive"),
    ("checkerboard:8x6:0.04", "looks the same turned half round"),
    ("charuco:7x5:0.04:0.05", "must be positive and smaller than the square"),
    ("charuco:7x5:0.04:0.03:9X9_7", "unknown ArUco dictionary"),
])
def test_parse_board_refuses(text, message):
    with pytest.raises(ZoopraxisError, match=message):
        cal.parse_board(text)


# -- detection -----------------------------------------------------------------------------------

def test_detected_corners_are_subpixel_and_in_board_order(scene):
    board, cams, poses, _, detections = scene
    errors = []
    for c in cams:
        for f, found in detections[c.name].items():
            truth = c.project(se3.apply(poses[f], board.object_points()[found.ids]))
            errors.append(np.linalg.norm(found.corners - truth, axis=-1))
    errors = np.concatenate(errors)
    # a wrong corner order would put corners a square (tens of pixels) off
    assert errors.max() < 0.3 and errors.mean() < 0.08
    assert all(len(d) >= cal.MIN_BOARD_VIEWS for d in detections.values())


def test_detection_order_survives_a_half_turned_board(scene):
    board, cams, poses, _, _ = scene
    # the same board turned half round about its normal: OpenCV may start from the other end
    turn = se3.transform(se3.exp_so3([0.0, 0.0, np.pi]),
                         board.object_points().max(axis=0) * [1, 1, 0])
    T = poses[0] @ turn
    found = cal.detect_board(cal.render_board(cams[2], T, board), board)
    truth = cams[2].project(se3.apply(T, board.object_points()))
    assert np.abs(found.corners - truth).max() < 0.3


def test_charuco_corners_are_found_with_their_ids():
    board = cal.parse_board("charuco:10x7:0.1:0.06")
    R, t = look_at([0.3, -1.2, 2.0], [0.45, 0.3, 0.0])
    cam = PinholeCamera("cam0", (640, 480), [[700, 0, 319.5], [0, 700, 239.5], [0, 0, 1]],
                        R=R, t=t)
    T = se3.transform(cal.WORLD_FROM_BOARD)
    found = cal.detect_board(cal.render_board(cam, T, board, blur=0.5), board)
    assert len(found.ids) >= 30                  # of 54; markers at grazing angles are lost
    truth = cam.project(se3.apply(T, board.object_points()[found.ids]))
    assert np.abs(found.corners - truth).max() < 0.3


def test_no_board_no_detection():
    image = np.full((120, 160), 128, np.uint8)
    assert cal.detect_board(image, cal.parse_board(BOARD)) is None


# -- calibration -------------------------------------------------------------------------------

def test_calibration_recovers_the_cameras(scene):
    """Reprojection within 0.3 px (target), intrinsics and extrinsics of the true cameras."""
    board, cams, poses, _, detections = scene
    result = cal.calibrate_detections(detections, board, sizes(cams), world_frame=0)
    assert result.world_frame == 0 and not result.warnings
    for c in cams:
        fit = result.cameras[c.name]
        assert result.rms[c.name] < 0.3
        assert np.allclose(fit.K, c.K, atol=2.0)                           # pixels
        assert np.degrees(np.linalg.norm(se3.log_so3(fit.R @ c.R.T))) < 0.2
        assert np.linalg.norm(fit.center - c.center) < 0.01                # metres
        # every true corner of every frame it saw lands within 0.3 px of where it should
        for f in detections[c.name]:
            X = se3.apply(poses[f], board.object_points())
            assert np.abs(fit.project(X) - c.project(X)).max() < 0.3


def test_world_is_the_floor_board(scene):
    board, cams, _, _, detections = scene
    result = cal.calibrate_detections(detections, board, sizes(cams), world_frame=0)
    corners = se3.apply(result.board_poses[0], board.object_points())
    assert np.allclose(corners[:, 2], 0.0) and np.allclose(corners[0], 0.0)
    assert all(c.center[2] > 1.0 for c in result.cameras.values())      # above the floor


def test_refuses_a_camera_with_too_few_board_views(scene):
    board, cams, _, _, detections = scene
    few = {**detections, "cam1": dict(list(detections["cam1"].items())[:3])}
    with pytest.raises(ZoopraxisError, match="camera 'cam1': the board .* was found in 3 "
                                             "frames; at least 4"):
        cal.calibrate_detections(few, board, sizes(cams))


def test_refuses_a_camera_never_seen_with_another(scene):
    board, cams, _, _, detections = scene
    # a fourth camera that saw the board only in frames where no other camera did
    alone = {f + 100: d for f, d in detections["cam2"].items()}
    with pytest.raises(ZoopraxisError, match="camera 'cam3' never sees the board in the same "
                                             "frame as a placed camera"):
        cal.calibrate_detections({**detections, "cam3": alone}, board,
                                 {**sizes(cams), "cam3": (640, 480)})


def test_refuses_a_high_reprojection_rms(scene):
    board, cams, _, _, detections = scene
    with pytest.raises(ZoopraxisError, match="camera 'cam.': reprojection RMS .* is over 0.01"):
        cal.calibrate_detections(detections, board, sizes(cams), max_rms=0.01)


def test_refuses_an_absurd_focal_length(scene):
    board, cams, _, _, detections = scene
    # plates said to be a tenth of their real size: the lens comes out a 12x telephoto
    with pytest.raises(ZoopraxisError, match="camera 'cam0': focal length .* is absurd"):
        cal.calibrate_detections({"cam0": detections["cam0"]}, board, {"cam0": (64, 48)})


def test_refuses_a_world_frame_nobody_saw(scene):
    board, cams, _, _, detections = scene
    with pytest.raises(ZoopraxisError, match="world frame 99: no camera found the board"):
        cal.calibrate_detections(detections, board, sizes(cams), world_frame=99)


# -- the command line ----------------------------------------------------------------------------

def test_calibrate_command_writes_calibration_json(scene, tmp_path, capsys):
    board, cams, _, images, _ = scene
    args = ["calibrate", "--board", BOARD, "--world-frame", "0"]
    for c in cams:
        folder = tmp_path / c.name
        folder.mkdir()
        for f, image in images[c.name].items():
            cv2.imwrite(str(folder / f"{f:06d}.png"), image, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        args += ["--plate", f"{c.name}={folder}"]
    out = tmp_path / "calibration.json"
    assert cli.main(args + ["--out", str(out)]) == 0
    captured = capsys.readouterr()
    assert "cam0: board in" in captured.out and "reprojection RMS" in captured.out
    assert "calibrate: searching for the board" in captured.err
    data = json.loads(out.read_text())
    assert [c["name"] for c in data["cameras"]] == ["cam0", "cam1", "cam2"]
    # refuses to overwrite, and refuses a wrong board with a one-line reason
    assert cli.main(args + ["--out", str(out)]) == 2
    assert "file exists" in capsys.readouterr().err
    assert cli.main(["calibrate", "--board", "checkerboard:7x4:0.1", "--frames", "0:2",
                     "--plate", f"cam0={tmp_path / 'cam0'}", "--out",
                     str(tmp_path / "x.json")]) == 2
    [line] = capsys.readouterr().err.strip().splitlines()[-1:]
    assert "camera 'cam0': the board (checkerboard:7x4:0.1) was not found in any of 2" in line
