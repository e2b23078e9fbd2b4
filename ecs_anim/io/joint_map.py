"""Which source joint is which canonical body part: the match (:func:`map_skeleton`) and its
result (:class:`JointMap`).

A source skeleton (BVH hierarchy, names in any convention) is matched to the canonical joints of
:mod:`ecs_anim.core.skeleton` by, in order:

1. a user YAML map (``--map FILE.yaml``, :mod:`ecs_anim.io.joint_user_map`), which may name a
   preset to start from and override single joints;
2. a named preset (``--map mixamo``), or the preset detected from the joint names
   (:mod:`ecs_anim.io.joint_presets`);
3. failing both, a structural match on the hierarchy and its lengths alone (names are read only
   to tell left from right when no pose shows it): the legs, the spine and the arms are the
   long branches, left and right from where the knees bend and the toes point (see
   :func:`~ecs_anim.io.joint_structure.structural_map`).

Canonical joints that a skeleton does not have are filled in by the importer: ``spine_1`` /
``spine_2`` between the pelvis and the neck, ``toe_*``, ``hand_*`` and ``head_top`` from the
orientation of the joint they hang from (see :mod:`ecs_anim.io.importing`), as are end parts too
short to be one (a 0.1 mm End Site at the ankle is no toe: :data:`END_PARTS`).
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import InputError, MappingError, did_you_mean, listed, quoted
from ecs_anim.core.rotations import normalize
from ecs_anim.core.skeleton import JOINTS
from ecs_anim.io.bvh import BvhSkeleton, rest_positions
from ecs_anim.io.joint_presets import (
    OPTIONAL,
    PRESETS,
    REQUIRED,
    detect_preset,
    find_joint,
    resolve_preset,
)
from ecs_anim.io.joint_structure import common_ancestor, structural_map
from ecs_anim.io.joint_user_map import check_user_map, load_user_map
from ecs_anim.io.missing_joints import missing_parts_message

F64 = NDArray[np.float64]


@dataclass
class JointMap:
    """The result of matching: canonical joint -> source joint index (None: filled in).

    ``thorax`` is the source joint whose orientation is the thorax (the lowest common ancestor
    of the shoulders and head), ``how`` says how the map was found, for the user.
    """

    source: dict[str, int | None]
    thorax: int
    how: str
    names: dict[str, str | None] = field(default_factory=dict)


# --- structural matching ---------------------------------------------------------------------


# --- user maps --------------------------------------------------------------------------------


def map_skeleton(skeleton: BvhSkeleton, map_spec: str | None = None,
                 poses: F64 | None = None) -> JointMap:
    """Match ``skeleton`` to the canonical joints. ``map_spec``: None (detect), a preset name,
    or a path to a user YAML map; ``poses`` (n_poses, n_joints, 3): joint positions in file axes
    that tell left from right in a structural match (see :func:`~ecs_anim.io.joint_structure.structural_map`). Raises
    :class:`MappingError` / :class:`InputError`."""
    user: dict[str, str] = {}
    user_lines: dict[str, int] = {}
    base: str | None = None
    user_path: str | None = None
    if map_spec is not None:
        if map_spec in PRESETS:
            base = map_spec
        elif map_spec.endswith((".yaml", ".yml")) or Path(map_spec).exists():
            user_path = map_spec
            base, user, user_lines = load_user_map(map_spec)
        else:
            hint = did_you_mean(map_spec, list(PRESETS), parenthesized=True)
            raise MappingError(f"--map {map_spec}: not a preset nor a YAML file{hint}; presets: "
                               f"{', '.join(PRESETS)}")
    if base is not None:
        preset = PRESETS[base]
        found = resolve_preset(preset, skeleton)
        how = f"preset {base}" + (" (requested)" if user_path is None else f" + {user_path}")
    else:
        detected = detect_preset(skeleton)
        if detected is not None:
            found = resolve_preset(detected, skeleton)
            how = f"preset {detected.name} (detected)"
        else:
            # With a user map, a partial structural match is completed by the user's entries.
            found = structural_map(skeleton, poses, partial=bool(user))
            how = "structure (no preset matched)"
        if user_path is not None:
            how += f" + {user_path}"
    for canonical, source_name in user.items():
        i = find_joint(skeleton, source_name)
        if i is None:
            close = difflib.get_close_matches(source_name, skeleton.names, n=3)
            raise InputError(user_path, f"joints.{canonical}: no joint {quoted(source_name)} in "
                                        f"{skeleton.path} (closest: "
                                        f"{listed(quoted(n) for n in close) or 'none'})",
                             user_lines[canonical])
        found[canonical] = i
    missing = [j for j in REQUIRED if found.get(j) is None]
    if missing:
        raise MappingError(missing_parts_message(skeleton, missing, [f"using {how}"]))
    source = {j: found.get(j) for j in JOINTS}
    # Zero-length End Sites (Bandai) carry no information: fill those parts in instead.
    for j in OPTIONAL:
        i = source[j]
        if i is not None and skeleton.joints[i].is_end_site and \
                np.linalg.norm(skeleton.joints[i].offset) < 1e-9:
            source[j] = None
    # Hand ends and the head top a preset does not name: the End Site below wrist / head.
    for end, parent in (("hand_l", "wrist_l"), ("hand_r", "wrist_r"), ("head_top", "head")):
        if source[end] is None:
            ends = [c for c in skeleton.children(source[parent])  # type: ignore[arg-type]
                    if skeleton.joints[c].is_end_site
                    and np.linalg.norm(skeleton.joints[c].offset) > 1e-9]
            source[end] = ends[0] if len(ends) == 1 else None
    # Toes a skeleton lacks: the End Site below the ankle when it is the toe tip (Daz, Perception
    # Neuron, OptiTrack), not when it marks the sole straight below (Biped).
    for side in "lr":
        if source[f"toe_{side}"] is None:
            source[f"toe_{side}"] = _toe_end_site(skeleton, source[f"knee_{side}"],  # type: ignore[arg-type]
                                                  source[f"ankle_{side}"])  # type: ignore[arg-type]
    _drop_degenerate_ends(skeleton, source, keep=set(user))
    if user_path is not None:
        check_user_map(skeleton, source, user_path, user_lines, how)
    thorax = common_ancestor(skeleton, [source["shoulder_l"], source["shoulder_r"], source["head"]])  # type: ignore[list-item]
    names = {j: (None if i is None else skeleton.names[i]) for j, i in source.items()}
    return JointMap(source=source, thorax=thorax, how=how, names=names)


def unused_joints(skeleton: BvhSkeleton, jmap: JointMap) -> list[str]:
    """Joints (End Sites aside) that move no mapped joint: leaves and chains the canonical body
    has no part for (fingers, eyes, twist and IK helpers, props), in file order. Helper joints
    above the pelvis (a ``Reference`` or ``Armature`` root) do move it and are not listed."""
    mapped = {i for i in jmap.source.values() if i is not None}
    carries = [i in mapped for i in range(len(skeleton.joints))]
    for i in range(len(skeleton.joints) - 1, 0, -1):  # file order is topological
        parent = skeleton.joints[i].parent
        if parent >= 0 and carries[i]:
            carries[parent] = True
    return [j.name for j, used in zip(skeleton.joints, carries, strict=True)
            if not used and not j.is_end_site]


#: End parts and the joint each hangs from, with the shortest plausible length of that segment as
#: a fraction of the leg (thigh + shank at rest). A foot (ankle to the ball) is 0.12-0.23 of it in
#: the dev files; hands (CMU's wrist-to-knuckle bone: 0.03) and head tops (a Daz head End Site:
#: 0.012) may be short, but not under 1 %.
END_PARTS: dict[str, tuple[str, float]] = {
    "toe_l": ("ankle_l", 0.05), "toe_r": ("ankle_r", 0.05), "hand_l": ("wrist_l", 0.01),
    "hand_r": ("wrist_r", 0.01), "head_top": ("head", 0.01),
}


def _drop_degenerate_ends(skeleton: BvhSkeleton, source: dict[str, int | None],
                          keep: set[str]) -> None:
    """Set to None (to be filled in from the joint they hang from) the end parts in ``source``
    closer to that joint at rest than a plausible fraction of the leg (:data:`END_PARTS`): a 0.1
    mm End Site at the ankle marks no toe. Parts in ``keep`` (named by the user) stay."""
    rest = rest_positions(skeleton)

    def gap(a: str, b: str) -> float:
        return float(np.linalg.norm(rest[source[a]] - rest[source[b]]))

    leg = 0.5 * sum(gap(f"hip_{s}", f"knee_{s}") + gap(f"knee_{s}", f"ankle_{s}") for s in "lr")
    for end, (parent, fraction) in END_PARTS.items():
        if end not in keep and source[end] is not None and gap(end, parent) < fraction * leg:
            source[end] = None


def _toe_end_site(skeleton: BvhSkeleton, knee: int, ankle: int) -> int | None:
    """The ankle's one End Site when it points more across the shank than along it (a toe tip
    ahead of the ankle, within 45 degrees of square to the shank), else None (a sole marker
    below the ankle, or no single End Site)."""
    ends = [c for c in skeleton.children(ankle) if skeleton.joints[c].is_end_site]
    if len(ends) != 1 or any(not skeleton.joints[c].is_end_site for c in skeleton.children(ankle)):
        return None
    rest = rest_positions(skeleton)
    shank = normalize(rest[ankle] - rest[knee])
    tip = skeleton.joints[ends[0]].offset
    along = float(np.dot(tip, shank))
    across = float(np.linalg.norm(tip - along * shank))
    return ends[0] if across > max(abs(along), 1e-9) else None


