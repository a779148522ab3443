"""The extension's preferences: tracker defaults, and whether the numerical dependencies load."""

import importlib.util

import bpy

# Blender looks preferences up by the extension's root package: ``zoopraxis`` in a plain
# install, ``bl_ext.<repo>.zoopraxis`` inside Blender. This module lives one level below it.
ROOT_PACKAGE = __package__.rpartition(".")[0]

# Blender ships numpy but neither scipy nor OpenCV; the extension zip built with wheels
# brings them, a plain zip relies on the user's own.
DEPENDENCIES = (("numpy", "numpy"), ("scipy", "scipy"), ("cv2", "OpenCV"))

TRACKERS = (
    ('DIFFERENTIAL', "Differential", "Gauss-Newton on image motion (Bregler & Malik, Yamamoto et al.)"),
    ('PARTICLE', "Particle", "Particle filter with a walking prior (Sidenbladh, Black & Fleet)"),
    ('HYBRID', "Hybrid", "Particle filter whose particles are refined differentially"),
)


def missing_dependencies():
    """Return the display names of the numerical dependencies Python cannot find."""
    return [label for module, label in DEPENDENCIES if importlib.util.find_spec(module) is None]


class ZOOPRAXIS_AddonPreferences(bpy.types.AddonPreferences):
    bl_idname = ROOT_PACKAGE

    default_tracker: bpy.props.EnumProperty(
        name="Default Tracker",
        description="Tracker used when a take does not choose one",
        items=TRACKERS,
        default='DIFFERENTIAL',
    )

    def draw(self, context):
        layout = self.layout
        layout.prop(self, "default_tracker")
        missing = missing_dependencies()
        if missing:
            col = layout.column(align=True)
            col.label(text="Missing: " + ", ".join(missing), icon='ERROR')
            col.label(text="Install the Zoopraxis build that bundles its wheels")
        else:
            layout.label(text="numpy, scipy and OpenCV are available", icon='CHECKMARK')


classes = (ZOOPRAXIS_AddonPreferences,)
