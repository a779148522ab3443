"""Camera calibration from a checkerboard (or ChArUco board) seen in the plates.

Every view's intrinsics come from OpenCV's ``calibrateCamera`` over the frames where it sees the
board (Zhang's method); the cameras are then placed relative to each other through frames where
several of them see the board at once, and a bundle adjustment refines all intrinsics, all
extrinsics and the board poses together, minimizing the reprojection error of every detected
corner. One board pose defines the world: the board lies on the floor there, so world Z is up,
the floor is z = 0 and the origin is the board's first inner corner.

A calibration that is clearly wrong is refused with the reason: too few board views, a camera
that never sees the board together with another one, an absurd focal length, or a reprojection
RMS above the threshold.

Convention:
    Board frame: origin at the first inner corner, x along a row of corners, y along a column,
    z = x cross y, which points into the board seen from its printed side. A checkerboard's
    first corner is the one next to the black corner square at its end of the diagonal (the
    board must have one even and one odd number of inner corners, so that the two ends
    differ); a ChArUco board's is corner id 0. World (the board of the world frame lying face
    up on the floor): ``X_w = (x, -y, -z)`` of the board frame, Z up. Cameras: OpenCV,
    ``X_c = R @ X_w + t``; pixels: OpenCV's.
"""

import functools
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from ..geometry import se3
from ..geometry.camera import PinholeCamera
from ..errors import ZoopraxisError

# The world is the board frame turned half a turn about its x axis (board face up on the floor).
WORLD_FROM_BOARD = np.diag([1.0, -1.0, -1.0])

MIN_BOARD_VIEWS = 4          # frames a camera must see the board in, for its intrinsics
MIN_CORNERS = 6              # corners a (ChArUco) detection needs to count
MAX_RMS_PX = 1.0             # default refusal threshold of the reprojection RMS
_DENSE_LIMIT = 4_000_000     # Jacobian entries up to which the bundle adjustment goes dense
# Plausible focal lengths, in multiples of the image's larger side (fisheye ~0.3, long
# telephoto ~10), and the largest aspect ratio fx / fy of real pixels.
FOCAL_RANGE = (0.25, 12.0)
MAX_PIXEL_ASPECT = 1.15

ARUCO_DICTIONARIES = tuple(n[5:] for n in dir(cv2.aruco) if n.startswith("DICT_")) \
    if hasattr(cv2, "aruco") else ()


