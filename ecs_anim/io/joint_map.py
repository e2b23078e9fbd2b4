"""Which source joint is which canonical body part.

A source skeleton (BVH hierarchy, names in any convention) is matched to the canonical joints of
:mod:`ecs_anim.core.skeleton` by, in order:

1. a user YAML map (``--map FILE.yaml``), which may name a preset to start from and override
   single joints;
2. a named preset (``--map mixamo``), or the preset detected from the joint names;
3. failing both, a structural match on the hierarchy and its lengths alone (names are read only
   to tell left from right when no pose shows it): the legs, the spine and the arms are the
   long branches, left and right from where the knees bend and the toes point (see
   :func:`structural_map`).

Canonical joints that a skeleton does not have are filled in by the importer: ``spine_1`` /
``spine_2`` between the pelvis and the neck, ``toe_*``, ``hand_*`` and ``head_top`` from the
orientation of the joint they hang from (see :mod:`ecs_anim.io.importing`).
"""

from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from numpy.typing import NDArray

from ecs_anim.core.errors import (
    InputError,
    MappingError,
    compose_yaml,
    did_you_mean,
    listed,
    quoted,
)
from ecs_anim.core.rotations import normalize
from ecs_anim.core.skeleton import JOINT_INDEX, JOINTS, PARENTS
from ecs_anim.io.bvh import BvhSkeleton, rest_positions

F64 = NDArray[np.float64]

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
    """The side a joint's name suggests (``LeftHand``, ``hand_l``, ``lShin``): for hints, and
    for left and right where no pose shows which way the body faces (:func:`_named_leftness`)."""
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


#: A branch is a major one (a limb, the spine, the neck and head) when it reaches at least this
#: fraction as far as the second-longest branch leaving the same joint (the other arm: a prop in
#: one hand makes its arm the longest by far); fingers, toes and twist helpers reach less (a neck
#: and head reaches about 0.35 as far as an arm from the thorax).
MAJOR_BRANCH_FRACTION = 0.15


#: Limbs are looked for among this many of a joint's farthest-reaching branches (a hub of a
#: generated 5,000-branch skeleton would otherwise compare 12 million pairs).
COMPARED_BRANCHES = 6


#: A joint named as the end of a chain (Mixamo's ``HeadTop_End``, Biped's ``HeadNub``,
#: Blender's ``head_end``, Maya's ``head_tip``) marks where the chain ends, as an End Site does.
_CHAIN_END_NAME = re.compile(r"(end|nub|tip|top|site)[\d_.\-\s]*$", re.IGNORECASE)


