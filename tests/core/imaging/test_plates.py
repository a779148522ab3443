"""Plate reading: image folders, videos, frame ranges and the errors a user can fix."""

import cv2
import numpy as np
import pytest

from zoopraxis.core.imaging import plates
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.imaging.plates import (
    check_same_length, natural_key, open_plate, parse_frame_range, to_gray_float)

W, H = 64, 48


def smooth_images(rng, n, channels=3):
    """n distinct low-frequency uint8 images (H, W, channels) that survive JPEG nearly intact."""
    coarse = rng.integers(0, 256, (n, 6, 8, channels), dtype=np.uint8)
    return [cv2.resize(c, (W, H), interpolation=cv2.INTER_CUBIC).reshape(H, W, channels)
            for c in coarse]


def write_folder(folder, images, names=None):
    folder.mkdir(exist_ok=True)
    names = names or [f"frame_{i:04d}.png" for i in range(len(images))]
    for name, image in zip(names, images):
        assert cv2.imwrite(str(folder / name), image)
    return folder


def write_video(path, images, fps=25.0):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (W, H))
    assert writer.isOpened()
    for image in images:
        writer.write(image)
    writer.release()
    return path


@pytest.fixture
def video(tmp_path, rng):
    images = smooth_images(rng, 24)
    return write_video(tmp_path / "cam0.avi", images), images


class CountingCapture:
    """cv2.VideoCapture that counts opens and grabs, to see how a plate decodes."""

    opens = 0
    grabs = 0
    original = cv2.VideoCapture

    def __init__(self, *args):
        type(self).opens += 1
        self._capture = self.original(*args)

    def grab(self):
        type(self).grabs += 1
        return self._capture.grab()

    def __getattr__(self, name):
        return getattr(self._capture, name)


@pytest.fixture
def counting(monkeypatch):
    CountingCapture.opens = CountingCapture.grabs = 0
    monkeypatch.setattr(plates.cv2, "VideoCapture", CountingCapture)
    return CountingCapture


# --- image folders -----------------------------------------------------------------------

def test_folder_natural_order_ignores_other_files(tmp_path, rng):
    images = smooth_images(rng, 4)
    folder = write_folder(tmp_path / "cam1", images, ["f1.png", "f2.png", "f10.png", "F11.png"])
    (folder / "notes.txt").write_text("not a frame")
    cv2.imwrite(str(folder / ".f0.png"), images[3])  # macOS resource-fork style hidden file

    with open_plate(folder, fps=50) as plate:
        assert plate.name == "cam1"
        assert plate.num_frames == len(plate) == 4
        assert plate.image_size == (W, H)
        assert plate.fps == 50.0
        for i, image in enumerate(images):
            np.testing.assert_array_equal(plate.read(i), image)


def test_natural_key_equals_plain_sort_for_zero_padded_names():
    names = [f"img_{i:05d}.png" for i in (3, 120, 7, 99999, 0)]
    assert sorted(names, key=natural_key) == sorted(names)
    assert sorted(["f10.png", "f2.png", "f1.png"], key=natural_key) == [
        "f1.png", "f2.png", "f10.png"]


