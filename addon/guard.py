"""Leave the scene as it was when an operator fails halfway.

An operator that fails returns CANCELLED, and Blender pushes no undo step for it: what the
worker had made by then (an armature without its action, a body mesh, timeline markers)
would stay in the file. :class:`SceneGuard` notes the data-blocks and markers there are before
the work and removes the ones the work added if it raises.
"""

import bpy

# Data-block collections a worker may add to; objects first, so nothing added is still used
# by an added object when its data is removed.
_COLLECTIONS = ("objects", "armatures", "meshes", "actions", "materials", "cameras",
                "collections")


class SceneGuard:
    """Context manager: on an exception, remove the data-blocks and timeline markers added
    inside it (the exception goes on)."""

    def __init__(self, scene=None):
        self.scene = scene

    def __enter__(self):
        self.scene = self.scene or bpy.context.scene
        self._before = {name: set(getattr(bpy.data, name)) for name in _COLLECTIONS}
        self._markers = set(self.scene.timeline_markers)
        return self

    def __exit__(self, kind, error, tb):
        if kind is None:
            return False
        for marker in [m for m in self.scene.timeline_markers if m not in self._markers]:
            self.scene.timeline_markers.remove(marker)
        for name in _COLLECTIONS:
            blocks = getattr(bpy.data, name)
            for block in [b for b in blocks if b not in self._before[name]]:
                blocks.remove(block)
        return False
