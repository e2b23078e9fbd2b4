"""The compiled solver's state and the body points it measures, one character at a time.

:class:`Tables` holds the skeleton's index tables (passed to the kernels as arguments: numba's
cache does not see module constants of other files), :class:`Goals` one tick's goals sorted by
character (CSR offsets ``start``), :class:`Winners` the goal each limb and the head serve.
:func:`point_position`, :func:`segment_frame`, :func:`goal_error` and
:func:`centre_of_mass` mirror :func:`ecs_anim.core.body_points.point_positions`,
:func:`ecs_anim.core.body_points.segment_frames`, ``ecs_anim.solver.shell._errors`` and
:func:`ecs_anim.core.morphology.centres_of_mass` for one point or one character.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import FRAME_PELVIS, SEG_DISTAL, SEG_FRAME, SEG_PROXIMAL
from ecs_anim.core.morphology import MASS_SEGMENTS
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX as L
from ecs_anim.runtime.kernels.decode import DecodedArrays
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    add_scaled,
    dot,
    frame_from_axes,
    jit,
    load3,
    load_frame,
    sub,
    to_world,
)
from ecs_anim.solver.shell import LIMB_MASS, SEGMENT_MOVED_BY_PASS

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]


class Tables(NamedTuple):
    """Skeleton indices the steps use (int64 arrays and ints).

    seg_proximal, seg_distal, seg_frame (N_LENGTHS,): a segment's joints and the frame its
    offsets are in (0..3 a limb slot, 4 pelvis, 5 thorax, 6 head); limb_joint (4, 4) per limb
    [leg_l, leg_r, arm_l, arm_r] its root, middle, end and distal-end joints; limb_length (4, 3)
    its upper, lower and distal lengths; group_limb_root, group_limb_middle (6,) per group the
    root and middle joint of the limb the trunk carries (-1: none); limb_of_group (6,) per
    group its limb slot (-1: not a limb); mass_proximal, mass_distal (n_segments,) the joints
    bounding each mass segment; hip, ankle, toe (2,) joints; thigh, shank (2,) lengths; then
    single joints and lengths; seg_moved_by_pass (N_LENGTHS,) 1 where a pass of the solve (limbs,
    head) moves the segment (:data:`ecs_anim.solver.shell.SEGMENT_MOVED_BY_PASS`)."""

    seg_proximal: I64
    seg_distal: I64
    seg_frame: I64
    limb_joint: I64
    limb_length: I64
    group_limb_root: I64
    group_limb_middle: I64
    limb_of_group: I64
    mass_proximal: I64
    mass_distal: I64
    limb_mass: I64
    hip: I64
    ankle: I64
    toe: I64
    thigh: I64
    shank: I64
    pelvis: int
    neck: int
    head: int
    head_top: int
    neck_length: int
    head_length: int
    seg_moved_by_pass: I64


def _ints(values: object) -> I64:
    return np.ascontiguousarray(np.asarray(values, dtype=np.int64))


def tables() -> Tables:
    """The tables of :mod:`ecs_anim.core.skeleton` and :mod:`ecs_anim.core.body_points`."""
    sides = ("l", "r")
    return Tables(
        seg_proximal=_ints(SEG_PROXIMAL), seg_distal=_ints(SEG_DISTAL), seg_frame=_ints(SEG_FRAME),
        limb_joint=_ints([[J[f"{leg}_{s}"] for leg in ("hip", "knee", "ankle", "toe")]
                          for s in sides]
                         + [[J[f"{arm}_{s}"] for arm in ("shoulder", "elbow", "wrist", "hand")]
                            for s in sides]),
        limb_length=_ints([[L[f"{b}_{s}"] for b in ("thigh", "shank", "foot")] for s in sides]
                          + [[L[f"{b}_{s}"] for b in ("upper_arm", "forearm", "hand")]
                             for s in sides]),
        group_limb_root=_ints([-1, -1, J["neck"], J["shoulder_l"], J["shoulder_r"], -1]),
        group_limb_middle=_ints([-1, -1, J["head"], J["elbow_l"], J["elbow_r"], -1]),
        limb_of_group=_ints([0, 1, -1, 2, 3, -1]),
        mass_proximal=_ints([J[s[1]] for s in MASS_SEGMENTS]),
        mass_distal=_ints([J[s[2]] for s in MASS_SEGMENTS]),
        limb_mass=_ints(LIMB_MASS),
        hip=_ints([J["hip_l"], J["hip_r"]]), ankle=_ints([J["ankle_l"], J["ankle_r"]]),
        toe=_ints([J["toe_l"], J["toe_r"]]), thigh=_ints([L["thigh_l"], L["thigh_r"]]),
        shank=_ints([L["shank_l"], L["shank_r"]]),
        pelvis=J["pelvis"], neck=J["neck"], head=J["head"], head_top=J["head_top"],
        neck_length=L["neck"], head_length=L["head"],
        seg_moved_by_pass=_ints(SEGMENT_MOVED_BY_PASS),
    )


class Goals(NamedTuple):
    """One tick's k goals sorted by character (the solved characters' local rows 0..r-1).

    start (r + 1,): character ``c``'s goals are ``start[c]:start[c + 1]``; the others as in
    :class:`ecs_anim.solver.goals.TickGoals` (k,) / (k, 3); ``goal`` is moved by goals that
    follow a point of their own body: ``on_self`` (k,) bool, that point's ``self_segment``,
    ``self_fraction``, ``self_offset`` and where it is now, ``self_at`` (k, 3); ``iterations``
    (k,) the iterations after which a goal no longer keeps its character's loop going nor
    turns the trunk (the frame budget's cut; the settings' ``iterations`` when uncut)."""

    start: I64
    table_index: I64
    orientation: B8
    group: I64
    bone: I64
    segment: I64
    fraction: F64
    offset: F64
    chain: I64
    priority: F64
    goal: F64
    axis: F64
    on_self: B8
    self_segment: I64
    self_fraction: F64
    self_offset: F64
    self_at: F64
    iterations: I64


class Winners(NamedTuple):
    """The goal (index into :class:`Goals`, -1: none) each part serves, fixed for the tick:
    first_limb, second_limb, orient_limb (r, 4) per limb; first_head, orient_head (r,)."""

    first_limb: I64
    second_limb: I64
    orient_limb: I64
    first_head: I64
    orient_head: I64


class Bodies(NamedTuple):
    """Per solved character: lengths (r, N_LENGTHS) m; masses (r, S) kg and com_fraction (r, S);
    footprint (r, 2, 3) where each foot must stay; in_contact (r, 2); com_desired (r, 3);
    com_on (r,); foot_in_world (r, 2, 3) each foot's world direction before the solve;
    iterations (r,) the most iterations each character gets this tick."""

    lengths: F64
    masses: F64
    com_fraction: F64
    footprint: F64
    in_contact: B8
    com_desired: F64
    com_on: B8
    foot_in_world: F64
    iterations: I64


@jit(inline="always")
def limb_frame(dec: DecodedArrays, c: int, slot: int) -> Frame:
    """The half-plane frame of limb ``slot`` (0, 1 legs; 2, 3 arms) of character ``c``."""
    if slot < 2:
        return load_frame(dec.leg2world[c, slot])
    return load_frame(dec.arm2world[c, slot - 2])


@jit(inline="always")
def segment_frame(dec: DecodedArrays, c: int, segment: int, t: Tables) -> Frame:
    """Mirrors :func:`ecs_anim.core.body_points.segment_frames` for one segment of character
    ``c``."""
    kind = t.seg_frame[segment]
    if kind < FRAME_PELVIS:
        limb = limb_frame(dec, c, kind)
        p = dec.positions[c]
        along = sub(load3(p[t.seg_distal[segment]]), load3(p[t.seg_proximal[segment]]))
        return frame_from_axes(along, limb[0], 2, 0, limb[1])
    if kind == FRAME_PELVIS:
        return load_frame(dec.pelvis2world[c])
    if kind == FRAME_PELVIS + 1:
        return load_frame(dec.thorax2world[c])
    return load_frame(dec.head2world[c])


@jit(inline="always")
def point_position(dec: DecodedArrays, c: int, segment: int, fraction: float, offset: Vec3,
                   t: Tables) -> Vec3:
    """Mirrors :func:`ecs_anim.core.body_points.point_positions` for one point of character ``c``:
    ``fraction`` along ``segment``, ``offset`` (m) in its frame."""
    p = dec.positions[c]
    a = load3(p[t.seg_proximal[segment]])
    b = load3(p[t.seg_distal[segment]])
    point = add_scaled(a, sub(b, a), fraction)
    if offset[0] != 0.0 or offset[1] != 0.0 or offset[2] != 0.0:
        point = add(point, to_world(segment_frame(dec, c, segment, t), offset))
    return point


@jit(inline="always")
def plain_point(positions: F64, c: int, proximal: int, distal: int, fraction: float) -> Vec3:
    """:func:`point_position` of a point without offset: ``fraction`` of the way from joint
    ``proximal`` to ``distal`` of character ``c`` (``positions`` (r, N_JOINTS, 3) m)."""
    a = load3(positions[c, proximal])
    b = load3(positions[c, distal])
    return add_scaled(a, sub(b, a), fraction)


@jit(inline="always")
def goal_point(dec: DecodedArrays, c: int, g: Goals, j: int, t: Tables) -> Vec3:
    """Where goal ``j``'s point of character ``c`` is now."""
    return point_position(dec, c, g.segment[j], g.fraction[j], load3(g.offset[j]), t)


