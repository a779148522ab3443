"""Tests of core.files.cmu: the standard joints of the CMU skeleton conventions, CMU captures in
the Zoopraxis world, MANIFEST.tsv and takes of any convention."""

import functools
from pathlib import Path

import numpy as np
import pytest

from zoopraxis.core.files import cmu
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX

# The small three-joint skeleton of test_bvh (not a CMU one).
CHAIN = (Path(__file__).parent / "chain.bvh").read_text()


@functools.lru_cache(maxsize=None)
def _load(path, fps=None):
    return cmu.load_cmu(path, fps)


@functools.lru_cache(maxsize=None)
def _standard_joints(path, fps=None):
    return cmu.standard_joints(_load(path, fps))


@pytest.fixture
def walk_path(shared_data):
    return str(shared_data / "cmu_mocap" / "131_01.bvh")


@pytest.fixture
def walk(walk_path):
    return _load(walk_path)


@pytest.fixture
def walk_joints(walk_path):
    return _standard_joints(walk_path)


@pytest.fixture
def playground(shared_data):
    return _load(str(shared_data / "cmu_mocap" / "01_01.bvh"))


def J(name):
    return JOINT_INDEX[name]


def facing_from_hips(joints):
    """Horizontal unit facing per frame: forward = left x up for a right-handed body."""
    left = joints[:, J("l_hip")] - joints[:, J("r_hip")]
    forward = np.cross(left, [0.0, 0.0, 1.0])
    return forward / np.linalg.norm(forward, axis=-1, keepdims=True)


class TestCmuFile:
    def test_header_and_hierarchy(self, walk):
        assert walk.fps == 120.0
        assert walk.num_frames == 994
        assert walk.num_joints == 31
        assert walk.names[:6] == ["Hips", "LHipJoint", "LeftHip", "LeftKnee", "LeftAnkle",
                                  "LeftToe"]
        assert walk.parents[walk.names.index("LeftKnee")] == walk.names.index("LeftHip")
        # 131 writes the arms Z X Y and everything else Z Y X.
        elbow = walk.channels[walk.names.index("LeftElbow")]
        assert elbow == ("Yrotation", "Xrotation", "Zrotation")
        assert walk.channels[walk.names.index("Neck")] == ("Yrotation", "Zrotation", "Xrotation")

    def test_both_cmu_namings_map(self, walk_joints, playground):
        assert walk_joints.shape == (994, 17, 3)
        assert cmu.standard_joints(playground, frames=slice(0, 3)).shape == (3, 17, 3)


class TestCmuGeometry:
    def test_height(self, walk, walk_joints, playground):
        # Stature to the head's End Site above the floor (lowest toe of the take).
        for motion, joints, low, high in ((walk, walk_joints, 1.3, 1.6),
                                          (playground, None, 1.5, 2.0)):
            if joints is None:
                joints = cmu.standard_joints(motion, frames=slice(0, None, 10))
                top = motion.end_site_position("Head", slice(0, None, 10))
            else:
                top = motion.end_site_position("Head")
            floor = joints[:, [J("l_toe"), J("r_toe")], 2].min()
            assert low < np.median(top[:, 2]) - floor < high

    def test_z_is_up(self, walk_joints):
        head, pelvis = walk_joints[:, J("head"), 2], walk_joints[:, J("pelvis"), 2]
        ankles = walk_joints[:, [J("l_ankle"), J("r_ankle")], 2]
        # 131_01 dips to a deep crouch near 3 s (pelvis 0.40 m up), hence the margins.
        assert np.all(head > pelvis + 0.2)
        assert np.all(pelvis[:, None] > ankles + 0.2)

    def test_floor_near_zero(self, walk_joints):
        toes = walk_joints[:, [J("l_toe"), J("r_toe")], 2]
        assert 0.0 < toes.min() < 0.05

    def test_thigh_is_rigid(self, walk_joints):
        for side in "lr":
            thigh = walk_joints[:, J(f"{side}_knee")] - walk_joints[:, J(f"{side}_hip")]
            length = np.linalg.norm(thigh, axis=-1)
            assert 0.35 < length.mean() < 0.5
            assert length.std() < 1e-3

    def test_neck_between_shoulders(self, walk_joints):
        shoulders = walk_joints[:, [J("l_shoulder"), J("r_shoulder")]].mean(axis=1)
        assert np.linalg.norm(walk_joints[:, J("neck")] - shoulders, axis=-1).max() < 0.04

    def test_head_centre_above_neck(self, walk_joints):
        # Neck to Head is 9 cm, Head to its End Site (crown) 9 cm; the centre is half-way.
        rise = walk_joints[:, J("head"), 2] - walk_joints[:, J("neck"), 2]
        assert 0.1 < np.median(rise) < 0.2
        assert np.all(rise > 0.0)