def test_folder_outputs_gray_and_float(tmp_path, rng):
    color = smooth_images(rng, 2)
    plate = open_plate(write_folder(tmp_path / "c", color))
    assert plate.fps is None
    image = color[1]
    np.testing.assert_array_equal(plate.read(1, gray=True),
                                  cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    as_float = plate.read(1, dtype=np.float32)
    assert as_float.dtype == np.float32 and as_float.shape == (H, W, 3)
    np.testing.assert_array_equal(as_float, image.astype(np.float32) / np.float32(255))
    gray_float = plate.read(1, gray=True, dtype=np.float32)
    assert gray_float.shape == (H, W)
    np.testing.assert_allclose(gray_float, image @ [0.114, 0.587, 0.299] / 255, atol=1e-5)

    gray = [i[..., 0] for i in smooth_images(rng, 2, channels=1)]
    plate = open_plate(write_folder(tmp_path / "g", gray))
    np.testing.assert_array_equal(plate.read(0, gray=True), gray[0])
    np.testing.assert_array_equal(plate.read(0), np.repeat(gray[0][..., None], 3, axis=2))
    np.testing.assert_array_equal(plate.read(0, gray=True, dtype=np.float32),
                                  gray[0] / np.float32(255))


def test_folder_16_bit_keeps_precision(tmp_path, rng):
    deep = rng.integers(0, 65536, (2, H, W, 3), dtype=np.uint16)
    plate = open_plate(write_folder(tmp_path / "deep", list(deep)))
    np.testing.assert_array_equal(plate.read(0, dtype=np.float32),
                                  deep[0] / np.float32(65535))
    np.testing.assert_array_equal(plate.read(0), np.rint(deep[0] / 257).astype(np.uint8))


def test_read_returns_fresh_arrays(tmp_path, rng):
    plate = open_plate(write_folder(tmp_path / "c", smooth_images(rng, 1)))
    first = plate.read(0)
    first[:] = 0
    assert plate.read(0).any()


def test_lru_serves_recent_frames_without_decoding(tmp_path, rng):
    images = smooth_images(rng, 10)
    folder = write_folder(tmp_path / "c", images)
    plate = open_plate(folder, cache_size=8)
    plate.read(0)
    cv2.imwrite(str(plate.files[0]), images[5])  # the file changes behind the plate's back
    np.testing.assert_array_equal(plate.read(0), images[0])  # cached
    for frame in range(1, 9):  # eight newer frames push frame 0 out
        plate.read(frame)
    np.testing.assert_array_equal(plate.read(0), images[5])  # decoded again


def test_frames_iterates_a_range(tmp_path, rng):
    images = smooth_images(rng, 6)
    plate = open_plate(write_folder(tmp_path / "c", images))
    got = list(plate.frames(2, 5, gray=True))
    assert [f for f, _ in got] == [2, 3, 4]
    for f, image in got:
        np.testing.assert_array_equal(image, cv2.cvtColor(images[f], cv2.COLOR_BGR2GRAY))
    assert [f for f, _ in plate.frames()] == list(range(6))


# --- videos ------------------------------------------------------------------------------

def test_video_matches_what_was_written(video):
    path, images = video
    plate = open_plate(path)
    assert plate.name == "cam0"
    assert plate.num_frames == len(images)
    assert plate.image_size == (W, H)
    assert plate.fps == pytest.approx(25.0)
    assert open_plate(path, fps=24).fps == 24.0
    written = np.array(images, dtype=np.float32)
    for f, image in plate.frames():
        errors = np.abs(written - image).mean(axis=(1, 2, 3))
        # JPEG (with its halved chroma) keeps each frame near its own original and far
        # from every other.
        assert errors[f] < 10.0 and np.delete(errors, f).min() > 40.0


def test_video_random_access_equals_sequential(video, counting):
    path, _ = video
    sequential = [image for _, image in open_plate(path, cache_size=0).frames()]
    plate = open_plate(path, cache_size=2)
    for frame in [5, 6, 20, 3, 23, 0, 12, 11, 1]:
        np.testing.assert_array_equal(plate.read(frame), sequential[frame], err_msg=frame)


def test_video_decodes_straight_through(video, counting):
    path, _ = video
    plate = open_plate(path, cache_size=8)
    assert counting.opens == 1 and counting.grabs == 1  # frame 0 probed at open
    for _ in plate.frames():
        pass
    assert counting.opens == 1 and counting.grabs == 24  # one pass, no re-seek

    for _ in range(3):  # a tracker reading t and t + 1 over and over
        plate.read(20), plate.read(21)
    assert counting.opens == 1 and counting.grabs == 24

    plate.read(2)  # behind and out of the cache: reopen and grab forward
    assert counting.opens == 2 and counting.grabs == 27
    plate.read(5)  # a little ahead: grab forward
    assert counting.opens == 2 and counting.grabs == 30


def test_closed_plate_reopens(video):
    path, _ = video
    with open_plate(path) as plate:
        before = plate.read(7)
    np.testing.assert_array_equal(plate.read(7), before)


# --- real footage ------------------------------------------------------------------------

def test_real_footage_direct_read_equals_sequential(shared_data):
    path = shared_data / "sports2d" / "walk_and_jumps.mp4"
    if not path.exists():
        pytest.skip(f"{path} is missing")
    capture = cv2.VideoCapture(str(path))
    for _ in range(101):
        ok, expected = capture.read()
        assert ok
    capture.release()

    plate = open_plate(path, cache_size=2)
    assert plate.image_size == (1768, 994)
    assert plate.fps == pytest.approx(30.0, abs=0.1)
    assert plate.num_frames > 200
    plate.read(101)
    np.testing.assert_array_equal(plate.read(100), expected)  # backwards: reopen path


# --- to_gray_float -----------------------------------------------------------------------

def test_to_gray_float_dtypes_and_channels():
    bgr = np.zeros((2, 3, 3), np.uint8)
    bgr[0, 0] = (255, 0, 0)  # pure blue
    bgr[0, 1] = (0, 0, 255)  # pure red
    bgr[1] = 255
    gray = to_gray_float(bgr)
    assert gray.dtype == np.float32 and gray.shape == (2, 3)
    np.testing.assert_allclose(gray[0, :2], [0.114, 0.299], atol=1e-6)
    np.testing.assert_allclose(gray[1], 1.0, atol=1e-6)

    np.testing.assert_allclose(to_gray_float(bgr.astype(np.uint16) * 257), gray, atol=1e-6)
    bgra = np.concatenate([bgr, np.zeros((2, 3, 1), np.uint8)], axis=2)
    np.testing.assert_array_equal(to_gray_float(bgra), gray)
    single = np.array([[0, 51, 255]], np.uint8)
    np.testing.assert_allclose(to_gray_float(single[..., None]), [[0, 0.2, 1]], atol=1e-7)
    np.testing.assert_array_equal(to_gray_float(np.array([[-0.5, 0.25, 7.0]])),
                                  np.array([[0, 0.25, 1]], np.float32))


def test_to_gray_float_rejects_bad_input():
    with pytest.raises(ValueError, match="pixel type int32"):
        to_gray_float(np.zeros((2, 2), np.int32))
    with pytest.raises(ValueError, match=r"got \(2, 2, 2\)"):
        to_gray_float(np.zeros((2, 2, 2), np.uint8))


# --- errors a user can fix ---------------------------------------------------------------

def test_missing_path(tmp_path):
    with pytest.raises(ZoopraxisError, match="nowhere: no such plate"):
        open_plate(tmp_path / "nowhere")


def test_folder_without_images(tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "readme.txt").write_text("x")
    with pytest.raises(ZoopraxisError,
                       match="no images in folder .*empty.*accepted: png, jpg, jpeg, tif"):
        open_plate(tmp_path / "empty")


def test_video_opencv_cannot_open(tmp_path):
    bad = tmp_path / "broken.mp4"
    bad.write_bytes(b"this is not a video" * 10)
    with pytest.raises(ZoopraxisError, match="cannot open video .*broken.mp4"):
        open_plate(bad)


def test_single_image_is_not_a_plate(tmp_path, rng):
    write_folder(tmp_path / "c", smooth_images(rng, 1), ["only.png"])
    with pytest.raises(ZoopraxisError, match="only.png is a single image"):
        open_plate(tmp_path / "c" / "only.png")


def test_bad_fps(tmp_path, rng):
    folder = write_folder(tmp_path / "c", smooth_images(rng, 1))
    with pytest.raises(ZoopraxisError, match="fps .* must be positive"):
        open_plate(folder, fps=0)


def test_frame_out_of_range(tmp_path, rng):
    plate = open_plate(write_folder(tmp_path / "cam2", smooth_images(rng, 5)))
    with pytest.raises(ZoopraxisError, match=r"frame 5 is outside plate 'cam2'.*0\.\.4"):
        plate.read(5)
    with pytest.raises(ZoopraxisError, match=r"frame -1 is outside plate 'cam2'"):
        plate.read(-1)
    with pytest.raises(ZoopraxisError, match=r"frames 3:9 are outside plate 'cam2'.*0:5"):
        plate.frames(3, 9)


def test_unreadable_image_names_file_and_frame(tmp_path, rng):
    folder = write_folder(tmp_path / "c", smooth_images(rng, 4))
    (folder / "frame_0002.png").write_bytes(b"garbage")
    plate = open_plate(folder)
    with pytest.raises(ZoopraxisError, match=r"cannot read image .*frame_0002.png \(frame 2"):
        plate.read(2)


def test_frame_size_mismatch(tmp_path, rng):
    folder = write_folder(tmp_path / "c", smooth_images(rng, 3))
    cv2.imwrite(str(folder / "frame_0001.png"), np.zeros((H, W + 2, 3), np.uint8))
    plate = open_plate(folder)
    with pytest.raises(ZoopraxisError,
                       match=rf"frame_0001.png \(frame 1\) is {W + 2}x{H}, .* is {W}x{H}"):
        plate.read(1)


def test_video_ending_early_names_the_frame(video):
    path, _ = video
    data = path.read_bytes()
    truncated = path.with_name("short.avi")
    truncated.write_bytes(data[:len(data) // 2])  # the header still claims 24 frames
    plate = open_plate(truncated)
    assert plate.num_frames == 24
    with pytest.raises(ZoopraxisError, match=r"short.avi ends early: frame \d+ .*24 frames"):
        for _ in plate.frames():
            pass


# --- views of one take -------------------------------------------------------------------

def test_check_same_length(tmp_path, rng):
    images = smooth_images(rng, 7)
    cam0 = open_plate(write_folder(tmp_path / "cam0", images[:5]))
    cam1 = open_plate(write_folder(tmp_path / "cam1", images))
    assert check_same_length({"cam0": cam0}) == 5
    assert check_same_length({"cam0": cam0, "cam1": cam1}, {"cam1": 2}) == 5
    with pytest.raises(ZoopraxisError, match="'cam0' 5 .*'cam1' 7 .*offset 0"):
        check_same_length({"cam0": cam0, "cam1": cam1})
    with pytest.raises(ZoopraxisError, match="'cam0' 4 .*'cam1' 6"):
        check_same_length({"cam0": cam0, "cam1": cam1}, {"cam0": 1, "cam1": 1})
    with pytest.raises(ZoopraxisError, match="offset -2 of view 'cam0' is negative"):
        check_same_length({"cam0": cam0, "cam1": cam1}, {"cam0": -2})
    with pytest.raises(ZoopraxisError, match="unknown view 'cam9'"):
        check_same_length({"cam0": cam0}, {"cam9": 1})


# --- --frames ----------------------------------------------------------------------------

@pytest.mark.parametrize("text, expected", [
    ("0:60", range(0, 60)), (":60", range(0, 60)), ("10:", range(10, 230)),
    (":", range(0, 230)), (" 5 : 7 ", range(5, 7)), (None, range(0, 230)),
    ("229:230", range(229, 230)),
])
def test_parse_frame_range(text, expected):
    assert parse_frame_range(text, 230) == expected


@pytest.mark.parametrize("text, message", [
    ("0:300", r"0:300 is not a non-empty range inside the plate's 230 frames"),
    ("230:", r"230:230 .*230 frames"),
    ("7:5", r"7:5 is not a non-empty range"),
    ("-1:5", "cannot be negative"),
    ("3:-1", "cannot be negative"),
    ("5", "'5' is not START:END"),
    ("a:b", "'a:b' is not START:END"),
    ("1:2:3", "is not START:END"),
])
def test_parse_frame_range_errors(text, message):
    with pytest.raises(ZoopraxisError, match=message):
        parse_frame_range(text, 230)
