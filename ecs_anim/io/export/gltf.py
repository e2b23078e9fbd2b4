"""A normalized motion played on a body, written as binary glTF 2.0 (``.glb``).

glTF's axes are Y up, the asset facing +Z with its left along +X, metres: the BVH export's axes
(DESIGN §8), so the same local rotations (:func:`ecs_anim.io.export.skeleton.local_rotations`) and the
same world conversion (the inverse of DESIGN §2's Y-up -> Z-up rotation) serve both files. The
file holds:

- the export skeleton (:data:`~ecs_anim.io.export.skeleton.EXPORT_NAMES`, parents
  :data:`~ecs_anim.io.export.skeleton.EXPORT_PARENTS`) as a node hierarchy whose rest pose is the BVH's
  T-pose, standing on the ground (soles at y = 0), plus a leaf node per end site (``toe_tip_l``,
  ``head_top``, ``hand_l``, ...: the canonical joints the hierarchy ends in);
- one animation, ``motion``: a rotation channel per joint and the root's translation, sampled
  once per frame (LINEAR, so a player reproduces every frame exactly and blends between them);
- a mesh of capsules, one per bone, each skinned rigidly (weight 1) to the joint that carries
  it, so any viewer shows a body.

A body that changed while the motion played (``lengths`` given, not every frame on ``morph``):
the rest pose is ``morph``, the final body, and every node (joint or end site) whose offset from
its parent differs on some frame gets a translation channel holding that offset on each frame,
so the joints are exact on every frame; the capsules keep the final body's sizes (a bone shorter
than its capsule earlier in the motion overlaps its neighbour). A body that never changed is
written as before, byte for byte.

Written with pygltflib: the JSON document is pygltflib's objects and the binary chunk is the
accessors' arrays laid end to end, each on a 4-byte boundary.
"""

from __future__ import annotations

from importlib import metadata

import numpy as np
import pygltflib as gl
from numpy.typing import NDArray

from ecs_anim.core.morphology import Morphology
from ecs_anim.core.normalized import DecodedPose
from ecs_anim.core.rotations import quat_from_matrix
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.export.skeleton import (
    EXPORT_JOINTS,
    EXPORT_NAMES,
    EXPORT_PARENTS,
    changing_offsets,
    local_rotations,
    rest_offsets,
)
from ecs_anim.io.importing import YUP_TO_ZUP

F64 = NDArray[np.float64]

#: The canonical joint (or, for the toes, a descriptive name) at each export joint's end site.
END_SITE_NAMES: dict[str, str] = {"toe_l": "toe_tip_l", "toe_r": "toe_tip_r", "head": "head_top",
                                  "wrist_l": "hand_l", "wrist_r": "hand_r"}

#: Capsule radius of a bone for a 1.75 m body, by the segment length that sets the bone (scaled
#: with stature); cosmetic, chosen to read as a body in a viewer.
CAPSULE_RADIUS_M: dict[str, float] = {
    "pelvis": 0.075, "thigh": 0.075, "shank": 0.055, "foot": 0.045,
    "spine_lower": 0.11, "spine_middle": 0.12, "spine_upper": 0.10, "neck": 0.05, "head": 0.095,
    "clavicle": 0.045, "upper_arm": 0.048, "forearm": 0.04, "hand": 0.035,
}
REFERENCE_STATURE_M = 1.75
CAPSULE_SEGMENTS = 12  # vertices around a capsule
CAPSULE_CAP_RINGS = 4  # latitude rings on each hemisphere, the equator included
BODY_COLOUR = (0.80, 0.62, 0.48, 1.0)  # linear RGBA


def _generator() -> str:
    try:
        return f"ecs_anim {metadata.version('ecs_anim')}"
    except metadata.PackageNotFoundError:  # run from a source tree that was never installed
        return "ecs_anim"


def _radius(length_name: str, morph: Morphology) -> float:
    """``thigh_l`` -> the thigh's radius, scaled by stature."""
    kind = length_name[:-2] if length_name[-2:] in ("_l", "_r") else length_name
    return CAPSULE_RADIUS_M[kind] * morph.stature / REFERENCE_STATURE_M


