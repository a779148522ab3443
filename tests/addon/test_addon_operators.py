"""The operators against the real bpy: plates, calibration, markers, jobs, bake, export, undo."""

import shutil

import numpy as np
import pytest

from test_addon_support import (SAMPLE, blender, bpy, registered,  # noqa: F401
                                synthetic_result, write_result)

from zoopraxis.core.errors import ZoopraxisError


def load_sample(views=("cam0", "cam1", "cam2")):
    bpy.ops.zoopraxis.load_plates(filepath=str(SAMPLE / views[0] / "000000.jpg"),
                                  directory=str(SAMPLE / views[0]),
                                  files=[{"name": "000000.jpg"}])
    for v in views[1:]:
        bpy.ops.zoopraxis.load_plates(filepath=str(SAMPLE / v / "000000.jpg"))
    return bpy.context.scene.zoopraxis


def remembered_initialization(context):
    """The initialization the add-on remembers for the scene's take as it is now, or None
    (none made, or made for other markers, cameras or one-view settings)."""
    from zoopraxis.addon import pipeline

    take = pipeline.gather(context)
    try:
        return pipeline.initial_for(context.scene, take)
    finally:
        take.close()


def scene_state():
    scene = bpy.context.scene
    return (len(bpy.data.objects), len(bpy.data.movieclips), len(bpy.data.actions),
            len(scene.zoopraxis.views), [len(c.tracking.tracks) for c in bpy.data.movieclips],
            scene.frame_start, scene.frame_end)


def test_load_plates_and_calibration(blender, tmp_path):
    from zoopraxis.addon.calibration import cameras_from_scene
    from zoopraxis.core.files.calibfile import read_calibration

    settings = load_sample()
    scene = blender.scene
    assert [v.name for v in settings.views] == ["cam0", "cam1", "cam2"]
    assert all(v.clip.frame_duration == 48 and v.num_frames == 48 for v in settings.views)
    assert (scene.frame_start, scene.frame_end) == (1, 48)
    assert (scene.render.resolution_x, scene.render.resolution_y) == (480, 360)
    assert len(settings.joints) == 17
    settings.views[1].offset = 3
    assert settings.views[1].clip.frame_start == -2
    settings.views[1].offset = 0

    bpy.ops.zoopraxis.load_calibration(filepath=str(SAMPLE / "calibration.json"))
    assert all(v.camera is not None for v in settings.views)
    cam = settings.views[2].camera
    bg = cam.data.background_images[0]
    assert cam.data.show_background_images and bg.clip == settings.views[2].clip
    truth = read_calibration(SAMPLE / "calibration.json")
    X = np.random.default_rng(2345).uniform([-1, -1, 0], [1, 1, 2], (40, 3))
    for name, camera in cameras_from_scene(blender).items():
        np.testing.assert_allclose(camera.project(X), truth[name].project(X), atol=0.01)

    # and back out to calibration.json, never over an existing file unless asked
    out = tmp_path / "calibration.json"
    bpy.ops.zoopraxis.export_calibration(filepath=str(out))
    with pytest.raises(RuntimeError, match="exists"):
        bpy.ops.zoopraxis.export_calibration(filepath=str(out))
    bpy.ops.zoopraxis.export_calibration(filepath=str(out), overwrite=True)
    written = read_calibration(out)
    for name in truth:
        np.testing.assert_allclose(written[name].project(X), truth[name].project(X), atol=0.01)


def test_load_calibration_of_the_footage_at_another_scale(blender, tmp_path):
    """A calibration of the full-size footage for plates at half its size: the camera objects
    are the plates' cameras; one of another shape is refused, naming both sizes."""
    from zoopraxis.addon.calibration import cameras_from_scene
    from zoopraxis.core.files.calibfile import read_calibration, write_calibration

    settings = load_sample()
    truth = read_calibration(SAMPLE / "calibration.json")
    wrong = tmp_path / "wrong.json"
    write_calibration(wrong, [c.replace(image_size=(480, 400)) for c in truth.values()])
    with pytest.raises(RuntimeError, match="camera 'cam0' is 480x400 but its plate is 480x360"):
        bpy.ops.zoopraxis.load_calibration(filepath=str(wrong))
    assert all(v.camera is None for v in settings.views)
    double = tmp_path / "double.json"
    write_calibration(double, [c.scaled(2.0, "resize") for c in truth.values()])
    bpy.ops.zoopraxis.load_calibration(filepath=str(double))
    X = np.random.default_rng(7).uniform([-1, -1, 0], [1, 1, 2], (40, 3))
    for name, camera in cameras_from_scene(blender).items():
        assert tuple(camera.image_size) == (480, 360)
        np.testing.assert_allclose(camera.project(X), truth[name].project(X), atol=0.01)

