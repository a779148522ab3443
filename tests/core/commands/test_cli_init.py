"""The init and prior commands, and the initialization options of the track command."""

import json

import numpy as np
import pytest

from zoopraxis import cli
from zoopraxis.core.body import body as bm
from zoopraxis.core.files.initfile import init_from_json
from zoopraxis.core.geometry.triangulate import procrustes_mpjpe
from zoopraxis.core.initialize.flips import FLIP_PARTS
from zoopraxis.core.initialize.run import ONE_VIEW_LENGTHS_NOTE
from zoopraxis.core.priors.pose import PosePrior
from zoopraxis.core.body.joints import JOINT_INDEX

from tests.core.initialize.test_initialize import _lean


def test_init_command_writes_init_json(tmp_path, capsys):
    root = cli.__file__.replace("cli.py", "samples/walk3/")
    out = tmp_path / "init.json"
    args = ["init", "--markers", root + "markers.json", "--calibration",
            root + "calibration.json", "--out", str(out)]
    args += [f"--plate=cam{i}={root}cam{i}" for i in range(3)]
    assert cli.main(args) == 0
    printed = capsys.readouterr().out
    assert "body dimensions (m): hip_width" in printed and "rms per view (px): cam0" in printed
    data = json.loads(out.read_text())
    assert data["format"] == "zoopraxis-init/1" and [a["frame"] for a in data["anchors"]] == \
        [0, 47]
    assert cli.main(args) == 2                                # no overwrite without --force
    assert "file exists" in capsys.readouterr().err


@pytest.mark.slow
def test_init_command_keeps_the_dims_of_an_earlier_init(tmp_path, capsys, fits_once):
    """--dims-from: a one-view init keeps the lengths a three-view init of the performer
    fitted; a file without them, or of another template, is refused naming it."""
    root = cli.__file__.replace("cli.py", "samples/walk3/")
    three = tmp_path / "three.json"
    args = ["init", "--markers", root + "markers.json", "--calibration",
            root + "calibration.json", "--out", str(three)]
    assert cli.main(args + [f"--plate=cam{i}={root}cam{i}" for i in range(3)]) == 0
    measured = json.loads(three.read_text())["dims"]
    root, markers, _ = _sample_first_anchor_in_cam0(tmp_path)
    one = ["init", "--markers", str(markers), f"--plate=cam0={root}cam0"]
    out = tmp_path / "one.json"
    assert cli.main(one + ["--out", str(out), "--dims-from", str(three)]) == 0
    assert f"(kept from {three})" in capsys.readouterr().out
    kept = json.loads(out.read_text())["dims"]
    assert all(kept[n] == pytest.approx(measured[n], abs=1e-5) for n in bm.LENGTH_DIMS)
    fitted = tmp_path / "fitted.json"
    assert cli.main(one + ["--out", str(fitted)]) == 0
    # Fitted to one view's clicks, the lengths come with a note naming the remedy.
    assert f"note: {ONE_VIEW_LENGTHS_NOTE}" in capsys.readouterr().out
    assert json.loads(fitted.read_text())["notes"] == [ONE_VIEW_LENGTHS_NOTE]
    assert json.loads(out.read_text())["notes"] == json.loads(three.read_text())["notes"] == []
    assert any(abs(json.loads(fitted.read_text())["dims"][n] - measured[n]) > 1e-3
               for n in bm.LENGTH_DIMS)
    capsys.readouterr()
    bad = tmp_path / "markers_copy.json"
    bad.write_text(markers.read_text())
    other = tmp_path / "other.json"
    data = json.loads(three.read_text())
    data["template"] = "sidenbladh"
    other.write_text(json.dumps(data))
    for path, message in ((tmp_path / "gone.json", "gone.json: no such file"),
                          (bad, "markers_copy.json: not an init.json or result.json"),
                          (other, "other.json: dimensions of the 'sidenbladh' body, not of "
                                  "'full'")):
        assert cli.main(one + ["--out", str(tmp_path / "x.json"), "--dims-from",
                               str(path)]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "x.json").exists()


def _sample_first_anchor_in_cam0(tmp_path):
    """The sample's plates folder, a markers.json with its first anchor in cam0 alone, and
    that anchor's frame."""
    root = cli.__file__.replace("cli.py", "samples/walk3/")
    marks = json.loads(open(root + "markers.json").read())
    marks["anchors"] = [{"frame": a["frame"], "views": {"cam0": a["views"]["cam0"]}}
                        for a in marks["anchors"][:1]]
    markers = tmp_path / "markers.json"
    markers.write_text(json.dumps(marks))
    return root, markers, marks["anchors"][0]["frame"]


