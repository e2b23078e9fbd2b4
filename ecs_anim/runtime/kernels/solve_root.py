"""The solver's root step (``adaptRoot``), compiled, for one character: the root moves
horizontally by the step that brings the centre of mass back once the next pass has re-planted
the limbs (predicted), and down where a planted leg could no longer reach its footprint (paper
§9).

Mirrors ``ecs_anim.solver.shell._Solve.root`` for one character's row of the solve state,
written in place: pose ``root_position`` and every decoded joint (the legs re-aim next).
"""

from __future__ import annotations

import math

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays, leg_length
from ecs_anim.runtime.kernels.solve_points import (
    B8,
    I64,
    Bodies,
    Goals,
    Tables,
    Winners,
    limb_frame,
)
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    add_scaled,
    cross,
    dot,
    jit,
    load3,
    scale,
    sub,
)

#: Mirrors ``ecs_anim.solver.shell.ROOT_PROBE_M`` and ``MIN_ROOT_JACOBIAN``.
ROOT_PROBE_M = 1e-3
MIN_ROOT_JACOBIAN = 0.1


@jit(inline="always")
def com_shortfall(c: int, positions: F64, masses: F64, com_fraction: F64, com_desired: F64,
                  com_on: B8, mass_proximal: I64, mass_distal: I64) -> tuple[float, float]:
    """The horizontal way (x, y) from character ``c``'s centre of mass to its desired place
    (m; 0 without COM control). Mirrors ``ecs_anim.solver.shell._Solve.com_shortfall``."""
    if not com_on[c]:
        return 0.0, 0.0
    # Mirrors solve_points.centre_of_mass (the same operations).
    total = 0.0
    x = y = 0.0
    for s in range(masses.shape[1]):
        a = load3(positions[c, mass_proximal[s]])
        bb = load3(positions[c, mass_distal[s]])
        seg_com = add_scaled(a, sub(bb, a), com_fraction[c, s])
        x += masses[c, s] * seg_com[0]
        y += masses[c, s] * seg_com[1]
        total += masses[c, s]
    return com_desired[c, 0] - x / total, com_desired[c, 1] - y / total


@jit(inline="always")
def lowering(c: int, positions: F64, b: Bodies, t: Tables, sx: float, sy: float,
             leg_extension: float) -> float:
    """How far down (m, <= 0) the root must go with a horizontal move (``sx``, ``sy``) so each
    planted leg still reaches its footprint. Mirrors ``_Solve._with_lowering``."""
    lengths_row = b.lengths[c]
    p = positions[c]
    sz = 0.0
    for s in range(2):
        # Mirrors ground_adapt.vertical_slack_for_reach for this hip once shifted.
        hx, hy, hz = p[t.hip[s], 0] + sx, p[t.hip[s], 1] + sy, p[t.hip[s], 2] + 0.0
        reach = leg_extension * (lengths_row[t.thigh[s]] + lengths_row[t.shank[s]])
        fx, fy, fz = b.footprint[c, s, 0], b.footprint[c, s, 1], b.footprint[c, s, 2]
        horizontal = math.sqrt((hx - fx) ** 2 + (hy - fy) ** 2)
        needed = fz + math.sqrt(max(reach**2 - horizontal**2, 0.0)) - hz
        sz = min(sz, min(needed, 0.0) if b.in_contact[c, s] else 0.0)
    return sz


@jit(inline="always")
def middle_after_root_move(root: Vec3, end: Vec3, frame: Frame, upper: float, lower: float,
                           move: Vec3) -> Vec3:
    """Mirrors :func:`ecs_anim.solver.steps.middle_after_root_move` for one limb."""
    moved = add(root, move)
    to_end = sub(end, moved)
    span = math.sqrt(dot(to_end, to_end))
    z_new = scale(to_end, 1.0 / span)
    # Mirrors ecs_anim.core.normalized.two_sphere_middle.
    z_middle = (upper**2 - lower**2 + span**2) / (2.0 * max(span, 1e-12))
    y_middle = math.sqrt(max(upper**2 - z_middle**2, 0.0))
    z_now, y_now = frame[2], frame[1]
    axis = cross(z_now, z_new)
    cos = dot(z_now, z_new)
    along = dot(axis, y_now) / (1.0 + cos)
    turned = cross(axis, y_now)
    y_new = (y_now[0] * cos + turned[0] + axis[0] * along,
             y_now[1] * cos + turned[1] + axis[1] * along,
             y_now[2] * cos + turned[2] + axis[2] * along)
    return add(add(moved, scale(y_new, y_middle)), scale(z_new, z_middle))


@jit(inline="always")
def held_limbs(c: int, positions: F64, g: Goals, w: Winners, t: Tables,
               tolerance_m: float) -> int:
    """Bit ``li`` set for each limb whose end the next pass keeps where it is: its goal a world
    point at its end, met now, and no second goal. Mirrors ``_Solve.held_limbs``."""
    held = 0
    for li in range(4):
        j = w.first_limb[c, li]
        if (j < 0 or w.second_limb[c, li] >= 0 or g.orientation[j] or g.on_self[j]
                or g.bone[j] != 1 or g.fraction[j] != 1.0 or g.offset[j, 0] != 0.0
                or g.offset[j, 1] != 0.0 or g.offset[j, 2] != 0.0):
            continue
        off = sub(load3(positions[c, t.limb_joint[li, 2]]), load3(g.goal[j]))
        if math.sqrt(dot(off, off)) <= tolerance_m * 0.01:
            held |= 1 << li
    return held


