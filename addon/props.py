"""The take's settings, stored on the scene as ``scene.zoopraxis``.

Views (one plate each: clip, camera object, frame offset), the joint list the marker panel
shows, tracker settings, the bone map for retargeting, and the state of a running job.
"""

import bpy
from bpy.props import (BoolProperty, CollectionProperty, EnumProperty, FloatProperty,
                       IntProperty, PointerProperty, StringProperty)

from ..core.body.body import TEMPLATES
from .preferences import TRACKERS
from .retarget import PRESETS

# Lines of ``init_notes`` that are notes (what the animator may do), not warnings.
NOTE_PREFIX = "note: "


def _sync_clip_start(settings):
    """Place every view's clip so take frame 0 shows at ``first_frame`` (plate frame = take
    frame + offset; clip frame 1 is plate frame 0)."""
    for view in settings.views:
        if view.clip is not None:
            view.clip.frame_start = settings.first_frame - view.offset


def _view_changed(self, context):
    _sync_clip_start(context.scene.zoopraxis)


def _redraw_clips(self, context):
    for area in context.screen.areas if context.screen else ():
        if area.type == 'CLIP_EDITOR':
            area.tag_redraw()


def _is_camera(self, obj):
    return obj.type == 'CAMERA'


def _is_armature(self, obj):
    return obj.type == 'ARMATURE'


class ZOOPRAXIS_PG_view(bpy.types.PropertyGroup):
    name: StringProperty(name="View", description="View name, as in markers.json and "
                                                  "calibration.json")
    path: StringProperty(name="Plate", description="Video file or image folder",
                         subtype='FILE_PATH')
    clip: PointerProperty(name="Clip", type=bpy.types.MovieClip)
    camera: PointerProperty(name="Camera", type=bpy.types.Object, poll=_is_camera,
                            description="Calibrated camera of this view")
    offset: IntProperty(name="Offset", description="Plate frame shown at take frame 0",
                        update=_view_changed)
    num_frames: IntProperty(name="Frames")


class ZOOPRAXIS_PG_joint(bpy.types.PropertyGroup):
    name: StringProperty(name="Joint")


class ZOOPRAXIS_PG_bone_pair(bpy.types.PropertyGroup):
    name: StringProperty(name="Segment", description="Body segment")
    bone: StringProperty(name="Bone", description="Bone of the target rig")


