"""Every reader of a user's file, fed malformed input: one ZoopraxisError naming the file, never
another exception, never a hang. (The BVH reader, being rewritten for issue 26, is left out.)

Each reader gets random bytes, truncations of a good file, values of the wrong type put at
every place of the good file's JSON tree, huge and non-finite numbers, and deep nesting.
"""

import json
import math
import os
import zipfile

import numpy as np
import pytest

from zoopraxis.core.files import calibfile, markers, result
from zoopraxis.core.commands import common as cli_common
from zoopraxis.core.files.initfile import read_init
from zoopraxis.core.priors import pose as pose_prior
from zoopraxis.core.priors.pose import resolve_pose_prior
from zoopraxis.core.body.body import DEFAULT_DIMS, make_body
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.files.inputs import read_json
from zoopraxis.core.body.joints import STANDARD_JOINTS

SAMPLE = __import__("pathlib").Path(calibfile.__file__).parents[2] / "samples" / "walk3"

# Values that no field of our files holds: each is put in place of each node in turn.
WRONG = ["12", "", None, True, [], {}, [[1, 2], [3]], 1e308, -1e308, 1e300, -1, 0, 10 ** 400,
         float("nan"), float("inf")]


def _nodes(data, path=()):
    """Paths of every node of a JSON tree (lists sampled: first and last entry)."""
    yield path
    if isinstance(data, dict):
        for key, value in data.items():
            yield from _nodes(value, path + (key,))
    elif isinstance(data, list) and data:
        for index in sorted({0, len(data) - 1}):
            yield from _nodes(data[index], path + (index,))


def _replaced(data, path, value):
    data = json.loads(json.dumps(data))
    if not path:
        return value
    node = data
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return data


def _dumps(data):
    try:
        return json.dumps(data)
    except ValueError:                     # an integer too long to print: write it by hand
        return json.dumps(data, default=str).replace('"' + "1" + "0" * 400 + '"', "1" + "0" * 400)


def malformed_texts(good, rng, mutations=120):
    """Byte strings a hostile user might hand a JSON reader in place of ``good``."""
    text = json.dumps(good).encode()
    yield rng.bytes(3000)
    yield b""
    yield b"\xff\xfe" + text
    yield b"[" * 100000 + b"]" * 100000
    yield b'{"a":' * 50000 + b"1" + b"}" * 50000
    yield b"1" * 5000
    for cut in rng.integers(1, len(text), 12):
        yield text[:cut]
    nodes = list(_nodes(good))
    for k in range(mutations):
        path = nodes[rng.integers(len(nodes))]
        value = WRONG[k % len(WRONG)]
        yield _dumps(_replaced(good, path, value)).encode()


def assert_one_line_or_ok(read, path):
    """``read(path)`` succeeds or raises a ZoopraxisError naming the file; nothing else."""
    try:
        read(path)
    except ZoopraxisError as error:
        assert path.name in str(error), str(error)
        assert "\n" not in str(error)


def fuzz(read, good, tmp_path, seed, name="f.json", mutations=120):
    rng = np.random.default_rng(seed)
    path = tmp_path / name
    tried = 0
    for blob in malformed_texts(good, rng, mutations):
        path.write_bytes(blob)
        assert_one_line_or_ok(read, path)
        tried += 1
    return tried


def good_result():
    body = make_body("full")
    F = 3
    return {"format": "zoopraxis-track/1", "mode": "calibrated", "fps": 30.0,
            "joints": list(STANDARD_JOINTS), "frames": [0, 1, 2],
            "joints3d": np.zeros((F, 17, 3)).tolist(),
            "views": {"cam0": {"joints2d": np.zeros((F, 17, 2)).tolist(),
                               "residual": [0.0] * F}},
            "status": ["ok", "uncertain", "lost"],
            "body": {"template": "full", "shapes": "ellipsoid", "dims": dict(DEFAULT_DIMS),
                     "dof_names": list(body.dof_names)},
            "roots": np.tile(np.eye(4), (F, 1, 1)).tolist(),
            "angles": np.zeros((F, body.n_dofs)).tolist()}


def good_init():
    body = make_body("full")
    camera = next(iter(calibfile.read_calibration(SAMPLE / "calibration.json").values()))
    return {"format": "zoopraxis-init/1", "mode": "calibrated", "template": "full",
            "dims": dict(DEFAULT_DIMS),
            "anchors": [{"frame": 0, "pose": [0.0] * (6 + body.n_dofs),
                         "views": {"cam0": {"camera": camera.to_dict(), "errors": [1.0]}}}]}