def test_unreadable_plate_and_unequal_lengths_leave_scene_alone(blender, tmp_path):
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "000000.png").write_bytes(b"not an image")
    before = scene_state()
    with pytest.raises(RuntimeError, match=r"cannot read image .*000000.png \(frame 0 of "
                                           r"plate 'bad'\)"):
        bpy.ops.zoopraxis.load_plates(filepath=str(bad / "000000.png"))
    assert scene_state() == before

    short = tmp_path / "short"
    shutil.copytree(SAMPLE / "cam1", short)
    for f in sorted(short.iterdir())[40:]:
        f.unlink()
    load_sample(("cam0",))
    before = scene_state()
    with pytest.raises(RuntimeError, match="plate 'short' has 40 frames but 'cam0' has 48"):
        bpy.ops.zoopraxis.load_plates(filepath=str(short / "000000.jpg"))
    assert scene_state() == before


def test_joint_markers_keep_user_tracks_and_round_trip(blender, tmp_path):
    from zoopraxis.addon import markers
    from zoopraxis.core.files.markers import read_markers

    settings = load_sample(("cam0", "cam1"))
    clip = settings.views[0].clip
    user = clip.tracking.tracks.new(name="l_knee", frame=5)
    user.markers.find_frame(5).co = (0.25, 0.75)
    other = clip.tracking.tracks.new(name="my feature", frame=1)
    blender.scene.frame_set(3)
    with blender.temp_override():
        bpy.ops.zoopraxis.add_joint_markers(all_views=True)
    names = [t.name for t in clip.tracking.tracks]
    assert sorted(names) == sorted(["l_knee", "my feature"] + [
        j for j in markers.STANDARD_JOINTS if j != "l_knee"])
    assert tuple(user.markers.find_frame(5).co) == pytest.approx((0.25, 0.75))
    assert len(user.markers) == 1 and len(other.markers) == 1
    assert clip.tracking.tracks["pelvis"].markers.find_frame(3) is not None
    # The stick figure: head above neck above pelvis, subject's left on the image right.
    co = {t.name: t.markers[0].co[:] for t in clip.tracking.tracks}
    assert co["head"][1] > co["neck"][1] > co["pelvis"][1] > co["l_knee"][1] - 1
    assert co["l_shoulder"][0] > co["r_shoulder"][0]

    anchors = markers.read_anchors(settings)
    assert [a.frame for a in anchors] == [2, 4]      # take frames of scene frames 3 and 5
    assert set(anchors[0].views) == {"cam0", "cam1"}
    assert anchors[1].views == {"cam0": {"l_knee": pytest.approx((119.5, 89.5))}}
    assert markers.placement(settings, "pelvis", 3) == [("cam0", 'KEY'), ("cam1", 'KEY')]
    assert markers.placement(settings, "l_knee", 3)[0] == ("cam0", 'ELSEWHERE')

    path = tmp_path / "markers.json"
    bpy.ops.zoopraxis.export_markers(filepath=str(path))
    with pytest.raises(RuntimeError, match="file exists"):
        bpy.ops.zoopraxis.export_markers(filepath=str(path))
    written = read_markers(path)
    assert [a.frame for a in written] == [2, 4]

    bpy.ops.wm.read_factory_settings(use_empty=True)
    settings = load_sample(("cam0", "cam1"))
    bpy.ops.zoopraxis.import_markers(filepath=str(path))
    again = markers.read_anchors(settings)
    for a, b in zip(written, again):
        for view in a.views:
            for joint, uv in a.views[view].items():
                assert b.views[view][joint] == pytest.approx(uv, abs=0.01)