@pytest.mark.slow
def test_init_command_one_view_with_and_without_the_pose_prior(tmp_path, capsys, fits_once):
    """The sample's first anchor in cam0 alone: the shipped pose prior's pose is 35 mm off the
    truth (Procrustes-aligned), the one without it (``--no-pose-prior``) 40 mm."""
    root, markers, frame = _sample_first_anchor_in_cam0(tmp_path)
    truth = json.loads(open(root + "truth.json").read())
    X = np.array(truth["joints3d"][truth["frames"].index(frame)])
    errors = {}
    for flag in ([], ["--no-pose-prior"]):
        out = tmp_path / f"init{len(flag)}.json"
        args = ["init", "--markers", str(markers), f"--plate=cam0={root}cam0",
                "--out", str(out), *flag]
        assert cli.main(args) == 0, capsys.readouterr().err
        data = json.loads(out.read_text())
        assert data["mode"] == "uncalibrated"
        joints = np.array(data["anchors"][0]["joints3d"])
        assert joints.shape == (17, 3)
        errors[len(flag)] = 1000 * procrustes_mpjpe(joints, X)
    assert errors[0] < 38 and errors[1] > errors[0] + 3


def _sample_anchor_in_one_view(tmp_path, frame, view):
    """The sample's folder, a markers.json with its anchor at ``frame`` in ``view`` alone, and
    the true joints there."""
    root = cli.__file__.replace("cli.py", "samples/walk3/")
    marks = json.loads(open(root + "markers.json").read())
    marks["anchors"] = [{"frame": a["frame"], "views": {view: a["views"][view]}}
                        for a in marks["anchors"] if a["frame"] == frame]
    markers = tmp_path / "markers.json"
    markers.write_text(json.dumps(marks))
    truth = json.loads(open(root + "truth.json").read())
    return root, markers, np.array(truth["joints3d"][truth["frames"].index(frame)])


