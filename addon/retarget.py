"""Retargeting a take onto an existing rig: naming presets, bone maps, world-orientation copy.

Each mapped target bone takes, frame by frame, the world-space rotation its body segment made
from the reference configuration, applied to the bone's own rest orientation: rest rolls and
axes of the target rig do not matter. Unmapped bones above mapped ones keep their rest pose
(keyed as such), so mapped children inherit nothing stray. The bone mapped to the pelvis also
follows the pelvis position, scaled by the ratio of leg lengths.
"""

import json
from pathlib import Path

import numpy as np

from ..core.errors import ZoopraxisError
from . import keying
from .motion import invert

_SIDES = {"l": ("Left", ".L"), "r": ("Right", ".R")}

PRESETS = (
    ('NONE', "Bone Map Only", "Map bones only through the bone map"),
    ('MIXAMO', "Mixamo", "Mixamo names (mixamorig:Hips, mixamorig:LeftArm, ...)"),
    ('RIGIFY', "Rigify", "Rigify names: DEF-, ORG- or metarig bones (spine, upper_arm.L, ...)"),
)


def _mixamo(prefix):
    m = {"pelvis": "Hips", "abdomen": "Spine", "chest": "Spine2", "head": "Neck"}
    for s, (side, _) in _SIDES.items():
        m.update({f"{s}_upper_arm": f"{side}Arm", f"{s}_forearm": f"{side}ForeArm",
                  f"{s}_thigh": f"{side}UpLeg", f"{s}_shank": f"{side}Leg",
                  f"{s}_foot": f"{side}Foot"})
    return {k: prefix + v for k, v in m.items()}


def _rigify(prefix):
    m = {"pelvis": "spine", "abdomen": "spine.001", "chest": "spine.003", "head": "spine.004"}
    for s, (_, suffix) in _SIDES.items():
        m.update({f"{s}_upper_arm": f"upper_arm{suffix}", f"{s}_forearm": f"forearm{suffix}",
                  f"{s}_thigh": f"thigh{suffix}", f"{s}_shank": f"shin{suffix}",
                  f"{s}_foot": f"foot{suffix}"})
    return {k: prefix + v for k, v in m.items()}


def preset_map(preset, bone_names):
    """The preset's segment -> bone names, with the prefix the rig uses.

    Mixamo rigs prefix their bones ``mixamorig:`` (or ``mixamorig1:`` ...); the prefix is read
    off the rig's hips bone. Rigify is tried as DEF-, ORG- and metarig names, in that order,
    taking the first whose pelvis bone the rig has.
    """
    names = set(bone_names)
    if preset == 'MIXAMO':
        hips = sorted(n for n in names if n.endswith("Hips"))
        return _mixamo(hips[0][:-4] if hips else "mixamorig:")
    if preset == 'RIGIFY':
        for prefix in ("DEF-", "ORG-", ""):
            if prefix + "spine" in names:
                return _rigify(prefix)
        return _rigify("DEF-")
    if preset in ('NONE', None):
        return {}
    raise ZoopraxisError(f"unknown bone naming preset '{preset}' "
                         f"(expected {', '.join(p[0] for p in PRESETS)})")


def read_bone_map(path):
    """Read a bone map JSON file: ``{"segment": "bone", ...}``."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise ZoopraxisError(f"{path}: no such bone map file") from None
    except json.JSONDecodeError as ex:
        raise ZoopraxisError(f"{path}: not valid JSON ({ex.msg} at line {ex.lineno})") from None
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise ZoopraxisError(f"{path}: a bone map maps segment names to bone names")
    return data


def resolve_bone_map(rig, segment_names, *, preset=None, bone_map=None):
    """Segment -> target bone, from a preset overridden by a user map, checked against the rig.

    Raises
    ------
    ZoopraxisError
        Naming the first mapped bone the rig lacks, or an unknown segment in the user map.
    """
    if rig is None or rig.type != 'ARMATURE':
        raise ZoopraxisError(f"'{getattr(rig, 'name', None)}' is not an armature")
    bones = rig.data.bones
    mapping = {k: v for k, v in preset_map(preset, bones.keys()).items() if k in segment_names}
    for segment, bone in (bone_map or {}).items():
        if segment not in segment_names:
            raise ZoopraxisError(f"bone map: unknown segment '{segment}' (segments: "
                                 f"{', '.join(segment_names)})")
        if bone:
            mapping[segment] = bone
    if not mapping:
        raise ZoopraxisError(f"rig '{rig.name}': no bones mapped (choose a preset or fill the "
                             "bone map)")
    for segment in segment_names:
        bone = mapping.get(segment)
        if bone is not None and bone not in bones:
            raise ZoopraxisError(f"rig '{rig.name}' has no bone '{bone}' (mapped from segment "
                                 f"'{segment}')")
    return mapping


def _leg_scale(rig, mapping, body, world_scale):
    """Target leg length over the body's, for root motion (1 when legs are not mapped)."""
    bones = rig.data.bones
    for side in ("l", "r"):
        thigh, shank = mapping.get(f"{side}_thigh"), mapping.get(f"{side}_shank")
        if thigh and shank:
            length = (bones[thigh].length + bones[shank].length) * world_scale
            return length / (body.dims["thigh"] + body.dims["shank"])
    return 1.0


