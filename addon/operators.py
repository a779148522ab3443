"""Thin operators: gather properties, import the worker lazily, call it, report one line.

Workers raise ZoopraxisError on bad input before they change the scene; an operator catches it
(and any other error), reports a short ERROR line naming the file, frame, view, joint or bone,
prints the traceback to the console, removes what a failed worker had added to the scene and
leaves the scene in Object mode.
"""

from pathlib import Path

import bpy
from bpy.props import (BoolProperty, CollectionProperty, FloatProperty, IntProperty,
                       StringProperty)
from bpy_extras.io_utils import ExportHelper, ImportHelper

from ..core.errors import ZoopraxisError
from .guard import SceneGuard
from .jobs import JobOperator, report_error
from .props import NOTE_PREFIX


def run(operator, context, work):
    """Call ``work()``; on any error report one line (the traceback goes to the console),
    take out what the work had added to the scene, and cancel. Always end in Object mode."""
    try:
        with SceneGuard(context.scene):
            work()
    except Exception as ex:
        report_error(operator, ex)
        return {'CANCELLED'}
    finally:
        obj = context.view_layer.objects.active if context.view_layer else None
        if obj is not None and obj.mode != 'OBJECT':
            bpy.ops.object.mode_set(mode='OBJECT')
    return {'FINISHED'}


def _reporter(operator):
    return lambda message: operator.report({'INFO'}, message)


class _FileAction:
    """A file chooser that hands the chosen path to one function of the add-on,
    ``function(context, path, report=..., force=...)``; ``action`` names it as
    ``(module, function)``. ``force`` is passed when the operator has an ``overwrite`` option.
    """

    action = None

    def execute(self, context):
        import importlib

        module, name = self.action
        function = getattr(importlib.import_module(f"{__package__}.{module}"), name)
        kwargs = {"report": _reporter(self)}
        if hasattr(self, "overwrite"):
            kwargs["force"] = self.overwrite
        return run(self, context, lambda: function(context, self.filepath, **kwargs))


# --- plates -----------------------------------------------------------------------------------

class ZOOPRAXIS_OT_load_plates(bpy.types.Operator, ImportHelper):
    """Load video files, or one image of a folder, as the plates of a take (one view each)"""
    bl_idname = "zoopraxis.load_plates"
    bl_label = "Load Plates"
    bl_options = {'REGISTER', 'UNDO'}

    files: CollectionProperty(type=bpy.types.OperatorFileListElement,
                              options={'HIDDEN', 'SKIP_SAVE'})
    directory: StringProperty(subtype='DIR_PATH', options={'HIDDEN', 'SKIP_SAVE'})
    view_name: StringProperty(name="View Name",
                              description="Name of the view (default: folder or file name)")
    fps: FloatProperty(name="Image FPS", default=0.0, min=0.0,
                                 description="Frame rate of image folders (0: keep the scene's)")

    def execute(self, context):
        from .plates import load_plates, plate_path

        directory = Path(bpy.path.abspath(self.directory)) if self.directory else None
        names = [f.name for f in self.files if f.name]
        paths = [directory / n for n in names] if directory and names else [Path(self.filepath)]
        if directory is not None and not names and directory.is_dir():
            paths = [directory]
        # Several images of one folder are one plate; several videos are several views.
        plates = list(dict.fromkeys(plate_path(p) for p in paths))
        if self.view_name and len(plates) == 1:
            plates = {self.view_name: plates[0]}
        return run(self, context, lambda: load_plates(context, plates, fps=self.fps or None,
                                                      report=_reporter(self)))


class ZOOPRAXIS_OT_remove_view(bpy.types.Operator):
    """Remove the active view from the take (its clip and camera stay in the file)"""
    bl_idname = "zoopraxis.remove_view"
    bl_label = "Remove View"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return len(context.scene.zoopraxis.views) > 0

    def execute(self, context):
        settings = context.scene.zoopraxis
        index = min(settings.active_view, len(settings.views) - 1)
        settings.views.remove(index)
        settings.active_view = max(0, index - 1)
        return {'FINISHED'}


# --- markers ----------------------------------------------------------------------------------

