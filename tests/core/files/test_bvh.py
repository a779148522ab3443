"""BVH reading, forward kinematics, world conversion, resampling and the standard joints."""

import functools

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zoopraxis.core.files import bvh
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import JOINT_INDEX, STANDARD_JOINTS

# A root with 6 channels, a child with ZXY and a grandchild with XYZ channels.
CHAIN = """\
HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Knee
  {
    OFFSET 0 1 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Ankle
    {
      OFFSET 0 1 0
      CHANNELS 3 Xrotation Yrotation Zrotation
      End Site
      {
        OFFSET 0 0 2
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0083333
1 2 3 90 0 0 0 90 0 0 0 0
0 0 0 0 0 0 0 0 0 0 0 0
"""


def one_joint(channels, values):
    """A root at the origin with the given channels and one frame, child at (0, 1, 0)."""
    return bvh.parse_bvh(
        f"HIERARCHY\nROOT A\n{{\n OFFSET 0 0 0\n CHANNELS {len(channels)} {' '.join(channels)}\n"
        " End Site\n {\n  OFFSET 0 1 0\n }\n}\n"
        f"MOTION\nFrames: 1\nFrame Time: 0.1\n{' '.join(map(str, values))}\n")


def write(tmp_path, text, name="bad.bvh"):
    path = tmp_path / name
    path.write_text(text)
    return path


def random_motion(rng, frames=5):
    """CHAIN's skeleton with random angles and root positions."""
    motion = bvh.parse_bvh(CHAIN)
    data = rng.uniform(-180, 180, (frames, motion.data.shape[1]))
    data[:, :3] = rng.normal(size=(frames, 3))
    return bvh.Motion(motion.names, motion.parents, motion.offsets, motion.channels,
                      motion.end_sites, motion.frame_time, data)


# ---------------------------------------------------------------------------------------
# Reading


class TestRead:
    def test_hierarchy(self, tmp_path):
        motion = bvh.read_bvh(write(tmp_path, CHAIN, "chain.bvh"))
        assert motion.names == ["Hips", "Knee", "Ankle"]
        assert motion.parents.tolist() == [-1, 0, 1]
        np.testing.assert_array_equal(motion.offsets, [[0, 0, 0], [0, 1, 0], [0, 1, 0]])
        assert motion.channels[0] == ("Xposition", "Yposition", "Zposition",
                                      "Zrotation", "Xrotation", "Yrotation")
        assert motion.channels[2] == ("Xrotation", "Yrotation", "Zrotation")
        assert list(motion.end_sites) == ["Ankle"]
        np.testing.assert_array_equal(motion.end_sites["Ankle"], [0, 0, 2])
        assert motion.source.endswith("chain.bvh")

    def test_motion_block(self):
        motion = bvh.parse_bvh(CHAIN)
        assert motion.data.shape == (2, 12)
        assert motion.num_frames == 2
        np.testing.assert_array_equal(motion.data[0, :4], [1, 2, 3, 90])
        assert motion.frame_time == pytest.approx(0.0083333)
        assert motion.fps == 120.0  # .0083333 is 120 fps written with 7 decimals

    def test_fps_not_snapped_when_far_from_integer(self):
        motion = bvh.parse_bvh(CHAIN.replace("0.0083333", "0.0333667"))
        assert motion.fps == pytest.approx(29.97, abs=1e-3)

    def test_zero_frames(self):
        text = CHAIN.split("Frames:")[0] + "Frames: 0\nFrame Time: 0.01\n"
        assert bvh.parse_bvh(text).data.shape == (0, 12)

    def test_channel_names_any_case_and_tabs(self):
        motion = bvh.parse_bvh(CHAIN.replace("Xrotation Yrotation Zrotation",
                                             "XROTATION\tyrotation  Zrotation"))
        assert motion.channels[2] == ("Xrotation", "Yrotation", "Zrotation")


