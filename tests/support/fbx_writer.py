"""ASCII FBX 7.4 files written from BVH clips, for the FBX import tests (no FBX file is shipped).

A skeleton of ``LimbNode`` models (``Lcl Translation`` / ``Lcl Rotation``, a hierarchy by
``OO`` connections) and one animation stack (take) per clip, each with a layer and curves for
every joint that has channels, sampled one key a frame. Centimetres (``UnitScaleFactor`` 1, the
FBX default) and Y up unless told otherwise; the BVH's numbers are written as they are, so a
Bandai clip (centimetres, Y up) is the same motion in both files.

``joint_frames``: a fixed rotation Q_j per joint (n_joints, 3, 3) turns each FBX joint's axes
away from the BVH's (as rigs with bones along their own X axis do), so the FBX rest pose has
joint orientations other than the identity: the joint's global orientation is the BVH's times
Q_j, its local rotation ``Q_parent^T R Q_j``, its translation ``Q_parent^T offset``. With
``pre_rotation`` the rest part ``Q_parent^T Q_j`` goes to the ``PreRotation`` property (always
XYZ, as FBX defines it) and the animated ``Lcl Rotation`` is ``Q_j^T R Q_j``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ecs_anim.io.bvh import BvhMotion, joint_local_transforms
from support.bvh_reference import euler_angles

#: FBX time units a second (KTime).
KTIME_PER_S = 46186158000
#: ufbx's / FBX's rotation orders (``RotationOrder`` enum): 0 XYZ means R = Rz Ry Rx.
FBX_ORDERS = {"XYZ": 0, "XZY": 1, "YZX": 2, "YXZ": 3, "ZXY": 4, "ZYX": 5}
#: The matrix product order (BVH channel order) of each FBX order: "XYZ" is Rz @ Ry @ Rx.
PRODUCT_ORDER = {name: name[::-1] for name in FBX_ORDERS}


@dataclass
class Take:
    """One animation stack: its name and the clip whose frames it holds (same skeleton)."""

    name: str
    motion: BvhMotion


def turned_joint_frames(n_joints: int, seed: int = 2005) -> np.ndarray:
    """A turned frame per joint (n_joints, 3, 3), as rigs with bones along their own axes
    have: ``joint_frames`` for :func:`fbx_text`."""
    from ecs_anim.core.rotations import axis_angle

    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n_joints, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return axis_angle(axes, rng.uniform(0.1, np.pi, n_joints))


def fbx_angles(matrices: np.ndarray, order: str) -> np.ndarray:
    """FBX ``Lcl Rotation`` values (n, 3): degrees about X, Y, Z, of rotation matrices
    (n, 3, 3) for the FBX rotation ``order`` (``"XYZ"``: R = Rz Ry Rx)."""
    product = PRODUCT_ORDER[order]
    angles = euler_angles(matrices, product)  # about product[k] each
    out = np.empty_like(angles)
    for k, axis in enumerate(product):
        out[:, "XYZ".index(axis)] = angles[:, k]
    return out


def _vec(v) -> str:
    return ",".join(repr(float(x) + 0.0) for x in v)


def _numbers(values) -> str:
    return ",".join(repr(float(x) + 0.0) for x in values)


def fbx_text(takes: list[Take], names: list[str] | None = None, order: str = "XYZ",
             joint_frames: np.ndarray | None = None, pre_rotation: bool = False,
             unit_scale_factor: float = 1.0, up_axis: int = 1, fps: float | None = None,
             animated: bool = True) -> str:
    """The ASCII FBX text of ``takes`` (their clips share the first one's skeleton); with
    ``animated`` False, the skeleton alone, with no animation stack (a rig).

    ``names``: the joints' names in the FBX (default: the BVH's); ``order``: the FBX
    ``RotationOrder`` of every joint; ``unit_scale_factor``: centimetres per file unit as FBX
    states it; ``up_axis``: 1 (Y) or 2 (Z); ``fps``: the scene's frame rate (default: the first
    clip's)."""
    skeleton = takes[0].motion.skeleton
    joints = skeleton.joints
    n = len(joints)
    names = names or skeleton.names
    q = np.broadcast_to(np.eye(3), (n, 3, 3)) if joint_frames is None else joint_frames
    q_parent = np.stack([q[j.parent] if j.parent >= 0 else np.eye(3) for j in joints])
    fps = fps or takes[0].motion.fps
    ids = {"model": lambda j: 1_000_000 + j, "attr": lambda j: 2_000_000 + j}
    out = ["; FBX 7.4.0 project file", "; written by ecs_anim's tests (tests/support/fbx_writer.py)",
           "", "FBXHeaderExtension:  {", "\tFBXHeaderVersion: 1003", "\tFBXVersion: 7400",
           '\tCreator: "ecs_anim tests"', "}",
           "GlobalSettings:  {", "\tVersion: 1000", "\tProperties70:  {",
           f'\t\tP: "UpAxis", "int", "Integer", "",{up_axis}',
           '\t\tP: "UpAxisSign", "int", "Integer", "",1',
           f'\t\tP: "FrontAxis", "int", "Integer", "",{2 if up_axis == 1 else 1}',
           f'\t\tP: "FrontAxisSign", "int", "Integer", "",{1 if up_axis == 1 else -1}',
           '\t\tP: "CoordAxis", "int", "Integer", "",0',
           '\t\tP: "CoordAxisSign", "int", "Integer", "",1',
           f'\t\tP: "UnitScaleFactor", "double", "Number", "",{unit_scale_factor!r}',
           '\t\tP: "TimeMode", "enum", "", "",14',
           f'\t\tP: "CustomFrameRate", "double", "Number", "",{float(fps)!r}',
           "\t}", "}", "Objects:  {"]
    connections: list[str] = []
    # Rest (static) values: the BVH's OFFSETs, no rotation.
    for j, joint in enumerate(joints):
        rest_local = q_parent[j].T @ q[j]
        pre = fbx_angles(rest_local[None], "XYZ")[0] if pre_rotation else np.zeros(3)
        lcl = np.zeros(3) if pre_rotation else fbx_angles(rest_local[None], order)[0]
        out += [f'\tNodeAttribute: {ids["attr"](j)}, "NodeAttribute::{names[j]}", "LimbNode" {{',
                '\t\tTypeFlags: "Skeleton"', "\t}",
                f'\tModel: {ids["model"](j)}, "Model::{names[j]}", "LimbNode" {{',
                "\t\tVersion: 232", "\t\tProperties70:  {",
                f'\t\t\tP: "RotationOrder", "enum", "", "",{FBX_ORDERS[order]}',
                '\t\t\tP: "RotationActive", "bool", "", "",1',
                '\t\t\tP: "InheritType", "enum", "", "",1',
                f'\t\t\tP: "PreRotation", "Vector3D", "Vector", "",{_vec(pre)}',
                f'\t\t\tP: "Lcl Translation", "Lcl Translation", "", "A",{_vec(q_parent[j].T @ joint.offset)}',
                f'\t\t\tP: "Lcl Rotation", "Lcl Rotation", "", "A",{_vec(lcl)}',
                "\t\t}", "\t\tShading: Y", '\t\tCulling: "CullingOff"', "\t}"]
        connections += [f'\tC: "OO",{ids["model"](j)},{ids["model"](joint.parent) if joint.parent >= 0 else 0}',
                        f'\tC: "OO",{ids["attr"](j)},{ids["model"](j)}']
    next_id = 10_000_000
    for take in takes if animated else []:
        rotations, translations = joint_local_transforms(take.motion)
        n_frames = take.motion.n_frames
        ticks = [round(k * KTIME_PER_S / fps) for k in range(n_frames)]
        stack, layer, next_id = next_id, next_id + 1, next_id + 2
        out += [f'\tAnimationStack: {stack}, "AnimStack::{take.name}", "" {{', "\t\tProperties70:  {",
                '\t\t\tP: "LocalStart", "KTime", "Time", "",0',
                f'\t\t\tP: "LocalStop", "KTime", "Time", "",{ticks[-1]}',
                '\t\t\tP: "ReferenceStart", "KTime", "Time", "",0',
                f'\t\t\tP: "ReferenceStop", "KTime", "Time", "",{ticks[-1]}',
                "\t\t}", "\t}",
                f'\tAnimationLayer: {layer}, "AnimLayer::BaseLayer", "" {{', "\t}"]
        connections.append(f'\tC: "OO",{layer},{stack}')
        for j, joint in enumerate(joints):
            if not joint.channels:
                continue
            local = np.swapaxes(q_parent[j], -1, -2) @ rotations[:, j] @ q[j]  # (F, 3, 3)
            if pre_rotation:
                local = np.swapaxes(q_parent[j].T @ q[j], -1, -2) @ local
            curves = {"T": translations[:, j] @ q_parent[j],  # Q_parent^T t, each frame
                      "R": fbx_angles(local, order)}
            for prop, values in curves.items():
                node, next_id = next_id, next_id + 1
                out += [f'\tAnimationCurveNode: {node}, "AnimCurveNode::{prop}", "" {{',
                        "\t\tProperties70:  {"]
                out += [f'\t\t\tP: "d|{a}", "Number", "", "A",{float(values[0, k])!r}'
                        for k, a in enumerate("XYZ")]
                out += ["\t\t}", "\t}"]
                connections += [f'\tC: "OO",{node},{layer}',
                                f'\tC: "OP",{node},{ids["model"](j)}, '
                                f'"{"Lcl Translation" if prop == "T" else "Lcl Rotation"}"']
                for k, a in enumerate("XYZ"):
                    curve, next_id = next_id, next_id + 1
                    out += [f'\tAnimationCurve: {curve}, "AnimCurve::", "" {{',
                            f"\t\tDefault: {float(values[0, k])!r}", "\t\tKeyVer: 4008",
                            f"\t\tKeyTime: *{n_frames} {{", f"\t\t\ta: {','.join(map(str, ticks))}",
                            "\t\t}", f"\t\tKeyValueFloat: *{n_frames} {{",
                            f"\t\t\ta: {_numbers(values[:, k])}", "\t\t}",
                            "\t\tKeyAttrFlags: *1 {", "\t\t\ta: 4", "\t\t}",  # linear
                            "\t\tKeyAttrDataFloat: *4 {", "\t\t\ta: 0,0,0,0", "\t\t}",
                            "\t\tKeyAttrRefCount: *1 {", f"\t\t\ta: {n_frames}", "\t\t}", "\t}"]
                    connections.append(f'\tC: "OP",{curve},{node}, "d|{a}"')
    out += ["}", "Connections:  {", *connections, "}", ""]
    return "\n".join(out)


def write_fbx(path: Path, takes: list[Take], **options) -> Path:
    """Write :func:`fbx_text` of ``takes`` to ``path``; returns ``path``."""
    path.write_text(fbx_text(takes, **options), encoding="utf-8")
    return path
