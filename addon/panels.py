"""Sidebar panels: the 3D View's "Zoopraxis" tab and the Movie Clip Editor's markers panel.

The 3D View panel walks through the steps Plates -> Calibration -> Markers -> Initialize ->
Track -> Bake/Export; each step says what is missing before it can run.
"""

import textwrap

import bpy

from ..core.body.joints import STANDARD_JOINTS
from .props import NOTE_PREFIX

# Characters of a warning per line in the sidebar (labels do not wrap).
NOTE_WIDTH = 46


def missing_for(context):
    """What each step still needs, as ``{step: message or None}``."""
    scene = context.scene
    settings = scene.zoopraxis
    views = list(settings.views)
    out = {"plates": None if views else "Load one plate per camera"}
    uncalibrated = [v.name for v in views if v.camera is None]
    out["calibration"] = None if views and not uncalibrated else (
        "Optional: without cameras the take is tracked uncalibrated" if views else
        "Load the plates first")
    placed = set()
    for view in views:
        if view.clip is not None:
            placed |= {t.name for t in view.clip.tracking.tracks if t.name in STANDARD_JOINTS}
    missing_joints = [j for j in STANDARD_JOINTS if j not in placed]
    out["markers"] = None if views and not missing_joints else (
        f"Place joint '{missing_joints[0]}' in some view ({len(missing_joints)} missing)"
        if views else "Load the plates first")
    ready = out["plates"] is None and out["markers"] is None
    out["initialize"] = None if ready else "Plates and markers first"
    out["track"] = None if ready else "Plates and markers first"
    has_result = bool(settings.result_path) or settings.armature is not None
    out["bake"] = None if has_result else "Track the take (or pick a result.json) first"
    return out


def _step(layout, title, icon, missing):
    box = layout.box()
    row = box.row()
    row.label(text=title, icon='CHECKMARK' if missing is None else icon)
    if missing:
        box.label(text=missing, icon='INFO')
    return box


class ZOOPRAXIS_UL_views(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_propname):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False, icon='CLIP')
        row.label(text=f"{item.num_frames} fr")
        row.label(text="", icon='CAMERA_DATA' if item.camera else 'BLANK1')


class ZOOPRAXIS_UL_joints(bpy.types.UIList):
    """Joints and, per view, whether a marker is keyed at the current frame."""

    def draw_item(self, context, layout, data, item, icon, active_data, active_propname):
        from .markers import placement

        settings = context.scene.zoopraxis
        row = layout.row(align=True)
        row.label(text=item.name)
        icons = {'KEY': 'KEYFRAME_HLT', 'ELSEWHERE': 'KEYFRAME', 'NONE': 'X'}
        for view, state in placement(settings, item.name, context.scene.frame_current):
            row.label(text=view, icon=icons[state])


class ZOOPRAXIS_UL_bone_map(bpy.types.UIList):
    def draw_item(self, context, layout, data, item, icon, active_data, active_propname):
        row = layout.row(align=True)
        row.prop(item, "name", text="", emboss=False)
        rig = context.scene.zoopraxis.rig
        if rig is not None and rig.type == 'ARMATURE':
            row.prop_search(item, "bone", rig.data, "bones", text="")
        else:
            row.prop(item, "bone", text="")


def _draw_init_notes(box, settings):
    """The last initialization's warnings, and per anchor frame clicked in one view a toggle
    per limb to turn it to its other depth (the ambiguous ones marked)."""
    from .pipeline import parse_flips

    for note in filter(None, settings.init_notes.split("\n")):
        col = box.column(align=True)
        icon = 'INFO' if note.startswith(NOTE_PREFIX) else 'ERROR'
        note = note.removeprefix(NOTE_PREFIX)
        for i, line in enumerate(textwrap.wrap(note, NOTE_WIDTH)):
            col.label(text=line, icon=icon if i == 0 else 'BLANK1')
    frames = [int(f) for f in settings.one_view_frames.split(",") if f.strip().isdigit()]
    if not frames:
        return
    flips = parse_flips(settings.depth_flips)
    ambiguous = parse_flips(settings.ambiguous_parts)
    box.label(text="Seen in one view: flip what looks wrong in depth")
    box.prop(settings, "camera_tilt")
    for frame in frames:
        row = box.row(align=True)
        row.label(text=f"Frame {frame}")
        for part, text in (("left arm", "L Arm"), ("right arm", "R Arm"), ("left leg", "L Leg"),
                           ("right leg", "R Leg"), ("body", "Body")):
            op = row.operator("zoopraxis.flip_depth", text=text,
                              icon='ERROR' if part in ambiguous.get(frame, ()) else 'NONE',
                              depress=part in flips.get(frame, ()))
            op.frame, op.part = frame, part


