"""Bake a tracked take onto an armature, a body mesh and (optionally) an existing rig.

The armature has one bone per body segment, named by the segment, head at its joint and tail
at its child joint; the rest pose is the body's reference configuration with the fitted
dimensions. Rotations are keyed per frame in bulk through a new slotted action each run, the
pelvis location too; per-frame tracking status and residual are keyed as custom properties of
the armature object (they show in the Graph Editor), and lost frames get timeline markers.

Convention: a bone's world matrix at frame ``f`` is ``seg2world[f, k] @ B_k`` with ``B_k`` its
rest matrix (the armature object at the identity); its pose basis is therefore
``B_k^-1 seg2world[f, parent]^-1 seg2world[f, k] B_k``. Take frame ``f`` is keyed at scene frame
``first_frame + f``.
"""

from pathlib import Path

import bpy
import numpy as np

from ..core.errors import ZoopraxisError
from ..core.files.outputs import check_output
from ..core.files.result import STATUSES, TrackResult, read_result
from . import keying, motion, retarget

ACTION_PREFIX = "Zoopraxis "
PROP_STATUS = "zoopraxis_status"
PROP_RESIDUAL = "zoopraxis_residual"
PROP_TAKE = "zoopraxis_take"
LOST_MARKER = "Zoopraxis: lost"
STATUS_CODES = {name: i for i, name in enumerate(STATUSES)}


def _settings(scene):
    return getattr(scene, "zoopraxis", None)


def scene_first_frame(scene):
    """Scene frame of take frame 0: the take's setting, else 1 (Blender's default start)."""
    settings = _settings(scene)
    return settings.first_frame if settings is not None else 1


def ensure_object_mode(context):
    obj = context.view_layer.objects.active
    if obj is not None and obj.mode != 'OBJECT':
        bpy.ops.object.mode_set(mode='OBJECT')


# --- the armature ---------------------------------------------------------------------------

def build_armature(context, body, name):
    """A new armature object of ``body`` in its reference configuration, linked to the scene.

    Bones along a limb get their local Z pointing forward (-Y), feet up (+Z): then flexion,
    the largest motion of each joint, is a rotation about the bone's local X.
    """
    collection = getattr(context, "collection", None) or context.scene.collection
    data = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, data)
    collection.objects.link(obj)
    obj.show_in_front = True
    for other in context.view_layer.objects.selected:
        other.select_set(False)
    context.view_layer.objects.active = obj
    obj.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    try:
        tails = {}
        for segment, parent, head, tail in motion.bone_segments(body):
            bone = data.edit_bones.new(segment)
            bone.head, bone.tail = head.tolist(), tail.tolist()
            bone.align_roll((0.0, 0.0, 1.0) if segment.endswith("foot") else (0.0, -1.0, 0.0))
            if parent is not None:
                bone.parent = data.edit_bones[parent]
                bone.use_connect = bool(np.allclose(tails[parent], head, atol=1e-6))
            tails[segment] = tail
    finally:
        bpy.ops.object.mode_set(mode='OBJECT')
    for pose_bone in obj.pose.bones:
        pose_bone.rotation_mode = 'QUATERNION'
    return obj


def key_armature(obj, body, seg2world, times, action_name):
    """Key the armature built by :func:`build_armature` from segment transforms (F, S, 4, 4)."""
    rest = np.array([np.array(obj.data.bones[s].matrix_local, float) for s in body.segment_names])
    action, channelbag = keying.new_action(obj, action_name)
    for k, segment in enumerate(body.segment_names):
        p = body.segment_parents[k]
        relative = seg2world[:, k] if p < 0 else motion.invert(seg2world[:, p]) @ seg2world[:, k]
        basis = motion.invert(rest[k]) @ relative @ rest[k]
        pose_bone = obj.pose.bones[segment]
        keying.key_rotation(channelbag, pose_bone, times, basis[:, :3, :3])
        if p < 0:
            keying.key_location(channelbag, pose_bone, times, basis[:, :3, 3])
    return action, channelbag


def key_status(obj, channelbag, result, times):
    """Key the per-frame status (0 ok, 1 uncertain, 2 lost) and the mean view residual."""
    codes = np.array([STATUS_CODES[s] for s in result.status], float)
    if result.residual:
        residual = np.nanmean(np.stack([np.asarray(r, float) for r in result.residual.values()]),
                              axis=0)
    else:
        residual = np.zeros(len(times))
    obj[PROP_STATUS] = int(codes[0]) if len(codes) else 0
    obj[PROP_RESIDUAL] = float(residual[0]) if len(residual) else 0.0
    obj.id_properties_ui(PROP_STATUS).update(
        min=0, max=2, description="Tracking status of the frame: 0 ok, 1 uncertain, 2 lost")
    obj.id_properties_ui(PROP_RESIDUAL).update(
        min=0.0, description="Image residual of the frame, mean over the views")
    keying.key_channels(channelbag, f'["{PROP_STATUS}"]', times, codes, group="Zoopraxis",
                        interpolation='CONSTANT')
    keying.key_channels(channelbag, f'["{PROP_RESIDUAL}"]', times, np.nan_to_num(residual),
                        group="Zoopraxis")


