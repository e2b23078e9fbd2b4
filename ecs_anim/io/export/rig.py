"""A user's rig as the body a motion is played on (``export --onto RIG``): its joints, rest pose
and segment lengths (:func:`load_rig`), and the rotation of every one of its joints in each
frame of a decoded motion (:func:`rig_pose`).

A rig is a BVH skeleton, a glTF/GLB skin or an FBX skeleton (read through ufbx). Its joints are matched to our body parts as import
matches a source skeleton (presets, structure, a user map YAML: :func:`~ecs_anim.io.joint_map.map_skeleton`),
and its rest pose measured as import measures a source (:func:`~ecs_anim.io.importing.canonical_clip`,
:func:`~ecs_anim.io.importing.source_morphology`), so its segment lengths are the body the
motion is decoded on.

How a joint turns. Each rig joint gets a *world delta* ``rest2posed`` (3, 3): the rotation that
takes the joint from the rig's rest pose to the frame's pose, in our world axes; its world
orientation is then ``rest2posed @ rest2world`` whatever its bone axes, and its local rotation
``parent_world^-1 @ world``. The delta of

- a joint that is a body part's (hip, knee, ankle, spine, neck, head, shoulder, elbow, wrist):
  the rotation taking its rest frame onto its posed frame, each frame built the same way from a
  primary axis (the bone towards the next part: hip -> knee, wrist -> hand) and a secondary one
  (the limb's half-plane normal, the pelvis's or thorax's or head's side axis); the pelvis takes
  the pelvis frame itself. The primary is aimed from where the joint actually is on the rig, so
  a rig whose bones do not sit exactly where ours do is not thrown further off down the chain;
- a joint between the pelvis and a part below it that is no part of ours (a clavicle, an extra
  spine or neck joint, a metacarpal): the smallest turn of its parent's delta that aims it at
  the one part below it;
- a twist joint (on the bone between two parts, as Rigify's ``.001`` halves and Daz's
  ``ThighTwist``, or a leaf named ``*twist*`` as Unreal's ``upperarm_twist_01_l``): its parent
  part's delta turned about the bone by a share of the twist between that part and the next
  (half for one twist joint, k / (n + 1) for the k-th of n);
- every other joint (fingers, eyes, roll and IK helpers, props, a root above the pelvis): its
  parent's delta, so it keeps its rest pose relative to its parent.

The rig's root motion goes to the pelvis joint (or, in a BVH whose pelvis has no position
channels, the lowest joint above it that has them).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError, InputError
from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import (
    ELBOW_HINT_IN_THORAX,
    KNEE_HINT_IN_PELVIS,
    DecodedPose,
    limb_frames,
    two_bone_middle,
)
from ecs_anim.core.rotations import (
    axis_angle,
    frame_from_axes,
    normalize,
    quat_from_matrix,
    rotation_between,
)
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.bvh import BvhJoint, BvhMotion, BvhSkeleton, read_bvh, rest_positions
from ecs_anim.io.importing import UP_AXES, YUP_TO_ZUP, canonical_clip, source_morphology, unit_scale
from ecs_anim.io.joint_map import JointMap

F64 = NDArray[np.float64]

#: Each body part's joint and the part its bone points to (its frame's primary axis).
NEXT_PART: dict[str, str] = {
    **{f"{a}_{s}": f"{b}_{s}" for s in "lr" for a, b in (
        ("hip", "knee"), ("knee", "ankle"), ("ankle", "toe"),
        ("shoulder", "elbow"), ("elbow", "wrist"), ("wrist", "hand"))},
    "spine_1": "spine_2", "spine_2": "neck", "neck": "head", "head": "head_top",
}
#: Parts at the end of a chain: they turn with the joint they hang from.
END_PARTS = ("toe_l", "toe_r", "hand_l", "hand_r", "head_top")
#: Parts an unmatched joint above several parts is aimed at, in this order (a chest joint
#: carrying the clavicles and the neck is aimed up the neck).
AIM_FIRST = ("spine_1", "spine_2", "neck", "head")
#: Limbs by their first joint: (middle, end, tip, side index, whether a leg).
LIMBS: dict[str, tuple[str, str, str, int, bool]] = {
    **{f"hip_{s}": (f"knee_{s}", f"ankle_{s}", f"toe_{s}", k, True) for k, s in enumerate("lr")},
    **{f"shoulder_{s}": (f"elbow_{s}", f"wrist_{s}", f"hand_{s}", k, False)
       for k, s in enumerate("lr")},
}
#: Parts whose bone may hold twist joints (thigh, shank, upper arm, forearm).
TWISTING = ("hip", "knee", "shoulder", "elbow")
#: A joint lies on a bone when it is this close to the line, as a fraction of the bone's length.
ON_BONE = 0.01


@dataclass(frozen=True)
class Rig:
    """A target rig: its joints in topological order, rest pose and body.

    names : (J,) joint names as in the file (BVH End Sites ``<joint>.end``).
    parents : (J,) parent index, -1 for a root.
    rest_in_world : (J, 3) rest positions, metres, our world (Z up).
    rest2world : (J, 3, 3) rest orientations in our world axes (a BVH's: its file axes).
    file2world : (3, 3) the file's axes -> ours; ``metres_per_unit`` its length unit.
    joint_map : canonical joint -> rig joint, as import matched it.
    morphology : the rig's segment lengths (the body the motion is decoded on).
    parts_at_rest : (N_JOINTS, 3) our joints at the rig's rest pose (metres, world), parts the
        rig lacks filled in as import fills them; ``body_at_rest`` (3, 3) its body axes
        (forward, left, up) at rest.
    translated : the joint that carries the root motion.
    kind : ``"bvh"``, ``"fbx"`` (written as a BVH rig) or ``"glb"``; ``bvh`` the skeleton as
        the BVH reader gives it, ``gltf`` the document and ``nodes`` the node of each joint
        (glTF rigs).
    """

    name: str
    path: str
    kind: str
    names: tuple[str, ...]
    parents: NDArray[np.int64]
    rest_in_world: F64
    rest2world: F64
    file2world: F64
    metres_per_unit: float
    joint_map: JointMap
    morphology: Morphology
    parts_at_rest: F64
    body_at_rest: F64
    translated: int
    bvh: BvhSkeleton | None = None
    gltf: Any = None
    nodes: tuple[int, ...] = field(default_factory=tuple)

    @property
    def n_joints(self) -> int:
        return len(self.names)


def _rest_motion(skeleton: BvhSkeleton) -> BvhMotion:
    """One frame of ``skeleton``'s rest pose: zero rotations, position channels at the OFFSET."""
    values: list[float] = []
    for joint in skeleton.joints:
        for channel in joint.channels:
            axis = "xyz".find(channel.lower()[0]) if channel.lower().endswith("position") else -1
            values.append(float(joint.offset[axis]) if axis >= 0 else 0.0)
    return BvhMotion(skeleton, np.array([values]), 1.0 / 30.0)


def _measure(skeleton: BvhSkeleton, full: BvhMotion, map_spec: str | None, unit: str | None,
             up: str | None, path: str) -> tuple[Morphology, JointMap, F64, F64, F64, float]:
    """Map and measure a rig skeleton: (morphology, joint map, parts at rest, body axes at
    rest, file2world, metres per unit)."""
    try:
        clip = canonical_clip(full, map_spec, unit=unit, up=up)
        morph = source_morphology(clip.positions, Path(path).stem)
        rest = canonical_clip(_rest_motion(skeleton), map_spec, unit=clip.unit, up=clip.up_axis)
    except InputError:
        raise
    except (EcsAnimError, ValueError) as exc:
        raise InputError(path, f"cannot use this skeleton as a rig: {exc}") from None
    return (morph, rest.joint_map, rest.positions[0], rest.pelvis2world[0],
            UP_AXES[clip.up_axis], unit_scale(clip.unit))


def _translated(parents: NDArray[np.int64], pelvis: int, can_translate: list[bool]) -> int:
    """The lowest joint from ``pelvis`` up that may carry a translation (the pelvis if none)."""
    j = pelvis
    while j >= 0:
        if can_translate[j]:
            return j
        j = int(parents[j])
    return pelvis


def load_bvh_rig(path: str | Path, map_spec: str | None = None) -> Rig:
    """A BVH skeleton as a rig: its rest pose is its OFFSETs (every rotation zero)."""
    return _skeleton_rig(Path(path), "bvh", read_bvh(path), map_spec)


def load_fbx_rig(path: str | Path, map_spec: str | None = None) -> Rig:
    """An FBX skeleton as a rig, read through ufbx as FBX import reads one
    (:func:`~ecs_anim.io.fbx.read_fbx`, with or without takes): its nodes' own transforms are
    its rest pose, their bone axes (joint orients, pre-rotations) taken out as a BVH has none,
    in the unit and up axis the file states where they make a human leg (else detected as for
    BVH). It is written as a BVH rig is: the BVH in its hierarchy, names and unit; the GLB its
    joints as nodes with a capsule on each bone."""
    from ecs_anim.io.fbx import fbx_canonical_clip, read_fbx

    fbx = read_fbx(path, rest_only=True)
    try:
        clip = fbx_canonical_clip(fbx, map_spec)
    except InputError:
        raise
    except (EcsAnimError, ValueError) as exc:
        raise InputError(path, f"cannot use this skeleton as a rig: {exc}") from None
    return _skeleton_rig(Path(path), "fbx", fbx.motion, map_spec, clip.unit, clip.up_axis)


def _skeleton_rig(path: Path, kind: str, motion: BvhMotion, map_spec: str | None,
                  unit: str | None = None, up: str | None = None) -> Rig:
    """A rig of a skeleton read as the BVH reader gives it (its rest pose its OFFSETs), in
    ``unit`` and with ``up`` (None: detected)."""
    skeleton = motion.skeleton
    morph, jmap, parts, body, file2world, scale = _measure(skeleton, motion, map_spec, unit, up,
                                                           str(path))
    parents = np.array([j.parent for j in skeleton.joints], dtype=np.int64)
    rest = rest_positions(skeleton) @ file2world.T * scale
    can_translate = [any(c.lower().endswith("position") for c in j.channels) for j in skeleton.joints]
    pelvis = jmap.source["pelvis"]
    assert pelvis is not None
    return Rig(name=path.stem, path=str(path), kind=kind, names=tuple(skeleton.names),
               parents=parents, rest_in_world=rest,
               rest2world=np.broadcast_to(file2world, (len(parents), 3, 3)).copy(),
               file2world=file2world, metres_per_unit=scale, joint_map=jmap, morphology=morph,
               parts_at_rest=parts, body_at_rest=body,
               translated=_translated(parents, pelvis, can_translate), bvh=skeleton)


def _node_matrix(node: Any) -> F64:
    """A glTF node's local transform (4, 4) from its matrix or TRS."""
    if node.matrix is not None:
        return np.array(node.matrix, dtype=float).reshape(4, 4).T  # column-major in the file
    out = np.eye(4)
    x, y, z, w = node.rotation if node.rotation is not None else (0.0, 0.0, 0.0, 1.0)
    rotation = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    scale = np.array(node.scale if node.scale is not None else (1.0, 1.0, 1.0), dtype=float)
    out[:3, :3] = rotation * scale
    out[:3, 3] = node.translation if node.translation is not None else (0.0, 0.0, 0.0)
    return out


def gltf_world_matrices(document: Any) -> F64:
    """Every node's rest world transform (n_nodes, 4, 4), glTF axes."""
    nodes = document.nodes
    parent = {c: p for p, node in enumerate(nodes) for c in (node.children or [])}
    world = np.full((len(nodes), 4, 4), np.nan)

    def place(k: int) -> F64:
        if np.isnan(world[k, 0, 0]):
            local = _node_matrix(nodes[k])
            world[k] = local if k not in parent else place(parent[k]) @ local
        out: F64 = world[k]
        return out

    for k in range(len(nodes)):
        place(k)
    return world


def uniform_scale(matrix: F64, what: str, path: str) -> float:
    """The uniform scale of a (4, 4) transform; a sheared or unevenly scaled one is refused."""
    linear = matrix[:3, :3]
    scales = np.linalg.norm(linear, axis=0)
    if not np.allclose(scales, scales[0], rtol=1e-4) or \
            not np.allclose(linear.T @ linear, scales[0] ** 2 * np.eye(3), atol=1e-4 * scales[0] ** 2):
        raise InputError(path, f"{what}: an uneven scale or shear ({scales.round(6).tolist()}); "
                               "--onto takes rigs whose joints are scaled evenly")
    return float(scales[0])


def load_gltf_rig(path: str | Path, map_spec: str | None = None) -> Rig:
    """A glTF/GLB skin as a rig: its joints are the skin's, its rest pose the nodes' own
    transforms (any bone axes; a scaled or turned armature above them is kept)."""
    import pygltflib

    path = Path(path)
    try:
        document = pygltflib.GLTF2.load(str(path))
    except Exception as exc:  # pygltflib raises whatever its parser meets
        raise InputError(path, f"not a glTF file pygltflib can read: {exc}") from None
    if not document.skins:
        raise InputError(path, "no skin: --onto needs a glTF rig with a skin (its joints)")
    joints = list(document.skins[0].joints)
    node_parent = {c: p for p, node in enumerate(document.nodes) for c in (node.children or [])}
    in_skin = set(joints)
    # Topological order: a joint after its nearest ancestor in the skin.
    depth = {}
    for k in joints:
        d, p = 0, node_parent.get(k)
        while p is not None:
            d, p = d + (p in in_skin), node_parent.get(p)
        depth[k] = d
    order = sorted(joints, key=lambda k: (depth[k], joints.index(k)))

    def skin_parent(k: int) -> int:
        p = node_parent.get(k)
        while p is not None and p not in in_skin:
            p = node_parent.get(p)
        return -1 if p is None else order.index(p)

    parents = np.array([skin_parent(k) for k in order], dtype=np.int64)
    for k, parent in zip(order, parents, strict=True):
        if parent >= 0 and node_parent.get(k) != order[parent]:
            raise InputError(path, f"joint {document.nodes[k].name or k} hangs from a node that "
                                   "is no joint of the skin, below another joint; --onto needs "
                                   "the skin's joints to hang from one another")
    if (parents < 0).sum() != 1:
        raise InputError(path, f"the skin's joints form {(parents < 0).sum()} trees; --onto needs one")
    world = gltf_world_matrices(document)[order]  # (J, 4, 4) glTF axes
    for k, node in zip(order, world, strict=True):
        uniform_scale(node, f"node {document.nodes[k].name or k}", str(path))
    position = world[:, :3, 3]
    names = [document.nodes[k].name or f"node{k}" for k in order]
    bvh_joints = [BvhJoint(name, int(p), position[i] - (position[p] if p >= 0 else 0.0),
                           ["Xposition", "Yposition", "Zposition"] if p < 0 else [])
                  for i, (name, p) in enumerate(zip(names, parents, strict=True))]
    for joint in bvh_joints:
        joint.channels += ["Zrotation", "Xrotation", "Yrotation"]
    skeleton = BvhSkeleton(bvh_joints, str(path))
    motion = _rest_motion(skeleton)
    morph, jmap, parts, body, _, _ = _measure(skeleton, motion, map_spec, "m", "y",
                                               str(path))
    rotation = world[:, :3, :3] / np.linalg.norm(world[:, :3, 0], axis=-1)[:, None, None]
    pelvis = jmap.source["pelvis"]
    assert pelvis is not None
    return Rig(name=path.stem, path=str(path), kind="glb", names=tuple(names), parents=parents,
               rest_in_world=position @ YUP_TO_ZUP.T, rest2world=YUP_TO_ZUP @ rotation,
               file2world=YUP_TO_ZUP, metres_per_unit=1.0, joint_map=jmap, morphology=morph,
               parts_at_rest=parts, body_at_rest=body, translated=pelvis, bvh=skeleton,
               gltf=document, nodes=tuple(order))


def load_rig(path: str | Path, map_spec: str | None = None) -> Rig:
    """A ``.bvh``, ``.glb``, ``.gltf`` or ``.fbx`` rig (see :class:`Rig`); ``map_spec`` as
    import's ``--map`` (a preset name or a user map YAML)."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "no such rig file")
    suffix = path.suffix.lower()
    if suffix == ".bvh":
        return load_bvh_rig(path, map_spec)
    if suffix in (".glb", ".gltf"):
        return load_gltf_rig(path, map_spec)
    if suffix == ".fbx":
        return load_fbx_rig(path, map_spec)
    raise EcsAnimError(f"--onto {path}: a rig is a .bvh, .glb, .gltf or .fbx file")


def rig_input_files(path: str | Path, map_spec: str | None = None) -> list[str]:
    """The files a rig reads (for commands that must not write over them): the rig and, when
    ``map_spec`` is one, its map YAML."""
    return [str(path)] + ([map_spec] if map_spec is not None and
                          Path(map_spec).suffix.lower() in (".yaml", ".yml") else [])


# --- the rig's joints in every frame -----------------------------------------------------------


def part_frames(positions: F64, pelvis2world: F64, thorax2world: F64, head2world: F64,
                leg2world: F64, arm2world: F64, starts: dict[str, F64]) -> dict[str, F64]:
    """The frame of every body part that turns a rig joint: (..., 3, 3) each, by canonical
    joint (see the module docstring); ``starts`` gives where each part's bone starts (its joint
    on the rig), by part, (..., 3).

    positions (..., N_JOINTS, 3); the body frames (..., 3, 3); limb frames (..., 2, 3, 3).
    """
    p = positions
    out = {"pelvis": pelvis2world}
    secondary = {"spine_1": (pelvis2world[..., :, 1], 2, 1), "spine_2": (thorax2world[..., :, 1], 2, 1),
                 "neck": (thorax2world[..., :, 1], 2, 1), "head": (head2world[..., :, 1], 2, 1)}
    for k, s in enumerate("lr"):
        leg_normal, arm_normal = leg2world[..., k, :, 0], arm2world[..., k, :, 0]
        secondary |= {f"hip_{s}": (leg_normal, 2, 0), f"knee_{s}": (leg_normal, 2, 0),
                      f"ankle_{s}": (leg_normal, 0, 1), f"shoulder_{s}": (arm_normal, 2, 0),
                      f"elbow_{s}": (arm_normal, 2, 0), f"wrist_{s}": (arm_normal, 2, 0)}
    for part, start in starts.items():
        axis_2nd, primary_axis, secondary_axis = secondary[part]
        out[part] = frame_from_axes(p[..., J[NEXT_PART[part]], :] - start, axis_2nd,
                                    primary_axis, secondary_axis)
    return out


def _rest_pose(rig: Rig) -> DecodedPose:
    """The rig's rest pose as a decoded pose: our joints where the rig has them, the body axes
    at rest as pelvis, thorax and head frames, and limb frames as encoding makes them."""
    p = rig.parts_at_rest
    body = rig.body_at_rest
    sides = [[J[f"{j}_{s}"] for s in "lr"] for j in ("hip", "knee", "ankle", "shoulder", "elbow",
                                                     "wrist")]
    legs = limb_frames(p[sides[0]], p[sides[1]], p[sides[2]], body @ KNEE_HINT_IN_PELVIS)
    arms = limb_frames(p[sides[3]], p[sides[4]], p[sides[5]], body @ ELBOW_HINT_IN_THORAX)
    return DecodedPose(p, body, body, body, legs, arms)


@dataclass(frozen=True)
class _Plan:
    """What drives each rig joint (see the module docstring), worked out once per rig.

    ``part[j]``: the body part whose frame turns joint j ("" if none); ``aim[j]``: the part an
    unmatched joint is aimed at ("" if none); ``twist[j]``: (part above, part below, share) for
    a twist joint, else None.
    """

    part: list[str]
    aim: list[str]
    twist: list[tuple[str, str, float] | None]
    above_pelvis: NDArray[np.bool_]


def _plan(rig: Rig) -> _Plan:
    n = rig.n_joints
    parents = rig.parents
    part_of = {i: c for c, i in rig.joint_map.source.items() if i is not None}
    children: list[list[int]] = [[] for _ in range(n)]
    for i, p in enumerate(parents):
        if p >= 0:
            children[p].append(i)
    pelvis = rig.joint_map.source["pelvis"]
    assert pelvis is not None
    above = np.zeros(n, dtype=bool)
    j = int(parents[pelvis])
    while j >= 0:
        above[j] = True
        j = int(parents[j])

    def parts_below(j: int) -> list[str]:
        """The first matched parts down each path from ``j``'s children."""
        found: list[str] = []
        stack = list(children[j])
        while stack:
            k = stack.pop()
            if k in part_of:
                found.append(part_of[k])
            else:
                stack.extend(children[k])
        return found

    def part_above(j: int) -> tuple[int, str] | None:
        k = int(parents[j])
        while k >= 0 and k not in part_of:
            k = int(parents[k])
        return None if k < 0 else (k, part_of[k])

    rest = rig.rest_in_world
    part: list[str] = [""] * n
    aim: list[str] = [""] * n
    twist: list[tuple[str, str, float] | None] = [None] * n
    for j in range(n):
        if j in part_of:
            c = part_of[j]
            part[j] = "" if c in END_PARTS else c
            continue
        if above[j]:
            continue
        below = parts_below(j)
        upper = part_above(j)
        next_part = NEXT_PART.get(upper[1], "") if upper is not None else ""
        if upper is not None and upper[1][:-2] in TWISTING and below == [next_part]:
            a = rest[upper[0]]
            b = rest[rig.joint_map.source[next_part]]
            bone = b - a
            length = float(np.linalg.norm(bone))
            along = float(np.dot(rest[j] - a, bone)) / max(length, 1e-12)
            off = float(np.linalg.norm(rest[j] - a - along * bone / max(length, 1e-12)))
            if 0.0 < along < length and off <= ON_BONE * length:
                # The k-th of n twist joints on this bone takes k / (n + 1) of the twist.
                k, nth = int(parents[j]), 1
                while k != upper[0]:
                    k, nth = int(parents[k]), nth + 1
                twist[j] = (upper[1], next_part, float(nth))
                aim[j] = next_part
                continue
        if not below and upper is not None and "twist" in rig.names[j].lower() and \
                upper[1][:-2] in TWISTING and int(parents[j]) == upper[0]:
            twist[j] = (upper[1], NEXT_PART[upper[1]], -1.0)  # a leaf: half the twist
            continue
        targets = [c for c in below if c in AIM_FIRST] or below
        if len(set(targets)) == 1:
            aim[j] = targets[0]
    # Shares: the k-th of n twist joints on one bone takes k / (n + 1).
    counts: dict[tuple[str, str], int] = {}
    for t in twist:
        if t is not None and t[2] > 0:
            counts[t[:2]] = max(counts.get(t[:2], 0), int(t[2]))
    twist = [None if t is None else
             (t[0], t[1], 0.5 if t[2] < 0 else t[2] / (counts[t[:2]] + 1)) for t in twist]
    return _Plan(part, aim, twist, above)


