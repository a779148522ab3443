"""Motion capture in BVH: reading, forward kinematics, resampling, and the standard joints.

A BVH file has a HIERARCHY (joints with an OFFSET from their parent, the CHANNELS they
animate, End Sites closing the chains) and a MOTION block (one line of channel values
per frame). :func:`read_bvh` reads any such file into a :class:`Motion`;
:func:`load_cmu` also converts a CMU capture into the Zoopraxis world (Z up, metres),
and :func:`standard_joints` reduces it to the 17 standard joints of the design contract.
:func:`read_take` reads a capture of any CMU convention (cgspeed's Motionbuilder and Daz
namings, ASF bone names, ASF/AMC through ``amc``) with the frame rate and reference frame
a ``MANIFEST.tsv`` beside it gives.

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
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from ..errors import ZoopraxisError
from ..body.joints import STANDARD_JOINTS

CMU_SCALE = 0.056444
"""Metres per CMU length unit (the CMU database's ``(1.0/0.45)*2.54/100``)."""

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
            Metres per file unit (:data:`CMU_SCALE` for CMU captures).
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


# ---------------------------------------------------------------------------------------
# Standard joints


@dataclass(frozen=True)
class JointRule:
    """Where one standard joint sits on a skeleton, and which bone carries it.

    The position is the mean of the origins of the joints ``at``, plus ``along`` times
    the vector from ``bone``'s origin to its End Site (the head's centre is half-way up
    the head bone), plus ``shift`` (metres, in ``bone``'s own frame, which for the
    skeletons here is the world's at rest: Z up). Its frame turns with ``bone``.
    """

    at: tuple
    bone: str
    along: float = 0.0
    shift: tuple = (0.0, 0.0, 0.0)


def _side(prefix, names, toe_along=0.0):
    """Rules for one side; ``names`` lists hip, knee, ankle, toe, shoulder, elbow, wrist.
    With ``toe_along`` the toe is that far along the toe bone towards its End Site."""
    hip, knee, ankle, toe, shoulder, elbow, wrist = names
    return {f"{prefix}_hip": JointRule((hip,), hip), f"{prefix}_knee": JointRule((knee,), knee),
            f"{prefix}_ankle": JointRule((ankle,), ankle),
            f"{prefix}_toe": JointRule((toe,), toe, along=toe_along),
            f"{prefix}_shoulder": JointRule((shoulder,), shoulder),
            f"{prefix}_elbow": JointRule((elbow,), elbow),
            f"{prefix}_wrist": JointRule((wrist,), wrist)}


SKELETONS = {
    # CMU, cgspeed's Motionbuilder-friendly BVH conversion (01_01.bvh, cmu_more/bvh_mb). Neck
    # runs from the top of the thorax; Neck1 starts at shoulder height, the base of the
    # visible neck.
    "cmu_cgspeed": {
        "pelvis": JointRule(("LeftUpLeg", "RightUpLeg"), "Hips"),
        "neck": JointRule(("Neck1",), "Neck1"),
        "head": JointRule(("Head",), "Head", along=0.5),
        **_side("l", ("LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase",
                      "LeftArm", "LeftForeArm", "LeftHand")),
        **_side("r", ("RightUpLeg", "RightLeg", "RightFoot", "RightToeBase",
                      "RightArm", "RightForeArm", "RightHand")),
    },
    # CMU with joint-named bones (131_*.bvh): LeftHip is the thigh, LeftShoulder the upper
    # arm, LeftCollar the clavicle; lowerneck starts at the top of the thorax, Neck at
    # shoulder height.
    "cmu_jointnames": {
        "pelvis": JointRule(("LeftHip", "RightHip"), "Hips"),
        "neck": JointRule(("Neck",), "Neck"),
        "head": JointRule(("Head",), "Head", along=0.5),
        **_side("l", ("LeftHip", "LeftKnee", "LeftAnkle", "LeftToe",
                      "LeftShoulder", "LeftElbow", "LeftWrist")),
        **_side("r", ("RightHip", "RightKnee", "RightAnkle", "RightToe",
                      "RightShoulder", "RightElbow", "RightWrist")),
    },
    # CMU's own ASF bone names (ASF/AMC read by ``amc``, and amc2bvh's output with the root
    # called ``hip``): each BVH joint sits at the start of its bone, so lfemur is the hip
    # joint, lhumerus the shoulder; upperneck starts at shoulder height.
    "cmu_asf": {
        "pelvis": JointRule(("lfemur", "rfemur"), "hip"),
        "neck": JointRule(("upperneck",), "upperneck"),
        "head": JointRule(("head",), "head", along=0.5),
        **_side("l", ("lfemur", "ltibia", "lfoot", "ltoes", "lhumerus", "lradius", "lwrist")),
        **_side("r", ("rfemur", "rtibia", "rfoot", "rtoes", "rhumerus", "rradius", "rwrist")),
    },
    # cgspeed's Daz-friendly conversion: every subject on one Daz figure (centimetres). The
    # foot has no toe joint: its End Site is the ball of the foot. The head bone starts at
    # the base of the skull and its children are the eyes, 8 cm up: the head's centre.
    "cmu_daz": {
        "pelvis": JointRule(("lThigh", "rThigh"), "hip"),
        "neck": JointRule(("neck",), "neck"),
        "head": JointRule(("head",), "head", shift=(0.0, 0.0, 0.08)),
        **_side("l", ("lThigh", "lShin", "lFoot", "lFoot", "lShldr", "lForeArm", "lHand"),
                toe_along=1.0),
        **_side("r", ("rThigh", "rShin", "rFoot", "rFoot", "rShldr", "rForeArm", "rHand"),
                toe_along=1.0),
    },
}
"""Skeleton name -> {standard joint -> JointRule}; add an entry to support a new skeleton."""

SKELETON_SCALE = {"cmu_cgspeed": CMU_SCALE, "cmu_jointnames": CMU_SCALE, "cmu_asf": CMU_SCALE,
                  "cmu_daz": 0.01}
"""Metres per file unit of each skeleton's files (Daz figures are in centimetres)."""

SKELETON_FAMILIES = {"cmu": ("cmu_cgspeed", "cmu_jointnames", "cmu_asf", "cmu_daz")}
"""Names that stand for whichever member skeleton's joints a motion has."""


def skeleton_of(motion, skeleton="cmu"):
    """The member of :data:`SKELETON_FAMILIES` (or the skeleton itself) whose rules map
    ``motion``'s joints.

    Raises
    ------
    ZoopraxisError
        No member maps it: the message names the file and a joint that the closest
        skeleton (the one missing fewest) needs and the motion lacks.
    """
    candidates = SKELETON_FAMILIES.get(skeleton, (skeleton,))
    closest = None
    for name in candidates:
        if name not in SKELETONS:
            raise ZoopraxisError(f"unknown skeleton '{skeleton}' "
                                 f"(expected one of {', '.join([*SKELETONS, *SKELETON_FAMILIES])})")
        needed = {j for rule in SKELETONS[name].values() for j in (*rule.at, rule.bone)}
        missing = sorted(needed - set(motion.names))
        if not missing:
            return name
        if closest is None or len(missing) < len(closest[1]):
            closest = (name, missing)
    name, missing = closest
    also = f" and {len(missing) - 1} more" if len(missing) > 1 else ""
    raise ZoopraxisError(f"{motion.source}: not a '{skeleton}' skeleton (no joint "
                         f"'{missing[0]}'{also}; closest: {name})")


def _rules(motion, skeleton):
    return SKELETONS[skeleton_of(motion, skeleton)]


def _standard(motion, skeleton, frames):
    if motion.space != "world":
        raise ZoopraxisError(f"{motion.source}: convert the motion with to_world() "
                             "before taking standard joints")
    rules = _rules(motion, skeleton)
    transforms = motion.global_transforms(frames)
    positions = transforms[..., :3, 3]
    result = np.zeros((len(transforms), len(STANDARD_JOINTS), 4, 4))
    result[..., 3, 3] = 1.0
    for k, joint in enumerate(STANDARD_JOINTS):
        rule = rules[joint]
        bone = motion.joint_index(rule.bone)
        point = positions[:, [motion.joint_index(a) for a in rule.at]].mean(axis=1)
        if rule.along:
            tip = motion.end_site_position(bone, transforms=transforms)
            point = point + rule.along * (tip - positions[:, bone])
        if any(rule.shift):
            point = point + transforms[:, bone, :3, :3] @ np.asarray(rule.shift, float)
        result[:, k, :3, :3] = transforms[:, bone, :3, :3]
        result[:, k, :3, 3] = point
    return result


def standard_joints(motion, skeleton="cmu", frames=None):
    """The 17 standard joints of a motion in world space.

    Parameters
    ----------
    motion : Motion
        Converted with :meth:`Motion.to_world` (world metres, Z up).
    skeleton : str
        A key of :data:`SKELETONS` or :data:`SKELETON_FAMILIES`.
    frames : None, int, slice or array of int

    Returns
    -------
    positions : array, shape (F, 17, 3)
        In :data:`~zoopraxis.core.body.joints.STANDARD_JOINTS` order, world metres.
    """
    return _standard(motion, skeleton, frames)[..., :3, 3]


def standard_joint_frames(motion, skeleton="cmu", frames=None):
    """World transforms of the bone that starts at each standard joint.

    Returns
    -------
    world_from_bone : array, shape (F, 17, 4, 4)
        Rotation of the bone's BVH joint (``JointRule.bone``), origin at the standard
        joint (:func:`standard_joints`). Shapes fixed in this frame follow the bone rigidly.

    Convention: the axes are the BVH joint's own, not aligned with the bone; the bone's
    direction in this frame is its child's OFFSET (after :meth:`Motion.to_world`). For
    CMU every joint's rest orientation is the world's, so at rest the axes are world axes.
    """
    return _standard(motion, skeleton, frames)


def load_cmu(path, fps=None):
    """Read a CMU BVH capture into world space (Z up, metres), optionally resampled.

    Returns
    -------
    motion : Motion
        ``read_bvh(path).to_world(CMU_SCALE, up="y")``, then ``.resampled(fps)`` if given.
    """
    motion = read_bvh(path).to_world(CMU_SCALE, up="y")
    return motion.resampled(fps) if fps is not None else motion


# ---------------------------------------------------------------------------------------
# Takes of any CMU convention, with the corrections of a MANIFEST.tsv


MANIFEST_NAME = "MANIFEST.tsv"


@dataclass(frozen=True)
class TakeInfo:
    """What a manifest says about one take: its true frame rate and whether the file starts
    with an inserted reference pose."""

    fps: float
    tpose: bool


_CAPTURE_FPS = re.compile(r"CMU capture\s+(\d+(?:\.\d+)?)\s*fps|^\s*(\d+(?:\.\d+)?)\s*fps")


def read_manifest(path):
    """Frame rates and reference frames of the takes of a folder's ``MANIFEST.tsv``.

    The file is tab-separated with a header line; the columns used are ``file`` (a path
    relative to the folder), ``frame_rate`` (the capture rate follows ``CMU capture``, or
    leads: ``120 fps (...)``) and ``frame_count`` (``incl. T-pose frame 0`` marks an inserted
    reference pose).

    Returns
    -------
    takes : dict of str to TakeInfo
        Keyed by file stem (``"60_05"``).

    Raises
    ------
    ZoopraxisError
        Unreadable, or a row without a frame rate (naming the line).
    """
    path = Path(path)
    try:
        lines = path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as e:
        raise ZoopraxisError(f"{path}: cannot read manifest ({e.strerror})") from None
    if not lines:
        raise ZoopraxisError(f"{path}: empty manifest")
    head = lines[0].split("\t")
    try:
        columns = [head.index(k) for k in ("file", "frame_rate", "frame_count")]
    except ValueError:
        raise ZoopraxisError(f"{path}:1: manifest header needs the columns file, "
                             "frame_rate and frame_count") from None
    takes = {}
    for n, line in enumerate(lines[1:], 2):
        cells = line.split("\t")
        if not line.strip():
            continue
        if len(cells) <= max(columns):
            raise ZoopraxisError(f"{path}:{n}: {len(cells)} columns, expected {len(head)}")
        name, rate, count = (cells[k] for k in columns)
        match = _CAPTURE_FPS.search(rate)
        if match is None:
            raise ZoopraxisError(f"{path}:{n}: no frame rate in '{rate}'")
        fps = float(match.group(1) or match.group(2))
        takes[Path(name).stem] = TakeInfo(fps, "T-pose frame 0" in count)
    return takes


def _manifest_for(path):
    for folder in (path.parent, path.parent.parent):
        candidate = folder / MANIFEST_NAME
        if candidate.is_file():
            return read_manifest(candidate)
    return {}


@dataclass(eq=False)
class Take:
    """A motion-capture take in the Zoopraxis world, whatever convention its file uses.

    Attributes
    ----------
    name : str
        The file's stem, CMU's ``SUBJECT_TRIAL`` (``"02_01"``).
    subject : str
        The performer: the part of the name before ``_``.
    motion : Motion
        World space (Z up, metres) at the take's true frame rate, reference frame dropped.
    skeleton : str
        The key of :data:`SKELETONS` that maps its joints.
    """

    name: str
    subject: str
    motion: Motion
    skeleton: str

    @property
    def fps(self):
        return self.motion.fps

    def joints(self, fps=None):
        """The 17 standard joints, world metres, shape (F, 17, 3), resampled to ``fps``."""
        motion = self.motion.resampled(fps) if fps is not None else self.motion
        return standard_joints(motion, self.skeleton)


def _is_reference_frame(motion):
    """A file whose first frame's root rotation is exactly zero and whose second frame's is
    not starts with an inserted reference pose (no capture holds the root that still)."""
    if motion.num_frames < 2:
        return False
    columns = [c for c, n in zip(motion._columns[0], motion.channels[0])
               if n in _ROTATION_CHANNELS]
    return bool(columns) and not motion.data[0, columns].any() and \
        bool(motion.data[1, columns].any())


def read_take(path, manifest=None):
    """Read a capture of any supported convention (BVH of every :data:`SKELETONS` naming,
    or AMC with its ASF) into world space with its standard-joint rules.

    The frame rate and the reference frame come from ``manifest`` (a :func:`read_manifest`
    result; by default the ``MANIFEST.tsv`` in the file's folder or the one above, if any)
    when it lists the take: a header that states the wrong rate is overruled and an inserted
    T-pose frame 0 dropped. A take it does not list keeps its header's rate (AMC: 120 fps)
    and loses frame 0 only if that frame is a reference pose (root rotation exactly zero).

    Returns
    -------
    take : Take

    Raises
    ------
    ZoopraxisError
        Unreadable or malformed, or a skeleton no rule maps (naming a joint it lacks).
    """
    path = Path(path)
    info = (_manifest_for(path) if manifest is None else manifest).get(path.stem)
    if path.suffix.lower() == ".amc":
        from .amc import AMC_FPS, read_amc

        motion = read_amc(path, fps=info.fps if info else AMC_FPS)
    else:
        motion = read_bvh(path)
        if info is not None:
            motion = replace(motion, frame_time=1.0 / info.fps)
    drop = info.tpose if info is not None else _is_reference_frame(motion)
    if drop:
        motion = replace(motion, data=motion.data[1:])
    skeleton = skeleton_of(motion)
    motion = motion.to_world(SKELETON_SCALE[skeleton], up="y")
    return Take(path.stem, subject_of(path.stem), motion, skeleton)


def capture_paths(*folders, hold_out=()):
    """The captures (``.bvh``, ``.amc``) under the folders, sorted, without those of the
    subjects ``hold_out`` (CMU's ``SUBJECT`` of ``SUBJECT_TRIAL``, as strings: ``"02"``).

    Raises
    ------
    ZoopraxisError
        A folder that does not exist.
    """
    paths = []
    for folder in map(Path, folders):
        if not folder.is_dir():
            raise ZoopraxisError(f"{folder}: no such folder")
        paths += [p for p in folder.rglob("*") if p.suffix.lower() in (".bvh", ".amc")]
    held = {str(s) for s in hold_out}
    return sorted((p for p in paths if subject_of(p.stem) not in held), key=str)


def subject_of(take):
    """The CMU subject of a take's name: ``"02"`` of ``"02_01"`` (the name itself if it has
    no ``_``)."""
    return str(take).split("_")[0]
