"""The solver's head step, compiled, for one character: neck and head as a two-segment chain
from the neck's base (the limbs' analytic step), then the head's orientation.

Mirrors ``ecs_anim.solver.shell._Solve.head`` for one character's row of the solve state,
written in place: pose ``neck_dir`` and ``head``, decoded ``head2world`` and the head joints.
"""

from __future__ import annotations

import math

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays, two_bone_middle
from ecs_anim.runtime.kernels.solve_math import reach_point
from ecs_anim.runtime.kernels.solve_points import Bodies, Goals, Tables, Winners
from ecs_anim.runtime.kernels.vec import (
    add,
    frame_from_axes,
    in_frame,
    jit,
    load3,
    load_frame,
    matmul,
    norm,
    quat_from_matrix,
    rotation_toward,
    scale,
    store3,
    store4,
    store_frame,
    sub,
    to_world,
    transpose,
)


@jit(inline="always")
def solve_head(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies,
               t: Tables) -> None:
    """Mirrors ``ecs_anim.solver.shell._Solve.head`` for character ``c`` (in place)."""
    first, orient = w.first_head[c], w.orient_head[c]
    if first < 0 and orient < 0:
        return
    p = dec.positions[c]
    lengths_row = b.lengths[c]
    neck = load3(p[t.neck])
    head = load3(p[t.head])
    head2world = load_frame(dec.head2world[c])
    thorax2world = load_frame(dec.thorax2world[c])
    if first >= 0:
        u, ll = lengths_row[t.neck_length], lengths_row[t.head_length]
        top = load3(p[t.head_top])
        frame = frame_from_axes(sub(top, neck), sub(head, neck), 2, 1, thorax2world[0])
        lower = frame_from_axes(sub(top, head), frame[0], 2, 0, frame[1])
        fraction = norm(sub(top, neck)) / (u + ll)
        on_head = g.bone[first] == 1
        along = g.fraction[first] * (ll if on_head else u)
        offset_world = to_world(head2world if on_head else thorax2world, load3(g.offset[first]))
        upper_bone = frame_from_axes(sub(head, neck), frame[0], 2, 0, frame[1])
        bone = lower if on_head else upper_bone
        q = in_frame(bone, offset_world)
        q = (q[0], q[1], q[2] + along)
        new_frame, new_fraction, _ = reach_point(neck, frame, u, ll, fraction, on_head, q,
                                                 load3(g.goal[first]), 1.0)
        new_head, new_top = two_bone_middle(new_frame, neck, u, ll, new_fraction * (u + ll))
        new_lower = frame_from_axes(sub(new_top, new_head), new_frame[0], 2, 0, new_frame[1])
        # The head turns as its bone does (twist included).
        head2world = matmul(matmul(new_lower, transpose(lower)), head2world)
        head = new_head
    if orient >= 0:
        axis = to_world(head2world, load3(g.axis[orient]))
        head2world = matmul(rotation_toward(axis, load3(g.goal[orient]), math.pi, 1.0), head2world)
    thorax_t = transpose(thorax2world)
    neck_len = lengths_row[t.neck_length]
    d = sub(head, neck)
    store3(pose.neck_dir[c],
           to_world(thorax_t, (d[0] / neck_len, d[1] / neck_len, d[2] / neck_len)))
    store4(pose.head[c], quat_from_matrix(matmul(thorax_t, head2world)))
    store_frame(dec.head2world[c], head2world)
    store3(p[t.head], head)
    store3(p[t.head_top], add(head, scale(to_world(head2world, load3(pose.head_top_dir[c])),
                                          lengths_row[t.head_length])))
