"""Joint-name presets, detection, structural matching and user maps.

Skeletons in each convention are made from our own exported walk by renaming its joints, so every
preset is exercised on a real hierarchy with known answers.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.core.errors import MappingError
from ecs_anim.core.skeleton import JOINTS
from ecs_anim.io.bvh import parse_bvh
from ecs_anim.io.importing import canonical_clip
from ecs_anim.io.joint_map import map_skeleton
from ecs_anim.io.joint_presets import PRESETS

WALK_TEXT = (MOTIONS_DIR / "walk.bvh").read_text()
HELPERS = ["pelvis_l", "pelvis_r", "lumbar", "cervical", "clavicle_l", "clavicle_r"]


def renamed(text: str, names: dict[str, str]) -> str:
    def sub(m: re.Match[str]) -> str:
        return m.group(1) + names.get(m.group(2), m.group(2))
    return re.sub(r"^(\s*(?:ROOT|JOINT)\s+)(\S+)\s*$", sub, text, flags=re.MULTILINE)


def preset_names(preset_name: str, prefix: str = "") -> dict[str, str]:
    preset = PRESETS[preset_name]
    names = {j: preset.joints[j][0] for j in JOINTS
             if j in preset.joints and not preset.joints[j][0].endswith(".end")
             and j not in ("head_top", "hand_l", "hand_r")}
    spare = [s for s in preset.signature if s not in names.values()]
    for helper in HELPERS:
        names[helper] = spare.pop(0) if spare else f"aux_{helper}"
    return {k: prefix + v for k, v in names.items()}


REFERENCE = canonical_clip(parse_bvh(WALK_TEXT, "walk.bvh")).positions


@pytest.mark.parametrize("preset", [p for p in PRESETS if p != "ecs_anim"])
def test_each_preset_is_detected_and_gives_the_same_motion(preset):
    prefix = {"mixamo": "mixamorig:", "humanik": "Character1_"}.get(preset, "")
    text = renamed(WALK_TEXT, preset_names(preset, prefix))
    clip = canonical_clip(parse_bvh(text, f"{preset}.bvh"))
    assert clip.joint_map.how == f"preset {preset} (detected)"
    # Joints a convention lacks (CMU has no second spine joint) are filled in, not compared.
    assert clip.measured.sum() >= len(JOINTS) - 3
    assert np.abs(clip.positions - REFERENCE)[:, clip.measured].max() < 1e-9


STRUCTURAL = {
    "pelvis": "Root", "hip_l": "L_UpperLegJnt", "knee_l": "L_LowerLegJnt", "ankle_l": "L_FootJnt",
    "toe_l": "L_ToeJnt", "hip_r": "R_UpperLegJnt", "knee_r": "R_LowerLegJnt",
    "ankle_r": "R_FootJnt", "toe_r": "R_ToeJnt", "spine_1": "Torso1", "spine_2": "Torso2",
    "neck": "NeckJnt", "head": "HeadJnt", "shoulder_l": "L_ArmJnt", "elbow_l": "L_ElbowJnt",
    "wrist_l": "L_HandJnt", "shoulder_r": "R_ArmJnt", "elbow_r": "R_ElbowJnt",
    "wrist_r": "R_HandJnt", "pelvis_l": "L_Socket", "pelvis_r": "R_Socket", "lumbar": "Waist",
    "cervical": "NeckBase", "clavicle_l": "L_Clav", "clavicle_r": "R_Clav",
}


def test_unknown_convention_is_matched_by_structure():
    clip = canonical_clip(parse_bvh(renamed(WALK_TEXT, STRUCTURAL), "odd.bvh"))
    assert clip.joint_map.how.startswith("structure")
    assert np.abs(clip.positions - REFERENCE).max() < 1e-9


def test_unmappable_skeleton_lists_missing_parts_and_closest_names():
    names = preset_names("mixamo") | {"wrist_l": "Thing", "wrist_r": "Other"}
    with pytest.raises(MappingError) as err:
        map_skeleton(parse_bvh(renamed(WALK_TEXT, names), "bad.bvh").skeleton, "mixamo")
    message = str(err.value)
    assert "wrist_l" in message and "wrist_r" in message and "closest" in message
    assert "--map" in message and "\n" not in message


def test_user_map_fixes_what_structure_cannot(tmp_path):
    names = STRUCTURAL | {"wrist_l": "Thing", "wrist_r": "Other"}
    user = tmp_path / "map.yaml"
    # Only what structure cannot find: the rest comes from the structural match.
    user.write_text("joints:\n  wrist_l: Thing\n  wrist_r: Other\n")
    clip = canonical_clip(parse_bvh(renamed(WALK_TEXT, names), "bad.bvh"), map_spec=str(user))
    assert str(user) in clip.joint_map.how
    assert np.abs(clip.positions - REFERENCE).max() < 1e-9


def test_requested_preset_and_unknown_preset():
    skeleton = parse_bvh(WALK_TEXT, "walk.bvh").skeleton
    assert map_skeleton(skeleton, "ecs_anim").how == "preset ecs_anim (requested)"
    with pytest.raises(MappingError, match="did you mean 'mixamo'"):
        map_skeleton(skeleton, "mixamoo")