def _active_clip(context):
    space = context.space_data
    if space is not None and space.type == 'CLIP_EDITOR' and space.clip is not None:
        return space.clip
    settings = context.scene.zoopraxis
    if len(settings.views):
        return settings.views[min(settings.active_view, len(settings.views) - 1)].clip
    return None


class ZOOPRAXIS_OT_add_joint_markers(bpy.types.Operator):
    """Add the 17 joint tracks at the current frame as a stick figure, keeping existing ones"""
    bl_idname = "zoopraxis.add_joint_markers"
    bl_label = "Add Joint Markers"
    bl_options = {'REGISTER', 'UNDO'}

    all_views: BoolProperty(name="All Views", default=False,
                            description="Add the joint tracks to the clips of all views")

    @classmethod
    def poll(cls, context):
        return _active_clip(context) is not None

    def execute(self, context):
        from .markers import add_joint_tracks, clip_frame
        from .plates import ensure_joint_list

        settings = context.scene.zoopraxis
        take_frame = context.scene.frame_current - settings.first_frame

        def work():
            clips = [v.clip for v in settings.views if v.clip] if self.all_views else \
                [_active_clip(context)]
            for clip in clips:
                view = next((v for v in settings.views if v.clip == clip), None)
                frame = clip_frame(view, take_frame) if view else \
                    context.scene.frame_current - clip.frame_start + 1
                if frame < 1 or frame > clip.frame_duration:
                    raise ZoopraxisError(f"clip '{clip.name}': scene frame "
                                         f"{context.scene.frame_current} is outside the plate")
                add_joint_tracks(clip, frame, report=_reporter(self))
            ensure_joint_list(settings)

        return run(self, context, work)


class ZOOPRAXIS_OT_export_markers(_FileAction, bpy.types.Operator, ExportHelper):
    """Write the joint markers of all views to markers.json"""
    bl_idname = "zoopraxis.export_markers"
    bl_label = "Export Markers"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    overwrite: BoolProperty(name="Overwrite", description="Replace an existing file")
    action = ("markers", "export_markers")


class ZOOPRAXIS_OT_import_markers(_FileAction, bpy.types.Operator, ImportHelper):
    """Add the joint markers of a markers.json file to the views' clips"""
    bl_idname = "zoopraxis.import_markers"
    bl_label = "Import Markers"
    bl_options = {'REGISTER', 'UNDO'}
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    action = ("markers", "import_markers")


# --- calibration ------------------------------------------------------------------------------

class ZOOPRAXIS_OT_load_calibration(_FileAction, bpy.types.Operator, ImportHelper):
    """Load calibration.json or a Pose2Sim/anipose TOML file as camera objects"""
    bl_idname = "zoopraxis.load_calibration"
    bl_label = "Load Calibration"
    bl_options = {'REGISTER', 'UNDO'}
    filter_glob: StringProperty(default="*.json;*.toml", options={'HIDDEN'})
    action = ("calibration", "load_calibration")


class ZOOPRAXIS_OT_export_calibration(_FileAction, bpy.types.Operator, ExportHelper):
    """Write the views' camera objects to calibration.json"""
    bl_idname = "zoopraxis.export_calibration"
    bl_label = "Export Calibration"
    filename_ext = ".json"
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})
    overwrite: BoolProperty(name="Overwrite", description="Replace an existing file")
    action = ("calibration", "export_calibration")


