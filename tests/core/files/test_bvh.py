"""BVH reading, forward kinematics, world conversion and resampling; the standard joints on a
small skeleton, ASF/AMC and malformed takes (the CMU captures themselves are in test_cmu)."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from zoopraxis.core.files import bvh
from zoopraxis.core.files import cmu
from zoopraxis.core.errors import ZoopraxisError
from zoopraxis.core.body.joints import STANDARD_JOINTS

# A root with 6 channels, a child with ZXY and a grandchild with XYZ channels (chain.bvh).
CHAIN = (Path(__file__).parent / "chain.bvh").read_text()


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
            cmu.standard_joints(bvh.parse_bvh(CHAIN))

    def test_wrong_skeleton(self):
        with pytest.raises(ZoopraxisError, match="<string>: not a 'cmu' skeleton"):
            cmu.standard_joints(bvh.parse_bvh(CHAIN).to_world(1.0))

    def test_unknown_skeleton(self):
        with pytest.raises(ZoopraxisError, match="unknown skeleton 'h36m'"):
            cmu.standard_joints(bvh.parse_bvh(CHAIN).to_world(1.0), skeleton="h36m")

    def test_rules_cover_all_standard_joints(self):
        for rules in cmu.SKELETONS.values():
            assert set(rules) == set(STANDARD_JOINTS)


# ---------------------------------------------------------------------------------------
# The CMU captures


# Parsed once per test session: the fixtures below only look the results up.


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


# Three takes of each convention of the shared data (cmu_more/SOURCE.md).


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