# ---------------------------------------------------------------------------------------------
# Boards
# ---------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Board:
    """A calibration board.

    Attributes
    ----------
    kind : {"checkerboard", "charuco"}
    cols, rows : int
        Checkerboard: inner corners per row and per column (OpenCV's pattern size; a board of
        10 x 7 squares has 9 x 6). ChArUco: squares per row and per column.
    square : float
        Side of a square, metres.
    marker : float
        ChArUco: side of a marker, metres.
    dictionary : str
        ChArUco: OpenCV's ArUco dictionary name without ``DICT_``, e.g. ``5X5_100``.
    """

    kind: str
    cols: int
    rows: int
    square: float
    marker: float = 0.0
    dictionary: str = "5X5_100"

    def __str__(self):
        tail = f":{self.marker:g}:{self.dictionary}" if self.kind == "charuco" else ""
        return f"{self.kind}:{self.cols}x{self.rows}:{self.square:g}{tail}"

    @property
    def n_corners(self):
        if self.kind == "checkerboard":
            return self.cols * self.rows
        return (self.cols - 1) * (self.rows - 1)

    def object_points(self):
        """Corners in the board frame (see module Convention), (N, 3), in corner id order."""
        if self.kind == "charuco":
            corners = np.asarray(self._charuco().getChessboardCorners(), float)
            return corners - corners[0]
        i, j = np.meshgrid(np.arange(self.cols), np.arange(self.rows))
        return np.stack([i.ravel(), j.ravel(), np.zeros(i.size)], axis=1) * self.square

    def _charuco(self):
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco,
                                                               "DICT_" + self.dictionary))
        return cv2.aruco.CharucoBoard((self.cols, self.rows), self.square, self.marker,
                                      dictionary)

    def texture(self, px_per_square=40):
        """An image of the printed board and the map from board coordinates to its pixels.

        Returns
        -------
        image : array, shape (H, W) uint8
        texture_from_board : array, shape (3, 3)
            Homography taking board ``(x, y, 1)`` (metres, board frame) to texture pixels.
        """
        q = int(px_per_square)
        if self.kind == "charuco":
            board = self._charuco()
            image = board.generateImage((self.cols * q, self.rows * q), marginSize=0)
            first = np.asarray(board.getChessboardCorners(), float)[0, :2]
            # Texture pixel p covers board [p, p + 1] * s / q measured from the board's corner.
            A = np.array([[q / self.square, 0.0, -0.5], [0.0, q / self.square, -0.5],
                          [0.0, 0.0, 1.0]])
            A[:2, 2] += first * q / self.square
            margin = q // 2
            image = cv2.copyMakeBorder(image, margin, margin, margin, margin,
                                       cv2.BORDER_CONSTANT, value=255)
            A[:2, 2] += margin
            return image, A
        # Squares (cols + 1) x (rows + 1), square (i, j) spanning board x in [(i-1)s, i s]:
        # black where i + j is even, so the square beyond corner 0 is black. Half a square of
        # white margin all round.
        margin = q // 2
        i = (np.arange((self.cols + 1) * q) // q)
        j = (np.arange((self.rows + 1) * q) // q)
        image = np.where((i[None, :] + j[:, None]) % 2 == 0, 0, 255).astype(np.uint8)
        image = cv2.copyMakeBorder(image, margin, margin, margin, margin, cv2.BORDER_CONSTANT,
                                   value=255)
        A = np.array([[q / self.square, 0.0, q + margin - 0.5],
                      [0.0, q / self.square, q + margin - 0.5], [0.0, 0.0, 1.0]])
        return image, A


def parse_board(text):
    """Parse the command line's ``--board``.

    ``checkerboard:COLSxROWS:SQUARE_M`` (inner corners, square side in metres) or
    ``charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]`` (squares, sides in metres, dictionary such
    as ``5X5_100``).

    Returns
    -------
    board : Board
    """
    parts = text.strip().split(":")
    kind = parts[0].lower()
    usage = ("--board must be checkerboard:COLSxROWS:SQUARE_M (inner corners, metres) or "
             f"charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT], got '{text}'")
    if kind not in ("checkerboard", "charuco"):
        raise ZoopraxisError(usage)
    expected = (3,) if kind == "checkerboard" else (4, 5)
    if len(parts) not in expected:
        raise ZoopraxisError(usage)
    try:
        cols, rows = (int(n) for n in parts[1].lower().split("x"))
        square = float(parts[2])
        marker = float(parts[3]) if kind == "charuco" else 0.0
    except ValueError:
        raise ZoopraxisError(usage) from None
    if not (square > 0 and np.isfinite(square)):
        raise ZoopraxisError(f"--board: the square side must be positive metres, got {parts[2]}")
    if kind == "checkerboard":
        if cols < 3 or rows < 3:
            raise ZoopraxisError(f"--board: a checkerboard needs at least 3x3 inner corners, "
                                 f"got {cols}x{rows}")
        if (cols + rows) % 2 == 0:
            raise ZoopraxisError(
                f"--board: checkerboard {cols}x{rows} looks the same turned half round, so "
                "cameras could disagree on its first corner; use one even and one odd count of "
                "inner corners (e.g. 9x6) or a ChArUco board")
        return Board("checkerboard", cols, rows, square)
    if not hasattr(cv2, "aruco"):
        raise ZoopraxisError("--board charuco: this OpenCV build has no aruco module")
    dictionary = parts[4].upper().removeprefix("DICT_") if len(parts) == 5 else "5X5_100"
    if dictionary not in ARUCO_DICTIONARIES:
        raise ZoopraxisError(f"--board: unknown ArUco dictionary '{parts[4]}' (e.g. "
                             "4X4_50, 5X5_100, 6X6_250)")
    if cols < 3 or rows < 3:
        raise ZoopraxisError(f"--board: a ChArUco board needs at least 3x3 squares, got "
                             f"{cols}x{rows}")
    if not 0 < marker < square:
        raise ZoopraxisError(f"--board: the marker side ({marker:g} m) must be positive and "
                             f"smaller than the square ({square:g} m)")
    board = Board("charuco", cols, rows, square, marker, dictionary)
    n_markers = (cols * rows) // 2
    capacity = int(dictionary.split("_")[1])
    if n_markers > capacity:
        raise ZoopraxisError(f"--board: a {cols}x{rows} ChArUco board has {n_markers} markers, "
                             f"more than dictionary {dictionary} holds")
    return board


# ---------------------------------------------------------------------------------------------
# Detection
# ---------------------------------------------------------------------------------------------

@dataclass
class Detection:
    """Board corners found in one image.

    Attributes
    ----------
    ids : array of int, shape (K,)
        Corner ids (indices into ``Board.object_points()``).
    corners : array, shape (K, 2)
        Pixels, OpenCV's convention.
    """

    ids: np.ndarray
    corners: np.ndarray


def detect_board(image, board):
    """Find the board's corners in an image, with subpixel accuracy.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, 3)
        8-bit gray or BGR.
    board : Board

    Returns
    -------
    detection : Detection or None
        None when the board is not found whole (checkerboard) or with fewer than MIN_CORNERS
        corners (ChArUco).
    """
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if gray.dtype != np.uint8:
        gray = cv2.normalize(gray, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    if board.kind == "charuco":
        corners, ids, _, _ = cv2.aruco.CharucoDetector(board._charuco()).detectBoard(gray)
        if ids is None or len(ids) < MIN_CORNERS:
            return None
        corners = corners.reshape(-1, 2)
        # The detector interpolates corners from the markers; refine them on the image, in a
        # window that stays clear of the markers (their edges would pull the corner).
        apart = np.linalg.norm(corners[:, None] - corners[None], axis=-1)
        clear = apart[apart > 0].min() * (board.square - board.marker) / board.square
        return Detection(ids.ravel().astype(int), _subpixel(gray, corners, clear))
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
    found, corners = cv2.findChessboardCorners(gray, (board.cols, board.rows), flags=flags)
    if not found:
        return None
    corners = corners.reshape(-1, 2)
    # The refinement window: most of the way to the next corner, at most 11 px.
    grid = corners.reshape(board.rows, board.cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=1), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=0), axis=-1).min())
    corners = _checkerboard_order(gray, _subpixel(gray, corners, spacing), board)
    return Detection(np.arange(board.n_corners), corners)


