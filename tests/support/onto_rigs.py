"""Rigs of each convention for the ``export --onto`` tests, written as a BVH or a skinned GLB.

Names and structure follow each convention's public documentation and tools (the source is named
at each one); the bones are laid out on one body: the shipped walk's own proportions scaled to
another stature, so that the rig's pelvis, spine and clavicle bases sit where the walk's do (its
hips along the walk's hip directions, its clavicles leaving the neck base). Extra bones sit where
they do on such rigs: twist bones on the bone they twist (Rigify's ``.001`` halves, Daz's
``*Twist``) or as leaves off it (Unreal's ``*_twist_01_l``), helpers and props as leaves,
fingers off the hand, a root at the floor. Each rig is made in a T pose (arms level) and an A pose
(arms 45 degrees down).

The files are written here, from positions, by this module's own small writers: a BVH's rest pose
is its OFFSETs; a GLB's nodes get Blender-like bone axes (each joint's Y along its bone, a turned
roll), under an ``Armature`` node turning Z up to Y up and scaling centimetres to metres, with
a mesh of one small triangle per joint skinned to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pygltflib as gl

#: One joint: (name, parent or None, place). A place is a body point (below) or
#: ``(a, b, t)``: the point a fraction t from body point a to b, or ``(a, (dx, dy, dz))``: an
#: offset (metres, body axes: forward, left, up) from body point a.
Joint = tuple


@dataclass
class Convention:
    name: str
    source: str
    joints: list[Joint]
    order: str = "ZXY"
    #: File axes: "y" (Y up, facing +Z, left +X, as BVH and glTF) or "z" (Unreal's Z up, X forward).
    up: str = "y"
    #: Metres per file unit.
    unit: float = 0.01


def _mirror(joints: list[Joint], left: str, right: str) -> list[Joint]:
    """``joints`` and their mirror images (names with ``left`` -> ``right``, or a leading
    ``left`` when it is a single letter as Daz's ``lShin``; body points ``_l`` -> ``_r``,
    offsets' left component negated)."""

    def name(n):
        if n is None:
            return None
        if len(left) == 1:
            return right + n[1:] if n.startswith(left) else n
        return n.replace(left, right)

    def place(p):
        if isinstance(p, str):
            return p[:-2] + "_r" if p.endswith("_l") else p
        if len(p) == 3:
            return (place(p[0]), place(p[1]), p[2])
        return (place(p[0]), (p[1][0], -p[1][1], p[1][2]))

    return joints + [(name(n), name(parent), place(p)) for n, parent, p in joints]


def _leg_arm(names: dict[str, str], extra: list[Joint] | None = None) -> list[Joint]:
    """A left leg and arm from ``names`` of hip, knee, ankle, toe, collar, shoulder, elbow,
    wrist, hand and their parents ``pelvis`` and ``chest`` (a joint at the neck base's place
    carries the collar)."""
    n = names
    return [(n["hip"], n["pelvis"], "hip_l"), (n["knee"], n["hip"], "knee_l"),
            (n["ankle"], n["knee"], "ankle_l"), (n["toe"], n["ankle"], "toe_l"),
            (n["collar"], n["chest"], "neck"), (n["shoulder"], n["collar"], "shoulder_l"),
            (n["elbow"], n["shoulder"], "elbow_l"), (n["wrist"], n["elbow"], "wrist_l")] \
        + (extra or [])


CONVENTIONS: list[Convention] = []

# --- Blender Rigify deform bones (Rigify's human metarig generated: DEF-spine (hips),
# DEF-spine.001-.003, .004 (neck), .005, .006 (head); DEF-shoulder.L, DEF-upper_arm.L and its
# .001 twist half, DEF-forearm.L(.001), DEF-hand.L, DEF-f_middle.01-.03.L, DEF-thumb.01-.03.L;
# DEF-pelvis.L, DEF-thigh.L(.001), DEF-shin.L(.001), DEF-foot.L, DEF-toe.L; a root bone at the floor.
CONVENTIONS.append(Convention("rigify", "Rigify metarig DEF- bones (find_string 'DEF-upper_arm.L')", [
    ("root", None, ("pelvis", (0.0, 0.0, -1.0))),
    ("DEF-spine", "root", "pelvis"), ("DEF-spine.001", "DEF-spine", "spine_1"),
    ("DEF-spine.002", "DEF-spine.001", ("spine_1", "spine_2", 0.5)),
    ("DEF-spine.003", "DEF-spine.002", "spine_2"), ("DEF-spine.004", "DEF-spine.003", "neck"),
    ("DEF-spine.005", "DEF-spine.004", ("neck", "head", 0.5)),
    ("DEF-spine.006", "DEF-spine.005", "head"), ("DEF-spine.006.tip", "DEF-spine.006", "head_top"),
] + _mirror(_leg_arm({"pelvis": "DEF-spine", "chest": "DEF-spine.003", "hip": "DEF-thigh.L",
                      "knee": "DEF-shin.L", "ankle": "DEF-foot.L", "toe": "DEF-toe.L",
                      "collar": "DEF-shoulder.L", "shoulder": "DEF-upper_arm.L",
                      "elbow": "DEF-forearm.L", "wrist": "DEF-hand.L"}, [
    ("DEF-pelvis.L", "DEF-spine", ("pelvis", (0.05, 0.05, 0.02))),
    ("DEF-thigh.L.001", "DEF-thigh.L", ("hip_l", "knee_l", 0.5)),
    ("DEF-shin.L.001", "DEF-shin.L", ("knee_l", "ankle_l", 0.5)),
    ("DEF-upper_arm.L.001", "DEF-upper_arm.L", ("shoulder_l", "elbow_l", 0.5)),
    ("DEF-forearm.L.001", "DEF-forearm.L", ("elbow_l", "wrist_l", 0.5)),
    ("DEF-f_middle.01.L", "DEF-hand.L", "hand_l"),
    ("DEF-f_middle.02.L", "DEF-f_middle.01.L", ("hand_l", (0.0, 0.0, 0.0))),
    ("DEF-thumb.01.L", "DEF-hand.L", ("wrist_l", (0.03, 0.02, 0.0))),
    ("DEF-thumb.02.L", "DEF-thumb.01.L", ("wrist_l", (0.06, 0.03, 0.0)))]), ".L", ".R"),
    order="XYZ"))

# Rigify's twist halves sit in the chain: DEF-thigh.L > DEF-thigh.L.001 > DEF-shin.L > ...
_halves = {f"DEF-{b}.{s}": f"DEF-{a}.{s}.001" for a, b in (
    ("thigh", "shin"), ("shin", "foot"), ("upper_arm", "forearm"), ("forearm", "hand"))
    for s in "LR"}
CONVENTIONS[-1].joints = [(n, _halves.get(n, p), place) for n, p, place in CONVENTIONS[-1].joints]

# --- MotionBuilder HumanIK (the HumanIK BVH template: Character1_Reference at the floor >
# Character1_Hips > Spine > Spine1 > Spine2 > Neck > Head; Spine2 > *Shoulder > *Arm > *ForeArm
# > *Hand > *HandMiddle1-3; Hips > *UpLeg > *Leg > *Foot > *ToeBase; and its *_RIGMESH helper
# leaves, one at the neck).
CONVENTIONS.append(Convention("humanik", "HumanIK BVH template (find_string 'Character1_LeftUpLeg')", [
    ("Character1_Reference", None, ("pelvis", (0.0, 0.0, -1.0))),
    ("Character1_Hips", "Character1_Reference", "pelvis"),
    ("Character1_Spine", "Character1_Hips", "spine_1"),
    ("Character1_Spine1", "Character1_Spine", ("spine_1", "spine_2", 0.5)),
    ("Character1_Spine2", "Character1_Spine1", "spine_2"),
    ("Character1_Neck", "Character1_Spine2", "neck"),
    ("Character1_Head", "Character1_Neck", "head"), ("Character1_Head.tip", "Character1_Head", "head_top"),
    ("Neck_RIGMESH", "Character1_Neck", ("neck", (0.1, 0.0, 0.0))),
    ("Pelvis_RIGMESH", "Character1_Hips", ("pelvis", (0.1, 0.0, 0.0))),
] + _mirror(_leg_arm({"pelvis": "Character1_Hips", "chest": "Character1_Spine2",
                      "hip": "Character1_LeftUpLeg", "knee": "Character1_LeftLeg",
                      "ankle": "Character1_LeftFoot", "toe": "Character1_LeftToeBase",
                      "collar": "Character1_LeftShoulder", "shoulder": "Character1_LeftArm",
                      "elbow": "Character1_LeftForeArm", "wrist": "Character1_LeftHand"}, [
    ("Character1_LeftHandMiddle1", "Character1_LeftHand", "hand_l"),
    ("Character1_LeftHandMiddle2", "Character1_LeftHandMiddle1", ("hand_l", (0.0, 0.0, -0.02))),
    ("L_Humerus_RIGMESH", "Character1_LeftArm", ("shoulder_l", (0.0, 0.0, 0.1)))]),
    "Left", "Right")))
# HumanIK's helpers are L_/R_: rename the mirrored one.
CONVENTIONS[-1].joints = [(n.replace("L_Humerus", "R_Humerus") if n.startswith("L_") and
                           p == "Character1_RightArm" else n, p, pl)
                          for n, p, pl in CONVENTIONS[-1].joints]

# --- Mixamo (mixamorig:Hips > Spine > Spine1 > Spine2 > Neck > Head > HeadTop_End; eyes;
# Spine2 > *Shoulder > *Arm > *ForeArm > *Hand > *HandIndex1-4, *HandMiddle1-4, *HandThumb1-4;
# Hips > *UpLeg > *Leg > *Foot > *ToeBase > *Toe_End).
_mx = "mixamorig:"
CONVENTIONS.append(Convention("mixamo", "Mixamo rig (find_string 'mixamorigLeftHandMiddle1')", [
    (_mx + "Hips", None, "pelvis"), (_mx + "Spine", _mx + "Hips", ("pelvis", "spine_1", 0.5)),
    (_mx + "Spine1", _mx + "Spine", "spine_1"), (_mx + "Spine2", _mx + "Spine1", "spine_2"),
    (_mx + "Neck", _mx + "Spine2", "neck"), (_mx + "Head", _mx + "Neck", "head"),
    (_mx + "HeadTop_End", _mx + "Head", "head_top"),
    (_mx + "LeftEye", _mx + "Head", ("head", (0.08, 0.03, 0.06))),
    (_mx + "RightEye", _mx + "Head", ("head", (0.08, -0.03, 0.06))),
] + _mirror(_leg_arm({"pelvis": _mx + "Hips", "chest": _mx + "Spine2", "hip": _mx + "LeftUpLeg",
                      "knee": _mx + "LeftLeg", "ankle": _mx + "LeftFoot", "toe": _mx + "LeftToeBase",
                      "collar": _mx + "LeftShoulder", "shoulder": _mx + "LeftArm",
                      "elbow": _mx + "LeftForeArm", "wrist": _mx + "LeftHand"}, [
    (_mx + "LeftToe_End", _mx + "LeftToeBase", ("toe_l", (0.05, 0.0, 0.0))),
    (_mx + "LeftHandMiddle1", _mx + "LeftHand", "hand_l"),
    (_mx + "LeftHandMiddle2", _mx + "LeftHandMiddle1", ("hand_l", (0.0, 0.0, -0.03))),
    (_mx + "LeftHandIndex1", _mx + "LeftHand", ("wrist_l", (0.03, 0.0, -0.08))),
    (_mx + "LeftHandThumb1", _mx + "LeftHand", ("wrist_l", (0.03, 0.02, -0.02)))]),
    "Left", "Right")))

# --- Unreal Engine 4 mannequin (root > pelvis > spine_01-03 > neck_01 > head; spine_03 >
# clavicle_l > upperarm_l > lowerarm_l > hand_l > middle_01-03_l; upperarm_twist_01_l,
# lowerarm_twist_01_l, thigh_twist_01_l, calf_twist_01_l leaves; thigh_l > calf_l > foot_l >
# ball_l; root > ik_foot_root > ik_foot_l, root > ik_hand_root > ik_hand_gun > ik_hand_r;
# hand_r > weapon_r), Z up, X forward, centimetres.
_ue_leg_arm = _leg_arm({"pelvis": "pelvis", "chest": "spine_03", "hip": "thigh_l",
                        "knee": "calf_l", "ankle": "foot_l", "toe": "ball_l",
                        "collar": "clavicle_l", "shoulder": "upperarm_l", "elbow": "lowerarm_l",
                        "wrist": "hand_l"}, [
    ("middle_01_l", "hand_l", "hand_l"), ("middle_02_l", "middle_01_l", ("hand_l", (0.0, 0.0, -0.03))),
    ("thumb_01_l", "hand_l", ("wrist_l", (0.03, 0.02, -0.02))),
    ("upperarm_twist_01_l", "upperarm_l", ("shoulder_l", "elbow_l", 0.5)),
    ("lowerarm_twist_01_l", "lowerarm_l", ("elbow_l", "wrist_l", 0.5)),
    ("thigh_twist_01_l", "thigh_l", ("hip_l", "knee_l", 0.5)),
    ("calf_twist_01_l", "calf_l", ("knee_l", "ankle_l", 0.5)),
    ("ik_foot_l", "ik_foot_root", "ankle_l")])
CONVENTIONS.append(Convention("ue4_mannequin", "UE4 mannequin skeleton (find_string 'lowerarm_twist_01_l')", [
    ("root", None, ("pelvis", (0.0, 0.0, -1.0))), ("pelvis", "root", "pelvis"),
    ("spine_01", "pelvis", ("pelvis", "spine_1", 0.5)), ("spine_02", "spine_01", "spine_1"),
    ("spine_03", "spine_02", "spine_2"), ("neck_01", "spine_03", "neck"),
    ("head", "neck_01", "head"), ("head_end", "head", "head_top"),
    ("ik_foot_root", "root", ("pelvis", (0.0, 0.0, -1.0))),
    ("ik_hand_root", "root", ("pelvis", (0.0, 0.0, -1.0))),
    ("ik_hand_gun", "ik_hand_root", "wrist_r"), ("ik_hand_r", "ik_hand_gun", "wrist_r"),
] + _mirror(_ue_leg_arm, "_l", "_r") + [
    ("weapon_r", "hand_r", ("wrist_r", (0.1, 0.0, 0.0)))], order="ZYX", up="z"))

# --- Unreal Engine 5 mannequin (root > pelvis > spine_01-05 > neck_01 > neck_02 > head;
# spine_05 > clavicle_l > upperarm_l > lowerarm_l > hand_l > middle_metacarpal_l > middle_01_l;
# upperarm_twist_01/02_l, lowerarm_twist_01/02_l, thigh_twist_01_l, calf_twist_01_l leaves).
CONVENTIONS.append(Convention("ue5_mannequin", "UE5 Manny skeleton (find_string 'spine_05')", [
    ("root", None, ("pelvis", (0.0, 0.0, -1.0))), ("pelvis", "root", "pelvis"),
    ("spine_01", "pelvis", ("pelvis", "spine_1", 0.5)), ("spine_02", "spine_01", "spine_1"),
    ("spine_03", "spine_02", ("spine_1", "spine_2", 0.5)), ("spine_04", "spine_03", "spine_2"),
    ("spine_05", "spine_04", ("spine_2", "neck", 0.5)), ("neck_01", "spine_05", "neck"),
    ("neck_02", "neck_01", ("neck", "head", 0.5)), ("head", "neck_02", "head"),
] + _mirror(_leg_arm({"pelvis": "pelvis", "chest": "spine_05", "hip": "thigh_l", "knee": "calf_l",
                      "ankle": "foot_l", "toe": "ball_l", "collar": "clavicle_l",
                      "shoulder": "upperarm_l", "elbow": "lowerarm_l", "wrist": "hand_l"}, [
    ("middle_metacarpal_l", "hand_l", ("wrist_l", "hand_l", 0.4)),
    ("middle_01_l", "middle_metacarpal_l", "hand_l"),
    ("upperarm_twist_01_l", "upperarm_l", ("shoulder_l", "elbow_l", 0.33)),
    ("upperarm_twist_02_l", "upperarm_l", ("shoulder_l", "elbow_l", 0.66)),
    ("lowerarm_twist_01_l", "lowerarm_l", ("elbow_l", "wrist_l", 0.5)),
    ("lowerarm_twist_02_l", "lowerarm_l", ("elbow_l", "wrist_l", 0.75)),
    ("thigh_twist_01_l", "thigh_l", ("hip_l", "knee_l", 0.5)),
    ("calf_twist_01_l", "calf_l", ("knee_l", "ankle_l", 0.5))]), "_l", "_r"), up="z"))

# --- Unity Humanoid (HumanBodyBones: Hips > Spine > Chest > UpperChest > Neck > Head > LeftEye,
# Jaw; UpperChest > LeftShoulder > LeftUpperArm > LeftLowerArm > LeftHand > LeftMiddleProximal >
# LeftMiddleIntermediate; Hips > LeftUpperLeg > LeftLowerLeg > LeftFoot > LeftToes).
CONVENTIONS.append(Convention("unity_humanoid", "Unity HumanBodyBones (docs.unity3d.com)", [
    ("Hips", None, "pelvis"), ("Spine", "Hips", "spine_1"),
    ("Chest", "Spine", ("spine_1", "spine_2", 0.5)), ("UpperChest", "Chest", "spine_2"),
    ("Neck", "UpperChest", "neck"), ("Head", "Neck", "head"),
    ("LeftEye", "Head", ("head", (0.08, 0.03, 0.06))), ("Jaw", "Head", ("head", (0.05, 0.0, -0.03))),
] + _mirror(_leg_arm({"pelvis": "Hips", "chest": "UpperChest", "hip": "LeftUpperLeg",
                      "knee": "LeftLowerLeg", "ankle": "LeftFoot", "toe": "LeftToes",
                      "collar": "LeftShoulder", "shoulder": "LeftUpperArm", "elbow": "LeftLowerArm",
                      "wrist": "LeftHand"}, [
    ("LeftMiddleProximal", "LeftHand", "hand_l"),
    ("LeftMiddleIntermediate", "LeftMiddleProximal", ("hand_l", (0.0, 0.0, -0.03)))]),
    "Left", "Right"), unit=1.0))

# --- VRM as VRoid Studio names its nodes (Root > J_Bip_C_Hips > J_Bip_C_Spine > J_Bip_C_Chest >
# J_Bip_C_UpperChest > J_Bip_C_Neck > J_Bip_C_Head > J_Adj_L_FaceEye, hair J_Sec_Hair1_01;
# UpperChest > J_Bip_L_Shoulder > J_Bip_L_UpperArm > J_Bip_L_LowerArm > J_Bip_L_Hand >
# J_Bip_L_Middle1-3; Hips > J_Bip_L_UpperLeg > J_Bip_L_LowerLeg > J_Bip_L_Foot > J_Bip_L_ToeBase).
CONVENTIONS.append(Convention("vrm", "VRoid Studio VRM node names (find_string 'J_Bip_C_Hips')", [
    ("Root", None, ("pelvis", (0.0, 0.0, -1.0))), ("J_Bip_C_Hips", "Root", "pelvis"),
    ("J_Bip_C_Spine", "J_Bip_C_Hips", "spine_1"),
    ("J_Bip_C_Chest", "J_Bip_C_Spine", ("spine_1", "spine_2", 0.5)),
    ("J_Bip_C_UpperChest", "J_Bip_C_Chest", "spine_2"), ("J_Bip_C_Neck", "J_Bip_C_UpperChest", "neck"),
    ("J_Bip_C_Head", "J_Bip_C_Neck", "head"),
    ("J_Adj_L_FaceEye", "J_Bip_C_Head", ("head", (0.08, 0.03, 0.06))),
    ("J_Sec_Hair1_01", "J_Bip_C_Head", ("head", (-0.08, 0.0, 0.1))),
    ("J_Sec_Hair2_01", "J_Sec_Hair1_01", ("head", (-0.1, 0.0, 0.0))),
] + _mirror(_leg_arm({"pelvis": "J_Bip_C_Hips", "chest": "J_Bip_C_UpperChest",
                      "hip": "J_Bip_L_UpperLeg", "knee": "J_Bip_L_LowerLeg", "ankle": "J_Bip_L_Foot",
                      "toe": "J_Bip_L_ToeBase", "collar": "J_Bip_L_Shoulder",
                      "shoulder": "J_Bip_L_UpperArm", "elbow": "J_Bip_L_LowerArm",
                      "wrist": "J_Bip_L_Hand"}, [
    ("J_Bip_L_Middle1", "J_Bip_L_Hand", "hand_l"),
    ("J_Bip_L_Middle2", "J_Bip_L_Middle1", ("hand_l", (0.0, 0.0, -0.03)))]), "_L_", "_R_"),
    unit=1.0))

# --- Daz Genesis 8 (hip > pelvis > lThighBend > lThighTwist > lShin > lFoot > lMetatarsals >
# lToe; hip > abdomenLower > abdomenUpper > chestLower > chestUpper > neckLower > neckUpper > head;
# chestUpper > lCollar > lShldrBend > lShldrTwist > lForearmBend > lForearmTwist > lHand >
# lCarpal2 > lMid1 > lMid2; BendTwist pairs from a Genesis 3 target rig).
_daz = [("lThighBend", "pelvis", "hip_l"), ("lThighTwist", "lThighBend", ("hip_l", "knee_l", 0.4)),
        ("lShin", "lThighTwist", "knee_l"), ("lFoot", "lShin", "ankle_l"),
        ("lMetatarsals", "lFoot", ("ankle_l", "toe_l", 0.5)), ("lToe", "lMetatarsals", "toe_l"),
        ("lCollar", "chestUpper", "neck"), ("lShldrBend", "lCollar", "shoulder_l"),
        ("lShldrTwist", "lShldrBend", ("shoulder_l", "elbow_l", 0.5)),
        ("lForearmBend", "lShldrTwist", "elbow_l"),
        ("lForearmTwist", "lForearmBend", ("elbow_l", "wrist_l", 0.5)),
        ("lHand", "lForearmTwist", "wrist_l"), ("lCarpal2", "lHand", ("wrist_l", "hand_l", 0.4)),
        ("lMid1", "lCarpal2", "hand_l"), ("lMid2", "lMid1", ("hand_l", (0.0, 0.0, -0.03)))]
CONVENTIONS.append(Convention("daz_genesis8", "Daz Genesis 8 (a Genesis 3 target rig's bones and BendTwist pairs)", [
    ("hip", None, "pelvis"), ("pelvis", "hip", ("pelvis", (0.0, 0.0, -0.02))),
    ("abdomenLower", "hip", ("pelvis", "spine_1", 0.5)), ("abdomenUpper", "abdomenLower", "spine_1"),
    ("chestLower", "abdomenUpper", "spine_2"), ("chestUpper", "chestLower", ("spine_2", "neck", 0.5)),
    ("neckLower", "chestUpper", "neck"), ("neckUpper", "neckLower", ("neck", "head", 0.5)),
    ("head", "neckUpper", "head"),
] + _mirror(_daz, "l", "r"), order="ZYX"))


# --- the body -----------------------------------------------------------------------------------


def body_points(motion, stature_scale: float, pose: str) -> dict[str, np.ndarray]:
    """Our joints at the rig's rest (metres, our axes: x forward, y left, z up), from the walk's
    proportions scaled by ``stature_scale``: the walk's hip directions, a straight spine, arms
    level (``pose`` "T") or 45 degrees down ("A"), legs straight, feet on the floor."""
    from ecs_anim.core.skeleton import LENGTH_INDEX

    lengths = motion.source_morphology.lengths * stature_scale

    def length(name: str) -> float:
        return float(lengths[LENGTH_INDEX[name]])

    hip_dir = motion.poses.hip_dir[0]  # (2, 3) in the pelvis frame: constant in the walk
    clavicle_dir = motion.poses.clavicle_dir[0]
    leg = length("thigh_l") + length("shank_l")
    p = {"pelvis": np.array([0.0, 0.0, leg + length("ankle_height_l")])}
    z = np.array([0.0, 0.0, 1.0])
    p["spine_1"] = p["pelvis"] + z * length("spine_lower")
    p["spine_2"] = p["spine_1"] + z * length("spine_middle")
    p["neck"] = p["spine_2"] + z * length("spine_upper")
    p["head"] = p["neck"] + z * length("neck")
    p["head_top"] = p["head"] + z * length("head")
    down = np.radians(45.0) if pose == "A" else 0.0
    foot = np.array([np.cos(np.radians(30.0)), 0.0, -np.sin(np.radians(30.0))])
    for k, s in enumerate("lr"):
        side = 1.0 if s == "l" else -1.0
        p[f"hip_{s}"] = p["pelvis"] + hip_dir[k] * length(f"pelvis_{s}")
        p[f"knee_{s}"] = p[f"hip_{s}"] - z * length(f"thigh_{s}")
        p[f"ankle_{s}"] = p[f"knee_{s}"] - z * length(f"shank_{s}")
        p[f"toe_{s}"] = p[f"ankle_{s}"] + foot * length(f"foot_{s}")
        p[f"shoulder_{s}"] = p["neck"] + clavicle_dir[k] * length(f"clavicle_{s}")
        arm = np.array([0.0, side * np.cos(down), -np.sin(down)])
        p[f"elbow_{s}"] = p[f"shoulder_{s}"] + arm * length(f"upper_arm_{s}")
        p[f"wrist_{s}"] = p[f"elbow_{s}"] + arm * length(f"forearm_{s}")
        p[f"hand_{s}"] = p[f"wrist_{s}"] + arm * length(f"hand_{s}")
    return p


def joint_places(convention: Convention, body: dict[str, np.ndarray]) -> np.ndarray:
    """(J, 3) each joint's rest place in our axes, metres."""
    out = []
    for _, _, place in convention.joints:
        if isinstance(place, str):
            out.append(body[place])
        elif len(place) == 3:
            a, b, t = place
            out.append((1 - t) * body[a] + t * body[b])
        else:
            out.append(body[place[0]] + np.asarray(place[1], float))
    return np.array(out)


#: Ours (x forward, y left, z up) -> a Y-up file's axes (left +X, up +Y, facing +Z), and -> Z up.
OURS_TO_FILE = {"y": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), "z": np.eye(3)}


