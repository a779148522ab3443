"""Clip marker coordinates and Blender cameras <-> OpenCV: the add-on's conversions."""

import numpy as np
import pytest

from test_addon_support import blender, bpy, registered  # noqa: F401

from zoopraxis.addon import convert
from zoopraxis.core.geometry.camera import PinholeCamera, look_at


def make_camera(size=(640, 480), fx=700.0, fy=None, c=None, name="cam0"):
    R, t = look_at([3.0, -4.0, 1.6], [0.2, 0.1, 1.0])
    c = c or ((size[0] - 1) / 2 + 23.0, (size[1] - 1) / 2 - 17.0)
    K = [[fx, 0.0, c[0]], [0.0, fy or fx, c[1]], [0.0, 0.0, 1.0]]
    return PinholeCamera(name, size, K, R=R, t=t)


def points(rng, n=30):
    return rng.uniform([-0.8, -0.8, 0.0], [1.2, 1.0, 2.0], (n, 3))


def test_clip_pixel_round_trip_and_corners():
    size = (640, 480)
    uv = np.array([[0.0, 0.0], [639.0, 479.0], [319.5, 239.5], [-0.5, -0.5]])
    co = convert.clip_from_pixels(uv, size)
    # Pixel centre 0 sits half a pixel in from the left edge; y is flipped.
    assert co[0] == pytest.approx([0.5 / 640, 1 - 0.5 / 480])
    assert co[2] == pytest.approx([0.5, 0.5])
    assert co[3] == pytest.approx([0.0, 1.0])
    np.testing.assert_allclose(convert.pixels_from_clip(co, size), uv, atol=1e-9)
    assert convert.pixels_from_clip(np.zeros((2, 3, 2)), size).shape == (2, 3, 2)


def test_markers_placed_at_projections_read_back(blender, rng, tmp_path):
    import cv2

    size = (640, 480)
    folder = tmp_path / "plate"
    folder.mkdir()
    for i in range(3):
        cv2.imwrite(str(folder / f"{i:04d}.png"), np.full((size[1], size[0], 3), 40 * i, np.uint8))
    clip = bpy.data.movieclips.load(str(folder / "0000.png"))
    assert tuple(clip.size) == size
    camera = make_camera(size)
    uv = camera.project(points(rng))
    track = clip.tracking.tracks.new(name="probe", frame=1)
    co = convert.clip_from_pixels(uv, size)
    for frame, xy in enumerate(co, start=1):
        track.markers.insert_frame(frame + 1, co=tuple(xy))
    read = np.array([track.markers.find_frame(f + 1).co[:] for f in range(1, len(uv) + 1)])
    np.testing.assert_allclose(convert.pixels_from_clip(read, clip.size), uv, atol=0.01)


@pytest.mark.parametrize("fy, aspect", [(None, (1.0, 1.0)), (None, (1.0, 1.25)),
                                        (712.0, (1.0, 1.0))])
def test_blender_camera_projects_like_pinhole(blender, rng, fy, aspect):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    scene = blender.scene
    size = (640, 480)
    scene.render.resolution_x, scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x, scene.render.pixel_aspect_y = aspect
    camera = make_camera(size, fy=fy)
    obj = bpy.data.objects.new("cam0", bpy.data.cameras.new("cam0"))
    scene.collection.objects.link(obj)
    convert.apply_pinhole(obj, camera, scene)
    bpy.context.view_layer.update()

    X = points(rng)
    ndc = np.array([world_to_camera_view(scene, obj, Vector(x))[:2] for x in X])
    blender_uv = convert.pixels_from_clip(ndc, size)
    if fy is None and aspect == (1.0, 1.0):
        # Blender itself can express this camera: its projection is the camera's.
        np.testing.assert_allclose(blender_uv, camera.project(X), atol=0.01)
    # Without the stored K, the camera read back is what Blender projects.
    stored = obj.pop(convert.PROP_K)
    np.testing.assert_allclose(convert.pinhole_from_object(obj, scene=scene).project(X),
                               blender_uv, atol=0.01)
    obj[convert.PROP_K] = stored
    back = convert.pinhole_from_object(obj, scene=scene)
    np.testing.assert_allclose(back.project(X), camera.project(X), atol=0.01)
    np.testing.assert_allclose(back.K, camera.K, atol=1e-3)
    np.testing.assert_allclose(back.R, camera.R, atol=1e-6)
    assert back.name == "cam0" and back.image_size == size


def test_edited_blender_camera_wins_over_stored_intrinsics(blender, rng):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    scene = blender.scene
    scene.render.resolution_x, scene.render.resolution_y = 640, 480
    obj = bpy.data.objects.new("cam0", bpy.data.cameras.new("cam0"))
    scene.collection.objects.link(obj)
    convert.apply_pinhole(obj, make_camera(), scene)
    obj.data.lens *= 1.3
    obj.data.shift_y = 0.05
    obj.data.sensor_fit = 'AUTO'
    obj.location.x += 0.5
    bpy.context.view_layer.update()
    X = points(rng)
    ndc = np.array([world_to_camera_view(scene, obj, Vector(x))[:2] for x in X])
    back = convert.pinhole_from_object(obj, scene=scene)
    np.testing.assert_allclose(back.project(X), convert.pixels_from_clip(ndc, (640, 480)),
                               atol=0.01)


def test_vertical_fit_and_portrait_images(blender, rng):
    from bpy_extras.object_utils import world_to_camera_view
    from mathutils import Vector

    scene = blender.scene
    scene.render.resolution_x, scene.render.resolution_y = 360, 640
    obj = bpy.data.objects.new("c", bpy.data.cameras.new("c"))
    scene.collection.objects.link(obj)
    obj.location = (0.5, -5.0, 1.0)
    obj.rotation_euler = (1.4, 0.05, 0.1)
    for fit in ('AUTO', 'VERTICAL'):
        obj.data.sensor_fit = fit
        obj.data.shift_x, obj.data.shift_y = 0.03, -0.02
        bpy.context.view_layer.update()
        X = points(rng)
        ndc = np.array([world_to_camera_view(scene, obj, Vector(x))[:2] for x in X])
        cam = convert.pinhole_from_object(obj, scene=scene)
        np.testing.assert_allclose(cam.project(X), convert.pixels_from_clip(ndc, (360, 640)),
                                   atol=0.01)


def test_non_camera_and_orthographic_are_refused(blender):
    from zoopraxis.core.errors import ZoopraxisError

    empty = bpy.data.objects.new("e", None)
    with pytest.raises(ZoopraxisError, match="'e' is not a camera"):
        convert.pinhole_from_object(empty)
    obj = bpy.data.objects.new("o", bpy.data.cameras.new("o"))
    obj.data.type = 'ORTHO'
    with pytest.raises(ZoopraxisError, match="not perspective"):
        convert.pinhole_from_object(obj, image_size=(10, 10))