class ZOOPRAXIS_OT_calibrate_board(JobOperator, bpy.types.Operator):
    """Calibrate the cameras from a calibration board seen in the plates"""
    bl_idname = "zoopraxis.calibrate_board"
    bl_label = "Calibrate from Board"
    bl_options = {'REGISTER', 'UNDO'}
    label = "Calibrate"

    def prepare(self, context):
        from ..core.calibration.calibrate import parse_board
        from . import pipeline

        settings = context.scene.zoopraxis
        board = parse_board(settings.board)
        world_frame = settings.board_world_frame if settings.board_world_frame >= 0 else None
        options = dict(step=settings.board_step, world_frame=world_frame,
                       max_rms=settings.board_max_rms)
        self._take = take = pipeline.gather(context, need_markers=False)
        if world_frame is not None and world_frame not in take.frames:
            raise ZoopraxisError(f"world frame {world_frame} is outside the take "
                                 f"({take.frames.start}:{take.frames.stop})")
        return lambda progress, cancel: pipeline.calibrate(take, board, progress=progress,
                                                           cancel=cancel, **options)

    def finish(self, context, result, cancelled):
        from .calibration import add_camera_objects

        objects = add_camera_objects(context, result.cameras)
        for warning in result.warnings:
            print(f"zoopraxis calibrate: warning: {warning}")
        rms = ", ".join(f"{name} {result.rms[name]:.2f} px" for name in objects)
        return (f"Calibrated {len(objects)} camera(s) from the board, world at frame "
                f"{result.world_frame}; RMS {rms}"
                + (f"; {len(result.warnings)} warning(s), see the console"
                   if result.warnings else ""))

    def cleanup(self):
        take = getattr(self, "_take", None)
        if take is not None:
            take.close()


# --- initialize and track ---------------------------------------------------------------------

class ZOOPRAXIS_OT_initialize(JobOperator, bpy.types.Operator):
    """Fit the body's dimensions and pose to the joint markers of the anchor frames"""
    bl_idname = "zoopraxis.initialize"
    bl_label = "Initialize"
    bl_options = {'REGISTER', 'UNDO'}
    label = "Initialize"

    def prepare(self, context):
        from . import pipeline

        self._take = pipeline.gather(context)
        take = self._take
        return lambda progress, cancel: pipeline.initialize(take, progress=progress,
                                                            cancel=cancel)

    def finish(self, context, init, cancelled):
        from . import pipeline
        from .bake import bake
        from .status import result_from_initial

        scene = context.scene
        settings = scene.zoopraxis
        pipeline.remember_initial(scene, init, self._take)
        settings.initialized = True
        result = result_from_initial(init, self._take)
        bake(context, result, name="init", body_mesh=True, report=print)
        rms = init.rms
        worst = max(rms.values(), default=0.0)
        warnings = list(init.warnings)
        for w in warnings:
            print(f"zoopraxis initialize: warning: {w}")
            self.report({'WARNING'}, w)
        notes = list(init.notes)
        for n in notes:
            print(f"zoopraxis initialize: note: {n}")
            self.report({'INFO'}, n)
        # What the panel shows: the warnings and notes, and the frames whose depth the animator
        # may judge by eye and flip.
        settings.init_notes = "\n".join(warnings + [NOTE_PREFIX + n for n in notes])
        settings.one_view_frames = ",".join(
            str(a.frame) for a in self._take.anchors if a.frame in init.poses
            and sum(1 for v in a.views if a.joint_count(v)) == 1)
        settings.ambiguous_parts = pipeline.format_flips(init.ambiguous_parts)
        return (f"Initialized at {len(init.poses)} anchor frame(s), click error up to "
                f"{worst:.1f} px" + (f", {len(warnings)} warning(s)" if warnings else "")
                + (f"; {init.distance_note()}" if self._take.init_options.perspective else ""))

    def cleanup(self):
        take = getattr(self, "_take", None)
        if take is not None:
            take.close()