@jit(inline="always")
def joint_share(c: int, b: Bodies, t: Tables, joint: int) -> float:
    """The share of character ``c``'s mass that moves with ``joint`` (its segments' centres of
    mass, weighted by how near to it each lies)."""
    moving = 0.0
    total = 0.0
    for s in range(b.masses.shape[1]):
        m, f = b.masses[c, s], b.com_fraction[c, s]
        if t.mass_proximal[s] == joint:
            moving += m * (1.0 - f)
        if t.mass_distal[s] == joint:
            moving += m * f
        total += m
    return moving / total


@jit(inline="always")
def com_move(c: int, dec: DecodedArrays, b: Bodies, t: Tables, held: int,
             middle_share: tuple[float, float, float, float], rigid: float,
             move: Vec3) -> tuple[float, float]:
    """The horizontal move (m) of character ``c``'s centre of mass once its held limbs re-bend
    after the root moved by ``move`` (the rest of the body moves with the root)."""
    lengths_row = b.lengths[c]
    x, y = move[0] * rigid, move[1] * rigid
    bend_x = bend_y = 0.0
    for li in range(4):
        if (held >> li) & 1:
            joints = t.limb_joint[li]
            middle = load3(dec.positions[c, joints[1]])
            moved = middle_after_root_move(
                load3(dec.positions[c, joints[0]]), load3(dec.positions[c, joints[2]]),
                limb_frame(dec, c, li), lengths_row[t.limb_length[li, 0]],
                lengths_row[t.limb_length[li, 1]], move)
            bend_x += middle_share[li] * (moved[0] - middle[0])
            bend_y += middle_share[li] * (moved[1] - middle[1])
    return x + bend_x, y + bend_y


@jit(inline="always")
def root_move(c: int, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies, t: Tables,
              ex: float, ey: float, tolerance_m: float, root_gain: float,
              leg_extension: float) -> Vec3:
    """The root's move (m) bringing character ``c``'s centre of mass by (``ex``, ``ey``) once
    the next pass has re-planted its limbs. Mirrors ``_Solve.root_move``."""
    held = held_limbs(c, dec.positions, g, w, t, tolerance_m)
    shares = (0.0, 0.0, 0.0, 0.0)
    rigid = 1.0
    for li in range(4):
        if (held >> li) & 1:
            joints = t.limb_joint[li]
            middle = joint_share(c, b, t, joints[1])
            end = joint_share(c, b, t, joints[2]) + joint_share(c, b, t, joints[3])
            shares = (middle if li == 0 else shares[0], middle if li == 1 else shares[1],
                      middle if li == 2 else shares[2], middle if li == 3 else shares[3])
            rigid -= middle + end
    ax, ay = com_move(c, dec, b, t, held, shares, rigid, (ROOT_PROBE_M, 0.0, 0.0))
    bx, by = com_move(c, dec, b, t, held, shares, rigid, (0.0, ROOT_PROBE_M, 0.0))
    ax, ay, bx, by = ax / ROOT_PROBE_M, ay / ROOT_PROBE_M, bx / ROOT_PROBE_M, by / ROOT_PROBE_M
    det = ax * by - bx * ay
    p = dec.positions
    if det > MIN_ROOT_JACOBIAN:
        # Newton's step (Cramer's rule), corrected once by the prediction at the step.
        sx, sy = (by * ex - bx * ey) / det, (ax * ey - ay * ex) / det
        sz = lowering(c, p, b, t, sx, sy, leg_extension)
        mx, my = com_move(c, dec, b, t, held, shares, rigid, (sx, sy, sz))
        rx, ry = ex - mx, ey - my
        sx, sy = sx + (by * rx - bx * ry) / det, sy + (ax * ry - ay * rx) / det
        sz = lowering(c, p, b, t, sx, sy, leg_extension)
        within = True
        for li in range(4):
            if (held >> li) & 1:
                joints = t.limb_joint[li]
                to_end = sub(sub(load3(p[c, joints[2]]), load3(p[c, joints[0]])), (sx, sy, sz))
                reach = ((leg_extension if li < 2 else 1.0)
                         * (b.lengths[c, t.limb_length[li, 0]] + b.lengths[c, t.limb_length[li, 1]]))
                within = within and math.sqrt(dot(to_end, to_end)) <= reach * (1.0 + 1e-9)
        if within:
            return sx, sy, sz
    sx, sy = ex * root_gain, ey * root_gain
    return sx, sy, lowering(c, p, b, t, sx, sy, leg_extension)


@jit(inline="always")
def solve_root(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies,
               t: Tables, com_tolerance_m: float, tolerance_m: float, root_gain: float,
               leg_extension: float) -> float:
    """Mirrors ``ecs_anim.solver.shell._Solve.root`` for character ``c`` (in place): returns
    the horizontal centre-of-mass error before the move (m; 0 without COM control).
    ``leg_extension``: the longest a planted leg stretches, as a share of thigh + shank."""
    positions = dec.positions
    ex, ey = com_shortfall(c, positions, b.masses, b.com_fraction, b.com_desired, b.com_on,
                           t.mass_proximal, t.mass_distal)
    size = math.sqrt(ex * ex + ey * ey)
    if not size > 0.1 * com_tolerance_m:
        return size
    sx, sy, sz = root_move(c, dec, g, w, b, t, ex, ey, tolerance_m, root_gain, leg_extension)
    unit = leg_length(b.lengths[c])
    pose.root_position[c, 0] += sx / unit
    pose.root_position[c, 1] += sy / unit
    pose.root_position[c, 2] += sz / unit
    p = positions[c]
    for joint in range(p.shape[0]):
        p[joint, 0] += sx
        p[joint, 1] += sy
        p[joint, 2] += sz
    return size