class _Tree:
    """A skeleton's hierarchy and rest lengths, as structural matching reads them.

    ``bone`` (n_joints,): distance from each joint to its parent at rest (0 for the root);
    ``is_end_site`` (n_joints,): End Sites, which mark where a chain ends rather than a joint;
    ``reach`` (n_joints,): the longest path from a joint down to a leaf; ``onward``: the child on
    that path (-1 at a leaf); ``size``: joints in each subtree. Joints at the place of their parent
    (zero offsets, zero-length End Sites) are *at the same place*; a run of them is one place.
    """

    def __init__(self, skeleton: BvhSkeleton):
        rest = rest_positions(skeleton)
        n = len(skeleton.joints)
        self.parents = np.array([j.parent for j in skeleton.joints])
        self.is_end_site = [j.is_end_site for j in skeleton.joints]
        self.names = [j.name for j in skeleton.joints]
        self.children: list[list[int]] = [[] for _ in range(n)]
        for i, p in enumerate(self.parents):
            if p >= 0:
                self.children[p].append(i)
        offsets = rest - rest[np.maximum(self.parents, 0)]
        self.bone = np.linalg.norm(offsets, axis=1)
        self.same_place = self.bone <= 1e-6 * max(1.0, float(np.abs(rest).max()))
        self.reach = np.zeros(n)
        self.onward = np.full(n, -1)
        self.size = np.ones(n, dtype=int)
        # File order is topological, so children are done before their parent; on a tie the
        # first child in the file wins.
        for i in range(n - 1, 0, -1):
            p = self.parents[i]
            if p < 0:
                continue
            self.size[p] += self.size[i]
            if self.branch(i) >= self.reach[p]:
                self.reach[p], self.onward[p] = self.branch(i), i

    def named_end(self, j: int) -> bool:
        """Whether joint ``j`` is named as the end of a chain (:data:`_CHAIN_END_NAME`)."""
        return bool(_CHAIN_END_NAME.search(self.names[j].split(":")[-1]))

    def branch(self, child: int) -> float:
        """How far the branch starting at ``child`` reaches from ``child``'s parent."""
        return float(self.bone[child] + self.reach[child])

    def hub_below(self, start: int) -> tuple[int, list[int]] | None:
        """The first joint from ``start`` down its longest path where three or more major branches
        leave, two of them limbs (the pelvis: two legs and the spine; the thorax: two arms and the
        neck), with them. Single-bone leaves reaching as far (IK targets at the feet under a
        root) make no hub."""
        j = start
        while j >= 0:
            reaches = sorted((self.branch(c) for c in self.children[j]), reverse=True)
            yardstick = reaches[1] if len(reaches) > 1 else self.reach[j]
            major = [c for c in self.children[j]
                     if yardstick > 0 and self.branch(c) >= MAJOR_BRANCH_FRACTION * yardstick]
            if len(major) >= 3 and sum(self.is_limb(c) for c in major) >= 2:
                return j, major
            if len(major) == 2 and all(self.is_limb(c) for c in major):
                # The limbs may leave a child whose sibling carries the rest (MikuMikuDance's
                # lower body under the centre, its upper body beside it): that child is the hub.
                for sub, rest in (major, major[::-1]):
                    limbs = [c for c in self.children[sub] if self.is_limb(c)]
                    if len(limbs) == 2:
                        return sub, [*limbs, rest]
            j = int(self.onward[j])
        return None

    def is_limb(self, branch: int) -> bool:
        """Whether ``branch`` has three places along its longest path (hip, knee, ankle)."""
        return len(self.places(branch)) >= 3

    def mirror_pair(self, branches: list[int]) -> tuple[int, int]:
        """The two limbs most alike in joints and reach (the legs, the arms), among the
        :data:`COMPARED_BRANCHES` reaching farthest."""
        branches = sorted((b for b in branches if self.is_limb(b)), key=self.branch,
                          reverse=True)[:COMPARED_BRANCHES]
        def unlike(a: int, b: int) -> float:
            joints: float = abs(self.size[a] - self.size[b]) / max(self.size[a], self.size[b])
            return joints + abs(self.branch(a) - self.branch(b)) / max(self.branch(a),
                                                                        self.branch(b))
        pairs = [(a, b) for k, a in enumerate(branches) for b in branches[k + 1:]]
        return min(pairs, key=lambda pair: unlike(*pair))

    def places(self, start: int) -> list[list[int]]:
        """The longest path from ``start`` down to a leaf, as places: runs of joints at one place,
        each listed top-down (the topmost of a run is the one a convention names)."""
        out: list[list[int]] = []
        j = start
        while j >= 0:
            if out and self.same_place[j]:
                out[-1].append(j)
            else:
                out.append([j])
            j = int(self.onward[j])
        return out


def _limb_places(tree: _Tree, hub: int, branch: int) -> tuple[list[list[int]], list[float], int]:
    """A leg or an arm leaving ``hub`` by ``branch``: its places from the hub on, the length of
    the segment reaching each (``lengths[k]`` from place k - 1 to k; k = 1 leaves the hub), and
    ``first``, the segment of the first long bone (0 when the path has too few places).

    The two long bones are the path's longest segment and the longer of its neighbours, never
    the segment leaving the hub (a pelvis offset, a clavicle: CMU's clavicle is longer than its
    forearm, and an ASF thorax's clavicle joints sit 0.28 m up at the neck base).
    """
    places = tree.places(branch)
    if tree.same_place[branch]:
        places[0].insert(0, hub)
    else:
        places.insert(0, [hub])
    lengths = [0.0] + [float(tree.bone[p[0]]) for p in places[1:]]
    if len(places) < 4:
        return places, lengths, 0
    longest = max(range(2, len(places)), key=lambda k: lengths[k])
    before = lengths[longest - 1] if longest >= 3 else -1.0
    after = lengths[longest + 1] if longest + 1 < len(places) else -1.0
    return places, lengths, longest - 1 if before > after else longest


#: Two segments are a mirror image of each other within this fraction of the longer.
MIRROR_TOLERANCE = 0.25


#: A leg's or an arm's joints: "proximal", "middle", "distal" and "end" (None: not found).
Limb = dict[str, int | None]


