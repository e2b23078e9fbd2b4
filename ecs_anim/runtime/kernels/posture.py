"""Compiled posture conversion (PostureConvert's work, paper §8): decode, the frozen check, the
export skeleton's local joint rotations and the resampled spine: the decode by blocks
(:func:`.decode.decode_rows`), the rest one store row at a time.

Mirrors :func:`ecs_anim.core.normalized.decode`, :func:`ecs_anim.io.export.skeleton.export_rotations`,
:func:`ecs_anim.io.export.skeleton.local_rotations` and :func:`ecs_anim.core.normalized.vertebrae`. On one
decoded pose the rotations agree with numpy to about 1e-15, straight limbs included; in the whole
tick a nearly straight limb re-aimed upstream (ground adaptation, the solver) has its twist
decided by rounding, so frames may differ by about 2e-6 there while positions agree to 1e-9 m.

The constant matrices of the export skeleton (:data:`ecs_anim.io.export.skeleton.BODY_TO_BVH_REST`,
:data:`ecs_anim.io.importing.YUP_TO_ZUP`, the rest hip directions, the parent indices) are passed
as arguments (:func:`export_constants`); joint indices are literals pinned by import-time checks.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.core.skeleton import N_JOINTS, N_LENGTHS, REST_HIP_DIR_LEFT
from ecs_anim.io.export.skeleton import BODY_TO_BVH_REST, EXPORT_NAMES, EXPORT_PARENTS
from ecs_anim.io.importing import YUP_TO_ZUP
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import (
    ANKLE,
    ELBOW,
    HAND,
    HEAD,
    HEAD_TOP,
    HIP,
    KNEE,
    L_SPINE_LOWER,
    NECK,
    PELVIS,
    SHOULDER,
    SPINE_1,
    SPINE_2,
    TOE,
    WRIST,
    DecodedArrays,
    PoseArrays,
    block_piece,
    decode_block,
    decoded_arrays,
    decoded_finite,
    leg_length,
    pelvis_frame,
    pose_arrays,
    spine_joint,
)
from ecs_anim.runtime.kernels.lanes import Column
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    frame_from_axes,
    jit,
    load3,
    load_frame,
    matmul,
    norm,
    rotation_between,
    scale,
    store3,
    store_frame,
    sub,
    to_world,
    transpose,
)

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]

# Export joints (ecs_anim.io.export.skeleton.EXPORT_NAMES): a leg's joints start at 1 + 5 * side, an
# arm's at 17 + 4 * side.
_E_PELVIS = 0
_E_LEG, _E_LEG_STRIDE = 1, 5  # pelvis_s, hip_s, knee_s, ankle_s, toe_s
_E_LUMBAR, _E_SPINE_1, _E_SPINE_2, _E_NECK, _E_CERVICAL, _E_HEAD = 11, 12, 13, 14, 15, 16
_E_ARM, _E_ARM_STRIDE = 17, 4  # clavicle_s, shoulder_s, elbow_s, wrist_s
N_EXPORT = 25

assert len(EXPORT_NAMES) == N_EXPORT
assert EXPORT_NAMES[:11] == ("pelvis", *(f"{j}_{s}" for s in "lr"
                                         for j in ("pelvis", "hip", "knee", "ankle", "toe")))
assert EXPORT_NAMES[11:17] == ("lumbar", "spine_1", "spine_2", "neck", "cervical", "head")
assert EXPORT_NAMES[17:] == tuple(f"{j}_{s}" for s in "lr"
                                  for j in ("clavicle", "shoulder", "elbow", "wrist"))


class ExportConstants(NamedTuple):
    """The export skeleton's constants, as arrays the kernels take.

    rest_hips (2, 3): pelvis origin -> hip at rest, body axes [left, right];
    bvh_from_world (3, 3): ``YUP_TO_ZUP.T``; rest2body (3, 3): ``BODY_TO_BVH_REST.T``;
    parents (N_EXPORT,) int64, -1 for the root.
    """

    rest_hips: F64
    bvh_from_world: F64
    rest2body: F64
    parents: I64


def export_constants() -> ExportConstants:
    x, y, z = REST_HIP_DIR_LEFT
    return ExportConstants(np.array([[x, y, z], [x, -y, z]]),
                           np.ascontiguousarray(YUP_TO_ZUP.T),
                           np.ascontiguousarray(BODY_TO_BVH_REST.T),
                           np.asarray(EXPORT_PARENTS, dtype=np.int64))


@jit()
def swing_from(parent_frame: Frame, rest_axis: Vec3, direction: Vec3) -> Frame:
    """Mirrors ``ecs_anim.io.export.skeleton._swing_from``: ``parent_frame`` turned by the smallest
    rotation taking its ``rest_axis`` onto ``direction`` (a bone with no twist of its own)."""
    return matmul(rotation_between(to_world(parent_frame, rest_axis), direction), parent_frame)


# Not inlined: numba types an inlined body again at every site (posture_rows,
# local_rotations_rows, posture_solved_rows), compiling for longer.
@jit()
def export_rotations_row(c: int, decoded: DecodedArrays, rest_hips: F64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.io.export.skeleton.export_rotations` for row ``c`` of ``decoded``: the
    world orientation (joint2world) of every export joint into ``out`` (N_EXPORT, 3, 3)."""
    p = decoded.positions[c]
    pelvis2world = load_frame(decoded.pelvis2world[c])
    thorax2world = load_frame(decoded.thorax2world[c])
    head2world = load_frame(decoded.head2world[c])
    side_y = pelvis2world[1]
    side_x = thorax2world[0]
    pelvis = load3(p[PELVIS])
    neck = load3(p[NECK])
    store_frame(out[_E_PELVIS], pelvis2world)
    for s in range(2):
        sign = 1.0 if s == 0 else -1.0
        hip, knee = load3(p[HIP + 4 * s]), load3(p[KNEE + 4 * s])
        ankle, toe = load3(p[ANKLE + 4 * s]), load3(p[TOE + 4 * s])
        leg_normal = load_frame(decoded.leg2world[c, s])[0]
        e = _E_LEG + _E_LEG_STRIDE * s
        store_frame(out[e], swing_from(pelvis2world, load3(rest_hips[s]), sub(hip, pelvis)))
        store_frame(out[e + 1], frame_from_axes(sub(hip, knee), leg_normal, 2, 1, leg_normal))
        store_frame(out[e + 2], frame_from_axes(sub(knee, ankle), leg_normal, 2, 1, leg_normal))
        foot = frame_from_axes(sub(toe, ankle), leg_normal, 0, 1, side_y)
        store_frame(out[e + 3], foot)
        store_frame(out[e + 4], foot)

        shoulder, elbow = load3(p[SHOULDER + 4 * s]), load3(p[ELBOW + 4 * s])
        wrist, hand = load3(p[WRIST + 4 * s]), load3(p[HAND + 4 * s])
        hinge = scale(load_frame(decoded.arm2world[c, s])[0], -sign)
        a = _E_ARM + _E_ARM_STRIDE * s
        store_frame(out[a], swing_from(thorax2world, (0.0, sign, 0.0), sub(shoulder, neck)))
        store_frame(out[a + 1], frame_from_axes(scale(sub(elbow, shoulder), sign), hinge, 1, 2,
                                                hinge))
        store_frame(out[a + 2], frame_from_axes(scale(sub(wrist, elbow), sign), hinge, 1, 2,
                                                hinge))
        store_frame(out[a + 3], frame_from_axes(scale(sub(hand, wrist), sign), hinge, 1, 2,
                                                side_x))
    up = (0.0, 0.0, 1.0)
    spine_1, spine_2 = load3(p[SPINE_1]), load3(p[SPINE_2])
    lumbar = swing_from(pelvis2world, up, sub(spine_1, pelvis))
    spine_1_frame = swing_from(lumbar, up, sub(spine_2, spine_1))
    store_frame(out[_E_LUMBAR], lumbar)
    store_frame(out[_E_SPINE_1], spine_1_frame)
    store_frame(out[_E_SPINE_2], swing_from(spine_1_frame, up, sub(neck, spine_2)))
    store_frame(out[_E_NECK], thorax2world)
    head = load3(p[HEAD])
    store_frame(out[_E_CERVICAL], swing_from(thorax2world, up, sub(head, neck)))
    store_frame(out[_E_HEAD], swing_from(head2world, up, sub(load3(p[HEAD_TOP]), head)))


