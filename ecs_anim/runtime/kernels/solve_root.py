"""The solver's root step (``adaptRoot``), compiled, for one character: the root moves
horizontally by the step that brings the centre of mass back once the next pass has re-planted
the legs (predicted), and down where a planted leg could no longer reach its footprint (paper
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
    load_frame,
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
def held_legs(c: int, positions: F64, g: Goals, w: Winners, t: Tables, tolerance_m: float) -> int:
    """Bit ``side`` set for each leg whose ankle the next pass keeps where it is: its goal a
    world point at the ankle (a planted foot's), met now, and no second goal. Mirrors
    ``_Solve.held_legs``."""
    held = 0
    for side in range(2):
        j = w.first_limb[c, side]
        if (j < 0 or w.second_limb[c, side] >= 0 or g.orientation[j] or g.on_self[j]
                or g.bone[j] != 1 or g.fraction[j] != 1.0 or g.offset[j, 0] != 0.0
                or g.offset[j, 1] != 0.0 or g.offset[j, 2] != 0.0):
            continue
        off = sub(load3(positions[c, t.ankle[side]]), load3(g.goal[j]))
        if math.sqrt(dot(off, off)) <= tolerance_m * 0.01:
            held |= 1 << side
    return held


@jit(inline="always")
def leg_shares(c: int, b: Bodies, t: Tables, li: int, total: float) -> tuple[float, float]:
    """The shares of character ``c``'s mass (``total`` kg) that move with leg ``li``'s knee
    and that stay with its ankle (mirrors ``_Solve.root_move``)."""
    upper, lower, distal = t.limb_mass[li, 0], t.limb_mass[li, 1], t.limb_mass[li, 2]
    upper_m, lower_m = b.masses[c, upper] / total, b.masses[c, lower] / total
    lower_f = b.com_fraction[c, lower]
    return (upper_m * b.com_fraction[c, upper] + lower_m * (1.0 - lower_f),
            lower_m * lower_f + b.masses[c, distal] / total)


@jit(inline="always")
def knee_move(c: int, dec: DecodedArrays, lengths_row: F64, t: Tables, li: int,
              move: Vec3) -> Vec3:
    """How far leg ``li``'s knee goes when the root moves by ``move`` and its ankle stays
    (:func:`middle_after_root_move`)."""
    joints = t.limb_joint[li]
    p = dec.positions[c]
    middle = load3(p[joints[1]])
    moved = middle_after_root_move(load3(p[joints[0]]), load3(p[joints[2]]),
                                   load_frame(dec.leg2world[c, li]), lengths_row[t.limb_length[li, 0]],
                                   lengths_row[t.limb_length[li, 1]], move)
    return sub(moved, middle)


@jit(inline="always")
def root_move(c: int, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies, t: Tables,
              ex: float, ey: float, tolerance_m: float, root_gain: float,
              leg_extension: float, predicted: bool) -> Vec3:
    """The root's move (m) bringing character ``c``'s centre of mass by (``ex``, ``ey``) once
    the next pass has re-planted its legs, where ``predicted`` (else the error times
    ``root_gain``). Mirrors ``_Solve.root_move`` (the centre of mass moves with the root but
    for the held legs: their knees' shares follow the knees, their ankles' stay)."""
    p = dec.positions
    sx, sy = ex * root_gain, ey * root_gain
    if predicted:
        held = held_legs(c, p, g, w, t, tolerance_m)
        lengths_row = b.lengths[c]
        total = 0.0
        for s in range(b.masses.shape[1]):
            total += b.masses[c, s]
        # Each held leg's shares of the mass, once (the same for the three moves).
        knee0 = ankle0 = knee1 = ankle1 = 0.0
        for li in range(2):
            if (held >> li) & 1:
                knee_share, ankle_share = leg_shares(c, b, t, li, total)
                if li == 0:
                    knee0, ankle0 = knee_share, ankle_share
                else:
                    knee1, ankle1 = knee_share, ankle_share
        h = ROOT_PROBE_M
        # The Jacobian from two probes of the root, along x and along y (over the probe): the
        # four knee moves written out, not in a loop, so the processor runs their four chains
        # of square roots and divisions side by side (a loop over the legs ran them one after
        # the other: 0.25 ms of 5.5 at 4,000). A leg not held is computed and not counted.
        pc = p[c]
        left, right = t.limb_joint[0], t.limb_joint[1]
        hip_l, knee_l, ankle_l = load3(pc[left[0]]), load3(pc[left[1]]), load3(pc[left[2]])
        hip_r, knee_r, ankle_r = load3(pc[right[0]]), load3(pc[right[1]]), load3(pc[right[2]])
        frame_l, frame_r = load_frame(dec.leg2world[c, 0]), load_frame(dec.leg2world[c, 1])
        upper_l, lower_l = lengths_row[t.limb_length[0, 0]], lengths_row[t.limb_length[0, 1]]
        upper_r, lower_r = lengths_row[t.limb_length[1, 0]], lengths_row[t.limb_length[1, 1]]
        along_x, along_y = (h, 0.0, 0.0), (0.0, h, 0.0)
        lx = sub(middle_after_root_move(hip_l, ankle_l, frame_l, upper_l, lower_l, along_x), knee_l)
        ly = sub(middle_after_root_move(hip_l, ankle_l, frame_l, upper_l, lower_l, along_y), knee_l)
        rx = sub(middle_after_root_move(hip_r, ankle_r, frame_r, upper_r, lower_r, along_x), knee_r)
        ry = sub(middle_after_root_move(hip_r, ankle_r, frame_r, upper_r, lower_r, along_y), knee_r)
        # Each held leg's knee share follows its knee, its ankle share stays (the x probe's
        # bend minus the probe itself, as the loop over the three moves summed them).
        ax, ay, bx, by = h, 0.0, 0.0, h
        if held & 1:
            ax = ax + (knee0 * lx[0] - (knee0 + ankle0) * h)
            ay = ay + (knee0 * lx[1] - (knee0 + ankle0) * 0.0)
            bx = bx + (knee0 * ly[0] - (knee0 + ankle0) * 0.0)
            by = by + (knee0 * ly[1] - (knee0 + ankle0) * h)
        if held & 2:
            ax = ax + (knee1 * rx[0] - (knee1 + ankle1) * h)
            ay = ay + (knee1 * rx[1] - (knee1 + ankle1) * 0.0)
            bx = bx + (knee1 * ry[0] - (knee1 + ankle1) * 0.0)
            by = by + (knee1 * ry[1] - (knee1 + ankle1) * h)
        ax, ay, bx, by = ax / h, ay / h, bx / h, by / h
        det = ax * by - bx * ay
        nx = ny = 0.0
        within = False
        # Newton's step, whose predicted move corrects it once while every held ankle stays
        # within reach (one call site of the knee's arithmetic: numba inlines a copy at each,
        # and the kernels' compile is counted).
        if det > MIN_ROOT_JACOBIAN:
            nx, ny = (by * ex - bx * ey) / det, (ax * ey - ay * ex) / det
            move = (nx, ny, lowering(c, p, b, t, nx, ny, leg_extension))
            mx, my = nx, ny
            within = True
            for li in range(2):
                if (held >> li) & 1:
                    knee_share, ankle_share = (knee0, ankle0) if li == 0 else (knee1, ankle1)
                    bend = knee_move(c, dec, lengths_row, t, li, move)
                    mx = mx + (knee_share * bend[0] - (knee_share + ankle_share) * move[0])
                    my = my + (knee_share * bend[1] - (knee_share + ankle_share) * move[1])
                    to_ankle = sub(sub(load3(p[c, t.ankle[li]]), load3(p[c, t.hip[li]])), move)
                    reach = leg_extension * (lengths_row[t.thigh[li]] + lengths_row[t.shank[li]])
                    within = within and math.sqrt(dot(to_ankle, to_ankle)) <= reach * (1.0 + 1e-9)
        if within:
            dx, dy = ex - mx, ey - my
            sx, sy = nx + (by * dx - bx * dy) / det, ny + (ax * dy - ay * dx) / det
    return sx, sy, lowering(c, p, b, t, sx, sy, leg_extension)


@jit(inline="always")
def solve_root(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies,
               t: Tables, ex: float, ey: float, com_tolerance_m: float, tolerance_m: float,
               root_gain: float, leg_extension: float, predicted: bool) -> float:
    """Mirrors ``ecs_anim.solver.shell._Solve.root`` for character ``c`` (in place), whose
    :func:`com_shortfall` is (``ex``, ``ey``) (m; measured by the caller on the joints as they
    are): returns its size. ``leg_extension``: the longest a planted leg stretches, as a share
    of thigh + shank; ``predicted``: the character has no goal that keeps it iterating
    (``_Solve.predicted``: else the root moves by the error times ``root_gain``)."""
    positions = dec.positions
    size = math.sqrt(ex * ex + ey * ey)
    if not size > 0.1 * com_tolerance_m:
        return size
    sx, sy, sz = root_move(c, dec, g, w, b, t, ex, ey, tolerance_m, root_gain, leg_extension,
                           predicted)
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