def _limbs(tree: _Tree, hub: int, pair: tuple[int, int]) -> tuple[Limb, Limb]:
    """The two legs (or arms) leaving ``hub`` by the branches ``pair``: each one's proximal,
    middle and distal joints (hip, knee, ankle / shoulder, elbow, wrist) and the end beyond (toe /
    hand). Where the two limbs' long bones (:func:`_limb_places`) are not at the same segment, a
    bone on one side only (a sword held in one hand, longer than the arm) was taken for one: both
    take the segment whose bones are alike on both sides. An end farther from the distal joint
    than the bone before it is dropped (filled in instead)."""
    (places_a, lengths_a, first_a), (places_b, lengths_b, first_b) = \
        (_limb_places(tree, hub, b) for b in pair)

    def alike(first: int) -> bool:
        return all(first + d < min(len(lengths_a), len(lengths_b)) and
                   abs(lengths_a[first + d] - lengths_b[first + d])
                   <= MIRROR_TOLERANCE * max(lengths_a[first + d], lengths_b[first + d])
                   for d in (0, 1))

    firsts = [first_a, first_b]
    if first_a != first_b:
        mirrored = [f for f in (first_a, first_b) if f and alike(f)]
        if len(mirrored) == 1:
            firsts = mirrored * 2
    out: list[Limb] = []
    for places, first in zip((places_a, places_b), firsts, strict=True):
        if not first:
            out.append({"proximal": None, "middle": None, "distal": None, "end": None})
            continue
        end = places[first + 2][0] if first + 2 < len(places) else None
        out.append({"proximal": places[first - 1][0], "middle": places[first][0],
                    "distal": places[first + 1][0], "end": end})
    for limb, lengths, first in zip(out, (lengths_a, lengths_b), firsts, strict=True):
        if limb["end"] is not None and lengths[first + 2] > lengths[first + 1]:
            limb["end"] = None  # farther than the forearm or shank: a prop, no hand or toe
    return out[0], out[1]


def _head(tree: _Tree, thorax: int, branch: int) -> tuple[int, int, int | None]:
    """(neck, head, head top) on the branch leaving the thorax upwards: the neck is its first
    joint (the thorax itself when the head hangs straight from it), the head top an End Site at
    its end (or a joint named as a chain's end, :data:`_CHAIN_END_NAME`, at the end or just before
    that End Site), the head the place before it, or the place where eyes or a jaw branch off. Any other leaf joint is the head
    itself: a file written without End Sites ends the neck there (OptiTrack's Chest, Neck,
    Head), and the head top is then filled in from proportions."""
    places = tree.places(branch)
    branching = next((k for k, place in enumerate(places) if len(tree.children[place[-1]]) > 1),
                     len(places) - 1)
    places = places[:branching + 1]
    last, k = places[-1][0], len(places) - 1
    if k >= 1 and not tree.children[last] and (tree.is_end_site[last] or tree.named_end(last)):
        if k >= 2 and tree.is_end_site[last] and tree.named_end(places[k - 1][0]):
            k -= 1  # an End Site beyond a joint named as the end (HeadTop_End): that joint
        head_top: int | None = places[k][0]
        head = places[k - 1][0]
    else:
        head_top, head = None, last
    return (branch if branch != head else thorax), head, head_top


def _leftness(poses: F64, pelvis: int, thorax: int,
              legs: tuple[dict[str, int | None], dict[str, int | None]]) -> tuple[float, float]:
    """How clearly the first of two legs is the left one, from -1 (surely the right) to 1: knees
    bend forward and toes point forward, and left is up x forward (BVH axes are right-handed).
    ``poses`` (n_poses, n_joints, 3); each pose counts by how much it shows. Also returns how
    much the poses show forward: the median length of those cues over the legs' length (a few
    hundredths for straight standing legs without toes, about 0.3 with toes or walking)."""
    up = poses[:, thorax] - poses[:, pelvis]
    forward = np.zeros_like(up)
    leg_length = np.zeros(len(poses))
    for leg in legs:
        hip, knee, ankle = (poses[:, leg[k]] for k in ("proximal", "middle", "distal"))
        along = normalize(ankle - hip)
        bend = knee - hip
        forward += bend - np.sum(bend * along, axis=-1, keepdims=True) * along
        leg_length += np.linalg.norm(bend, axis=-1) + np.linalg.norm(ankle - knee, axis=-1)
        if leg["end"] is not None:
            forward += poses[:, leg["end"]] - ankle
    lateral = poses[:, legs[0]["proximal"]] - poses[:, legs[1]["proximal"]]
    shown = np.linalg.norm(lateral, axis=-1) * np.linalg.norm(np.cross(up, forward), axis=-1)
    leftness = float(np.sum(lateral * np.cross(up, forward)) / max(float(np.sum(shown)), 1e-300))
    cue = float(np.median(np.linalg.norm(forward, axis=-1) / np.maximum(leg_length, 1e-300)))
    return leftness, cue


