"""The fitted body over the plates: the last result's 2D joints as a stick figure in the clips.

A draw handler of the Movie Clip Editor's main region draws, for the clip's view and the
current frame, the tracked joints of the take's last result (``settings.result_path``, the
file a track writes or the one picked to bake) as the stick figure of
:data:`core.body.joints.STICK_BONES`: the subject's left in blue, right in red, the spine in white.
It reads ``joints2d`` per view, so calibrated and uncalibrated takes show alike. The scene's
``show_fit_overlay`` turns it on and off.

Convention: ``joints2d`` are OpenCV pixels of the view's plate; they become normalized clip
coordinates with :func:`convert.clip_from_pixels`, then the region's pixels through the clip
editor's View2D, whose view units are clip pixels (times the clip's display aspect) from the
image's bottom-left corner (zoom and pan included; 2D stabilization is not applied).
"""

import os

import bpy
import numpy as np

from ..core.errors import ZoopraxisError
from ..core.body.joints import JOINT_INDEX, STICK_BONES
from . import convert

LEFT_COLOR = (0.25, 0.5, 1.0, 1.0)
RIGHT_COLOR = (1.0, 0.3, 0.25, 1.0)
CENTER_COLOR = (0.95, 0.95, 0.95, 1.0)
LOST_ALPHA = 0.35
LINE_WIDTH = 2.0

# (path, mtime_ns) -> (TrackResult or None, {take frame: row}); one entry, the last result read.
_cache = {}
_handle = None


def _side(bone):
    if any(n.startswith("l_") for n in bone):
        return "left"
    if any(n.startswith("r_") for n in bone):
        return "right"
    return "center"


BONE_COLORS = tuple({"left": LEFT_COLOR, "right": RIGHT_COLOR, "center": CENTER_COLOR}[_side(b)]
                    for b in STICK_BONES)


def stick_segments(result, view, frame, image_size):
    """The stick figure of one view and take frame, in normalized clip coordinates.

    Parameters
    ----------
    result : core.result.TrackResult
    view : str
    frame : int
        Take frame (a value of ``result.frames``).
    image_size : (int, int)
        The view's plate size, pixels.

    Returns
    -------
    segments : array, shape (n, 2, 2)
        Bone ends as clip marker coordinates (origin bottom-left corner, y up, 0..1); bones
        with an end not tracked (NaN) are left out, so ``n`` may be 0.
    colors : array, shape (n, 4)
        RGBA per bone: left blue, right red, spine white; faded on a lost frame.
    """
    empty = np.zeros((0, 2, 2)), np.zeros((0, 4))
    if view not in result.joints2d:
        return empty
    rows = np.flatnonzero(np.asarray(result.frames) == int(frame))
    if rows.size == 0:
        return empty
    row = int(rows[0])
    uv = np.asarray(result.joints2d[view][row], float)
    ends = np.array([[JOINT_INDEX[a], JOINT_INDEX[b]] for a, b in STICK_BONES])
    segments = convert.clip_from_pixels(uv[ends], image_size)
    keep = np.isfinite(segments).all(axis=(1, 2))
    colors = np.array(BONE_COLORS)
    if result.status[row] == "lost":
        colors[:, 3] = LOST_ALPHA
    return segments[keep], colors[keep]


def last_result(settings):
    """The TrackResult at ``settings.result_path``, read once per file version; None if none
    or unreadable (the overlay then draws nothing)."""
    from ..core.files.result import read_result

    path = bpy.path.abspath(settings.result_path) if settings.result_path else ""
    if not path:
        return None
    try:
        key = (path, os.stat(path).st_mtime_ns)
    except OSError:
        return None
    if key not in _cache:
        _cache.clear()
        try:
            _cache[key] = read_result(path)
        except ZoopraxisError as ex:
            print(f"zoopraxis overlay: {ex}")
            _cache[key] = None
    return _cache[key]


def _clip_aspect(clip):
    """View units per clip pixel, (x, y), as ``BKE_movieclip_get_aspect``: x is always 1, y
    takes the clip's display aspect and the tracking camera's pixel aspect."""
    ax, ay = clip.display_aspect
    pixel = clip.tracking.camera.pixel_aspect or 1.0
    return 1.0, (ay / ax / pixel if ax > 0 else 1.0)


def region_from_clip(co, clip, view2d):
    """Region pixels of normalized clip coordinates, through the clip editor's View2D."""
    w, h = clip.size
    ax, ay = _clip_aspect(clip)
    span = 1000.0  # measure the View2D over a long stretch: view_to_region rounds to ints
    x0, y0 = view2d.view_to_region(0.0, 0.0, clip=False)
    x1, y1 = view2d.view_to_region(span, span, clip=False)
    sx, sy = (x1 - x0) / span, (y1 - y0) / span
    co = np.asarray(co, float)
    return np.stack([x0 + sx * co[..., 0] * w * ax, y0 + sy * co[..., 1] * h * ay], axis=-1)


def _draw():
    try:
        _draw_stick_figure(bpy.context)
    except Exception as ex:  # never break the editor's drawing
        print(f"zoopraxis overlay: {ex!r}")


def _draw_stick_figure(context):
    import gpu
    from gpu_extras.batch import batch_for_shader

    scene, space, region = context.scene, context.space_data, context.region
    settings = getattr(scene, "zoopraxis", None)
    if settings is None or not settings.show_fit_overlay or space is None or region is None:
        return
    clip = space.clip
    view = next((v for v in settings.views if clip is not None and v.clip == clip), None)
    if view is None:
        return
    result = last_result(settings)
    if result is None:
        return
    frame = scene.frame_current - settings.first_frame
    segments, colors = stick_segments(result, view.name, frame, tuple(clip.size))
    if not len(segments):
        return
    points = region_from_clip(segments.reshape(-1, 2), clip, region.view2d)
    vertex_colors = np.repeat(colors, 2, axis=0)
    try:
        shader = gpu.shader.from_builtin('POLYLINE_SMOOTH_COLOR')
        shader.uniform_float("viewportSize", (region.width, region.height))
        shader.uniform_float("lineWidth", LINE_WIDTH)
    except (ValueError, TypeError):
        shader = gpu.shader.from_builtin('SMOOTH_COLOR')
    batch = batch_for_shader(shader, 'LINES', {"pos": points.astype(np.float32).tolist(),
                                               "color": vertex_colors.astype(np.float32).tolist()})
    gpu.state.blend_set('ALPHA')
    batch.draw(shader)
    gpu.state.blend_set('NONE')


def is_drawing():
    """True while the draw handler is installed."""
    return _handle is not None


def register():
    global _handle
    if _handle is not None:
        return
    try:
        _handle = bpy.types.SpaceClipEditor.draw_handler_add(_draw, (), 'WINDOW', 'POST_PIXEL')
    except (RuntimeError, TypeError, ValueError) as ex:
        # No drawing without a GPU context (some background builds): the rest still works.
        print(f"zoopraxis overlay: no clip editor overlay ({ex})")
        _handle = None


def unregister():
    global _handle
    handle, _handle = _handle, None
    _cache.clear()
    if handle is not None:
        bpy.types.SpaceClipEditor.draw_handler_remove(handle, 'WINDOW')
