"""Motion capture in BVH: reading, forward kinematics and resampling.

A BVH file has a HIERARCHY (joints with an OFFSET from their parent, the CHANNELS they
animate, End Sites closing the chains) and a MOTION block (one line of channel values
per frame). :func:`read_bvh` reads any such file into a :class:`Motion`, which converts itself
into the Zoopraxis world (Z up, metres). What the CMU captures mean in terms of our 17 standard
joints, and their MANIFEST.tsv, is :mod:`cmu`.

Convention (BVH, as written by Biovision and read by Blender's importer):

- A joint's local transform maps its own coordinates into its parent's:
  ``parent_from_joint = [R | offset + p]`` with ``p`` the joint's position channels
  (zero when it has none).
- The rotation channels compose in the order listed, each about the joint's own
  (already rotated) axis -- intrinsic: ``CHANNELS 3 Zrotation Xrotation Yrotation``
  with values ``(a, b, c)`` gives ``R = Rz(a) @ Rx(b) @ Ry(c)``. Angles are degrees.
- Rotations are active and right-handed: ``Rz(90)`` takes +X to +Y.
"""

import math
import re
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..errors import ZoopraxisError

_AXES = "XYZ"
_POSITION_CHANNELS = {a + "position": i for i, a in enumerate(_AXES)}
_ROTATION_CHANNELS = {a + "rotation": i for i, a in enumerate(_AXES)}
_CHANNEL_NAMES = {n.lower(): n for n in (*_POSITION_CHANNELS, *_ROTATION_CHANNELS)}

# world_from_file for each supported up axis of the file. A Y-up file goes to Z up by
# +90 degrees about X, (x, y, z) -> (x, -z, y): a rotation, so left stays left.
_WORLD_FROM_FILE = {
    "y": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]),
    "z": np.eye(3),
}