def capsule(start: F64, end: F64, radius: float) -> tuple[F64, F64, NDArray[np.int64]]:
    """A closed capsule around the segment ``start``-``end`` (each (3,), not equal): every vertex
    lies ``radius`` from the segment.

    Returns positions (V, 3), unit normals (V, 3) and counter-clockwise (outward) triangles
    (T, 3) indexing them, with V = 2 + 2 * CAPSULE_CAP_RINGS * CAPSULE_SEGMENTS.
    """
    axis = (end - start) / np.linalg.norm(end - start)
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]  # the world axis least along the bone
    side = np.cross(axis, helper)
    side /= np.linalg.norm(side)
    up = np.cross(axis, side)
    around = 2.0 * np.pi * np.arange(CAPSULE_SEGMENTS) / CAPSULE_SEGMENTS
    rings = CAPSULE_CAP_RINGS
    # Latitudes from just above the bottom pole to the equator, then equator to below the top.
    latitude = np.concatenate([np.linspace(-np.pi / 2, 0.0, rings + 1)[1:],
                               np.linspace(0.0, np.pi / 2, rings + 1)[:-1]])  # (2R,)
    centre = np.where(np.arange(2 * rings) < rings, 0.0, 1.0)  # 0: start cap, 1: end cap
    radial = np.cos(around)[:, None] * side + np.sin(around)[:, None] * up  # (S, 3)
    ring_normals = (np.cos(latitude)[:, None, None] * radial[None]
                    + np.sin(latitude)[:, None, None] * axis)  # (2R, S, 3)
    ring_centres = start + centre[:, None] * (end - start)  # (2R, 3)
    normals = np.concatenate([-axis[None], ring_normals.reshape(-1, 3), axis[None]])
    positions = np.concatenate([start[None] - radius * axis,
                                (ring_centres[:, None] + radius * ring_normals).reshape(-1, 3),
                                end[None] + radius * axis])
    s = CAPSULE_SEGMENTS
    nxt = (np.arange(s) + 1) % s
    ring = 1 + s * np.arange(2 * rings)[:, None]  # first vertex of each ring, (2R, 1)
    bottom = np.stack([np.zeros(s, dtype=np.int64), 1 + nxt, 1 + np.arange(s)], axis=-1)
    lower, upper = ring[:-1] + np.arange(s), ring[1:] + np.arange(s)  # (2R-1, S)
    lower_next, upper_next = ring[:-1] + nxt, ring[1:] + nxt
    # ``around`` turns from ``side`` to ``up`` = axis x side, counter-clockwise seen from +axis:
    # outward-facing (counter-clockwise seen from outside) is then lower, next around, upper.
    band = np.concatenate([np.stack([lower, lower_next, upper_next], axis=-1).reshape(-1, 3),
                           np.stack([lower, upper_next, upper], axis=-1).reshape(-1, 3)])
    top_pole = len(positions) - 1
    top = np.stack([np.full(s, top_pole), ring[-1] + np.arange(s), ring[-1] + nxt], axis=-1)
    return positions, normals, np.concatenate([bottom, band, top])


