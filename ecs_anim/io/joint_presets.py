"""Matching by names: the naming conventions a source skeleton may follow (:data:`PRESETS`), the
canonical joints every source must provide, a name as compared, a preset resolved on a
skeleton's names and the preset detected from them."""

from __future__ import annotations

import re
from dataclasses import dataclass

from ecs_anim.core.skeleton import JOINTS
from ecs_anim.io.bvh import BvhSkeleton

#: Canonical joints every source must provide (the others can be filled in).
REQUIRED: tuple[str, ...] = (
    "pelvis", "hip_l", "knee_l", "ankle_l", "hip_r", "knee_r", "ankle_r", "neck", "head",
    "shoulder_l", "elbow_l", "wrist_l", "shoulder_r", "elbow_r", "wrist_r",
)


OPTIONAL: tuple[str, ...] = tuple(j for j in JOINTS if j not in REQUIRED)


def _sided(table: dict[str, list[str]], left: str, right: str) -> dict[str, list[str]]:
    """Expand ``{"hip_{s}": ["{S}UpLeg"]}``-style entries for both sides."""
    out: dict[str, list[str]] = {}
    for key, names in table.items():
        if "{s}" in key:
            for side, token in (("l", left), ("r", right)):
                out[key.format(s=side)] = [n.format(S=token, s=token.lower()) for n in names]
        else:
            out[key] = names
    return out


@dataclass(frozen=True)
class Preset:
    """A naming convention: canonical joint -> candidate source names (first present wins).

    ``signature`` names must all be present for the preset to be detected automatically.
    End Sites are named ``<joint>.end``.
    """

    name: str
    description: str
    joints: dict[str, list[str]]
    signature: tuple[str, ...]
    #: Names carry a character prefix up to the first underscore (HumanIK's ``Character1_Hips``,
    #: any character name): matched with it removed, and only on names that have one.
    prefixed: bool = False


