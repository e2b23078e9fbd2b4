"""The solver's root step (``adaptRoot``), compiled, for one character: the root moves
horizontally by the centre-of-mass error times the gain, and down where a planted leg could no
longer reach its footprint (paper §9).

Mirrors ``ecs_anim.solver_shell._Solve.root`` for one character's row of the solve state,
written in place: pose ``root_position`` and every decoded joint (the legs re-aim next).
"""

from __future__ import annotations

import math

from numba import njit

from .decode import DecodedArrays, PoseArrays, leg_length
from .solve_points import Bodies, Tables, centre_of_mass


@njit(cache=True, inline="always")
def solve_root(c: int, pose: PoseArrays, dec: DecodedArrays, b: Bodies, t: Tables,
               com_tolerance_m: float, root_gain: float, leg_extension: float) -> float:
    """Mirrors ``ecs_anim.solver_shell._Solve.root`` for character ``c`` (in place): returns
    the horizontal centre-of-mass error before the move (m; 0 without COM control).
    ``leg_extension``: the longest a planted leg stretches, as a share of thigh + shank."""
    if not b.com_on[c]:
        return 0.0
    com = centre_of_mass(dec, c, b.masses[c], b.com_fraction[c], t)
    ex = b.com_desired[c, 0] - com[0]
    ey = b.com_desired[c, 1] - com[1]
    size = math.sqrt(ex * ex + ey * ey)
    if not size > 0.1 * com_tolerance_m:
        return size
    sx, sy = ex * root_gain, ey * root_gain
    lengths_row = b.lengths[c]
    p = dec.positions[c]
    sz = 0.0
    for s in range(2):
        # Mirrors ground_adapt.vertical_slack_for_reach for this hip once shifted.
        hx, hy, hz = p[t.hip[s], 0] + sx, p[t.hip[s], 1] + sy, p[t.hip[s], 2] + 0.0
        reach = leg_extension * (lengths_row[t.thigh[s]] + lengths_row[t.shank[s]])
        fx, fy, fz = b.footprint[c, s, 0], b.footprint[c, s, 1], b.footprint[c, s, 2]
        horizontal = math.sqrt((hx - fx) ** 2 + (hy - fy) ** 2)
        needed = fz + math.sqrt(max(reach**2 - horizontal**2, 0.0)) - hz
        sz = min(sz, min(needed, 0.0) if b.in_contact[c, s] else 0.0)
    unit = leg_length(lengths_row)
    pose.root_position[c, 0] += sx / unit
    pose.root_position[c, 1] += sy / unit
    pose.root_position[c, 2] += sz / unit
    for joint in range(p.shape[0]):
        p[joint, 0] += sx
        p[joint, 1] += sy
        p[joint, 2] += sz
    return size
