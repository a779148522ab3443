"""Load plates into the scene: a movie clip per view, the frame range, rate and resolution.

Plates are opened with :mod:`core.imaging.plates` first (the reader the tracker uses), so anything the
tracker could not read is refused before the scene changes.
"""

from pathlib import Path

import bpy

from ..core.errors import ZoopraxisError
from ..core.body.joints import STANDARD_JOINTS
from ..core.imaging.plates import IMAGE_EXTENSIONS, natural_key, open_plate
from ..core.files.plausible import check_frame_rates
from . import convert


def plate_path(path):
    """The plate a picked path stands for: an image inside a folder means the folder."""
    path = Path(bpy.path.abspath(str(path)))
    if path.is_file() and path.suffix.lower() in IMAGE_EXTENSIONS:
        return path.parent
    return path


def _first_image(folder):
    images = sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_EXTENSIONS
                     and not p.name.startswith(".")), key=lambda p: natural_key(p.name))
    return images[0]


def ensure_joint_list(settings):
    if len(settings.joints) != len(STANDARD_JOINTS):
        settings.joints.clear()
        for name in STANDARD_JOINTS:
            settings.joints.add().name = name


def attach_background(camera_obj, clip):
    """Show ``clip`` behind ``camera_obj`` (once), so the fitted body is seen over the plate."""
    data = camera_obj.data
    data.show_background_images = True
    for bg in data.background_images:
        if bg.source == 'MOVIE_CLIP' and bg.clip == clip:
            return bg
    bg = data.background_images.new()
    bg.source = 'MOVIE_CLIP'
    bg.clip = clip
    bg.alpha = 1.0
    return bg


def find_camera(view_name):
    """A camera object calibrated for this view (``zoopraxis_view`` property), if any."""
    for obj in bpy.data.objects:
        if obj.type == 'CAMERA' and obj.get(convert.PROP_VIEW) == view_name:
            return obj
    return None


def load_plates(context, plates, *, fps=None, report=print):
    """Add one view per plate: a movie clip, the take's frame range, rate and resolution.

    Parameters
    ----------
    context : bpy.types.Context
    plates : dict of str to path, or list of paths
        View name -> video file or image folder (an image file stands for its folder). A list
        names each view after its folder or file stem.
    fps : float, optional
        Frame rate for image folders (a video's own rate is used otherwise).

    Returns
    -------
    views : list of ZOOPRAXIS_PG_view
        The views added.

    Raises
    ------
    ZoopraxisError
        A plate cannot be read, a view name is taken, or the plates differ in length (from
        each other or the views already loaded); nothing is changed then.
    """
    scene = context.scene
    settings = scene.zoopraxis
    items = plates.items() if isinstance(plates, dict) else [(None, p) for p in plates]
    if not items:
        raise ZoopraxisError("no plates given")
    opened = []
    for name, path in items:
        path = plate_path(path)
        with open_plate(path, name=name, fps=fps) as plate:
            opened.append((plate.name, path, plate.num_frames, plate.fps, plate.image_size))
    names = [o[0] for o in opened]
    check_frame_rates({o[0]: o[3] for o in opened})
    for name in names:
        if settings.view(name) is not None:
            raise ZoopraxisError(f"view '{name}' is already loaded")
        if names.count(name) > 1:
            raise ZoopraxisError(f"two plates are named '{name}'")
    lengths = [(v.name, v.num_frames) for v in settings.views] + [(o[0], o[2]) for o in opened]
    for name, n in lengths[1:]:
        if n != lengths[0][1]:
            raise ZoopraxisError(f"plate '{name}' has {n} frames but '{lengths[0][0]}' has "
                                 f"{lengths[0][1]}: the views of a take must be equally long")

    clips = []
    try:
        for name, path, n, _, size in opened:
            source = _first_image(path) if path.is_dir() else path
            clip = bpy.data.movieclips.load(str(source))
            clip.name = name
            clips.append(clip)
            if clip.frame_duration != n:
                report(f"clip '{name}': Blender sees {clip.frame_duration} frames, the plate "
                       f"has {n} (are the images numbered one by one?)")
    except RuntimeError as ex:
        for clip in clips:
            bpy.data.movieclips.remove(clip)
        raise ZoopraxisError(f"Blender cannot load plate '{name}' ({path}): {ex}") from None

    first_new = not len(settings.views)
    added = []
    for (name, path, n, plate_fps, size), clip in zip(opened, clips):
        view = settings.views.add()
        view.name, view.path, view.clip, view.num_frames = name, str(path), clip, n
        camera = find_camera(name)
        if camera is not None:
            view.camera = camera
            attach_background(camera, clip)
        added.append(view)
    settings.active_view = len(settings.views) - 1
    ensure_joint_list(settings)
    from .props import _sync_clip_start

    _sync_clip_start(settings)
    n = opened[0][2]
    scene.frame_start = settings.first_frame
    scene.frame_end = settings.first_frame + n - 1
    if first_new:
        w, h = opened[0][4]
        scene.render.resolution_x, scene.render.resolution_y = w, h
        scene.render.resolution_percentage = 100
        rate = next((o[3] for o in opened if o[3]), None)
        if rate:
            scene.render.fps = max(1, int(round(rate)))
            scene.render.fps_base = scene.render.fps / rate
    report(f"loaded {len(added)} plate(s): {', '.join(names)} ({n} frames)")
    return added
