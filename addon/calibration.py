"""Calibration in the scene: camera objects <-> calibration files, and a board in the plates.

The camera objects are the calibration: whatever the user adjusts on them is what tracking
uses. Loading a file adds new camera objects (existing ones are never changed) and points the
views at them.
"""

from pathlib import Path

import bpy

from ..core.files.calibfile import cameras_for_plates, read_calibration, write_calibration
from ..core.geometry.camera import PinholeCamera
from ..core.errors import ZoopraxisError
from . import convert
from .plates import attach_background


def cameras_from_scene(context, *, required=True):
    """PinholeCamera of every view from its camera object, by view name.

    Returns an empty dict when no view has a camera and ``required`` is False (uncalibrated).
    """
    settings = context.scene.zoopraxis
    cameras = {}
    missing = []
    for view in settings.views:
        if view.camera is None:
            missing.append(view.name)
            continue
        size = tuple(view.clip.size) if view.clip is not None else None
        cameras[view.name] = convert.pinhole_from_object(view.camera, name=view.name,
                                                         image_size=size, scene=context.scene)
    if missing and (required or cameras):
        raise ZoopraxisError(f"view '{missing[0]}' has no camera object: load a calibration or "
                             "pick its camera")
    return cameras


def add_camera_objects(context, cameras, *, report=print):
    """A new camera object per PinholeCamera, assigned to the view of the same name.

    Returns
    -------
    objects : dict of str to bpy.types.Object
    """
    settings = context.scene.zoopraxis
    collection = getattr(context, "collection", None) or context.scene.collection
    objects = {}
    for name, camera in cameras.items():
        data = bpy.data.cameras.new(name)
        obj = bpy.data.objects.new(name, data)
        collection.objects.link(obj)
        convert.apply_pinhole(obj, camera, context.scene)
        data.clip_start, data.clip_end = 0.05, 200.0
        view = settings.view(name)
        if view is not None:
            view.camera = obj
            if view.clip is not None:
                attach_background(obj, view.clip)
        objects[name] = obj
    if context.scene.camera is None and objects:
        context.scene.camera = next(iter(objects.values()))
    return objects


def load_calibration(context, filepath, *, report=print):
    """Read calibration.json or Pose2Sim/anipose TOML and show its cameras as camera objects.

    Raises
    ------
    ZoopraxisError
        The file is bad, holds no perspective camera, or a camera's image size is neither its
        view's plate's nor one the plate can be taken for (``calibfile.camera_for_plate``).
    """
    settings = context.scene.zoopraxis
    cameras = read_calibration(filepath)
    pinholes = {n: c for n, c in cameras.items() if isinstance(c, PinholeCamera)}
    if not pinholes:
        raise ZoopraxisError(f"{filepath}: no perspective camera to show")
    sizes = {}
    for name in pinholes:
        view = settings.view(name)
        if view is not None and view.clip is not None:
            sizes[name] = tuple(view.clip.size)
    pinholes, notes = cameras_for_plates(pinholes, sizes, filepath)
    for note in notes:
        report(note)
    objects = add_camera_objects(context, pinholes, report=report)
    settings.calibration_path = str(filepath)
    unmatched = [v.name for v in settings.views if v.name not in pinholes]
    report(f"loaded {len(objects)} camera(s) from {Path(filepath).name}"
           + (f"; no camera for view(s) {', '.join(unmatched)}" if unmatched else ""))
    return objects


def export_calibration(context, filepath, *, force=False, report=print):
    """Write the views' camera objects to calibration.json."""
    cameras = cameras_from_scene(context)
    if not cameras:
        raise ZoopraxisError("no view has a camera object to write")
    write_calibration(filepath, cameras, force=force)
    report(f"wrote {len(cameras)} camera(s) to {filepath}")
    return cameras
