"""Baking a take onto an armature: bone motion, BVH and FBX round trips, new actions each run."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from test_addon_support import (SAMPLE, blender, bpy, matrix_np, registered,  # noqa: F401
                                synthetic_result, write_result)

from zoopraxis.addon import bake as bake_mod
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX

# Which bone end carries each standard joint in the full template.
JOINT_BONE_END = {
    "pelvis": ("pelvis", "head"), "neck": ("head", "head"), "head": ("head", "tail"),
    **{f"{s}_{j}": (f"{s}_{b}", end) for s in "lr" for j, b, end in (
        ("shoulder", "upper_arm", "head"), ("elbow", "forearm", "head"),
        ("wrist", "forearm", "tail"), ("hip", "thigh", "head"), ("knee", "shank", "head"),
        ("ankle", "foot", "head"), ("toe", "foot", "tail"))},
}


def joint_positions(obj, scene, frames):
    """World positions of the 17 joints read off the posed armature, shape (F, 17, 3)."""
    out = np.empty((len(frames), 17, 3))
    world = matrix_np(obj.matrix_world)
    for i, frame in enumerate(frames):
        scene.frame_set(int(frame))
        for joint, (bone, end) in JOINT_BONE_END.items():
            p = np.array(getattr(obj.pose.bones[bone], end))
            out[i, JOINT_INDEX[joint]] = world[:3, :3] @ p + world[:3, 3]
    return out


def world_rotations(obj, scene, frames, bones):
    """World rotation of each bone relative to its rest orientation, shape (F, B, 3, 3)."""
    out = np.empty((len(frames), len(bones), 3, 3))
    W = matrix_np(obj.matrix_world)[:3, :3]
    W = W / np.cbrt(np.linalg.det(W))
    for i, frame in enumerate(frames):
        scene.frame_set(int(frame))
        for j, name in enumerate(bones):
            pose = matrix_np(obj.pose.bones[name].matrix)[:3, :3]
            rest = matrix_np(obj.data.bones[name].matrix_local)[:3, :3]
            pose /= np.linalg.norm(pose, axis=0)
            rest /= np.linalg.norm(rest, axis=0)
            out[i, j] = W @ pose @ rest.T @ W.T
    return out


def angle_deg(Ra, Rb):
    c = (np.trace(np.swapaxes(Ra, -1, -2) @ Rb, axis1=-2, axis2=-1) - 1) / 2
    return np.degrees(np.arccos(np.clip(c, -1, 1)))


def test_bone_positions_follow_joints3d(blender):
    result, body = synthetic_result(20)
    obj, action = bake_mod.bake(None, result, report=lambda *_: None)
    assert obj.type == 'ARMATURE' and set(obj.data.bones.keys()) == set(body.segment_names)
    assert obj.animation_data.action == action and action.name == "Zoopraxis take"
    assert action.frame_range[:] == pytest.approx((1.0, 20.0))
    # One F-curve per channel: 4 quaternion channels per bone, pelvis location, 2 status.
    bag = action.layers[0].strips[0].channelbag(action.slots[0])
    assert len(bag.fcurves) == 4 * body.n_segments + 3 + 2
    X = joint_positions(obj, blender.scene, 1 + result.frames)
    np.testing.assert_allclose(X, result.joints3d, atol=1e-3)
    # The rest pose is the body's reference configuration with its dimensions.
    assert obj.data.bones["l_thigh"].length == pytest.approx(body.dims["thigh"], abs=1e-6)
    mesh = [c for c in obj.children if c.type == 'MESH']
    assert len(mesh) == 1 and set(mesh[0].vertex_groups.keys()) == set(body.segment_names)
    assert mesh[0].modifiers[0].object == obj


def test_status_keyed_and_worst_frame(blender):
    result, _ = synthetic_result(12)
    result.status[4] = "lost"
    result.status[7] = "uncertain"
    result.residual["cam0"][9] = 5.0
    obj, _ = bake_mod.bake(None, result, body_mesh=False, first_frame=10,
                           report=lambda *_: None)
    scene = blender.scene
    scene.frame_set(14)
    assert obj[bake_mod.PROP_STATUS] == 2
    scene.frame_set(19)
    assert obj[bake_mod.PROP_RESIDUAL] == pytest.approx(5.0)
    assert [m.frame for m in scene.timeline_markers if m.name == bake_mod.LOST_MARKER] == [14]
    assert bake_mod.worst_frame(obj) == 14
    # Lost before uncertain before the largest residual.
    result.status[4] = "ok"
    obj2, _ = bake_mod.bake(None, result, body_mesh=False, first_frame=10,
                            report=lambda *_: None)
    assert bake_mod.worst_frame(obj2) == 17
    result.status[7] = "ok"
    obj3, _ = bake_mod.bake(None, result, body_mesh=False, first_frame=10,
                            report=lambda *_: None)
    assert bake_mod.worst_frame(obj3) == 19
    assert not [m for m in scene.timeline_markers if m.name == bake_mod.LOST_MARKER]


def test_second_bake_makes_new_action_and_keeps_first(blender):
    result, _ = synthetic_result(8)
    obj1, act1 = bake_mod.bake(None, result, body_mesh=False, report=lambda *_: None)
    before = [(fc.data_path, fc.array_index, [tuple(k.co) for k in fc.keyframe_points])
              for fc in act1.layers[0].strips[0].channelbags[0].fcurves]
    result.angles = result.angles + 0.1
    obj2, act2 = bake_mod.bake(None, result, body_mesh=False, report=lambda *_: None)
    assert act2 != act1 and act2.name == "Zoopraxis take.001" and obj2 != obj1
    after = [(fc.data_path, fc.array_index, [tuple(k.co) for k in fc.keyframe_points])
             for fc in act1.layers[0].strips[0].channelbags[0].fcurves]
    assert after == before
    assert obj1.animation_data.action == act1 and act1.use_fake_user


def test_without_angles_bones_aim_at_joints(blender):
    result, body = synthetic_result(10, angles=False)
    obj, _ = bake_mod.bake(None, result, body_mesh=False, report=lambda *_: None)
    frames = 1 + result.frames
    X = joint_positions(obj, blender.scene, frames)
    pelvis_and_hips = [JOINT_INDEX[j] for j in ("pelvis", "l_hip", "r_hip", "neck")]
    np.testing.assert_allclose(X[:, pelvis_and_hips], result.joints3d[:, pelvis_and_hips],
                               atol=1e-2)
    # Every limb bone points at its child joint.
    for segment, joint in (("l_thigh", "l_knee"), ("r_shank", "r_ankle"), ("l_foot", "l_toe"),
                           ("r_upper_arm", "r_elbow"), ("l_forearm", "l_wrist"),
                           ("head", "head")):
        for i, frame in enumerate(frames):
            blender.scene.frame_set(int(frame))
            bone = obj.pose.bones[segment]
            direction = np.array(bone.tail) - np.array(bone.head)
            goal = result.joints3d[i, JOINT_INDEX[joint]] - np.array(bone.head)
            cos = direction @ goal / np.linalg.norm(direction) / np.linalg.norm(goal)
            assert np.degrees(np.arccos(min(cos, 1.0))) < 0.1, (segment, frame)


def test_without_angles_a_stiff_spine_is_exact(blender):
    result, body = synthetic_result(10)
    spine = [i for i, n in enumerate(body.dof_names) if n.startswith(("lumbar", "thorax"))]
    result.angles[:, spine] = 0.0
    result.joints3d = body.joints(result.roots, result.angles)
    result.angles = result.roots = None
    obj, _ = bake_mod.bake(None, result, body_mesh=False, report=lambda *_: None)
    X = joint_positions(obj, blender.scene, 1 + result.frames)
    np.testing.assert_allclose(X, result.joints3d, atol=1e-3)


def test_bad_result_leaves_scene_alone(blender, tmp_path):
    result, _ = synthetic_result(5)
    result.angles = result.angles[:, :5]
    n_objects, n_actions = len(bpy.data.objects), len(bpy.data.actions)
    with pytest.raises(ZoopraxisError, match="'angles' has shape"):
        bake_mod.bake(None, result, report=lambda *_: None)
    with pytest.raises(ZoopraxisError, match="no such result file"):
        bake_mod.bake(None, tmp_path / "missing.json", report=lambda *_: None)
    assert (len(bpy.data.objects), len(bpy.data.actions)) == (n_objects, n_actions)


def test_bvh_round_trip_matches_result(blender, tmp_path):
    from zoopraxis.addon import export

    result, body = synthetic_result(15)
    obj, _ = bake_mod.bake(None, result, body_mesh=False, report=lambda *_: None)
    path = export.export_bvh(blender, obj, tmp_path / "take.bvh", report=lambda *_: None)
    with pytest.raises(ZoopraxisError, match="file exists"):
        export.export_bvh(blender, obj, path, report=lambda *_: None)
    bpy.ops.import_anim.bvh(filepath=str(path), axis_forward='Y', axis_up='Z',
                            rotate_mode='NATIVE', frame_start=1)
    imported = blender.view_layer.objects.active
    assert imported.type == 'ARMATURE' and imported != obj
    frames = 1 + result.frames
    X = joint_positions(imported, blender.scene, frames)
    np.testing.assert_allclose(X, result.joints3d, atol=1e-3)
    segments = list(body.segment_names)
    ours = world_rotations(obj, blender.scene, frames, segments)
    theirs = world_rotations(imported, blender.scene, frames, segments)
    truth = body.seg2world(result.roots, result.angles)[:, :, :3, :3]
    assert angle_deg(ours, truth).max() < 0.05
    assert angle_deg(theirs, truth).max() < 0.5


def test_fbx_round_trip_has_armature_and_animation(blender, tmp_path):
    from zoopraxis.addon import export

    result, body = synthetic_result(10)
    obj, _ = bake_mod.bake(None, result, report=lambda *_: None)
    path = export.export_fbx(blender, [obj] + list(obj.children), tmp_path / "take.fbx",
                             report=lambda *_: None)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=str(path))
    arms = [o for o in bpy.data.objects if o.type == 'ARMATURE']
    meshes = [o for o in bpy.data.objects if o.type == 'MESH']
    assert len(arms) == 1 and len(meshes) == 1
    arm = arms[0]
    assert set(body.segment_names) <= set(arm.data.bones.keys())
    action = arm.animation_data.action
    assert action is not None
    start, end = action.frame_range
    assert (end - start) == pytest.approx(9, abs=0.01)
    X = joint_positions(arm, bpy.context.scene, np.arange(int(start), int(end) + 1))
    # FBX has no bone tails (the importer guesses them): compare the joints at bone heads.
    heads = [JOINT_INDEX[j] for j, (_, end) in JOINT_BONE_END.items() if end == "head"]
    np.testing.assert_allclose(X[:, heads], result.joints3d[:, heads], atol=1e-3)


def test_bake_command_writes_blend_bvh_fbx(tmp_path):
    result, _ = synthetic_result(6)
    path = write_result(tmp_path / "result.json", result)
    outs = [tmp_path / "take.blend", tmp_path / "take.bvh", tmp_path / "take.fbx"]
    cmd = [sys.executable, "-m", "zoopraxis", "bake", "--result", str(path), "--blend",
           str(outs[0]), "--bvh", str(outs[1]), "--fbx", str(outs[2])]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert all(p.stat().st_size > 0 for p in outs)
    assert "HIERARCHY" in outs[1].read_text()[:20]
    # A second run refuses to replace them, and says which file.
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert again.returncode == 2
    assert again.stderr.strip().splitlines()[-1] == (
        f"zoopraxis bake: error: {outs[0]}: file exists (use --force to replace it)")
    forced = subprocess.run(cmd + ["--force"], capture_output=True, text=True, timeout=300,
                            cwd=tmp_path)
    assert forced.returncode == 0, forced.stderr
    missing = subprocess.run([sys.executable, "-m", "zoopraxis", "bake", "--result",
                              str(tmp_path / "nope.json"), "--bvh", str(tmp_path / "x.bvh")],
                             capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert missing.returncode == 2 and "no such result file" in missing.stderr


def short_sample(folder, frames):
    """The bundled sample cut to its first ``frames`` frames (the anchors among them kept),
    in ``folder``."""
    folder.mkdir()
    for name in ("calibration.json", "truth.json"):
        shutil.copy(SAMPLE / name, folder / name)
    markers = json.loads((SAMPLE / "markers.json").read_text())
    markers["anchors"] = [a for a in markers["anchors"] if a["frame"] < frames]
    (folder / "markers.json").write_text(json.dumps(markers))
    for view in ("cam0", "cam1", "cam2"):
        (folder / view).mkdir()
        for f in range(frames):
            shutil.copy(SAMPLE / view / f"{f:06d}.jpg", folder / view / f"{f:06d}.jpg")
    return folder


@pytest.mark.slow
def test_demo_inside_blender_bakes_through_the_command_table(blender, tmp_path, capsys):
    """With bpy loaded (``blender --command zoopraxis demo``), the demo bakes in this process
    through the root command table (core never imports the add-on) and writes every output.
    On the sample's first 12 frames (tracked from the anchor at frame 0): MPJPE 18.1 mm (15.7
    over the whole sample, which takes four times as long)."""
    import re

    from zoopraxis import cli

    out = tmp_path / "demo"
    sample = short_sample(tmp_path / "sample", 12)
    assert cli.main(["demo", "--sample", str(sample), "--out", str(out)]) == 0
    for name in ("result.json", "take.blend", "take.bvh", "take.fbx", "contact_sheet.png"):
        assert (out / name).stat().st_size > 0, name
    said = capsys.readouterr().out
    assert "zoopraxis bake: wrote" in said
    mpjpe = float(re.search(r"MPJPE ([0-9.]+) mm", said).group(1))
    assert mpjpe < 40
