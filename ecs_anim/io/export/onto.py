"""A normalized motion written onto a user's rig (``export --onto RIG``): a BVH in the rig's own
hierarchy, channel order and unit, or a GLB in its node hierarchy (with its own mesh, skin and
materials when the rig is a GLB).

The motion is decoded on the rig's body (its measured segment lengths, as ``--morphology
RIG.bvh`` does) and every rig joint turned as :func:`~ecs_anim.io.export.rig.rig_pose` says.
A simulated run (``run --export DIR --onto RIG``, ``rec.save(..., onto=rig)``, ``batch
--onto``) is retargeted first: :func:`recorded_on_rig`. FBX is not written (no maintained
writer): convert the BVH or GLB in a DCC tool.
"""

from __future__ import annotations

import copy
import io
from pathlib import Path

import numpy as np
import pygltflib as gl
from numpy.typing import NDArray

from ecs_anim.core.errors import EcsAnimError
from ecs_anim.core.morphology import leg_length
from ecs_anim.core.normalized import DecodedPose, decode, encode, frames_from_positions
from ecs_anim.core.rotations import matrix_to_euler, quat_from_matrix
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.io.export.gltf import (
    BinaryChunk,
    capsule_mesh,
    continuous_quaternions,
    generator_name,
)
from ecs_anim.io.export.npz import write_npz
from ecs_anim.io.export.rig import Rig, RigPose, rig_pose
from ecs_anim.io.export.skeleton import body_frames
from ecs_anim.io.importing import YUP_TO_ZUP

F64 = NDArray[np.float64]

#: Capsule radius on a BVH rig's bones in a GLB, for a 1.75 m body (cosmetic).
RIG_BONE_RADIUS_M = 0.03


def _rotation_order(channels: list[str], name: str) -> str:
    order = "".join(c[0].upper() for c in channels if c.lower().endswith("rotation"))
    if len(order) != 3 or len(set(order)) != 3:
        raise EcsAnimError(f"rig joint {name}: {len(order)} rotation channels; writing a motion "
                           "onto a BVH rig needs three on every joint")
    return order


def bvh_onto_rig(rig: Rig, posed: RigPose, fps: float, decimals: int = 6) -> str:
    """BVH text of ``posed`` in the rig's own hierarchy: its names, OFFSETs, channels (each
    joint's own rotation order and position channels) and length unit, in its file axes."""
    skeleton = rig.bvh
    assert skeleton is not None
    file2world = rig.file2world
    unit = rig.metres_per_unit
    # Joint orientation in file axes (the rest pose is the identity there).
    joint2file = file2world.T @ posed.rest2posed @ file2world  # (F, J, 3, 3)
    parents = rig.parents
    local = np.swapaxes(joint2file[:, np.maximum(parents, 0)], -1, -2) @ joint2file
    local[:, parents < 0] = joint2file[:, parents < 0]
    move = (posed.positions[:, rig.translated] - rig.rest_in_world[rig.translated]) \
        @ file2world / unit  # (F, 3) file units; the joints above it keep their rest pose
    # The joint whose position channels carry the move: the translated one or, where it has none
    # (a glTF rig's pelvis below its root), the lowest one above it that has them.
    carrier = rig.translated
    while carrier >= 0 and not any(c.lower().endswith("position")
                                   for c in skeleton.joints[carrier].channels):
        carrier = int(parents[carrier])
    fmt = f"{{:.{decimals}f}}"
    columns: list[F64] = []
    lines = ["HIERARCHY"]
    children: dict[int, list[int]] = {}
    for i, p in enumerate(parents):
        children.setdefault(int(p), []).append(i)

    def name_of(i: int) -> str:
        return "_".join(rig.names[i].split()) or f"joint{i}"

    def emit(i: int, depth: int) -> None:
        pad = "\t" * depth
        joint = skeleton.joints[i]
        # (Rounded first: an offset a hair below zero is written 0, not -0.)
        offset = " ".join(fmt.format(round(float(x), decimals) + 0.0) for x in joint.offset)
        if joint.is_end_site:
            lines.extend([f"{pad}End Site", f"{pad}{{", f"{pad}\tOFFSET {offset}", f"{pad}}}"])
            return
        lines.append(f"{pad}{'ROOT' if parents[i] < 0 else 'JOINT'} {name_of(i)}")
        lines.extend([f"{pad}{{", f"{pad}\tOFFSET {offset}"])
        lines.append(f"{pad}\tCHANNELS {len(joint.channels)} {' '.join(joint.channels)}")
        order = _rotation_order(joint.channels, rig.names[i])
        euler = matrix_to_euler(local[:, i], order)
        rotations = iter(range(3))
        for channel in joint.channels:
            key = channel.lower()
            if key.endswith("position"):
                axis = "xyz".index(key[0])
                value = np.full(len(local), joint.offset[axis])
                if i == carrier:
                    value = value + move[:, axis]
                columns.append(value)
            else:
                columns.append(euler[:, next(rotations)])
        for c in children.get(i, []):
            emit(c, depth + 1)
        lines.append(f"{pad}}}")

    for root in children[-1]:
        emit(root, 0)
    values = np.stack(columns, axis=-1) if columns else np.zeros((len(local), 0))
    lines += ["MOTION", f"Frames: {len(values)}", f"Frame Time: {1.0 / fps:.8f}"]
    lines += [" ".join(fmt.format(float(v) + 0.0) for v in row) for row in values]
    return "\n".join(lines) + "\n"