def test_sample_markers_import_matches_file(blender):
    from zoopraxis.addon import markers
    from zoopraxis.core.files.markers import read_markers

    settings = load_sample()
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    got = markers.read_anchors(settings)
    want = read_markers(SAMPLE / "markers.json")
    assert [a.frame for a in got] == [a.frame for a in want]
    for view, joints in want[0].views.items():
        for joint, uv in joints.items():
            assert got[0].views[view][joint] == pytest.approx(uv, abs=0.01)
    # Importing again keeps every marker that is already placed.
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert len(bpy.data.movieclips[0].tracking.tracks) == 17


def test_joint_marked_in_no_view_is_refused(blender, monkeypatch, tmp_path):
    from zoopraxis.addon import pipeline
    from zoopraxis.core.body.joints import STANDARD_JOINTS
    from zoopraxis.core.files.markers import Anchor, write_markers

    settings = load_sample(("cam0",))
    clicked = {j: (100.0 + i, 100.0) for i, j in enumerate(STANDARD_JOINTS) if j != "r_toe"}
    write_markers(tmp_path / "m.json", [Anchor(0, {"cam0": clicked})])
    bpy.ops.zoopraxis.import_markers(filepath=str(tmp_path / "m.json"))
    calls = []
    monkeypatch.setattr(pipeline, "track", lambda *a, **k: calls.append(1))
    before = scene_state()
    for operator in (bpy.ops.zoopraxis.track, bpy.ops.zoopraxis.initialize):
        with pytest.raises(RuntimeError, match="joint 'r_toe' is marked in no view"):
            operator()
    assert calls == [] and scene_state() == before and not settings.running


def fake_track_result(take, n=None):
    result, _ = synthetic_result(len(take.frames) if n is None else n, views=tuple(take.plates))
    result.frames = np.array(list(take.frames))[:result.num_frames]
    result.status[5] = "lost"
    return result


def test_track_operator_with_injected_worker(blender, monkeypatch, tmp_path):
    from zoopraxis.addon import bake, pipeline, status

    monkeypatch.setattr(status, "output_folder", lambda: tmp_path)
    settings = load_sample()
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    seen = {}

    def fake_track(take, *, init=None, progress=None, cancel=None, log=None):
        seen["take"] = take
        for i in range(len(take.frames)):
            progress(i + 1, len(take.frames))
        return fake_track_result(take)

    monkeypatch.setattr(pipeline, "track", fake_track)
    settings.use_frame_range = True
    settings.frame_range_start, settings.frame_range_end = 10, 30
    assert bpy.ops.zoopraxis.track() == {'FINISHED'}
    take = seen["take"]
    assert take.frames == range(10, 30) and set(take.plates) == {"cam0", "cam1", "cam2"}
    from zoopraxis.core.files.markers import read_markers

    assert take.cameras is None     # no calibration loaded: uncalibrated
    assert [a.frame for a in take.anchors] == [a.frame for a in read_markers(
        SAMPLE / "markers.json")]
    assert settings.result_path.endswith("result.json") and (tmp_path / "result.json").exists()
    arm = settings.armature
    assert arm is not None and arm.animation_data.action.name == "Zoopraxis result"
    assert "Tracked 20 frames: 19 ok, 0 uncertain, 1 lost" in settings.status
    markers = [m.frame for m in blender.scene.timeline_markers if m.name == bake.LOST_MARKER]
    assert markers == [1 + 15]
    bpy.ops.zoopraxis.jump_worst_frame()
    assert blender.scene.frame_current == 16
    # A second run writes a new result file and a new action.
    assert bpy.ops.zoopraxis.track() == {'FINISHED'}
    assert (tmp_path / "result.001.json").exists()
    assert settings.armature.animation_data.action.name == "Zoopraxis result.001"