class TestReadErrors:
    def test_bad_keyword(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("    JOINT Ankle", "    JOINTS Ankle"))
        with pytest.raises(ZoopraxisError,
                           match=r"bad\.bvh:10: unexpected 'JOINTS' in joint 'Knee'"):
            bvh.read_bvh(path)

    def test_missing_hierarchy(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("HIERARCHY", "HIERARCY"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:1: expected 'HIERARCHY'"):
            bvh.read_bvh(path)

    def test_wrong_number_of_values(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("0 0 0 0 0 0 0 0 0 0 0 0\n",
                                             "0 0 0 0 0 0 0 0 0 0 0\n"))
        with pytest.raises(ZoopraxisError,
                           match=r"bad\.bvh:25: frame 1 has 11 values.* 12 channels"):
            bvh.read_bvh(path)

    def test_compensating_line_lengths_are_caught(self, tmp_path):
        text = CHAIN.replace("1 2 3 90 0 0 0 90 0 0 0 0\n0 0 0 0 0 0 0 0 0 0 0 0\n",
                             "1 2 3 90 0 0 0 90 0 0 0 0 7\n0 0 0 0 0 0 0 0 0 0 0\n")
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:24: frame 0 has 13 values"):
            bvh.read_bvh(write(tmp_path, text))

    def test_missing_motion(self, tmp_path):
        path = write(tmp_path, CHAIN.split("MOTION")[0])
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:\d+: missing MOTION"):
            bvh.read_bvh(path)

    def test_not_a_number(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("1 2 3 90", "1 2 x 90"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:24: frame 0 has 'x', not a number"):
            bvh.read_bvh(path)

    def test_too_few_frame_lines(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("Frames: 2", "Frames: 3"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:\d+: 'Frames: 3' but the file has 2"):
            bvh.read_bvh(path)

    def test_bad_frame_time(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("Frame Time: 0.0083333", "Frame Time: fast"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:23: expected 'Frame Time"):
            bvh.read_bvh(path)

    def test_unknown_channel(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("Zrotation Xrotation Yrotation\n    JOINT",
                                             "Zrotation Xrotation Wrotation\n    JOINT"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:9: unknown channel 'Wrotation'"):
            bvh.read_bvh(path)

    def test_bad_offset(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("OFFSET 0 0 2", "OFFSET 0 0"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:17: OFFSET of the End Site of 'Ankle'"):
            bvh.read_bvh(path)

    def test_unclosed_joint(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("}\nMOTION", "MOTION"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:\d+: unexpected end of HIERARCHY"):
            bvh.read_bvh(path)

    def test_duplicate_joint(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("JOINT Ankle", "JOINT Knee"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:10: duplicate joint name 'Knee'"):
            bvh.read_bvh(path)

    def test_missing_file(self, tmp_path):
        with pytest.raises(ZoopraxisError, match=r"nope\.bvh: cannot read"):
            bvh.read_bvh(tmp_path / "nope.bvh")


# ---------------------------------------------------------------------------------------
# Euler angles and forward kinematics


class TestRotations:
    def test_single_axis_is_right_handed(self):
        # Rz(90) takes +Y to -X.
        np.testing.assert_allclose(one_joint(["Zrotation"], [90]).end_site_position("A"),
                                   [[-1, 0, 0]], atol=1e-12)

    def test_channel_order_zxy(self):
        # Rz(90) @ Rx(90) @ (0, 1, 0) = Rz(90) @ (0, 0, 1) = (0, 0, 1)
        motion = one_joint(["Zrotation", "Xrotation", "Yrotation"], [90, 90, 0])
        np.testing.assert_allclose(motion.end_site_position("A"), [[0, 0, 1]], atol=1e-12)

    def test_channel_order_xzy(self):
        # Rx(90) @ Rz(90) @ (0, 1, 0) = Rx(90) @ (-1, 0, 0) = (-1, 0, 0)
        motion = one_joint(["Xrotation", "Zrotation", "Yrotation"], [90, 90, 0])
        np.testing.assert_allclose(motion.end_site_position("A"), [[-1, 0, 0]], atol=1e-12)

    @pytest.mark.parametrize("order", ["ZXY", "XYZ", "ZYX", "YXZ"])
    def test_intrinsic_matches_scipy(self, rng, order):
        angles = rng.uniform(-180, 180, (7, 3))
        text = (f"HIERARCHY\nROOT A\n{{\nOFFSET 0 0 0\nCHANNELS 3 "
                + " ".join(a + "rotation" for a in order)
                + "\n}\nMOTION\nFrames: 7\nFrame Time: 0.1\n"
                + "\n".join(" ".join(map(repr, row)) for row in angles) + "\n")
        expected = Rotation.from_euler(order, angles, degrees=True).as_matrix()
        np.testing.assert_allclose(bvh.parse_bvh(text).local_rotations()[:, 0], expected,
                                   atol=1e-12)

    def test_joint_without_rotation_channels_is_identity(self):
        motion = one_joint(["Xposition", "Yposition", "Zposition"], [1, 2, 3])
        np.testing.assert_array_equal(motion.local_rotations()[0, 0], np.eye(3))


class TestForwardKinematics:
    def test_chain_by_hand(self):
        motion = bvh.parse_bvh(CHAIN)
        # Frame 0: root at (1, 2, 3) turned Rz(90); the knee turns Rx(90).
        # knee  = (1, 2, 3) + Rz90 (0, 1, 0)             = (0, 2, 3)
        # ankle = knee + Rz90 Rx90 (0, 1, 0) = + (0, 0, 1) = (0, 2, 4)
        # tip   = ankle + Rz90 Rx90 (0, 0, 2) = + (2, 0, 0) = (2, 2, 4)
        np.testing.assert_allclose(motion.positions(0)[0], [[1, 2, 3], [0, 2, 3], [0, 2, 4]],
                                   atol=1e-12)
        np.testing.assert_allclose(motion.end_site_position("Ankle", 0), [[2, 2, 4]], atol=1e-12)
        # Frame 1: rest pose.
        np.testing.assert_allclose(motion.positions(1)[0], [[0, 0, 0], [0, 1, 0], [0, 2, 0]])
        np.testing.assert_allclose(motion.root_positions(), [[1, 2, 3], [0, 0, 0]])

    def test_shapes_and_frame_selection(self, rng):
        motion = random_motion(rng, frames=6)
        assert motion.local_rotations().shape == (6, 3, 3, 3)
        assert motion.global_transforms().shape == (6, 3, 4, 4)
        assert motion.positions(slice(1, 4)).shape == (3, 3, 3)
        assert motion.end_site_position("Ankle", [0, 5]).shape == (2, 3)
        np.testing.assert_allclose(motion.positions([4, 2]), motion.positions()[[4, 2]])
        np.testing.assert_allclose(motion.positions(3), motion.positions()[3:4])

    def test_transforms_are_rigid(self, rng):
        transforms = random_motion(rng).global_transforms()
        rotations = transforms[..., :3, :3]
        np.testing.assert_allclose(rotations @ np.swapaxes(rotations, -1, -2),
                                   np.broadcast_to(np.eye(3), rotations.shape), atol=1e-12)
        np.testing.assert_allclose(np.linalg.det(rotations), 1.0)
        np.testing.assert_array_equal(transforms[..., 3, :], np.broadcast_to([0, 0, 0, 1],
                                                                             transforms.shape[:-1]))

    def test_bone_lengths_constant(self, rng):
        positions = random_motion(rng, frames=20).positions()
        np.testing.assert_allclose(np.linalg.norm(positions[:, 2] - positions[:, 1], axis=-1), 1.0)

    def test_position_channels_add_to_offset(self):
        text = CHAIN.replace("CHANNELS 6 Xposition Yposition Zposition",
                             "CHANNELS 6 Zposition Xposition Yposition")
        np.testing.assert_allclose(bvh.parse_bvh(text).root_positions()[0], [2, 3, 1])

    def test_end_site_of_joint_without_one(self):
        with pytest.raises(ZoopraxisError, match="joint 'Knee' has no End Site"):
            bvh.parse_bvh(CHAIN).end_site_position("Knee")

    def test_unknown_joint(self):
        with pytest.raises(ZoopraxisError, match="<string>: no joint named 'Elbow'"):
            bvh.parse_bvh(CHAIN).joint_index("Elbow")


# ---------------------------------------------------------------------------------------
# World conversion


class TestToWorld:
    def test_y_up_rotates_positions(self, rng):
        motion = random_motion(rng)
        world = motion.to_world(0.5, up="y")
        x, y, z = np.moveaxis(motion.positions(), -1, 0)
        np.testing.assert_allclose(world.positions(), 0.5 * np.stack([x, -z, y], axis=-1),
                                   atol=1e-12)
        x, y, z = motion.end_site_position("Ankle").T
        np.testing.assert_allclose(world.end_site_position("Ankle"),
                                   0.5 * np.stack([x, -z, y], axis=-1), atol=1e-12)

    def test_y_up_conjugates_rotations(self, rng):
        motion = random_motion(rng)
        world_from_file = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])
        expected = world_from_file @ motion.global_transforms()[..., :3, :3] @ world_from_file.T
        np.testing.assert_allclose(motion.to_world(1.0).global_transforms()[..., :3, :3],
                                   expected, atol=1e-12)

    def test_channels_are_relabelled(self):
        world = bvh.parse_bvh(CHAIN).to_world(2.0)
        assert world.channels[0] == ("Xposition", "Zposition", "Yposition",
                                     "Yrotation", "Xrotation", "Zrotation")
        np.testing.assert_allclose(world.data[0, :4], [2, 4, -6, -90])
        np.testing.assert_allclose(world.offsets[1], [0, 0, 2])
        assert world.space == "world"

    def test_z_up_only_scales(self, rng):
        motion = random_motion(rng)
        np.testing.assert_allclose(motion.to_world(3.0, up="z").positions(),
                                   3.0 * motion.positions(), atol=1e-12)

    def test_once_only(self):
        world = bvh.parse_bvh(CHAIN).to_world(1.0)
        with pytest.raises(ZoopraxisError, match="already in world space"):
            world.to_world(1.0)

    def test_bad_up_axis(self):
        with pytest.raises(ZoopraxisError, match="unsupported up axis 'x'"):
            bvh.parse_bvh(CHAIN).to_world(1.0, up="x")


# ---------------------------------------------------------------------------------------
# Resampling


def spinning_motion(fps, seconds):
    """One joint turning at a constant rate about a tilted axis, Euler ZXY channels."""
    times = np.arange(int(round(seconds * fps)) + 1) / fps
    axis = np.array([0.3, 1.0, -0.5]) / np.linalg.norm([0.3, 1.0, -0.5])
    rotations = Rotation.from_rotvec(np.outer(times * 4.0, axis))  # 4 rad/s: Euler wraps
    angles = np.unwrap(rotations.as_euler("ZXY", degrees=True), period=360, axis=0)
    data = np.hstack([np.outer(times, [1.0, -2.0, 0.5]), angles])
    motion = bvh.Motion(["A"], [-1], [[0, 0, 0]],
                        [("Xposition", "Yposition", "Zposition",
                          "Zrotation", "Xrotation", "Yrotation")],
                        {"A": [0, 1, 0]}, 1.0 / fps, data)
    return motion, axis


class TestResample:
    def test_integer_ratio_takes_every_kth_frame(self, rng):
        motion = random_motion(rng, frames=10)
        slow = motion.resampled(40)
        assert slow.num_frames == 4 and slow.fps == 40.0
        np.testing.assert_array_equal(slow.data, motion.data[::3])

    def test_fractional_ratio_slerps(self):
        motion, axis = spinning_motion(120, 1.0)
        out = motion.resampled(50)
        assert out.num_frames == 51 and out.fps == 50.0
        times = np.arange(51) / 50
        truth = Rotation.from_rotvec(np.outer(times * 4.0, axis)).as_matrix()
        np.testing.assert_allclose(out.local_rotations()[:, 0], truth, atol=1e-9)
        np.testing.assert_allclose(out.root_positions(), np.outer(times, [1.0, -2.0, 0.5]),
                                   atol=1e-12)

    def test_fractional_ratio_keeps_euler_continuous(self):
        motion, _ = spinning_motion(120, 2.0)
        angles = motion.resampled(50).data[:, 3:]
        # 4 rad/s at 50 fps turns 4.6 degrees a frame; a 360 jump would show.
        assert np.abs(np.diff(angles, axis=0)).max() < 20.0

    def test_bad_rate(self):
        with pytest.raises(ZoopraxisError, match="cannot resample to 0 fps"):
            bvh.parse_bvh(CHAIN).resampled(0)


# ---------------------------------------------------------------------------------------
# Standard joints on a tiny skeleton


class TestStandardJointsErrors:
    def test_requires_world_space(self):
        with pytest.raises(ZoopraxisError, match="convert the motion with to_world"):
            bvh.standard_joints(bvh.parse_bvh(CHAIN))

    def test_wrong_skeleton(self):
        with pytest.raises(ZoopraxisError, match="<string>: not a 'cmu' skeleton"):
            bvh.standard_joints(bvh.parse_bvh(CHAIN).to_world(1.0))

    def test_unknown_skeleton(self):
        with pytest.raises(ZoopraxisError, match="unknown skeleton 'h36m'"):
            bvh.standard_joints(bvh.parse_bvh(CHAIN).to_world(1.0), skeleton="h36m")

    def test_rules_cover_all_standard_joints(self):
        for rules in bvh.SKELETONS.values():
            assert set(rules) == set(STANDARD_JOINTS)


# ---------------------------------------------------------------------------------------
# The CMU captures


# Parsed once per test session: the fixtures below only look the results up.
@functools.lru_cache(maxsize=None)
def _load(path, fps=None):
    return bvh.load_cmu(path, fps)


@functools.lru_cache(maxsize=None)
def _standard_joints(path, fps=None):
    return bvh.standard_joints(_load(path, fps))


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
        assert bvh.standard_joints(playground, frames=slice(0, 3)).shape == (3, 17, 3)


class TestCmuGeometry:
    def test_height(self, walk, walk_joints, playground):
        # Stature to the head's End Site above the floor (lowest toe of the take).
        for motion, joints, low, high in ((walk, walk_joints, 1.3, 1.6),
                                          (playground, None, 1.5, 2.0)):
            if joints is None:
                joints = bvh.standard_joints(motion, frames=slice(0, None, 10))
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
        for joints in (walk_joints, bvh.standard_joints(playground, frames=slice(0, None, 10))):
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
        frames = bvh.standard_joint_frames(walk)
        np.testing.assert_allclose(frames[..., :3, 3], walk_joints, atol=1e-12)
        rotations = frames[..., :3, :3]
        np.testing.assert_allclose(np.linalg.det(rotations), 1.0)
        # Each bone's far joint is fixed in the frame of the bone.
        for start, end in (("l_hip", "l_knee"), ("r_shoulder", "r_elbow"), ("l_knee", "l_ankle")):
            world_from_bone = frames[:, J(start)]
            local = np.einsum("fba,fb->fa", world_from_bone[:, :3, :3],
                              walk_joints[:, J(end)] - world_from_bone[:, :3, 3])
            assert np.abs(local - local[0]).max() < 1e-9


# ---------------------------------------------------------------------------------------
# Takes of every CMU convention (cmu_more), ASF/AMC, manifests, malformed input


# A two-bone leg with a tilted local frame (axis) on the thigh and one dof on the shank.
ASF = """\
:version 1.10
:units
  mass 1.0
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name thigh
     direction 0 -1 0
     length 2
     axis 0 0 30 XYZ
    dof rx ry rz
    limits (-160.0 20.0)
           (-70.0 70.0)
           (-60.0 70.0)
  end
  begin
     id 2
     name shank
     direction 0.6 -0.8 0
     length 1
     axis 10 0 0 XYZ
    dof rx
  end
:hierarchy
  begin
    root thigh
    thigh shank
  end
"""

AMC = """\
#!OML:ASF leg.asf
:FULLY-SPECIFIED
:DEGREES
1
root 1 2 3 10 20 30
thigh 40 -15 25
shank 35
2
root 0 0 0 0 0 0
thigh 0 0 0
shank 0
"""


def acclaim_reference(root, thigh, shank):
    """The leg's knee and foot by the Acclaim rules written out directly: a bone's end is
    where it starts plus its length along ``world_from_bone C M C^-1 direction``."""
    def fixed(angles, order="xyz"):
        return Rotation.from_euler(order, angles, degrees=True).as_matrix()

    world_from_root = fixed(root[3:])
    C1, C2 = fixed([0, 0, 30]), fixed([10, 0, 0])
    world_from_thigh = world_from_root @ C1 @ fixed(thigh) @ C1.T
    world_from_shank = world_from_thigh @ C2 @ fixed([shank], "x") @ C2.T
    hip = np.array(root[:3], float)
    knee = hip + 2 * world_from_thigh @ [0, -1, 0]
    foot = knee + 1 * world_from_shank @ [0.6, -0.8, 0]
    return hip, knee, foot


def leg_files(tmp_path, asf=ASF, amc=AMC):
    (tmp_path / "leg.asf").write_text(asf)
    (tmp_path / "leg_01.amc").write_text(amc)
    return tmp_path / "leg_01.amc"


class TestAcclaim:
    def test_forward_kinematics_match_the_acclaim_rules(self, tmp_path):
        from zoopraxis.core.files import amc

        motion = amc.read_amc(leg_files(tmp_path))
        assert motion.names == ["hip", "thigh", "shank"]
        assert motion.fps == 120.0 and motion.num_frames == 2
        positions = motion.positions()
        for frame, values in enumerate((([1, 2, 3, 10, 20, 30], [40, -15, 25], 35),
                                        ([0] * 6, [0, 0, 0], 0))):
            hip, knee, foot = acclaim_reference(*values)
            np.testing.assert_allclose(positions[frame, 1], hip, atol=1e-9)
            np.testing.assert_allclose(positions[frame, 2], knee, atol=1e-9)
            np.testing.assert_allclose(motion.end_site_position("shank", frame)[0], foot,
                                       atol=1e-9)

    def test_radians(self, tmp_path):
        from zoopraxis.core.files import amc

        degrees = amc.read_amc(leg_files(tmp_path)).positions()
        radian_amc = AMC.replace("thigh 40 -15 25", "thigh " + " ".join(
            repr(float(np.radians(v))) for v in (40, -15, 25))).replace(
            "shank 35", f"shank {np.radians(35)!r}").replace(
            "root 1 2 3 10 20 30", "root 1 2 3 " + " ".join(
                repr(float(np.radians(v))) for v in (10, 20, 30)))
        radian_asf = ASF.replace("angle deg", "angle rad").replace(
            "axis 0 0 30 XYZ", f"axis 0 0 {np.radians(30)!r} XYZ").replace(
            "axis 10 0 0 XYZ", f"axis {np.radians(10)!r} 0 0 XYZ")
        radians = amc.read_amc(leg_files(tmp_path, radian_asf, radian_amc)).positions()
        np.testing.assert_allclose(radians, degrees, atol=1e-9)

    @pytest.mark.parametrize("file, change, message", [
        ("amc", ("shank 35", "shank 35 1"), r"leg_01\.amc:7: bone shank has 2 values"),
        ("amc", ("thigh 40", "knee 40"), r"leg_01\.amc:6: no bone named 'knee'"),
        ("amc", ("shank 35", "shank nan"), r"leg_01\.amc:7: bone shank: 'nan' are not finite"),
        ("amc", ("1\nroot 1", "root 1"), r"leg_01\.amc:\d+: 'root' before the first frame"),
        ("asf", ("length 2", "length two"), r"leg\.asf:\d+: length: 'two' are not finite"),
        ("asf", ("axis 10 0 0 XYZ", "axis 10 0 0 XYY"), r"leg\.asf:\d+: axis order 'XYY'"),
        ("asf", ("thigh shank\n", "thigh foot\n"),
         r"leg\.asf:\d+: hierarchy names unknown bone 'foot'"),
        ("asf", ("    dof rx\n", "    dof tx\n"),
         r"leg\.asf:\d+: bone shank: unsupported dof 'tx'"),
    ])
    def test_bad_file(self, tmp_path, file, change, message):
        from zoopraxis.core.files import amc

        texts = {"asf": ASF, "amc": AMC}
        texts[file] = texts[file].replace(*change)
        with pytest.raises(ZoopraxisError, match=message):
            amc.read_amc(leg_files(tmp_path, **texts))

    def test_missing_skeleton(self, tmp_path):
        from zoopraxis.core.files import amc

        (tmp_path / "leg_01.amc").write_text(AMC)
        with pytest.raises(ZoopraxisError, match=r"leg_01\.amc: no skeleton file leg\.asf"):
            amc.read_amc(tmp_path / "leg_01.amc")


MANIFEST_HEAD = "file\tcmu_subject_trial\tframe_rate\tframe_count\n"


class TestManifest:
    def test_rates_and_reference_frames(self, tmp_path):
        path = tmp_path / "MANIFEST.tsv"
        path.write_text(MANIFEST_HEAD
                        + "bvh_daz/60_05.bvh\t60_05\theader 120.00 fps; CMU capture 60 fps "
                          "(HEADER WRONG: use 60 fps)\t1679 (incl. T-pose frame 0)\n"
                        + "asf_amc/35_01.amc\t35_01\t120 fps (CMU capture rate)\t358\n")
        takes = bvh.read_manifest(path)
        assert takes == {"60_05": bvh.TakeInfo(60.0, True), "35_01": bvh.TakeInfo(120.0, False)}

    def test_row_without_rate(self, tmp_path):
        path = tmp_path / "MANIFEST.tsv"
        path.write_text(MANIFEST_HEAD + "a/01_01.bvh\t01_01\tfast\t10\n")
        with pytest.raises(ZoopraxisError, match=r"MANIFEST\.tsv:2: no frame rate in 'fast'"):
            bvh.read_manifest(path)

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
            bvh.read_take(folder / "07_01.bvh")
        renamed = text.replace("Hips", "hip").replace("Knee", "lfemur").replace("Ankle", "ltibia")
        (folder / "07_01.bvh").write_text(renamed)
        with pytest.raises(ZoopraxisError, match=r"no joint 'head' and \d+ more; closest: cmu_asf"):
            bvh.read_take(folder / "07_01.bvh")


# Three takes of each convention of the shared data (cmu_more/SOURCE.md).
TAKES = [("bvh_mb/02_01.bvh", "cmu_cgspeed", 120.0, 343),
         ("bvh_mb/09_01.bvh", "cmu_cgspeed", 120.0, 148),
         ("bvh_daz/12_01.bvh", "cmu_daz", 120.0, 523),
         ("bvh_daz/60_10.bvh", "cmu_daz", 60.0, 1197),       # header says 120
         ("bvh_asfnames/16_01.bvh", "cmu_asf", 120.0, 322),   # header says 30; no T-pose
         ("asf_amc/35_01.amc", "cmu_asf", 120.0, 358)]


@functools.lru_cache(maxsize=None)
def _take(path):
    take = bvh.read_take(path)
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


class TestFuzz:
    """Malformed files of every kind end in one ZoopraxisError naming the file."""

    def check(self, read, path):
        try:
            read(path)
        except ZoopraxisError as error:
            assert path.name in str(error) and "\n" not in str(error)

    def test_bvh(self, tmp_path, rng):
        path = tmp_path / "fuzz.bvh"
        text = CHAIN.encode()
        for trial in range(300):
            data = bytearray(text)
            kind = trial % 4
            if kind == 0:                                   # truncated
                data = data[:rng.integers(len(data))]
            elif kind == 1:                                 # random bytes over a stretch
                start = rng.integers(len(data))
                data[start:start + 8] = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
            elif kind == 2:                                 # a number made non-finite
                tokens = text.decode().split(" ")
                k = rng.integers(len(tokens))
                tokens[k] = rng.choice(["nan", "inf", "-inf", "1e999"])
                data = bytearray(" ".join(tokens).encode())
            else:                                           # nothing but noise
                data = rng.integers(0, 256, rng.integers(1, 400), dtype=np.uint8).tobytes()
            path.write_bytes(bytes(data))
            self.check(bvh.read_bvh, path)

    def test_asf_amc(self, tmp_path, rng):
        from zoopraxis.core.files import amc

        for trial in range(200):
            asf, motion = bytearray(ASF.encode()), bytearray(AMC.encode())
            target = asf if trial % 2 else motion
            if trial % 3 == 0:
                del target[rng.integers(len(target)):]
            else:
                start = rng.integers(len(target))
                target[start:start + 6] = rng.integers(0, 256, 6, dtype=np.uint8).tobytes()
            (tmp_path / "leg.asf").write_bytes(bytes(asf))
            (tmp_path / "leg_01.amc").write_bytes(bytes(motion))
            try:
                amc.read_amc(tmp_path / "leg_01.amc")
            except ZoopraxisError as error:
                assert ("leg_01.amc" in str(error) or "leg.asf" in str(error)) \
                    and "\n" not in str(error)

    def test_non_finite_value_named(self, tmp_path):
        path = write(tmp_path, CHAIN.replace("1 2 3 90", "1 2 inf 90"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:24: frame 0 has 'inf', not a finite"):
            bvh.read_bvh(path)
        path = write(tmp_path, CHAIN.replace("OFFSET 0 0 2", "OFFSET 0 nan 2"))
        with pytest.raises(ZoopraxisError, match=r"bad\.bvh:16: .*'nan' is not a finite"):
            bvh.read_bvh(path)


def test_capture_paths_hold_subjects_out(tmp_path):
    for name in ("a/02_01.bvh", "a/02_02.bvh", "b/35_01.amc", "b/35.asf", "b/notes.txt",
                 "131_01.bvh"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("")
    stems = [p.stem for p in bvh.capture_paths(tmp_path)]
    assert sorted(stems) == ["02_01", "02_02", "131_01", "35_01"]
    assert [p.stem for p in bvh.capture_paths(tmp_path, hold_out=["02", "131"])] == ["35_01"]
    assert bvh.subject_of("135_04") == "135"
    with pytest.raises(ZoopraxisError, match="nowhere: no such folder"):
        bvh.capture_paths(tmp_path / "nowhere")