def _reach_with_rig_bones(rig: Rig, pose: DecodedPose, parts: F64, first: str, root: F64) -> None:
    """Move the middle and end (and tip) of limb ``first`` in ``parts`` (frames, N_JOINTS, 3) to
    where the rig's bones reach from ``root`` (frames, 3), the rig's hip or shoulder: the end
    at ours (as near as the bones reach), the middle in our limb's half-plane (two spheres)."""
    middle, end, tip, side, leg = LIMBS[first]
    src = rig.joint_map.source
    if src[middle] is None or src[end] is None:
        return
    rest = rig.rest_in_world
    upper = float(np.linalg.norm(rest[src[middle]] - rest[src[first]]))
    lower = float(np.linalg.norm(rest[src[end]] - rest[src[middle]]))
    limb = (pose.leg2world if leg else pose.arm2world)[:, side]
    target = parts[:, J[end]]
    frame = frame_from_axes(target - root, limb[:, :, 1], 2, 1, fallback_secondary=limb[:, :, 0])
    reach = np.linalg.norm(target - root, axis=-1)
    n = len(reach)
    at_middle, at_end = two_bone_middle(frame, root, np.full(n, upper), np.full(n, lower), reach)
    parts[:, J[tip]] += at_end - target
    parts[:, J[middle]] = at_middle
    parts[:, J[end]] = at_end


