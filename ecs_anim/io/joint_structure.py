"""Matching by structure: the hierarchy and its rest lengths alone, whatever the joints are called
(:func:`structural_map`)."""

from __future__ import annotations

import re

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import MappingError
from ecs_anim.core.rotations import normalize
from ecs_anim.io.bvh import BvhSkeleton, rest_positions
from ecs_anim.io.joint_presets import side_of_name
from ecs_anim.io.missing_joints import GIVE_A_MAP

F64 = NDArray[np.float64]


def ancestors(skeleton: BvhSkeleton, j: int) -> list[int]:
    """Joint ``j``'s ancestors, its parent first."""
    out = []
    p = skeleton.joints[j].parent
    while p >= 0:
        out.append(p)
        p = skeleton.joints[p].parent
    return out


def common_ancestor(skeleton: BvhSkeleton, joints: list[int]) -> int:
    """The lowest joint that is ``joints``' own or an ancestor of each of them."""
    chains = [[j] + ancestors(skeleton, j) for j in joints]
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
    ``rest`` (n_joints, 3): rest positions in file axes; ``reach`` (n_joints,): the longest path
    from a joint down to a leaf; ``onward``: the child on that path (-1 at a leaf); ``size``:
    joints in each subtree. Joints at the place of their parent
    (zero offsets, zero-length End Sites) are *at the same place*; a run of them is one place.
    """

    def __init__(self, skeleton: BvhSkeleton):
        rest = rest_positions(skeleton)
        self.rest = rest
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


def _limb_places(tree: _Tree, hub: int, branch: int, lowest: int = 2
                 ) -> tuple[list[list[int]], list[float], int]:
    """A leg or an arm leaving ``hub`` by ``branch``: its places from the hub on, the length of
    the segment reaching each (``lengths[k]`` from place k - 1 to k; k = 1 leaves the hub), and
    ``first``, the segment of the first long bone (0 when the path has too few places).

    The two long bones are the longest of the segments from ``lowest`` on and the longer of its
    neighbours among them, never the segment leaving the hub (a pelvis offset, a clavicle:
    CMU's clavicle is longer than its forearm, and an ASF thorax's clavicle joints sit 0.28 m up
    at the neck base), nor the segment to the chain's end mark (an End Site, or a leaf joint named
    as a chain's end, :data:`_CHAIN_END_NAME`) while two others remain: that end is the hand's or
    the foot's tip, however long (3ds Max Biped's hand End Site repeats the forearm's OFFSET).
    ``lowest`` is left at 2 unless the proximal joint must lie farther out (:func:`_limbs`).
    """
    places = tree.places(branch)
    if tree.same_place[branch]:
        places[0].insert(0, hub)
    else:
        places.insert(0, [hub])
    lengths = [0.0] + [float(tree.bone[p[0]]) for p in places[1:]]
    last = places[-1][0]
    marks_end = not tree.children[last] and (tree.is_end_site[last] or tree.named_end(last))

    def usable_from(low: int) -> int:  # segments low .. usable - 1 may be long bones
        return len(places) - 1 if marks_end and len(places) - 1 - low >= 2 else len(places)

    if usable_from(lowest) - lowest < 2:
        lowest = 2
    usable = usable_from(lowest)
    if usable - lowest < 2:
        return places, lengths, 0
    longest = max(range(lowest, usable), key=lambda k: lengths[k])
    before = lengths[longest - 1] if longest > lowest else -1.0
    after = lengths[longest + 1] if longest + 1 < usable else -1.0
    return places, lengths, longest - 1 if before > after else longest


#: Two segments are a mirror image of each other within this fraction of the longer.
MIRROR_TOLERANCE = 0.25


#: Lengths within this fraction of each other are the same (as written: 25.4996 and 25.4996004).
SAME_LENGTH = 1e-3


#: A leg's or an arm's joints: "proximal", "middle", "distal" and "end" (None: not found).
Limb = dict[str, int | None]


def _limbs(tree: _Tree, hub: int, pair: tuple[int, int],
           wider_than: float = 0.0) -> tuple[Limb, Limb]:
    """The two legs (or arms) leaving ``hub`` by the branches ``pair``: each one's proximal,
    middle and distal joints (hip, knee, ankle / shoulder, elbow, wrist) and the end beyond (toe /
    hand). The proximal joints are the first places along the limbs farther apart at rest than
    ``wider_than``, or beyond them: for the arms, the hips' width, as shoulders are farther apart
    than hips and a collar joint at the sternum is not (the collar bone between is no long bone
    however long). Where the two limbs' long bones (:func:`_limb_places`) are not at the same
    segment, a bone on one side only (a sword held in one hand, longer than the arm) was taken
    for one: both take the segment whose bones are alike on both sides. An end farther from the
    distal joint than the bone before it is dropped (filled in instead)."""
    lowest = [2, 2]
    if wider_than > 0.0:
        sides = [tree.places(b) for b in pair]
        wide = [k for k in range(min(len(p) for p in sides))
                if np.linalg.norm(tree.rest[sides[0][k][0]] - tree.rest[sides[1][k][0]])
                > wider_than]
        if wide:
            # Place k of a branch is place k + 1 from the hub (k when the branch starts at the
            # hub's place, :func:`_limb_places`); the segment leaving it is one more.
            lowest = [max(2, wide[0] + (1 if tree.same_place[b] else 2)) for b in pair]
    (places_a, lengths_a, first_a), (places_b, lengths_b, first_b) = \
        (_limb_places(tree, hub, b, low) for b, low in zip(pair, lowest, strict=True))

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
        if limb["end"] is not None and lengths[first + 2] > (1 + SAME_LENGTH) * lengths[first + 1]:
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
            side = side_of_name(skeleton.joints[leg[part]].name)  # type: ignore[index]
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
    Along each limb the two long bones give hip, knee, ankle (shoulder, elbow, wrist; the shoulders
    no nearer the thorax than the first joints farther apart than the hips, :func:`_limbs`); spine
    joints are picked evenly between pelvis and neck. Left is up x forward, forward being where
    the knees bend and the toes point: in the rest pose when it is a stance that shows it, else in
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
        hips = [leg["proximal"] for leg in leg_parts]
        hip_width = 0.0 if None in hips else \
            float(np.linalg.norm(tree.rest[hips[0]] - tree.rest[hips[1]]))
        arm_parts = _limbs(tree, thorax, arms, hip_width)
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
                           f"structure ({problem}); {GIVE_A_MAP}")
    return found


def _spine(skeleton: BvhSkeleton, pelvis: int, neck: int) -> dict[str, int | None]:
    """``spine_1`` and ``spine_2``: joints strictly between pelvis and neck at places of their
    own, picked at a third and two thirds of them (Mixamo's Spine1, Spine2 of three)."""
    rest = rest_positions(skeleton)
    below_pelvis = set([pelvis] + ancestors(skeleton, pelvis))
    chain = [a for a in reversed(ancestors(skeleton, neck)) if a not in below_pelvis]
    distinct = [a for a in chain
                if np.linalg.norm(rest[a] - rest[pelvis]) > 1e-9
                and np.linalg.norm(rest[a] - rest[neck]) > 1e-9]
    spine_1 = distinct[len(distinct) // 3] if distinct else None
    spine_2 = distinct[(2 * len(distinct)) // 3] if len(distinct) >= 2 else None
    return {"spine_1": spine_1, "spine_2": None if spine_2 == spine_1 else spine_2}