class TestCmuMotion:
    def test_walk_progresses(self, walk_joints):
        pelvis = walk_joints[:, J("pelvis")]
        assert np.linalg.norm(pelvis[-1, :2] - pelvis[0, :2]) > 1.0

    def test_left_is_subjects_left(self, walk_joints, playground):
        # With left and right swapped, the hips would say the subject faces backwards:
        # against the feet (ankle -> toe) and against the walk.
        walk_direction = walk_joints[-1, J("pelvis")] - walk_joints[0, J("pelvis")]
        walk_direction[2] = 0
        walk_direction /= np.linalg.norm(walk_direction)
        assert facing_from_hips(walk_joints)[0] @ walk_direction > 0.9
        for joints in (walk_joints, cmu.standard_joints(playground, frames=slice(0, None, 10))):
            facing = facing_from_hips(joints)
            feet = (joints[:, [J("l_toe"), J("r_toe")]]
                    - joints[:, [J("l_ankle"), J("r_ankle")]]).sum(axis=1)
            feet[:, 2] = 0
            feet /= np.linalg.norm(feet, axis=-1, keepdims=True)
            assert facing[0] @ feet[0] > 0.9
            assert np.mean(np.sum(facing * feet, axis=-1) > 0.7) > 0.95

    def test_walks_towards_minus_y(self, walk_joints):
        walk_direction = walk_joints[-1, J("pelvis"), :2] - walk_joints[0, J("pelvis"), :2]
        assert walk_direction[1] / np.linalg.norm(walk_direction) < -0.95

    def test_stance_toes_stay_put(self, walk_joints, walk):
        # The intrinsic Euler order keeps planted feet still; the reversed (extrinsic)
        # order slides the right toe at ~0.75 m/s on this take.
        for side in "lr":
            toe = walk_joints[:, J(f"{side}_toe")]
            speed = np.linalg.norm(np.diff(toe[:, :2], axis=0), axis=-1) * walk.fps
            planted = toe[:-1, 2] < np.percentile(toe[:, 2], 20)
            assert np.median(speed[planted]) < 0.25

    def test_resample_to_30(self, walk, walk_joints, walk_path):
        slow = _load(walk_path, 30)
        assert slow.fps == 30.0
        assert slow.num_frames == (walk.num_frames + 3) // 4
        np.testing.assert_allclose(_standard_joints(walk_path, 30), walk_joints[::4], atol=1e-12)


class TestCmuFrames:
    def test_frames_follow_bones(self, walk, walk_joints):
        frames = cmu.standard_joint_frames(walk)
        np.testing.assert_allclose(frames[..., :3, 3], walk_joints, atol=1e-12)
        rotations = frames[..., :3, :3]
        np.testing.assert_allclose(np.linalg.det(rotations), 1.0)
        # Each bone's far joint is fixed in the frame of the bone.
        for start, end in (("l_hip", "l_knee"), ("r_shoulder", "r_elbow"), ("l_knee", "l_ankle")):
            world_from_bone = frames[:, J(start)]
            local = np.einsum("fba,fb->fa", world_from_bone[:, :3, :3],
                              walk_joints[:, J(end)] - world_from_bone[:, :3, 3])
            assert np.abs(local - local[0]).max() < 1e-9


MANIFEST_HEAD = "file\tcmu_subject_trial\tframe_rate\tframe_count\n"


class TestManifest:
    def test_rates_and_reference_frames(self, tmp_path):
        path = tmp_path / "MANIFEST.tsv"
        path.write_text(MANIFEST_HEAD
                        + "bvh_daz/60_05.bvh\t60_05\theader 120.00 fps; CMU capture 60 fps "
                          "(HEADER WRONG: use 60 fps)\t1679 (incl. T-pose frame 0)\n"
                        + "asf_amc/35_01.amc\t35_01\t120 fps (CMU capture rate)\t358\n")
        takes = cmu.read_manifest(path)
        assert takes == {"60_05": cmu.TakeInfo(60.0, True), "35_01": cmu.TakeInfo(120.0, False)}

    def test_row_without_rate(self, tmp_path):
        path = tmp_path / "MANIFEST.tsv"
        path.write_text(MANIFEST_HEAD + "a/01_01.bvh\t01_01\tfast\t10\n")
        with pytest.raises(ZoopraxisError, match=r"MANIFEST\.tsv:2: no frame rate in 'fast'"):
            cmu.read_manifest(path)

    def test_manifest_overrules_header_and_drops_frame_0(self, tmp_path):
        folder = tmp_path / "bvh"
        folder.mkdir()
        text = CHAIN.replace("Frames: 2", "Frames: 3").replace(
            "1 2 3 90", "0 0 0 0 0 0 0 0 0 0 0 0\n1 2 3 90")
        (folder / "07_01.bvh").write_text(text)
        (tmp_path / "MANIFEST.tsv").write_text(
            MANIFEST_HEAD + "bvh/07_01.bvh\t07_01\theader 120 fps; CMU capture 60 fps\t"
                            "3 (incl. T-pose frame 0)\n")
        with pytest.raises(ZoopraxisError, match=r"07_01\.bvh: not a 'cmu' skeleton \(no joint"):
            cmu.read_take(folder / "07_01.bvh")
        renamed = text.replace("Hips", "hip").replace("Knee", "lfemur").replace("Ankle", "ltibia")
        (folder / "07_01.bvh").write_text(renamed)
        with pytest.raises(ZoopraxisError, match=r"no joint 'head' and \d+ more; closest: cmu_asf"):
            cmu.read_take(folder / "07_01.bvh")


