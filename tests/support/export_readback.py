"""Exported files read back independently of the writers: a .bvh through a plain forward
kinematics (:func:`support.bvh_reference.reference_world`: a non-root joint's position channels
replace its OFFSET), a .glb through glTF's node rules (translation, rotation and scale sampled
per frame, composed down the node tree), both turned into our Z-up world by hand.

Each gives the canonical joints (``ecs_anim.JOINTS``) as (frames, 22, 3) metres, so a file can be
compared with its ``.npz`` frame by frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib

from ecs_anim.core.skeleton import JOINTS
from support.bvh_reference import reference_world

#: A canonical joint that a BVH holds as an End Site when its body never changed.
BVH_END_SITES = {"head_top": "head.end", "hand_l": "wrist_l.end", "hand_r": "wrist_r.end"}
# glTF's Y up -> our Z up: (x, y, z) -> (x, -z, y).
GLTF_TO_OURS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def bvh_joints(path: Path) -> np.ndarray:
    """(frames, 22, 3) the canonical joints of an exported .bvh, metres, Z up."""
    names, positions = reference_world(path, 1.0, "y")
    index = [names.index(j) if j in names else names.index(BVH_END_SITES[j]) for j in JOINTS]
    return positions[:, index]


def quat_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4), scalar-last, normalized first."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def glb_world(path: Path) -> tuple[list[str], np.ndarray]:
    """(node names, (frames, nodes, 4, 4) node-to-world transforms in glTF axes) of a GLB's one
    animation: each node's TRS (or matrix) with the animated channels replacing theirs, composed
    down the node tree."""
    doc = pygltflib.GLTF2.load_from_bytes(path.read_bytes())
    blob = doc.binary_blob()
    widths = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}

    def accessor(k: int) -> np.ndarray:
        a = doc.accessors[k]
        view = doc.bufferViews[a.bufferView]
        assert a.componentType == 5126
        data = np.frombuffer(blob, np.float32, a.count * widths[a.type],
                             (view.byteOffset or 0) + (a.byteOffset or 0))
        return data.reshape(a.count, -1).astype(np.float64)

    (animation,) = doc.animations
    frames = len(accessor(animation.samplers[0].input))
    nodes = doc.nodes
    t = np.array([[n.translation or [0.0, 0.0, 0.0] for n in nodes]] * frames, dtype=float)
    q = np.array([[n.rotation or [0.0, 0.0, 0.0, 1.0] for n in nodes]] * frames, dtype=float)
    s = np.array([[n.scale or [1.0, 1.0, 1.0] for n in nodes]] * frames, dtype=float)
    for channel in animation.channels:
        target = {"translation": t, "rotation": q}[channel.target.path]
        target[:, channel.target.node] = accessor(animation.samplers[channel.sampler].output)
    local = np.tile(np.eye(4), (frames, len(nodes), 1, 1))
    local[..., :3, :3] = quat_matrix(q) * s[..., None, :]
    local[..., :3, 3] = t
    for k, node in enumerate(nodes):
        if node.matrix is not None:
            local[:, k] = np.array(node.matrix, float).reshape(4, 4).T
    parent = {c: p for p, n in enumerate(nodes) for c in (n.children or [])}
    world = np.full_like(local, np.nan)

    def place(k: int) -> None:
        if not np.isnan(world[0, k, 0, 0]):
            return
        if k in parent:
            place(parent[k])
            world[:, k] = world[:, parent[k]] @ local[:, k]
        else:
            world[:, k] = local[:, k]

    for k in range(len(nodes)):
        place(k)
    return [n.name for n in nodes], world


def glb_joints(path: Path) -> np.ndarray:
    """(frames, 22, 3) the canonical joints of an exported .glb (its nodes of those names),
    metres, Z up, at each sample of its one animation (:func:`glb_world`)."""
    names, world = glb_world(path)
    return np.stack([world[:, names.index(j), :3, 3] for j in JOINTS], axis=1) @ GLTF_TO_OURS.T