def mark_lost_frames(scene, result, times):
    """Replace the previous run's "lost" timeline markers by this result's."""
    for marker in [m for m in scene.timeline_markers if m.name == LOST_MARKER]:
        scene.timeline_markers.remove(marker)
    for status, frame in zip(result.status, times):
        if status == "lost":
            scene.timeline_markers.new(LOST_MARKER, frame=int(frame))


def worst_frame(obj):
    """Scene frame of the worst keyed frame of a baked object: lost first, then by residual."""
    adt = obj.animation_data if obj is not None else None
    if adt is None or adt.action is None or PROP_RESIDUAL not in obj:
        raise ZoopraxisError(f"'{getattr(obj, 'name', None)}' has no tracking residual keyed; "
                             "bake a take first")
    from bpy_extras import anim_utils

    bag = anim_utils.animdata_get_channelbag_for_assigned_slot(adt)
    curves = {fc.data_path: fc for fc in bag.fcurves} if bag else {}
    res = curves.get(f'["{PROP_RESIDUAL}"]')
    if res is None or len(res.keyframe_points) == 0:
        raise ZoopraxisError(f"'{obj.name}' has no tracking residual keyed")
    co = np.empty(2 * len(res.keyframe_points))
    res.keyframe_points.foreach_get("co", co)
    frames, residual = co[0::2], co[1::2]
    score = residual.copy()
    stat = curves.get(f'["{PROP_STATUS}"]')
    if stat is not None and len(stat.keyframe_points) == len(frames):
        sco = np.empty(2 * len(frames))
        stat.keyframe_points.foreach_get("co", sco)
        score = score + 1e9 * sco[1::2]
    return int(round(frames[int(np.argmax(score))]))


# --- the body mesh --------------------------------------------------------------------------

def _ring(rx, ry, z, n):
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack([rx * np.cos(a), ry * np.sin(a), np.full(n, z)])


def _lathe(rings, bottom, top, n):
    """Vertices and faces of rings stacked along z, closed by a bottom and a top vertex."""
    verts = [bottom] + [r for ring in rings for r in ring] + [top]
    faces = []
    last = 1 + (len(rings) - 1) * n
    for i in range(n):
        j = (i + 1) % n
        faces.append((0, 1 + j, 1 + i))
        faces.append((len(verts) - 1, last + i, last + j))
    for r in range(len(rings) - 1):
        a, b = 1 + r * n, 1 + (r + 1) * n
        for i in range(n):
            j = (i + 1) % n
            faces.append((a + i, a + j, b + j, b + i))
    return np.array(verts), faces


def primitive_geometry(prims, n=16, n_rings=7):
    """Mesh vertices (reference frame), faces and the segment of every vertex of primitives."""
    from ..core.body.primitives import ELLIPSOID

    verts, faces, seg = [], [], []
    offset = 0
    for p in range(len(prims)):
        a, b, c = prims.size[p]
        if prims.kind[p] == ELLIPSOID:
            phi = np.linspace(0, np.pi, n_rings + 2)[1:-1]
            rings = [_ring(a * np.sin(f), b * np.sin(f), -c * np.cos(f), n) for f in phi]
            v, f = _lathe(rings, [0, 0, -c], [0, 0, c], n)
        else:
            taper = prims.taper[p]
            rings = [_ring(a, b, 0.0, n), _ring(a * taper, b * taper, c, n)]
            v, f = _lathe(rings, [0, 0, 0], [0, 0, c], n)
        T = prims.prim2seg[p]
        verts.append(v @ T[:3, :3].T + T[:3, 3])
        faces += [tuple(i + offset for i in face) for face in f]
        seg.append(np.full(len(v), prims.segment[p]))
        offset += len(v)
    return np.concatenate(verts), faces, np.concatenate(seg)


def build_body_mesh(context, armature, body, name):
    """The body's segment shapes as one mesh, each vertex weighted fully to its segment's bone."""
    verts, faces, seg = primitive_geometry(body.primitives())
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts.tolist(), [], faces)
    mesh.update()
    mesh.shade_smooth()
    obj = bpy.data.objects.new(name, mesh)
    (getattr(context, "collection", None) or context.scene.collection).objects.link(obj)
    for k, segment in enumerate(body.segment_names):
        group = obj.vertex_groups.new(name=segment)
        group.add(np.flatnonzero(seg == k).tolist(), 1.0, 'REPLACE')
    obj.parent = armature
    modifier = obj.modifiers.new("Armature", 'ARMATURE')
    modifier.object = armature
    return obj