def _gltf_world_rotations(rig: Rig, posed: RigPose) -> F64:
    """Each joint's world orientation in glTF axes (F, J, 3, 3): a GLB rig's nodes turned from
    their rest orientation; a BVH rig's joints from the identity (its nodes have no rest turn)."""
    world: F64 = YUP_TO_ZUP.T @ (posed.joint2world if rig.kind == "glb"
                                 else posed.rest2posed @ YUP_TO_ZUP)
    return world


def _animation(chunk: BinaryChunk, nodes: list[int], local: F64, translation: F64,
               translated_node: int, fps: float) -> gl.Animation:
    """One animation, ``motion``: a rotation channel per node of ``nodes`` (local (F, J, 3, 3),
    glTF axes) and the translation (F, 3) of ``translated_node``, sampled once per frame."""
    n_frames = local.shape[0]
    times = (np.arange(n_frames) / fps).astype(np.float32)
    time_accessor = chunk.array(times, "SCALAR", gl.FLOAT, bounds=True)
    quats = continuous_quaternions(quat_from_matrix(local))
    quats /= np.linalg.norm(quats, axis=-1, keepdims=True)
    samplers = [gl.AnimationSampler(input=time_accessor, interpolation="LINEAR",
                                    output=chunk.array(translation.astype(np.float32), "VEC3",
                                                       gl.FLOAT))]
    channels = [gl.AnimationChannel(sampler=0, target=gl.AnimationChannelTarget(
        node=translated_node, path="translation"))]
    for k, node in enumerate(nodes):
        samplers.append(gl.AnimationSampler(
            input=time_accessor, interpolation="LINEAR",
            output=chunk.array(np.ascontiguousarray(quats[:, k]).astype(np.float32), "VEC4",
                               gl.FLOAT)))
        channels.append(gl.AnimationChannel(sampler=len(samplers) - 1, target=gl.AnimationChannelTarget(
            node=node, path="rotation")))
    return gl.Animation(name="motion", samplers=samplers, channels=channels)


