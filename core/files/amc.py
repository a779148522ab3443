"""Acclaim motion capture (ASF skeleton, AMC motion), the CMU database's own format.

:func:`read_amc` turns an AMC file and its ASF skeleton into a :class:`~.bvh.Motion`, the
shape in which every other capture is handled (forward kinematics, world conversion,
resampling, standard joints), with one joint per ASF bone, named as in the ASF.

Convention (Acclaim, as CMU writes it):

- Each bone has a direction and a length (the bone's vector at rest, in the skeleton's own
  axes: Y up for CMU) and an ``axis``: the orientation ``C`` of the bone's local frame, three
  angles applied about the fixed X, Y, Z axes in the order named (``XYZ``: ``C = Rz Ry Rx``).
- An AMC line gives a bone's ``dof`` values; they rotate the bone in its local frame, each
  about a fixed axis in the order of the ``dof`` line (``rx ry rz``: ``M = Rz Ry Rx``). In
  the skeleton's axes the bone turns by ``L = C M C^-1`` relative to its parent.
- A bone starts where its parent ends (the root's children at the root) and turns the
  bones below it. The root takes ``order`` values (``TX TY TZ RX RY RZ``), its frame given by
  ``orientation`` in the ``axis`` order.

As a Motion, every joint's rest frame is the skeleton's axes (as amc2bvh writes it): joint j
sits at the start of bone j with OFFSET the parent bone's vector, its rotation channels
``Zrotation Yrotation Xrotation`` hold ``L`` as intrinsic Z Y X angles, and a bone without
children closes with an End Site at its own vector. The root is called ``hip``, as amc2bvh
calls it, so that such BVH files and AMC files share one skeleton (``cmu.SKELETONS``).
"""

import math
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from .bvh import Motion
from ..errors import ZoopraxisError

ROOT_NAME = "hip"
AMC_FPS = 120.0
"""CMU's capture rate; an AMC file carries none."""

_ROTATIONS = {"rx": 0, "ry": 1, "rz": 2}
_TRANSLATIONS = {"tx": 0, "ty": 1, "tz": 2}


def _fixed_axis_rotation(angles_deg, order):
    """Rotations, shape (F, 3, 3), of angles (F, k) about fixed axes applied in ``order``
    (a string of x, y, z): the first named turns first."""
    return Rotation.from_euler(order.lower(), angles_deg, degrees=True).as_matrix()


class _Bone:
    def __init__(self):
        self.name = None
        self.direction = None
        self.length = None
        self.axis = None            # (angles (3,), order)
        self.dof = ()


def _read_text(path, what):
    try:
        with open(path, encoding="utf-8", errors="replace") as f:
            return f.read()
    except OSError as e:
        raise ZoopraxisError(f"{path}: cannot read {what} file ({e.strerror})") from None


def _numbers(tokens, count, where, what):
    if len(tokens) < count:
        raise ZoopraxisError(f"{where}: {what} needs {count} numbers, found {len(tokens)}")
    try:
        values = [float(t) for t in tokens[:count]]
    except ValueError:
        values = [math.nan]
    if not all(math.isfinite(v) for v in values):
        raise ZoopraxisError(f"{where}: {what}: '{' '.join(tokens[:count])}' are not "
                             "finite numbers")
    return values