def test_initialize_operator_with_injected_worker(blender, monkeypatch):
    from zoopraxis.addon import pipeline
    from zoopraxis.core.body.body import make_body
    from zoopraxis.core.files.initfile import InitResult

    settings = load_sample()
    bpy.ops.zoopraxis.load_calibration(filepath=str(SAMPLE / "calibration.json"))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))

    from zoopraxis.core.files.markers import read_markers

    full = make_body("full")
    init = InitResult(full, {a.frame: full.rest_pose(np.eye(4))
                             for a in read_markers(SAMPLE / "markers.json")}, {},
                      warnings=["a warning"], rms={"cam0": 1.5, "cam1": 2.5},
                      notes=["a note"], calibrated=True)
    got = {}

    def fake_initialize(take, progress=None, cancel=None):
        got["cameras"] = take.cameras
        return init

    monkeypatch.setattr(pipeline, "initialize", fake_initialize)
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    assert set(got["cameras"]) == {"cam0", "cam1", "cam2"}
    assert settings.initialized and "click error up to 2.5 px" in settings.status
    assert settings.init_notes.split("\n") == ["a warning", "note: a note"]
    assert settings.armature.name == "Zoopraxis init"
    take = pipeline.gather(blender)
    assert pipeline.initial_for(blender.scene, take) is init
    take.close()


def test_modal_job_progress_cancel_keeps_frames_done(blender):
    import threading

    from zoopraxis.addon.jobs import Job, JobOperator

    gate = threading.Event()
    done_frames = []

    def work(progress, cancel):
        for i in range(100):
            if cancel():
                break
            done_frames.append(i)
            progress(i + 1, 100)
            if i == 9:
                gate.set()
            threading.Event().wait(0.002)
        return list(done_frames)

    class Event:
        def __init__(self, type, value='NOTHING'):
            self.type, self.value = type, value

    class FakeOperator(JobOperator):
        label = "Track"

        def __init__(self):
            self.reports, self.finished = [], None

        def report(self, kind, message):
            self.reports.append((kind, message))

        def prepare(self, context):
            return work

        def finish(self, context, value, cancelled):
            self.finished = (value, cancelled)
            return f"kept {len(value)} frames"

    op = FakeOperator()
    settings = blender.scene.zoopraxis
    wm = blender.window_manager
    op._job = Job(work).start()
    op._timer = wm.event_timer_add(0.1, window=blender.window)
    settings.running = True
    assert gate.wait(5)
    assert op.modal(blender, Event('MOUSEMOVE')) == {'PASS_THROUGH'}
    op.modal(blender, Event('ESC', 'PRESS'))
    state = {'RUNNING_MODAL'}
    for _ in range(200):
        state = op.modal(blender, Event('TIMER'))
        if state != {'RUNNING_MODAL'}:
            break
        threading.Event().wait(0.01)
    assert state == {'FINISHED'}
    value, cancelled = op.finished
    assert cancelled and 10 <= len(value) < 100 and value == done_frames
    assert not settings.running and settings.status.startswith(f"kept {len(value)} frames")
    assert op.reports[-1][0] == {'WARNING'}


def test_modal_job_reports_worker_errors(blender):
    from zoopraxis.addon.jobs import Job, JobOperator

    class FakeOperator(JobOperator):
        label = "Track"
        reports = []

        def report(self, kind, message):
            self.reports.append((kind, message))

    def work(progress, cancel):
        raise ZoopraxisError("frame 7 of plate 'cam1' cannot be decoded")

    op = FakeOperator()
    job = Job(work).run_here()
    assert op._complete(blender, job) == {'CANCELLED'}
    assert op.reports == [({'ERROR'}, "frame 7 of plate 'cam1' cannot be decoded")]


def test_bake_operator_rig_errors_and_exports(blender, tmp_path):
    result, body = synthetic_result(6)
    path = write_result(tmp_path / "take.json", result)
    settings = blender.scene.zoopraxis
    rig = bpy.data.objects.new("rig", bpy.data.armatures.new("rig"))
    blender.scene.collection.objects.link(rig)
    settings.rig = rig
    settings.preset = 'MIXAMO'
    before = scene_state()
    with pytest.raises(RuntimeError, match="rig 'rig' has no bone 'mixamorig:Hips' "
                                           r"\(mapped from segment 'pelvis'\)"):
        bpy.ops.zoopraxis.bake(filepath=str(path))
    assert scene_state() == before and rig.animation_data is None
    settings.rig = None
    assert bpy.ops.zoopraxis.bake(filepath=str(path)) == {'FINISHED'}
    arm = settings.armature
    assert arm.animation_data.action.name == "Zoopraxis take"
    blender.view_layer.objects.active = arm
    bpy.ops.zoopraxis.export_bvh(filepath=str(tmp_path / "take.bvh"))
    bpy.ops.zoopraxis.export_fbx(filepath=str(tmp_path / "take.fbx"))
    assert (tmp_path / "take.bvh").stat().st_size > 0 and (tmp_path / "take.fbx").exists()
    with pytest.raises(RuntimeError, match="take.bvh: file exists"):
        bpy.ops.zoopraxis.export_bvh(filepath=str(tmp_path / "take.bvh"))