def twist_shares(rig: Rig) -> dict[str, float]:
    """The rig's twist joints (see the module docstring) and the share of the twist each takes."""
    plan = _plan(rig)
    return {rig.names[j]: t[2] for j, t in enumerate(plan.twist) if t is not None}


def _twist_angle(relative: F64, axis: F64) -> F64:
    """Angle (radians) of the twist of rotations ``relative`` (..., 3, 3) about ``axis`` (3,):
    the swing-twist split of the quaternion. Returns (...)."""
    q = quat_from_matrix(relative)
    along = q[..., :3] @ axis
    angle: F64 = 2.0 * np.arctan2(along, q[..., 3])
    return (angle + np.pi) % (2.0 * np.pi) - np.pi


@dataclass
class RigPose:
    """A decoded motion on a rig.

    rest2posed : (frames, J, 3, 3) each joint's world delta from the rest pose (our axes).
    joint2world : (frames, J, 3, 3) world orientations (our axes).
    positions : (frames, J, 3) joint positions, metres, world Z up.
    """

    rest2posed: F64
    joint2world: F64
    positions: F64


def rig_pose(rig: Rig, pose: DecodedPose) -> RigPose:
    """Every rig joint's rotation and position in each frame of ``pose`` (decoded on
    ``rig.morphology``, frames leading). Vectorized over frames; the loop runs once over the
    rig's joints, parents first."""
    plan = _plan(rig)
    n_frames = pose.positions.shape[0]
    n = rig.n_joints
    rest_pose = _rest_pose(rig)
    src = rig.joint_map.source
    bone_parts = [c for c in NEXT_PART if src.get(c) is not None and c not in END_PARTS]
    rest_frames = part_frames(rest_pose.positions, rest_pose.pelvis2world, rest_pose.thorax2world,
                              rest_pose.head2world, rest_pose.leg2world, rest_pose.arm2world,
                              {c: rig.rest_in_world[src[c]] for c in bone_parts})
    rest = rig.rest_in_world
    delta = np.empty((n_frames, n, 3, 3))
    where = np.empty((n_frames, n, 3))
    eye = np.broadcast_to(np.eye(3), (n_frames, 3, 3))
    pelvis = src["pelvis"]
    assert pelvis is not None
    # Where each part should be; a limb's middle and end are moved to where the rig's own bones
    # can put them from where its hip or shoulder actually is (the end where ours is).
    posed_parts = pose.positions.copy()
    # The rig's pelvis is put where its hips' midpoint is ours (its pelvis joint may sit higher
    # or further back between the hips than the capture's): then only the hips' spread differs.
    pelvis_turn = pose.pelvis2world @ rest_frames["pelvis"].T
    hips = [int(src["hip_l"]), int(src["hip_r"])]  # type: ignore[arg-type]
    rig_hips = np.einsum("fab,b->fa", pelvis_turn, rest[hips].mean(axis=0) - rest[pelvis])
    our_hips = posed_parts[:, [J["hip_l"], J["hip_r"]]].mean(axis=1) - posed_parts[:, J["pelvis"]]
    pelvis_at = posed_parts[:, J["pelvis"]] + our_hips - rig_hips
    for j in range(n):
        p = int(rig.parents[j])
        if p < 0:
            where[:, j] = rest[j]
        else:
            where[:, j] = where[:, p] + np.einsum("fab,b->fa", delta[:, p], rest[j] - rest[p])
        if j == rig.translated:
            # Joints above the pelvis keep their rest pose: the pelvis's own move is theirs.
            where[:, j] = where[:, j] + pelvis_at - rest[pelvis]
        parent_delta = eye if p < 0 else delta[:, p]
        c = plan.part[j]
        if c == "pelvis":
            delta[:, j] = pelvis_turn
        elif c:
            if c in LIMBS:
                _reach_with_rig_bones(rig, pose, posed_parts, c, where[:, j])
            posed = part_frames(posed_parts, pose.pelvis2world, pose.thorax2world,
                                pose.head2world, pose.leg2world, pose.arm2world,
                                {c: where[:, j]})[c]
            delta[:, j] = posed @ rest_frames[c].T
        elif plan.aim[j]:
            target = posed_parts[:, J[plan.aim[j]]]
            rest_bone = rig.parts_at_rest[J[plan.aim[j]]] - rest[j]
            now = np.einsum("fab,b->fa", parent_delta, rest_bone)
            delta[:, j] = rotation_between(now, target - where[:, j]) @ parent_delta
        else:
            delta[:, j] = parent_delta
    # Twist joints: turned about their bone by their share of the twist between the part above
    # and the part below (both done above); joints that only follow their parent follow the
    # turned joint; then the positions, by the final deltas.
    follows = [not (plan.part[j] or plan.aim[j]) or plan.above_pelvis[j] for j in range(n)]
    for j in range(n):
        t = plan.twist[j]
        p = int(rig.parents[j])
        if t is not None:
            upper, lower, share = t
            a, b = src[upper], src[lower]
            assert a is not None and b is not None
            axis = normalize(rest[b] - rest[a])
            relative = np.swapaxes(delta[:, a], -1, -2) @ delta[:, b]
            turn = axis_angle(np.broadcast_to(axis, (n_frames, 3)),
                              share * _twist_angle(relative, axis))
            delta[:, j] = delta[:, j] @ turn
        elif follows[j] and p >= 0:
            delta[:, j] = delta[:, p]
        if p >= 0 and j != rig.translated:
            where[:, j] = where[:, p] + np.einsum("fab,b->fa", delta[:, p], rest[j] - rest[p])
    joint2world = delta @ rig.rest2world
    return RigPose(delta, joint2world, where)


__all__ = ["Rig", "RigPose", "load_rig", "rig_input_files", "rig_pose", "twist_shares"]