#: A rest pose whose cues say left or right at least this clearly (1: every cue agrees, exactly
#: across the body) decides the sides; real rest poses give 0 (no cue) or above 0.99.
CLEAR_LEFTNESS = 0.5


#: Poses whose forward cues (:func:`_leftness`) are shorter than this fraction of the legs show
#: no side: straight standing legs without toes (a toe-less file with its End Sites dropped) give
#: 0.03-0.07, where any toe or a walk gives 0.17 or more. The joints' names then decide.
WEAK_FORWARD_CUE = 0.1


def _named_leftness(skeleton: BvhSkeleton,
                    legs: tuple[dict[str, int | None], dict[str, int | None]]) -> float:
    """1 when the first limb's joints are named left and the second's right (``LeftHip``,
    ``thigh_l``), -1 the other way round, 0 when the names say neither or disagree."""
    votes = 0
    for leg, sign in zip(legs, (1, -1), strict=True):
        for part in ("proximal", "middle", "distal"):
            side = _side_of(skeleton.joints[leg[part]].name)  # type: ignore[index]
            votes += sign * {"l": 1, "r": -1}.get(side or "", 0)
    return float(np.sign(votes))


def _stands(pose: F64, pelvis: int, thorax: int,
            legs: tuple[dict[str, int | None], dict[str, int | None]]) -> bool:
    """Whether both legs point away from the spine (within 60 degrees) in ``pose`` (n_joints, 3)."""
    up = normalize(pose[thorax] - pose[pelvis])
    return all(float(np.dot(up, normalize(pose[leg["distal"]] - pose[leg["proximal"]]))) < -0.5
               for leg in legs)


