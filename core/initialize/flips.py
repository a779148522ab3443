"""What one view leaves ambiguous, and what the animator may turn: the limbs whose depth can
flip, the body parts named in reports, the left-right click pairs that may be exchanged, and the
check of the depth flips asked for (:func:`check_flips`)."""

from ..errors import ZoopraxisError
from .problem import CLICK_SIGMA_PX

# Pairs whose clicks may be exchanged by mistake (subject's left and right).
LR_PAIRS = tuple((f"l_{j}", f"r_{j}") for j in
                 ("shoulder", "elbow", "wrist", "hip", "knee", "ankle", "toe"))

# Limb parts whose depth can flip in one view: (pivot joint, joints beyond it).
LIMB_FLIPS = tuple((f"{s}_{a}", tuple(f"{s}_{j}" for j in rest)) for s in ("l", "r")
                   for a, *rest in (("shoulder", "elbow", "wrist"), ("elbow", "wrist"),
                                    ("hip", "knee", "ankle", "toe"), ("knee", "ankle", "toe")))

# Limbs whose two parts can each flip in depth: (pivot, middle joint, joints beyond the pivot,
# joints beyond the middle, DOF name prefixes of the limb).
_FLIP_LIMBS = tuple(
    (f"{s}_{a}", f"{s}_{b}", tuple(f"{s}_{j}" for j in (b,) + rest),
     tuple(f"{s}_{j}" for j in rest), tuple(f"{s}_{d}_" for d in dofs))
    for s in ("l", "r")
    for a, b, rest, dofs in (("shoulder", "elbow", ("wrist",), ("shoulder", "elbow")),
                             ("hip", "knee", ("ankle", "toe"), ("hip", "knee", "ankle"))))

# Parts of the body named in reports, by the joints that move with them.
BODY_PARTS = {"the trunk": ("neck", "l_shoulder", "r_shoulder", "l_hip", "r_hip"),
              "the head": ("head",),
              "the left arm": ("l_elbow", "l_wrist"), "the right arm": ("r_elbow", "r_wrist"),
              "the left leg": ("l_knee", "l_ankle", "l_toe"),
              "the right leg": ("r_knee", "r_ankle", "r_toe")}

# What an animator may turn to its other depth in a frame clicked in one view: a limb (its best
# other depth configuration) or the whole body (its mirror image in depth).
FLIP_PARTS = ("left arm", "right arm", "left leg", "right leg", "body")

# An alternative pose whose cost is within this many px^2 of the best one fits as well: under
# clicks of CLICK_SIGMA_PX it is at most e times less likely.
AMBIGUOUS_COST = CLICK_SIGMA_PX ** 2
_AMBIGUOUS_M = 0.10     # ... and it is a different pose if some joint moves this far
# A limb whose mirror image moves no joint more than this is not worth trying mirrored.
_MIN_FLIP_M = 0.05
_EXPLORE_NFEV = 30         # evaluations of a short fit that ranks a mirrored limb


def flip_part(name):
    """A body part's name as ``FLIP_PARTS`` spell it ("the Left-Leg" -> "left leg"), or None."""
    text = " ".join(str(name).lower().replace("-", " ").replace("_", " ").split())
    if text.startswith("the "):
        text = text[4:]
    if text in ("whole body", "all"):
        text = "body"
    return text if text in FLIP_PARTS else None


def check_flips(flips, frames):
    """Flips as ``{frame: [part, ...]}`` with the parts' names checked.

    Raises
    ------
    ZoopraxisError
        An unknown part or a frame that is not an anchor frame.
    """
    out = {}
    for frame, parts in (flips or {}).items():
        if int(frame) not in frames:
            raise ZoopraxisError(f"depth flip: frame {frame} is not an anchor frame (anchors: "
                                 f"{', '.join(str(f) for f in frames) or 'none'})")
        for part in ([parts] if isinstance(parts, str) else parts):
            name = flip_part(part)
            if name is None:
                raise ZoopraxisError(f"depth flip at frame {frame}: unknown body part '{part}' "
                                     f"(one of: {', '.join(FLIP_PARTS)})")
            if name not in out.setdefault(int(frame), []):
                out[int(frame)].append(name)
    return out
