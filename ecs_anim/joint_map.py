"""Which source joint is which canonical body part.

A source skeleton (BVH hierarchy, names in any convention) is matched to the canonical joints of
:mod:`ecs_anim.skeleton` by, in order:

1. a user YAML map (``--map FILE.yaml``), which may name a preset to start from and override
   single joints;
2. a named preset (``--map mixamo``), or the preset detected from the joint names;
3. failing both, a structural match: hands and feet found by name, everything else by the
   hierarchy (the upper arm is the nearest ancestor of the elbow at a different place, ...).

Canonical joints that a skeleton does not have are filled in by the importer: ``spine_1`` /
``spine_2`` between the pelvis and the neck, ``toe_*``, ``hand_*`` and ``head_top`` from the
orientation of the joint they hang from (see :mod:`ecs_anim.importing`).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from .bvh import BvhSkeleton, rest_positions
from .errors import InputError, MappingError, compose_yaml
from .skeleton import JOINTS

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
            "mixamo", "Adobe Mixamo (mixamorig:Hips, mixamorig:LeftUpLeg, ...; prefix optional)",
            _sided({
                "pelvis": ["Hips"], "hip_{s}": ["{S}UpLeg"], "knee_{s}": ["{S}Leg"],
                "ankle_{s}": ["{S}Foot"], "toe_{s}": ["{S}ToeBase"], "spine_1": ["Spine1"],
                "spine_2": ["Spine2"], "neck": ["Neck"], "head": ["Head"],
                "head_top": ["HeadTop_End", "Head.end"], "shoulder_{s}": ["{S}Arm"],
                "elbow_{s}": ["{S}ForeArm"], "wrist_{s}": ["{S}Hand"],
                "hand_{s}": ["{S}HandMiddle1", "{S}Hand.end"],
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


def _key(name: str) -> str:
    """Name as compared: namespace prefixes (``mixamorig:``, ``Bob:``, ``a|b|``) dropped, lower case."""
    return re.split(r"[:|]", name)[-1].strip().lower()


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


def _resolve_preset(preset: Preset, skeleton: BvhSkeleton) -> dict[str, int | None]:
    index = {_key(n): i for i, n in enumerate(skeleton.names)}
    out: dict[str, int | None] = {}
    for canonical, candidates in preset.joints.items():
        out[canonical] = next((index[_key(c)] for c in candidates if _key(c) in index), None)
    return out


def _complete(preset_map: dict[str, int | None]) -> bool:
    return all(preset_map.get(j) is not None for j in REQUIRED)


def detect_preset(skeleton: BvhSkeleton) -> Preset | None:
    """The preset whose signature is present and which names every required joint, if any."""
    keys = {_key(n) for n in skeleton.names}
    best: tuple[int, Preset] | None = None
    for preset in PRESETS.values():
        if not all(_key(s) in keys for s in preset.signature):
            continue
        resolved = _resolve_preset(preset, skeleton)
        if not _complete(resolved):
            continue
        count = sum(v is not None for v in resolved.values())
        if best is None or count > best[0]:
            best = (count, preset)
    return None if best is None else best[1]


# --- structural matching ---------------------------------------------------------------------

def _side_of(name: str) -> str | None:
    raw = re.split(r"[:|]", name)[-1]
    low = raw.lower()
    if "left" in low or re.search(r"(^|[_\s.\-])l($|[_\s.\-])", low) or re.match(r"^l[A-Z_]", raw):
        return "l"
    if "right" in low or re.search(r"(^|[_\s.\-])r($|[_\s.\-])", low) or re.match(r"^r[A-Z_]", raw):
        return "r"
    return None


def _ancestors(skeleton: BvhSkeleton, j: int) -> list[int]:
    out = []
    p = skeleton.joints[j].parent
    while p >= 0:
        out.append(p)
        p = skeleton.joints[p].parent
    return out


def _lca(skeleton: BvhSkeleton, joints: list[int]) -> int:
    chains = [[j] + _ancestors(skeleton, j) for j in joints]
    common = set(chains[0]).intersection(*chains[1:])
    return next(j for j in chains[0] if j in common)


def _nearest_distinct_ancestor(skeleton: BvhSkeleton, rest: np.ndarray, j: int,
                               stop: set[int] | None = None) -> int | None:
    """Nearest ancestor at another place in the rest pose, skipping twist/roll helpers."""
    for a in _ancestors(skeleton, j):
        if stop and a in stop:
            return None
        name = skeleton.joints[a].name.lower()
        if "twist" in name or "roll" in name:
            continue
        if np.linalg.norm(rest[a] - rest[j]) > 1e-6 * max(1.0, float(np.abs(rest).max())):
            return a
    return None


def _by_keyword(skeleton: BvhSkeleton, side: str, words: tuple[str, ...],
                exclude: tuple[str, ...] = ()) -> list[int]:
    out = []
    for i, joint in enumerate(skeleton.joints):
        if joint.is_end_site:
            continue
        low = _key(joint.name)
        if any(w in low for w in words) and not any(x in low for x in exclude):
            if _side_of(joint.name) == side:
                out.append(i)
    return out


def structural_map(skeleton: BvhSkeleton, given: dict[str, int] | None = None,
                   partial: bool = False) -> dict[str, int | None]:
    """Match by structure plus a few unambiguous name cues.

    ``given`` joints (from a user map) are taken as decided and the rest is derived from them
    (a given wrist finds its elbow and shoulder). Raises :class:`MappingError` naming what is
    missing, unless ``partial`` (then the parts it could not find are None).
    """
    given = given or {}
    rest = rest_positions(skeleton)
    found: dict[str, int | None] = {}
    problems: list[str] = []

    def topmost(cands: list[int]) -> int | None:
        if not cands:
            return None
        depth = {c: len(_ancestors(skeleton, c)) for c in cands}
        best = min(depth.values())
        tops = [c for c in cands if depth[c] == best]
        return tops[0] if len(tops) == 1 else None

    for side in ("l", "r"):
        ankle = given.get(f"ankle_{side}", topmost(_by_keyword(skeleton, side, ("foot", "ankle"))))
        wrist = given.get(f"wrist_{side}", topmost(_by_keyword(skeleton, side, ("hand", "wrist"))))
        if ankle is None:
            problems.append(f"ankle_{side}: no single joint named like a {_SIDE_WORD[side]} foot or ankle")
        if wrist is None:
            problems.append(f"wrist_{side}: no single joint named like a {_SIDE_WORD[side]} hand or wrist")
        found[f"ankle_{side}"], found[f"wrist_{side}"] = ankle, wrist
        for distal, mid, prox in (("ankle", "knee", "hip"), ("wrist", "elbow", "shoulder")):
            d = found[f"{distal}_{side}"]
            m = given.get(f"{mid}_{side}",
                          None if d is None else _nearest_distinct_ancestor(skeleton, rest, d))
            p = given.get(f"{prox}_{side}",
                          None if m is None else _nearest_distinct_ancestor(skeleton, rest, m))
            found[f"{mid}_{side}"], found[f"{prox}_{side}"] = m, p
        toe_cands = [] if ankle is None else [
            c for c in _by_keyword(skeleton, side, ("toe", "ball")) if ankle in _ancestors(skeleton, c)
        ]
        found[f"toe_{side}"] = topmost(toe_cands)
    heads = [i for i, j in enumerate(skeleton.joints)
             if not j.is_end_site and "head" in _key(j.name) and "top" not in _key(j.name)
             and _side_of(j.name) is None]
    head = given.get("head", topmost(heads))
    if head is None:
        problems.append("head: no single joint named like a head")
    found["head"] = head
    if found.get("hip_l") is not None and found.get("hip_r") is not None and head is not None:
        pelvis = _lca(skeleton, [found["hip_l"], found["hip_r"], head])  # type: ignore[list-item]
        found["pelvis"] = pelvis
        necks = [i for i in [head] + _ancestors(skeleton, head)
                 if "neck" in _key(skeleton.joints[i].name)]
        found["neck"] = necks[-1] if necks else _nearest_distinct_ancestor(skeleton, rest, head)
        # Spine joints strictly between pelvis and neck, at distinct places.
        neck = found["neck"]
        if neck is not None:
            chain = [a for a in reversed(_ancestors(skeleton, neck)) if a not in
                     [pelvis] + _ancestors(skeleton, pelvis)]
            distinct = [a for a in chain
                        if np.linalg.norm(rest[a] - rest[pelvis]) > 1e-9
                        and np.linalg.norm(rest[a] - rest[neck]) > 1e-9]
            found["spine_1"] = distinct[len(distinct) // 3] if distinct else None
            found["spine_2"] = distinct[(2 * len(distinct)) // 3] if len(distinct) >= 2 else None
            if found["spine_1"] == found["spine_2"]:
                found["spine_2"] = None
    found.update(given)
    # Ends: the End Site below the head and each wrist's farthest descendant, if any.
    if head is not None:
        found["head_top"] = _farthest_descendant(skeleton, rest, head)
    for side in "lr":
        wrist = found.get(f"wrist_{side}")
        found[f"hand_{side}"] = None if wrist is None else _farthest_descendant(skeleton, rest, wrist)
    missing = [j for j in REQUIRED if found.get(j) is None]
    if missing and not partial:
        raise MappingError(_missing_message(skeleton, missing, problems))
    return found


def _farthest_descendant(skeleton: BvhSkeleton, rest: np.ndarray, j: int) -> int | None:
    """The descendant of ``j`` farthest from it in the rest pose (None if all coincide)."""
    best, best_d = None, 1e-9
    stack = skeleton.children(j)
    while stack:
        c = stack.pop()
        d = float(np.linalg.norm(rest[c] - rest[j]))
        if d > best_d:
            best, best_d = c, d
        stack.extend(skeleton.children(c))
    return best


_SIDE_WORD = {"l": "left", "r": "right"}
_PART_WORDS = {"pelvis": "hips pelvis root", "hip": "upleg thigh hip", "knee": "leg knee shin calf",
               "ankle": "foot ankle", "neck": "neck", "head": "head", "shoulder": "arm shoulder",
               "elbow": "forearm elbow", "wrist": "hand wrist"}


def _missing_message(skeleton: BvhSkeleton, missing: list[str], problems: list[str]) -> str:
    names = [j.name for j in skeleton.joints if not j.is_end_site]
    parts = []
    for m in missing:
        base, _, side = m.partition("_")
        # Closest names: similarity to the part's usual words, the right side slightly preferred.
        words = [base] + _PART_WORDS.get(base, "").split()
        scored = sorted(names, key=lambda n: -(max(
            difflib.SequenceMatcher(None, w, _key(n)).ratio() for w in words)
            + (0.1 if side and _side_of(n) == side else 0.0)))
        parts.append(f"{m} (closest: {', '.join(scored[:3]) if scored else 'none'})")
    why = f" ({'; '.join(problems)})" if problems else ""
    return (f"cannot find these body parts in the skeleton: {'; '.join(parts)}{why}. "
            f"Give a map with --map FILE.yaml (joints: {{canonical: source_name}}) or a preset "
            f"({', '.join(PRESETS)}). Joints in the file: {', '.join(names)}")


# --- user maps --------------------------------------------------------------------------------

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
                raise InputError(path, f"base: unknown preset {base!r}; presets are "
                                       f"{', '.join(PRESETS)}", line)
        elif key == "joints":
            if not isinstance(value_node, yaml.MappingNode):
                raise InputError(path, "joints: expected a mapping canonical_name: source_name", line)
            for k_node, v_node in value_node.value:
                k = k_node.value
                kline = k_node.start_mark.line + 1
                if k not in JOINTS:
                    close = difflib.get_close_matches(k, JOINTS, n=1)
                    hint = f" (did you mean {close[0]!r}?)" if close else ""
                    raise InputError(path, f"joints.{k}: unknown canonical joint{hint}; "
                                           f"canonical joints are {', '.join(JOINTS)}", kline)
                if not isinstance(v_node, yaml.ScalarNode) or v_node.value in ("", None):
                    raise InputError(path, f"joints.{k}: expected a source joint name", kline)
                joints[k] = str(v_node.value)
                lines[k] = kline
        else:
            close = difflib.get_close_matches(str(key), ["base", "joints"], n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise InputError(path, f"{key}: unknown key{hint}; expected 'base' and 'joints'", line)
    return base, joints, lines


def _find(skeleton: BvhSkeleton, name: str) -> int | None:
    """Index of a joint by exact name, else by case- and namespace-insensitive name."""
    names = skeleton.names
    if name in names:
        return names.index(name)
    keys = [_key(n) for n in names]
    return keys.index(_key(name)) if _key(name) in keys else None


def map_skeleton(skeleton: BvhSkeleton, map_spec: str | None = None) -> JointMap:
    """Match ``skeleton`` to the canonical joints. ``map_spec``: None (detect), a preset name,
    or a path to a user YAML map. Raises :class:`MappingError` / :class:`InputError`."""
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
            close = difflib.get_close_matches(map_spec, list(PRESETS), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise MappingError(f"--map {map_spec}: not a preset nor a YAML file{hint}; presets: "
                               f"{', '.join(PRESETS)}")
    if base is not None:
        preset = PRESETS[base]
        found = _resolve_preset(preset, skeleton)
        how = f"preset {base}" + (" (requested)" if user_path is None else f" + {user_path}")
    else:
        detected = detect_preset(skeleton)
        if detected is not None:
            found = _resolve_preset(detected, skeleton)
            how = f"preset {detected.name} (detected)"
        else:
            # With a user map, a partial structural match is completed by the user's entries.
            given = {k: _find(skeleton, v) for k, v in user.items()}
            found = structural_map(skeleton, {k: i for k, i in given.items() if i is not None},
                                   partial=bool(user))
            how = "structure and names (no preset matched)"
        if user_path is not None:
            how += f" + {user_path}"
    for canonical, source_name in user.items():
        i = _find(skeleton, source_name)
        if i is None:
            close = difflib.get_close_matches(source_name, skeleton.names, n=3)
            raise InputError(user_path, f"joints.{canonical}: no joint {source_name!r} in "
                                        f"{skeleton.path} (closest: {', '.join(close) or 'none'})",
                             user_lines[canonical])
        found[canonical] = i
    missing = [j for j in REQUIRED if found.get(j) is None]
    if missing:
        raise MappingError(_missing_message(skeleton, missing, [f"using {how}"]))
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
    thorax = _lca(skeleton, [source["shoulder_l"], source["shoulder_r"], source["head"]])  # type: ignore[list-item]
    names = {j: (None if i is None else skeleton.names[i]) for j, i in source.items()}
    return JointMap(source=source, thorax=thorax, how=how, names=names)


def preset_summary() -> str:
    """One line per preset, for ``--help`` and error messages."""
    return "\n".join(f"  {p.name:18s} {p.description}" for p in PRESETS.values())