@dataclass(eq=False)
class Motion:
    """A skeleton and its channel values over time, as stored in a BVH file.

    Parameters
    ----------
    names : list of str, length J
        Joint names, parents before children (file order).
    parents : array of int, shape (J,)
        Index of each joint's parent, -1 for a root.
    offsets : array, shape (J, 3)
        Each joint's origin in its parent's frame, at rest.
    channels : list of tuple of str, length J
        Channel names per joint, in file order (``"Xposition"``, ``"Zrotation"``, ...).
    end_sites : dict of str to array, shape (3,)
        End Site offset in the frame of the joint it closes, by joint name.
    frame_time : float
        Seconds per frame.
    data : array, shape (F, C)
        Raw channel values, C = total number of channels; positions in file units,
        rotations in degrees.
    source : str
        Where the motion came from, for error messages.
    space : {"file", "world"}
        ``"world"`` once :meth:`to_world` has converted it to Z up and metres.
    """

    names: list
    parents: np.ndarray
    offsets: np.ndarray
    channels: list
    end_sites: dict
    frame_time: float
    data: np.ndarray
    source: str = "<motion>"
    space: str = "file"
    _columns: list = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        self.names = list(self.names)
        self.parents = np.asarray(self.parents, dtype=int)
        self.offsets = np.asarray(self.offsets, dtype=float).reshape(len(self.names), 3)
        self.channels = [tuple(c) for c in self.channels]
        self.end_sites = {k: np.asarray(v, dtype=float) for k, v in self.end_sites.items()}
        self.data = np.asarray(self.data, dtype=float)
        num_channels = sum(len(c) for c in self.channels)
        if self.data.ndim != 2 or self.data.shape[1] != num_channels:
            raise ZoopraxisError(f"{self.source}: motion data has shape {self.data.shape}, "
                                 f"expected (frames, {num_channels})")
        if any(p >= j for j, p in enumerate(self.parents)):
            raise ZoopraxisError(f"{self.source}: joints must come after their parents")
        starts = np.cumsum([0] + [len(c) for c in self.channels])
        self._columns = [range(starts[j], starts[j + 1]) for j in range(len(self.names))]

    @property
    def fps(self):
        """Frames per second, ``1 / frame_time`` snapped to an integer within 1e-4.

        BVH writers round the frame time (CMU: ``.0083333``), so 120 fps would otherwise
        read as 120.0005.
        """
        fps = 1.0 / self.frame_time
        return float(round(fps)) if abs(fps - round(fps)) < 1e-4 * fps else fps

    @property
    def num_frames(self):
        """Number of frames F."""
        return self.data.shape[0]

    @property
    def num_joints(self):
        """Number of joints J (End Sites excluded)."""
        return len(self.names)

    def joint_index(self, joint):
        """Index of ``joint`` (a name or an index); ZoopraxisError naming the file if absent."""
        if isinstance(joint, (int, np.integer)):
            return int(joint)
        try:
            return self.names.index(joint)
        except ValueError:
            raise ZoopraxisError(f"{self.source}: no joint named '{joint}'") from None

    def _rows(self, frames):
        if frames is None:
            return self.data
        if isinstance(frames, slice):
            return self.data[frames]
        return self.data[np.atleast_1d(np.asarray(frames))]

    def local_rotations(self, frames=None):
        """Rotation of each joint relative to its parent, from its Euler channels.

        Parameters
        ----------
        frames : None, int, slice or array of int
            Frames to evaluate; all when None.

        Returns
        -------
        parent_from_joint : array, shape (F, J, 3, 3)
            Identity for joints without rotation channels.

        Convention: intrinsic, in channel order: ``R = R_c1 @ R_c2 @ R_c3`` (module doc).
        """
        rows = self._rows(frames)
        rotations = np.broadcast_to(np.eye(3), (len(rows), self.num_joints, 3, 3)).copy()
        for j, names in enumerate(self.channels):
            for column, name in zip(self._columns[j], names):
                axis = _ROTATION_CHANNELS.get(name)
                if axis is not None:
                    rotations[:, j] = rotations[:, j] @ _axis_rotations(axis, rows[:, column])
        return rotations

    def local_translations(self, frames=None):
        """Origin of each joint in its parent's frame: OFFSET plus position channels.

        Returns
        -------
        parent_from_joint_translation : array, shape (F, J, 3)
        """
        rows = self._rows(frames)
        translations = np.broadcast_to(self.offsets, (len(rows), self.num_joints, 3)).copy()
        for j, names in enumerate(self.channels):
            for column, name in zip(self._columns[j], names):
                axis = _POSITION_CHANNELS.get(name)
                if axis is not None:
                    translations[:, j, axis] += rows[:, column]
        return translations

    def root_positions(self, frames=None):
        """Position of the (first) root joint in the motion's space.

        Returns
        -------
        positions : array, shape (F, 3)
        """
        return self.local_translations(frames)[:, 0]

    def global_transforms(self, frames=None):
        """Forward kinematics: each joint's frame in the motion's space.

        Returns
        -------
        space_from_joint : array, shape (F, J, 4, 4)
            Homogeneous transforms; ``[:, j, :3, 3]`` is joint j's origin.

        Convention: ``space_from_joint = space_from_parent @ parent_from_joint`` with
        ``parent_from_joint = [R_local | offset + position channels]``.
        """
        rotations = self.local_rotations(frames)
        translations = self.local_translations(frames)
        transforms = np.zeros(rotations.shape[:2] + (4, 4))
        transforms[..., 3, 3] = 1.0
        for j, p in enumerate(self.parents):
            if p < 0:
                transforms[:, j, :3, :3] = rotations[:, j]
                transforms[:, j, :3, 3] = translations[:, j]
            else:
                parent_rotation = transforms[:, p, :3, :3]
                transforms[:, j, :3, :3] = parent_rotation @ rotations[:, j]
                transforms[:, j, :3, 3] = (
                    np.einsum("fab,fb->fa", parent_rotation, translations[:, j])
                    + transforms[:, p, :3, 3])
        return transforms

    def positions(self, frames=None):
        """Joint origins in the motion's space.

        Returns
        -------
        positions : array, shape (F, J, 3)
        """
        return self.global_transforms(frames)[..., :3, 3]

    def end_site_position(self, joint, frames=None, transforms=None):
        """Position of the End Site closing ``joint`` (a name or an index).

        Parameters
        ----------
        transforms : array, shape (F, J, 4, 4), optional
            Result of :meth:`global_transforms` for the same frames, to avoid recomputing.

        Returns
        -------
        positions : array, shape (F, 3)
        """
        j = self.joint_index(joint)
        name = self.names[j]
        if name not in self.end_sites:
            raise ZoopraxisError(f"{self.source}: joint '{name}' has no End Site")
        if transforms is None:
            transforms = self.global_transforms(frames)
        space_from_joint = transforms[:, j]
        return space_from_joint[:, :3, :3] @ self.end_sites[name] + space_from_joint[:, :3, 3]

    def resampled(self, fps):
        """The same motion at another frame rate.

        When ``self.fps / fps`` is an integer k (120 -> 30: k = 4), every k-th frame is
        taken exactly, starting with the first. Otherwise the new frames are at times
        ``i / fps`` within the capture; position channels are interpolated linearly and
        each joint's rotation by slerp (``scipy.spatial.transform.Slerp``), then written
        back as Euler angles in the joint's channel order, choosing among equivalent
        angle triples (and multiples of 360) the one closest to the linearly
        interpolated channels, so the curves stay continuous. Joints with fewer than
        three rotation channels are interpolated linearly per channel.

        Returns
        -------
        motion : Motion
        """
        if not fps > 0:
            raise ZoopraxisError(f"{self.source}: cannot resample to {fps} fps")
        ratio = self.fps / fps
        step = round(ratio)
        if self.num_frames == 0 or step >= 1 and abs(ratio - step) < 1e-6 * ratio:
            return replace(self, data=self.data[::step].copy(), frame_time=1.0 / fps)

        duration = (self.num_frames - 1) / self.fps
        count = int(math.floor(duration * fps + 1e-9)) + 1
        source_times = np.arange(self.num_frames) / self.fps
        times = np.arange(count) / fps
        # Linear interpolation of every channel: the answer for positions and the
        # reference that picks continuous Euler angles after the slerp.
        data = np.stack([np.interp(times, source_times, column) for column in self.data.T], axis=1)
        if self.num_frames > 1:
            for j, names in enumerate(self.channels):
                columns = [c for c, n in zip(self._columns[j], names) if n in _ROTATION_CHANNELS]
                sequence = "".join(names[c - self._columns[j].start][0] for c in columns)
                if len(sequence) != 3 or sequence[0] == sequence[1] or sequence[1] == sequence[2]:
                    continue
                rotations = Rotation.from_euler(sequence, self.data[:, columns], degrees=True)
                slerped = Slerp(source_times, rotations)(times)
                data[:, columns] = _closest_euler(slerped, sequence, data[:, columns])
        return replace(self, data=data, frame_time=1.0 / fps)

    def to_world(self, scale, up="y"):
        """This motion in the Zoopraxis world: right-handed, Z up, metres.

        Parameters
        ----------
        scale : float
            Metres per file unit (:data:`cmu.CMU_SCALE` for CMU captures).
        up : {"y", "z"}
            The file's up axis.

        Returns
        -------
        motion : Motion
            ``space="world"``; its FK gives ``world = scale * world_from_file @ file``.

        Convention: for a Y-up file ``world_from_file`` is +90 degrees about X,
        ``(x, y, z) -> (x, -z, y)``: a rotation, never a reflection, so the subject's left
        stays left. Offsets, End Sites and position channels are rotated and scaled; every
        joint's rotation is conjugated, ``R' = W @ R @ W.T``, which for an axis permutation
        is exact on the channels themselves: ``Zrotation a`` becomes ``Yrotation -a`` and
        ``Yrotation b`` becomes ``Zrotation b``. The result is again a plain BVH-style
        motion (rest pose Z up) that can be resampled or written out.
        """
        if self.space == "world":
            raise ZoopraxisError(f"{self.source}: motion is already in world space")
        key = str(up).lower()
        if key not in _WORLD_FROM_FILE:
            raise ZoopraxisError(f"{self.source}: unsupported up axis '{up}' (expected 'y' or 'z')")
        if not scale > 0:
            raise ZoopraxisError(f"{self.source}: scale must be positive, got {scale}")
        world_from_file = _WORLD_FROM_FILE[key]
        # Column k of world_from_file is where file axis k lands: world axis m, sign s.
        target_axis = np.abs(world_from_file).argmax(axis=0)
        target_sign = world_from_file[target_axis, np.arange(3)]

        data = self.data.copy()
        channels = []
        for j, names in enumerate(self.channels):
            renamed = []
            for column, name in zip(self._columns[j], names):
                axis, kind = _AXES.index(name[0]), name[1:]
                data[:, column] *= target_sign[axis] * (scale if kind == "position" else 1.0)
                renamed.append(_AXES[target_axis[axis]] + kind)
            channels.append(tuple(renamed))
        return replace(
            self,
            offsets=scale * self.offsets @ world_from_file.T,
            end_sites={k: scale * world_from_file @ v for k, v in self.end_sites.items()},
            channels=channels, data=data, space="world")


