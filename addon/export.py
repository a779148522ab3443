"""Export a baked take through Blender's own exporters (BVH, FBX) and save .blend files.

Each writer refuses to replace an existing file unless ``force``, and has Blender's exporter
write a temporary file beside the target that replaces it only once complete; selection and
the active object are restored afterwards.
"""

import contextlib
import os
import re
import sys
import tempfile

import bpy

from ..core.errors import ZoopraxisError
from ..core.files.outputs import check_output, replacing


def _check(path, force, suffix):
    return check_output(path, force, suffixes=(suffix,), option="export")


@contextlib.contextmanager
def _exporting(path, what):
    """A temporary file name beside ``path`` for one of Blender's exporters, which write in
    place: renamed over ``path`` only when the exporter succeeded, so a failure (a full disk)
    leaves the old file as it was. A failed exporter becomes one ZoopraxisError naming the
    file; what it printed (Blender prints the traceback itself) is kept as the error's note."""
    with replacing(path, suffix=path.suffix) as temporary:
        # The exporter makes the file itself (and .blend saving would back up an existing one).
        temporary.unlink()
        console = _Console()
        try:
            with console:
                yield temporary
        except RuntimeError as error:
            text = console.text + str(error)
            error = ZoopraxisError(f"{path}: {what} failed ({_exception_line(text)})"
                                   + ("; the old file is unchanged" if path.exists() else ""))
            error.add_note(text)
            raise error from None
        console.replay()


def _exception_line(text):
    """The line naming the exception in a printed traceback (the last such), else the last."""
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    named = [line for line in lines if re.match(r"^[\w.]*(Error|Exception)\b.*:", line)]
    return (named or lines or ["no message"])[-1]


class _Console:
    """Catch what Blender prints on the process's stdout and stderr (C code writes there, not
    through sys.stdout) while an exporter runs; ``replay`` passes it on unchanged."""

    def __init__(self):
        self.text = ""
        self._sink = self._saved = None

    def __enter__(self):
        try:
            self._sink = tempfile.TemporaryFile()
            sys.stdout.flush()
            sys.stderr.flush()
            self._saved = (os.dup(1), os.dup(2))
            os.dup2(self._sink.fileno(), 1)
            os.dup2(self._sink.fileno(), 2)
        except OSError:
            self._sink = self._saved = None  # no capture then: the output goes through
        return self

    def __exit__(self, *exc):
        if self._saved is None:
            return False
        sys.stdout.flush()
        sys.stderr.flush()
        for fd, saved in zip((1, 2), self._saved):
            os.dup2(saved, fd)
            os.close(saved)
        self._sink.seek(0)
        self.text = self._sink.read().decode("utf-8", "replace")
        self._sink.close()
        return False

    def replay(self):
        if self.text:
            sys.stdout.write(self.text)
            sys.stdout.flush()


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
            with _exporting(path, "Blender's BVH exporter") as temporary:
                bpy.ops.export_anim.bvh(filepath=str(temporary), check_existing=False,
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
    with _Selection(context, objects), _Restore(scene, frame_range), \
            _exporting(path, "Blender's FBX exporter") as temporary:
        bpy.ops.export_scene.fbx(filepath=str(temporary), check_existing=False,
                                 use_selection=True, object_types={'ARMATURE', 'MESH'},
                                 add_leaf_bones=False, bake_anim=True,
                                 bake_anim_use_all_actions=False, bake_anim_use_nla_strips=False,
                                 bake_anim_simplify_factor=0.0)
    report(f"wrote {path}")
    return path


def save_blend(filepath, *, force=False, report=print):
    """Save a copy of the session as .blend (the session keeps its own file name)."""
    path = _check(filepath, force, ".blend")
    with _exporting(path, "saving the .blend file") as temporary:
        bpy.ops.wm.save_as_mainfile(filepath=str(temporary), check_existing=False, copy=True)
    report(f"wrote {path}")
    return path