def _glb_onto_gltf_rig(rig: Rig, posed: RigPose, fps: float) -> bytes:
    """The rig's own document (meshes, skins, materials, buffers kept) with one animation,
    ``motion``, replacing any it had."""
    from ecs_anim.io.export.rig import gltf_world_matrices

    document = copy.deepcopy(rig.gltf)
    blob = document.binary_blob() or b""
    if len(document.buffers) > 1 or any(b.uri for b in document.buffers):
        raise EcsAnimError(f"--onto {rig.path}: a GLB with one embedded buffer is needed (this "
                           "rig's buffers are separate files or data URIs)")
    rest_world = gltf_world_matrices(document)
    world = _gltf_world_rotations(rig, posed)  # (F, J, 3, 3)
    node_parent = {c: p for p, node in enumerate(document.nodes) for c in (node.children or [])}
    n_frames = world.shape[0]
    parent_world = np.empty_like(world)
    for j, node in enumerate(rig.nodes):
        p = int(rig.parents[j])
        if p >= 0:
            parent_world[:, j] = world[:, p]
        elif node in node_parent:
            m = rest_world[node_parent[node], :3, :3]
            parent_world[:, j] = m / np.linalg.norm(m[:, 0])
        else:
            parent_world[:, j] = np.eye(3)
    local = np.swapaxes(parent_world, -1, -2) @ world
    # The translated joint's parent is at rest (joints above the pelvis do not turn).
    t_node = rig.nodes[rig.translated]
    parent_matrix = rest_world[node_parent[t_node]] if t_node in node_parent else np.eye(4)
    position = posed.positions[:, rig.translated] @ YUP_TO_ZUP  # (F, 3) glTF axes
    homogeneous = np.concatenate([position, np.ones((n_frames, 1))], axis=-1)
    translation = (homogeneous @ np.linalg.inv(parent_matrix).T)[:, :3]

    chunk = BinaryChunk()
    chunk.length = len(blob) + (-len(blob) % 4)
    base_views = len(document.bufferViews)
    base_accessors = len(document.accessors)
    animation = _animation(chunk, list(rig.nodes), local, translation, t_node, fps)
    for view in chunk.buffer_views:
        document.bufferViews.append(view)
    for accessor in chunk.accessors:
        accessor.bufferView += base_views
        document.accessors.append(accessor)
    for sampler in animation.samplers:
        sampler.input += base_accessors
        sampler.output += base_accessors
    document.animations = [animation]
    new_blob = blob + b"\0" * (-len(blob) % 4) + chunk.blob()
    if not document.buffers:
        document.buffers = [gl.Buffer()]
    document.buffers[0].byteLength = len(new_blob)
    document.set_binary_blob(new_blob)
    return b"".join(document.save_to_bytes())


def _glb_onto_bvh_rig(rig: Rig, posed: RigPose, fps: float) -> bytes:
    """A GLB of a BVH rig: its joints (End Sites too) as nodes in glTF axes (Y up, metres),
    rest rotations the identity, a capsule on every bone skinned to the joint carrying it."""
    n = rig.n_joints
    parents = rig.parents
    rest = rig.rest_in_world @ YUP_TO_ZUP  # (J, 3) glTF axes
    offsets = rest - np.where(parents[:, None] >= 0, rest[np.maximum(parents, 0)], 0.0)
    chunk = BinaryChunk()
    nodes = [gl.Node(name=rig.names[j], translation=offsets[j].tolist(),
                     children=[int(c) for c in np.flatnonzero(parents == j)] or None)
             for j in range(n)]
    inverse_bind = np.tile(np.eye(4), (n, 1, 1))
    inverse_bind[:, :3, 3] = -rest
    ibm = chunk.array(np.swapaxes(inverse_bind, 1, 2).astype(np.float32), "MAT4", gl.FLOAT)
    radius = RIG_BONE_RADIUS_M * rig.morphology.stature / 1.75
    lengths = np.linalg.norm(offsets, axis=1)
    mesh = capsule_mesh(chunk, [(rest[parents[j]], rest[j], min(radius, 0.3 * float(lengths[j])),
                                 int(parents[j]))
                                for j in range(n) if parents[j] >= 0 and lengths[j] >= 1e-6], n)
    nodes.append(gl.Node(name="body", mesh=0, skin=0))
    world = _gltf_world_rotations(rig, posed)
    parent_world = world[:, np.maximum(parents, 0)]
    parent_world[:, parents < 0] = np.eye(3)
    local = np.swapaxes(parent_world, -1, -2) @ world
    moving = [j for j in range(n) if rig.bvh is None or not rig.bvh.joints[j].is_end_site]
    moved = rig.translated
    above = int(parents[moved])
    # Joints above the translated one keep their rest pose, so its parent is at its rest place.
    translation = posed.positions[:, moved] @ YUP_TO_ZUP - (rest[above] if above >= 0 else 0.0)
    animation = _animation(chunk, moving, local[:, moving], translation, moved, fps)
    roots = [int(r) for r in np.flatnonzero(parents < 0)]
    document = gl.GLTF2(
        asset=gl.Asset(version="2.0", generator=generator_name()),
        scene=0, scenes=[gl.Scene(name=rig.name, nodes=roots + [n])], nodes=nodes,
        meshes=[mesh],
        skins=[gl.Skin(name=rig.name, skeleton=roots[0], joints=list(range(n)),
                       inverseBindMatrices=ibm)],
        materials=[gl.Material(name="body", pbrMetallicRoughness=gl.PbrMetallicRoughness(
            baseColorFactor=[0.80, 0.62, 0.48, 1.0], metallicFactor=0.0, roughnessFactor=0.8))],
        animations=[animation], accessors=chunk.accessors, bufferViews=chunk.buffer_views,
        buffers=[gl.Buffer(byteLength=chunk.length)])
    document.set_binary_blob(chunk.blob())
    return b"".join(document.save_to_bytes())