def _subpixel(gray, corners, spacing):
    """Corners refined by cv2.cornerSubPix in a window reaching most of the way to the nearest
    other corner (``spacing`` pixels away), at most 11 px each side."""
    half = int(np.clip(spacing * 0.4, 2, 11))
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
    refined = cv2.cornerSubPix(gray, np.asarray(corners, np.float32).reshape(-1, 1, 2),
                               (half, half), (-1, -1), criteria)
    return refined.reshape(-1, 2).astype(float)


def _checkerboard_order(gray, corners, board):
    """Put OpenCV's corners in the board's own order (module Convention).

    OpenCV returns the grid row by row but may start from any end and run either way round.
    A board seen from its printed side keeps its handedness in the image (x along a row, y
    along a column turn clockwise, as u and v do), which fixes the direction of the rows; the
    colour of the corner squares at the two ends of the diagonal fixes the end.
    """
    grid = corners.reshape(board.rows, board.cols, 2)
    a, b = grid[0, 1] - grid[0, 0], grid[1, 0] - grid[0, 0]
    if a[0] * b[1] - a[1] * b[0] < 0:
        grid = grid[:, ::-1]
    flat = grid.reshape(-1, 2)
    obj = board.object_points()[:, :2]
    H, _ = cv2.findHomography(obj, flat)
    s = board.square
    ends = np.array([[-0.5 * s, -0.5 * s], [(board.cols - 0.5) * s, (board.rows - 0.5) * s]])
    px = cv2.perspectiveTransform(ends.reshape(-1, 1, 2), H).reshape(-1, 2)
    # Mean brightness of a small patch in the middle of each corner square.
    side = max(3, int(0.3 * np.min(np.linalg.norm(np.diff(flat[:2], axis=0)))) | 1)
    values = [float(cv2.getRectSubPix(gray, (side, side), tuple(map(float, p))).mean())
              for p in px]
    if values[0] > values[1]:
        flat = flat[::-1]
    return flat.copy()


# ---------------------------------------------------------------------------------------------
# Calibration
# ---------------------------------------------------------------------------------------------