class ZOOPRAXIS_OT_flip_depth(bpy.types.Operator):
    """Turn a limb (or the whole body) of an anchor frame clicked in one view to its other
    depth, or back, and initialize again: one view cannot tell a limb pointing towards the
    camera from one pointing away"""
    bl_idname = "zoopraxis.flip_depth"
    bl_label = "Flip in Depth"
    bl_options = {'REGISTER', 'UNDO'}

    frame: IntProperty(name="Frame", description="Take frame of the anchor")
    part: StringProperty(name="Part", description="left arm, right arm, left leg, right leg "
                                                  "or body")

    def execute(self, context):
        from ..core.initialize.flips import FLIP_PARTS
        from . import pipeline

        settings = context.scene.zoopraxis
        if self.part not in FLIP_PARTS:
            self.report({'ERROR'}, f"unknown body part '{self.part}' (one of: "
                                   f"{', '.join(FLIP_PARTS)})")
            return {'CANCELLED'}
        if settings.running:
            self.report({'ERROR'}, "another Zoopraxis job is running (Esc stops it)")
            return {'CANCELLED'}
        flips = pipeline.parse_flips(settings.depth_flips)
        parts = flips.setdefault(self.frame, [])
        if self.part in parts:
            parts.remove(self.part)
        else:
            parts.append(self.part)
        settings.depth_flips = pipeline.format_flips({f: p for f, p in flips.items() if p})
        how = 'INVOKE_DEFAULT' if context.window is not None and not bpy.app.background \
            else 'EXEC_DEFAULT'
        # In the UI the initialization runs on as a modal job of its own; this operator is
        # done once it started (or ran) it.
        try:
            started = bpy.ops.zoopraxis.initialize(how)
        except RuntimeError as ex:          # the initialization's own one-line error
            self.report({'ERROR'}, str(ex).removeprefix("Error: ").strip())
            return {'CANCELLED'}
        return {'FINISHED'} if started & {'FINISHED', 'RUNNING_MODAL'} else {'CANCELLED'}


class ZOOPRAXIS_OT_track(JobOperator, bpy.types.Operator):
    """Track the body through the plates, then key it onto a new armature"""
    bl_idname = "zoopraxis.track"
    bl_label = "Track"
    bl_options = {'REGISTER', 'UNDO'}
    label = "Track"

    def prepare(self, context):
        from ..core.files.outputs import check_output
        from . import pipeline
        from .status import output_folder

        # result.json goes there after the work: a folder that takes no file is found now
        check_output(output_folder() / "result.json", True)
        self._take = take = pipeline.gather(context)
        init = pipeline.initial_for(context.scene, take)
        return lambda progress, cancel: pipeline.track(
            take, init=init, progress=progress, cancel=cancel,
            log=lambda message: print(f"zoopraxis track: {message}", flush=True))

    def finish(self, context, result, cancelled):
        from .status import apply_result

        return apply_result(context, result, cancelled, report=print)

    def cleanup(self):
        take = getattr(self, "_take", None)
        if take is not None:
            take.close()


class ZOOPRAXIS_OT_jump_worst_frame(bpy.types.Operator):
    """Go to the worst tracked frame: lost first, then uncertain, then the largest residual"""
    bl_idname = "zoopraxis.jump_worst_frame"
    bl_label = "Jump to Worst Frame"

    def execute(self, context):
        from .bake import worst_frame

        def work():
            obj = context.scene.zoopraxis.armature or context.active_object
            context.scene.frame_set(worst_frame(obj))

        return run(self, context, work)


# --- bake and export --------------------------------------------------------------------------

class ZOOPRAXIS_OT_bake(bpy.types.Operator):
    """Key a tracked result onto a new armature, or retarget it onto the target rig"""
    bl_idname = "zoopraxis.bake"
    bl_label = "Bake"
    bl_options = {'REGISTER', 'UNDO'}

    filepath: StringProperty(name="Result", subtype='FILE_PATH',
                             description="result.json (default: the take's last result)")

    def execute(self, context):
        from .bake import bake

        settings = context.scene.zoopraxis
        path = bpy.path.abspath(self.filepath or settings.result_path)
        bone_map = {pair.name: pair.bone for pair in settings.bone_map if pair.name}

        def work():
            if not path:
                raise ZoopraxisError("no result to bake: track the take or pick a result.json")
            obj, action = bake(context, path, rig=settings.rig, preset=settings.preset,
                               bone_map=bone_map, body_mesh=settings.body_mesh,
                               name=Path(path).stem, report=_reporter(self))
            settings.result_path = path

        return run(self, context, work)


def _armature(context):
    obj = context.active_object
    if obj is not None and obj.type == 'ARMATURE':
        return obj
    return context.scene.zoopraxis.armature


class ZOOPRAXIS_OT_export_bvh(bpy.types.Operator, ExportHelper):
    """Export the baked armature's motion as BVH with Blender's exporter"""
    bl_idname = "zoopraxis.export_bvh"
    bl_label = "Export BVH"
    filename_ext = ".bvh"
    filter_glob: StringProperty(default="*.bvh", options={'HIDDEN'})
    overwrite: BoolProperty(name="Overwrite", description="Replace an existing file")

    @classmethod
    def poll(cls, context):
        return _armature(context) is not None

    def execute(self, context):
        from .export import export_bvh

        return run(self, context, lambda: export_bvh(context, _armature(context), self.filepath,
                                                     force=self.overwrite,
                                                     report=_reporter(self)))


