"""Export a baked take through Blender's own exporters (BVH, FBX) and save .blend files.

Each writer refuses to replace an existing file unless ``force``; selection and the active
object are restored afterwards.
"""

from pathlib import Path

import bpy

from ..core.errors import ZoopraxisError


def _check(path, force, suffix):
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise ZoopraxisError(f"{path}: expected a {suffix} file name")
    if path.exists() and not force:
        raise ZoopraxisError(f"{path}: file exists (use --force to replace it)")
    if not path.parent.is_dir():
        raise ZoopraxisError(f"{path}: folder {path.parent} does not exist")
    return path


class _Selection:
    """Select exactly ``objects`` (the first active) for an exporter; restore on exit."""

    def __init__(self, context, objects):
        self.context = context
        self.objects = list(objects)

    def __enter__(self):
        layer = self.context.view_layer
        self.before = [o for o in layer.objects if o.select_get()]
        self.active = layer.objects.active
        for o in self.before:
            o.select_set(False)
        for o in self.objects:
            o.select_set(True)
        layer.objects.active = self.objects[0]
        return self

    def __exit__(self, *exc):
        layer = self.context.view_layer
        for o in self.objects:
            if o.name in layer.objects:
                o.select_set(False)
        for o in self.before:
            if o.name in layer.objects:
                o.select_set(True)
        layer.objects.active = self.active


class _Restore:
    def __init__(self, scene, frame_range):
        self.scene, self.frame_range = scene, frame_range

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.scene.frame_start, self.scene.frame_end = self.frame_range


def _frame_range(obj, scene):
    action = obj.animation_data.action if obj.animation_data else None
    if action is None:
        return scene.frame_start, scene.frame_end
    start, end = action.frame_range
    return int(round(start)), int(round(end))


def export_bvh(context, armature, filepath, *, force=False, report=print):
    """Write the armature's action as BVH with ``bpy.ops.export_anim.bvh``; returns the path."""
    path = _check(filepath, force, ".bvh")
    if armature is None or armature.type != 'ARMATURE':
        raise ZoopraxisError(f"'{getattr(armature, 'name', None)}' is not an armature")
    start, end = _frame_range(armature, context.scene)
    with _Selection(context, [armature]):
        with context.temp_override(object=armature, active_object=armature):
            bpy.ops.export_anim.bvh(filepath=str(path), check_existing=False,
                                    frame_start=start, frame_end=end, rotate_mode='NATIVE')
    report(f"wrote {path} (frames {start}-{end})")
    return path


def export_fbx(context, objects, filepath, *, force=False, report=print):
    """Write objects (armature first) and their animation as FBX with Blender's exporter."""
    path = _check(filepath, force, ".fbx")
    objects = [o for o in objects if o is not None]
    if not objects:
        raise ZoopraxisError(f"{path}: nothing to export")
    scene = context.scene
    frame_range = scene.frame_start, scene.frame_end
    # The FBX exporter bakes the scene's frame range: narrow it to the take's while it runs.
    scene.frame_start, scene.frame_end = _frame_range(objects[0], scene)
    with _Selection(context, objects), _Restore(scene, frame_range):
        bpy.ops.export_scene.fbx(filepath=str(path), check_existing=False, use_selection=True,
                                 object_types={'ARMATURE', 'MESH'}, add_leaf_bones=False,
                                 bake_anim=True, bake_anim_use_all_actions=False,
                                 bake_anim_use_nla_strips=False, bake_anim_simplify_factor=0.0)
    report(f"wrote {path}")
    return path


def save_blend(filepath, *, force=False, report=print):
    """Save a copy of the session as .blend (the session keeps its own file name)."""
    path = _check(filepath, force, ".blend")
    bpy.ops.wm.save_as_mainfile(filepath=str(path), check_existing=False, copy=True)
    report(f"wrote {path}")
    return path