def test_markers_reader_fuzzed(tmp_path):
    good = json.loads((SAMPLE / "markers.json").read_text())
    assert fuzz(markers.read_markers, good, tmp_path, 2345) > 130


def test_calibration_json_reader_fuzzed(tmp_path):
    good = json.loads((SAMPLE / "calibration.json").read_text())
    fuzz(calibfile.read_calibration, good, tmp_path, 2346)


def test_calibration_toml_reader_fuzzed(tmp_path):
    rng = np.random.default_rng(2347)
    good = ('[cam_01]\nname = "cam_01"\nsize = [ 640.0, 480.0,]\n'
            'matrix = [ [ 500.0, 0.0, 319.5,], [ 0.0, 500.0, 239.5,], [ 0.0, 0.0, 1.0,],]\n'
            'distortions = [ 0.0, 0.0, 0.0, 0.0,]\nrotation = [ 0.1, -1.2, 0.3,]\n'
            'translation = [ 0.5, 0.2, 4.0,]\nfisheye = false\n').encode()
    path = tmp_path / "cal.toml"
    blobs = [rng.bytes(2000), b"a = " + b"[" * 5000 + b"]" * 5000, b"[cam]\nsize = 'x'\n"]
    blobs += [good[:cut] for cut in rng.integers(1, len(good), 15)]
    blobs += [good.replace(b"0.1, -1.2", b"1e400, -1.2"), good.replace(b"500.0", b"nan"),
              good.replace(b"[ 640.0, 480.0,]", b"'big'")]
    for blob in blobs:
        path.write_bytes(blob)
        assert_one_line_or_ok(calibfile.read_calibration, path)


def test_result_reader_fuzzed(tmp_path):
    good = good_result()
    path = tmp_path / "r.json"
    path.write_text(json.dumps(good))
    assert result.read_result(path).num_frames == 3           # the good file reads
    fuzz(result.read_result, good, tmp_path, 2348, name="r.json", mutations=200)


def test_init_reader_fuzzed(tmp_path):
    good = good_init()
    path = tmp_path / "init.json"
    path.write_text(json.dumps(good))
    assert list(read_init(path).poses) == [0]
    fuzz(read_init, good, tmp_path, 2349, name="init.json")


def test_dims_reader_fuzzed(tmp_path):
    good = good_init()
    fuzz(lambda p: cli_common.read_dims(p, "full"), good, tmp_path, 2350, name="dims.json")


def test_pose_prior_reader_fuzzed(tmp_path):
    rng = np.random.default_rng(2351)
    dof_names = make_body("full").dof_names
    good = tmp_path / "good.npz"
    np.savez_compressed(good, angles=np.zeros((4, len(dof_names)), np.float32),
                        takes=np.array(["a"] * 4), dof_names=np.array(dof_names),
                        template=np.array("full"))
    raw = good.read_bytes()
    assert resolve_pose_prior(str(good), "full") is not None
    bad = tmp_path / "p.npz"
    blobs = [rng.bytes(3000), b"", b"PK\x03\x04" + rng.bytes(300)]
    blobs += [raw[:cut] for cut in rng.integers(1, len(raw), 12)]
    for blob in blobs:
        bad.write_bytes(blob)
        pose_prior._PRIOR_FILES.clear()
        assert_one_line_or_ok(lambda p: resolve_pose_prior(str(p), "full"), bad)
    with zipfile.ZipFile(bad, "w") as archive:                 # an npz of wrong arrays
        archive.writestr("angles.npy", b"junk")
    with pytest.raises(ZoopraxisError, match="p.npz: not a pose prior file"):
        resolve_pose_prior(str(bad), "full")
    nan = tmp_path / "nan.npz"
    np.savez_compressed(nan, angles=np.full((4, len(dof_names)), np.nan), takes=np.array(["a"] * 4),
                        dof_names=np.array(dof_names), template=np.array("full"))
    with pytest.raises(ZoopraxisError, match="nan.npz: not a pose prior file"):
        resolve_pose_prior(str(nan), "full")


@pytest.mark.parametrize("reader", [markers.read_markers, result.read_result,
                                    calibfile.read_calibration, read_init,
                                    lambda p: cli_common.read_dims(p, "full")])
def test_readers_refuse_pipes_and_folders_without_opening(tmp_path, reader):
    pipe = tmp_path / "pipe.json"
    os.mkfifo(pipe)
    with pytest.raises(ZoopraxisError, match="pipe.json: is not a regular file"):
        reader(pipe)                    # opening the pipe would block forever
    folder = tmp_path / "folder.json"
    folder.mkdir()
    with pytest.raises(ZoopraxisError, match="folder.json: is a folder"):
        reader(folder)


