"""Retargeting onto existing rigs: Mixamo names, other rest rolls, object transforms, bone maps."""

import numpy as np
import pytest

from test_addon_support import blender, bpy, registered, synthetic_result  # noqa: F401
from test_addon_bake import angle_deg, world_rotations

from zoopraxis.addon import bake as bake_mod
from zoopraxis.core.errors import ZoopraxisError


def rig_bones(body, prefix="mixamorig:"):
    """Mixamo-like bones (name, parent, head, tail) standing on the ground, in world metres."""
    p = {n: body.reference_point(n) + [0, 0, 0.93] for n in (
        "pelvis", "lumbar", "thorax", "neck", "head", "l_shoulder", "l_elbow", "l_wrist",
        "r_shoulder", "r_elbow", "r_wrist", "l_hip", "l_knee", "l_ankle", "l_toe", "r_hip",
        "r_knee", "r_ankle", "r_toe")}
    mid = (p["lumbar"] + p["thorax"]) / 2
    bones = [("Hips", None, p["pelvis"], p["lumbar"]), ("Spine", "Hips", p["lumbar"], mid),
             ("Spine1", "Spine", mid, p["thorax"]), ("Spine2", "Spine1", p["thorax"], p["neck"]),
             ("Neck", "Spine2", p["neck"], p["head"]),
             ("Head", "Neck", p["head"], p["head"] + [0, 0, 0.1])]
    for s, side in (("l", "Left"), ("r", "Right")):
        bones += [
            (f"{side}Shoulder", "Spine2", p["neck"] + [0, 0, -0.03], p[f"{s}_shoulder"]),
            (f"{side}Arm", f"{side}Shoulder", p[f"{s}_shoulder"], p[f"{s}_elbow"]),
            (f"{side}ForeArm", f"{side}Arm", p[f"{s}_elbow"], p[f"{s}_wrist"]),
            (f"{side}Hand", f"{side}ForeArm", p[f"{s}_wrist"], p[f"{s}_wrist"] - [0, 0, 0.08]),
            (f"{side}UpLeg", "Hips", p[f"{s}_hip"], p[f"{s}_knee"]),
            (f"{side}Leg", f"{side}UpLeg", p[f"{s}_knee"], p[f"{s}_ankle"]),
            (f"{side}Foot", f"{side}Leg", p[f"{s}_ankle"], p[f"{s}_toe"]),
            (f"{side}ToeBase", f"{side}Foot", p[f"{s}_toe"], p[f"{s}_toe"] - [0, 0.05, 0])]
    return [(prefix + n, parent and prefix + parent, h, t) for n, parent, h, t in bones]


def make_rig(context, bones, rng, matrix=None, skip=()):
    """An armature like an imported Mixamo rig: rotated +90 deg about X, scale 0.01."""
    from mathutils import Matrix

    W = np.eye(4) if matrix is None else matrix
    data = bpy.data.armatures.new("rig")
    rig = bpy.data.objects.new("rig", data)
    context.scene.collection.objects.link(rig)
    rig.matrix_world = Matrix(W.tolist())
    context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode='EDIT')
    to_arm = np.linalg.inv(W)
    for name, parent, head, tail in bones:
        if name in skip:
            continue
        eb = data.edit_bones.new(name)
        eb.head = (to_arm @ np.append(head, 1))[:3].tolist()
        eb.tail = (to_arm @ np.append(tail, 1))[:3].tolist()
        eb.roll = float(rng.uniform(-np.pi, np.pi))
        if parent and parent not in skip:
            eb.parent = data.edit_bones[parent]
    bpy.ops.object.mode_set(mode='OBJECT')
    for pb in rig.pose.bones:
        pb.rotation_mode = 'QUATERNION'
    rig.pose.bones[1].rotation_mode = 'ZXY'  # an Euler bone among them
    return rig


MIXAMO_IMPORT = np.array([[0.01, 0, 0, 0], [0, 0, -0.01, 0], [0, 0.01, 0, 0], [0, 0, 0, 1.0]])