@dataclass
class CalibrationResult:
    """What :func:`calibrate_detections` found.

    Attributes
    ----------
    cameras : dict of str to PinholeCamera
    rms : dict of str to float
        Reprojection RMS per camera after the bundle adjustment, pixels.
    views : dict of str to int
        Frames in which each camera saw the board.
    world_frame : int
        The frame whose board pose defines the world.
    board_poses : dict of int to array, shape (4, 4)
        ``world_from_board`` of every frame used.
    warnings : list of str
    """

    cameras: dict
    rms: dict
    views: dict
    world_frame: int
    board_poses: dict
    warnings: list = field(default_factory=list)


def _transform(rvec, tvec):
    return se3.transform(cv2.Rodrigues(np.asarray(rvec, float).reshape(3))[0],
                         np.asarray(tvec, float).reshape(3))


def calibrate_detections(detections, board, image_sizes, *, world_frame=None,
                         max_rms=MAX_RMS_PX, fix_k3=True):
    """Calibrate the cameras from board detections (the work of :func:`calibrate`).

    Parameters
    ----------
    detections : dict of str to dict of int to Detection
        Per view, the frames where the board was found.
    board : Board
    image_sizes : dict of str to (int, int)
        Width and height per view.
    world_frame : int, optional
        The frame whose board lies on the floor; default the first frame seen by the most
        cameras.
    max_rms : float
        Refuse a camera whose reprojection RMS exceeds this, pixels.
    fix_k3 : bool
        Keep the sixth-order radial coefficient at zero (it overfits on few views).

    Returns
    -------
    result : CalibrationResult

    Raises
    ------
    ZoopraxisError
        Too few board views for a camera, a camera never seen with another one, a world frame
        no camera saw, an absurd focal length, or an RMS over ``max_rms``, naming the camera.
    """
    names = list(detections)
    if not names:
        raise ZoopraxisError("no views to calibrate")
    obj_all = board.object_points()
    for name in names:
        n = len(detections[name])
        if n < MIN_BOARD_VIEWS:
            raise ZoopraxisError(
                f"camera '{name}': the board ({board}) was found in {n} frame"
                f"{'' if n == 1 else 's'}; at least {MIN_BOARD_VIEWS} frames, with the board "
                "tilted differently, are needed for its lens")
    # 1. Intrinsics per camera (Zhang), with the board's pose in each of its frames.
    intrinsics, cam_from_board, warnings = {}, {}, []
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    for name in names:
        frames = sorted(detections[name])
        obj = [obj_all[detections[name][f].ids].astype(np.float32) for f in frames]
        img = [detections[name][f].corners.astype(np.float32).reshape(-1, 1, 2) for f in frames]
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img, tuple(image_sizes[name]),
                                                         None, None, flags=flags)
        _check_focal(name, K, image_sizes[name])
        intrinsics[name] = (K, dist.ravel()[:5])
        cam_from_board[name] = {f: _transform(r, t) for f, r, t in zip(frames, rvecs, tvecs)}
    # 2. The world: a frame's board on the floor.
    seen_by = {}
    for name in names:
        for f in detections[name]:
            seen_by.setdefault(f, []).append(name)
    if world_frame is None:
        world_frame = min(seen_by, key=lambda f: (-len(seen_by[f]), f))
    elif world_frame not in seen_by:
        raise ZoopraxisError(f"world frame {world_frame}: no camera found the board there")
    # 3. Chain the cameras through frames they share, breadth first from the world frame.
    world_from_board_f = se3.transform(WORLD_FROM_BOARD)
    cam_from_world = {n: cam_from_board[n][world_frame] @ se3.invert(world_from_board_f)
                      for n in seen_by[world_frame]}
    board_in_world = {world_frame: world_from_board_f}
    changed = True
    while changed:
        changed = False
        for f, cams in seen_by.items():
            if f not in board_in_world:
                known = [n for n in cams if n in cam_from_world]
                if known:
                    n = known[0]
                    board_in_world[f] = se3.invert(cam_from_world[n]) @ cam_from_board[n][f]
                    changed = True
        for n in names:
            if n not in cam_from_world:
                shared = [f for f in detections[n] if f in board_in_world]
                if shared:
                    cam_from_world[n] = _mean_pose([cam_from_board[n][f]
                                                    @ se3.invert(board_in_world[f])
                                                    for f in shared])
                    changed = True
    lost = [n for n in names if n not in cam_from_world]
    if lost:
        raise ZoopraxisError(
            f"camera '{lost[0]}' never sees the board in the same frame as a placed camera "
            f"({', '.join(cam_from_world)}): show the board to it and another camera at once")
    # 4. Bundle adjustment of everything but the world frame's board.
    cameras = {n: PinholeCamera(n, image_sizes[n], intrinsics[n][0], intrinsics[n][1],
                                cam_from_world[n][:3, :3], cam_from_world[n][:3, 3])
               for n in names}
    cameras, board_in_world, rms = _bundle_adjust(cameras, board_in_world, detections, obj_all,
                                                  world_frame, fix_k3)
    for name, cam in cameras.items():
        _check_focal(name, cam.K, cam.image_size)
        if rms[name] > max_rms:
            raise ZoopraxisError(
                f"camera '{name}': reprojection RMS {rms[name]:.2f} px is over {max_rms:g} px: "
                "the board may be detected wrongly, the plates may be out of sync, or the lens "
                "needs more board views")
        if cam.center[2] < 0:
            warnings.append(f"camera '{name}' is below the floor (z = {cam.center[2]:.2f} m): "
                            f"was the board of frame {world_frame} lying face up on the floor?")
    return CalibrationResult(cameras, rms, {n: len(detections[n]) for n in names}, world_frame,
                             board_in_world, warnings)