def parse_asf(text, source="<asf>"):
    """The skeleton of an ASF file.

    Returns
    -------
    skeleton : dict
        ``units`` (file length unit, as given), ``root_order`` (list of AMC channel names),
        ``root_axis`` (order string), ``root_position`` (3,), ``root_orientation`` (3,),
        ``bones`` (name -> _Bone), ``children`` (name -> list of names; ``"root"``'s first).

    Raises
    ------
    ZoopraxisError
        Naming the file and line.
    """
    section = None
    root = {"order": None, "axis": "XYZ", "position": [0.0] * 3, "orientation": [0.0] * 3}
    bones, children, bone, angle_unit = {}, {}, None, "deg"
    limits = False
    for n, raw in enumerate(text.splitlines(), 1):
        where = f"{source}:{n}"
        tokens = raw.split()
        if not tokens or tokens[0].startswith("#"):
            continue
        key = tokens[0]
        if key.startswith(":"):
            section, limits = key[1:].lower(), False
            continue
        if section == "units" and key == "angle":
            angle_unit = tokens[1].lower() if len(tokens) > 1 else ""
            if angle_unit not in ("deg", "rad"):
                raise ZoopraxisError(f"{where}: unknown angle unit '{' '.join(tokens[1:])}'")
        elif section == "root":
            if key == "order":
                root["order"] = [t.lower() for t in tokens[1:]]
                unknown = [t for t in root["order"] if t not in _ROTATIONS | _TRANSLATIONS]
                if unknown:
                    raise ZoopraxisError(f"{where}: unknown root channel '{unknown[0]}'")
            elif key == "axis":
                root["axis"] = tokens[1].upper() if len(tokens) > 1 else ""
            elif key in ("position", "orientation"):
                root[key] = _numbers(tokens[1:], 3, where, f"root {key}")
        elif section == "bonedata":
            if key == "begin":
                bone, limits = _Bone(), False
            elif bone is None:
                raise ZoopraxisError(f"{where}: '{key}' outside a begin/end bone block")
            elif key == "end":
                for field, what in (("name", "name"), ("direction", "direction"),
                                    ("length", "length"), ("axis", "axis")):
                    if getattr(bone, field) is None:
                        raise ZoopraxisError(f"{where}: bone {bone.name or '?'} has no {what}")
                if bone.name in bones or bone.name in ("root", ROOT_NAME):
                    raise ZoopraxisError(f"{where}: duplicate bone name '{bone.name}'")
                bones[bone.name], bone = bone, None
            elif key == "name" and len(tokens) > 1:
                bone.name = tokens[1]
            elif key == "direction":
                bone.direction = np.array(_numbers(tokens[1:], 3, where, "direction"))
            elif key == "length":
                bone.length = _numbers(tokens[1:], 1, where, "length")[0]
            elif key == "axis":
                angles = _numbers(tokens[1:], 3, where, "axis")
                order = tokens[4].upper() if len(tokens) > 4 else ""
                if sorted(order) != ["X", "Y", "Z"]:
                    raise ZoopraxisError(f"{where}: axis order '{order}' is not a "
                                         "permutation of XYZ")
                bone.axis = (np.array(angles), order)
            elif key == "dof":
                bone.dof = tuple(t.lower() for t in tokens[1:])
                unknown = [t for t in bone.dof if t not in _ROTATIONS]
                if unknown:
                    raise ZoopraxisError(f"{where}: bone {bone.name}: unsupported dof "
                                         f"'{unknown[0]}'")
            elif key == "limits":
                limits = True
            elif key in ("id", "bodymass", "cofmass") or limits:
                continue
            else:
                raise ZoopraxisError(f"{where}: unexpected '{key}' in bone {bone.name or '?'}")
        elif section == "hierarchy" and key not in ("begin", "end"):
            parent = "root" if key == "root" else key
            if parent != "root" and parent not in bones:
                raise ZoopraxisError(f"{where}: hierarchy names unknown bone '{key}'")
            for child in tokens[1:]:
                if child not in bones:
                    raise ZoopraxisError(f"{where}: hierarchy names unknown bone '{child}'")
                children.setdefault(parent, []).append(child)
    if root["order"] is None:
        raise ZoopraxisError(f"{source}: no :root order line")
    if sorted(root["axis"]) != ["X", "Y", "Z"]:
        raise ZoopraxisError(f"{source}: root axis '{root['axis']}' is not a permutation of XYZ")
    if not bones or "root" not in children:
        raise ZoopraxisError(f"{source}: no bones under the root in :hierarchy")
    if angle_unit == "rad":
        for b in bones.values():
            b.axis = (np.degrees(b.axis[0]), b.axis[1])
        root["orientation"] = list(np.degrees(root["orientation"]))
    return {"root": root, "bones": bones, "children": children, "radians": angle_unit == "rad"}


def _bone_order(children):
    """Bones in parent-before-child order (depth first from the root), with parents."""
    order, stack = [], [(c, "root") for c in reversed(children["root"])]
    seen = set()
    while stack:
        name, parent = stack.pop()
        if name in seen:
            raise ZoopraxisError(f"bone '{name}' appears twice in :hierarchy")
        seen.add(name)
        order.append((name, parent))
        stack += [(c, name) for c in reversed(children.get(name, []))]
    return order