TAKES = [("bvh_mb/02_01.bvh", "cmu_cgspeed", 120.0, 343),
         ("bvh_mb/09_01.bvh", "cmu_cgspeed", 120.0, 148),
         ("bvh_daz/12_01.bvh", "cmu_daz", 120.0, 523),
         ("bvh_daz/60_10.bvh", "cmu_daz", 60.0, 1197),       # header says 120
         ("bvh_asfnames/16_01.bvh", "cmu_asf", 120.0, 322),   # header says 30; no T-pose
         ("asf_amc/35_01.amc", "cmu_asf", 120.0, 358)]


@functools.lru_cache(maxsize=None)
def _take(path):
    take = cmu.read_take(path)
    return take, take.joints(30)


class TestCmuMore:
    @pytest.mark.parametrize("name, skeleton, fps, frames", TAKES)
    def test_read(self, shared_data, name, skeleton, fps, frames):
        take, joints = _take(str(shared_data / "cmu_more" / name))
        assert (take.skeleton, take.fps, take.motion.num_frames) == (skeleton, fps, frames)
        assert take.subject == name.split("/")[1].split("_")[0]
        assert joints.shape == (len(range(0, frames, int(fps // 30))), 17, 3)

    @pytest.mark.parametrize("name", [t[0] for t in TAKES])
    def test_standing_body(self, shared_data, name):
        """A human in metres, Z up, left on the left, feet on the floor: wrong units, a
        T-pose left in, or mirrored axes all break one of these."""
        take, joints = _take(str(shared_data / "cmu_more" / name))
        toes = joints[:, [J("l_toe"), J("r_toe")], 2]
        stature = joints[:, J("head"), 2] - toes.min(axis=1)
        assert 1.2 < np.median(stature) < 1.8
        assert -0.02 < toes.min() < 0.08
        thigh = np.linalg.norm(joints[:, J("l_knee")] - joints[:, J("l_hip")], axis=-1)
        assert 0.33 < thigh.mean() < 0.5 and thigh.std() < 1e-3
        facing = facing_from_hips(joints)
        feet = (joints[:, [J("l_toe"), J("r_toe")]] - joints[:, [J("l_ankle"), J("r_ankle")]]
                ).sum(axis=1)
        feet[:, 2] = 0
        feet /= np.linalg.norm(feet, axis=-1, keepdims=True)
        assert np.mean(np.sum(facing * feet, axis=-1) > 0.5) > 0.95
        # the T-pose frame is gone: the first frame does not hold both arms out level
        arms = joints[0, [J("l_wrist"), J("r_wrist")], 2] \
            - joints[0, [J("l_shoulder"), J("r_shoulder")], 2]
        assert np.abs(arms).max() > 0.08

    def test_amc_walk_plants_its_feet(self, shared_data):
        # the Acclaim rotation order read backwards slides the planted feet
        take, _ = _take(str(shared_data / "cmu_more" / "asf_amc" / "35_01.amc"))
        joints = take.joints()
        toe = joints[:, J("l_toe")]
        speed = np.linalg.norm(np.diff(toe[:, :2], axis=0), axis=-1) * take.fps
        assert np.median(speed[toe[:-1, 2] < np.percentile(toe[:, 2], 20)]) < 0.15
        assert np.linalg.norm(joints[-1, J("pelvis"), :2] - joints[0, J("pelvis"), :2]) > 3.0


def test_capture_paths_hold_subjects_out(tmp_path):
    for name in ("a/02_01.bvh", "a/02_02.bvh", "b/35_01.amc", "b/35.asf", "b/notes.txt",
                 "131_01.bvh"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("")
    stems = [p.stem for p in cmu.capture_paths(tmp_path)]
    assert sorted(stems) == ["02_01", "02_02", "131_01", "35_01"]
    assert [p.stem for p in cmu.capture_paths(tmp_path, hold_out=["02", "131"])] == ["35_01"]
    assert cmu.subject_of("135_04") == "135"
    with pytest.raises(ZoopraxisError, match="nowhere: no such folder"):
        cmu.capture_paths(tmp_path / "nowhere")