@jit()
def bvh_globals_row(world: F64, bvh_from_world: F64, rest2body: F64) -> None:
    """In place, each (3, 3) of ``world`` (N_EXPORT, 3, 3) joint2world becomes joint2bvh =
    ``bvh_from_world @ joint2world @ rest2body``, as in :func:`ecs_anim.io.export.skeleton.local_rotations`."""
    a = load_frame(bvh_from_world)
    b = load_frame(rest2body)
    for j in range(world.shape[0]):
        store_frame(world[j], matmul(matmul(a, load_frame(world[j])), b))


@jit()
def local_from_globals_row(glob: F64, parents: I64, out: F64) -> None:
    """Mirrors the last step of :func:`ecs_anim.io.export.skeleton.local_rotations`: each joint's
    rotation relative to its parent, ``glob[parent].T @ glob[joint]`` (the root's own), from
    ``glob`` (N_EXPORT, 3, 3) into ``out`` (N_EXPORT, 3, 3)."""
    for j in range(glob.shape[0]):
        g = load_frame(glob[j])
        if parents[j] < 0:
            store_frame(out[j], g)
        else:
            store_frame(out[j], matmul(transpose(load_frame(glob[parents[j]])), g))


@jit()
def even_spine_joints(control: tuple[Vec3, Vec3, Vec3, Vec3], length: float, count: int,
                      iterations: int, out: F64) -> None:
    """Mirrors :func:`ecs_anim.core.normalized.spine_joints` for one spine cut into ``count``
    segments of the same chord ``length`` (m): the joints into ``out`` (count, 3), in the frame
    of the control points. Newton stops per spine (see :func:`.decode.spine_joints`)."""
    chords = (norm(sub(control[1], control[0])), norm(sub(control[2], control[1])),
              norm(sub(control[3], control[2])))
    t = 0.0
    point = control[0]
    for k in range(count):
        t, point = spine_joint(control, chords[min(k, 2)], length, t, point, iterations)
        store3(out[k], point)


