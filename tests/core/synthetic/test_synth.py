"""Synthetic plates: the rendered body sits where the ground truth says, files are complete."""

import json

import numpy as np
import pytest

from zoopraxis.core.files import calibfile
from zoopraxis.core.imaging import plates
from zoopraxis.core.synthetic import synth
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX


@pytest.fixture(scope="module")
def walk(request):
    from tests.conftest import shared_data_dir

    data = shared_data_dir()
    if data is None:
        pytest.skip("shared data (../shared/data) is not beside this clone")
    scene, joints = synth.take_from_bvh(data / "cmu_mocap" / "131_01.bvh", frames=slice(0, 8),
                                        views=2, image_size=(240, 180), noise=0, clutter=4)
    return scene, joints


def test_joints_project_inside_the_rendered_body(walk):
    scene, joints = walk
    for v, cam in enumerate(scene.cameras):
        for f in (0, 7):
            _, label = scene.render_frame(f, v)
            uv = np.rint(cam.project(joints[f])).astype(int)
            inside = [label[y, x] >= 0 for x, y in uv
                      if 0 <= x < label.shape[1] and 0 <= y < label.shape[0]]
            # joint centres lie inside the limbs (a wrist may sit just off a thin hand)
            assert np.mean(inside) >= 0.9


def test_body_fills_a_plausible_part_of_the_view(walk):
    scene, joints = walk
    _, label = scene.render_frame(0, 0)
    frac = np.mean(label >= 0)
    assert 0.02 < frac < 0.4
    uv = scene.cameras[0].project(joints[0])
    height_px = uv[:, 1].max() - uv[:, 1].min()
    assert height_px > 0.35 * 180


def test_textures_and_noise(walk):
    scene, _ = walk
    image, label = scene.render_frame(3, 1)
    gray = image.mean(axis=2)
    # the body carries texture: image gradients inside it are not zero
    gy, gx = np.gradient(gray)
    assert np.median(np.hypot(gx, gy)[label >= 0]) > 0.5
    noisy = synth.Scene(scene.body, scene.cameras, scene.backgrounds, noise=8.0)
    noisy_image, _ = noisy.render_frame(3, 1)
    diff = noisy_image.astype(float) - image
    assert 5.0 < diff.std() < 11.0


def test_builds_change_the_silhouette(walk):
    scene, joints = walk
    heavy = synth.make_scene(joints, np.repeat(np.eye(4)[None, None], 8, 0).repeat(17, 1),
                             views=1, image_size=(240, 180), build="heavy")
    slim = synth.make_scene(joints, np.repeat(np.eye(4)[None, None], 8, 0).repeat(17, 1),
                            views=1, image_size=(240, 180), build="slim")
    area = [np.sum(s.render_frame(0, 0)[1] >= 0) for s in (slim, heavy)]
    assert area[1] > 1.2 * area[0]


def test_write_take_round_trip(walk, tmp_path):
    scene, joints = walk
    out = tmp_path / "take"
    n = synth.write_take(out, scene, joints, marker_noise=1.0, image_format="jpg")
    assert n == 8
    cams = calibfile.read_calibration(out / "calibration.json")
    assert list(cams) == ["cam0", "cam1"]
    truth = synth.read_truth(out / "truth.json")
    assert truth["joints3d"].shape == (8, 17, 3)
    assert np.allclose(truth["joints2d"]["cam1"], cams["cam1"].project(truth["joints3d"]),
                       atol=0.01)
    plate = plates.open_plate(out / "cam0")
    assert len(plate) == 8 and plate.image_size == (240, 180)
    markers = json.loads((out / "markers.json").read_text())
    clicked = np.array(markers["anchors"][0]["views"]["cam0"]["l_knee"])
    true = truth["joints2d"]["cam0"][0, JOINT_INDEX["l_knee"]]
    assert 0 < np.linalg.norm(clicked - true) < 5.0
    with pytest.raises(ZoopraxisError, match="not empty"):
        synth.write_take(out, scene, joints)


def test_cancel_keeps_frames_written(walk, tmp_path):
    scene, joints = walk
    calls = []
    n = synth.write_take(tmp_path / "t", scene, joints, cancel=lambda: len(calls) >= 3,
                         progress=lambda done, total: calls.append(done))
    assert n == 3
    assert len(list((tmp_path / "t" / "cam0").iterdir())) == 3
    assert synth.read_truth(tmp_path / "t" / "truth.json")["joints3d"].shape[0] == 3


def test_bad_input():
    with pytest.raises(ZoopraxisError, match="shape"):
        synth.make_scene(np.zeros((4, 5, 3)), np.zeros((4, 17, 4, 4)))
    with pytest.raises(ZoopraxisError, match="no such file"):
        synth.read_truth("/nonexistent/truth.json")