class ZOOPRAXIS_OT_export_fbx(bpy.types.Operator, ExportHelper):
    """Export the baked armature, its body mesh and motion as FBX with Blender's exporter"""
    bl_idname = "zoopraxis.export_fbx"
    bl_label = "Export FBX"
    filename_ext = ".fbx"
    filter_glob: StringProperty(default="*.fbx", options={'HIDDEN'})
    overwrite: BoolProperty(name="Overwrite", description="Replace an existing file")

    @classmethod
    def poll(cls, context):
        return _armature(context) is not None

    def execute(self, context):
        from .export import export_fbx

        arm = _armature(context)
        return run(self, context, lambda: export_fbx(context, [arm] + list(arm.children),
                                                     self.filepath, force=self.overwrite,
                                                     report=_reporter(self)))


# --- bone map ---------------------------------------------------------------------------------

class ZOOPRAXIS_OT_bone_map_add(bpy.types.Operator):
    """Add a row to the bone map"""
    bl_idname = "zoopraxis.bone_map_add"
    bl_label = "Add Bone Pair"
    bl_options = {'REGISTER', 'UNDO'}

    def execute(self, context):
        settings = context.scene.zoopraxis
        settings.bone_map.add()
        settings.active_bone_pair = len(settings.bone_map) - 1
        return {'FINISHED'}


class ZOOPRAXIS_OT_bone_map_remove(bpy.types.Operator):
    """Remove the active row of the bone map"""
    bl_idname = "zoopraxis.bone_map_remove"
    bl_label = "Remove Bone Pair"
    bl_options = {'REGISTER', 'UNDO'}

    @classmethod
    def poll(cls, context):
        return len(context.scene.zoopraxis.bone_map) > 0

    def execute(self, context):
        settings = context.scene.zoopraxis
        settings.bone_map.remove(min(settings.active_bone_pair, len(settings.bone_map) - 1))
        settings.active_bone_pair = max(0, settings.active_bone_pair - 1)
        return {'FINISHED'}


class ZOOPRAXIS_OT_bone_map_load(bpy.types.Operator, ImportHelper):
    """Fill the bone map from a JSON file mapping body segments to rig bones"""
    bl_idname = "zoopraxis.bone_map_load"
    bl_label = "Load Bone Map"
    bl_options = {'REGISTER', 'UNDO'}
    filter_glob: StringProperty(default="*.json", options={'HIDDEN'})

    def execute(self, context):
        from .retarget import read_bone_map

        def work():
            mapping = read_bone_map(self.filepath)
            settings = context.scene.zoopraxis
            settings.bone_map.clear()
            for segment, bone in mapping.items():
                pair = settings.bone_map.add()
                pair.name, pair.bone = segment, bone
            self.report({'INFO'}, f"bone map: {len(mapping)} pair(s) from {self.filepath}")

        return run(self, context, work)


classes = (
    ZOOPRAXIS_OT_load_plates, ZOOPRAXIS_OT_remove_view, ZOOPRAXIS_OT_add_joint_markers,
    ZOOPRAXIS_OT_export_markers, ZOOPRAXIS_OT_import_markers, ZOOPRAXIS_OT_load_calibration,
    ZOOPRAXIS_OT_export_calibration, ZOOPRAXIS_OT_calibrate_board, ZOOPRAXIS_OT_initialize,
    ZOOPRAXIS_OT_flip_depth, ZOOPRAXIS_OT_track, ZOOPRAXIS_OT_jump_worst_frame, ZOOPRAXIS_OT_bake,
    ZOOPRAXIS_OT_export_bvh, ZOOPRAXIS_OT_export_fbx, ZOOPRAXIS_OT_bone_map_add,
    ZOOPRAXIS_OT_bone_map_remove, ZOOPRAXIS_OT_bone_map_load,
)