PRESETS: dict[str, Preset] = {
    p.name: p
    for p in [
        Preset(
            "ecs_anim", "ecs_anim's own BVH export (canonical names)",
            {j: [j] for j in JOINTS if j not in ("head_top", "hand_l", "hand_r")}
            | {"head_top": ["head.end"], "hand_l": ["wrist_l.end"], "hand_r": ["wrist_r.end"]},
            ("lumbar", "cervical", "clavicle_l"),
        ),
        Preset(
            "cmu_motionbuilder", "CMU, cgspeed MotionBuilder-friendly release (Hips, LeftUpLeg, ...)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}UpLeg"], "knee_{s}": ["{S}Leg"],
                "ankle_{s}": ["{S}Foot"], "toe_{s}": ["{S}ToeBase"], "spine_1": ["Spine"],
                "neck": ["Neck"], "head": ["Head"], "head_top": ["Head.end"],
                "shoulder_{s}": ["{S}Arm"], "elbow_{s}": ["{S}ForeArm"],
                "wrist_{s}": ["{S}Hand"],
            }, "Left", "Right")
            | {"hand_l": ["LFingers", "LeftHandIndex1"], "hand_r": ["RFingers", "RightHandIndex1"]},
            ("LHipJoint", "LowerBack", "Neck1"),
        ),
        Preset(
            "cmu_3dsmax", "CMU, cgspeed 3ds Max-friendly release (LeftHip, LeftKnee, lowerback, ...)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}Hip"], "knee_{s}": ["{S}Knee"],
                "ankle_{s}": ["{S}Ankle"], "toe_{s}": ["{S}Toe"], "spine_1": ["Chest"],
                "neck": ["lowerneck"], "head": ["Head"], "head_top": ["Head.end"],
                "shoulder_{s}": ["{S}Shoulder"], "elbow_{s}": ["{S}Elbow"],
                "wrist_{s}": ["{S}Wrist"],
            }, "Left", "Right") | {"hand_l": ["LFingers"], "hand_r": ["RFingers"]},
            ("LHipJoint", "lowerback", "lowerneck"),
        ),
        Preset(
            "biped_bvh", "3ds Max Biped BVH export (Hips, LeftHip, Chest, CS_BVH, LeftCollar, ...)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}Hip"], "knee_{s}": ["{S}Knee"],
                "ankle_{s}": ["{S}Ankle"], "spine_1": ["Chest"], "spine_2": ["CS_BVH"],
                "neck": ["Neck"], "head": ["Head"], "head_top": ["Head.end"],
                "shoulder_{s}": ["{S}Shoulder"], "elbow_{s}": ["{S}Elbow"],
                "wrist_{s}": ["{S}Wrist"], "hand_{s}": ["{S}Wrist.end"],
            }, "Left", "Right"),
            ("CS_BVH", "LeftCollar"),
        ),
        Preset(
            "biped_bip01", "3ds Max Biped native names (Bip01 Pelvis, Bip01 L Thigh, ...)",
            _sided({
                "pelvis": ["Bip01 Pelvis", "Bip01"], "hip_{s}": ["Bip01 {S} Thigh"],
                "knee_{s}": ["Bip01 {S} Calf"], "ankle_{s}": ["Bip01 {S} Foot"],
                "toe_{s}": ["Bip01 {S} Toe0"], "spine_1": ["Bip01 Spine1"],
                "spine_2": ["Bip01 Spine2"], "neck": ["Bip01 Neck"], "head": ["Bip01 Head"],
                "head_top": ["Bip01 HeadNub", "Bip01 Head.end"],
                "shoulder_{s}": ["Bip01 {S} UpperArm"], "elbow_{s}": ["Bip01 {S} Forearm"],
                "wrist_{s}": ["Bip01 {S} Hand"], "hand_{s}": ["Bip01 {S} Finger2", "Bip01 {S} Hand.end"],
            }, "L", "R"),
            ("Bip01 L Thigh",),
        ),
        Preset(
            "bandai", "Bandai Namco Research Motion Dataset (joint_Root, UpperLeg_L, Toes_L, ...)",
            {
                "pelvis": ["Hips"], "spine_1": ["Spine"], "spine_2": ["Chest"], "neck": ["Neck"],
                "head": ["Head"],
            } | {
                k.format(s=s): [v.format(S=s.upper())]
                for s in ("l", "r")
                for k, v in {
                    "hip_{s}": "UpperLeg_{S}", "knee_{s}": "LowerLeg_{S}", "ankle_{s}": "Foot_{S}",
                    "toe_{s}": "Toes_{S}", "shoulder_{s}": "UpperArm_{S}",
                    "elbow_{s}": "LowerArm_{S}", "wrist_{s}": "Hand_{S}",
                }.items()
            },
            ("joint_Root", "UpperLeg_L"),
        ),
        Preset(
            "mixamo", "Adobe Mixamo (mixamorig:Hips, mixamorig:LeftUpLeg, ...; prefix optional; also Ubisoft LaFAN1, whose toes are LeftToe)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}UpLeg"], "knee_{s}": ["{S}Leg"],
                "ankle_{s}": ["{S}Foot"], "toe_{s}": ["{S}ToeBase", "{S}Toe"],
                "spine_1": ["Spine1"], "spine_2": ["Spine2"], "neck": ["Neck"], "head": ["Head"],
                "head_top": ["HeadTop_End", "Head.end"], "shoulder_{s}": ["{S}Arm"],
                "elbow_{s}": ["{S}ForeArm"], "wrist_{s}": ["{S}Hand"],
                "hand_{s}": ["{S}HandMiddle1", "{S}HandEnd", "{S}Hand.end"],
            }, "Left", "Right"),
            ("Spine2", "LeftUpLeg", "LeftForeArm"),
        ),
        Preset(
            "daz", "Daz Studio / Poser (hip, abdomen, lThigh or lThighBend, lShin, lShldr, ...)",
            _sided({
                "pelvis": ["hip"], "hip_{s}": ["{s}ThighBend", "{s}Thigh"], "knee_{s}": ["{s}Shin"],
                "ankle_{s}": ["{s}Foot"], "toe_{s}": ["{s}Toe"],
                "spine_1": ["abdomenUpper", "abdomen2", "abdomen"],
                "spine_2": ["chestLower", "chest"], "neck": ["neckLower", "neck"],
                "head": ["head"], "head_top": ["head.end"],
                "shoulder_{s}": ["{s}ShldrBend", "{s}Shldr"],
                "elbow_{s}": ["{s}ForearmBend", "{s}ForeArm"], "wrist_{s}": ["{s}Hand"],
                "hand_{s}": ["{s}Mid1", "{s}Hand.end"],
            }, "l", "r"),
            ("hip", "lShin"),
        ),
        Preset(
            "smpl", "SMPL / SMPL-X body joints (Pelvis, L_Hip, Spine1, L_Collar, ... or left_hip)",
            {
                "pelvis": ["Pelvis", "m_avg_Pelvis"], "spine_1": ["Spine2", "spine2", "m_avg_Spine2"],
                "spine_2": ["Spine3", "spine3", "m_avg_Spine3"], "neck": ["Neck", "m_avg_Neck"],
                "head": ["Head", "m_avg_Head"], "head_top": ["Head.end", "m_avg_Head.end"],
            } | {
                k.format(s=s): [v.format(S=S) for v in vs]
                for s, S, long in (("l", "L", "left"), ("r", "R", "right"))
                for k, vs in {
                    "hip_{s}": ["{S}_Hip", f"{long}_hip", "m_avg_{S}_Hip"],
                    "knee_{s}": ["{S}_Knee", f"{long}_knee", "m_avg_{S}_Knee"],
                    "ankle_{s}": ["{S}_Ankle", f"{long}_ankle", "m_avg_{S}_Ankle"],
                    "toe_{s}": ["{S}_Foot", f"{long}_foot", "m_avg_{S}_Foot"],
                    "shoulder_{s}": ["{S}_Shoulder", f"{long}_shoulder", "m_avg_{S}_Shoulder"],
                    "elbow_{s}": ["{S}_Elbow", f"{long}_elbow", "m_avg_{S}_Elbow"],
                    "wrist_{s}": ["{S}_Wrist", f"{long}_wrist", "m_avg_{S}_Wrist"],
                    "hand_{s}": ["{S}_Hand", f"{long}_hand", "m_avg_{S}_Hand"],
                }.items()
            },
            ("Spine3",),
        ),
        Preset(
            "humanik", "Autodesk HumanIK / MotionBuilder characters (Character1_Hips, "
            "Character1_LeftUpLeg, ...: any character prefix)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}UpLeg"], "knee_{s}": ["{S}Leg"],
                "ankle_{s}": ["{S}Foot"], "toe_{s}": ["{S}ToeBase"], "spine_1": ["Spine"],
                "spine_2": ["Spine2", "Spine1"], "neck": ["Neck"], "head": ["Head"],
                "shoulder_{s}": ["{S}Arm"], "elbow_{s}": ["{S}ForeArm"], "wrist_{s}": ["{S}Hand"],
                "hand_{s}": ["{S}HandMiddle1"],
            }, "Left", "Right"),
            ("Hips", "LeftUpLeg", "LeftForeArm"), prefixed=True,
        ),
        Preset(
            "rigify", "Blender Rigify deform bones (DEF-spine, DEF-thigh.L, DEF-upper_arm.L, ...; "
            "the .001 twist halves are not body parts)",
            _sided({
                "pelvis": ["DEF-spine"], "hip_{s}": ["DEF-thigh.{S}"], "knee_{s}": ["DEF-shin.{S}"],
                "ankle_{s}": ["DEF-foot.{S}"], "toe_{s}": ["DEF-toe.{S}"],
                "spine_1": ["DEF-spine.001"], "spine_2": ["DEF-spine.003", "DEF-spine.002"],
                "neck": ["DEF-spine.004"], "head": ["DEF-spine.006", "DEF-spine.005"],
                "shoulder_{s}": ["DEF-upper_arm.{S}"], "elbow_{s}": ["DEF-forearm.{S}"],
                "wrist_{s}": ["DEF-hand.{S}"], "hand_{s}": ["DEF-f_middle.01.{S}"],
            }, "L", "R"),
            ("DEF-spine", "DEF-thigh.L"),
        ),
        Preset(
            "unity_humanoid", "Unity Humanoid and VRM humanoid bone names (Hips, Chest, "
            "LeftUpperLeg, LeftLowerArm, ...; leftUpperLeg in VRM)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}UpperLeg"], "knee_{s}": ["{S}LowerLeg"],
                "ankle_{s}": ["{S}Foot"], "toe_{s}": ["{S}Toes"], "spine_1": ["Spine"],
                "spine_2": ["UpperChest", "Chest"], "neck": ["Neck"], "head": ["Head"],
                "shoulder_{s}": ["{S}UpperArm"], "elbow_{s}": ["{S}LowerArm"],
                "wrist_{s}": ["{S}Hand"], "hand_{s}": ["{S}MiddleProximal"],
            }, "Left", "Right"),
            ("Hips", "LeftUpperLeg", "LeftLowerArm"),
        ),
        Preset(
            "vrm", "VRM models as VRoid Studio names their nodes (J_Bip_C_Hips, J_Bip_L_UpperLeg, ...)",
            _sided({
                "pelvis": ["J_Bip_C_Hips"], "hip_{s}": ["J_Bip_{S}_UpperLeg"],
                "knee_{s}": ["J_Bip_{S}_LowerLeg"], "ankle_{s}": ["J_Bip_{S}_Foot"],
                "toe_{s}": ["J_Bip_{S}_ToeBase"], "spine_1": ["J_Bip_C_Spine"],
                "spine_2": ["J_Bip_C_UpperChest", "J_Bip_C_Chest"], "neck": ["J_Bip_C_Neck"],
                "head": ["J_Bip_C_Head"], "shoulder_{s}": ["J_Bip_{S}_UpperArm"],
                "elbow_{s}": ["J_Bip_{S}_LowerArm"], "wrist_{s}": ["J_Bip_{S}_Hand"],
                "hand_{s}": ["J_Bip_{S}_Middle1"],
            }, "L", "R"),
            ("J_Bip_C_Hips", "J_Bip_L_UpperLeg"),
        ),
        Preset(
            "unreal", "Unreal Engine mannequin (pelvis, spine_01, thigh_l, calf_l, upperarm_l, ...)",
            {
                "pelvis": ["pelvis"], "spine_1": ["spine_02"], "spine_2": ["spine_04", "spine_03"],
                "neck": ["neck_01"], "head": ["head"], "head_top": ["head.end"],
            } | {
                k.format(s=s): [v.format(s=s) for v in vs]
                for s in ("l", "r")
                for k, vs in {
                    "hip_{s}": ["thigh_{s}"], "knee_{s}": ["calf_{s}"], "ankle_{s}": ["foot_{s}"],
                    "toe_{s}": ["ball_{s}"], "shoulder_{s}": ["upperarm_{s}"],
                    "elbow_{s}": ["lowerarm_{s}"], "wrist_{s}": ["hand_{s}"],
                    "hand_{s}": ["middle_01_{s}", "hand_{s}.end"],
                }.items()
            },
            ("spine_01", "thigh_l", "calf_l"),
        ),
    ]
}


