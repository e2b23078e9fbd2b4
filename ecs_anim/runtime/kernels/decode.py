"""Compiled decode: normalized poses on each character's body (paper eq. 2 and §8).

Mirrors :func:`ecs_anim.core.normalized.decode` (the ``use_stretch=False`` path, what the tick
uses) :func:`decode_row` for one character, :func:`decode_rows` over a chunk of store rows
(``rows[lo:hi]``: one chunk per thread; by blocks of characters, the spines on the vector units:
:func:`spine_block`), :func:`decode` the Python entry over every row. The poses are passed as
:class:`PoseArrays` (the arrays of a
:class:`~ecs_anim.core.normalized.NormalizedPoses`, no copies) and the result written into
:class:`DecodedArrays` (the arrays of a :class:`~ecs_anim.core.normalized.DecodedPose`).

Joint and length indices are written here as literals (numba's cache keys on this file's source,
not on :mod:`ecs_anim.core.skeleton`'s); an import-time check pins them to the skeleton.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.core.skeleton import N_JOINTS, N_LENGTHS
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.lanes import BLOCK, Column, at, col3, col4, put3, put4
from ecs_anim.runtime.kernels.vec import (
    F64,
    TINY,
    Frame,
    Quat,
    Vec3,
    add,
    add_scaled,
    dot,
    frame_from_axes,
    jit,
    load3,
    load4,
    load_frame,
    matmul,
    matrix_from_quat,
    norm,
    normalize,
    quat_mul,
    rot_z,
    rotation_from_quat,
    scale,
    store3,
    store_frame,
    sub,
    to_world,
)

# Joints (ecs_anim.core.skeleton.JOINTS); side s (0 left, 1 right) adds 4 * s to a limb joint.
PELVIS, HIP, KNEE, ANKLE, TOE = 0, 1, 2, 3, 4
SPINE_1, SPINE_2, NECK, HEAD, HEAD_TOP = 9, 10, 11, 12, 13
SHOULDER, ELBOW, WRIST, HAND = 14, 15, 16, 17
# Lengths (ecs_anim.core.skeleton.LENGTHS); side s adds s.
L_PELVIS, L_THIGH, L_SHANK, L_FOOT = 0, 2, 4, 6
L_SPINE_LOWER, L_NECK, L_HEAD = 10, 13, 14
L_CLAVICLE, L_UPPER_ARM, L_FOREARM, L_HAND = 15, 17, 19, 21

assert (J["pelvis"], J["hip_l"], J["knee_l"], J["ankle_l"], J["toe_l"], J["hip_r"], J["toe_r"]) \
    == (PELVIS, HIP, KNEE, ANKLE, TOE, HIP + 4, TOE + 4)
assert (J["spine_1"], J["spine_2"], J["neck"], J["head"], J["head_top"]) \
    == (SPINE_1, SPINE_2, NECK, HEAD, HEAD_TOP)
assert (J["shoulder_l"], J["elbow_l"], J["wrist_l"], J["hand_l"], J["shoulder_r"], J["hand_r"]) \
    == (SHOULDER, ELBOW, WRIST, HAND, SHOULDER + 4, HAND + 4)
assert (L["pelvis_l"], L["thigh_l"], L["shank_l"], L["foot_l"], L["foot_r"], L["thigh_r"]) \
    == (L_PELVIS, L_THIGH, L_SHANK, L_FOOT, L_FOOT + 1, L_THIGH + 1)
assert (L["spine_lower"], L["spine_middle"], L["spine_upper"], L["neck"], L["head"]) \
    == (L_SPINE_LOWER, L_SPINE_LOWER + 1, L_SPINE_LOWER + 2, L_NECK, L_HEAD)
assert (L["clavicle_l"], L["upper_arm_l"], L["forearm_l"], L["hand_l"], L["hand_r"]) \
    == (L_CLAVICLE, L_UPPER_ARM, L_FOREARM, L_HAND, L_HAND + 1)
assert N_JOINTS == 22 and N_LENGTHS == 23

I64 = NDArray[np.int64]


class PoseArrays(NamedTuple):
    """The arrays of :class:`ecs_anim.core.normalized.NormalizedPoses` (same names, same order),
    as a tuple numba can take. Leading axis: store rows (n,); see ``NormalizedPoses`` for shapes."""

    root_position: F64
    root_heading: F64
    pelvis_local: F64
    hip_dir: F64
    leg_frame: F64
    leg_fraction: F64
    foot_dir: F64
    spine_points: F64
    thorax: F64
    neck_dir: F64
    head: F64
    head_top_dir: F64
    clavicle_dir: F64
    arm_frame: F64
    arm_fraction: F64
    hand_dir: F64
    stretch: F64


class DecodedArrays(NamedTuple):
    """The arrays of :class:`ecs_anim.core.normalized.DecodedPose` (same names and order).

    positions (n, N_JOINTS, 3) metres; pelvis2world, thorax2world, head2world (n, 3, 3);
    leg2world, arm2world (n, 2, 3, 3) [left, right]; frames hold their axes as columns.
    """

    positions: F64
    pelvis2world: F64
    thorax2world: F64
    head2world: F64
    leg2world: F64
    arm2world: F64


class LegPoseArrays(NamedTuple):
    """The arrays of :class:`PoseArrays` that :func:`decode_legs_row` reads (same names), for
    kernels that need only the legs."""

    root_position: F64
    root_heading: F64
    pelvis_local: F64
    hip_dir: F64
    leg_frame: F64
    leg_fraction: F64
    foot_dir: F64


def leg_pose_arrays(pose: PoseArrays) -> LegPoseArrays:
    """The leg arrays of ``pose`` (the same arrays, no copies)."""
    return LegPoseArrays(*(getattr(pose, name) for name in LegPoseArrays._fields))


def pose_arrays(poses: NormalizedPoses) -> PoseArrays:
    """The arrays of ``poses`` as a :class:`PoseArrays` (views, no copies)."""
    return PoseArrays(*(np.asarray(getattr(poses, name), dtype=np.float64)
                        for name in PoseArrays._fields))


def decoded_arrays(decoded: DecodedPose) -> DecodedArrays:
    """The arrays of ``decoded`` as a :class:`DecodedArrays` (no copies)."""
    return DecodedArrays(decoded.positions, decoded.pelvis2world, decoded.thorax2world,
                         decoded.head2world, decoded.leg2world, decoded.arm2world)


def decoded_pose(arrays: DecodedArrays) -> DecodedPose:
    """A :class:`DecodedPose` holding ``arrays`` (no copies)."""
    return DecodedPose(*arrays)


def empty_decoded(n: int) -> DecodedArrays:
    """Uninitialized output arrays for ``n`` rows."""
    return DecodedArrays(np.empty((n, N_JOINTS, 3)), np.empty((n, 3, 3)), np.empty((n, 3, 3)),
                         np.empty((n, 3, 3)), np.empty((n, 2, 3, 3)), np.empty((n, 2, 3, 3)))


def fits(arrays: DecodedArrays | DecodedPose | None, n: int) -> bool:
    """Whether ``arrays`` has the shapes of ``n`` decoded rows and is C-contiguous (so that the
    kernels can write it again: :func:`scatter_block` writes flat views)."""
    if arrays is None:
        return False
    shapes = ((n, N_JOINTS, 3), (n, 3, 3), (n, 3, 3), (n, 3, 3), (n, 2, 3, 3), (n, 2, 3, 3))
    if isinstance(arrays, DecodedPose):
        arrays = decoded_arrays(arrays)
    return all(a.shape == s and a.dtype == np.float64 and a.flags.writeable
               and a.flags.c_contiguous for a, s in zip(arrays, shapes, strict=True))


@jit()
def leg_length(lengths_row: F64) -> float:
    """Mirrors :func:`ecs_anim.core.morphology.leg_length` for one (N_LENGTHS,) row (m)."""
    total: float = 0.5 * (lengths_row[L_THIGH] + lengths_row[L_SHANK]
                          + lengths_row[L_THIGH + 1] + lengths_row[L_SHANK + 1])
    return total


@jit()
def half_plane(upper: float, lower: float, reach: float) -> tuple[float, float, float]:
    """Mirrors :func:`ecs_anim.core.normalized.two_sphere_middle` as ``two_bone_middle`` uses
    it: the root-end distance ``reach`` (m) clamped to what the two bones can span, and the
    middle joint's (y, z) in the limb's half-plane (m). Returns (y, z, reach)."""
    reach = min(max(reach, abs(upper - lower)), upper + lower)
    safe = max(reach, 1e-9)
    z = (upper**2 - lower**2 + reach**2) / (2.0 * safe)
    y = math.sqrt(max(upper**2 - z**2, 0.0))
    return y, z, reach


@jit()
def two_bone_middle(limb2world: Frame, root: Vec3, upper: float, lower: float,
                    reach: float) -> tuple[Vec3, Vec3]:
    """Mirrors :func:`ecs_anim.core.normalized.two_bone_middle` for one limb: (middle, end) joints,
    the root-end distance ``reach`` (m) clamped to what the two bones can span."""
    y, z, reach = half_plane(upper, lower, reach)
    middle = add(add(root, scale(limb2world[1], y)), scale(limb2world[2], z))
    end = add(root, scale(limb2world[2], reach))
    return middle, end


@jit()
def limb_from_root(limb2world: Frame, root: Vec3, upper: float, lower: float,
                   reach: float) -> tuple[Vec3, Vec3, Frame]:
    """:func:`two_bone_middle` and :func:`distal_frames` of one limb (the decode's): (middle,
    end, lower2world). The lower bone runs from (y, z) to (0, reach) in the limb's half-plane,
    so its frame is the limb frame turned about its x axis by that direction: no world vector
    normalized, nor x made normal to it (the limb frame, from a quaternion, is orthonormal).
    The same frame as ``distal_frames`` to rounding (a zero-length bone's too: (x, 0, 0))."""
    y, z, reach = half_plane(upper, lower, reach)
    x_axis, y_axis, z_axis = limb2world
    middle = add(add(root, scale(y_axis, y)), scale(z_axis, z))
    end = add(root, scale(z_axis, reach))
    a, b = -y, reach - z  # end - middle in the half-plane (y, z)
    inv = 1.0 / max(math.sqrt(a * a + b * b), TINY)
    a, b = a * inv, b * inv
    lower2world = (x_axis, sub(scale(y_axis, b), scale(z_axis, a)),
                   add(scale(y_axis, a), scale(z_axis, b)))
    return middle, end, lower2world


@jit()
def distal_frames(limb: Frame, mid: Vec3, end: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.core.normalized.distal_frames`: z mid->end, x the limb frame's x."""
    return frame_from_axes(sub(end, mid), limb[0], 2, 0, limb[1])


@jit()
def limb_frames(root: Vec3, mid: Vec3, end: Vec3, hint: Vec3) -> Frame:
    """Mirrors :func:`ecs_anim.core.normalized.limb_frames`: z root->end, y towards ``mid``."""
    return frame_from_axes(sub(end, root), sub(mid, root), 2, 1, hint)


@jit()
def world_quat(parent2world: Quat, local: Quat) -> Quat:
    """The turn ``local`` (in its parent's frame) in the world, ``parent2world local``: the
    frame ``matmul(matrix_from_quat(parent2world), matrix_from_quat(local))`` to rounding, as a
    quaternion, so that a frame's children in the decode cost a quaternion product, not a
    matrix product. Neither is normalized (:func:`.vec.rotation_from_quat` divides by the
    square of the norm); a zero ``local`` is the identity, as ``matrix_from_quat`` makes it."""
    # The product computed always and the parent chosen where ``local`` is zero (a select, not a
    # branch: the blocks' loops run on the vector units).
    zero = local[0] * local[0] + local[1] * local[1] + local[2] * local[2] \
        + local[3] * local[3] < TINY * TINY
    q = quat_mul(parent2world, local)
    return (parent2world[0] if zero else q[0], parent2world[1] if zero else q[1],
            parent2world[2] if zero else q[2], parent2world[3] if zero else q[3])


@jit(inline="always")
def pelvis_frame(c: int, pose: PoseArrays | LegPoseArrays) -> Frame:
    """``pelvis2world`` of row ``c``: heading about Z times the local pelvis rotation."""
    return matmul(rot_z(pose.root_heading[c]), matrix_from_quat(load4(pose.pelvis_local[c])))


@jit(inline="always")
def decode_legs_row(c: int, pose: PoseArrays | LegPoseArrays, seg: F64, base: F64) -> tuple[
        Vec3, Frame, tuple[Vec3, Vec3], tuple[Vec3, Vec3], tuple[Vec3, Vec3], tuple[Vec3, Vec3],
        tuple[Frame, Frame], tuple[Frame, Frame]]:
    """Mirrors :func:`ecs_anim.core.normalized.decode_legs` for store row ``c``.

    ``seg`` (N_LENGTHS,) the segment lengths, ``base`` (N_LENGTHS,) the unstretched ones that
    normalize the root (m). Returns (pelvis, pelvis2world, hips, knees, ankles, toes, leg2world,
    shank2world), each pair [left, right].
    """
    pelvis2world = pelvis_frame(c, pose)
    pelvis = scale(load3(pose.root_position[c]), leg_length(base))
    hip_l, knee_l, ankle_l, toe_l, leg_l, shank_l = _leg(c, 0, pose, seg, pelvis, pelvis2world)
    hip_r, knee_r, ankle_r, toe_r, leg_r, shank_r = _leg(c, 1, pose, seg, pelvis, pelvis2world)
    return (pelvis, pelvis2world, (hip_l, hip_r), (knee_l, knee_r), (ankle_l, ankle_r),
            (toe_l, toe_r), (leg_l, leg_r), (shank_l, shank_r))


@jit(inline="always")
def _leg(c: int, s: int, pose: PoseArrays | LegPoseArrays, seg: F64, pelvis: Vec3,
         pelvis2world: Frame) -> tuple[Vec3, Vec3, Vec3, Vec3, Frame, Frame]:
    """One leg of :func:`decode_legs_row` (side ``s``): hip, knee, ankle, toe, leg2world,
    shank2world."""
    hip = add(pelvis, scale(to_world(pelvis2world, load3(pose.hip_dir[c, s])), seg[L_PELVIS + s]))
    leg2world = matmul(pelvis2world, matrix_from_quat(load4(pose.leg_frame[c, s])))
    knee, ankle, toe, shank2world = leg_below_hip(c, s, pose, seg, hip, leg2world)
    return hip, knee, ankle, toe, leg2world, shank2world


@jit(inline="always")
def _decoded_legs_row(c: int, pose: PoseArrays, seg: F64) -> tuple[
        Quat, Vec3, Frame, tuple[Vec3, Vec3], tuple[Vec3, Vec3], tuple[Vec3, Vec3],
        tuple[Vec3, Vec3], tuple[Frame, Frame]]:
    """The pelvis and legs of row ``c`` as the decode makes them: :func:`decode_legs_row`'s
    result to rounding (on ``seg`` both ways), cheaper (frames as quaternion products,
    :func:`world_quat`; each shank's frame from its half-plane, :func:`limb_from_root`).
    Returns (pelvis2world as a quaternion, pelvis, pelvis2world, hips, knees, ankles, toes,
    leg2world); the ground adaptation keeps :func:`decode_legs_row`'s bits."""
    half = 0.5 * pose.root_heading[c]
    pelvis2world_q = world_quat((0.0, 0.0, math.sin(half), math.cos(half)),
                                load4(pose.pelvis_local[c]))
    pelvis2world = rotation_from_quat(pelvis2world_q)
    pelvis = scale(load3(pose.root_position[c]), leg_length(seg))
    hip_l, knee_l, ankle_l, toe_l, leg_l = _decoded_leg(c, 0, pose, seg, pelvis, pelvis2world,
                                                        pelvis2world_q)
    hip_r, knee_r, ankle_r, toe_r, leg_r = _decoded_leg(c, 1, pose, seg, pelvis, pelvis2world,
                                                        pelvis2world_q)
    return (pelvis2world_q, pelvis, pelvis2world, (hip_l, hip_r), (knee_l, knee_r),
            (ankle_l, ankle_r), (toe_l, toe_r), (leg_l, leg_r))


@jit(inline="always")
def _decoded_leg(c: int, s: int, pose: PoseArrays, seg: F64, pelvis: Vec3, pelvis2world: Frame,
                 pelvis2world_q: Quat) -> tuple[Vec3, Vec3, Vec3, Vec3, Frame]:
    """Leg ``s`` of :func:`_decoded_legs_row`: hip, knee, ankle, toe, leg2world."""
    hip = add(pelvis, scale(to_world(pelvis2world, load3(pose.hip_dir[c, s])), seg[L_PELVIS + s]))
    leg2world = rotation_from_quat(world_quat(pelvis2world_q, load4(pose.leg_frame[c, s])))
    thigh, shank = seg[L_THIGH + s], seg[L_SHANK + s]
    knee, ankle, shank2world = limb_from_root(leg2world, hip, thigh, shank,
                                              pose.leg_fraction[c, s] * (thigh + shank))
    toe = add(ankle, scale(to_world(shank2world, load3(pose.foot_dir[c, s])), seg[L_FOOT + s]))
    return hip, knee, ankle, toe, leg2world


@jit(inline="always")
def leg_below_hip(c: int, s: int, pose: PoseArrays | LegPoseArrays, seg: F64, hip: Vec3,
                  leg2world: Frame) -> tuple[Vec3, Vec3, Vec3, Frame]:
    """The rest of leg ``s`` of row ``c`` as :func:`decode_legs_row` decodes it, from its
    ``hip`` (m, world) and ``leg2world``: knee, ankle, toe, shank2world (for a caller that
    has the leg's frame as a matrix already)."""
    thigh, shank = seg[L_THIGH + s], seg[L_SHANK + s]
    knee, ankle = two_bone_middle(leg2world, hip, thigh, shank,
                                  pose.leg_fraction[c, s] * (thigh + shank))
    shank2world = distal_frames(leg2world, knee, ankle)
    toe = add(ankle, scale(to_world(shank2world, load3(pose.foot_dir[c, s])), seg[L_FOOT + s]))
    return knee, ankle, toe, shank2world


@jit()
def _span(q0: Vec3, q1: Vec3, q2: Vec3, q3: Vec3, u: float) -> tuple[Vec3, Vec3]:
    """Point and tangent of the Catmull-Rom span from ``q1`` to ``q2`` at ``u``, with the
    coefficients of :func:`ecs_anim.core.normalized._span_coefficients` (same operation order)."""
    c0 = q1
    c1 = scale(sub(q2, q0), 0.5)
    c2 = scale(sub(add(sub(scale(q0, 2.0), scale(q1, 5.0)), scale(q2, 4.0)), q3), 0.5)
    c3 = scale(add(sub(sub(scale(q1, 3.0), q0), scale(q2, 3.0)), q3), 0.5)
    point = add(c0, scale(add(c1, scale(add(c2, scale(c3, u)), u)), u))
    tangent = add(c1, scale(add(scale(c2, 2.0), scale(c3, 3.0 * u)), u))
    return point, tangent


@jit()
def curve_at(control: tuple[Vec3, Vec3, Vec3, Vec3], t: float) -> tuple[Vec3, Vec3]:
    """Mirrors :func:`ecs_anim.core.normalized._curve_at` for one spline: point and tangent (d/dt)
    at ``t`` (three spans through the four control points, then the straight extension)."""
    q0, q1, q2, q3 = control
    span = min(np.floor(max(t, 0.0)), 3.0)
    u = t - span
    if span == 3.0:
        tangent = sub(q3, q2)
        return add(q3, scale(tangent, u)), tangent
    start = sub(scale(q0, 2.0), q1)
    end = sub(scale(q3, 2.0), q2)
    if span == 0.0:
        return _span(start, q0, q1, q2, u)
    if span == 1.0:
        return _span(q0, q1, q2, q3, u)
    return _span(q1, q2, q3, end, u)


@jit()
def at_distance(start: Vec3, point: Vec3, tangent: Vec3, length: float) -> Vec3:
    """Mirrors :func:`ecs_anim.core.normalized._at_distance`: ``point`` moved along the ray from
    ``start`` to exactly ``length`` (m) from it (the tangent, then z, where that is undefined)."""
    offset = sub(point, start)
    if norm(offset) > 1e-9:
        direction = normalize(offset)
    elif norm(tangent) > 1e-9:
        direction = normalize(tangent)
    else:
        direction = (0.0, 0.0, 1.0)
    return add_scaled(start, direction, length)


@jit()
def spine_joints(control: tuple[Vec3, Vec3, Vec3, Vec3], lower: float, middle: float,
                 upper: float, iterations: int) -> tuple[Vec3, Vec3, Vec3]:
    """Mirrors :func:`ecs_anim.core.normalized.spine_joints` for one spine of three segments: the
    joints along the spline through ``control`` at exactly the chord lengths ``lower``,
    ``middle``, ``upper`` (m) from one another, starting at the first control point.

    Newton stops per spine (the numpy one stops when every spine of the batch has converged;
    the extra steps move a converged joint by about 1e-13 m).
    """
    chords = (norm(sub(control[1], control[0])), norm(sub(control[2], control[1])),
              norm(sub(control[3], control[2])))
    t, first = spine_joint(control, chords[0], lower, 0.0, control[0], iterations)
    t, second = spine_joint(control, chords[1], middle, t, first, iterations)
    _, third = spine_joint(control, chords[2], upper, t, second, iterations)
    return first, second, third


@jit()
def spine_joint(control: tuple[Vec3, Vec3, Vec3, Vec3], chord: float, length: float,
                 prev_t: float, prev_p: Vec3, iterations: int) -> tuple[float, Vec3]:
    """One step of :func:`spine_joints`: the curve parameter and the joint ``length`` (m) from
    ``prev_p`` (at parameter ``prev_t``) along the spline, ``chord`` the control points' own."""
    t = prev_t + length / max(chord, 1e-9)
    point, tangent = curve_at(control, t)
    for _ in range(iterations):
        d = sub(point, prev_p)
        g = dot(d, d) - length**2
        if abs(g) <= 1e-13 * length**2:
            break
        slope = 2.0 * dot(d, tangent)
        step = g / slope if abs(slope) > 1e-12 else 0.0
        t = min(max(t - step, prev_t + 1e-6), 9.0)
        point, tangent = curve_at(control, t)
    return t, at_distance(prev_p, point, tangent, length)


@jit(inline="always")
def decode_row(c: int, pose: PoseArrays, lengths_row: F64, out: DecodedArrays) -> None:
    """Mirrors :func:`ecs_anim.core.normalized.decode` (``use_stretch=False``) for store row ``c``
    on the body ``lengths_row`` (N_LENGTHS,) (m): writes row ``c`` of every ``out`` array."""
    seg = lengths_row
    control, pelvis2world_q = decode_lower_row(c, pose, seg, out)
    spine = spine_joints(control, seg[L_SPINE_LOWER], seg[L_SPINE_LOWER + 1],
                         seg[L_SPINE_LOWER + 2], 6)
    decode_upper_row(c, pose, seg, spine, pelvis2world_q, out)


@jit(inline="always")
def spine_control(c: int, pose: PoseArrays, seg: F64) -> tuple[Vec3, Vec3, Vec3, Vec3]:
    """The spine's control points of store row ``c`` in the pelvis frame (m): the origin and
    ``spine_points`` scaled by the spine's length."""
    spine_len = seg[L_SPINE_LOWER] + seg[L_SPINE_LOWER + 1] + seg[L_SPINE_LOWER + 2]
    points = pose.spine_points[c]
    return ((0.0, 0.0, 0.0), scale(load3(points[0]), spine_len),
            scale(load3(points[1]), spine_len), scale(load3(points[2]), spine_len))


@jit(inline="always")
def decode_lower_row(c: int, pose: PoseArrays, seg: F64,
                     out: DecodedArrays) -> tuple[tuple[Vec3, Vec3, Vec3, Vec3], Quat]:
    """The first part of :func:`decode_row`: the pelvis and the legs into row ``c`` of ``out``;
    returns the spine's control points (:func:`spine_control`) and ``pelvis2world`` as a
    quaternion (:func:`world_quat`)."""
    pelvis2world_q, pelvis, pelvis2world, hips, knees, ankles, toes, legs = _decoded_legs_row(
        c, pose, seg)
    positions = out.positions[c]
    store3(positions[PELVIS], pelvis)
    for s in range(2):
        store3(positions[HIP + 4 * s], hips[s])
        store3(positions[KNEE + 4 * s], knees[s])
        store3(positions[ANKLE + 4 * s], ankles[s])
        store3(positions[TOE + 4 * s], toes[s])
        store_frame(out.leg2world[c, s], legs[s])
    store_frame(out.pelvis2world[c], pelvis2world)
    return spine_control(c, pose, seg), pelvis2world_q


@jit(inline="always")
def decode_upper_row(c: int, pose: PoseArrays, seg: F64, spine: tuple[Vec3, Vec3, Vec3],
                     pelvis2world_q: Quat, out: DecodedArrays) -> None:
    """The last part of :func:`decode_row`, once :func:`decode_lower_row` has written row ``c``
    of ``out`` (and returned ``pelvis2world_q``): the ``spine`` joints (pelvis frame, m) placed
    in the world, then the thorax, the head and the arms."""
    positions = out.positions[c]
    pelvis = load3(positions[PELVIS])
    pelvis2world = load_frame(out.pelvis2world[c])
    for k in range(3):
        store3(positions[SPINE_1 + k], add(pelvis, to_world(pelvis2world, spine[k])))
    neck = load3(positions[NECK])

    thorax2world_q = world_quat(pelvis2world_q, load4(pose.thorax[c]))
    thorax2world = rotation_from_quat(thorax2world_q)
    head2world = rotation_from_quat(world_quat(thorax2world_q, load4(pose.head[c])))
    head = add(neck, scale(to_world(thorax2world, load3(pose.neck_dir[c])), seg[L_NECK]))
    store3(positions[HEAD], head)
    store3(positions[HEAD_TOP],
           add(head, scale(to_world(head2world, load3(pose.head_top_dir[c])), seg[L_HEAD])))
    store_frame(out.thorax2world[c], thorax2world)
    store_frame(out.head2world[c], head2world)

    for s in range(2):
        shoulder = add(neck, scale(to_world(thorax2world, load3(pose.clavicle_dir[c, s])),
                                   seg[L_CLAVICLE + s]))
        arm2world = rotation_from_quat(world_quat(thorax2world_q, load4(pose.arm_frame[c, s])))
        upper, fore = seg[L_UPPER_ARM + s], seg[L_FOREARM + s]
        elbow, wrist, forearm2world = limb_from_root(arm2world, shoulder, upper, fore,
                                                     pose.arm_fraction[c, s] * (upper + fore))
        hand = add(wrist, scale(to_world(forearm2world, load3(pose.hand_dir[c, s])),
                                seg[L_HAND + s]))
        store3(positions[SHOULDER + 4 * s], shoulder)
        store3(positions[ELBOW + 4 * s], elbow)
        store3(positions[WRIST + 4 * s], wrist)
        store3(positions[HAND + 4 * s], hand)
        store_frame(out.arm2world[c, s], arm2world)


# The scratch of decode_rows: a block's, one column a character of the block (flat, rows of BLOCK:
# lanes.at). The inputs, gathered row by row (gather_block): the heading's half-angle sine and
# cosine (library calls, which LLVM does not vectorize), the pose, the lengths ...
_B_HALF, _B_ROOT, _B_PELVIS_LOCAL, _B_HIP_DIR, _B_LEG_FRAME = 0, 2, 5, 9, 15  # side s: + 3 s, + 4 s
_B_LEG_FRACTION, _B_FOOT_DIR, _B_THORAX, _B_NECK_DIR, _B_HEAD = 23, 25, 31, 35, 38
_B_HEAD_TOP_DIR, _B_CLAVICLE_DIR, _B_ARM_FRAME, _B_ARM_FRACTION, _B_HAND_DIR = 42, 45, 51, 59, 61
_B_LENGTHS = 67  # N_LENGTHS of them, in the skeleton's order
# ... the spines' (spine_block): the four control points (the first the origin), the curve
# parameter and the previous joint's, the origin and the three joints (pelvis frame, m); their
# segment lengths are the lengths' own. The origins are stored so that each joint's loops differ
# only in the rows they read (one compiled loop for all) ...
_S_CONTROL, _S_T, _S_PREV_T, _S_JOINT = 90, 102, 103, 104
_S_LENGTH = _B_LENGTHS + L_SPINE_LOWER
# ... pelvis2world as a quaternion (lower_lanes for upper_lanes), and the results in the
# order of a row of each out array (positions; frames as store_frame writes them), so that
# scatter_block copies runs of them.
_B_PELVIS_Q, _B_POSITIONS = 116, 120
_B_PELVIS2WORLD, _B_THORAX2WORLD, _B_HEAD2WORLD, _B_LEG2WORLD, _B_ARM2WORLD = \
    186, 195, 204, 213, 231
# ... whether the positions are all finite (finite_lanes: 1.0 or 0.0), the spine's curve
# point and tangent at the parameter its Newton iteration last tried (spine_joint_lanes) ...
_B_FINITE, _S_POINT, _S_TANGENT = 249, 250, 253
# ... and whether its Newton iteration is still moving after the passes over the block.
_S_MOVING = 256
#: Rows of a block's scratch (:func:`spine_scratch`).
BLOCK_ROWS = 257
assert _B_LENGTHS + N_LENGTHS == _S_CONTROL and _B_POSITIONS + 3 * N_JOINTS == _B_PELVIS2WORLD
assert _B_ARM2WORLD + 18 == _B_FINITE


def spine_scratch(n: int) -> F64:
    """The scratch :func:`decode_rows` (and ``posture_rows``) need for ``n`` rows: two sets of
    ``n // BLOCK + 1`` block scratches (each a block's BLOCK_ROWS rows of BLOCK, flat). A
    chunk of at least :data:`.lanes.BLOCK` rows from ``lo`` decodes each of its blocks in the
    block scratch ``lo // BLOCK`` of the first set (chunks that long never share one; one
    thread touches 64 kB); a shorter one (:func:`decode_rows`) decodes row ``i`` in column
    ``i % BLOCK`` of the block scratch ``i // BLOCK`` of the second set (its own column
    whatever the chunks; its pages untouched while every chunk is long enough). About 16 MB
    of address space at 4,000 rows, of which a tick touches the blocks its chunks use."""
    return np.empty((2 * (n // BLOCK + 1), BLOCK_ROWS * BLOCK))


def spine_scratch_fits(scratch: F64, n: int) -> bool:
    """Whether ``scratch`` (:func:`spine_scratch`, kept from an earlier call) serves ``n`` rows
    on any chunking: the kernels index it by the chunk's first row without bounds checks."""
    return bool(scratch.shape[0] >= 2 * (n // BLOCK + 1))


@jit()
def put_matrix(scratch: F64, r: int, j: Column, m: Frame) -> None:
    """The frame ``m`` into rows ``r:r + 9`` of column ``j`` as :func:`.vec.store_frame` writes
    it into a (3, 3) array (row by row of the matrix, its axes as columns)."""
    for i in range(3):
        put3(scratch, r + 3 * i, j, (m[0][i], m[1][i], m[2][i]))


@jit()
def col_matrix(scratch: F64, r: int, j: Column) -> Frame:
    """The frame :func:`put_matrix` wrote into rows ``r:r + 9`` of column ``j``."""
    a, b, c = col3(scratch, r, j), col3(scratch, r + 3, j), col3(scratch, r + 6, j)
    return ((a[0], b[0], c[0]), (a[1], b[1], c[1]), (a[2], b[2], c[2]))


@jit(inline="always")
def _length(scratch: F64, k: int, j: Column) -> float:
    """Length ``k`` (the skeleton's index) of column ``j`` (m)."""
    length: float = scratch[at(_B_LENGTHS + k, j)]
    return length


# Loops over the block's rows, each gathering a few of the arrays (a row's ~100 values in one
# loop, each to another line of the scratch, took a fifth longer).
@jit(inline="always")  # one call site
def gather_block(start: int, stop: int, rows: I64, pose: PoseArrays, lengths: F64,
                 scratch: F64, first: Column) -> None:
    """What the block's loops read of the store rows ``rows[start:stop]`` into the columns
    from ``first`` of a block scratch: the pose, the lengths, the heading's half-angle
    sine and cosine and the spines' control points (:func:`spine_control`)."""
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        half = 0.5 * pose.root_heading[c]
        scratch[at(_B_HALF, j)], scratch[at(_B_HALF + 1, j)] = math.sin(half), math.cos(half)
        put3(scratch, _B_ROOT, j, load3(pose.root_position[c]))
        put4(scratch, _B_PELVIS_LOCAL, j, load4(pose.pelvis_local[c]))
        put4(scratch, _B_THORAX, j, load4(pose.thorax[c]))
        put3(scratch, _B_NECK_DIR, j, load3(pose.neck_dir[c]))
        put4(scratch, _B_HEAD, j, load4(pose.head[c]))
        put3(scratch, _B_HEAD_TOP_DIR, j, load3(pose.head_top_dir[c]))
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        for s in range(2):
            put3(scratch, _B_HIP_DIR + 3 * s, j, load3(pose.hip_dir[c, s]))
            put4(scratch, _B_LEG_FRAME + 4 * s, j, load4(pose.leg_frame[c, s]))
            scratch[at(_B_LEG_FRACTION + s, j)] = pose.leg_fraction[c, s]
            put3(scratch, _B_FOOT_DIR + 3 * s, j, load3(pose.foot_dir[c, s]))
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        for s in range(2):
            put3(scratch, _B_CLAVICLE_DIR + 3 * s, j, load3(pose.clavicle_dir[c, s]))
            put4(scratch, _B_ARM_FRAME + 4 * s, j, load4(pose.arm_frame[c, s]))
            scratch[at(_B_ARM_FRACTION + s, j)] = pose.arm_fraction[c, s]
            put3(scratch, _B_HAND_DIR + 3 * s, j, load3(pose.hand_dir[c, s]))
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        seg = lengths[c]
        for k in range(N_LENGTHS):
            scratch[at(_B_LENGTHS + k, j)] = seg[k]
        control = spine_control(c, pose, seg)
        for k in range(4):
            put3(scratch, _S_CONTROL + 3 * k, j, control[k])
        put3(scratch, _S_JOINT, j, (0.0, 0.0, 0.0))
        scratch[at(_S_PREV_T, j)] = 0.0


#: A limb's rows in the block scratch, its first length and its first joint, side 0 (side s:
#: its root's direction + 3 s, frame + 4 s, fraction + s, end's direction + 3 s, limb2world
#: + 9 s; its lengths every other one from the first, + s; its joints root, middle, end, tip
#: + 4 s).
_LEG_LAYOUT = (_B_HIP_DIR, _B_LEG_FRAME, _B_LEG_FRACTION, _B_FOOT_DIR, _B_LEG2WORLD, L_PELVIS,
               HIP)
_ARM_LAYOUT = (_B_CLAVICLE_DIR, _B_ARM_FRAME, _B_ARM_FRACTION, _B_HAND_DIR, _B_ARM2WORLD,
               L_CLAVICLE, SHOULDER)
assert (L_THIGH, L_SHANK, L_FOOT) == (L_PELVIS + 2, L_PELVIS + 4, L_PELVIS + 6)
assert (L_UPPER_ARM, L_FOREARM, L_HAND) == (L_CLAVICLE + 2, L_CLAVICLE + 4, L_CLAVICLE + 6)


@jit(inline="always")
def _limb_lanes(scratch: F64, j: Column, s: int, layout: tuple[int, int, int, int, int, int, int],
                parent: Vec3, parent2world: Frame, parent2world_q: Quat) -> None:
    """Limb ``s`` (a leg from the pelvis, :data:`_LEG_LAYOUT`, or an arm from the neck,
    :data:`_ARM_LAYOUT`) of :func:`lower_lanes` or :func:`upper_lanes` (:func:`_decoded_leg`'s
    and :func:`decode_upper_row`'s operations): its root (hip, shoulder), middle, end, tip and
    limb2world into column ``j``."""
    root_dir, frame, fraction, end_dir, limb2world_row, first_length, first_joint = layout
    root = add(parent, scale(to_world(parent2world, col3(scratch, root_dir + 3 * s, j)),
                             _length(scratch, first_length + s, j)))
    limb2world = rotation_from_quat(world_quat(parent2world_q, col4(scratch, frame + 4 * s, j)))
    upper = _length(scratch, first_length + 2 + s, j)
    lower = _length(scratch, first_length + 4 + s, j)
    middle, end, lower2world = limb_from_root(
        limb2world, root, upper, lower, scratch[at(fraction + s, j)] * (upper + lower))
    tip = add(end, scale(to_world(lower2world, col3(scratch, end_dir + 3 * s, j)),
                         _length(scratch, first_length + 6 + s, j)))
    joint = first_joint + 4 * s
    put3(scratch, _B_POSITIONS + 3 * joint, j, root)
    put3(scratch, _B_POSITIONS + 3 * (joint + 1), j, middle)
    put3(scratch, _B_POSITIONS + 3 * (joint + 2), j, end)
    put3(scratch, _B_POSITIONS + 3 * (joint + 3), j, tip)
    put_matrix(scratch, limb2world_row + 9 * s, j, limb2world)


# A call, not inlined (as spine_block).
@jit()
def lower_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """:func:`decode_lower_row` (the pelvis and legs: :func:`_decoded_legs_row`'s operations)
    for the columns ``start:stop`` of a block scratch, in a loop over them that runs on the
    vector units: the same bits."""
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        pelvis2world_q = world_quat((0.0, 0.0, scratch[at(_B_HALF, j)],
                                     scratch[at(_B_HALF + 1, j)]),
                                    col4(scratch, _B_PELVIS_LOCAL, j))
        pelvis2world = rotation_from_quat(pelvis2world_q)
        # leg_length's sum
        leg = 0.5 * (_length(scratch, L_THIGH, j) + _length(scratch, L_SHANK, j)
                     + _length(scratch, L_THIGH + 1, j) + _length(scratch, L_SHANK + 1, j))
        pelvis = scale(col3(scratch, _B_ROOT, j), leg)
        put4(scratch, _B_PELVIS_Q, j, pelvis2world_q)
        put3(scratch, _B_POSITIONS + 3 * PELVIS, j, pelvis)
        put_matrix(scratch, _B_PELVIS2WORLD, j, pelvis2world)
        # (Both legs spelled out: as a loop over the sides, LLVM vectorized nothing.)
        _limb_lanes(scratch, j, 0, _LEG_LAYOUT, pelvis, pelvis2world, pelvis2world_q)
        _limb_lanes(scratch, j, 1, _LEG_LAYOUT, pelvis, pelvis2world, pelvis2world_q)


@jit(inline="always")
def _spine_joint_lanes(scratch: F64, j: Column, k: int, pelvis: Vec3,
                       pelvis2world: Frame) -> Vec3:
    """Spine joint ``k`` of column ``j`` placed in the world (m), into the column."""
    joint = add(pelvis, to_world(pelvis2world, col3(scratch, _S_JOINT + 3 * (k + 1), j)))
    put3(scratch, _B_POSITIONS + 3 * (SPINE_1 + k), j, joint)
    return joint


# A call, not inlined (as spine_block).
@jit()
def upper_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """:func:`decode_upper_row` (the spine joints placed, the thorax, the head, the arms) for
    the columns ``start:stop`` of a block scratch once :func:`lower_lanes` and
    :func:`spine_block` have run, in a loop over them that runs on the vector units: the same
    bits."""
    for k in range(start, stop):
        j = Column(k)  # (the same type: for mypy, which takes k for an int)
        pelvis = col3(scratch, _B_POSITIONS + 3 * PELVIS, j)
        pelvis2world = col_matrix(scratch, _B_PELVIS2WORLD, j)
        _spine_joint_lanes(scratch, j, 0, pelvis, pelvis2world)
        _spine_joint_lanes(scratch, j, 1, pelvis, pelvis2world)
        neck = _spine_joint_lanes(scratch, j, 2, pelvis, pelvis2world)
        thorax2world_q = world_quat(col4(scratch, _B_PELVIS_Q, j), col4(scratch, _B_THORAX, j))
        thorax2world = rotation_from_quat(thorax2world_q)
        head2world = rotation_from_quat(world_quat(thorax2world_q, col4(scratch, _B_HEAD, j)))
        head = add(neck, scale(to_world(thorax2world, col3(scratch, _B_NECK_DIR, j)),
                               _length(scratch, L_NECK, j)))
        put3(scratch, _B_POSITIONS + 3 * HEAD, j, head)
        put3(scratch, _B_POSITIONS + 3 * HEAD_TOP, j,
             add(head, scale(to_world(head2world, col3(scratch, _B_HEAD_TOP_DIR, j)),
                             _length(scratch, L_HEAD, j))))
        put_matrix(scratch, _B_THORAX2WORLD, j, thorax2world)
        put_matrix(scratch, _B_HEAD2WORLD, j, head2world)
        _limb_lanes(scratch, j, 0, _ARM_LAYOUT, neck, thorax2world, thorax2world_q)
        _limb_lanes(scratch, j, 1, _ARM_LAYOUT, neck, thorax2world, thorax2world_q)


@jit()
def finite_lanes(scratch: F64, start: Column, stop: Column) -> None:
    """Whether the positions of each of the columns ``start:stop`` of a block scratch are all
    finite, 1.0 or 0.0 into its row ``_B_FINITE``, in a loop over the columns that runs on the
    vector units (``x * 0.0`` is 0 for a finite ``x``, NaN otherwise, and a NaN stays in a
    sum; one sum a coordinate, so that the three run side by side)."""
    for k in range(start, stop):
        j = Column(k)
        x = y = z = 0.0
        for joint in range(N_JOINTS):
            r = _B_POSITIONS + 3 * joint
            x += scratch[at(r, j)] * 0.0
            y += scratch[at(r + 1, j)] * 0.0
            z += scratch[at(r + 2, j)] * 0.0
        scratch[at(_B_FINITE, j)] = 1.0 if x + y + z == 0.0 else 0.0


@jit(inline="always")
def decoded_finite(scratch: F64, j: Column) -> bool:
    """Whether the positions :func:`decode_block` decoded in column ``j`` of its block scratch
    are all finite (with ``finite_only``)."""
    return bool(scratch[at(_B_FINITE, j)] != 0.0)


@jit(inline="always")
def _scatter_run(scratch: F64, r: int, j: Column, flat: F64, c: int, size: int) -> None:
    """Rows ``r:r + size`` of column ``j`` into row ``c`` of an out array of ``size`` values a
    row, ``flat`` (its flat view: constant offsets from the row's start, where indices into a
    row of the (n, ...) array multiply its strides)."""
    row = Column(c) * Column(size)
    for k in range(size):
        flat[row + Column(k)] = scratch[at(r + k, j)]


# (A flat view an array a block: numba's reshape calls its runtime, so not one a row.)
@jit(inline="always")  # one call site
def scatter_block(start: int, stop: int, rows: I64, scratch: F64, out: DecodedArrays,
                  first: Column, finite_only: bool) -> None:
    """The block's results in the columns from ``first`` of a block scratch into the rows
    ``rows[start:stop]`` of every ``out`` array (C-contiguous); with ``finite_only``, the
    positions only where they are all finite (:func:`finite_lanes` has run)."""
    # (Loops of a few arrays each, as gather_block.)
    positions = out.positions.reshape(-1)
    for i in range(start, stop):
        j = first + Column(i - start)
        if not finite_only or decoded_finite(scratch, j):
            _scatter_run(scratch, _B_POSITIONS, j, positions, rows[i], 3 * N_JOINTS)
    pelvis2world, thorax2world = out.pelvis2world.reshape(-1), out.thorax2world.reshape(-1)
    head2world = out.head2world.reshape(-1)
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        _scatter_run(scratch, _B_PELVIS2WORLD, j, pelvis2world, c, 9)
        _scatter_run(scratch, _B_THORAX2WORLD, j, thorax2world, c, 9)
        _scatter_run(scratch, _B_HEAD2WORLD, j, head2world, c, 9)
    leg2world, arm2world = out.leg2world.reshape(-1), out.arm2world.reshape(-1)
    for i in range(start, stop):
        c = rows[i]
        j = first + Column(i - start)
        _scatter_run(scratch, _B_LEG2WORLD, j, leg2world, c, 18)
        _scatter_run(scratch, _B_ARM2WORLD, j, arm2world, c, 18)


@jit(inline="always")
def curve_at_lanes(control: tuple[Vec3, Vec3, Vec3, Vec3], t: float) -> tuple[Vec3, Vec3]:
    """:func:`curve_at` (the same operations, so the same result) without branches: each
    span's points are chosen, not jumped to, so that a loop of it over characters is
    vectorized."""
    q0, q1, q2, q3 = control
    span = min(np.floor(max(t, 0.0)), 3.0)
    u = t - span
    start = sub(scale(q0, 2.0), q1)
    end = sub(scale(q3, 2.0), q2)
    first, second = span == 0.0, span == 1.0
    point, tangent = _span(start if first else (q0 if second else q1),
                           q0 if first else (q1 if second else q2),
                           q1 if first else (q2 if second else q3),
                           q2 if first else (q3 if second else end), u)
    beyond = sub(q3, q2)
    straight = span == 3.0
    return (add(q3, scale(beyond, u)) if straight else point), (beyond if straight else tangent)


@jit(inline="always")
def _lane_control(scratch: F64, j: Column) -> tuple[Vec3, Vec3, Vec3, Vec3]:
    """The spine's control points of column ``j``."""
    return (col3(scratch, _S_CONTROL, j), col3(scratch, _S_CONTROL + 3, j),
            col3(scratch, _S_CONTROL + 6, j), col3(scratch, _S_CONTROL + 9, j))


# A call, not inlined into decode_block: inlined, its loops made the row loops so long that LLVM
# stopped inlining their small helpers (matmul, matrix_from_quat): 20 % slower.
@jit()
def spine_block(scratch: F64, start: Column, stop: Column, iterations: int) -> None:
    """:func:`spine_joints` of the columns ``start:stop`` of a block scratch (control points
    and lengths in, :func:`gather_block`; joints out), in loops over those characters that run
    on the vector units.

    Each column's result is :func:`spine_joints`' own: a spine whose Newton iteration has
    converged keeps its parameter while the others go on (its joint, recomputed from it, is
    the same), and the block stops once all have converged or after ``iterations``.
    """
    # Each joint a literal (three compiled bodies: its rows constants, 0.41 against 0.63 ms a
    # tick at 4,000; 1.6 s more to compile).
    spine_joint_lanes(scratch, start, stop, 0, iterations)
    spine_joint_lanes(scratch, start, stop, 1, iterations)
    spine_joint_lanes(scratch, start, stop, 2, iterations)


# Not inlined (one compiled body for the three joints: inlined, decode_rows took twice as long
# to compile, and its row loops' small helpers were no longer inlined).
@jit()
def spine_joint_lanes(scratch: F64, start: Column, stop: Column, k: int,
                      iterations: int) -> None:
    """:func:`spine_joint` for joint ``k`` of the spines in the columns ``start:stop`` of a
    block scratch (see :func:`spine_block`): Newton passes over every column while more than
    :data:`_FEW_MOVING` are still moving, then the few left one by one (their own passes
    continued: the same steps, so the same bits)."""
    lanes = range(start, stop)
    below, above = _S_CONTROL + 3 * k, _S_CONTROL + 3 * (k + 1)
    prev_row, joint_row = _S_JOINT + 3 * k, _S_JOINT + 3 * (k + 1)
    length_row = _S_LENGTH + k
    for i in lanes:
        j = Column(i)
        chord = norm(sub(col3(scratch, above, j), col3(scratch, below, j)))
        scratch[at(_S_T, j)] = scratch[at(_S_PREV_T, j)] + scratch[at(length_row, j)] \
            / max(chord, 1e-9)
    passes = 0
    moving = int(stop - start)
    while passes < iterations and moving > _FEW_MOVING:
        moving = 0
        for i in lanes:
            j = Column(i)
            done = _newton_pass(scratch, j, prev_row, length_row)
            scratch[at(_S_MOVING, j)] = 0.0 if done else 1.0
            moving += 0 if done else 1
        passes += 1
    if moving > 0:  # the rest of each moving column's passes, alone (a branch a column)
        for i in lanes:
            j = Column(i)
            if passes == 0 or scratch[at(_S_MOVING, j)] != 0.0:
                _finish_newton(scratch, j, prev_row, length_row, iterations - passes)
    for i in lanes:
        j = Column(i)
        joint = at_distance(col3(scratch, prev_row, j), col3(scratch, _S_POINT, j),
                            col3(scratch, _S_TANGENT, j), scratch[at(length_row, j)])
        put3(scratch, joint_row, j, joint)
        scratch[at(_S_PREV_T, j)] = scratch[at(_S_T, j)]


#: At most this many columns of a block still moving, :func:`spine_joint_lanes` finishes them
#: one by one rather than in another pass over the whole block (at 4,000 characters, 375 of
#: the 4,000 spines take a second Newton step, and nearly every block of 32 has one of them).
_FEW_MOVING = BLOCK // 4


@jit(inline="always")
def _newton_pass(scratch: F64, j: Column, prev_row: int, length_row: int) -> bool:
    """One Newton pass of :func:`spine_joint` for column ``j``: the curve at its parameter
    (kept: the joint is placed from the last point and tangent evaluated), and the parameter
    stepped unless the point is at the segment's length from the previous joint. Returns
    whether it was (the parameter then kept)."""
    prev_p = col3(scratch, prev_row, j)
    length, t = scratch[at(length_row, j)], scratch[at(_S_T, j)]
    point, tangent = curve_at_lanes(_lane_control(scratch, j), t)
    put3(scratch, _S_POINT, j, point)
    put3(scratch, _S_TANGENT, j, tangent)
    d = sub(point, prev_p)
    g = dot(d, d) - length**2
    done = abs(g) <= 1e-13 * length**2
    slope = 2.0 * dot(d, tangent)
    step = g / slope if abs(slope) > 1e-12 else 0.0
    stepped = min(max(t - step, scratch[at(_S_PREV_T, j)] + 1e-6), 9.0)
    scratch[at(_S_T, j)] = t if done else stepped
    return bool(done)


# Not inlined: its loop with an exit is what the few moving columns run (a call each).
@jit()
def _finish_newton(scratch: F64, j: Column, prev_row: int, length_row: int,
                   passes: int) -> None:
    """At most ``passes`` more Newton passes of column ``j`` (:func:`_newton_pass`), and the
    curve at the parameter last stepped to if it is still moving after them."""
    for _ in range(passes):
        if _newton_pass(scratch, j, prev_row, length_row):
            return
    point, tangent = curve_at_lanes(_lane_control(scratch, j), scratch[at(_S_T, j)])
    put3(scratch, _S_POINT, j, point)
    put3(scratch, _S_TANGENT, j, tangent)


# A call: one compiled body for decode_rows and posture_rows.
@jit()
def decode_block(start: int, stop: int, rows: I64, pose: PoseArrays, lengths: F64,
                 out: DecodedArrays, scratch: F64, first: Column, finite_only: bool) -> None:
    """:func:`decode_row` of the store rows ``rows[start:stop]`` in the columns ``first:first
    + stop - start`` (at most :data:`.lanes.BLOCK`) of the block scratch ``scratch``
    (BLOCK_ROWS * BLOCK,): gathered row by row, the pelvis and legs, the spines and the upper
    body in loops over the block's characters that run on the vector units, the results put
    in the rows of ``out``; the same bits as :func:`decode_row`. With ``finite_only``, a row's
    positions are written only where they are all finite (:func:`decoded_finite` says which);
    its frames are written anyway."""
    last = first + Column(stop - start)
    gather_block(start, stop, rows, pose, lengths, scratch, first)
    lower_lanes(scratch, first, last)
    spine_block(scratch, first, last, 6)
    upper_lanes(scratch, first, last)
    if finite_only:
        finite_lanes(scratch, first, last)
    scatter_block(start, stop, rows, scratch, out, first, finite_only)


@jit(inline="always")
def block_piece(lo: int, hi: int, start: int, scratch: F64) -> tuple[int, F64, Column]:
    """Where the chunk ``rows[lo:hi]`` decodes its rows from ``start`` (:func:`decode_block`):
    the end of that piece, its block scratch in ``scratch`` (:func:`spine_scratch`) and its
    first column. A chunk of at least :data:`.lanes.BLOCK` rows decodes by blocks of BLOCK rows
    in block scratch ``lo // BLOCK`` from column 0; a shorter one (which may share its first
    block scratch with another) each row ``i`` in its own column ``i % BLOCK`` of block scratch
    ``i // BLOCK`` of the second set, by pieces within BLOCK-aligned runs of rows."""
    if hi - lo >= BLOCK:
        return min(start + BLOCK, hi), scratch[lo // BLOCK], Column(0)
    return (min(hi, (start // BLOCK + 1) * BLOCK),
            scratch[scratch.shape[0] // 2 + start // BLOCK], Column(start % BLOCK))


@jit(nogil=True)
def decode_rows(lo: int, hi: int, rows: I64, pose: PoseArrays, lengths: F64, out: DecodedArrays,
                scratch: F64) -> None:
    """Mirrors :func:`ecs_anim.core.normalized.decode` over the store rows ``rows[lo:hi]``
    (int64): row ``c`` of ``pose`` on the body ``lengths[c]`` ((n, N_LENGTHS), m) into row ``c``
    of every ``out`` array (C-contiguous, :func:`fits`; the other rows are left as they are).
    ``scratch``:
    :func:`spine_scratch` of ``len(rows)``.

    By blocks of :data:`.lanes.BLOCK` rows on the vector units (:func:`decode_block`,
    :func:`block_piece`); the same result as :func:`decode_row` on each row, whatever the
    block."""
    start = lo
    while start < hi:
        stop, block, first = block_piece(lo, hi, start, scratch)
        decode_block(start, stop, rows, pose, lengths, out, block, first, False)
        start = stop


def decode(poses: NormalizedPoses, lengths: F64, out: DecodedPose | None = None) -> DecodedPose:
    """Compiled :func:`ecs_anim.core.normalized.decode` (``use_stretch=False``) of every row.

    ``poses`` with one leading axis (n,); ``lengths`` (n, N_LENGTHS) or (N_LENGTHS,) (m);
    ``out`` is written in place when given (and returned), else allocated.
    """
    pose = pose_arrays(poses)
    n = pose.root_heading.shape[0]
    lengths = np.ascontiguousarray(np.broadcast_to(lengths, (n, N_LENGTHS)), dtype=np.float64)
    # (The kernel writes C-contiguous arrays: another ``out`` gets a copy.)
    arrays = decoded_arrays(out) if out is not None and fits(out, n) else empty_decoded(n)
    over_chunks(decode_rows, n, np.arange(n, dtype=np.int64), pose, lengths, arrays,
                spine_scratch(n))
    if out is None:
        return decoded_pose(arrays)
    if arrays.positions is not out.positions:
        for target, value in zip(decoded_arrays(out), arrays, strict=True):
            target[...] = value
    return out
