"""markers.json and result.json: round trips and errors that name the key, frame or joint."""

import json

import numpy as np
import pytest

from zoopraxis.core.files import markers, result
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import STANDARD_JOINTS


def write(tmp_path, data, name="f.json"):
    path = tmp_path / name
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return path


def test_markers_round_trip(tmp_path):
    anchors = [markers.Anchor(12, {"cam1": {"l_knee": (1.5, 2.5)}}),
               markers.Anchor(0, {"cam0": {j: (float(i), 2.0 * i) for i, j in
                                           enumerate(STANDARD_JOINTS)}})]
    path = tmp_path / "markers.json"
    markers.write_markers(path, anchors)
    back = markers.read_markers(path)
    assert [a.frame for a in back] == [0, 12]                       # sorted by frame
    assert back[0].array("cam0")[5].tolist() == [5.0, 10.0]
    assert np.isnan(back[1].array("cam0")).all()
    with pytest.raises(ZoopraxisError, match="exists"):
        markers.write_markers(path, anchors)


@pytest.mark.parametrize("data, message", [
    ({}, "missing required key 'anchors'"),
    ({"anchors": [{"views": {}}]}, "anchor 0: missing required key 'frame'"),
    ({"anchors": [{"frame": -1, "views": {}}]}, "'frame' must be a whole number"),
    ({"anchors": [{"frame": 0, "views": {"cam0": {"knee": [1, 2]}}}]},
     "view 'cam0': unknown joint 'knee'"),
    ({"anchors": [{"frame": 3, "views": {"cam0": {"l_knee": [1]}}}]},
     "frame 3, view 'cam0', joint 'l_knee': expected \\[u, v\\]"),
    ({"anchors": [{"frame": 0, "views": {}}, {"frame": 0, "views": {}}]}, "two anchors"),
    ("{not json", "not valid JSON"),
])
def test_markers_errors(tmp_path, data, message):
    with pytest.raises(ZoopraxisError, match=message):
        markers.read_markers(write(tmp_path, data))


def test_check_markers():
    full = {j: (1.0, 1.0) for j in STANDARD_JOINTS}
    ok = [markers.Anchor(0, {"cam0": full})]
    markers.check_markers(ok, ["cam0"], 10)
    with pytest.raises(ZoopraxisError, match="view 'camX' is not one of the plates"):
        markers.check_markers([markers.Anchor(0, {"camX": full})], ["cam0"], 10)
    with pytest.raises(ZoopraxisError, match="anchor frame 20 is outside the take"):
        markers.check_markers([markers.Anchor(20, {"cam0": full})], ["cam0"], 10)
    few = {j: (1.0, 1.0) for j in STANDARD_JOINTS[:4]}
    with pytest.raises(ZoopraxisError, match="no view has at least 6 joints"):
        markers.check_markers([markers.Anchor(0, {"cam0": few})], ["cam0"], 10)
    with pytest.raises(ZoopraxisError, match="no anchors"):
        markers.check_markers([], ["cam0"], 10)


def make_result(F=3):
    rng = np.random.default_rng(2345)
    return result.TrackResult(
        mode="calibrated", fps=30.0, frames=np.arange(F), joints3d=rng.normal(size=(F, 17, 3)),
        joints2d={"cam0": rng.normal(size=(F, 17, 2))}, residual={"cam0": rng.uniform(size=F)},
        status=["ok", "uncertain", "lost"][:F], body={"template": "full"},
        roots=np.tile(np.eye(4), (F, 1, 1)), angles=rng.normal(size=(F, 29)),
        extra={"tracker": "differential"})


def test_result_round_trip(tmp_path):
    res = make_result()
    path = tmp_path / "result.json"
    result.write_result(path, res)
    back = result.read_result(path)
    assert np.allclose(back.joints3d, res.joints3d, atol=1e-5)
    assert np.allclose(back.joints2d["cam0"], res.joints2d["cam0"], atol=1e-3)
    assert back.status == res.status and back.extra["tracker"] == "differential"
    assert np.allclose(back.angles, res.angles, atol=1e-6)
    with pytest.raises(ZoopraxisError, match="exists"):
        result.write_result(path, res)
    data = json.loads(path.read_text())
    assert data["format"] == "zoopraxis-track/1" and data["joints"] == list(STANDARD_JOINTS)


def test_result_joint_order_is_by_name(tmp_path):
    data = make_result().to_json()
    order = list(reversed(STANDARD_JOINTS)) + ["l_hand"]
    idx = [STANDARD_JOINTS.index(j) if j in STANDARD_JOINTS else 0 for j in order]
    data["joints"] = order
    data["joints3d"] = np.asarray(data["joints3d"])[:, idx].tolist()
    data["views"]["cam0"]["joints2d"] = np.asarray(data["views"]["cam0"]["joints2d"])[:, idx].tolist()
    back = result.read_result(write(tmp_path, data))
    assert np.allclose(back.joints3d, np.asarray(make_result().to_json()["joints3d"]))


@pytest.mark.parametrize("change, message", [
    (lambda d: d.pop("status"), "missing required key 'status'"),
    (lambda d: d.update(format="other/1"), "format 'other/1'"),
    (lambda d: d.update(mode="guess"), "mode 'guess'"),
    (lambda d: d["joints"].remove("l_knee"), "joint 'l_knee' is missing"),
    (lambda d: d.update(status=["ok", "ok", "maybe"]), "unknown status 'maybe'"),
    (lambda d: d["views"]["cam0"].update(residual=[0.0]),
     r"view 'cam0': 'residual' has shape \(1,\)"),
])
def test_result_errors(tmp_path, change, message):
    data = make_result().to_json()
    change(data)
    with pytest.raises(ZoopraxisError, match=message):
        result.read_result(write(tmp_path, data))
