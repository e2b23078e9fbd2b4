"""The solver's root step (``adaptRoot``), compiled, for one character: the root moves
horizontally by the centre-of-mass error times the gain, and down where a planted leg could no
longer reach its footprint (paper §9).

Mirrors ``ecs_anim.solver.shell._Solve.root`` for one character's row of the solve state,
written in place: pose ``root_position`` and every decoded joint (the legs re-aim next).
"""

from __future__ import annotations

import math

from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays, leg_length
from ecs_anim.runtime.kernels.solve_points import B8, I64, Bodies, Tables
from ecs_anim.runtime.kernels.vec import F64, add_scaled, jit, load3, sub


@jit(inline="always")
def solve_root(c: int, pose: PoseArrays, dec: DecodedArrays, b: Bodies, t: Tables,
               com_tolerance_m: float, root_gain: float, leg_extension: float) -> float:
    """Mirrors ``ecs_anim.solver.shell._Solve.root`` for character ``c`` (in place): returns
    the horizontal centre-of-mass error before the move (m; 0 without COM control).
    ``leg_extension``: the longest a planted leg stretches, as a share of thigh + shank."""
    return root_step(c, pose.root_position, dec.positions, b.lengths, b.masses, b.com_fraction,
                     b.footprint, b.in_contact, b.com_desired, b.com_on, t.mass_proximal,
                     t.mass_distal, t.hip, t.thigh, t.shank, com_tolerance_m, root_gain,
                     leg_extension)


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
def root_step(c: int, root_position: F64, positions: F64, lengths: F64, masses: F64,
              com_fraction: F64, footprint: F64, in_contact: B8, com_desired: F64, com_on: B8,
              mass_proximal: I64, mass_distal: I64, hip: I64, thigh: I64, shank: I64,
              com_tolerance_m: float, root_gain: float, leg_extension: float) -> float:
    """:func:`solve_root` on the arrays it reads and writes (the fields of the same names of
    the pose, the decoded rows, the bodies and the tables), which the shell passes rather than
    the state tuples."""
    ex, ey = com_shortfall(c, positions, masses, com_fraction, com_desired, com_on,
                           mass_proximal, mass_distal)
    size = math.sqrt(ex * ex + ey * ey)
    if not size > 0.1 * com_tolerance_m:
        return size
    sx, sy = ex * root_gain, ey * root_gain
    lengths_row = lengths[c]
    p = positions[c]
    sz = 0.0
    for s in range(2):
        # Mirrors ground_adapt.vertical_slack_for_reach for this hip once shifted.
        hx, hy, hz = p[hip[s], 0] + sx, p[hip[s], 1] + sy, p[hip[s], 2] + 0.0
        reach = leg_extension * (lengths_row[thigh[s]] + lengths_row[shank[s]])
        fx, fy, fz = footprint[c, s, 0], footprint[c, s, 1], footprint[c, s, 2]
        horizontal = math.sqrt((hx - fx) ** 2 + (hy - fy) ** 2)
        needed = fz + math.sqrt(max(reach**2 - horizontal**2, 0.0)) - hz
        sz = min(sz, min(needed, 0.0) if in_contact[c, s] else 0.0)
    unit = leg_length(lengths_row)
    root_position[c, 0] += sx / unit
    root_position[c, 1] += sy / unit
    root_position[c, 2] += sz / unit
    for joint in range(p.shape[0]):
        p[joint, 0] += sx
        p[joint, 1] += sy
        p[joint, 2] += sz
    return size
