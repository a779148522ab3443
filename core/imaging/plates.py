"""Plates: one camera's footage, a video file or a folder of images, read frame by frame.

Frames are streamed through OpenCV, never loaded all at once (a take can be thousands of 4K
frames); a small LRU keeps the last few decoded frames so a tracker that reads ``t`` and
``t + 1`` over and over decodes each frame once.

Convention: images come back OpenCV style, ``(H, W, 3)`` BGR or ``(H, W)`` gray, origin at the
centre of the top-left pixel. Frames are 0-based indices into the plate; the views of one take
share the index, up to a per-view offset (take frame ``f`` is plate frame ``f + offset``).
"""

import functools
import math
import operator
import re
import stat
from collections import OrderedDict
from pathlib import Path

import cv2
import numpy as np

from ..errors import ZoopraxisError
from ..files.inputs import file_mode

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp")
EXR_EXTENSION = ".exr"
DEFAULT_CACHE_SIZE = 8

# ANYDEPTH keeps 16-bit and float plates at full precision; ANYCOLOR keeps gray images gray
# (and drops alpha). Unlike IMREAD_UNCHANGED it still honours EXIF orientation.
_IMREAD_FLAGS = cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR


@functools.cache
def exr_supported():
    """Whether this OpenCV reads OpenEXR.

    OpenCV ships its EXR codec disabled; it is on only when ``OPENCV_IO_ENABLE_OPENEXR=1`` was
    set before the first EXR access (OpenCV caches the answer, and so do we). We never flip
    that switch ourselves: it guards a parser OpenCV does not trust with arbitrary files.
    """
    try:
        ok, buf = cv2.imencode(EXR_EXTENSION, np.zeros((1, 1), np.float32))
        return bool(ok) and cv2.imdecode(buf, _IMREAD_FLAGS) is not None
    except cv2.error:
        return False


def accepted_extensions():
    """Image file extensions a plate folder may hold, lower case with the dot."""
    return IMAGE_EXTENSIONS + ((EXR_EXTENSION,) if exr_supported() else ())


def natural_key(name):
    """Sort key that orders digit runs by value, so ``f2.png`` < ``f10.png``.

    Zero-padded names sort as they would by plain string order.
    """
    # re.split with a capturing group alternates text, digits, text, ..., so equal
    # positions of two keys always hold the same type.
    parts = re.split(r"(\d+)", name.lower())
    return [int(p) if i % 2 else p for i, p in enumerate(parts)], name


def to_gray_float(image):
    """Convert an image to gray float32 in [0, 1], the form trackers work on.

    Parameters
    ----------
    image : array, shape (H, W), (H, W, 1), (H, W, 3) BGR or (H, W, 4) BGRA
        uint8 (scaled by 1/255), uint16 (scaled by 1/65535) or float (clipped to [0, 1]; HDR
        values above 1 saturate). Alpha is ignored.

    Returns
    -------
    gray : array, shape (H, W), float32
        Luma with OpenCV's weights, 0.299 R + 0.587 G + 0.114 B.
    """
    unit = _to_unit_float(_drop_extra_channels(np.asarray(image)))
    return cv2.cvtColor(unit, cv2.COLOR_BGR2GRAY) if unit.ndim == 3 else unit


def _drop_extra_channels(image):
    if image.ndim == 3 and image.shape[2] == 1:
        return image[..., 0]
    if image.ndim == 3 and image.shape[2] == 4:
        return image[..., :3]
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3):
        return image
    raise ValueError(f"expected an image of shape (H, W) or (H, W, 1|3|4), got {image.shape}")


def _to_unit_float(image):
    """New float32 array in [0, 1] from uint8, uint16 or float pixels."""
    if image.dtype == np.uint8:
        return np.divide(image, 255, dtype=np.float32)
    if image.dtype == np.uint16:
        return np.divide(image, 65535, dtype=np.float32)
    if np.issubdtype(image.dtype, np.floating):
        return np.clip(image, 0.0, 1.0).astype(np.float32)
    raise ValueError(f"unsupported pixel type {image.dtype} (expected uint8, uint16 or float)")


