"""Calibrate from Board against the real bpy and the real core.calibrate: rendered board images
loaded as plates, solved into camera objects; a bad board spec refused in one line."""

import cv2
import numpy as np
import pytest

from test_addon_support import blender, bpy, registered  # noqa: F401

from zoopraxis.core.calibration import calibrate as cal
from zoopraxis.core.geometry import se3
from zoopraxis.core.geometry.camera import PinholeCamera, look_at

BOARD = "checkerboard:9x6:0.1"


def true_cameras():
    """Two cameras looking down at the floor from opposite-ish sides, each with its own lens."""
    cams = []
    for i, azimuth in enumerate(np.radians([20.0, 150.0])):
        R, t = look_at([2.2 * np.cos(azimuth), 2.2 * np.sin(azimuth), 1.9], [0.0, 0.0, 0.4])
        f = 820.0 + 30 * i
        K = [[f, 0.0, 319.5 + 4 * i], [0.0, f, 239.5 - 3 * i], [0.0, 0.0, 1.0]]
        cams.append(PinholeCamera(f"cam{i}", (640, 480), K, [-0.1, 0.04, 0.0, 0.0, 0.0], R, t))
    return cams


def board_poses(board, n=8, seed=7):
    """Frame 0: the board on the floor at the world origin; then tilted and lifted."""
    rng = np.random.default_rng(seed)
    half = board.object_points().max(axis=0) / 2
    poses = {0: se3.transform(cal.WORLD_FROM_BOARD)}
    for f in range(1, n):
        axis = np.append(rng.normal(size=2), 0.0)
        axis /= np.linalg.norm(axis)
        R = se3.exp_so3([0.0, 0.0, rng.uniform(-0.6, 0.6)]) \
            @ se3.exp_so3(axis * np.radians(rng.uniform(15, 35))) @ cal.WORLD_FROM_BOARD
        centre = [rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15), rng.uniform(0.2, 0.6)]
        poses[f] = se3.transform(R, centre - R @ half)
    return poses


@pytest.fixture(scope="module")
def board_plates(tmp_path_factory):
    """One image folder per camera of the board rendered at every frame."""
    root = tmp_path_factory.mktemp("board")
    board = cal.parse_board(BOARD)
    cams = true_cameras()
    poses = board_poses(board)
    for cam in cams:
        folder = root / cam.name
        folder.mkdir()
        for f, T in poses.items():
            cv2.imwrite(str(folder / f"{f:06d}.png"), cal.render_board(cam, T, board, blur=0.5))
    return root, cams, poses


def load_plates(root, names):
    for name in names:
        bpy.ops.zoopraxis.load_plates(filepath=str(root / name / "000000.png"))
    return bpy.context.scene.zoopraxis


def test_calibrate_from_board_puts_cameras_in_the_scene(blender, board_plates):
    from zoopraxis.addon.calibration import cameras_from_scene

    root, cams, poses = board_plates
    settings = load_plates(root, [c.name for c in cams])
    settings.board = BOARD
    settings.board_world_frame = 0
    assert bpy.ops.zoopraxis.calibrate_board() == {'FINISHED'}
    assert "RMS cam0 " in settings.status and " px" in settings.status, settings.status
    assert "world at frame 0" in settings.status
    assert all(v.camera is not None and v.camera.type == 'CAMERA' for v in settings.views)
    assert blender.scene.camera is not None
    fitted = cameras_from_scene(blender)
    X = np.random.default_rng(3).uniform([-0.5, -0.5, 0.0], [0.5, 0.5, 1.0], (30, 3))
    for cam in cams:
        # the scene's camera object reproduces the true camera: world is the floor board
        assert np.abs(fitted[cam.name].project(X) - cam.project(X)).max() < 1.0
        assert np.linalg.norm(fitted[cam.name].center - cam.center) < 0.02


def test_calibrate_from_board_refuses_a_bad_board_spec(blender, board_plates):
    root, cams, _ = board_plates
    settings = load_plates(root, [cams[0].name])
    settings.board = "checkerboard:9x7:0.1"       # both counts odd: refused by parse_board
    objects = len(bpy.data.objects)
    with pytest.raises(RuntimeError, match=r"^Error: --board: checkerboard 9x7 looks the same"):
        bpy.ops.zoopraxis.calibrate_board()
    assert len(bpy.data.objects) == objects and settings.views[0].camera is None

    settings.board = "chessboard:9x6"
    with pytest.raises(RuntimeError) as info:
        bpy.ops.zoopraxis.calibrate_board()
    assert "--board must be checkerboard:COLSxROWS:SQUARE_M" in str(info.value)
    assert "\n" not in str(info.value).strip()
    assert len(bpy.data.objects) == objects


def test_calibrate_from_board_world_frame_outside_take(blender, board_plates):
    root, cams, poses = board_plates
    settings = load_plates(root, [c.name for c in cams])
    settings.board = BOARD
    settings.board_world_frame = len(poses) + 5
    with pytest.raises(RuntimeError, match=f"world frame {len(poses) + 5} is outside the take"):
        bpy.ops.zoopraxis.calibrate_board()
    assert all(v.camera is None for v in settings.views)