def retarget(rig, body, seg2world, times, mapping, *, action_name, report=print):
    """Key the motion of ``seg2world`` onto ``rig`` through ``mapping``; returns the action.

    Parameters
    ----------
    rig : bpy.types.Object
        The target armature; its rest pose and object transform are used as they are.
    body : BodyModel
    seg2world : array, shape (F, S, 4, 4)
    times : array, shape (F,)
        Scene frames to key.
    mapping : dict of str to str
        Segment -> bone (:func:`resolve_bone_map`).

    Returns
    -------
    action : bpy.types.Action
        A new action on the rig (its previous one is kept with a fake user).
    channelbag : bpy.types.ActionChannelbag
    """
    W = np.array(rig.matrix_world, dtype=float)
    world_scale = float(np.cbrt(abs(np.linalg.det(W[:3, :3]))))
    Wr = W[:3, :3] / world_scale
    F = len(times)
    bones = rig.data.bones
    seg_of = {bone: seg for seg, bone in mapping.items()}
    rest = {b.name: np.array(b.matrix_local, dtype=float) for b in bones}
    # The bones keyed: mapped ones and every ancestor of one.
    keyed = set()
    for bone in mapping.values():
        b = bones[bone]
        while b is not None and b.name not in keyed:
            keyed.add(b.name)
            b = b.parent
    order = _topological(bones)

    scale = _leg_scale(rig, mapping, body, world_scale)
    standing = body.dims["thigh"] + body.dims["shank"] + body.dims["ankle_height"]
    pose = {}
    basis = {}
    for name in order:
        b = bones[name]
        L = rest[name]
        parent = b.parent.name if b.parent else None
        if parent is None:
            base = np.broadcast_to(L, (F, 4, 4)).copy()
        else:
            base = pose[parent] @ (invert(rest[parent]) @ L)
        segment = seg_of.get(name)
        if segment is not None:
            k = body.segment_names.index(segment)
            Q = seg2world[:, k, :3, :3]
            base[:, :3, :3] = Wr.T @ Q @ Wr @ L[:3, :3]
            if segment == "pelvis":
                # Root motion: the pelvis path scaled to the rig, from where the rig stands.
                # A subject standing at the origin puts the pelvis at (0, 0, standing).
                moved = seg2world[:, k, :3, 3] - [0.0, 0.0, standing]
                head_world = (W @ np.append(L[:3, 3], 1.0))[:3] + scale * moved
                base[:, :3, 3] = ((head_world - W[:3, 3]) @ Wr) / world_scale
        pose[name] = base
        if name in keyed:
            local = L if parent is None else invert(rest[parent]) @ L
            parent_pose = np.eye(4) if parent is None else pose[parent]
            basis[name] = invert(local) @ invert(parent_pose) @ base

    action, channelbag = keying.new_action(rig, action_name)
    for name in order:
        if name not in basis:
            continue
        pose_bone = rig.pose.bones[name]
        keying.key_rotation(channelbag, pose_bone, times, basis[name][:, :3, :3])
        if seg_of.get(name) == "pelvis":
            keying.key_location(channelbag, pose_bone, times, basis[name][:, :3, 3])
    report(f"retargeted {F} frames onto {len(mapping)} bones of '{rig.name}'")
    return action, channelbag


def _topological(bones):
    order, seen = [], set()

    def visit(b):
        if b.name in seen:
            return
        if b.parent is not None:
            visit(b.parent)
        seen.add(b.name)
        order.append(b.name)

    for b in bones:
        visit(b)
    return order
