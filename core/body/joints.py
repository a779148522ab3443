"""The 17 standard joints of the design contract, and their left/right pairing.

Left and right are the subject's own. ``pelvis`` is the mid-point of the two hip joint
centres, ``head`` the centre of the head, ``toe`` the ball of the foot.
"""

STANDARD_JOINTS = (
    "pelvis", "neck", "head",
    "l_shoulder", "l_elbow", "l_wrist",
    "r_shoulder", "r_elbow", "r_wrist",
    "l_hip", "l_knee", "l_ankle", "l_toe",
    "r_hip", "r_knee", "r_ankle", "r_toe",
)

JOINT_INDEX = {name: i for i, name in enumerate(STANDARD_JOINTS)}

# Bones of the stick figure, as pairs of standard joint names (used for drawing and for
# the initial marker layout).
STICK_BONES = (
    ("pelvis", "neck"), ("neck", "head"),
    ("neck", "l_shoulder"), ("l_shoulder", "l_elbow"), ("l_elbow", "l_wrist"),
    ("neck", "r_shoulder"), ("r_shoulder", "r_elbow"), ("r_elbow", "r_wrist"),
    ("pelvis", "l_hip"), ("l_hip", "l_knee"), ("l_knee", "l_ankle"), ("l_ankle", "l_toe"),
    ("pelvis", "r_hip"), ("r_hip", "r_knee"), ("r_knee", "r_ankle"), ("r_ankle", "r_toe"),
)


def mirror_name(name):
    """Return the name of the joint on the other side (``l_knee`` <-> ``r_knee``)."""
    if name.startswith("l_"):
        return "r_" + name[2:]
    if name.startswith("r_"):
        return "l_" + name[2:]
    return name


# Index permutation that swaps left and right joints.
MIRROR_PERMUTATION = tuple(JOINT_INDEX[mirror_name(n)] for n in STANDARD_JOINTS)