class _BinaryChunk:
    """The binary chunk being built, with pygltflib's buffer views and accessors into it."""

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.length = 0
        self.buffer_views: list[gl.BufferView] = []
        self.accessors: list[gl.Accessor] = []

    def view(self, data: NDArray[np.generic], target: int | None = None) -> int:
        """Append ``data`` (C order) as a new buffer view; returns its index."""
        raw = np.ascontiguousarray(data).tobytes()
        self.buffer_views.append(gl.BufferView(buffer=0, byteOffset=self.length,
                                               byteLength=len(raw), target=target))
        pad = -len(raw) % 4  # every view starts 4-byte aligned (the largest component size)
        self.parts.append(raw + b"\0" * pad)
        self.length += len(raw) + pad
        return len(self.buffer_views) - 1

    def accessor(self, view: int, data: NDArray[np.generic], kind: str, component: int,
                 byte_offset: int = 0, bounds: bool = False, normalized: bool = False) -> int:
        """An accessor over ``data`` (count, *element) already stored in ``view`` at
        ``byte_offset``; ``bounds`` records min/max (required for positions and animation
        times). Returns its index."""
        flat = data.reshape(len(data), -1)
        self.accessors.append(gl.Accessor(
            bufferView=view, byteOffset=byte_offset, componentType=component, count=len(data),
            type=kind, normalized=normalized or None,
            min=flat.min(axis=0).tolist() if bounds else None,
            max=flat.max(axis=0).tolist() if bounds else None))
        return len(self.accessors) - 1

    def array(self, data: NDArray[np.generic], kind: str, component: int,
              target: int | None = None, bounds: bool = False) -> int:
        """One array as its own view and accessor; returns the accessor's index."""
        return self.accessor(self.view(data, target), data, kind, component, bounds=bounds)

    def blob(self) -> bytes:
        return b"".join(self.parts)


