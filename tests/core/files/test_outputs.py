"""Outputs never cost the user a file: checked before the work, written under a unique
temporary name, renamed over the old file only when complete; inputs never overwritten."""

import errno
import json
import os
import shutil
import tempfile
from pathlib import Path

import pytest

from zoopraxis import cli
from zoopraxis.core.files import outputs, result
from zoopraxis.core.errors import ZoopraxisError

SAMPLE = Path(cli.__file__).parent / "samples" / "walk3"
PLATES = [a for v in ("cam0", "cam1", "cam2") for a in ("--plate", f"{v}={SAMPLE / v}")]


def test_check_output_refuses_before_any_work(tmp_path):
    inp = tmp_path / "markers.json"
    inp.write_text("{}")
    with pytest.raises(ZoopraxisError, match="is a folder"):
        outputs.check_output(tmp_path, True)
    with pytest.raises(ZoopraxisError, match="is the same file as --markers"):
        outputs.check_output(inp, True, inputs=[("--markers", inp)])
    link = tmp_path / "link.json"
    link.symlink_to(inp)
    with pytest.raises(ZoopraxisError, match="is the same file as --markers"):
        outputs.check_output(tmp_path / "." / "link.json", True, inputs=[("--markers", inp)])
    with pytest.raises(ZoopraxisError, match="markers.json is a file, not a folder"):
        outputs.check_output(inp / "r.json", True)
    with pytest.raises(ZoopraxisError, match="file exists"):
        outputs.check_output(inp, False)
    with pytest.raises(ZoopraxisError, match="expected a .bvh file name"):
        outputs.check_output(tmp_path / "x.txt", False, suffixes=(".bvh",))
    assert outputs.check_output(tmp_path / "new" / "r.json", False) == tmp_path / "new" / "r.json"
    assert not list(tmp_path.glob(".zoopraxis-probe*"))


def test_check_output_probes_the_folder(tmp_path, monkeypatch):
    # os.access says yes to root on a read-only mount: the check makes a file to be sure.
    def read_only(*args, **kwargs):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(tempfile, "mkstemp", read_only)
    with pytest.raises(ZoopraxisError, match="cannot write into .*Read-only file system"):
        outputs.check_output(tmp_path / "r.json", True)


def test_failed_write_leaves_the_old_file_byte_for_byte(tmp_path):
    path = tmp_path / "init.json"
    path.write_bytes(b'{"old": true}\n')
    os.chmod(path, 0o640)
    with pytest.raises(ZoopraxisError, match="No space left on device.*old file is unchanged"):
        with outputs.replacing(path) as temporary:
            temporary.write_text('{"new": ')
            raise OSError(errno.ENOSPC, "No space left on device")
    assert path.read_bytes() == b'{"old": true}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ["init.json"]
    with pytest.raises(KeyboardInterrupt):
        with outputs.replacing(path) as temporary:
            temporary.write_text("half")
            raise KeyboardInterrupt
    assert path.read_bytes() == b'{"old": true}\n' and len(list(tmp_path.iterdir())) == 1
    outputs.write_text(path, "new")
    assert path.read_text() == "new" and path.stat().st_mode & 0o777 == 0o640


def test_two_writers_of_one_file_never_share_a_temporary_name(tmp_path):
    path = tmp_path / "r.json"
    with outputs.replacing(path) as first, outputs.replacing(path) as second:
        assert first != second and first.parent == second.parent == tmp_path
        first.write_text("first")
        second.write_text("second")
    assert path.read_text() == "first"          # the outer one finished last
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]


def test_nothing_written_is_an_error(tmp_path):
    path = tmp_path / "t.bvh"
    path.write_text("old")
    with pytest.raises(ZoopraxisError, match="nothing was written; the old file is unchanged"):
        with outputs.replacing(path, suffix=".bvh") as temporary:
            assert temporary.name.endswith(".part.bvh")
    assert path.read_text() == "old"


@pytest.mark.parametrize("command, option", [("track", "--markers"), ("init", "--markers"),
                                             ("init", "--calibration")])
def test_inputs_are_never_outputs(tmp_path, capsys, command, option):
    files = {}
    for name in ("markers.json", "calibration.json"):
        files[name] = tmp_path / name
        shutil.copy(SAMPLE / name, files[name])
    target = files["markers.json" if option == "--markers" else "calibration.json"]
    before = target.read_bytes()
    args = [command] + PLATES + ["--markers", str(files["markers.json"]), "--calibration",
                                 str(files["calibration.json"]), "--out", str(target), "--force"]
    assert cli.main(args) == 2
    assert f"is the same file as {option}" in capsys.readouterr().err
    assert target.read_bytes() == before


def test_prior_output_must_be_npz_and_not_a_take(tmp_path, capsys):
    take = tmp_path / "take.json"
    take.write_text("{}")
    assert cli.main(["prior", str(take), "--out", str(take), "--force"]) == 2
    assert "expected a .npz file name" in capsys.readouterr().err
    assert take.read_text() == "{}"


def test_track_output_folder_checked_before_tracking(tmp_path, capsys, monkeypatch):
    import zoopraxis.core.take.track as track

    def never(*args, **kwargs):
        raise AssertionError("tracked although the output cannot be written")

    monkeypatch.setattr(track, "track", never)
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    for out, message in ((tmp_path, "is a folder"),
                         (blocker / "r.json", "is a file, not a folder")):
        assert cli.main(["track"] + PLATES + ["--markers", str(SAMPLE / "markers.json"),
                                              "--out", str(out), "--force"]) == 2
        assert message in capsys.readouterr().err


def test_track_keeps_the_frames_when_writing_fails_after_the_work(tmp_path, capsys,
                                                                  monkeypatch):
    old = tmp_path / "r.json"
    old.write_text("old result")
    real = result.write_result

    def full_disk(path, res, *, force=False):
        if Path(path) == old:
            raise ZoopraxisError(f"{path}: cannot write (No space left on device); the old "
                                 "file is unchanged")
        return real(path, res, force=force)

    monkeypatch.setattr(result, "write_result", full_disk)
    code = cli.main(["track"] + PLATES + ["--markers", str(SAMPLE / "markers.json"),
                                          "--calibration", str(SAMPLE / "calibration.json"),
                                          "--frames", "0:2", "--workers", "1",
                                          "--out", str(old), "--force"])
    err = capsys.readouterr().err
    assert code == 2 and old.read_text() == "old result"
    rescue = Path(err.split("the 2 frames tracked are saved in ")[1].split()[0])
    try:
        assert json.loads(rescue.read_text())["frames"] == [0, 1]
    finally:
        rescue.unlink()