@jit(inline="always")
def vertebrae_row(c: int, pose: PoseArrays, lengths_row: F64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.core.normalized.vertebrae` for store row ``c``: ``out.shape[0]``
    evenly spaced vertebra joints from the pelvis origin to the neck, world (count, 3), m."""
    count = out.shape[0]
    spine_len = (lengths_row[L_SPINE_LOWER] + lengths_row[L_SPINE_LOWER + 1]
                 + lengths_row[L_SPINE_LOWER + 2])
    points = pose.spine_points[c]
    control = ((0.0, 0.0, 0.0), scale(load3(points[0]), spine_len),
               scale(load3(points[1]), spine_len), scale(load3(points[2]), spine_len))
    even_spine_joints(control, spine_len / count, count, 6, out)
    pelvis2world = pelvis_frame(c, pose)
    pelvis = scale(load3(pose.root_position[c]), leg_length(lengths_row))
    for k in range(count):
        store3(out[k], add(pelvis, to_world(pelvis2world, load3(out[k]))))


@jit()
def all_finite(a: F64) -> bool:
    """Whether every element of the array ``a`` is finite."""
    for x in a.flat:
        if not math.isfinite(x):
            return False
    return True


# Inlined at its two call sites: as a call, handing it its arguments (sixteen then) cost about a
# fifth of posture_rows' time.
@jit(inline="always")
def posture_of_decoded_row(c: int, pose: PoseArrays, lengths: F64, posture: DecodedArrays,
                           positions_good: bool, previous: F64, slot: int, frozen: B8,
                           newly_bad: B8, rotations: bool, world: F64, local: F64,
                           rest_hips: F64, bvh_from_world: F64, rest2body: F64, parents: I64,
                           vertebrae: F64, have_previous: bool) -> None:
    """What :func:`posture_rows` does with store row ``c`` once ``posture`` holds its decoded
    frames and, if they are all finite (``positions_good``), its decoded positions (the
    store's, written over; else the row's positions before, kept): the frozen check
    (``frozen``, ``newly_bad``: the positions, and with ``rotations`` the rotations, all
    finite), ``local[c]`` with ``rotations`` and ``vertebrae[c]``; with ``rotations``,
    ``previous[slot]`` (N_JOINTS, 3) holds the row's positions before, put back if its
    rotations are not finite. Arguments as there."""
    good = positions_good
    if rotations and good:
        export_rotations_row(c, posture, rest_hips, world[c])
        bvh_globals_row(world[c], bvh_from_world, rest2body)
        good = all_finite(world[c])
        if not good:
            copy_positions(posture.positions, c, previous, slot)
    newly_bad[c] = not good and not frozen[c]
    frozen[c] = not good  # a pose finite again (a sane body or target) is published again
    if good and rotations:
        local_from_globals_row(world[c], parents, local[c])
    if vertebrae.shape[1] > 0 and (good or not have_previous):
        vertebrae_row(c, pose, lengths[c], vertebrae[c])


@jit(inline="always")
def with_positions(decoded: DecodedArrays, positions: F64) -> DecodedArrays:
    """``decoded``'s frames with ``positions`` (n, N_JOINTS, 3) for its joints."""
    return DecodedArrays(positions, decoded.pelvis2world, decoded.thorax2world,
                         decoded.head2world, decoded.leg2world, decoded.arm2world)


@jit(inline="always")
def copy_positions(dst: F64, c: int, src: F64, i: int) -> None:
    """``dst[c] = src[i]`` for (n, N_JOINTS, 3) arrays (indices, not :func:`.vec.copy_row`'s
    flat views: numba's reshape calls its runtime, twice a row)."""
    for joint in range(N_JOINTS):
        for a in range(3):
            dst[c, joint, a] = src[i, joint, a]


@jit(nogil=True)
def posture_rows(lo: int, hi: int, rows: I64, pose: PoseArrays, lengths: F64,
                 decoded: DecodedArrays, frozen: B8, newly_bad: B8, positions: F64, rotations: bool,
                 world: F64, local: F64, rest_hips: F64, bvh_from_world: F64, rest2body: F64,
                 parents: I64, vertebrae: F64, have_previous: bool, scratch: F64) -> None:
    """PostureConvert over the store rows ``rows[lo:hi]`` (int64), in place.

    Each row ``c``: decode on ``lengths[c]`` into the frames of ``decoded`` and ``positions[c]``
    (n, N_JOINTS, 3; all C-contiguous, :func:`.decode.fits`); with ``rotations``, the export joints' joint2bvh into the scratch
    ``world`` (n, N_EXPORT, 3, 3). A row whose positions (or rotations) are not finite becomes
    ``frozen`` (``newly_bad[c]`` set when it was not before, else cleared), and stops being
    frozen once they are finite again. A frozen row keeps ``positions[c]``, ``local[c]`` (n,
    N_EXPORT, 3, 3) and ``vertebrae[c]`` (n, count, 3) (its vertebrae are written anyway
    without ``have_previous``); the others get new ones (``local`` with ``rotations``,
    ``vertebrae`` when ``count > 0``). Mirrors ``systems.posture_convert`` on
    :func:`ecs_anim.core.normalized.decode`, :func:`ecs_anim.io.export.skeleton.local_rotations`
    and :func:`ecs_anim.core.normalized.vertebrae`. ``scratch``: :func:`.decode.spine_scratch`
    of ``len(rows)``, for :func:`.decode.decode_block` (as :func:`.decode.decode_rows`);
    ``decoded.positions`` (at least len(rows), N_JOINTS, 3; not ``positions``) is scratch too,
    of which this chunk uses rows ``lo`` to ``lo + BLOCK`` with ``rotations``.

    By blocks of :data:`.lanes.BLOCK` rows (:func:`.decode.block_piece`): their decode on the
    vector units, positions written only where they are all finite (a frozen row's are kept
    without being set aside), then the rest row by row.
    """
    posture = with_positions(decoded, positions)
    previous = decoded.positions
    start = lo
    while start < hi:
        stop, block, first = block_piece(lo, hi, start, scratch)
        if rotations:  # a row whose rotations are not finite gets these back (in cache)
            for i in range(start, stop):
                copy_positions(previous, lo + i - start, positions, rows[i])
        decode_block(start, stop, rows, pose, lengths, posture, block, first, True)
        for i in range(start, stop):
            posture_of_decoded_row(rows[i], pose, lengths, posture,
                                   decoded_finite(block, first + Column(i - start)), previous,
                                   lo + i - start, frozen, newly_bad, rotations, world, local,
                                   rest_hips, bvh_from_world, rest2body, parents, vertebrae,
                                   have_previous)
        start = stop


@jit(nogil=True)
def local_rotations_rows(lo: int, hi: int, rows: I64, decoded: DecodedArrays, rest_hips: F64,
                         bvh_from_world: F64, rest2body: F64, parents: I64, world: F64,
                         out: F64) -> None:
    """Mirrors :func:`ecs_anim.io.export.skeleton.local_rotations` over the rows ``rows[lo:hi]`` of
    ``decoded``: into ``out`` (n, N_EXPORT, 3, 3), with ``world`` (n, N_EXPORT, 3, 3) as scratch."""
    for i in range(lo, hi):
        c = rows[i]
        export_rotations_row(c, decoded, rest_hips, world[c])
        bvh_globals_row(world[c], bvh_from_world, rest2body)
        local_from_globals_row(world[c], parents, out[c])


def local_rotations(pose: DecodedPose) -> F64:
    """Compiled :func:`ecs_anim.io.export.skeleton.local_rotations` of every row of ``pose`` (n, ...):
    (n, N_EXPORT, 3, 3)."""
    arrays = decoded_arrays(pose)
    n = arrays.positions.shape[0]
    k = export_constants()
    out = np.empty((n, N_EXPORT, 3, 3))
    over_chunks(local_rotations_rows, n, np.arange(n, dtype=np.int64), arrays, k.rest_hips,
                k.bvh_from_world, k.rest2body, k.parents, np.empty((n, N_EXPORT, 3, 3)), out)
    return out


@jit(nogil=True)
def vertebrae_rows(lo: int, hi: int, rows: I64, pose: PoseArrays, lengths: F64, out: F64) -> None:
    """Mirrors :func:`ecs_anim.core.normalized.vertebrae` over the rows ``rows[lo:hi]``: into ``out``
    (n, count, 3) world, m, from ``lengths`` (n, N_LENGTHS)."""
    for i in range(lo, hi):
        c = rows[i]
        vertebrae_row(c, pose, lengths[c], out[c])


def vertebrae(poses: NormalizedPoses, lengths: F64, count: int) -> F64:
    """Compiled :func:`ecs_anim.core.normalized.vertebrae` of every row: (n, count, 3)."""
    if count < 1:
        raise ValueError(f"count must be >= 1, got {count}")
    pose = pose_arrays(poses)
    n = pose.root_heading.shape[0]
    lengths = np.ascontiguousarray(np.broadcast_to(lengths, (n, N_LENGTHS)), dtype=np.float64)
    out = np.empty((n, count, 3))
    over_chunks(vertebrae_rows, n, np.arange(n, dtype=np.int64), pose, lengths, out)
    return out