class ZOOPRAXIS_PG_settings(bpy.types.PropertyGroup):
    views: CollectionProperty(type=ZOOPRAXIS_PG_view)
    active_view: IntProperty()
    joints: CollectionProperty(type=ZOOPRAXIS_PG_joint)
    active_joint: IntProperty()
    first_frame: IntProperty(name="First Frame", default=1, update=_view_changed,
                             description="Scene frame of take frame 0")

    calibration_path: StringProperty(name="Calibration", subtype='FILE_PATH')
    board: StringProperty(name="Board", default="checkerboard:9x6:0.04",
                          description="checkerboard:COLSxROWS:SQUARE_M (inner corners, metres) "
                                      "or charuco:COLSxROWS:SQUARE_M:MARKER_M[:DICT]")
    board_step: IntProperty(name="Step", default=1, min=1,
                            description="Search the board in every n-th take frame")
    board_world_frame: IntProperty(name="World Frame", default=-1, min=-1,
                                   description="Take frame whose board lies on the floor and "
                                               "defines the world (-1: the one most cameras "
                                               "see)")
    board_max_rms: FloatProperty(name="Max RMS", default=1.0, min=0.01, subtype='PIXEL',
                                 description="Refuse a calibration whose reprojection error "
                                             "is above this, pixels")
    markers_path: StringProperty(name="Markers", subtype='FILE_PATH')
    result_path: StringProperty(name="Result", subtype='FILE_PATH',
                                description="result.json of the last track, or one to bake")

    template: EnumProperty(name="Body", items=[(t.upper(), t.title(), f"Body template '{t}'")
                                               for t in TEMPLATES], default='FULL')
    tracker: EnumProperty(name="Tracker", items=TRACKERS, default='DIFFERENTIAL')
    use_frame_range: BoolProperty(name="Frame Range", description="Track part of the take")
    frame_range_start: IntProperty(name="Start", min=0, description="First take frame")
    frame_range_end: IntProperty(name="End", min=1, default=1,
                                 description="Take frame after the last")

    running: BoolProperty(name="Running")
    status: StringProperty(name="Status")
    progress: FloatProperty(name="Progress", min=0.0, max=1.0, subtype='FACTOR')
    initialized: BoolProperty(name="Initialized")
    init_notes: StringProperty(
        name="Initialization Notes",
        description="Warnings and notes of the last initialization, one a line (notes start "
                    "with 'note: ')")
    one_view_frames: StringProperty(
        name="Frames Clicked in One View",
        description="Anchor frames of the last initialization clicked in one view only "
                    "(comma separated): their limbs' depth is a guess the animator may flip")
    ambiguous_parts: StringProperty(
        name="Ambiguous Parts",
        description="FRAME:PART;... that another depth fits about as well (last "
                    "initialization)")
    camera_tilt: FloatProperty(
        name="Camera Looks Down", default=0.0, min=-80.0, max=80.0, step=100, precision=0,
        description="Uncalibrated, at anchor frames clicked in one view: how many degrees the "
                    "camera looks down at the upright subject (give or take 10; one view "
                    "cannot see the subject's lean towards or away from it). Used by "
                    "Initialize and Track")
    pose_prior_path: StringProperty(
        name="Pose Prior", subtype='FILE_PATH',
        description="At anchor frames clicked in one view, the limbs' depth is chosen by a "
                    "pose prior: empty for the shipped one, or a prior file learned from "
                    "takes of the motion at hand ('zoopraxis prior'). Used by Initialize and "
                    "Track")
    proportions_prior_path: StringProperty(
        name="Proportions Prior", subtype='FILE_PATH',
        description="The body proportions the fitted lengths lean on: empty for the shipped "
                    "prior (captured performers), or a file from "
                    "tools/learn_proportions_prior.py. Uncalibrated, a given file's mean and "
                    "spread replace the template's proportions. Used by Initialize and Track")
    use_pose_basis: BoolProperty(
        name="Pose Basis", default=True,
        description="Uncalibrated, at anchor frames clicked in one view: also search from a "
                    "basis of captured 3D poses fitted to the clicks and let it, beside "
                    "everyday poses, choose the pose. Off: the pose prior alone (a little "
                    "better for poses unlike any captured). Used by Initialize and Track")
    dims_path: StringProperty(
        name="Body Lengths From", subtype='FILE_PATH',
        description="Keep the body lengths of the same performer fitted before: an init.json "
                    "or result.json of a shot seen in several views (one view alone sees the "
                    "lengths poorly). Empty: fit them to the clicks. Used by Initialize and "
                    "Track")
    near_cameras: BoolProperty(
        name="Near Cameras", default=False,
        description="Uncalibrated views filmed from near the body (a phone or a normal lens a "
                    "few metres away): fit each camera's perspective too. Off: far or telephoto "
                    "views, scaled orthographic. Used by Initialize and Track")
    depth_flips: StringProperty(
        name="Depth Flips",
        description="FRAME:PART;... turned to their other depth by the animator (used by "
                    "Initialize and Track)")

    armature: PointerProperty(name="Armature", type=bpy.types.Object, poll=_is_armature,
                              description="Armature of the last bake")
    rig: PointerProperty(name="Target Rig", type=bpy.types.Object, poll=_is_armature,
                         description="Existing rig to retarget onto (empty: build an armature)")
    preset: EnumProperty(name="Naming", items=PRESETS, default='MIXAMO')
    bone_map: CollectionProperty(type=ZOOPRAXIS_PG_bone_pair)
    active_bone_pair: IntProperty()
    show_fit_overlay: BoolProperty(name="Show Fit", default=True, update=_redraw_clips,
                                   description="Draw the tracked joints of the last result "
                                               "over the plates in the Movie Clip Editor")
    body_mesh: BoolProperty(name="Body Mesh", default=True,
                            description="Bind the volumetric body to the baked armature")

    def view(self, name):
        return next((v for v in self.views if v.name == name), None)


classes = (ZOOPRAXIS_PG_view, ZOOPRAXIS_PG_joint, ZOOPRAXIS_PG_bone_pair, ZOOPRAXIS_PG_settings)


@bpy.app.handlers.persistent
def _forget_initial(*args):
    # An initialization belongs to the session's scene, not to a newly loaded file.
    from . import pipeline

    pipeline.forget()


def register():
    bpy.types.Scene.zoopraxis = PointerProperty(type=ZOOPRAXIS_PG_settings)
    bpy.app.handlers.load_post.append(_forget_initial)


def unregister():
    if _forget_initial in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(_forget_initial)
    del bpy.types.Scene.zoopraxis