def _axis_rotations(axis, degrees):
    """Rotations about one coordinate axis, shape (F, 3, 3), angles in degrees."""
    radians = np.deg2rad(degrees)
    c, s = np.cos(radians), np.sin(radians)
    i, k = [(1, 2), (2, 0), (0, 1)][axis]
    rotations = np.zeros(radians.shape + (3, 3))
    rotations[:, axis, axis] = 1.0
    rotations[:, i, i] = c
    rotations[:, k, k] = c
    rotations[:, i, k] = -s
    rotations[:, k, i] = s
    return rotations


def _closest_euler(rotations, sequence, reference):
    """Intrinsic Euler angles (degrees, shape (F, 3)) of ``rotations`` nearest ``reference``.

    Every rotation has two angle triples (away from gimbal lock), each defined up to
    multiples of 360 per angle; pick the one closest to the reference frame by frame.
    """
    first = rotations.as_euler(sequence, degrees=True)
    proper = sequence[0] == sequence[2]
    second = first + np.array([180.0, 0.0, 180.0])
    second[:, 1] = -first[:, 1] if proper else 180.0 - first[:, 1]
    candidates = []
    for angles in (first, second):
        angles = angles + 360.0 * np.round((reference - angles) / 360.0)
        candidates.append(angles)
    distance = [np.abs(c - reference).sum(axis=1) for c in candidates]
    return np.where((distance[0] <= distance[1])[:, None], candidates[0], candidates[1])