def capsule_mesh(chunk: _BinaryChunk, bones: list[tuple[F64, F64, float, int]],
                 n_joints: int) -> gl.Mesh:
    """The body drawn as a capsule on each bone, rigidly skinned: ``bones`` (start, end (3,) m,
    radius m, the skin joint that carries it), of a skin of ``n_joints`` joints; its vertices,
    normals, joints, weights and indices added to ``chunk`` in that order. One mesh, "body",
    with material 0 (the glTF writer's and the writer onto a rig's)."""
    positions, normals, triangles, owners = [], [], [], []
    count = 0
    for start, end, radius, joint in bones:
        v, nrm, t = capsule(start, end, radius)
        positions.append(v)
        normals.append(nrm)
        triangles.append(t + count)
        owners.append(np.full(len(v), joint))
        count += len(v)
    joint_type = (np.uint8, gl.UNSIGNED_BYTE) if n_joints <= 256 else (np.uint16, gl.UNSIGNED_SHORT)
    vertex_joints = np.zeros((count, 4), dtype=joint_type[0])
    vertex_joints[:, 0] = np.concatenate(owners)
    weights = np.zeros((count, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    index_type = (np.uint16, gl.UNSIGNED_SHORT) if count < 65535 else (np.uint32, gl.UNSIGNED_INT)
    attributes = gl.Attributes(
        POSITION=chunk.array(np.concatenate(positions).astype(np.float32), "VEC3", gl.FLOAT,
                             gl.ARRAY_BUFFER, bounds=True),
        NORMAL=chunk.array(np.concatenate(normals).astype(np.float32), "VEC3", gl.FLOAT,
                           gl.ARRAY_BUFFER),
        JOINTS_0=chunk.array(vertex_joints, "VEC4", joint_type[1], gl.ARRAY_BUFFER),
        WEIGHTS_0=chunk.array(weights, "VEC4", gl.FLOAT, gl.ARRAY_BUFFER))
    indices = chunk.array(np.concatenate(triangles).reshape(-1).astype(index_type[0]), "SCALAR",
                          index_type[1], gl.ELEMENT_ARRAY_BUFFER)
    return gl.Mesh(name="body", primitives=[gl.Primitive(attributes=attributes, indices=indices,
                                                         material=0, mode=gl.TRIANGLES)])


def _continuous(quats: F64) -> F64:
    """Flip signs along the frame axis so neighbouring frames' quaternions (frames, ..., 4) lie
    in one hemisphere: a player's slerp between samples then takes the short way."""
    same_side = np.sum(quats[1:] * quats[:-1], axis=-1) >= 0.0  # (frames-1, ...)
    sign = np.concatenate([np.ones((1,) + quats.shape[1:-1]),
                           np.cumprod(np.where(same_side, 1.0, -1.0), axis=0)])
    out: F64 = quats * sign[..., None]
    return out


def _rest_world_positions(joint_offsets: F64, root: F64) -> F64:
    """Rest positions (E, 3) of the export joints with the root at ``root``: rest rotations
    are the identity, so offsets add along the chain (parents precede children)."""
    out = np.empty_like(joint_offsets)
    for k, parent in enumerate(EXPORT_PARENTS):  # chain order, 25 joints, once per file
        out[k] = root if parent < 0 else out[parent] + joint_offsets[k]
    return out


def glb_bytes(morph: Morphology, pelvis_in_world: F64, local: F64, fps: float,
              lengths: F64 | None = None) -> bytes:
    """A ``.glb`` of the pelvis path and the export skeleton's local rotations.

    Parameters
    ----------
    morph : the body (bone lengths, capsule sizes).
    pelvis_in_world : (frames, 3) metres, world Z up.
    local : (frames, len(EXPORT_NAMES), 3, 3) local rotations in BVH axes, as
        :func:`ecs_anim.io.export.skeleton.local_rotations` gives them.
    fps : frames per second (> 0).
    lengths : (frames, N_LENGTHS) metres, the body each frame was posed on, when it changed
        (``morph`` is then the final body; see the module docstring); None: ``morph`` throughout.

    The same inputs as :func:`ecs_anim.io.export.skeleton.bvh_from_rotations`; see the module docstring
    for what the file holds.
    """
    n_frames, n_joints = local.shape[0], len(EXPORT_NAMES)
    joint_offsets, end_offsets = rest_offsets(morph)
    ends = [k for k, j in enumerate(EXPORT_JOINTS) if j.end_site is not None]
    # Rest pose standing on the ground: the soles (an ankle height below the ankles) at y = 0.
    rest_no_root = _rest_world_positions(joint_offsets, np.zeros(3))
    soles = [rest_no_root[EXPORT_NAMES.index(f"ankle_{s}"), 1] - morph[f"ankle_height_{s}"]
             for s in "lr"]
    rest_root = np.array([0.0, -min(soles), 0.0])
    rest_joints = rest_no_root + rest_root
    rest_ends = rest_joints[ends] + end_offsets[ends]

    chunk = _BinaryChunk()
    # Nodes: the joints, then the end sites, then the mesh's own node at the scene root (a
    # skinned mesh's node must carry no transform of its own).
    nodes = [gl.Node(name=j.name,
                     translation=(rest_root if j.parent is None else joint_offsets[k]).tolist(),
                     children=[c for c in range(n_joints) if EXPORT_PARENTS[c] == k]
                     + [n_joints + e for e, parent in enumerate(ends) if parent == k])
             for k, j in enumerate(EXPORT_JOINTS)]
    nodes += [gl.Node(name=END_SITE_NAMES[EXPORT_NAMES[k]], translation=end_offsets[k].tolist())
              for k in ends]
    for node in nodes:
        node.children = node.children or None  # leaves: no empty list in the file
    skin_joints = list(range(n_joints + len(ends)))
    bind_positions = np.concatenate([rest_joints, rest_ends])  # (skin joints, 3), rest rotation I
    inverse_bind = np.tile(np.eye(4), (len(skin_joints), 1, 1))
    inverse_bind[:, :3, 3] = -bind_positions
    # glTF matrices are column-major: store each transposed.
    ibm_accessor = chunk.array(np.swapaxes(inverse_bind, 1, 2).astype(np.float32), "MAT4",
                               gl.FLOAT)

    # The body: a capsule on each bone of non-zero rest length, skinned to the joint carrying it.
    # A bone is (carrying joint, offset of its far end from it, the length that sets it); each
    # joint carries at most one, so a vertex's joint names its capsule.
    bones: list[tuple[int, F64, str]] = []
    for k, j in enumerate(EXPORT_JOINTS):
        if j.parent is not None and j.rest_offset[0]:  # the zero-length joints carry no bone
            bones.append((int(EXPORT_PARENTS[k]), joint_offsets[k], j.rest_offset[0]))
        if j.end_site is not None:
            bones.append((k, end_offsets[k], j.end_site[0]))
    mesh = capsule_mesh(chunk, [(rest_joints[joint], rest_joints[joint] + offset,
                                 _radius(length_name, morph), joint)
                                for joint, offset, length_name in bones], len(skin_joints))
    nodes.append(gl.Node(name="body", mesh=0, skin=0))

    # The animation: one time track shared by every sampler.
    times = (np.arange(n_frames) / fps).astype(np.float32)
    time_accessor = chunk.array(times, "SCALAR", gl.FLOAT, bounds=True)
    root_in_gltf = pelvis_in_world @ YUP_TO_ZUP  # Z up -> Y up: the inverse of DESIGN §2's turn
    quats = _continuous(quat_from_matrix(local))  # (frames, E, 4), x y z w as glTF stores them
    rotation_view = chunk.view(np.moveaxis(quats, 1, 0).astype(np.float32))  # joint-major
    samplers = [gl.AnimationSampler(input=time_accessor, interpolation="LINEAR",
                                    output=chunk.array(root_in_gltf.astype(np.float32), "VEC3",
                                                       gl.FLOAT))]
    channels = [gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(
        node=0, path="translation"))]
    for k in range(n_joints):
        output = chunk.accessor(rotation_view, quats[:, k], "VEC4", gl.FLOAT,
                                byte_offset=k * n_frames * 16)
        samplers.append(gl.AnimationSampler(input=time_accessor, interpolation="LINEAR",
                                            output=output))
        channels.append(gl.AnimationChannel(sampler=len(samplers) - 1,
                                            target=gl.AnimationChannelTarget(node=k,
                                                                             path="rotation")))
    moving = changing_offsets(morph, lengths)
    if moving is not None:  # a changed body: the offsets that change, animated per frame
        frame_joints, frame_ends, joint_moves, end_moves = moving
        targets = [(k, frame_joints[:, k]) for k in np.flatnonzero(joint_moves)] + \
            [(n_joints + e, frame_ends[:, k]) for e, k in enumerate(ends) if end_moves[k]]
        offsets = np.stack([values for _, values in targets]).astype(np.float32)  # node-major
        offset_view = chunk.view(offsets)
        for i, (node, _) in enumerate(targets):
            output = chunk.accessor(offset_view, offsets[i], "VEC3", gl.FLOAT,
                                    byte_offset=i * n_frames * 12)
            samplers.append(gl.AnimationSampler(input=time_accessor, interpolation="LINEAR",
                                                output=output))
            channels.append(gl.AnimationChannel(sampler=len(samplers) - 1,
                                                target=gl.AnimationChannelTarget(
                                                    node=int(node), path="translation")))

    document = gl.GLTF2(
        asset=gl.Asset(version="2.0", generator=_generator()),
        scene=0,
        scenes=[gl.Scene(name=morph.name, nodes=[0, len(nodes) - 1])],
        nodes=nodes,
        meshes=[mesh],
        skins=[gl.Skin(name="skeleton", skeleton=0, joints=skin_joints,
                       inverseBindMatrices=ibm_accessor)],
        materials=[gl.Material(name="body", pbrMetallicRoughness=gl.PbrMetallicRoughness(
            baseColorFactor=list(BODY_COLOUR), metallicFactor=0.0, roughnessFactor=0.8))],
        animations=[gl.Animation(name="motion", samplers=samplers, channels=channels)],
        accessors=chunk.accessors,
        bufferViews=chunk.buffer_views,
        buffers=[gl.Buffer(byteLength=chunk.length)],
    )
    document.set_binary_blob(chunk.blob())
    return b"".join(document.save_to_bytes())


def glb_from_pose(pose: DecodedPose, morph: Morphology, fps: float) -> bytes:
    """A ``.glb`` of decoded poses (frames leading) on ``morph``: as
    :func:`ecs_anim.io.export.skeleton.bvh_text`, for glTF."""
    return glb_bytes(morph, pose.positions[:, J["pelvis"]], local_rotations(pose), fps)


#: The binary chunk builder, the quaternion track smoother and the generator name, for the
#: export onto a user's rig (:mod:`ecs_anim.io.export.onto`).
BinaryChunk = _BinaryChunk
continuous_quaternions = _continuous
generator_name = _generator