def test_bone_map_operators(blender, tmp_path):
    import json

    path = tmp_path / "map.json"
    path.write_text(json.dumps({"pelvis": "root", "l_thigh": "thigh_L"}))
    settings = blender.scene.zoopraxis
    bpy.ops.zoopraxis.bone_map_load(filepath=str(path))
    assert [(p.name, p.bone) for p in settings.bone_map] == [("pelvis", "root"),
                                                             ("l_thigh", "thigh_L")]
    bpy.ops.zoopraxis.bone_map_add()
    bpy.ops.zoopraxis.bone_map_remove()
    assert len(settings.bone_map) == 2
    path.write_text("[1, 2]")
    with pytest.raises(RuntimeError, match="a bone map maps segment names to bone names"):
        bpy.ops.zoopraxis.bone_map_load(filepath=str(path))


def test_undo_restores_scene(registered):
    bpy.ops.wm.read_factory_settings()     # the empty factory file has no undo stack
    before = scene_state()
    bpy.ops.ed.undo_push(message="before")
    load_sample(("cam0",))
    bpy.ops.zoopraxis.add_joint_markers()
    bpy.ops.ed.undo_push(message="after")
    assert scene_state() != before
    bpy.ops.ed.undo()
    assert scene_state() == before
    for cls in __import__("zoopraxis.addon.operators", fromlist=["classes"]).classes:
        if cls.__name__ not in ("ZOOPRAXIS_OT_export_markers", "ZOOPRAXIS_OT_export_calibration",
                                "ZOOPRAXIS_OT_jump_worst_frame", "ZOOPRAXIS_OT_export_bvh",
                                "ZOOPRAXIS_OT_export_fbx"):
            assert cls.bl_options >= {'REGISTER', 'UNDO'}, cls.__name__


def test_panels_draw_steps(blender):
    from zoopraxis.addon.panels import missing_for

    missing = missing_for(blender)
    assert missing["plates"] == "Load one plate per camera"
    load_sample(("cam0",))
    missing = missing_for(blender)
    assert missing["plates"] is None and missing["markers"].startswith("Place joint 'pelvis'")
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    missing = missing_for(blender)
    assert missing["markers"] is None and missing["track"] is None
    assert missing["calibration"].startswith("Optional")


def test_real_pipeline_on_sample_tracks_and_bakes(blender, monkeypatch, tmp_path):
    """The adapter against the real workers: calibrated sample, three frames."""
    pytest.importorskip("zoopraxis.core.take.track")
    import json

    from zoopraxis.addon import status
    from test_addon_bake import joint_positions

    monkeypatch.setattr(status, "output_folder", lambda: tmp_path)
    settings = load_sample()
    bpy.ops.zoopraxis.load_calibration(filepath=str(SAMPLE / "calibration.json"))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    settings.use_frame_range = True
    settings.frame_range_start, settings.frame_range_end = 0, 3
    assert bpy.ops.zoopraxis.track() == {'FINISHED'}
    truth = np.array(json.loads((SAMPLE / "truth.json").read_text())["joints3d"])[:3]
    X = joint_positions(settings.armature, blender.scene, [1, 2, 3])
    assert np.median(np.linalg.norm(X - truth, axis=-1)) < 0.05


class _Layout:
    """Enough of a UILayout to record what a draw function puts in it."""

    def __init__(self, log):
        self.log = log

    def label(self, text="", icon='NONE'):
        self.log.append(("label", text, icon))

    def column(self, align=False):
        return self

    def row(self, align=False):
        return self

    def operator(self, idname, text="", icon='NONE', depress=False):
        self.log.append(("operator", idname, text, icon, depress))
        return type("Props", (), {})()

    def prop(self, data, name, **options):
        self.log.append(("prop", name))