def parse_amc(text, skeleton, source="<amc>"):
    """Per-frame root channels and bone dof values of an AMC file.

    Returns
    -------
    root : array, shape (F, len(root order))
    dofs : dict of bone name -> array, shape (F, len(bone dof))
        Zeros for bones the file never names.
    """
    bones = skeleton["bones"]
    widths = {"root": len(skeleton["root"]["order"])}
    widths.update({name: len(b.dof) for name, b in bones.items()})
    frames, current, numbers = [], None, []
    for n, raw in enumerate(text.splitlines(), 1):
        tokens = raw.split()
        if not tokens or tokens[0].startswith(("#", ":")):
            continue
        if len(tokens) == 1 and tokens[0].isascii() and tokens[0].isdigit():
            current = {}
            frames.append(current)
            numbers.append(n)
            continue
        name = tokens[0]
        where = f"{source}:{n}"
        if current is None:
            raise ZoopraxisError(f"{where}: '{name}' before the first frame number")
        if name not in widths:
            raise ZoopraxisError(f"{where}: no bone named '{name}' in the skeleton")
        if len(tokens) - 1 != widths[name]:
            raise ZoopraxisError(f"{where}: bone {name} has {len(tokens) - 1} values, the "
                                 f"skeleton gives it {widths[name]}")
        current[name] = _numbers(tokens[1:], widths[name], where, f"bone {name}")
    if not frames:
        raise ZoopraxisError(f"{source}: no frames")
    missing = [k for k, f in enumerate(frames) if "root" not in f]
    if missing:
        raise ZoopraxisError(f"{source}:{numbers[missing[0]]}: frame has no root line")
    root = np.array([f["root"] for f in frames])
    dofs = {name: np.array([f.get(name, [0.0] * widths[name]) for f in frames])
            .reshape(len(frames), widths[name]) for name in bones}
    return root, dofs


def motion_from_asf_amc(skeleton, root, dofs, source="<amc>", fps=AMC_FPS):
    """The :class:`~.bvh.Motion` of an ASF skeleton and its AMC values (module doc).

    Returns
    -------
    motion : Motion
        In the file's axes and units (``space="file"``), at ``fps``.
    """
    order = _bone_order(skeleton["children"])
    names = [ROOT_NAME] + [name for name, _ in order]
    index = {"root": 0, **{name: k + 1 for k, (name, _) in enumerate(order)}}
    bones = skeleton["bones"]
    radians = skeleton["radians"]
    F = len(root)
    info = skeleton["root"]
    offsets = [np.array(info["position"], float)]
    parents = [-1]
    for name, parent in order:
        parents.append(index[parent])
        offsets.append(np.zeros(3) if parent == "root"
                       else bones[parent].length * bones[parent].direction)
    end_sites = {name: bones[name].length * bones[name].direction
                 for name, _ in order if name not in skeleton["children"]}

    def local(axis_deg, axis_order, values, dof):
        C = _fixed_axis_rotation(np.asarray(axis_deg, float)[None], axis_order)[0]
        angles = np.degrees(values) if radians else values
        M = np.broadcast_to(np.eye(3), (F, 3, 3))
        if dof:
            M = _fixed_axis_rotation(angles, "".join(d[1] for d in dof))
        return C @ M @ C.T

    root_order = info["order"]
    rot = [c for c in root_order if c in _ROTATIONS]
    root_values = root[:, [root_order.index(c) for c in rot]]
    translation = np.zeros((F, 3))
    for c in root_order:
        if c in _TRANSLATIONS:
            translation[:, _TRANSLATIONS[c]] = root[:, root_order.index(c)]
    rotations = [local(info["orientation"], info["axis"], root_values, rot)]
    for name, _ in order:
        bone = bones[name]
        rotations.append(local(bone.axis[0], bone.axis[1], dofs[name], bone.dof))
    # Intrinsic Z Y X angles of each local rotation: the channels Zrotation Yrotation Xrotation.
    euler = [Rotation.from_matrix(r).as_euler("ZYX", degrees=True) for r in rotations]
    data = np.hstack([translation] + euler)
    channels = [("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")]
    channels += [("Zrotation", "Yrotation", "Xrotation")] * len(order)
    return Motion(names, parents, np.array(offsets), channels, end_sites, 1.0 / fps, data,
                  source=source)


def find_asf(amc_path):
    """The ASF skeleton of an AMC file: ``SUBJECT.asf`` beside ``SUBJECT_TRIAL.amc``, or the
    only ASF in its folder."""
    amc_path = Path(amc_path)
    named = amc_path.with_name(amc_path.stem.split("_")[0] + ".asf")
    if named.is_file():
        return named
    others = sorted(amc_path.parent.glob("*.asf"))
    if len(others) == 1:
        return others[0]
    raise ZoopraxisError(f"{amc_path}: no skeleton file {named.name} beside it")


def read_amc(path, asf=None, fps=AMC_FPS):
    """Read an AMC file and its ASF skeleton (:func:`find_asf` unless given) as a Motion.

    Returns
    -------
    motion : Motion
        File axes and units (for CMU: Y up, ``cmu.CMU_SCALE`` metres per unit), ``fps``.

    Raises
    ------
    ZoopraxisError
        A missing or malformed file; the message names it and the line.
    """
    asf = Path(asf) if asf is not None else find_asf(path)
    skeleton = parse_asf(_read_text(asf, "ASF"), source=str(asf))
    root, dofs = parse_amc(_read_text(path, "AMC"), skeleton, source=str(path))
    return motion_from_asf_amc(skeleton, root, dofs, source=str(path), fps=fps)