def structural_map(skeleton: BvhSkeleton, poses: F64 | None = None,
                   partial: bool = False) -> dict[str, int | None]:
    """Match by the hierarchy and its lengths alone, whatever the joints are called.

    The pelvis is the first joint below the root where three major branches leave: the two most
    alike are the legs, the largest other one the spine; the thorax is the first such joint up the
    spine, its two most alike branches the arms and the largest other one the neck and head.
    Along each limb the two long bones give hip, knee, ankle (shoulder, elbow, wrist); spine joints
    are picked evenly between pelvis and neck. Left is up x forward, forward being where the knees
    bend and the toes point: in the rest pose when it is a stance that shows it, otherwise in
    ``poses`` ((n_poses, n_joints, 3) joint positions in file axes, e.g. every frame of the clip),
    and when those show no forward either (:data:`WEAK_FORWARD_CUE`), the joints' names if they
    say the sides (``LeftHip``, ``thigh_l``).

    Raises :class:`MappingError` saying what it could not find, unless ``partial`` (then the parts
    it could not find are None).
    """
    tree = _Tree(skeleton)
    found: dict[str, int | None] = {}
    root = int(np.flatnonzero(tree.parents < 0)[0])
    pelvis_hub = tree.hub_below(root)
    thorax_hub = None
    problem = "no joint where two legs and a spine branch off"
    if pelvis_hub is not None:
        pelvis, branches = pelvis_hub
        legs = tree.mirror_pair(branches)
        spine = max((b for b in branches if b not in legs), key=lambda b: tree.size[b])
        thorax_hub = tree.hub_below(spine)
        problem = "no joint up the spine where two arms and a neck branch off"
    if pelvis_hub is not None and thorax_hub is not None:
        thorax, branches = thorax_hub
        arms = tree.mirror_pair(branches)
        neck_branch = max((b for b in branches if b not in arms), key=lambda b: tree.size[b])
        found["pelvis"] = pelvis
        neck, found["head"], found["head_top"] = _head(tree, thorax, neck_branch)
        found["neck"] = neck
        leg_parts = _limbs(tree, pelvis, legs)
        arm_parts = _limbs(tree, thorax, arms)
        if all(limb["distal"] is not None for limb in leg_parts + arm_parts):
            # The rest pose tells the sides if it is a stance with feet or knees showing forward;
            # otherwise (Bandai's bones lie along X at rest; Biped's stand straight with a sole
            # End Site and no toes) the clip's poses do.
            # Poses showing no forward (straight legs without toes) leave the sides to the
            # joints' names when these say them, for the arms as well.
            geometry = rest_positions(skeleton)[None]
            leftness, _ = _leftness(geometry, pelvis, thorax, leg_parts)
            by_names = False
            if poses is not None and not (_stands(geometry[0], pelvis, thorax, leg_parts)
                                          and abs(leftness) > CLEAR_LEFTNESS):
                geometry = poses
                leftness, cue = _leftness(geometry, pelvis, thorax, leg_parts)
                named = _named_leftness(skeleton, leg_parts)
                by_names = cue < WEAK_FORWARD_CUE and named != 0.0
                leftness = named if by_names else leftness
            if leftness < 0.0:
                leg_parts = leg_parts[::-1]
            # The left arm is the one on the left hip's side.
            lateral = geometry[:, leg_parts[0]["proximal"]] - geometry[:, leg_parts[1]["proximal"]]
            across = geometry[:, arm_parts[0]["proximal"]] - geometry[:, arm_parts[1]["proximal"]]
            named_arms = _named_leftness(skeleton, arm_parts) if by_names else 0.0
            if (named_arms or float(np.sum(lateral * across))) < 0.0:
                arm_parts = arm_parts[::-1]
            for side, leg, arm in zip("lr", leg_parts, arm_parts, strict=False):
                found |= {f"hip_{side}": leg["proximal"], f"knee_{side}": leg["middle"],
                          f"ankle_{side}": leg["distal"],
                          f"shoulder_{side}": arm["proximal"], f"elbow_{side}": arm["middle"],
                          f"wrist_{side}": arm["distal"], f"hand_{side}": arm["end"]}
                # An End Site below the ankle may mark the sole rather than the toe: only a joint.
                toe = leg["end"]
                found[f"toe_{side}"] = None if toe is None or skeleton.joints[toe].is_end_site \
                    else toe
            found.update(_spine(skeleton, pelvis, neck))
            problem = ""
        else:
            problem = "a leg or an arm has fewer than three joints at distinct places"
    if problem and not partial:
        raise MappingError(f"cannot match the skeleton by its names (no preset fits) nor by its "
                           f"structure ({problem}); {_GIVE_A_MAP}")
    return found