# ---------------------------------------------------------------------------------------
# Reading


def read_bvh(path):
    """Read a BVH file.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    motion : Motion
        In the file's own axes and units (``space="file"``).

    Raises
    ------
    ZoopraxisError
        The file is malformed; the message names the file and line.
    """
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
    except OSError as e:
        raise ZoopraxisError(f"{path}: cannot read BVH file ({e.strerror})") from None
    return parse_bvh(text, source=str(path))


def parse_bvh(text, source="<string>"):
    """Parse the text of a BVH file; see :func:`read_bvh`. ``source`` names it in errors."""
    lines = text.splitlines()
    motion_line = next((i for i, line in enumerate(lines) if line.split()[:1] == ["MOTION"]), None)
    if motion_line is None:
        raise ZoopraxisError(f"{source}:{len(lines) + 1}: missing MOTION section")
    skeleton = _HierarchyParser(lines[:motion_line], source).parse()
    frame_time, data = _parse_motion(lines, motion_line, source,
                                     sum(len(c) for c in skeleton["channels"]))
    return Motion(frame_time=frame_time, data=data, source=source, **skeleton)


class _HierarchyParser:
    """Recursive descent over the HIERARCHY tokens, each tagged with its line number."""

    def __init__(self, lines, source):
        self.source = source
        self.tokens = [(token, n + 1) for n, line in enumerate(lines) for token in line.split()]
        self.position = 0
        self.end_line = len(lines) + 1
        self.names, self.parents, self.offsets, self.channels, self.end_sites = [], [], [], [], {}

    def fail(self, message, line=None):
        raise ZoopraxisError(f"{self.source}:{line or self.end_line}: {message}")

    def next(self, what):
        if self.position >= len(self.tokens):
            self.fail(f"unexpected end of HIERARCHY, expected {what}")
        token = self.tokens[self.position]
        self.position += 1
        return token

    def expect(self, keyword):
        token, line = self.next(f"'{keyword}'")
        if token != keyword:
            self.fail(f"expected '{keyword}', found '{token}'", line)
        return line

    def parse(self):
        self.expect("HIERARCHY")
        while self.position < len(self.tokens):
            token, line = self.next("ROOT")
            if token != "ROOT":
                self.fail(f"expected ROOT or MOTION, found '{token}'", line)
            self.joint(parent=-1)
        if not self.names:
            self.fail("HIERARCHY has no ROOT joint")
        return {"names": self.names, "parents": self.parents, "offsets": self.offsets,
                "channels": self.channels, "end_sites": self.end_sites}

    def numbers(self, count, what):
        values = []
        for _ in range(count):
            token, line = self.next(what)
            try:
                value = float(token)
            except ValueError:
                value = math.nan
            if not math.isfinite(value):
                self.fail(f"{what}: '{token}' is not a finite number", line)
            values.append(value)
        return values

    def joint(self, parent):
        name, line = self.next("a joint name")
        if name in ("{", "}"):
            self.fail(f"expected a joint name, found '{name}'", line)
        if name in self.names:
            self.fail(f"duplicate joint name '{name}'", line)
        index = len(self.names)
        self.names.append(name)
        self.parents.append(parent)
        self.channels.append(())
        self.expect("{")
        self.expect("OFFSET")
        self.offsets.append(self.numbers(3, f"OFFSET of joint '{name}'"))
        while True:
            token, line = self.next(f"'}}' closing joint '{name}'")
            if token == "CHANNELS":
                self.channels[index] = self.channel_list(name, line)
            elif token == "JOINT":
                self.joint(parent=index)
            elif token == "End":
                self.expect("Site")
                self.expect("{")
                self.expect("OFFSET")
                offset = self.numbers(3, f"OFFSET of the End Site of '{name}'")
                self.expect("}")
                # A second End Site under one joint is legal but has no use here.
                self.end_sites.setdefault(name, offset)
            elif token == "}":
                return
            else:
                self.fail(f"unexpected '{token}' in joint '{name}' "
                          "(expected CHANNELS, JOINT, End Site or '}')", line)

    def channel_list(self, name, line):
        token, count_line = self.next("a channel count")
        if not (token.isascii() and token.isdigit()):
            self.fail(f"CHANNELS of joint '{name}': '{token}' is not a count", count_line)
        names = []
        for _ in range(int(token)):
            channel, channel_line = self.next(f"a channel name of joint '{name}'")
            canonical = _CHANNEL_NAMES.get(channel.lower())
            if canonical is None:
                self.fail(f"unknown channel '{channel}' of joint '{name}'", channel_line)
            names.append(canonical)
        return tuple(names)