@pytest.mark.slow
def test_one_view_flips_in_depth_from_the_panel(blender, fits_once):
    """Initialize from one view: the panel offers each limb of the anchor frames to flip in
    depth; a flip is remembered for Initialize and Track, runs the fit again, and a second
    click undoes it."""
    from zoopraxis.addon import pipeline
    from zoopraxis.addon.panels import _draw_init_notes
    from zoopraxis.core.initialize.run import ONE_VIEW_LENGTHS_NOTE

    settings = load_sample(("cam0",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    assert settings.one_view_frames == "0,47" and settings.depth_flips == ""
    # The lengths are fitted to one view: the panel says how to do better, as a note.
    assert "note: " + ONE_VIEW_LENGTHS_NOTE in settings.init_notes.split("\n")
    log = []
    _draw_init_notes(_Layout(log), settings)
    labels = [entry for entry in log if entry[0] == "label"]
    assert ("label", ONE_VIEW_LENGTHS_NOTE[:20], 'INFO') in \
        [(kind, text[:20], icon) for kind, text, icon in labels]
    assert not any(text.startswith("note: ") for _, text, _ in labels)
    take = pipeline.gather(blender)
    before = pipeline.initial_for(blender.scene, take)
    take.close()
    assert before.flipped == {}
    assert bpy.ops.zoopraxis.flip_depth(frame=0, part="left leg") == {'FINISHED'}
    assert settings.depth_flips == "0:left leg"
    take = pipeline.gather(blender)
    assert take.init_options.flips == {0: ["left leg"]}
    after = pipeline.initial_for(blender.scene, take)
    take.close()
    assert after is not None and after is not before
    if after.flipped:
        assert after.flipped == {0: ["left leg"]}
        moved = np.linalg.norm(after.joints3d(0) - before.joints3d(0), axis=1).max()
        assert moved > 0.1
    else:
        assert any("left leg" in line for line in settings.init_notes.split("\n"))
    log = []
    _draw_init_notes(_Layout(log), settings)
    buttons = [entry for entry in log if entry[0] == "operator"]
    assert len(buttons) == 10                        # 5 parts for each of the 2 frames
    assert ("operator", "zoopraxis.flip_depth", "L Leg", 'ERROR' if "0:left leg" in
            settings.ambiguous_parts else 'NONE', True) in buttons
    assert bpy.ops.zoopraxis.flip_depth(frame=0, part="left leg") == {'FINISHED'}
    assert settings.depth_flips == ""
    take = pipeline.gather(blender)
    again = pipeline.initial_for(blender.scene, take)
    take.close()
    assert again.flipped == {}
    assert np.allclose(again.joints3d(0), before.joints3d(0), atol=1e-6)
    with pytest.raises(RuntimeError, match="unknown body part 'tail'"):
        bpy.ops.zoopraxis.flip_depth(frame=0, part="tail")
    assert settings.depth_flips == ""


@pytest.mark.slow
def test_one_view_camera_tilt_from_the_panel(blender, fits_once):
    """The panel's "Camera Looks Down" reaches the one-view fit: the sample's level cam0 is
    fitted about level by default (within 12 degrees); said to look down 30 degrees, the
    remembered fit is stale and the new one looks at least 3 degrees further down (about 5:
    the prior is a give-or-take-10 one, and this close view's clicks hold the fit near
    level)."""
    from zoopraxis.addon.panels import _draw_init_notes

    def lean():
        init = remembered_initialization(blender)
        if init is None:
            return None
        R = init.cameras["cam0"].R
        return float(np.degrees(np.arcsin(R[2, 2])))

    settings = load_sample(("cam0",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    level = lean()
    assert abs(level) < 12.0
    log = []
    _draw_init_notes(_Layout(log), settings)
    assert ("prop", "camera_tilt") in log
    settings.camera_tilt = 30.0
    assert lean() is None                   # made for another tilt: Track initializes again
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    assert lean() < level - 3.0


def test_flip_reports_the_initialization_error(blender):
    """A flip whose initialization cannot run (no markers) says why in one line; the toggle
    is kept for when it can."""
    settings = load_sample(("cam0",))
    with pytest.raises(RuntimeError, match="joint markers: no anchors"):
        bpy.ops.zoopraxis.flip_depth(frame=0, part="right arm")
    assert settings.depth_flips == "0:right arm"


@pytest.mark.slow
def test_pose_prior_file_from_the_panel(blender, tmp_path, fits_once):
    """The Initialize step's "Pose Prior" file reaches the one-view fit: with a prior learned
    from the take itself (its truth, as from an earlier track of the performer) the sample's
    cam2 alone gives a pose nearer the truth at the last anchor than the shipped prior (51 mm
    against 83, Procrustes-aligned); the remembered fit goes stale when the file is set; a
    missing file, or a prior of another body template, is refused in one line before any job
    starts."""
    import json

    from zoopraxis.core.geometry.triangulate import procrustes_mpjpe
    from zoopraxis.core.priors.pose import PosePrior, take_angles

    truth = json.loads((SAMPLE / "truth.json").read_text())
    X = np.array(truth["joints3d"][truth["frames"].index(47)])
    prior = tmp_path / "self.npz"
    angles, _ = take_angles(np.array(truth["joints3d"]))
    PosePrior.from_takes({"walk3": angles}).save(prior)

    def error_at_47():
        fitted = remembered_initialization(blender)
        if fitted is None:
            return None
        return 1000 * procrustes_mpjpe(fitted.body.joints(fitted.poses[47]), X)

    settings = load_sample(("cam2",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    shipped = error_at_47()
    settings.pose_prior_path = str(prior)
    assert error_at_47() is None            # made with another prior: Track initializes again
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    learned = error_at_47()
    assert learned < 0.8 * shipped
    settings.pose_prior_path = str(tmp_path / "gone.npz")
    with pytest.raises(RuntimeError, match=r"Pose Prior: .*gone\.npz: no such pose prior file"):
        bpy.ops.zoopraxis.initialize()
    settings.pose_prior_path = str(prior)       # the full body's prior, for another body
    settings.template = "SIDENBLADH"
    with pytest.raises(RuntimeError, match=r"self\.npz: the pose prior was learned on the "
                                           r"'full' body, not on 'sidenbladh'"):
        bpy.ops.zoopraxis.initialize()


@pytest.mark.slow
def test_body_lengths_file_from_the_panel(blender, tmp_path, fits_once):
    """The Initialize step's "Body Lengths From" file: a one-view initialization keeps the
    lengths of a three-view init.json of the performer instead of fitting its own; the
    remembered fit goes stale when the file is set; a missing file is refused in one line."""
    import json

    from zoopraxis import cli
    from zoopraxis.core.body.body import LENGTH_DIMS

    three = tmp_path / "three.json"
    assert cli.main(["init", "--markers", str(SAMPLE / "markers.json"), "--calibration",
                     str(SAMPLE / "calibration.json"), "--out", str(three)]
                    + [f"--plate=cam{i}={SAMPLE / f'cam{i}'}" for i in range(3)]) == 0
    measured = json.loads(three.read_text())["dims"]
    settings = load_sample(("cam2",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    own = remembered_initialization(blender).body.dims
    assert any(abs(own[n] - measured[n]) > 1e-3 for n in LENGTH_DIMS)
    settings.dims_path = str(three)
    assert remembered_initialization(blender) is None
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    kept = remembered_initialization(blender).body.dims
    assert all(abs(kept[n] - measured[n]) < 1e-5 for n in LENGTH_DIMS)
    settings.dims_path = str(tmp_path / "gone.json")
    with pytest.raises(RuntimeError, match=r"Body Lengths From: .*gone\.json: no such file"):
        bpy.ops.zoopraxis.initialize()


def test_proportions_prior_file_from_the_panel(blender, tmp_path):
    """The Initialize step's "Proportions Prior" file: three calibrated views fit lengths about
    the proportions of that file's performers instead of the shipped prior's (performers with
    shanks 60 % longer: a longer shank, by about 2 mm, as the sample's clicks of two frames in
    three views measure the bones); the remembered fit goes stale when the file is set; a file
    that is not a prior is refused in one line naming the field."""
    from zoopraxis.core.body.body import DEFAULT_DIMS, LENGTH_DIMS
    from zoopraxis.core.priors.proportions import ProportionsPrior

    long_shanks = tmp_path / "long_shanks.npz"
    lengths = np.array([[DEFAULT_DIMS[n] * s * (1.6 if n == "shank" else 1.0)
                         for n in LENGTH_DIMS] for s in (0.95, 1.0, 1.05)])
    ProportionsPrior(["a", "b", "c"], lengths).save(long_shanks)
    settings = load_sample()
    bpy.ops.zoopraxis.load_calibration(filepath=str(SAMPLE / "calibration.json"))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    assert remembered_initialization(blender).calibrated
    shipped = remembered_initialization(blender).body.dims
    settings.proportions_prior_path = str(long_shanks)
    assert remembered_initialization(blender) is None
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    own = remembered_initialization(blender).body.dims
    assert own["shank"] > shipped["shank"] + 0.001
    assert own["shank"] / own["thigh"] > shipped["shank"] / shipped["thigh"]
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a prior")
    settings.proportions_prior_path = str(bad)
    with pytest.raises(RuntimeError, match=r"Proportions Prior: .*bad\.npz: not a proportions "
                                           r"prior file"):
        bpy.ops.zoopraxis.initialize()


class _PanelLayout(_Layout):
    """A UILayout for a whole panel: what ``_Layout`` does not record is accepted."""

    def __getattr__(self, name):
        return lambda *args, **options: self


def test_pose_basis_toggle_is_on_by_default(blender):
    """The Initialize step's "Pose Basis", offered while no view is calibrated, is on by
    default (the shipped basis, as ``track`` gives it) and, turned off, gives Initialize and
    Track none."""
    import types

    from zoopraxis.addon import pipeline
    from zoopraxis.addon.panels import VIEW3D_PT_zoopraxis

    settings = load_sample(("cam0",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    log = []
    VIEW3D_PT_zoopraxis.draw(types.SimpleNamespace(layout=_PanelLayout(log)), blender)
    assert ("prop", "use_pose_basis") in log and settings.use_pose_basis
    for on, expected in ((False, None), (True, "default")):
        settings.use_pose_basis = on
        take = pipeline.gather(blender)
        take.close()
        assert take.init_options.pose_basis == expected


@pytest.mark.slow
def test_near_cameras_from_the_panel(blender, monkeypatch, fits_once):
    """The Initialize step's "Near Cameras", offered while no view is calibrated, reaches the
    one-view fit and the tracker's own initialization: the sample's cam0, 4.1 m from the
    walker, gets a camera distance of that order (reported by Initialize) instead of none;
    the remembered fit goes stale when it is set."""
    import types

    from zoopraxis.addon import pipeline
    from zoopraxis.addon.panels import VIEW3D_PT_zoopraxis
    from zoopraxis.core.initialize import run as core_init

    def drawn():
        log = []
        VIEW3D_PT_zoopraxis.draw(types.SimpleNamespace(layout=_PanelLayout(log)), blender)
        return ("prop", "near_cameras") in log

    settings = load_sample(("cam0",))
    bpy.ops.zoopraxis.import_markers(filepath=str(SAMPLE / "markers.json"))
    assert drawn()
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    assert remembered_initialization(blender).cameras["cam0"].kappa == 0.0
    settings.near_cameras = True
    assert remembered_initialization(blender) is None
    assert bpy.ops.zoopraxis.initialize() == {'FINISHED'}
    kappa = remembered_initialization(blender).cameras["cam0"].kappa
    assert 2.0 < 1.0 / kappa < 8.0
    assert f"camera distance (m): cam0 {1.0 / kappa:.1f}" in settings.status
    # Track without a remembered fit initializes with the view's perspective too
    asked = []
    real = core_init.initialize

    def spy(*args, **options):
        asked.append(options.get("perspective"))
        return real(*args, **options)

    monkeypatch.setattr(core_init, "initialize", spy)
    settings.use_frame_range = True
    settings.frame_range_start, settings.frame_range_end = 0, 2
    take = pipeline.gather(blender)
    try:
        result = pipeline.track(take)
    finally:
        take.close()
    assert asked == [True] and list(result.frames) == [0, 1]
    bpy.ops.zoopraxis.load_calibration(filepath=str(SAMPLE / "calibration.json"))
    assert not drawn()