def _check_focal(name, K, image_size):
    fx, fy = K[0, 0], K[1, 1]
    side = max(image_size)
    lo, hi = FOCAL_RANGE
    if not (lo * side <= fx <= hi * side and lo * side <= fy <= hi * side):
        raise ZoopraxisError(
            f"camera '{name}': focal length fx={fx:.0f} px, fy={fy:.0f} px is absurd for a "
            f"{image_size[0]}x{image_size[1]} image: the board views do not constrain the lens "
            "(tilt the board more)")
    if max(fx / fy, fy / fx) > MAX_PIXEL_ASPECT:
        raise ZoopraxisError(f"camera '{name}': focal lengths fx={fx:.0f} px and fy={fy:.0f} px "
                             "disagree: pixels are not that far from square")


def _mean_pose(transforms):
    """Average of rigid transforms: chordal mean rotation, mean translation."""
    T = np.asarray(transforms)
    R = se3.orthonormalize(T[:, :3, :3].mean(axis=0))
    return se3.transform(R, T[:, :3, 3].mean(axis=0))


def _bundle_adjust(cameras, board_in_world, detections, obj_all, world_frame, fix_k3):
    """Refine intrinsics (fx, fy, cx, cy, k1, k2, p1, p2), camera poses and board poses.

    Parameters per camera: Rodrigues vector and translation (OpenCV's), then the intrinsics;
    per board frame except the world's: rotation increment and translation. The Jacobian is
    OpenCV's ``projectPoints`` derivative for the camera, and ``d uv / d t_cam @ R_cam`` (the
    derivative by the world point) chained with the board's motion for the board.

    Returns
    -------
    cameras : dict of str to PinholeCamera
    board_in_world : dict of int to array, shape (4, 4)
    rms : dict of str to float
    """
    names = list(cameras)
    frames = sorted(f for f in board_in_world if f != world_frame)
    n_dist = 4 if fix_k3 else 5
    cam_size = 6 + 4 + n_dist
    board_col = {f: len(names) * cam_size + 6 * i for i, f in enumerate(frames)}
    pairs = [(c, n, f) for c, n in enumerate(names) for f in sorted(detections[n])
             if f in board_in_world]
    x0 = []
    for n in names:
        cam = cameras[n]
        rvec = cv2.Rodrigues(cam.R)[0].ravel()
        K = cam.K
        x0 += [rvec, cam.t, [K[0, 0], K[1, 1], K[0, 2], K[1, 2]], cam.dist[:n_dist]]
    for f in frames:
        x0 += [np.zeros(3), board_in_world[f][:3, 3]]
    x0 = np.concatenate([np.ravel(a) for a in x0])
    R_board0 = {f: board_in_world[f][:3, :3] for f in frames}
    counts = [len(detections[n][f].ids) for _, n, f in pairs]
    rows_of = np.cumsum([0] + [2 * k for k in counts])
    m = int(rows_of[-1])

    def unpack(x):
        cams = []
        for c in range(len(names)):
            p = x[c * cam_size:(c + 1) * cam_size]
            K = np.array([[p[6], 0.0, p[8]], [0.0, p[7], p[9]], [0.0, 0.0, 1.0]])
            dist = np.zeros(5)
            dist[:n_dist] = p[10:10 + n_dist]
            cams.append((p[:3], p[3:6], K, dist))
        boards = {world_frame: board_in_world[world_frame]}
        for f in frames:
            q = x[board_col[f]:board_col[f] + 6]
            boards[f] = se3.transform(se3.exp_so3(q[:3]) @ R_board0[f], q[3:])
        return cams, boards

    def fun(x):
        cams, boards = unpack(x)
        r = np.empty(m)
        rows, cols, vals = [], [], []
        for i, (c, n, f) in enumerate(pairs):
            det = detections[n][f]
            T = boards[f]
            X = se3.apply(T, obj_all[det.ids])
            rvec, tvec, K, dist = cams[c]
            uv, J = cv2.projectPoints(X, rvec, tvec, K, dist)
            r[rows_of[i]:rows_of[i + 1]] = (uv.reshape(-1, 2) - det.corners).ravel()
            row = np.arange(rows_of[i], rows_of[i + 1])
            J_cam = np.concatenate([J[:, :10], J[:, 10:10 + n_dist]], axis=1)
            rows.append(np.repeat(row, cam_size))
            cols.append(np.tile(c * cam_size + np.arange(cam_size), len(row)))
            vals.append(J_cam.ravel())
            if f != world_frame:
                R_cam = cv2.Rodrigues(rvec)[0]
                d_uv_dX = (J[:, 3:6] @ R_cam).reshape(-1, 2, 3)                 # (K, 2, 3)
                w = x[board_col[f]:board_col[f] + 3]
                d_X = np.concatenate([-se3.hat3(X - T[:3, 3]) @ se3.left_jacobian_so3(w),
                                      np.broadcast_to(np.eye(3), (len(X), 3, 3))], axis=-1)
                rows.append(np.repeat(row, 6))
                cols.append(np.tile(board_col[f] + np.arange(6), len(row)))
                vals.append((d_uv_dX @ d_X).reshape(-1, 6).ravel())
        J = sparse.coo_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))),
                              shape=(m, x.size))
        # Small problems are faster dense; large ones (many frames) stay sparse.
        return r, (J.toarray() if m * x.size < _DENSE_LIMIT else J.tocsr())

    cache = {}

    def evaluate(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = fun(x)
        return cache[key]

    dense = not sparse.issparse(evaluate(x0)[1])
    result = least_squares(lambda x: evaluate(x)[0], x0, jac=lambda x: evaluate(x)[1],
                           method="trf", x_scale="jac", loss="huber", f_scale=2.0,
                           tr_solver="exact" if dense else "lsmr", max_nfev=100)
    cams, boards = unpack(result.x)
    residual = evaluate(result.x)[0].reshape(-1, 2)
    out, rms = {}, {}
    for c, n in enumerate(names):
        rvec, tvec, K, dist = cams[c]
        out[n] = PinholeCamera(n, cameras[n].image_size, K, dist,
                               se3.orthonormalize(cv2.Rodrigues(rvec)[0]), tvec)
        sel = np.concatenate([np.arange(rows_of[i], rows_of[i + 1]) // 2
                              for i, (cc, _, _) in enumerate(pairs) if cc == c])
        rms[n] = float(np.sqrt(np.mean(np.sum(residual[sel] ** 2, axis=-1))))
    return out, boards, rms


def calibrate(plates, board, frames=None, *, step=1, world_frame=None, max_rms=MAX_RMS_PX,
              progress=None, cancel=None):
    """Calibrate the cameras of a take from a board seen in its plates.

    Parameters
    ----------
    plates : dict of str to plates.Plate
        The views, by name.
    board : Board
    frames : range, optional
        Plate frames to search for the board; default all.
    step : int
        Search every ``step``-th frame of ``frames``.
    world_frame : int, optional
        See :func:`calibrate_detections`.
    max_rms : float
    progress : callable(done, total), optional
        Called after each image searched.
    cancel : callable() -> bool, optional
        Polled between images; stops the search early (the frames searched are used).

    Returns
    -------
    result : CalibrationResult
    """
    if int(step) != step or step < 1:
        raise ZoopraxisError(f"--step must be a whole number >= 1, got {step}")
    names = list(plates)
    if frames is None:
        frames = range(min(p.num_frames for p in plates.values()))
    searched = list(frames)[::int(step)]
    detections = {n: {} for n in names}
    total, done = len(searched) * len(names), 0
    for f in searched:
        if cancel is not None and cancel():
            break
        for n in names:
            if f < plates[n].num_frames:
                found = detect_board(plates[n].read(f, gray=True), board)
                if found is not None:
                    detections[n][f] = found
            done += 1
            if progress is not None:
                progress(done, total)
    for n in names:
        if not detections[n]:
            raise ZoopraxisError(
                f"camera '{n}': the board ({board}) was not found in any of {len(searched)} "
                "frames searched (checkerboards count inner corners: 10x7 squares are 9x6)")
    return calibrate_detections(detections, board, {n: plates[n].image_size for n in names},
                                world_frame=world_frame, max_rms=max_rms)


# ---------------------------------------------------------------------------------------------
# Synthetic board images (tests and benchmarks)
# ---------------------------------------------------------------------------------------------

def render_board(camera, world_from_board, board, *, background=128, blur=0.0, noise=0.0,
                 rng=None, supersample=2):
    """Render the board into a camera's image: a plane textured with the printed board.

    The board is drawn by a homography into an image ``supersample`` times larger and reduced
    with area averaging (so edges are antialiased without a shift), then warped through the lens
    distortion, blurred and given sensor noise.

    Parameters
    ----------
    camera : PinholeCamera
    world_from_board : array, shape (4, 4)
    board : Board
    background : int
        Grey level outside the board.
    blur : float
        Gaussian blur sigma, pixels.
    noise : float
        Sensor noise sigma, grey levels.
    rng : numpy.random.Generator, optional
    supersample : int

    Returns
    -------
    image : array, shape (H, W) uint8
    """
    texture, texture_from_board = board.texture()
    cam_from_board = np.hstack([camera.R, camera.t[:, None]]) @ world_from_board
    K = camera.K.copy()
    k = int(supersample)
    # Supersampled pixel centres: pixel u covers [u - 0.5, u + 0.5], sub-pixel i of it sits at
    # u - 0.5 + (i + 0.5) / k, i.e. U = k (u + 0.5) - 0.5.
    S = np.array([[k, 0.0, 0.5 * k - 0.5], [0.0, k, 0.5 * k - 0.5], [0.0, 0.0, 1.0]])
    image_from_board = S @ K @ cam_from_board[:, [0, 1, 3]]
    H = image_from_board @ np.linalg.inv(texture_from_board)
    w, h = camera.image_size
    big = cv2.warpPerspective(texture.astype(np.float32), H, (w * k, h * k),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                              borderValue=float(background))
    # Only where the plane lies in front of the camera: the third coordinate of the board point
    # seen through a pixel is 1 / depth, linear in the pixel.
    a, b, c = np.linalg.inv(image_from_board)[2]
    behind = a * np.arange(w * k)[None, :] + b * np.arange(h * k)[:, None] + c <= 0
    big[behind] = background
    image = cv2.resize(big, (w, h), interpolation=cv2.INTER_AREA)
    if camera.has_distortion:
        map_u, map_v = _ideal_pixels(camera)
        image = cv2.remap(image, map_u, map_v, cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_CONSTANT, borderValue=float(background))
    if blur > 0:
        image = cv2.GaussianBlur(image, (0, 0), blur)
    if noise > 0:
        rng = np.random.default_rng() if rng is None else rng
        image = image + rng.normal(0.0, noise, image.shape).astype(np.float32)
    return np.clip(np.round(image), 0, 255).astype(np.uint8)


@functools.lru_cache(maxsize=8)
def _ideal_pixels(camera):
    """Where each pixel of a distorting camera looks in its distortion-free image, as maps
    for cv2.remap (cameras are immutable, so the maps are kept)."""
    w, h = camera.image_size
    u, v = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    ideal = camera.undistort_points(np.stack([u, v], axis=-1)).astype(np.float32)
    return ideal[..., 0].copy(), ideal[..., 1].copy()


__all__ = ["Board", "parse_board", "Detection", "detect_board", "CalibrationResult",
           "calibrate", "calibrate_detections", "render_board", "WORLD_FROM_BOARD"]
