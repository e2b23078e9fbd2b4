"""The canonical skeleton every character shares (DESIGN §3).

One topology for all characters, so per-tick work runs on arrays holding every character.
Joint positions are always ordered as :data:`JOINTS`; segment lengths as :data:`LENGTHS`.

Body axes used throughout (a character's own frame): ``x`` forward, ``y`` to the character's
left, ``z`` up (right-handed, matching the Z-up world of DESIGN §2).
"""

from __future__ import annotations

from typing import Final

#: Canonical joints, in topological order (a parent always comes before its children).
#: ``hand_*`` is the end of the hand (knuckles), ``head_top`` the top of the skull, ``toe_*`` the
#: ball of the foot; ``neck`` is the base of the neck (top of the spine), ``head`` the skull base.
JOINTS: Final[tuple[str, ...]] = (
    "pelvis",
    "hip_l", "knee_l", "ankle_l", "toe_l",
    "hip_r", "knee_r", "ankle_r", "toe_r",
    "spine_1", "spine_2", "neck", "head", "head_top",
    "shoulder_l", "elbow_l", "wrist_l", "hand_l",
    "shoulder_r", "elbow_r", "wrist_r", "hand_r",
)
JOINT_INDEX: Final[dict[str, int]] = {name: i for i, name in enumerate(JOINTS)}
N_JOINTS: Final[int] = len(JOINTS)

_PARENT_NAMES: Final[dict[str, str | None]] = {
    "pelvis": None,
    "hip_l": "pelvis", "knee_l": "hip_l", "ankle_l": "knee_l", "toe_l": "ankle_l",
    "hip_r": "pelvis", "knee_r": "hip_r", "ankle_r": "knee_r", "toe_r": "ankle_r",
    "spine_1": "pelvis", "spine_2": "spine_1", "neck": "spine_2", "head": "neck",
    "head_top": "head",
    "shoulder_l": "neck", "elbow_l": "shoulder_l", "wrist_l": "elbow_l", "hand_l": "wrist_l",
    "shoulder_r": "neck", "elbow_r": "shoulder_r", "wrist_r": "elbow_r", "hand_r": "wrist_r",
}
#: Parent index per joint, -1 for the root. Shape (N_JOINTS,).
PARENTS: Final[tuple[int, ...]] = tuple(
    -1 if (parent := _PARENT_NAMES[j]) is None else JOINT_INDEX[parent]
    for j in JOINTS
)

#: Segment lengths of a morphology, in metres, in this order. Each bone is named by the pair of
#: joints it joins; ``ankle_height_*`` is the ankle's height above a flat ground under a flat foot.
LENGTH_BONES: Final[dict[str, tuple[str, str] | None]] = {
    "pelvis_l": ("pelvis", "hip_l"),
    "pelvis_r": ("pelvis", "hip_r"),
    "thigh_l": ("hip_l", "knee_l"),
    "thigh_r": ("hip_r", "knee_r"),
    "shank_l": ("knee_l", "ankle_l"),
    "shank_r": ("knee_r", "ankle_r"),
    "foot_l": ("ankle_l", "toe_l"),
    "foot_r": ("ankle_r", "toe_r"),
    "ankle_height_l": None,
    "ankle_height_r": None,
    "spine_lower": ("pelvis", "spine_1"),
    "spine_middle": ("spine_1", "spine_2"),
    "spine_upper": ("spine_2", "neck"),
    "neck": ("neck", "head"),
    "head": ("head", "head_top"),
    "clavicle_l": ("neck", "shoulder_l"),
    "clavicle_r": ("neck", "shoulder_r"),
    "upper_arm_l": ("shoulder_l", "elbow_l"),
    "upper_arm_r": ("shoulder_r", "elbow_r"),
    "forearm_l": ("elbow_l", "wrist_l"),
    "forearm_r": ("elbow_r", "wrist_r"),
    "hand_l": ("wrist_l", "hand_l"),
    "hand_r": ("wrist_r", "hand_r"),
}
LENGTHS: Final[tuple[str, ...]] = tuple(LENGTH_BONES)
LENGTH_INDEX: Final[dict[str, int]] = {name: i for i, name in enumerate(LENGTHS)}
N_LENGTHS: Final[int] = len(LENGTHS)

#: Index pairs (proximal joint, distal joint) for each length that is a bone; -1 for the others.
BONE_JOINTS: Final[tuple[tuple[int, int], ...]] = tuple(
    (-1, -1) if pair is None else (JOINT_INDEX[pair[0]], JOINT_INDEX[pair[1]])
    for pair in LENGTH_BONES.values()
)

SIDES: Final[tuple[str, str]] = ("l", "r")

#: Pelvis origin -> left hip joint in the pelvis frame at rest: 30 degrees below the side axis,
#: so the hips sit half a pelvis length below the pelvis origin (mirror y for the right hip).
#: Used by the rest pose of exported BVH, by authored motions and by ``Morphology.stature``.
REST_HIP_DIR_LEFT: Final[tuple[float, float, float]] = (0.0, 0.8660254037844386, -0.5)


def joint(name: str) -> int:
    """Index of a canonical joint, with a clear error for an unknown name."""
    try:
        return JOINT_INDEX[name]
    except KeyError:
        raise KeyError(f"unknown joint {name!r}; canonical joints are: {', '.join(JOINTS)}") from None


def length(name: str) -> int:
    """Index of a morphology length, with a clear error for an unknown name."""
    try:
        return LENGTH_INDEX[name]
    except KeyError:
        raise KeyError(f"unknown segment {name!r}; segments are: {', '.join(LENGTHS)}") from None
