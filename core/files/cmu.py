"""The CMU motion-capture database in Zoopraxis terms: where the 17 standard joints sit on each
of its skeleton conventions (cgspeed's Motionbuilder and Daz namings, ASF bone names), loading a
CMU capture into the Zoopraxis world (:func:`load_cmu`), and reading a take of any convention
(BVH, or ASF/AMC through ``amc``) with the frame rate and reference frame a ``MANIFEST.tsv``
beside it gives (:func:`read_take`). Reading BVH itself is :mod:`bvh`.

Convention: joints come out in world metres, Z up, in
:data:`~zoopraxis.core.body.joints.STANDARD_JOINTS` order; a CMU length unit is
:data:`CMU_SCALE` metres.
"""

import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import ZoopraxisError
from ..body.joints import STANDARD_JOINTS
from .bvh import Motion, _ROTATION_CHANNELS, read_bvh

CMU_SCALE = 0.056444
"""Metres per CMU length unit (the CMU database's ``(1.0/0.45)*2.54/100``)."""


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


def kept_takes(takes, exclude=(), exclude_subjects=()):
    """Mask of the take names ``takes`` (array of str) that are neither in ``exclude`` nor of
    a subject in ``exclude_subjects`` (a prior's leave-subjects-out at load time)."""
    takes = np.asarray(takes)
    subjects = np.array([subject_of(t) for t in takes])
    return ~np.isin(takes, list(exclude)) & ~np.isin(subjects, [str(s) for s in exclude_subjects])