def _to_uint8(image):
    """New uint8 array from uint8, uint16 or float pixels, rounding to nearest."""
    if image.dtype == np.uint8:
        return image.copy()
    if image.dtype == np.uint16:
        # round(v / 257): 257 maps the 16-bit range exactly onto 0..255.
        return ((image.astype(np.uint32) + 128) // 257).astype(np.uint8)
    return np.rint(_to_unit_float(image) * 255).astype(np.uint8)


class Plate:
    """One camera's footage, read lazily frame by frame; open with :func:`open_plate`.

    Attributes
    ----------
    path : Path
        The video file or image folder.
    name : str
        View name used in messages (the file stem or folder name unless given).
    num_frames : int
        Number of frames, also ``len(plate)``.
    image_size : tuple of int
        ``(width, height)`` in pixels, of the first frame; every frame must match.
    fps : float or None
        Frames per second: the one given to :func:`open_plate`, else the video container's,
        else None (image folders carry no rate).

    Notes
    -----
    Use as a context manager or call :meth:`close`. A closed plate reopens on the next read.
    """

    def __init__(self, path, name, fps, cache_size):
        self.path = path
        self.name = name
        self.fps = fps
        self.num_frames = 0
        self.image_size = (0, 0)
        self._cache_size = int(cache_size)
        self._cache = OrderedDict()  # frame -> decoded image (as stored), most recent last

    def __len__(self):
        return self.num_frames

    def __repr__(self):
        w, h = self.image_size
        return (f"<{type(self).__name__} '{self.name}' {self.path}: {self.num_frames} frames "
                f"{w}x{h}, fps {self.fps}>")

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Release the decoder and the cached frames."""
        self._cache.clear()

    def read(self, frame, *, gray=False, dtype=np.uint8):
        """Read one frame.

        Parameters
        ----------
        frame : int
            0-based plate frame index.
        gray : bool
            Return luma (OpenCV's BGR2GRAY weights) instead of BGR.
        dtype : np.uint8 or np.float32
            uint8 in 0..255 (16-bit and float sources are rounded), or float32 in [0, 1]
            (the same as :func:`to_gray_float` for gray).

        Returns
        -------
        image : array, shape (H, W, 3) BGR, or (H, W) if ``gray``
            A fresh array: writing to it does not touch the cache.
        """
        dtype = np.dtype(dtype)
        if dtype not in (np.uint8, np.float32):
            raise ValueError(f"dtype must be uint8 or float32, got {dtype}")
        return _convert(self._decoded(self._check_frame(frame)), gray, dtype)

    def frames(self, start=0, stop=None, *, gray=False, dtype=np.uint8):
        """Iterate ``(frame, image)`` over ``start .. stop - 1`` in order.

        Videos are decoded straight through, never re-seeked within the range. ``stop``
        defaults to the end of the plate; images are as :meth:`read` returns them.
        """
        stop = self.num_frames if stop is None else operator.index(stop)
        start = operator.index(start)
        if not 0 <= start <= stop <= self.num_frames:
            raise ZoopraxisError(
                f"frames {start}:{stop} are outside plate '{self.name}' ({self.path}): "
                f"valid frames are 0:{self.num_frames}")
        # Checked above, not inside the generator, so a bad range fails at the call.
        return ((f, self.read(f, gray=gray, dtype=dtype)) for f in range(start, stop))

    def _check_frame(self, frame):
        frame = operator.index(frame)
        if not 0 <= frame < self.num_frames:
            raise ZoopraxisError(
                f"frame {frame} is outside plate '{self.name}' ({self.path}): "
                f"valid frames are 0..{self.num_frames - 1}")
        return frame

    def _decoded(self, frame):
        image = self._cache.get(frame)
        if image is not None:
            self._cache.move_to_end(frame)
            return image
        image = self._decode(frame)
        if image.shape[:2] != self.image_size[::-1]:
            w, h = self.image_size
            raise ZoopraxisError(
                f"{self._frame_source(frame)} (frame {frame}) is {image.shape[1]}x"
                f"{image.shape[0]}, but frame 0 of plate '{self.name}' is {w}x{h}")
        self._remember(frame, image)
        return image

    def _remember(self, frame, image):
        if self._cache_size <= 0:
            return
        self._cache[frame] = image
        while len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)

    def _decode(self, frame):
        raise NotImplementedError

    def _frame_source(self, frame):
        raise NotImplementedError


class _FolderPlate(Plate):
    """A folder of images, one file per frame in natural name order (``files``, list of Path)."""

    def __init__(self, path, name, fps, cache_size, files):
        super().__init__(path, name, fps, cache_size)
        self.files = files
        self.num_frames = len(files)
        first = self._decode(0)
        self.image_size = (first.shape[1], first.shape[0])
        self._remember(0, first)

    def _frame_source(self, frame):
        return f"image {self.files[frame]}"

    def _decode(self, frame):
        file = self.files[frame]
        image = cv2.imread(str(file), _IMREAD_FLAGS)
        if image is None:
            raise ZoopraxisError(
                f"cannot read image {file} (frame {frame} of plate '{self.name}')")
        if image.dtype not in (np.uint8, np.uint16) and not np.issubdtype(image.dtype,
                                                                             np.floating):
            raise ZoopraxisError(
                f"image {file} (frame {frame}) has pixel type {image.dtype}; "
                f"plates must be 8-bit, 16-bit or float")
        return _drop_extra_channels(image)


class _VideoPlate(Plate):
    """A video file, decoded forwards only.

    ``CAP_PROP_POS_FRAMES`` seeking lands on the wrong frame for some codecs, so we never
    seek: a frame ahead is reached by grabbing forward, a frame behind by reopening the file
    and grabbing forward from frame 0 (correct before fast; the LRU absorbs short steps back).
    """

    def __init__(self, path, name, fps, cache_size):
        super().__init__(path, name, fps, cache_size)
        self._capture = None
        self._next = 0  # frame the next grab() returns
        self._open()
        if self.fps is None:
            container_fps = self._capture.get(cv2.CAP_PROP_FPS)
            self.fps = container_fps if math.isfinite(container_fps) and container_fps > 0 \
                else None
        claimed = self._capture.get(cv2.CAP_PROP_FRAME_COUNT)
        self.num_frames = int(claimed) if math.isfinite(claimed) and claimed > 0 \
            else self._count_frames()
        if self.num_frames == 0:
            raise ZoopraxisError(f"OpenCV cannot decode any frame of video {path}")
        try:
            first = self._decode(0)
        except ZoopraxisError:
            raise ZoopraxisError(f"OpenCV cannot decode video {path}") from None
        self.image_size = (first.shape[1], first.shape[0])
        self._remember(0, first)

    def close(self):
        super().close()
        if self._capture is not None:
            self._capture.release()
            self._capture = None

    def _open(self):
        if self._capture is not None:
            self._capture.release()
        self._capture = cv2.VideoCapture(str(self.path))
        self._next = 0
        if not self._capture.isOpened():
            self._capture = None
            raise ZoopraxisError(f"OpenCV cannot open video {self.path}")

    def _count_frames(self):
        # Some streams do not state their length; counting costs one decode pass.
        count = 0
        while self._capture.grab():
            count += 1
        self._open()
        return count

    def _frame_source(self, frame):
        return f"video {self.path}"

    def _decode(self, frame):
        if self._capture is None or frame < self._next:
            self._open()
        while self._next <= frame:
            if not self._capture.grab():
                raise ZoopraxisError(
                    f"video {self.path} ends early: frame {self._next} cannot be decoded "
                    f"though the container claims {self.num_frames} frames "
                    f"(use --frames to stop before it)")
            self._next += 1
        ok, image = self._capture.retrieve()
        if not ok or image is None:
            raise ZoopraxisError(f"video {self.path}: frame {frame} cannot be decoded")
        return image


def _convert(image, gray, dtype):
    """New array from a decoded (H, W) or (H, W, 3) image, as :meth:`Plate.read` promises."""
    if dtype == np.float32:
        if gray:
            return to_gray_float(image)
        unit = _to_unit_float(image)
        return cv2.cvtColor(unit, cv2.COLOR_GRAY2BGR) if unit.ndim == 2 else unit
    image8 = _to_uint8(image)
    if gray:
        return image8 if image8.ndim == 2 else cv2.cvtColor(image8, cv2.COLOR_BGR2GRAY)
    return cv2.cvtColor(image8, cv2.COLOR_GRAY2BGR) if image8.ndim == 2 else image8


def open_plate(path, *, name=None, fps=None, cache_size=DEFAULT_CACHE_SIZE):
    """Open a video file or a folder of images as a plate.

    Parameters
    ----------
    path : str or Path
        A video file OpenCV can decode, or a folder of images (png, jpg, jpeg, tif, tiff, bmp,
        and exr when OpenCV's EXR codec is enabled), one per frame in natural name order
        (``f2.png`` before ``f10.png``). Hidden files and other extensions are ignored.
    name : str, optional
        View name for messages; defaults to the folder name or the file stem.
    fps : float, optional
        Frame rate; overrides a video container's rate, and is the only rate a folder has.
    cache_size : int
        Decoded frames kept in memory (each 4K BGR frame is 25 MB).

    Returns
    -------
    plate : Plate

    Raises
    ------
    ZoopraxisError
        The path is missing, is a single image, is a folder without images, or is a video
        OpenCV cannot open; ``fps`` is not positive.
    """
    path = Path(path).expanduser()
    if fps is not None:
        fps = float(fps)
        if not (math.isfinite(fps) and fps > 0):
            raise ZoopraxisError(f"fps of plate {path} must be positive, got {fps}")
    mode = file_mode(path, "plate")
    if not (stat.S_ISDIR(mode) or stat.S_ISREG(mode)):
        # Opening a named pipe blocks until a writer comes, deaf to Ctrl-C: never try.
        raise ZoopraxisError(f"plate {path} is not a regular file or folder (a pipe or a "
                             "device?); a plate is a video file or a folder of images")
    if path.is_dir():
        return _FolderPlate(path, name or path.name, fps, cache_size, _list_images(path))
    if path.suffix.lower() in IMAGE_EXTENSIONS + (EXR_EXTENSION,):
        raise ZoopraxisError(
            f"{path} is a single image; a plate is a video file or a folder of images")
    return _VideoPlate(path, name or path.stem, fps, cache_size)


def _list_images(folder):
    """Image files of a folder in natural order; ZoopraxisError when there are none."""
    try:
        candidates = [p for p in folder.iterdir() if not p.name.startswith(".") and p.is_file()]
    except OSError as error:
        raise ZoopraxisError(f"plate folder {folder}: cannot list it ({error.strerror})") from None
    has_exr = any(p.suffix.lower() == EXR_EXTENSION for p in candidates)
    # Probe EXR only when there is some: the probe makes OpenCV log a warning if disabled.
    accepted = accepted_extensions() if has_exr else IMAGE_EXTENSIONS
    files = sorted((p for p in candidates if p.suffix.lower() in accepted),
                   key=lambda p: natural_key(p.name))
    if not files:
        hint = (" (its .exr files need OpenCV's EXR codec: set OPENCV_IO_ENABLE_OPENEXR=1)"
                if has_exr and not exr_supported() else "")
        names = ", ".join(e[1:] for e in accepted_extensions())
        raise ZoopraxisError(f"no images in folder {folder}{hint}; accepted: {names}")
    for frame, file in enumerate(files):
        _check_complete(file, frame)
    return files


# A JPEG ends with the EOI marker; some writers append a few bytes (padding, a trailer) after.
_JPEG_END = b"\xff\xd9"
_JPEG_TAIL_BYTES = 4096


def _check_complete(file, frame):
    """Refuse an empty image file or a JPEG without its end marker (a copy cut short), which
    libjpeg would decode with grey where the data stops and only a console warning."""
    try:
        size = file.stat().st_size
        if size == 0:
            raise ZoopraxisError(f"image {file} (frame {frame}) is empty")
        if file.suffix.lower() not in (".jpg", ".jpeg"):
            return
        with open(file, "rb") as stream:
            stream.seek(max(0, size - _JPEG_TAIL_BYTES))
            tail = stream.read()
    except OSError as error:
        raise ZoopraxisError(f"image {file} (frame {frame}): cannot read "
                             f"({error.strerror})") from None
    if _JPEG_END not in tail:
        raise ZoopraxisError(f"image {file} (frame {frame}) is cut off: the JPEG has no end "
                             "marker (copy it again from the source)")


def check_same_length(plates, offsets=None):
    """Check that the views of one take cover the same take frames, and count them.

    Take frame ``f`` is plate frame ``f + offsets[view]`` (0 when not given), so a view covers
    take frames ``0 .. num_frames - offset - 1``. Offsets are not negative: give offset 0 to the
    view that starts last.

    Parameters
    ----------
    plates : dict of str to Plate
        View name -> plate (anything with ``num_frames``).
    offsets : dict of str to int, optional
        View name -> plate frame shown at take frame 0.

    Returns
    -------
    num_frames : int
        The common number of take frames.
    """
    offsets = dict(offsets or {})
    if not plates:
        raise ZoopraxisError("no plates given")
    unknown = sorted(set(offsets) - set(plates))
    if unknown:
        raise ZoopraxisError(
            f"offset given for unknown view '{unknown[0]}' (views: {', '.join(plates)})")
    lengths = {}
    for view, plate in plates.items():
        offset = operator.index(offsets.get(view, 0))
        if offset < 0:
            raise ZoopraxisError(
                f"offset {offset} of view '{view}' is negative: take frame 0 would be plate "
                f"frame {offset} (give offset 0 to the view that starts last)")
        if offset >= plate.num_frames:
            raise ZoopraxisError(
                f"offset {offset} of view '{view}' is past its {plate.num_frames} frames")
        lengths[view] = (plate.num_frames - offset, plate.num_frames, offset)
    if len({n for n, _, _ in lengths.values()}) > 1:
        listed = ", ".join(f"'{v}' {n} ({total} frames, offset {off})"
                           for v, (n, total, off) in lengths.items())
        raise ZoopraxisError(f"views of one take cover different numbers of frames: {listed}")
    return next(iter(lengths.values()))[0]


def parse_frame_range(text, num_frames):
    """Parse the command line's ``--frames START:END`` (END excluded) against a plate.

    Either side may be omitted (``:60``, ``10:``, ``:``); None means the whole plate.

    Returns
    -------
    frames : range
        Non-empty, inside ``0 .. num_frames - 1``.
    """
    if text is None:
        return range(num_frames)
    match = re.fullmatch(r"\s*(-?\d*)\s*:\s*(-?\d*)\s*", text)
    if match is None:
        raise ZoopraxisError(f"--frames '{text}' is not START:END (e.g. 0:60; END excluded)")
    start_text, stop_text = match.groups()
    if start_text.startswith("-") or stop_text.startswith("-"):
        raise ZoopraxisError(f"--frames '{text}': frame numbers cannot be negative")
    start = int(start_text) if start_text else 0
    stop = int(stop_text) if stop_text else num_frames
    if stop > num_frames or start >= stop:
        raise ZoopraxisError(
            f"--frames {start}:{stop} is not a non-empty range inside the plate's "
            f"{num_frames} frames (0:{num_frames})")
    return range(start, stop)