def test_read_json_names_what_is_wrong(tmp_path):
    path = tmp_path / "x.json"
    path.write_bytes(b"\x00\xff binary")
    with pytest.raises(ZoopraxisError, match="x.json: not a text file"):
        read_json(path, "markers file")
    path.write_bytes(b"[" * 100000)
    with pytest.raises(ZoopraxisError, match="x.json: JSON nested too deep"):
        read_json(path, "markers file")
    path.write_bytes(b'{"a": ' + b"1" * 5000 + b"}")
    with pytest.raises(ZoopraxisError, match="x.json: not valid JSON"):
        read_json(path, "markers file")


@pytest.mark.parametrize("uv, message", [
    ("12", "pixels, got .12."),
    ([1, 2, 3], "expected \\[u, v\\]"),
    ([True, 2], "expected \\[u, v\\]"),
    ([1e300, 5], "is no pixel of any image"),
    ([math.inf, 5], "not finite"),
])
def test_markers_click_must_be_two_numbers(uv, message):
    data = {"anchors": [{"frame": 0, "views": {"cam0": {"l_knee": uv}}}]}
    with pytest.raises(ZoopraxisError, match="frame 0, view 'cam0', joint 'l_knee': .*" + message):
        markers.parse_markers(data, "m.json")


def test_result_values_checked(tmp_path):
    cases = [("fps", "thirty", "'fps' must be a positive number"),
             ("fps", 0, "'fps' must be a positive number"),
             ("views", [1, 2], "'views' must map view names"),
             ("frames", ["a", "b", "c"], "'frames' must be a list of frame numbers"),
             ("angles", [[float("nan")] * 29] * 3, "'angles' holds NaN or infinity"),
             ("joints3d", [[[0, 0, 0]] * 17] * 2 + [[[0, 0]] * 17], "'joints3d' must be an array")]
    path = tmp_path / "r.json"
    for key, value, message in cases:
        path.write_text(json.dumps(dict(good_result(), **{key: value})))
        with pytest.raises(ZoopraxisError, match="r.json: " + message):
            result.read_result(path)
    data = good_result()
    data["body"]["dims"]["thigh"] = 50.0
    path.write_text(json.dumps(data))
    with pytest.raises(ZoopraxisError, match="body length 'thigh' of 50 m is outside the human"):
        result.read_result(path)


def test_plate_reader_fuzzed(tmp_path, monkeypatch):
    import cv2

    from zoopraxis.core.imaging import plates

    rng = np.random.default_rng(2352)
    video = tmp_path / "good.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 30, (64, 48))
    for k in range(6):
        writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    writer.release()
    raw = video.read_bytes()
    bad = tmp_path / "bad.avi"
    for blob in [rng.bytes(5000), b"", raw[:len(raw) // 2], raw[:200],
                 raw[:4000] + rng.bytes(4000)]:
        bad.write_bytes(blob)
        try:
            with plates.open_plate(bad) as plate:
                for frame in range(plate.num_frames):
                    plate.read(frame)
        except ZoopraxisError as error:
            assert "bad.avi" in str(error)
    folder = tmp_path / "frames"
    folder.mkdir()
    for k, blob in enumerate([rng.bytes(3000), b"\xff\xd8" + rng.bytes(3000) + b"\xff\xd9"]):
        (folder / f"{k}.jpg").write_bytes(blob)
        with pytest.raises(ZoopraxisError, match=f"{k}.jpg"):
            plates.open_plate(folder)
        (folder / f"{k}.jpg").unlink()

    def unlistable(self):
        raise PermissionError(13, "Permission denied")

    (folder / "0.jpg").write_bytes(b"x")
    monkeypatch.setattr(type(folder), "iterdir", unlistable)
    with pytest.raises(ZoopraxisError, match="frames: cannot list it \\(Permission denied\\)"):
        plates.open_plate(folder)


def test_prior_command_take_reader_fuzzed(tmp_path):
    from zoopraxis.core.commands.prior import read_take_joints

    truth = {"format": "zoopraxis-truth/1", "joints": list(STANDARD_JOINTS),
             "joints3d": np.zeros((2, 17, 3)).tolist()}
    fuzz(read_take_joints, truth, tmp_path, 2353, name="truth.json")
    fuzz(read_take_joints, good_result(), tmp_path, 2354, name="result.json")