def glb_onto_rig(rig: Rig, posed: RigPose, fps: float) -> bytes:
    """A ``.glb`` of ``posed`` in the rig's node hierarchy (see the module docstring)."""
    if rig.kind == "glb":
        return _glb_onto_gltf_rig(rig, posed, fps)
    return _glb_onto_bvh_rig(rig, posed, fps)


def rig_of(onto: str | Path | Rig, map_spec: str | None = None) -> Rig:
    """``onto`` as a :class:`Rig` (a path is loaded with :func:`~ecs_anim.io.export.rig.load_rig`)."""
    from ecs_anim.io.export.rig import load_rig

    return onto if isinstance(onto, Rig) else load_rig(onto, map_spec)


def recorded_on_rig(rig: Rig, positions: F64, local_rotations: F64, lengths: F64) -> DecodedPose:
    """A simulated character's recorded postures retargeted onto the rig's body.

    Each frame is normalized on the body it was simulated on (paper eq. 1: its own segment
    lengths, so a body changed during the run too), with the simulation's pelvis and thorax
    frames, and decoded on ``rig.morphology``, as ``export --onto`` decodes a clip. The path
    is then the recording's, scaled by the ratio of leg lengths from where the character
    started (each frame's step times that frame's ratio): the rig starts where the character
    did, its feet step as far as its legs reach (no sliding) and its height above z = 0 scales
    with its legs.

    positions : (frames, N_JOINTS, 3) the recorded joints, metres, world Z up.
    local_rotations : (frames, len(EXPORT_NAMES), 3, 3) the export skeleton's, BVH axes.
    lengths : (frames, N_LENGTHS) the segment lengths each posture was made on, metres.
    Returns the pose (frames leading) on the rig's body, for
    :func:`~ecs_anim.io.export.rig.rig_pose`.
    """
    pelvis2world, thorax2world = body_frames(local_rotations)
    _, _, head2world = frames_from_positions(positions)
    poses = encode(positions, pelvis2world, thorax2world, head2world, lengths)
    pose = decode(poses, rig.morphology.lengths)
    ratio = leg_length(rig.morphology.lengths) / leg_length(lengths)  # (frames,)
    pelvis = positions[:, J["pelvis"]]
    steps = np.diff(pelvis[:, :2], axis=0) * ratio[1:, None]
    path = pelvis[0, :2] + np.concatenate([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    # decode put the pelvis at the recorded one times the ratio: move each frame onto the path.
    pose.positions[..., :2] += (path - pose.positions[:, J["pelvis"], :2])[:, None, :]
    return pose


def onto_rig_bytes(rig: Rig, pose: DecodedPose, kind: str, fps: float,
                   contacts: NDArray[np.bool_]) -> bytes:
    """One file of ``pose`` (decoded on ``rig.morphology``) onto the rig: ``kind`` ``"bvh"``
    (:func:`bvh_onto_rig`), ``"glb"`` (:func:`glb_onto_rig`) or ``"npz"`` (our joints on the
    rig's body, with ``contacts`` (frames, 2) bool, as without a rig)."""
    if kind == "npz":
        buffer = io.BytesIO()
        write_npz(buffer, pose.positions, fps, contacts)
        return buffer.getvalue()
    posed = rig_pose(rig, pose)
    if kind == "bvh":
        return bvh_onto_rig(rig, posed, fps).encode("utf-8")
    return glb_onto_rig(rig, posed, fps)
