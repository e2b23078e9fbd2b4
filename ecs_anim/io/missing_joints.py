"""The error for body parts a skeleton's map lacks: the joints named most like them, and what to
give instead."""

from __future__ import annotations

import difflib

import numpy as np

from ecs_anim.core.errors import listed, quoted
from ecs_anim.io.bvh import BvhSkeleton
from ecs_anim.io.joint_presets import name_key, side_of_name

#: Words a body part's joints are often named with, to find the names most like a missing part.
_PART_WORDS = {"pelvis": "hips pelvis root", "hip": "upleg thigh hip", "knee": "leg knee shin calf",
               "ankle": "foot ankle", "neck": "neck", "head": "head", "shoulder": "arm shoulder",
               "elbow": "forearm elbow", "wrist": "hand wrist"}
#: Missing parts named in an error, each with this many closest joint names; the rest counted.
HINTED_PARTS, HINTS_PER_PART = 2, 2


def missing_parts_message(skeleton: BvhSkeleton, missing: list[str], problems: list[str]) -> str:
    """One line: the first missing parts with the joints named most like them, the count of the
    others, why, and what to give instead."""
    names = [j.name for j in skeleton.joints if not j.is_end_site]
    keys = [name_key(n) for n in names]
    parts = []
    for m in missing[:HINTED_PARTS]:
        base, _, side = m.partition("_")
        # Closest names: similarity to the part's usual words, the right side slightly preferred.
        matcher = difflib.SequenceMatcher()
        score = np.zeros(len(names))
        for word in [base] + _PART_WORDS.get(base, "").split():
            matcher.set_seq2(word)
            for k, key in enumerate(keys):
                matcher.set_seq1(key)
                if matcher.real_quick_ratio() > score[k] and matcher.quick_ratio() > score[k]:
                    score[k] = max(score[k], matcher.ratio())
        score += [0.1 if side and side_of_name(n) == side else 0.0 for n in names]
        closest = [names[k] for k in np.argsort(-score, kind="stable")[:HINTS_PER_PART]]
        parts.append(f"{m} (closest: {listed(quoted(n) for n in closest) or 'none'})")
    found_parts = listed(parts + missing[len(parts):], HINTED_PARTS)
    why = f" ({'; '.join(problems)})" if problems else ""
    return f"cannot find these body parts in the skeleton: {found_parts}{why}; {GIVE_A_MAP}"


#: What to give when matching fails, ending every such error.
GIVE_A_MAP = ("give --map PRESET or FILE.yaml (joints: {canonical: source_name}); presets: "
              "ecs-anim import --help")