def test_prior_command_learns_from_captures_tracks_and_truth(tmp_path, capsys, shared_data):
    """``zoopraxis prior`` reads BVH captures, result.json (lost frames left out) and synth's
    truth.json, and writes a prior file ``--pose-prior`` takes; bad input is one line."""
    root = cli.__file__.replace("cli.py", "samples/walk3/")
    truth = json.loads(open(root + "truth.json").read())
    status = ["ok"] * len(truth["frames"])
    status[:5] = ["lost"] * 5
    result = {"format": "zoopraxis-track/1", "mode": "calibrated", "fps": 30.0,
              "joints": truth["joints"], "frames": truth["frames"],
              "joints3d": truth["joints3d"], "views": {}, "status": status}
    tracked = tmp_path / "shot" / "result.json"
    tracked.parent.mkdir()
    tracked.write_text(json.dumps(result))
    bvh_path = shared_data / "cmu_mocap" / "131_02.bvh"
    out = tmp_path / "prior.npz"
    args = ["prior", str(bvh_path), root + "truth.json", str(tracked), "--step", "8",
            "--out", str(out)]
    assert cli.main(args) == 0, capsys.readouterr().err
    assert f"of 3 takes -> {out}" in capsys.readouterr().out
    prior = PosePrior.load(out)
    counts = {t: list(prior.takes).count(t) for t in set(prior.takes)}
    n = len(truth["frames"])
    assert counts["walk3/truth"] == 2 * len(range(0, n, 8))
    assert counts["shot/result"] == 2 * len(range(0, n, 8)) - 2     # frame 0 was lost
    assert counts["131_02"] > 60
    assert cli.main(args) == 2 and "file exists" in capsys.readouterr().err
    for bad, message in ((tmp_path / "nope.bvh", "nope.bvh: no such file"),
                         (root + "calibration.json", "calibration.json: missing required key"),
                         (cli.__file__, "cli.py: not a take")):
        assert cli.main(["prior", str(bad), "--out", str(tmp_path / "x.npz")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert cli.main(["prior", str(bvh_path), "--step", "0", "--out", str(tmp_path / "x.npz")]) \
        == 2 and "--step 0" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow
def test_init_and_track_commands_take_a_pose_prior_file(tmp_path, capsys):
    """``--pose-prior FILE`` decides the depth of a frame clicked in one view: the sample's
    last anchor in cam2 alone is 88 mm off the truth (Procrustes-aligned) with the shipped
    prior and 52 mm with one learned from the take itself (its truth.json, as an earlier
    track of the same performer would be). A missing or mismatched file is named in one
    line."""
    root, markers, X = _sample_anchor_in_one_view(tmp_path, 47, "cam2")
    prior = tmp_path / "self.npz"
    assert cli.main(["prior", root + "truth.json", "--step", "1", "--out", str(prior)]) == 0
    errors = {}
    for flag in ([], ["--pose-prior", str(prior)]):
        out = tmp_path / f"init{len(flag)}.json"
        assert cli.main(["init", "--markers", str(markers), f"--plate=cam2={root}cam2",
                         "--out", str(out), *flag]) == 0, capsys.readouterr().err
        joints = np.array(json.loads(out.read_text())["anchors"][0]["joints3d"])
        errors[len(flag)] = 1000 * procrustes_mpjpe(joints, X)
    assert errors[0] > 75.0 and errors[2] < 0.75 * errors[0]
    other = tmp_path / "other.npz"
    names = bm.make_body("sidenbladh").dof_names
    PosePrior(np.zeros((4, len(names))), names, "sidenbladh").save(other)
    capsys.readouterr()
    base = ["--markers", str(markers), f"--plate=cam2={root}cam2", "--out",
            str(tmp_path / "bad.json")]
    for command in ("init", "track"):
        for flag, message in ((["--pose-prior", str(tmp_path / "no.npz")],
                               "no.npz: no such pose prior file"),
                              (["--pose-prior", str(other)],
                               "other.npz: the pose prior was learned on the 'sidenbladh' "
                               "body, not on 'full'"),
                              (["--pose-prior", str(prior), "--no-pose-prior"],
                               "give --pose-prior or --no-pose-prior, not both")):
            assert cli.main([command] + base + flag) == 2
            err = capsys.readouterr().err
            assert message in err and err.count("\n") == 1
    assert not (tmp_path / "bad.json").exists()


@pytest.mark.slow
def test_init_and_track_commands_take_the_camera_tilt(tmp_path, capsys, fits_once):
    """``--camera-tilt DOWN[:SPREAD]`` reaches the one-view fit (the sample's cam0 looks at the
    walker about level; told 30 degrees down, give or take 3, the fitted camera looks down
    20-35); bad values and calibrated views are refused in one line."""
    root, markers, _ = _sample_first_anchor_in_cam0(tmp_path)
    leans = []
    for tilt in ([], ["--camera-tilt", "30:3"]):
        out = tmp_path / f"init{len(tilt)}.json"
        args = ["init", "--markers", str(markers), f"--plate=cam0={root}cam0",
                "--out", str(out), *tilt]
        assert cli.main(args) == 0, capsys.readouterr().err
        R = np.array(json.loads(out.read_text())["anchors"][0]["views"]["cam0"]["camera"]["R"])
        leans.append(_lean(R))
    assert abs(leans[0]) < 12.0 and -35.0 < leans[1] < -20.0
    capsys.readouterr()
    base = ["init", "--markers", str(markers), f"--plate=cam0={root}cam0",
            "--out", str(tmp_path / "bad.json")]
    for value, message in (("steep", "expected DOWN or DOWN:SPREAD"),
                           ("95", "between -90 and 90"), ("10:0", "between -90 and 90")):
        assert cli.main(base + ["--camera-tilt", value]) == 2
        err = capsys.readouterr().err
        assert f"--camera-tilt {value}: " in err and message in err and err.count("\n") == 1
    calibrated = ["track", "--markers", root + "markers.json", "--calibration",
                  root + "calibration.json", "--out", str(tmp_path / "r.json"),
                  "--camera-tilt", "10"] + [f"--plate=cam{i}={root}cam{i}" for i in range(3)]
    for command in (calibrated, ["init"] + calibrated[1:]):
        assert cli.main(command) == 2
        assert "--camera-tilt is for uncalibrated views" in capsys.readouterr().err


@pytest.mark.slow
def test_init_command_flips_a_limb_and_says_how(tmp_path, capsys, fits_once):
    root, markers, frame = _sample_first_anchor_in_cam0(tmp_path)
    base = ["init", "--markers", str(markers), f"--plate=cam0={root}cam0"]
    assert cli.main(base + ["--out", str(tmp_path / "a.json")]) == 0
    plain = json.loads((tmp_path / "a.json").read_text())
    assert plain["flipped"] == {}
    for frame_s, parts in plain["ambiguous_parts"].items():
        assert all(p in FLIP_PARTS for p in parts)
        assert f"--flip {frame_s}:" in capsys.readouterr().out
    assert cli.main(base + ["--out", str(tmp_path / "b.json"), "--flip",
                            f"{frame}:left-leg", "--flip", f"{frame}:right-arm"]) == 0
    printed = capsys.readouterr().out
    data = json.loads((tmp_path / "b.json").read_text())
    made = data["flipped"].get(str(frame), [])
    assert f"frame {frame}: flipped in depth: {', '.join(made)}" in printed if made else True
    for part in ("left leg", "right arm"):
        assert part in made or any(part in w for w in data["warnings"])
    moved = np.linalg.norm(np.array(data["anchors"][0]["joints3d"])
                           - np.array(plain["anchors"][0]["joints3d"]), axis=1)
    assert (moved.max() > 0.1) == bool(made)
    assert init_from_json(data).flipped == {frame: made} if made else True
    assert cli.main(base + ["--out", str(tmp_path / "c.json"), "--flip", "tail"]) == 2
    err = capsys.readouterr().err
    assert "--flip 'tail': expected FRAME:PART" in err and len(err.strip().splitlines()) == 1


@pytest.mark.slow
def test_init_command_fits_a_near_views_perspective(tmp_path, capsys):
    """``init --perspective``: the sample's cam0, 4.1 m from the walker, gets a camera
    distance near that, printed and kept in init.json, which reads back to the same camera;
    calibrated views are refused in one line."""
    from zoopraxis.core.files.calibfile import read_calibration

    root, markers, frame = _sample_first_anchor_in_cam0(tmp_path)
    out = tmp_path / "near.json"
    assert cli.main(["init", "--markers", str(markers), f"--plate=cam0={root}cam0",
                     "--out", str(out), "--perspective"]) == 0, capsys.readouterr().err
    printed = capsys.readouterr().out
    data = json.loads(out.read_text())
    camera = data["anchors"][0]["views"]["cam0"]["camera"]
    true = read_calibration(root + "calibration.json")["cam0"]
    truth = json.loads(open(root + "truth.json").read())
    pelvis = np.array(truth["joints3d"])[truth["frames"].index(frame), JOINT_INDEX["pelvis"]]
    assert 0.7 < 1.0 / camera["kappa"] / true.depth(pelvis) < 1.5      # 4.7 m for 4.1 m
    assert f"camera distance (m): cam0 {1.0 / camera['kappa']:.1f}" in printed
    back = init_from_json(data)
    assert back.cameras["cam0"].kappa == camera["kappa"]
    calibrated = ["init", "--markers", root + "markers.json", "--calibration",
                  root + "calibration.json", "--out", str(tmp_path / "r.json"),
                  "--perspective"] + [f"--plate=cam{i}={root}cam{i}" for i in range(3)]
    assert cli.main(calibrated) == 2
    err = capsys.readouterr().err
    assert "--perspective is for uncalibrated views" in err and err.count("\n") == 1


def test_prior_command_reads_every_cmu_convention(shared_data):
    """``zoopraxis prior`` takes AMC captures (ASF beside them) and Daz-named BVH, at their
    true rates: 60_10's header says 120 fps, its capture is 60."""
    from zoopraxis.core.commands.prior import read_take_joints

    more = shared_data / "cmu_more"
    assert read_take_joints(more / "asf_amc" / "35_01.amc").shape == (90, 17, 3)
    assert read_take_joints(more / "bvh_daz" / "60_10.bvh").shape == (599, 17, 3)


def test_init_command_takes_a_calibration_made_at_another_scale(tmp_path, capsys):
    """Plates at half the calibrated size (the calibration of full-size footage, the plates an
    export at half size): the cameras are scaled to the plates, with a note, and the fit is
    the one of the plates' own calibration; a calibration of another shape is refused."""
    from zoopraxis.core.files.calibfile import read_calibration, write_calibration

    root = cli.__file__.replace("cli.py", "samples/walk3/")
    cameras = read_calibration(root + "calibration.json")
    double = tmp_path / "double.json"
    write_calibration(double, [c.scaled(2.0, "resize") for c in cameras.values()])
    plates = [f"--plate=cam{i}={root}cam{i}" for i in range(3)]
    outs = {}
    for name, calibration in (("own", root + "calibration.json"), ("double", str(double))):
        outs[name] = tmp_path / f"init_{name}.json"
        assert cli.main(["init", "--markers", root + "markers.json", "--calibration",
                         calibration, "--out", str(outs[name])] + plates) == 0
        printed = capsys.readouterr().out
        assert ("note: " in printed) == (name == "double")
    assert "camera 'cam0' is 960x720 but its plate is 480x360" in printed
    assert "scaled by 0.5" in printed
    own, scaled = (json.loads(outs[n].read_text()) for n in ("own", "double"))
    assert all(scaled["dims"][n] == pytest.approx(own["dims"][n], abs=1e-4)
               for n in bm.LENGTH_DIMS)
    wrong = tmp_path / "wrong.json"
    write_calibration(wrong, [c.replace(image_size=(480, 400)) for c in cameras.values()])
    assert cli.main(["init", "--markers", root + "markers.json", "--calibration", str(wrong),
                     "--out", str(tmp_path / "w.json")] + plates) == 2
    assert f"{wrong}: camera 'cam0' is 480x400 but its plate is 480x360" in \
        capsys.readouterr().err