# --- the worker -----------------------------------------------------------------------------

def _as_result(result):
    if isinstance(result, TrackResult):
        return result
    return read_result(result)


def bake(context, result, *, rig=None, bone_map=None, preset=None, name="take", body_mesh=True,
         first_frame=None, report=print):
    """Bake a take: a new armature (or a retargeted rig) keyed from the result.

    Parameters
    ----------
    context : bpy.types.Context or None
        None for ``bpy.context`` (headless).
    result : TrackResult or path of result.json
    rig : bpy.types.Object, optional
        An existing armature to retarget onto instead of building one.
    bone_map : dict of str to str, optional
        Segment -> rig bone, overriding the preset's entries.
    preset : {'NONE', 'MIXAMO', 'RIGIFY'}, optional
    name : str
        Take name: the action is "Zoopraxis NAME" (".001" ... when taken).
    body_mesh : bool
        Also build the volumetric body mesh bound to the armature (not with ``rig``).
    first_frame : int, optional
        Scene frame of take frame 0; the take's setting by default.

    Returns
    -------
    armature : bpy.types.Object
    action : bpy.types.Action
    """
    context = context or bpy.context
    result = _as_result(result)
    if result.num_frames == 0:
        raise ZoopraxisError("result: no frames to bake")
    body = motion.body_of(result)
    seg2world = motion.segment_motion(result, body)
    mapping = None
    if rig is not None:
        mapping = retarget.resolve_bone_map(rig, body.segment_names, preset=preset,
                                            bone_map=bone_map)
    scene = context.scene
    start = scene_first_frame(scene) if first_frame is None else int(first_frame)
    times = start + np.asarray(result.frames, float)
    action_name = ACTION_PREFIX + name
    ensure_object_mode(context)

    if rig is not None:
        action, channelbag = retarget.retarget(rig, body, seg2world, times, mapping,
                                               action_name=action_name, report=report)
        target = rig
    else:
        target = build_armature(context, body, f"Zoopraxis {name}")
        action, channelbag = key_armature(target, body, seg2world, times, action_name)
        if body_mesh:
            build_body_mesh(context, target, body, f"Zoopraxis {name} body")
        how = "joint angles" if result.angles is not None else "3D joints (aimed bones)"
        report(f"baked {result.num_frames} frames of {body.n_segments} bones from {how} "
               f"into '{action.name}'")
    target[PROP_TAKE] = name
    key_status(target, channelbag, result, times)
    mark_lost_frames(scene, result, times)
    settings = _settings(scene)
    if settings is not None:
        settings.armature = target
    return target, action


def set_scene_range(scene, result, first_frame):
    """Scene frame range and rate of the take."""
    frames = np.asarray(result.frames)
    scene.frame_start = int(first_frame + frames.min())
    scene.frame_end = int(first_frame + frames.max())
    fps = float(result.fps)
    scene.render.fps = max(1, int(round(fps)))
    scene.render.fps_base = scene.render.fps / fps


def check_outputs(outputs, force, result_path):
    """Check the outputs before any work: the right extension, writable, none of them the
    result read nor another output (:func:`outputs.check_output`).

    Parameters
    ----------
    outputs : dict of str to path or None
        Option (``--bvh``) -> file; None where not given.
    """
    seen = [("--result", result_path)]
    for option, path in outputs.items():
        if path is None:
            continue
        check_output(path, force, inputs=seen, suffixes=("." + option.lstrip("-"),),
                     option=option)
        seen.append((option, path))


def bake_file(result_path, *, blend=None, bvh=None, fbx=None, force=False, name=None,
              report=print):
    """Bake result.json headless and write a .blend, a BVH and/or an FBX.

    Outside a loaded .blend file the session starts from an empty scene, so the outputs hold
    the take only. Every output is checked before anything is written.

    Returns
    -------
    written : list of Path
    """
    from . import export

    check_outputs({"--blend": blend, "--bvh": bvh, "--fbx": fbx}, force, result_path)
    result = read_result(result_path)
    if not bpy.data.filepath:
        # An empty file, preferences untouched: inside Blender this command runs with the
        # extension enabled, and factory settings would disable it.
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    context = bpy.context
    first_frame = 1
    obj, action = bake(context, result, name=name or Path(result_path).stem,
                       first_frame=first_frame, report=report)
    set_scene_range(context.scene, result, first_frame)
    written = []
    if bvh:
        written.append(export.export_bvh(context, obj, bvh, force=True, report=report))
    if fbx:
        written.append(export.export_fbx(context, [obj] + list(obj.children), fbx, force=True,
                                         report=report))
    if blend:
        written.append(export.save_blend(blend, force=True, report=report))
    return written
