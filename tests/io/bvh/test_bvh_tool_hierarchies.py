"""Skeletons as common mocap and animation tools write them, imported with no flags.

Each tool's hierarchy (joint names, parent/child topology, which joints end in an End Site, the
channel order) is written here by hand from a file or writer seen in public material (the source
is named at each tool); the offsets are plausible human ones in cm, Y up, facing +Z, left at +X,
T-pose, not the tool's own numbers. Every clip is the same synthetic walk: the hips move forward
at 1.2 m/s, the thighs swing +-25 degrees about the lateral axis in antiphase, the knees bend
0-40 degrees, the upper arms swing +-15 degrees and the elbows are bent 10-20 degrees.

For each tool: the import succeeds with no flags, the canonical joints are the source joints a
human would pick (the thigh joint for the hip, the upper-arm joint and not the clavicle for the
shoulder, the tool's left for left, the foot's End Site for the toe when there is no toe joint),
and the export on the source body gives back the source joints within 0.1 mm on every frame
(against the independent forward kinematics of ``support/bvh_reference.py``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from support.bvh_reference import (
    axis_rotation,
    errors_m,
    euler_angles,
    import_and_export,
    reference_world,
)

MM = 1e-3
N_FRAMES = 60
FRAME_TIME_S = 1.0 / 30.0
WALK_SPEED_CM_S = 120.0
#: Walk phase at frame 0: not 0, so that frame 0 is no rest pose (which the import drops).
PHASE0 = 0.9

#: A joint: (name as the importer reports it, parent, OFFSET (cm), End Site OFFSET or None,
#: name as written in the file when it differs: a name used twice is read as ``Name#2``).
Joint = tuple


@dataclass
class Tool:
    name: str
    source: str
    joints: list[Joint]
    #: canonical joint -> source joint a human would pick (End Sites as ``<joint>.end``).
    expected: dict[str, str]
    order: str = "ZXY"
    six_channels_everywhere: bool = False
    #: Order of the root's position channels as the tool writes them.
    position_order: str = "XYZ"

    # --- writing the clip ----------------------------------------------------------------------

    def _rest(self) -> dict[str, np.ndarray]:
        place: dict[str, np.ndarray] = {}
        for name, parent, offset, *_ in self.joints:
            place[name] = np.asarray(offset, float) + (place[parent] if parent else 0.0)
        return place

    def _local_rotations(self) -> dict[str, np.ndarray]:
        """Per driven joint, (n, 3, 3) local rotations of the walk."""
        t = np.arange(N_FRAMES) * FRAME_TIME_S
        phase = 2 * np.pi * t + PHASE0
        e = self.expected
        rot: dict[str, np.ndarray] = {}

        def drive(canonical: str, axis: str, degrees: np.ndarray) -> None:
            name = e.get(canonical)
            if name is not None and not name.endswith(".end"):
                rot[name] = axis_rotation(axis, degrees)

        rot[self.joints[0][0]] = axis_rotation("Y", 5.0 * np.sin(phase))  # the root yaws a little
        for side, shift in (("l", 0.0), ("r", np.pi)):
            p = phase + shift
            drive(f"hip_{side}", "X", -25.0 * np.sin(p))  # negative about X: the foot goes forward
            drive(f"knee_{side}", "X", 20.0 * (1.0 - np.cos(p)))  # 0-40, the shank backwards
            drive(f"ankle_{side}", "X", 5.0 * np.sin(p))
        sign = {"l": -1.0, "r": 1.0}  # arms along +X (left) and -X (right): forward about Y
        for side in "lr":
            drive(f"shoulder_{side}", "Y", 15.0 * np.sin(phase))
            drive(f"elbow_{side}", "Y", sign[side] * (15.0 + 5.0 * np.sin(phase)))
        return rot

    def text(self) -> str:
        rest = self._rest()
        root = self.joints[0][0]
        # The root's height puts the lowest rest joint 2 cm above the floor.
        height = rest[root][1] - min(p[1] for p in rest.values()) + 2.0
        t = np.arange(N_FRAMES) * FRAME_TIME_S
        phase = 2 * np.pi * t + PHASE0
        root_place = np.stack([2.0 * np.sin(phase), height + 1.5 * np.cos(2 * phase),
                               WALK_SPEED_CM_S * t], axis=-1)
        rotations = self._local_rotations()
        rot_names = [f"{a}rotation" for a in self.order]
        pos_names = [f"{a}position" for a in self.position_order]
        columns: list[np.ndarray] = []
        out = ["HIERARCHY"]
        children: dict[str | None, list[Joint]] = {}
        for j in self.joints:
            children.setdefault(j[1], []).append(j)

        def vec(v) -> str:
            return " ".join(f"{float(x):.6f}" for x in v)

        def emit(joint: Joint, depth: int) -> None:
            name, parent, offset, end = joint[:4]
            written = joint[4] if len(joint) > 4 else name
            pad = "\t" * depth
            out.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {written}")
            out.append(pad + "{")
            out.append(f"{pad}\tOFFSET {vec(offset)}")
            matrix = rotations.get(name, np.broadcast_to(np.eye(3), (N_FRAMES, 3, 3)))
            angles = euler_angles(np.ascontiguousarray(matrix), self.order)
            if parent is None or self.six_channels_everywhere:
                place = root_place if parent is None else np.tile(offset, (N_FRAMES, 1))
                out.append(f"{pad}\tCHANNELS 6 {' '.join(pos_names + rot_names)}")
                columns.append(place[:, ["XYZ".index(a) for a in self.position_order]])
            else:
                out.append(f"{pad}\tCHANNELS 3 {' '.join(rot_names)}")
            columns.append(angles)
            for child in children.get(name, []):
                emit(child, depth + 1)
            if end is not None:
                out.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {vec(end)}",
                            f"{pad}\t}}"])
            out.append(pad + "}")

        emit(self.joints[0], 0)
        values = np.concatenate(columns, axis=1)
        out += ["MOTION", f"Frames: {N_FRAMES}", f"Frame Time: {FRAME_TIME_S:.8f}"]
        out += [" ".join(f"{v:.6f}" for v in row) for row in values]
        return "\n".join(out) + "\n"


def _sides(left: list[Joint], rename) -> list[Joint]:
    """``left`` and its mirror image: each name through ``rename`` (left -> right), X negated."""
    right = []
    for name, parent, offset, end, *written in left:
        o = (-offset[0], offset[1], offset[2])
        e = None if end is None else (-end[0], end[1], end[2])
        right.append((rename(name), rename(parent), o, e, *[rename(w) for w in written]))
    return left + right


def _expect(left: dict[str, str], rename, **middle: str) -> dict[str, str]:
    """Canonical -> source names: ``left`` for ``*_l``, mirrored by ``rename`` for ``*_r``."""
    out = dict(middle)
    for canonical, name in left.items():
        out[f"{canonical}_l"] = name
        out[f"{canonical}_r"] = rename(name)
    return out


def _swap(left: str, right: str):
    return lambda name: name.replace(left, right) if name else name


# Plausible adult proportions (cm), shared by the tools: pelvis half-width 9, thigh 44, shank 42,
# ankle to ball 15 (4 down) and ball to tip 6, clavicle 15, upper arm 29, forearm 26, hand 18.
THIGH, SHANK = (0, -44, 0), (0, -42, 0)
TO_BALL, BALL_TO_TIP, FOOT_TIP = (0, -8, 13), (0, -1, 6), (0, -9, 19)
UPPER_ARM, FOREARM, HAND = (29, 0, 0), (26, 0, 0), (18, 0, 0)

TOOLS: list[Tool] = []

# --- Xsens MVN (AnyBody/ammr: Application/MocapExamples/BVH_Xsens/BVH-files/S01_Trial02.bvh):
# Hips(6) > Chest > Chest2 > Chest3 > Chest4 > Neck > Head(End Site); Chest4 > *Collar >
# *Shoulder (upper arm) > *Elbow > *Wrist(End Site); Hips > *Hip > *Knee > *Ankle > *Toe(End
# Site). Root OFFSET 0 0 0, rotations Y X Z.
_r = _swap("Left", "Right")
TOOLS.append(Tool(
    "xsens_mvn", "AnyBody/ammr:Application/MocapExamples/BVH_Xsens/BVH-files/S01_Trial02.bvh",
    [("Hips", None, (0, 0, 0), None), ("Chest", "Hips", (0, 10.5, 0), None),
     ("Chest2", "Chest", (0, 12.2, 0), None), ("Chest3", "Chest2", (0, 11.0, 0), None),
     ("Chest4", "Chest3", (0, 11.0, 0), None), ("Neck", "Chest4", (0, 15.3, 0), None),
     ("Head", "Neck", (0, 10.2, 0), (0, 19.8, 0))]
    + _sides([("LeftCollar", "Chest4", (3.1, 8.5, 0), None),
              ("LeftShoulder", "LeftCollar", (13.7, 0, 0), None),
              ("LeftElbow", "LeftShoulder", UPPER_ARM, None),
              ("LeftWrist", "LeftElbow", FOREARM, HAND),
              ("LeftHip", "Hips", (8.4, -0.1, 0), None), ("LeftKnee", "LeftHip", THIGH, None),
              ("LeftAnkle", "LeftKnee", SHANK, None),
              ("LeftToe", "LeftAnkle", (0, -10, 15.3), (0, -1.5, 6.1))], _r),
    _expect({"hip": "LeftHip", "knee": "LeftKnee", "ankle": "LeftAnkle", "toe": "LeftToe",
             "shoulder": "LeftShoulder", "elbow": "LeftElbow", "wrist": "LeftWrist"}, _r,
            pelvis="Hips", neck="Neck", head="Head"),
    order="YXZ"))

# --- Perception Neuron / Axis Studio (AnyBody/ammr: Application/MocapExamples/BVH_NeuronMoCap/
# BVH-files/Sit-Stand3_chr00.bvh): 6 channels Y X Z on every joint; Hips > *UpLeg > *Leg >
# *Foot(End Site = toe tip, no toe joint); Hips > Spine > Spine1 > Spine2 > Neck > Neck1 >
# Head(End Site); Spine2 > *Shoulder > *Arm > *ForeArm > *Hand > fingers: *HandThumb1-3,
# *InHandIndex > *HandIndex1-3, *InHandMiddle > *HandMiddle1-3, *InHandRing > *HandRing1-3,
# *InHandPinky > *HandPinky1-3 (each finger's last joint with an End Site).
_fingers: list[Joint] = [("LeftHandThumb1", "LeftHand", (2.6, 0.2, 3.3), None),
                         ("LeftHandThumb2", "LeftHandThumb1", (3.9, 0, 0), None),
                         ("LeftHandThumb3", "LeftHandThumb2", (2.7, 0, 0), (2.3, 0, 0))]
for _finger, _z in (("Index", 2.1), ("Middle", 0.8), ("Ring", -0.1), ("Pinky", -1.3)):
    _fingers += [(f"LeftInHand{_finger}", "LeftHand", (3.4, 0.5, _z), None),
                 (f"LeftHand{_finger}1", f"LeftInHand{_finger}", (5.4, 0, 0.5 * _z), None),
                 (f"LeftHand{_finger}2", f"LeftHand{_finger}1", (3.8, 0, 0), None),
                 (f"LeftHand{_finger}3", f"LeftHand{_finger}2", (2.3, 0, 0), (1.9, 0, 0))]
TOOLS.append(Tool(
    "perception_neuron_axis_studio",
    "AnyBody/ammr:Application/MocapExamples/BVH_NeuronMoCap/BVH-files/Sit-Stand3_chr00.bvh",
    [("Hips", None, (0, 97, 0), None), ("Spine", "Hips", (0, 8.1, 0), None),
     ("Spine1", "Spine", (0, 18.0, 0), None), ("Spine2", "Spine1", (0, 12.8, 0), None),
     ("Neck", "Spine2", (0, 19.1, 0), None), ("Neck1", "Neck", (0, 4.3, 0), None),
     ("Head", "Neck1", (0, 4.3, 0), (0, 19.1, 0))]
    + _sides([("LeftUpLeg", "Hips", (11, 0, 0), None), ("LeftLeg", "LeftUpLeg", THIGH, None),
              ("LeftFoot", "LeftLeg", SHANK, (0, -10, 15.1)),
              ("LeftShoulder", "Spine2", (2.9, 13.3, 0), None),
              ("LeftArm", "LeftShoulder", (16.1, 0, 0), None),
              ("LeftForeArm", "LeftArm", (28, 0, 0), None),
              ("LeftHand", "LeftForeArm", (26, 0, 0), None)] + _fingers, _r),
    _expect({"hip": "LeftUpLeg", "knee": "LeftLeg", "ankle": "LeftFoot", "toe": "LeftFoot.end",
             "shoulder": "LeftArm", "elbow": "LeftForeArm", "wrist": "LeftHand"}, _r,
            pelvis="Hips", neck="Neck", head="Head"),
    order="YXZ", six_channels_everywhere=True))

# --- Rokoko Studio ("Rokoko Newton" bones, DADIU-2019-Team-4/MoMa:Assets/Scripts/PMAnimation/
# BoneType.cs: hips, leftThigh, leftShin, leftFoot, leftToe, leftToeTip, spine1-4,
# leftShoulder, leftArm, leftForeArm, leftHand, neck, head; capitalised as in
# facebookresearch/AnimatedDrawings' retarget configs: RightThigh, RightShin, RightFoot,
# RightToe, Spine1-Spine4, Neck, Head, RightShoulder, RightArm, RightForeArm, RightHand).
# Topology from the enum's order (shoulders and neck on Spine4); the toe tip is a joint.
TOOLS.append(Tool(
    "rokoko_studio", "DADIU-2019-Team-4/MoMa:Assets/Scripts/PMAnimation/BoneType.cs",
    [("Hips", None, (0, 0, 0), None), ("Spine1", "Hips", (0, 10, 0), None),
     ("Spine2", "Spine1", (0, 10, 0), None), ("Spine3", "Spine2", (0, 10, 0), None),
     ("Spine4", "Spine3", (0, 12, 0), None), ("Neck", "Spine4", (0, 14, 0), None),
     ("Head", "Neck", (0, 10, 0), (0, 18, 0))]
    + _sides([("LeftThigh", "Hips", (9, -2, 0), None), ("LeftShin", "LeftThigh", THIGH, None),
              ("LeftFoot", "LeftShin", SHANK, None), ("LeftToe", "LeftFoot", TO_BALL, None),
              ("LeftToeTip", "LeftToe", BALL_TO_TIP, (0, 0, 1)),
              ("LeftShoulder", "Spine4", (3, 9, 0), None),
              ("LeftArm", "LeftShoulder", (14, 0, 0), None),
              ("LeftForeArm", "LeftArm", UPPER_ARM, None),
              ("LeftHand", "LeftForeArm", FOREARM, HAND)], _r),
    _expect({"hip": "LeftThigh", "knee": "LeftShin", "ankle": "LeftFoot", "toe": "LeftToe",
             "shoulder": "LeftArm", "elbow": "LeftForeArm", "wrist": "LeftHand"}, _r,
            pelvis="Hips", neck="Neck", head="Head")))

# --- Ubisoft LAFAN1 (names from YanjieZe/GMR: general_motion_retargeting/utils/lafan1.py and
# ik_configs/bvh_lafan1_to_h1.json: Hips, LeftUpLeg, LeftLeg, LeftFoot, LeftToe, Spine, Spine1,
# Spine2, LeftArm, LeftForeArm; stevenhaener/dynamo_scripts:lafan_breakdown.m lists the channel
# blocks in file order: Hips, LeftUpLeg, LeftLeg, LeftFoot, LeftToe(Base), RightUpLeg ...,
# Spine, Spine1, Spine2, Neck, Head, LeftShoulder, LeftArm, LeftForeArm, LeftHand, Right...).
# Rotations Z Y X. (The real files' bones lie along local X at rest; here the rest is a T-pose.)
TOOLS.append(Tool(
    "ubisoft_lafan1", "YanjieZe/GMR:general_motion_retargeting/utils/lafan1.py",
    [("Hips", None, (0, 0, 0), None)]
    + _sides([("LeftUpLeg", "Hips", (10, -2, 0), None), ("LeftLeg", "LeftUpLeg", THIGH, None),
              ("LeftFoot", "LeftLeg", SHANK, None),
              ("LeftToe", "LeftFoot", TO_BALL, BALL_TO_TIP)], _r)
    + [("Spine", "Hips", (0, 8, 0), None), ("Spine1", "Spine", (0, 12, 0), None),
       ("Spine2", "Spine1", (0, 14, 0), None), ("Neck", "Spine2", (0, 22, 0), None),
       ("Head", "Neck", (0, 10, 0), (0, 18, 0))]
    + _sides([("LeftShoulder", "Spine2", (3, 17, 0), None),
              ("LeftArm", "LeftShoulder", (14, 0, 0), None),
              ("LeftForeArm", "LeftArm", UPPER_ARM, None),
              ("LeftHand", "LeftForeArm", FOREARM, HAND)], _r),
    _expect({"hip": "LeftUpLeg", "knee": "LeftLeg", "ankle": "LeftFoot", "toe": "LeftToe",
             "shoulder": "LeftArm", "elbow": "LeftForeArm", "wrist": "LeftHand"}, _r,
            pelvis="Hips", neck="Neck", head="Head"),
    order="ZYX"))

# --- Second Life / OpenSim (the SL hierarchy in a MNN-to-SL BVH writer, "Source:
# wiki.secondlife.com/wiki/How_to_create_animations"; lCollar/lShldr/lForeArm/lHand also in
# other SL/Poser BVH): hip(6) > Abdomen > Chest > Neck > Head(End Site); Chest > lCollar >
# lShldr > lForeArm > lHand(End Site); hip > lThigh > lShin > lFoot(End Site ahead and below:
# the toe tip). Rotations Z X Y.

def _sl_right(name):
    return "r" + name[1:] if name and name[0] == "l" and name[1].isupper() else name


TOOLS.append(Tool(
    "second_life", "find_string 'JOINT lShldr' (SL BVH writer citing the SL wiki)",
    [("hip", None, (0, 0, 0), None), ("Abdomen", "hip", (0, 9, 0), None),
     ("Chest", "Abdomen", (0, 22, -1), None), ("Neck", "Chest", (0, 27, -1), None),
     ("Head", "Neck", (0, 9, 0), (0, 9, 0))]
    + _sides([("lCollar", "Chest", (3.5, 25, -1), None), ("lShldr", "lCollar", (10, 0, 0), None),
              ("lForeArm", "lShldr", UPPER_ARM, None), ("lHand", "lForeArm", FOREARM, (10, 0, 0)),
              ("lThigh", "hip", (9, -4, 1.5), None), ("lShin", "lThigh", THIGH, None),
              ("lFoot", "lShin", SHANK, (0, -9, 10))], _sl_right),
    _expect({"hip": "lThigh", "knee": "lShin", "ankle": "lFoot", "toe": "lFoot.end",
             "shoulder": "lShldr", "elbow": "lForeArm", "wrist": "lHand"}, _sl_right,
            pelvis="hip", neck="Neck", head="Head")))

# --- Kinect v1 SDK writer (kinectbvh.cpp, KinectBVH::CreateSkeletonInformation): Hips > Chest
# (at SPINE) > Neck (SHOULDER_CENTER) > Head (HEAD, End Site); Chest > LeftCollar (at
# SHOULDER_LEFT) > LeftUpArm (ELBOW_LEFT) > LeftLowArm (WRIST_LEFT) > LeftHand (HAND_LEFT, End
# Site); Chest > RightCollar > *LeftUpArm > LeftLowArm > LeftHand* (the writer repeats the left
# names on the right: read as LeftUpArm#2 ...); Hips > LeftUpLeg (HIP_LEFT) > LeftLowLeg
# (KNEE_LEFT) > LeftFoot (FOOT_LEFT, End Site). Every joint Z X Y. Each joint is where its
# Kinect point is, so the joint at the shoulder is LeftCollar, at the elbow LeftUpArm.
def _kinect1_right(name):
    return {"LeftCollar": "RightCollar", "LeftUpArm": "LeftUpArm#2", "LeftLowArm": "LeftLowArm#2",
            "LeftHand": "LeftHand#2", "LeftUpLeg": "RightUpLeg", "LeftLowLeg": "RightLowLeg",
            "LeftFoot": "RightFoot", "LeftFoot.end": "RightFoot.end"}.get(name, name)


_kinect1_left: list[Joint] = [
    ("LeftCollar", "Chest", (17, 20, 0), None), ("LeftUpArm", "LeftCollar", UPPER_ARM, None),
    ("LeftLowArm", "LeftUpArm", FOREARM, None), ("LeftHand", "LeftLowArm", (8, 0, 0), (8, 0, 0)),
    ("LeftUpLeg", "Hips", (8, -6, 0), None), ("LeftLowLeg", "LeftUpLeg", THIGH, None),
    ("LeftFoot", "LeftLowLeg", (0, -44, 6), (0, -1, 10))]
TOOLS.append(Tool(
    "kinect_v1_sdk", "find_string 'JOINT RightCollar': kinectbvh.cpp (KinectBVH)",
    [("Hips", None, (0, 0, 0), None), ("Chest", "Hips", (0, 10, 0), None),
     ("Neck", "Chest", (0, 34, 0), None), ("Head", "Neck", (0, 16, 0), (0, 10, 0))]
    + _sides(_kinect1_left, _kinect1_right),
    _expect({"hip": "LeftUpLeg", "knee": "LeftLowLeg", "ankle": "LeftFoot",
             "toe": "LeftFoot.end", "shoulder": "LeftCollar", "elbow": "LeftUpArm",
             "wrist": "LeftLowArm"}, _kinect1_right, pelvis="Hips", neck="Neck", head="Head")))
for _k, _j in enumerate(TOOLS[-1].joints):  # the right arm is written with the left names
    if "#2" in _j[0]:
        TOOLS[-1].joints[_k] = _j[:4] + (_j[0].split("#")[0],)

# --- Kinect v2 SDK writer (find_string 'JOINT KneeLeft': a C# BVH writer over
# KinectSensor.BodyFrameSource): ROOT spineBase (6: Xposition Zposition Yposition Xrotation
# Zrotation Yrotation) > spineMid > spineShoulder > neck > head (End Site 0 0 0);
# spineShoulder > shoulderLeft > elbowLeft > wristLeft > handLeft > handTipLeft (End Site 0 0 0);
# spineBase > hipLeft > kneeLeft > ankleLeft > footLeft (End Site); joints X Z Y. No clavicle
# joint: the shoulders hang from spineShoulder.
_k2 = _swap("Left", "Right")
TOOLS.append(Tool(
    "kinect_v2_sdk", "find_string 'JOINT KneeLeft': C# Kinect v2 BVH writer",
    [("spineBase", None, (0, 0, 0), None), ("spineMid", "spineBase", (0, 28, 0), None),
     ("spineShoulder", "spineMid", (0, 24, 0), None), ("neck", "spineShoulder", (0, 6, 0), None),
     ("head", "neck", (0, 16, 0), (0, 0, 0))]
    + _sides([("shoulderLeft", "spineShoulder", (17, -4, 0), None),
              ("elbowLeft", "shoulderLeft", UPPER_ARM, None),
              ("wristLeft", "elbowLeft", FOREARM, None), ("handLeft", "wristLeft", (8, 0, 0), None),
              ("handTipLeft", "handLeft", (9, 0, 0), (0, 0, 0)),
              ("hipLeft", "spineBase", (8, -6, 0), None), ("kneeLeft", "hipLeft", THIGH, None),
              ("ankleLeft", "kneeLeft", SHANK, None),
              ("footLeft", "ankleLeft", (0, -6, 12), (0, 0, 4))], _k2),
    _expect({"hip": "hipLeft", "knee": "kneeLeft", "ankle": "ankleLeft", "toe": "footLeft",
             "shoulder": "shoulderLeft", "elbow": "elbowLeft", "wrist": "wristLeft"}, _k2,
            pelvis="spineBase", neck="neck", head="head"),
    order="XZY", position_order="XZY"))

# --- Unity humanoid (HumanBodyBones names: find_string 'JOINT LeftUpperLeg' gives Unity-style
# BVH with Hips > Spine > Chest > Neck > Head, *Shoulder > *UpperArm > *LowerArm > *Hand and
# *UpperLeg > *LowerLeg > *Foot; HumanBodyBones.LeftToes, UpperChest in Unity motion-matching
# code). Hips > Spine > Chest > UpperChest > Neck > Head; UpperChest > *Shoulder ...;
# Hips > *UpperLeg > *LowerLeg > *Foot > *Toes.
TOOLS.append(Tool(
    "unity_humanoid", "find_string 'JOINT LeftUpperLeg' (Unity-style BVH writers)",
    [("Hips", None, (0, 0, 0), None), ("Spine", "Hips", (0, 10, 0), None),
     ("Chest", "Spine", (0, 12, 0), None), ("UpperChest", "Chest", (0, 12, 0), None),
     ("Neck", "UpperChest", (0, 16, 0), None), ("Head", "Neck", (0, 10, 0), (0, 18, 0))]
    + _sides([("LeftShoulder", "UpperChest", (3, 11, 0), None),
              ("LeftUpperArm", "LeftShoulder", (14, 0, 0), None),
              ("LeftLowerArm", "LeftUpperArm", UPPER_ARM, None),
              ("LeftHand", "LeftLowerArm", FOREARM, HAND),
              ("LeftUpperLeg", "Hips", (9, -5, 0), None),
              ("LeftLowerLeg", "LeftUpperLeg", THIGH, None),
              ("LeftFoot", "LeftLowerLeg", SHANK, None),
              ("LeftToes", "LeftFoot", TO_BALL, BALL_TO_TIP)], _r),
    _expect({"hip": "LeftUpperLeg", "knee": "LeftLowerLeg", "ankle": "LeftFoot",
             "toe": "LeftToes", "shoulder": "LeftUpperArm", "elbow": "LeftLowerArm",
             "wrist": "LeftHand"}, _r, pelvis="Hips", neck="Neck", head="Head")))

# --- MotionBuilder HumanIK (find_string 'JOINT Character1_LeftUpLeg': a BVH template with
# Character1_Hips > Character1_Spine > Character1_Spine1 > Character1_*Shoulder > *Arm >
# *ForeArm > *Hand(End Site); Spine1 > Character1_Neck > Character1_Head(End Site); Hips >
# Character1_*UpLeg > *Leg > *Foot > *ToeBase(End Site); and 10 cm helper leaves with zero
# End Sites on most joints: L_Humerus_RIGMESH on the arm, L_Radius_RIGMESH on the forearm,
# L_Shoulder_RIGMESH, Neck_RIGMESH, Torso_RIGMESH, Spine_RIGMESH, L_Femur/Tibia/Talus_RIGMESH,
# Pelvis_RIGMESH). Rotations Z X Y.
def _hik(left: str):
    return lambda name: (name.replace(f"Character1_{left}", "Character1_Right" if left == "Left"
                                      else "Character1_Left").replace("L_", "R_") if name else name)


_hik_r = _hik("Left")
TOOLS.append(Tool(
    "motionbuilder_humanik", "find_string 'JOINT Character1_LeftUpLeg' (HumanIK BVH template)",
    [("Character1_Hips", None, (0, 0, 0), None),
     ("Character1_Spine", "Character1_Hips", (0, 12, 0), None),
     ("Character1_Spine1", "Character1_Spine", (0, 24, 0), None),
     ("Character1_Neck", "Character1_Spine1", (0, 20, 0), None),
     ("Character1_Head", "Character1_Neck", (0, 10, 0), (0, 10, 0)),
     ("Neck_RIGMESH", "Character1_Neck", (0, 0, 10), (0, 0, 0)),
     ("Torso_RIGMESH", "Character1_Spine1", (0, 0, 10), (0, 0, 0)),
     ("Spine_RIGMESH", "Character1_Spine", (0, 0, 10), (0, 0, 0)),
     ("Pelvis_RIGMESH", "Character1_Hips", (0, 0, 10), (0, 0, 0))]
    + _sides([("Character1_LeftShoulder", "Character1_Spine1", (3, 16, 0), None),
              ("Character1_LeftArm", "Character1_LeftShoulder", (14, 0, 0), None),
              ("Character1_LeftForeArm", "Character1_LeftArm", UPPER_ARM, None),
              ("Character1_LeftHand", "Character1_LeftForeArm", FOREARM, (9, 0, 0.5)),
              ("L_Radius_RIGMESH", "Character1_LeftForeArm", (0, 10, 0), (0, 0, 0)),
              ("L_Humerus_RIGMESH", "Character1_LeftArm", (0, 10, 0), (0, 0, 0)),
              ("L_Shoulder_RIGMESH", "Character1_LeftShoulder", (0, 0, 10), (0, 0, 0)),
              ("Character1_LeftUpLeg", "Character1_Hips", (9, -5, 0), None),
              ("Character1_LeftLeg", "Character1_LeftUpLeg", THIGH, None),
              ("Character1_LeftFoot", "Character1_LeftLeg", SHANK, None),
              ("Character1_LeftToeBase", "Character1_LeftFoot", (1.9, -6.7, 14.7), (10, 0, 0)),
              ("L_Talus_RIGMESH", "Character1_LeftFoot", (10, 0, 0), (0, 0, 0)),
              ("L_Tibia_RIGMESH", "Character1_LeftLeg", (10, 0, 0), (0, 0, 0)),
              ("L_Femur_RIGMESH", "Character1_LeftUpLeg", (10, 0, 0), (0, 0, 0))], _hik_r),
    _expect({"hip": "Character1_LeftUpLeg", "knee": "Character1_LeftLeg",
             "ankle": "Character1_LeftFoot", "toe": "Character1_LeftToeBase",
             "shoulder": "Character1_LeftArm", "elbow": "Character1_LeftForeArm",
             "wrist": "Character1_LeftHand"}, _hik_r, pelvis="Character1_Hips",
            neck="Character1_Neck", head="Character1_Head")))

# --- Blender Rigify, deform bones only (names from a Rigify rename table: DEF-spine (hips),
# DEF-spine.001-.003, DEF-spine.004 (neck), .005 (neck2), .006 (head), DEF-shoulder.L,
# DEF-upper_arm.L, DEF-upper_arm.L.001, DEF-forearm.L, DEF-forearm.L.001, DEF-hand.L,
# DEF-pelvis.L, DEF-thigh.L, DEF-thigh.L.001, DEF-shin.L, DEF-foot.L, DEF-toe.L). Topology
# ASSUMED from the names (the .001 twist halves between the long bones, thighs and the
# DEF-pelvis.L leaf on DEF-spine, shoulders on DEF-spine.003): a Rust auto-mapper notes that
# Rigify's own deform parenting is flatter. Rotations X Y Z.
_def_r = _swap(".L", ".R")
TOOLS.append(Tool(
    "blender_rigify_def", "find_string '\"DEF-upper_arm.L\"' (Rigify rename tables)",
    [("DEF-spine", None, (0, 0, 0), None), ("DEF-spine.001", "DEF-spine", (0, 10, 0), None),
     ("DEF-spine.002", "DEF-spine.001", (0, 12, 0), None),
     ("DEF-spine.003", "DEF-spine.002", (0, 14, 0), None),
     ("DEF-spine.004", "DEF-spine.003", (0, 16, 0), None),
     ("DEF-spine.005", "DEF-spine.004", (0, 5, 0), None),
     ("DEF-spine.006", "DEF-spine.005", (0, 5, 0), (0, 20, 0))]
    + _sides([("DEF-pelvis.L", "DEF-spine", (2, 2, 3), (10, 0, 0)),
              ("DEF-thigh.L", "DEF-spine", (9, -3, 0), None),
              ("DEF-thigh.L.001", "DEF-thigh.L", (0, -22, 0), None),
              ("DEF-shin.L", "DEF-thigh.L.001", (0, -22, 0), None),
              ("DEF-shin.L.001", "DEF-shin.L", (0, -21, 0), None),
              ("DEF-foot.L", "DEF-shin.L.001", (0, -21, 0), None),
              ("DEF-toe.L", "DEF-foot.L", TO_BALL, BALL_TO_TIP),
              ("DEF-shoulder.L", "DEF-spine.003", (3, 12, 0), None),
              ("DEF-upper_arm.L", "DEF-shoulder.L", (14, 0, 0), None),
              ("DEF-upper_arm.L.001", "DEF-upper_arm.L", (14.5, 0, 0), None),
              ("DEF-forearm.L", "DEF-upper_arm.L.001", (14.5, 0, 0), None),
              ("DEF-forearm.L.001", "DEF-forearm.L", (13, 0, 0), None),
              ("DEF-hand.L", "DEF-forearm.L.001", (13, 0, 0), HAND)], _def_r),
    _expect({"hip": "DEF-thigh.L", "knee": "DEF-shin.L", "ankle": "DEF-foot.L",
             "toe": "DEF-toe.L", "shoulder": "DEF-upper_arm.L", "elbow": "DEF-forearm.L",
             "wrist": "DEF-hand.L"}, _def_r, pelvis="DEF-spine", neck="DEF-spine.004",
            head="DEF-spine.006"),
    order="XYZ"))

# --- MMD (PMX standard bones, Japanese and the PMX English names, from a VMD-to-VRM mapping:
# センター center, 上半身 upper body, 上半身2 upper body2, 首 neck, 頭 head, 左肩 shoulder_L,
# 左腕 arm_L, 左ひじ elbow_L, 左手首 wrist_L, 左足 leg_L, 左ひざ knee_L, 左足首 ankle_L,
# 左つま先 "L toe"; 下半身 lower body, the legs' parent, whose rotation the same code moves onto
# センター and 上半身, its siblings' parent). センター > 上半身 > 上半身2 > 首 > 頭; 上半身2 > 左肩 >
# 左腕 > 左ひじ > 左手首; センター > 下半身 > 左足 > 左ひざ > 左足首 > 左つま先. (The English name
# "lower body" is not in that source.) Rotations Z X Y.
def _mmd(names: dict[str, str]) -> tuple[list[Joint], dict[str, str]]:
    def n(name: str) -> str:
        return names[name]

    left = [(n("左肩"), n("上半身2"), (3, 14, 0), None), (n("左腕"), n("左肩"), (12, 0, 0), None),
            (n("左ひじ"), n("左腕"), UPPER_ARM, None), (n("左手首"), n("左ひじ"), FOREARM, HAND),
            (n("左足"), n("下半身"), (9, -8, 0), None), (n("左ひざ"), n("左足"), THIGH, None),
            (n("左足首"), n("左ひざ"), SHANK, None), (n("左つま先"), n("左足首"), TO_BALL, BALL_TO_TIP)]
    right = {n(k): n(k.replace("左", "右")) for k in ("左肩", "左腕", "左ひじ", "左手首", "左足",
                                                   "左ひざ", "左足首", "左つま先")}
    right |= {v + ".end": right[v] + ".end" for v in list(right)}

    def rename(name):
        return right.get(name, name)

    joints = [(n("センター"), None, (0, 0, 0), None), (n("下半身"), n("センター"), (0, 10, 0), None),
              (n("上半身"), n("センター"), (0, 10, 0), None),
              (n("上半身2"), n("上半身"), (0, 14, 0), None),
              (n("首"), n("上半身2"), (0, 24, 0), None), (n("頭"), n("首"), (0, 8, 0), (0, 16, 0))]
    joints += _sides(left, rename)
    expected = _expect({"hip": n("左足"), "knee": n("左ひざ"), "ankle": n("左足首"),
                        "toe": n("左つま先"), "shoulder": n("左腕"), "elbow": n("左ひじ"),
                        "wrist": n("左手首")}, rename, pelvis=n("下半身"), neck=n("首"), head=n("頭"))
    return joints, expected


_MMD_JA = {k: k for k in ("センター", "下半身", "上半身", "上半身2", "首", "頭", "左肩", "左腕", "左ひじ",
                          "左手首", "左足", "左ひざ", "左足首", "左つま先", "右肩", "右腕", "右ひじ",
                          "右手首", "右足", "右ひざ", "右足首", "右つま先")}
_MMD_EN = {"センター": "center", "下半身": "lower body", "上半身": "upper body",
           "上半身2": "upper body2", "首": "neck", "頭": "head", "左肩": "shoulder_L", "左腕": "arm_L",
           "左ひじ": "elbow_L", "左手首": "wrist_L", "左足": "leg_L", "左ひざ": "knee_L",
           "左足首": "ankle_L", "左つま先": "L toe", "右肩": "shoulder_R", "右腕": "arm_R",
           "右ひじ": "elbow_R", "右手首": "wrist_R", "右足": "leg_R", "右ひざ": "knee_R",
           "右足首": "ankle_R", "右つま先": "R toe"}
for _label, _names in (("mmd_japanese", _MMD_JA), ("mmd_romanised", _MMD_EN)):
    _mmd_joints, _mmd_expected = _mmd(_names)
    TOOLS.append(Tool(_label, "find_string '\"左ひざ\"' (VMD loader bone mapping)", _mmd_joints,
                      _mmd_expected))


#: Tools whose import is known to be wrong, with the measured result (none: MotionBuilder HumanIK
#: and Blender Rigify, open in issue 12, map by their presets since issue 33).
XFAIL: dict[str, str] = {}


def _params():
    out = []
    for tool in TOOLS:
        marks = [pytest.mark.xfail(strict=True, reason=XFAIL[tool.name])] if tool.name in XFAIL \
            else []
        out.append(pytest.param(tool, id=tool.name, marks=marks))
    return out


@pytest.mark.parametrize("tool", _params())
def test_tool_skeleton_maps_to_the_joints_a_human_picks_and_round_trips(tool, tmp_path):
    path = tmp_path / f"{tool.name}.bvh"
    path.write_text(tool.text(), encoding="utf-8")
    info, exported = import_and_export(path, tmp_path / "out")
    wrong = {j: (want, info["joints"].get(j)) for j, want in tool.expected.items()
             if info["joints"].get(j) != want}
    assert not wrong, f"{tool.name} ({info['joint_map']}): canonical: (expected, got) {wrong}"
    names, ref = reference_world(path, 0.01, "y")
    ref = ref[info.get("first_file_frame", 0):]
    errors = errors_m(info, exported, names, ref)
    assert set(tool.expected) <= set(errors), sorted(set(tool.expected) - set(errors))
    worst = max(errors, key=lambda j: errors[j])
    assert errors[worst] < 0.1 * MM, f"{worst} off by {errors[worst] * 1e3:.4f} mm"


def test_the_clips_are_the_walk_they_claim(tmp_path):
    """The synthetic walk itself: the left knee bends 0-40 degrees, the thighs swing in
    antiphase and the hips move forward (+Z), on the Xsens clip by independent FK."""
    tool = next(t for t in TOOLS if t.name == "xsens_mvn")
    path = tmp_path / "walk.bvh"
    path.write_text(tool.text())
    names, p = reference_world(path, 0.01, "y")  # metres, Z up: file +Z is -Y here
    hip, knee, ankle = (p[:, names.index(n)] for n in ("LeftHip", "LeftKnee", "LeftAnkle"))
    a, b = knee - hip, ankle - knee
    bend = np.degrees(np.arccos(np.sum(a * b, -1) / np.linalg.norm(a, axis=-1)
                                / np.linalg.norm(b, axis=-1)))
    assert 38.0 < bend.max() <= 40.0 + 1e-6 and bend.min() < 1.0
    forward = -(p[-1, names.index("Hips"), 1] - p[0, names.index("Hips"), 1])
    assert abs(forward - 1.2 * (N_FRAMES - 1) * FRAME_TIME_S) < 1e-6
    left = -(p[:, names.index("LeftAnkle"), 1] - p[:, names.index("LeftHip"), 1])
    right = -(p[:, names.index("RightAnkle"), 1] - p[:, names.index("RightHip"), 1])
    assert np.corrcoef(left, right)[0, 1] < -0.9
