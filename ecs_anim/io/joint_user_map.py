"""User joint maps (``--map FILE.yaml``): reading one, and blaming its entries that cannot be right."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml

from ecs_anim.core.errors import InputError, compose_yaml, did_you_mean, listed, quoted
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS, PARENTS
from ecs_anim.io.bvh import BvhSkeleton, rest_positions
from ecs_anim.io.joint_presets import PRESETS
from ecs_anim.io.joint_structure import ancestors


def load_user_map(path: str | Path) -> tuple[str | None, dict[str, str], dict[str, int]]:
    """Read a user map YAML: ``{base: PRESET (optional), joints: {canonical: source_name}}``.

    Returns (base preset name, joints, line of each entry). Errors name the file, line and key.
    """
    path = str(path)
    node = compose_yaml(path, "map")
    if node is None or not isinstance(node, yaml.MappingNode):
        raise InputError(path, "a joint map must be a mapping with 'joints:' (and optional 'base:')", 1)
    base: str | None = None
    joints: dict[str, str] = {}
    lines: dict[str, int] = {}
    for key_node, value_node in node.value:
        key = key_node.value
        line = key_node.start_mark.line + 1
        if key == "base":
            base = str(value_node.value)
            if base not in PRESETS:
                raise InputError(path, f"base: unknown preset {quoted(base)}; presets are "
                                       f"{', '.join(PRESETS)}", line)
        elif key == "joints":
            if not isinstance(value_node, yaml.MappingNode):
                raise InputError(path, "joints: expected a mapping canonical_name: source_name", line)
            for k_node, v_node in value_node.value:
                k = k_node.value
                kline = k_node.start_mark.line + 1
                if k not in JOINTS:
                    hint = did_you_mean(k, JOINTS, parenthesized=True)
                    raise InputError(path, f"joints.{k}: unknown canonical joint{hint}; "
                                           f"canonical joints are {listed(JOINTS)} (all in "
                                           "docs/format.md)", kline)
                if not isinstance(v_node, yaml.ScalarNode) or v_node.value in ("", None):
                    raise InputError(path, f"joints.{k}: expected a source joint name", kline)
                joints[k] = str(v_node.value)
                lines[k] = kline
        else:
            hint = did_you_mean(str(key), ["base", "joints"], parenthesized=True)
            raise InputError(path, f"{key}: unknown key{hint}; expected 'base' and 'joints'", line)
    return base, joints, lines


def _hierarchy_parent(joint: str, source: dict[str, int | None]) -> str | None:
    """The nearest mapped canonical ancestor a source must hang below: the canonical parent, but
    for a shoulder the spine under the neck (CMU's clavicles branch off below the neck joint)."""
    parent = PARENTS[JOINT_INDEX[joint]]
    while parent >= 0 and (source[JOINTS[parent]] is None
                           or (joint.startswith("shoulder_") and JOINTS[parent] == "neck")):
        parent = PARENTS[parent]
    return None if parent < 0 else JOINTS[parent]


def check_user_map(skeleton: BvhSkeleton, source: dict[str, int | None], user_path: str,
                   user_lines: dict[str, int], how: str) -> None:
    """Blame the map file, at the entry's line, for an entry that cannot be right: two canonical
    joints on one source joint, a joint not below its canonical parent's, or at its place."""
    rest = rest_positions(skeleton)
    same_place = 1e-6 * max(1.0, float(np.abs(rest).max()))
    owner: dict[int, str] = {}
    for joint, i in source.items():
        if i is None:
            continue
        other = owner.setdefault(i, joint)
        if other != joint and (joint in user_lines or other in user_lines):
            entry, first = (joint, other) if joint in user_lines else (other, joint)
            given = f"joints.{first} (line {user_lines[first]})" if first in user_lines else \
                f"{first} by {how.split(' + ')[0]}"
            raise InputError(user_path, f"joints.{entry}: {quoted(skeleton.names[i])} is already "
                                        f"{given}; each canonical joint needs a joint of its own",
                             user_lines[entry])
    for joint in JOINTS:
        parent = _hierarchy_parent(joint, source)
        if source[joint] is None or parent is None or not {joint, parent} & user_lines.keys():
            continue
        i, p = source[joint], source[parent]
        assert i is not None and p is not None
        entry = joint if joint in user_lines else parent
        pair = f"{quoted(skeleton.names[i])} ({joint}) is {{}} {quoted(skeleton.names[p])} ({parent})"
        if p not in ancestors(skeleton, i):
            raise InputError(user_path, f"joints.{entry}: {pair.format('not below')} in "
                                        f"{skeleton.path}", user_lines[entry])
        if PARENTS[JOINT_INDEX[joint]] == JOINT_INDEX[parent] and \
                float(np.linalg.norm(rest[i] - rest[p])) <= same_place:
            raise InputError(user_path, f"joints.{entry}: {pair.format('at the place of')} at "
                                        "rest (a bone of zero length)", user_lines[entry])