def _spine(skeleton: BvhSkeleton, pelvis: int, neck: int) -> dict[str, int | None]:
    """``spine_1`` and ``spine_2``: joints strictly between pelvis and neck at places of their
    own, picked at a third and two thirds of them (Mixamo's Spine1, Spine2 of three)."""
    rest = rest_positions(skeleton)
    below_pelvis = set([pelvis] + _ancestors(skeleton, pelvis))
    chain = [a for a in reversed(_ancestors(skeleton, neck)) if a not in below_pelvis]
    distinct = [a for a in chain
                if np.linalg.norm(rest[a] - rest[pelvis]) > 1e-9
                and np.linalg.norm(rest[a] - rest[neck]) > 1e-9]
    spine_1 = distinct[len(distinct) // 3] if distinct else None
    spine_2 = distinct[(2 * len(distinct)) // 3] if len(distinct) >= 2 else None
    return {"spine_1": spine_1, "spine_2": None if spine_2 == spine_1 else spine_2}

_PART_WORDS = {"pelvis": "hips pelvis root", "hip": "upleg thigh hip", "knee": "leg knee shin calf",
               "ankle": "foot ankle", "neck": "neck", "head": "head", "shoulder": "arm shoulder",
               "elbow": "forearm elbow", "wrist": "hand wrist"}
#: Missing parts named in an error, each with this many closest joint names; the rest counted.
HINTED_PARTS, HINTS_PER_PART = 2, 2


def _missing_message(skeleton: BvhSkeleton, missing: list[str], problems: list[str]) -> str:
    """One line: the first missing parts with the joints named most like them, the count of the
    others, why, and what to give instead."""
    names = [j.name for j in skeleton.joints if not j.is_end_site]
    keys = [_key(n) for n in names]
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
        score += [0.1 if side and _side_of(n) == side else 0.0 for n in names]
        closest = [names[k] for k in np.argsort(-score, kind="stable")[:HINTS_PER_PART]]
        parts.append(f"{m} (closest: {listed(quoted(n) for n in closest) or 'none'})")
    found_parts = listed(parts + missing[len(parts):], HINTED_PARTS)
    why = f" ({'; '.join(problems)})" if problems else ""
    return f"cannot find these body parts in the skeleton: {found_parts}{why}; {_GIVE_A_MAP}"


_GIVE_A_MAP = ("give --map PRESET or FILE.yaml (joints: {canonical: source_name}); presets: "
               "ecs-anim import --help")


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


def _find(skeleton: BvhSkeleton, name: str) -> int | None:
    """Index of a joint by exact name, else by case- and namespace-insensitive name."""
    names = skeleton.names
    if name in names:
        return names.index(name)
    keys = [_key(n) for n in names]
    return keys.index(_key(name)) if _key(name) in keys else None


def map_skeleton(skeleton: BvhSkeleton, map_spec: str | None = None,
                 poses: F64 | None = None) -> JointMap:
    """Match ``skeleton`` to the canonical joints. ``map_spec``: None (detect), a preset name,
    or a path to a user YAML map; ``poses`` (n_poses, n_joints, 3): joint positions in file axes
    that tell left from right in a structural match (see :func:`structural_map`). Raises
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
        found = _resolve_preset(preset, skeleton)
        how = f"preset {base}" + (" (requested)" if user_path is None else f" + {user_path}")
    else:
        detected = detect_preset(skeleton)
        if detected is not None:
            found = _resolve_preset(detected, skeleton)
            how = f"preset {detected.name} (detected)"
        else:
            # With a user map, a partial structural match is completed by the user's entries.
            found = structural_map(skeleton, poses, partial=bool(user))
            how = "structure (no preset matched)"
        if user_path is not None:
            how += f" + {user_path}"
    for canonical, source_name in user.items():
        i = _find(skeleton, source_name)
        if i is None:
            close = difflib.get_close_matches(source_name, skeleton.names, n=3)
            raise InputError(user_path, f"joints.{canonical}: no joint {quoted(source_name)} in "
                                        f"{skeleton.path} (closest: "
                                        f"{listed(quoted(n) for n in close) or 'none'})",
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
    # Toes a skeleton lacks: the End Site below the ankle when it is the toe tip (Daz, Perception
    # Neuron, OptiTrack), not when it marks the sole straight below (Biped).
    for side in "lr":
        if source[f"toe_{side}"] is None:
            source[f"toe_{side}"] = _toe_end_site(skeleton, source[f"knee_{side}"],  # type: ignore[arg-type]
                                                  source[f"ankle_{side}"])  # type: ignore[arg-type]
    if user_path is not None:
        _check_user_map(skeleton, source, user_path, user_lines, how)
    thorax = _lca(skeleton, [source["shoulder_l"], source["shoulder_r"], source["head"]])  # type: ignore[list-item]
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


def _hierarchy_parent(joint: str, source: dict[str, int | None]) -> str | None:
    """The nearest mapped canonical ancestor a source must hang below: the canonical parent, but
    for a shoulder the spine under the neck (CMU's clavicles branch off below the neck joint)."""
    parent = PARENTS[JOINT_INDEX[joint]]
    while parent >= 0 and (source[JOINTS[parent]] is None
                           or (joint.startswith("shoulder_") and JOINTS[parent] == "neck")):
        parent = PARENTS[parent]
    return None if parent < 0 else JOINTS[parent]


def _check_user_map(skeleton: BvhSkeleton, source: dict[str, int | None], user_path: str,
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
        if p not in _ancestors(skeleton, i):
            raise InputError(user_path, f"joints.{entry}: {pair.format('not below')} in "
                                        f"{skeleton.path}", user_lines[entry])
        if PARENTS[JOINT_INDEX[joint]] == JOINT_INDEX[parent] and \
                float(np.linalg.norm(rest[i] - rest[p])) <= same_place:
            raise InputError(user_path, f"joints.{entry}: {pair.format('at the place of')} at "
                                        "rest (a bone of zero length)", user_lines[entry])


def preset_summary() -> str:
    """One line per preset, for ``--help`` and error messages."""
    return "\n".join(f"  {p.name:18s} {p.description}" for p in PRESETS.values())