_FRAMES = re.compile(r"\s*Frames\s*:\s*(\S+)\s*$")
_FRAME_TIME = re.compile(r"\s*Frame\s+Time\s*:\s*(\S+)\s*$")


def _parse_motion(lines, motion_line, source, num_channels):
    """Frame time and channel values, shape (F, C), of the MOTION block."""
    def header(offset, pattern, what, convert, smallest):
        n = motion_line + offset
        match = pattern.match(lines[n]) if n < len(lines) else None
        try:
            value = convert(match.group(1)) if match else None
        except ValueError:
            value = None
        if value is None or not smallest <= value < math.inf:
            found = f"'{lines[n].strip()}'" if n < len(lines) else "end of file"
            raise ZoopraxisError(
                f"{source}:{n + 1}: expected '{what}: <{what.lower()}>', found {found}")
        return value

    num_frames = header(1, _FRAMES, "Frames", int, 0)
    frame_time = header(2, _FRAME_TIME, "Frame Time", float, 1e-9)
    first = motion_line + 3
    numbered = [(first + i + 1, line) for i, line in enumerate(lines[first:]) if line.strip()]
    if len(numbered) != num_frames:
        where = numbered[num_frames][0] if len(numbered) > num_frames else len(lines) + 1
        raise ZoopraxisError(f"{source}:{where}: 'Frames: {num_frames}' but the file has "
                             f"{len(numbered)} frame lines")
    rows = [line.split() for _, line in numbered]
    counts = np.fromiter(map(len, rows), dtype=int, count=len(rows))
    wrong = np.flatnonzero(counts != num_channels)
    if wrong.size:
        n = wrong[0]
        raise ZoopraxisError(f"{source}:{numbered[n][0]}: frame {n} has {counts[n]} values, "
                             f"the HIERARCHY declares {num_channels} channels")
    try:
        data = np.array(rows, dtype=np.float64).reshape(num_frames, num_channels)
    except ValueError:
        for n, row in enumerate(rows):
            for token in row:
                try:
                    float(token)
                except ValueError:
                    raise ZoopraxisError(f"{source}:{numbered[n][0]}: frame {n} has "
                                         f"'{token}', not a number") from None
        raise
    bad = ~np.isfinite(data)
    if bad.any():
        n, c = np.argwhere(bad)[0]
        raise ZoopraxisError(f"{source}:{numbered[n][0]}: frame {n} has '{rows[n][c]}', "
                             "not a finite number")
    return frame_time, data