def test_retarget_onto_mixamo_rig_with_other_rolls(blender, rng):
    result, body = synthetic_result(12)
    rig = make_rig(blender, rig_bones(body), rng, MIXAMO_IMPORT)
    old = bpy.data.actions.new("user's walk")
    rig.animation_data_create().action = old
    obj, action = bake_mod.bake(None, result, rig=rig, preset='MIXAMO', report=lambda *_: None)
    assert obj == rig and action.name == "Zoopraxis take" and rig.animation_data.action == action
    assert old.name in bpy.data.actions and old.use_fake_user  # the user's action is kept
    frames = 1 + result.frames
    S = body.seg2world(result.roots, result.angles)
    mapped = {"pelvis": "Hips", "abdomen": "Spine", "chest": "Spine2", "head": "Neck",
              "l_upper_arm": "LeftArm", "r_forearm": "RightForeArm", "l_thigh": "LeftUpLeg",
              "r_shank": "RightLeg", "l_foot": "LeftFoot"}
    bones = ["mixamorig:" + b for b in mapped.values()]
    got = world_rotations(rig, blender.scene, frames, bones)
    want = S[:, [body.segment_names.index(s) for s in mapped], :3, :3]
    assert angle_deg(got, want).max() < 0.5
    # Same proportions, so the mapped bones' heads land on the joints.
    W = np.array(rig.matrix_world)
    for seg, joint in (("LeftArm", "l_shoulder"), ("RightLeg", "r_knee"), ("LeftFoot", "l_ankle"),
                       ("Hips", "pelvis"), ("Neck", "neck")):
        from zoopraxis.core.body.joints import JOINT_INDEX

        for i, frame in enumerate(frames):
            blender.scene.frame_set(int(frame))
            head = W @ np.append(rig.pose.bones["mixamorig:" + seg].head, 1)
            assert np.linalg.norm(head[:3] - result.joints3d[i, JOINT_INDEX[joint]]) < 1e-3


def test_missing_mapped_bone_is_named_and_rig_untouched(blender, rng):
    result, body = synthetic_result(4)
    rig = make_rig(blender, rig_bones(body), rng, skip=("mixamorig:LeftLeg",))
    n_actions = len(bpy.data.actions)
    with pytest.raises(ZoopraxisError, match=r"rig 'rig' has no bone 'mixamorig:LeftLeg' "
                                             r"\(mapped from segment 'l_shank'\)"):
        bake_mod.bake(None, result, rig=rig, preset='MIXAMO', report=lambda *_: None)
    assert len(bpy.data.actions) == n_actions and rig.animation_data is None


def test_user_bone_map_and_prefix_detection(blender, rng):
    result, body = synthetic_result(5)
    rig = make_rig(blender, rig_bones(body, prefix="mixamorig7:"), rng)
    # The user map overrides the preset: the head goes on the Head bone instead of the Neck.
    obj, action = bake_mod.bake(None, result, rig=rig, preset='MIXAMO',
                                bone_map={"head": "mixamorig7:Head"}, report=lambda *_: None)
    S = body.seg2world(result.roots, result.angles)
    got = world_rotations(rig, blender.scene, 1 + result.frames, ["mixamorig7:Head"])
    assert angle_deg(got[:, 0], S[:, body.segment_names.index("head"), :3, :3]).max() < 0.5
    with pytest.raises(ZoopraxisError, match="bone map: unknown segment 'tail'"):
        bake_mod.bake(None, result, rig=rig, bone_map={"tail": "x"}, report=lambda *_: None)
    with pytest.raises(ZoopraxisError, match="has no bone 'DEF-spine'"):
        bake_mod.bake(None, result, rig=rig, preset='RIGIFY', report=lambda *_: None)
    with pytest.raises(ZoopraxisError, match="no bones mapped"):
        bake_mod.bake(None, result, rig=rig, preset='NONE', report=lambda *_: None)


def test_rigify_names(blender, rng):
    from zoopraxis.addon.retarget import preset_map

    assert preset_map('RIGIFY', ["ORG-spine", "spine"])["l_shank"] == "ORG-shin.L"
    assert preset_map('RIGIFY', ["spine"])["r_upper_arm"] == "upper_arm.R"
    assert preset_map('RIGIFY', ["DEF-spine", "ORG-spine"])["pelvis"] == "DEF-spine"
