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
_DTYPES = {5123: np.uint16, 5125: np.uint32, 5126: np.float32, 5121: np.uint8}
_WIDTH = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
# glTF's Y up -> our Z up: (x, y, z) -> (x, -z, y).
_GLTF_TO_OURS = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])


def bvh_joints(path: Path) -> np.ndarray:
    """(frames, 22, 3) the canonical joints of an exported .bvh, metres, Z up."""
    names, positions = reference_world(path, 1.0, "y")
    index = [names.index(j) if j in names else names.index(BVH_END_SITES[j]) for j in JOINTS]
    return positions[:, index]


def glb_joints(path: Path) -> np.ndarray:
    """(frames, 22, 3) the canonical joints of an exported .glb (its nodes of those names),
    metres, Z up, at each sample of its one animation."""
    doc = pygltflib.GLTF2.load_from_bytes(path.read_bytes())
    blob = doc.binary_blob()

    def accessor(k: int) -> np.ndarray:
        a = doc.accessors[k]
        view = doc.bufferViews[a.bufferView]
        width = _WIDTH[a.type]
        data = np.frombuffer(blob, _DTYPES[a.componentType], a.count * width,
                             (view.byteOffset or 0) + (a.byteOffset or 0))
        return data.reshape(a.count, width).astype(np.float64)

    (animation,) = doc.animations
    frames = accessor(animation.samplers[0].input).shape[0]
    nodes = doc.nodes
    t = np.array([[n.translation or [0.0, 0.0, 0.0] for n in nodes]] * frames)
    q = np.array([[n.rotation or [0.0, 0.0, 0.0, 1.0] for n in nodes]] * frames)
    for channel in animation.channels:
        values = accessor(animation.samplers[channel.sampler].output)
        target = {"translation": t, "rotation": q}[channel.target.path]
        target[:, channel.target.node] = values
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    rotation = np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)
    parent = {c: p for p, n in enumerate(nodes) for c in (n.children or [])}
    world_r, world_t = {}, {}

    def place(k: int) -> None:
        if k in world_t:
            return
        if k not in parent:
            world_r[k], world_t[k] = rotation[:, k], t[:, k]
            return
        place(parent[k])
        world_r[k] = world_r[parent[k]] @ rotation[:, k]
        world_t[k] = world_t[parent[k]] + np.einsum("fij,fj->fi", world_r[parent[k]], t[:, k])

    names = [n.name for n in nodes]
    for k in range(len(nodes)):
        place(k)
    return np.stack([world_t[names.index(j)] for j in JOINTS], axis=1) @ _GLTF_TO_OURS.T