def name_key(name: str) -> str:
    """Name as compared: namespace prefixes (``mixamorig:``, ``Bob:``, ``a|b|``) dropped, lower case."""
    return re.split(r"[:|]", name)[-1].strip().lower()


_CHARACTER_PREFIX = re.compile(r"^[^_]+_(?=.)")


def _keys(preset: Preset, skeleton: BvhSkeleton) -> dict[str, int]:
    """The skeleton's names as the preset compares them -> joint index: :func:`name_key`, and
    for a ``prefixed`` preset only the names with a character prefix, without it."""
    keys = [name_key(n) for n in skeleton.names]
    if not preset.prefixed:
        return {k: i for i, k in enumerate(keys)}
    return {_CHARACTER_PREFIX.sub("", k): i for i, k in enumerate(keys) if _CHARACTER_PREFIX.match(k)}


def resolve_preset(preset: Preset, skeleton: BvhSkeleton) -> dict[str, int | None]:
    """Canonical joint -> the skeleton's joint the preset names first (None where none)."""
    index = _keys(preset, skeleton)
    out: dict[str, int | None] = {}
    for canonical, candidates in preset.joints.items():
        out[canonical] = next((index[name_key(c)] for c in candidates if name_key(c) in index), None)
    return out


def _complete(preset_map: dict[str, int | None]) -> bool:
    return all(preset_map.get(j) is not None for j in REQUIRED)