def bvh_text(convention: Convention, body: dict[str, np.ndarray]) -> str:
    """The rig as a BVH with one frame of its rest pose (the root's own place)."""
    places = joint_places(convention, body) @ OURS_TO_FILE[convention.up].T / convention.unit
    names = [j[0] for j in convention.joints]
    parent = [None if j[1] is None else names.index(j[1]) for j in convention.joints]
    children = {i: [c for c in range(len(names)) if parent[c] == i] for i in range(len(names))}
    rot = " ".join(f"{a}rotation" for a in convention.order)
    lines = ["HIERARCHY"]
    channels = []

    def emit(i: int, depth: int) -> None:
        pad = "\t" * depth
        offset = places[i] - (places[parent[i]] if parent[i] is not None else 0.0)
        lines.append(f"{pad}{'ROOT' if parent[i] is None else 'JOINT'} {names[i]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET {' '.join(f'{v + 0.0:.6f}' for v in np.round(offset, 6))}")
        if parent[i] is None:
            lines.append(f"{pad}\tCHANNELS 6 Xposition Yposition Zposition {rot}")
            channels.extend(offset.tolist() + [0.0] * 3)
        else:
            lines.append(f"{pad}\tCHANNELS 3 {rot}")
            channels.extend([0.0] * 3)
        for c in children[i]:
            emit(c, depth + 1)
        if not children[i]:
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET 0.000000 "
                      f"{2.0 if convention.up == 'y' else 0.0:.6f} "
                      f"{2.0 if convention.up == 'z' else 0.0:.6f}", f"{pad}\t}}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.0333333"]
    lines += [" ".join(f"{v:.6f}" for v in channels)] * 2
    return "\n".join(lines) + "\n"


