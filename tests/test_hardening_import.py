"""Import hardening (issue 11): ASCII-only BVH numbers, map mistakes blamed on the map, short error
messages whatever the input holds, and structural matching of skeletons whose joint names say
nothing (``Bone_000``...)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOCAP_DIR, MOTIONS_DIR, require_mocap
from ecs_anim.bvh import parse_bvh
from ecs_anim.importing import canonical_clip
from ecs_anim.skeleton import JOINT_INDEX, JOINTS

WALK = MOTIONS_DIR / "walk.bvh"


def generic_names(text: str) -> str:
    """``text`` with every ROOT and JOINT renamed ``Bone_000``, ``Bone_001``... in file order (End
    Sites stay End Sites), so that no name says what a joint is."""
    numbers = iter(range(1_000_000))
    return re.sub(r"^(\s*(?:ROOT|JOINT)\s+).+?\s*$",
                  lambda m: f"{m.group(1)}Bone_{next(numbers):03d}", text, flags=re.M)


# --- item 16: structural matching on topology and rest geometry ------------------------------

#: One clip of each skeleton convention in ../shared/mocap: CMU (MotionBuilder and 3ds Max
#: releases), 3ds Max Biped (no toes, sole End Sites), Bandai (bones along X at rest; bow has
#: non-zero End Sites, walk zero-length ones).
GENERIC_CLIPS = ("cmu_01_01_playground_jumps.bvh", "cmumax_131_02_start_walk_stop_m.bvh",
                 "cmubiped_10_01_kick_30fps.bvh", "bandai_walk.bvh", "bandai_bow.bvh")


def _same_import(text: str, name: str, up: str = "y") -> tuple[np.ndarray, np.ndarray, str]:
    """Canonical positions of the file as it is and with generic names, and how the latter was
    mapped."""
    original = canonical_clip(parse_bvh(text, name), up=up)
    generic = canonical_clip(parse_bvh(generic_names(text), name), up=up)
    return original.positions, generic.positions, generic.joint_map.how


@pytest.mark.parametrize("name", GENERIC_CLIPS)
def test_generic_joint_names_are_matched_by_structure_as_by_the_preset(name):
    require_mocap()
    original, generic, how = _same_import((MOCAP_DIR / name).read_text(), name)
    assert how == "structure (no preset matched)"
    # Every canonical joint, the filled-in ones (toes, hands, head top, spine) included.
    assert np.abs(generic - original).max() < 1e-6


def test_our_own_export_with_generic_names_is_matched_by_structure():
    original, generic, how = _same_import(WALK.read_text(), "walk.bvh")
    assert how.startswith("structure")
    assert np.abs(generic - original).max() < 1e-6


def test_generic_names_on_a_z_up_file_read_with_up_z():
    """A Z-up capture (FAIR's, Mixamo-like names) read with ``--up z``; the structure also finds
    its ``LeftHandEnd`` joint, which the mixamo preset does not know (and fills in)."""
    require_mocap()
    name = "varied/fair_zup_walk_inch_120hz.bvh"
    if not (MOCAP_DIR / name).exists():
        pytest.skip(f"{name} not in {MOCAP_DIR}")
    original, generic, _ = _same_import((MOCAP_DIR / name).read_text(), name, up="z")
    body = [JOINT_INDEX[j] for j in JOINTS if j not in ("hand_l", "hand_r")]
    assert np.abs(generic[:, body] - original[:, body]).max() < 1e-6
    # Z up in, Z up out: the head is above the pelvis by most of a trunk in every frame.
    rise = generic[:, JOINT_INDEX["head"], 2] - generic[:, JOINT_INDEX["pelvis"], 2]
    assert rise.min() > 0.4
