"""The fitted body over the plates: stick-figure segments from a result, and the clip editor's
draw handler installed and removed with the extension (background mode, no drawing)."""

import numpy as np

from test_addon_support import blender, bpy, registered, synthetic_result  # noqa: F401

from zoopraxis.core.body.joints import JOINT_INDEX, STICK_BONES


def test_stick_segments_are_clip_coordinates_of_the_view_and_frame():
    from zoopraxis.addon import convert, overlay

    result, _ = synthetic_result(5, views=("cam0", "cam1"))
    result.mode = "uncalibrated"
    result.joints2d["cam1"] = result.joints2d["cam1"] + 7.0
    result.frames = np.arange(10, 15)
    size = (480, 360)
    segments, colors = overlay.stick_segments(result, "cam1", 12, size)
    assert segments.shape == (len(STICK_BONES), 2, 2) and colors.shape == (len(STICK_BONES), 4)
    uv = result.joints2d["cam1"][2]
    for (a, b), seg in zip(STICK_BONES, segments):
        np.testing.assert_allclose(convert.pixels_from_clip(seg, size),
                                   uv[[JOINT_INDEX[a], JOINT_INDEX[b]]], atol=1e-9)
    # the pixel centre (0, 0) is half a pixel in from the clip's top-left corner
    np.testing.assert_allclose(convert.clip_from_pixels([0.0, 0.0], size),
                               [0.5 / 480, 1 - 0.5 / 360])
    bones = dict(zip(STICK_BONES, colors))
    assert tuple(bones[("l_knee", "l_ankle")]) == overlay.LEFT_COLOR
    assert tuple(bones[("neck", "r_shoulder")]) == overlay.RIGHT_COLOR
    assert tuple(bones[("pelvis", "neck")]) == overlay.CENTER_COLOR

    # a frame or view the result lacks draws nothing; untracked joints drop their bones
    assert overlay.stick_segments(result, "cam1", 3, size)[0].shape == (0, 2, 2)
    assert overlay.stick_segments(result, "cam9", 12, size)[0].shape == (0, 2, 2)
    result.joints2d["cam0"] = result.joints2d["cam0"].copy()
    result.joints2d["cam0"][0, JOINT_INDEX["l_wrist"]] = np.nan
    segments, _ = overlay.stick_segments(result, "cam0", 10, size)
    assert len(segments) == len(STICK_BONES) - 1
    result.status[1] = "lost"
    _, colors = overlay.stick_segments(result, "cam0", 11, size)
    assert np.allclose(colors[:, 3], overlay.LOST_ALPHA)


def test_region_pixels_follow_the_clip_editor_zoom_and_pan(blender, tmp_path):
    from zoopraxis.addon import overlay

    image = tmp_path / "plate.png"
    bpy.data.images.new("plate", 64, 48).save(filepath=str(image))
    clip = bpy.data.movieclips.load(str(image))
    assert tuple(clip.size) == (64, 48)

    class View2D:           # zoom 2, image's bottom-left corner at region pixel (30, 10)
        def view_to_region(self, x, y, clip=True):
            return round(30 + 2 * x), round(10 + 2 * y)

    corners = overlay.region_from_clip([[0.0, 0.0], [1.0, 1.0], [0.5, 0.25]], clip, View2D())
    np.testing.assert_allclose(corners, [[30, 10], [30 + 128, 10 + 96], [30 + 64, 10 + 24]])
    clip.display_aspect = (1.0, 2.0)          # tall pixels: the clip editor stretches y
    corners = overlay.region_from_clip([[1.0, 1.0]], clip, View2D())
    np.testing.assert_allclose(corners, [[30 + 128, 10 + 192]])


def test_last_result_reads_the_take_result_once_per_version(blender, tmp_path):
    from test_addon_support import write_result
    from zoopraxis.addon import overlay

    settings = blender.scene.zoopraxis
    assert overlay.last_result(settings) is None
    settings.result_path = str(tmp_path / "missing.json")
    assert overlay.last_result(settings) is None
    path = write_result(tmp_path / "result.json", synthetic_result(3)[0])
    settings.result_path = str(path)
    first = overlay.last_result(settings)
    assert first is not None and first.num_frames == 3
    assert overlay.last_result(settings) is first
    (tmp_path / "bad.json").write_text("{")
    settings.result_path = str(tmp_path / "bad.json")
    assert overlay.last_result(settings) is None       # reported on the console, not raised


def test_draw_handler_follows_register_and_unregister(registered):
    import zoopraxis
    from zoopraxis.addon import overlay

    assert overlay.is_drawing()
    zoopraxis.unregister()
    assert not overlay.is_drawing()
    zoopraxis.register()
    assert overlay.is_drawing()
    overlay._draw()                 # no clip editor in the context: draws nothing, no error


def test_draw_handler_guard_when_drawing_is_unavailable(registered, monkeypatch):
    from zoopraxis.addon import overlay

    overlay.unregister()

    def refuse(*args):
        raise RuntimeError("no GPU")

    with monkeypatch.context() as m:
        m.setattr(bpy.types.SpaceClipEditor, "draw_handler_add", refuse, raising=False)
        overlay.register()
        assert not overlay.is_drawing()
        overlay.unregister()           # nothing installed: nothing to remove
    overlay.register()
    assert overlay.is_drawing()