def _frame_y_along(direction: np.ndarray, roll: float) -> np.ndarray:
    """A rotation whose Y axis is ``direction`` (3,), turned by ``roll`` radians about it."""
    y = direction / np.linalg.norm(direction)
    helper = np.array([0.0, 0.0, 1.0]) if abs(y[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(y, helper)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    c, s = np.cos(roll), np.sin(roll)
    return np.stack([c * x + s * z, y, -s * x + c * z], axis=1)


def _quat(m: np.ndarray) -> list[float]:
    """(x, y, z, w) of a rotation matrix (3, 3)."""
    from ecs_anim.core.rotations import quat_from_matrix

    return quat_from_matrix(m).tolist()


def glb_bytes(convention: Convention, body: dict[str, np.ndarray], seed: int = 33) -> bytes:
    """The rig as a skinned GLB: an ``Armature`` node (Z up -> Y up, cm -> m) over the joints,
    each with its Y axis along its bone and a random roll, and one triangle per joint."""
    rng = np.random.default_rng(seed)
    places = joint_places(convention, body) @ OURS_TO_FILE["y"].T  # glTF world, metres
    names = [j[0] for j in convention.joints]
    parent = [None if j[1] is None else names.index(j[1]) for j in convention.joints]
    n = len(names)
    world_rot = []
    for i in range(n):
        kids = [c for c in range(n) if parent[c] == i]
        target = places[kids[0]] if kids else places[i] + (places[i] - places[parent[i]]
                                                          if parent[i] is not None else [0, 1, 0])
        direction = target - places[i]
        if np.linalg.norm(direction) < 1e-6:
            direction = np.array([0.0, 1.0, 0.0])
        world_rot.append(_frame_y_along(direction, rng.uniform(-np.pi, np.pi)))
    scale = 0.01
    armature_rot = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # -90 deg about X
    nodes = [gl.Node(name="Armature", rotation=_quat(armature_rot), scale=[scale] * 3,
                     children=[1 + i for i in range(n) if parent[i] is None])]
    for i in range(n):
        up = parent[i]
        p_rot = armature_rot if up is None else world_rot[up]
        p_pos = np.zeros(3) if up is None else places[up]
        local_rot = p_rot.T @ world_rot[i]
        local_t = p_rot.T @ (places[i] - p_pos) / scale
        nodes.append(gl.Node(name=names[i], rotation=_quat(local_rot), translation=local_t.tolist(),
                             children=[1 + c for c in range(n) if parent[c] == i] or None))
    inverse_bind = []
    for i in range(n):
        m = np.eye(4)
        m[:3, :3] = scale * world_rot[i]
        m[:3, 3] = places[i]
        inverse_bind.append(np.linalg.inv(m).T.astype(np.float32))  # column-major
    tri = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.0, 0.02, 0.0]])
    vertices = np.concatenate([places[i] + tri for i in range(n)]).astype(np.float32)
    joints = np.zeros((3 * n, 4), np.uint8)
    joints[:, 0] = np.repeat(np.arange(n), 3)
    weights = np.zeros((3 * n, 4), np.float32)
    weights[:, 0] = 1.0
    indices = np.arange(3 * n, dtype=np.uint16)
    blobs = [np.stack(inverse_bind).tobytes(), vertices.tobytes(), joints.tobytes(),
             weights.tobytes(), indices.tobytes()]
    views, offset = [], 0
    data = b""
    for k, raw in enumerate(blobs):
        target = [None, gl.ARRAY_BUFFER, gl.ARRAY_BUFFER, gl.ARRAY_BUFFER, gl.ELEMENT_ARRAY_BUFFER][k]
        views.append(gl.BufferView(buffer=0, byteOffset=offset, byteLength=len(raw), target=target))
        pad = -len(raw) % 4
        data += raw + b"\0" * pad
        offset += len(raw) + pad
    accessors = [
        gl.Accessor(bufferView=0, componentType=gl.FLOAT, count=n, type="MAT4"),
        gl.Accessor(bufferView=1, componentType=gl.FLOAT, count=3 * n, type="VEC3",
                    min=vertices.min(axis=0).tolist(), max=vertices.max(axis=0).tolist()),
        gl.Accessor(bufferView=2, componentType=gl.UNSIGNED_BYTE, count=3 * n, type="VEC4"),
        gl.Accessor(bufferView=3, componentType=gl.FLOAT, count=3 * n, type="VEC4"),
        gl.Accessor(bufferView=4, componentType=gl.UNSIGNED_SHORT, count=3 * n, type="SCALAR"),
    ]
    nodes.append(gl.Node(name=f"{convention.name}_mesh", mesh=0, skin=0))
    document = gl.GLTF2(
        asset=gl.Asset(version="2.0", generator="onto_rigs test"), scene=0,
        scenes=[gl.Scene(nodes=[0, len(nodes) - 1])], nodes=nodes,
        meshes=[gl.Mesh(primitives=[gl.Primitive(attributes=gl.Attributes(
            POSITION=1, JOINTS_0=2, WEIGHTS_0=3), indices=4, material=0)])],
        materials=[gl.Material(name="skin")],
        skins=[gl.Skin(joints=list(range(1, n + 1)), inverseBindMatrices=0, skeleton=1)],
        accessors=accessors, bufferViews=views, buffers=[gl.Buffer(byteLength=len(data))])
    document.set_binary_blob(data)
    return b"".join(document.save_to_bytes())


def write_rig(convention: Convention, body: dict[str, np.ndarray], path: Path) -> Path:
    """Write the rig as ``path`` (.bvh or .glb); returns ``path``."""
    if path.suffix == ".bvh":
        path.write_text(bvh_text(convention, body))
    else:
        path.write_bytes(glb_bytes(convention, body))
    return path