def detect_preset(skeleton: BvhSkeleton) -> Preset | None:
    """The preset whose signature is present and which names every required joint, if any."""
    best: tuple[int, Preset] | None = None
    for preset in PRESETS.values():
        keys = _keys(preset, skeleton)
        if not all(name_key(s) in keys for s in preset.signature):
            continue
        resolved = resolve_preset(preset, skeleton)
        if not _complete(resolved):
            continue
        count = sum(v is not None for v in resolved.values())
        if best is None or count > best[0]:
            best = (count, preset)
    return None if best is None else best[1]


def side_of_name(name: str) -> str | None:
    """The side a joint's name suggests (``LeftHand``, ``hand_l``, ``lShin``): for hints, and
    for left and right where no pose shows which way the body faces (structural matching)."""
    raw = re.split(r"[:|]", name)[-1]
    low = raw.lower()
    if "left" in low or re.search(r"(^|[_\s.\-])l($|[_\s.\-])", low) or re.match(r"^l[A-Z_]", raw):
        return "l"
    if "right" in low or re.search(r"(^|[_\s.\-])r($|[_\s.\-])", low) or re.match(r"^r[A-Z_]", raw):
        return "r"
    return None


def find_joint(skeleton: BvhSkeleton, name: str) -> int | None:
    """Index of a joint by exact name, else by case- and namespace-insensitive name."""
    names = skeleton.names
    if name in names:
        return names.index(name)
    keys = [name_key(n) for n in names]
    return keys.index(name_key(name)) if name_key(name) in keys else None


def preset_summary() -> str:
    """One line per preset, for ``--help`` and error messages."""
    return "\n".join(f"  {p.name:18s} {p.description}" for p in PRESETS.values())
