"""The add-on under bad input: every operator reports one line, prints the traceback, and leaves
the scene as it was; exports replace a file only when the new one is complete."""

import json

import pytest

from test_addon_support import (SAMPLE, blender, bpy, registered,  # noqa: F401
                                synthetic_result, write_result)

from zoopraxis.core.errors import ZoopraxisError


def scene_state():
    scene = bpy.context.scene
    return (sorted(o.name for o in bpy.data.objects), sorted(a.name for a in bpy.data.actions),
            sorted(a.name for a in bpy.data.armatures), sorted(m.name for m in bpy.data.meshes),
            [(m.name, m.frame) for m in scene.timeline_markers])


class FakeOperator:
    def __init__(self):
        self.reports = []

    def report(self, kind, message):
        self.reports.append((kind, message))


def test_run_reports_any_error_in_one_line_and_undoes_the_work(blender, capsys):
    from zoopraxis.addon.operators import run

    before = scene_state()

    def half_made():
        arm = bpy.data.objects.new("half", bpy.data.armatures.new("half"))
        blender.scene.collection.objects.link(arm)
        bpy.data.actions.new("half action")
        blender.scene.timeline_markers.new("lost", frame=3)
        raise KeyError("cam1")

    op = FakeOperator()
    assert run(op, blender, half_made) == {'CANCELLED'}
    assert op.reports == [({'ERROR'}, "internal error, see the console: KeyError: 'cam1'")]
    assert "Traceback" in capsys.readouterr().out
    assert scene_state() == before


def test_job_operator_reports_a_worker_bug_in_one_line(blender):
    from zoopraxis.addon.jobs import Job, JobOperator

    class Op(FakeOperator, JobOperator):
        label = "Track"

    def work(progress, cancel):
        raise KeyError("cam1")

    op = Op()
    assert op._complete(blender, Job(work).run_here()) == {'CANCELLED'}
    assert op.reports == [({'ERROR'}, "internal error, see the console: KeyError: 'cam1'")]
    assert blender.scene.zoopraxis.status.startswith("Track: failed: internal error")


def test_bake_from_nan_angles_leaves_no_armature(blender, tmp_path):
    result, _ = synthetic_result(4)
    path = write_result(tmp_path / "take.json", result)
    data = json.loads(path.read_text())
    data["angles"][2][5] = float("nan")
    path.write_text(json.dumps(data))
    before = scene_state()
    with pytest.raises(RuntimeError, match="take.json: 'angles' holds NaN or infinity"):
        bpy.ops.zoopraxis.bake(filepath=str(path))
    assert scene_state() == before


def test_bake_failing_halfway_leaves_no_armature(blender, tmp_path, monkeypatch):
    from zoopraxis.addon import bake as bake_mod

    def broken(*args, **kwargs):
        raise ZoopraxisError("body mesh: cannot be built")

    monkeypatch.setattr(bake_mod, "build_body_mesh", broken)
    result, _ = synthetic_result(4)
    path = write_result(tmp_path / "take.json", result)
    before = scene_state()
    with pytest.raises(RuntimeError, match="body mesh: cannot be built"):
        bpy.ops.zoopraxis.bake(filepath=str(path))
    assert scene_state() == before


def test_export_into_a_folder_that_cannot_be_made(blender, tmp_path):
    result, _ = synthetic_result(4)
    assert bpy.ops.zoopraxis.bake(filepath=str(write_result(tmp_path / "take.json",
                                                            result))) == {'FINISHED'}
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for op, name in ((bpy.ops.zoopraxis.export_bvh, "x.bvh"),
                     (bpy.ops.zoopraxis.export_fbx, "x.fbx")):
        with pytest.raises(RuntimeError, match="afile is a file, not a folder"):
            op(filepath=str(blocker / name))


def test_failed_exporter_leaves_the_old_file(tmp_path):
    from zoopraxis.addon.export import _exporting

    old = tmp_path / "take.bvh"
    old.write_bytes(b"HIERARCHY old")
    printed = ("Error: Python: Traceback (most recent call last):\n  File \"export_bvh.py\"\n"
               "OSError: [Errno 28] No space left on device\nLocation: ops.py:109")
    with pytest.raises(ZoopraxisError, match=r"take.bvh: Blender's BVH exporter failed "
                                             r"\(OSError: \[Errno 28\] No space left on "
                                             r"device\); the old file is unchanged"):
        with _exporting(old, "Blender's BVH exporter") as temporary:
            temporary.write_text("HIERARCHY half")
            raise RuntimeError(printed)
    assert old.read_bytes() == b"HIERARCHY old"
    assert [p.name for p in tmp_path.iterdir()] == ["take.bvh"]


def test_bake_command_checks_every_output_before_writing_any(tmp_path):
    from zoopraxis.addon.bake import bake_file

    result, _ = synthetic_result(4)
    path = write_result(tmp_path / "take.json", result)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for kwargs, message in (({"fbx": blocker / "x.fbx"}, "afile is a file, not a folder"),
                            ({"blend": tmp_path / "x.txt"}, "expected a .blend file name"),
                            ({"fbx": tmp_path / "t.bvh"}, "expected a .fbx file name")):
        with pytest.raises(ZoopraxisError, match=message):
            bake_file(path, bvh=tmp_path / "t.bvh", report=lambda *_: None, **kwargs)
        assert not (tmp_path / "t.bvh").exists()
    odd = write_result(tmp_path / "result.bvh", result)    # a result under a BVH's name
    before = odd.read_bytes()
    with pytest.raises(ZoopraxisError, match="--bvh .*result.bvh: is the same file as --result"):
        bake_file(odd, bvh=odd, force=True, report=lambda *_: None)
    assert odd.read_bytes() == before


def test_track_with_a_removed_clip_is_one_line(blender):
    for view in ("cam0", "cam1"):
        bpy.ops.zoopraxis.load_plates(filepath=str(SAMPLE / view / "000000.jpg"))
    settings = blender.scene.zoopraxis
    bpy.data.movieclips.remove(settings.views[1].clip)
    with pytest.raises(RuntimeError, match="view 'cam1': its movie clip was removed"):
        bpy.ops.zoopraxis.track()


def test_load_plates_refuses_videos_of_different_frame_rates(blender, tmp_path):
    import cv2
    import numpy as np

    from zoopraxis.addon.plates import load_plates

    videos = {}
    for view, fps in (("cam0", 30), ("cam1", 25)):
        videos[view] = tmp_path / f"{view}.avi"
        writer = cv2.VideoWriter(str(videos[view]), cv2.VideoWriter_fourcc(*"MJPG"), fps,
                                 (64, 48))
        for _ in range(3):
            writer.write(np.zeros((48, 64, 3), np.uint8))
        writer.release()
    before = len(bpy.data.movieclips)
    with pytest.raises(ZoopraxisError, match="'cam0' \\(30 fps\\) and 'cam1' \\(25 fps\\)"):
        load_plates(blender, videos, report=lambda *_: None)
    assert len(bpy.data.movieclips) == before and not len(blender.scene.zoopraxis.views)