@jit(inline="always")
def goal_error(dec: DecodedArrays, c: int, g: Goals, j: int, t: Tables) -> float:
    """Mirrors ``ecs_anim.solver.shell._errors`` for goal ``j`` of character ``c``: the distance
    of its point to its goal (m), or the angle of an orientation (rad)."""
    if g.orientation[j]:
        axis = to_world(segment_frame(dec, c, g.segment[j], t), load3(g.axis[j]))
        return math.acos(min(max(dot(axis, load3(g.goal[j])), -1.0), 1.0))
    d = sub(goal_point(dec, c, g, j, t), load3(g.goal[j]))
    return math.sqrt(dot(d, d))


@jit(inline="always")
def centre_of_mass(dec: DecodedArrays, c: int, masses: F64, com_fraction: F64,
                   t: Tables) -> Vec3:
    """Mirrors :func:`ecs_anim.core.morphology.centres_of_mass` for character ``c`` (masses and
    com_fraction its (S,) rows)."""
    p = dec.positions[c]
    total = 0.0
    x = y = z = 0.0
    for s in range(masses.shape[0]):
        a = load3(p[t.mass_proximal[s]])
        b = load3(p[t.mass_distal[s]])
        seg_com = add_scaled(a, sub(b, a), com_fraction[s])
        x += masses[s] * seg_com[0]
        y += masses[s] * seg_com[1]
        z += masses[s] * seg_com[2]
        total += masses[s]
    return (x / total, y / total, z / total)