class VIEW3D_PT_zoopraxis(bpy.types.Panel):
    bl_label = "Zoopraxis"
    bl_space_type = 'VIEW_3D'
    bl_region_type = 'UI'
    bl_category = "Zoopraxis"

    def draw(self, context):
        settings = context.scene.zoopraxis
        missing = missing_for(context)
        layout = self.layout

        box = _step(layout, "1. Plates", 'FILE_MOVIE', missing["plates"])
        box.template_list("ZOOPRAXIS_UL_views", "", settings, "views", settings, "active_view",
                          rows=2)
        row = box.row(align=True)
        row.operator("zoopraxis.load_plates", icon='FILEBROWSER')
        row.operator("zoopraxis.remove_view", text="", icon='REMOVE')
        if len(settings.views):
            view = settings.views[min(settings.active_view, len(settings.views) - 1)]
            col = box.column(align=True)
            col.prop(view, "offset")
            col.prop(view, "camera")
            box.prop(settings, "first_frame")

        box = _step(layout, "2. Calibration", 'CAMERA_DATA', missing["calibration"])
        row = box.row(align=True)
        row.operator("zoopraxis.load_calibration", icon='IMPORT')
        row.operator("zoopraxis.export_calibration", text="", icon='EXPORT')
        col = box.column(align=True)
        col.prop(settings, "board")
        row = col.row(align=True)
        row.prop(settings, "board_step")
        row.prop(settings, "board_world_frame")
        row.prop(settings, "board_max_rms")
        sub = box.row()
        sub.enabled = bool(settings.views) and not settings.running
        sub.operator("zoopraxis.calibrate_board", icon='MESH_GRID')

        box = _step(layout, "3. Markers", 'TRACKER', missing["markers"])
        box.label(text="Place the joints in the Movie Clip Editor")
        row = box.row(align=True)
        row.operator("zoopraxis.import_markers", icon='IMPORT')
        row.operator("zoopraxis.export_markers", icon='EXPORT')

        box = _step(layout, "4. Initialize", 'ARMATURE_DATA', missing["initialize"])
        box.prop(settings, "template")
        box.prop(settings, "pose_prior_path")
        box.prop(settings, "proportions_prior_path")
        box.prop(settings, "dims_path")
        if not any(view.camera for view in settings.views):       # uncalibrated
            box.prop(settings, "use_pose_basis")
            box.prop(settings, "near_cameras")
        sub = box.row()
        sub.enabled = missing["initialize"] is None and not settings.running
        sub.operator("zoopraxis.initialize", icon='POSE_HLT')
        _draw_init_notes(box, settings)

        box = _step(layout, "5. Track", 'TRACKING', missing["track"])
        box.prop(settings, "tracker")
        row = box.row(align=True)
        row.prop(settings, "use_frame_range")
        sub = row.row(align=True)
        sub.enabled = settings.use_frame_range
        sub.prop(settings, "frame_range_start")
        sub.prop(settings, "frame_range_end")
        sub = box.row()
        sub.enabled = missing["track"] is None and not settings.running
        sub.operator("zoopraxis.track", icon='PLAY')
        if settings.running:
            box.progress(factor=settings.progress, text=settings.status)
        elif settings.status:
            box.label(text=settings.status)
        box.operator("zoopraxis.jump_worst_frame", icon='ERROR')

        box = _step(layout, "6. Bake / Export", 'EXPORT', missing["bake"])
        box.prop(settings, "result_path")
        box.prop(settings, "rig")
        if settings.rig is not None:
            box.prop(settings, "preset")
            row = box.row()
            row.template_list("ZOOPRAXIS_UL_bone_map", "", settings, "bone_map", settings,
                              "active_bone_pair", rows=2)
            col = row.column(align=True)
            col.operator("zoopraxis.bone_map_add", text="", icon='ADD')
            col.operator("zoopraxis.bone_map_remove", text="", icon='REMOVE')
            col.operator("zoopraxis.bone_map_load", text="", icon='FILEBROWSER')
        else:
            box.prop(settings, "body_mesh")
        box.operator("zoopraxis.bake", icon='ACTION')
        row = box.row(align=True)
        row.operator("zoopraxis.export_bvh", icon='EXPORT')
        row.operator("zoopraxis.export_fbx", icon='EXPORT')


class CLIP_PT_zoopraxis_markers(bpy.types.Panel):
    bl_label = "Zoopraxis Joints"
    bl_space_type = 'CLIP_EDITOR'
    bl_region_type = 'UI'
    bl_category = "Zoopraxis"

    @classmethod
    def poll(cls, context):
        return context.space_data is not None and context.space_data.clip is not None

    def draw(self, context):
        settings = context.scene.zoopraxis
        layout = self.layout
        layout.prop(settings, "show_fit_overlay")
        row = layout.row(align=True)
        row.operator("zoopraxis.add_joint_markers", icon='ADD')
        row.operator("zoopraxis.add_joint_markers", text="All Views").all_views = True
        if len(settings.joints):
            layout.template_list("ZOOPRAXIS_UL_joints", "", settings, "joints", settings,
                                 "active_joint", rows=6)
        else:
            layout.label(text="Load plates to list the joints", icon='INFO')
        layout.label(text="Drag each marker onto its joint; keyed markers at")
        layout.label(text="later frames correct the tracker")
        row = layout.row(align=True)
        row.operator("zoopraxis.import_markers", icon='IMPORT')
        row.operator("zoopraxis.export_markers", icon='EXPORT')


classes = (ZOOPRAXIS_UL_views, ZOOPRAXIS_UL_joints, ZOOPRAXIS_UL_bone_map, VIEW3D_PT_zoopraxis,
           CLIP_PT_zoopraxis_markers)
