"""Local avoidance between walkers, compiled: optimal reciprocal collision avoidance (ORCA).

van den Berg, Guy, Lin, Manocha 2011, "Reciprocal n-body collision avoidance": each agent,
given its neighbours' positions and velocities, keeps the velocities that avoid each of them
for ``time_horizon_s`` with half of the effort (a half-plane of velocities per neighbour, the
*ORCA line*), and takes the one of them nearest its preferred velocity, within its maximum
speed: a 2D linear program, or, when the half-planes leave no room, the velocity that
violates them least (a 3D linear program). The steps follow RVO2's ``Agent::computeNewVelocity``,
``linearProgram1/2/3`` (the reference implementation; agents only, no polygon obstacles), with
these additions, for walkers: an agent that does not avoid (standing at its goal, or switched
off) is a *passive* neighbour, whose ORCA line the other takes in full instead of half; an
agent behind another going the same way takes its line in full and the one ahead none (a
file); two agents' combined radius is at least what their legs' strides need in the direction
they are from each other (:func:`legs_apart`); and an agent slowed below its slowest steps
walks them where the lines allow (:func:`at_least`).

Neighbours are found on a uniform grid hashed into a table (:func:`build_grid`, a counting sort
of the agents by cell; :func:`sort_by_cell` lays their positions out in that order): each
agent keeps its ``max_neighbours`` nearest within the neighbour distance, the search radius
shrinking to the farthest kept once the list is full (as RVO2's k-d tree query), looking at
the cells (half that distance wide) ring by ring about its own, nearest first, while they are
in range (:func:`nearest_neighbours`).

2D vectors are tuples ``(x, y)``; lines are rows ``(point_x, point_y, direction_x,
direction_y)`` of a caller's scratch array (the kernels allocate nothing). :func:`orca_velocities`
is the numpy-facing call.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels import MIN_ROWS_PER_THREAD, over_chunks, threads
from ecs_anim.runtime.kernels.vec import F64, TINY, jit

I64 = NDArray[np.int64]
B = NDArray[np.bool_]
Vec2 = tuple[float, float]

#: RVO2's RVO_EPSILON: parallel lines, in the linear programs.
EPSILON = 1e-5
#: The grid's cells are the neighbour distance over this wide: the search looks at this many
#: rings of cells about an agent's own, each cell only while it is in range.
CELLS_PER_RANGE = 2


@jit()
def det(a: Vec2, b: Vec2) -> float:
    """The 2D cross product ``a.x b.y - a.y b.x``."""
    return a[0] * b[1] - a[1] * b[0]


@jit()
def cell_hash(ix: int, iy: int, mask: int) -> int:
    """The table slot of grid cell ``(ix, iy)`` (a table of ``mask + 1`` slots, a power of 2)."""
    return ((ix * 73856093) ^ (iy * 19349663)) & mask


@jit(nogil=True)
def build_grid(position: F64, cell_m: float, mask: int, slot: I64, start: I64,
               order: I64) -> None:
    """Sort the agents by grid cell (a counting sort over the hash table's slots).

    position : (k, 2) agents' positions, m.
    cell_m : the cells' width, m.
    mask : the table has ``mask + 1`` slots (a power of 2).
    slot : (k,) written: each agent's slot.
    start : (mask + 2,) written: the agents of slot ``s`` are ``order[start[s]:start[s + 1]]``.
    order : (k,) written: agent indices sorted by slot.
    """
    for i in range(position.shape[0]):
        slot[i] = cell_hash(math.floor(position[i, 0] / cell_m),
                            math.floor(position[i, 1] / cell_m), mask)
    sort_by_slot(slot, start, order)


@jit(nogil=True)
def sort_by_slot(slot: I64, start: I64, order: I64) -> None:
    """A counting sort of the agents by ``slot`` (k,), each below ``start.size - 1``: ``start``
    written, the agents of slot ``s`` are ``order[start[s]:start[s + 1]]`` (``order`` (k,)
    written, each slot's agents in increasing index)."""
    n, slots = slot.shape[0], start.shape[0] - 1
    for s in range(slots + 1):
        start[s] = 0
    for i in range(n):
        start[slot[i] + 1] += 1
    for s in range(slots):
        start[s + 1] += start[s]
    # start[s] is now where slot s begins; fill, then shift back.
    for i in range(n):
        order[start[slot[i]]] = i
        start[slot[i]] += 1
    for s in range(slots - 1, 0, -1):
        start[s] = start[s - 1]
    start[0] = 0


@jit()
def lp1(lines: F64, row: int, line: int, radius: float, opt: Vec2,
        direction_opt: bool) -> tuple[bool, float, float]:
    """RVO2's ``linearProgram1``: the best velocity on line ``line`` of ``lines[row]`` within
    the speed ``radius`` and the lines before it (ok, x, y); not ok when there is none."""
    px, py = lines[row, line, 0], lines[row, line, 1]
    dx, dy = lines[row, line, 2], lines[row, line, 3]
    dot_pd = px * dx + py * dy
    discriminant = dot_pd * dot_pd + radius * radius - (px * px + py * py)
    if discriminant < 0.0:
        return False, 0.0, 0.0
    root = math.sqrt(discriminant)
    t_left, t_right = -dot_pd - root, -dot_pd + root
    for j in range(line):
        qx, qy = lines[row, j, 0], lines[row, j, 1]
        ex, ey = lines[row, j, 2], lines[row, j, 3]
        denominator = dx * ey - dy * ex
        numerator = ex * (py - qy) - ey * (px - qx)
        if abs(denominator) <= EPSILON:
            if numerator < 0.0:
                return False, 0.0, 0.0
            continue
        t = numerator / denominator
        if denominator >= 0.0:
            t_right = min(t_right, t)
        else:
            t_left = max(t_left, t)
        if t_left > t_right:
            return False, 0.0, 0.0
    if direction_opt:
        t = t_right if opt[0] * dx + opt[1] * dy > 0.0 else t_left
    else:
        t = min(max(dx * (opt[0] - px) + dy * (opt[1] - py), t_left), t_right)
    return True, px + t * dx, py + t * dy


@jit()
def lp2(lines: F64, row: int, n_lines: int, radius: float, opt: Vec2,
        direction_opt: bool) -> tuple[int, float, float]:
    """RVO2's ``linearProgram2``: the velocity nearest ``opt`` (or furthest along it, with
    ``direction_opt``) within the speed ``radius`` and left of the ``n_lines`` lines of
    ``lines[row]``. Returns (the first line that could not be met, or ``n_lines``; x, y)."""
    if direction_opt:
        rx, ry = opt[0] * radius, opt[1] * radius
    else:
        speed_sq = opt[0] * opt[0] + opt[1] * opt[1]
        if speed_sq > radius * radius:
            s = radius / math.sqrt(speed_sq)
            rx, ry = opt[0] * s, opt[1] * s
        else:
            rx, ry = opt
    for i in range(n_lines):
        if det((lines[row, i, 2], lines[row, i, 3]),
               (lines[row, i, 0] - rx, lines[row, i, 1] - ry)) > 0.0:
            ok, x, y = lp1(lines, row, i, radius, opt, direction_opt)
            if not ok:
                return i, rx, ry
            rx, ry = x, y
    return n_lines, rx, ry


@jit()
def lp3(lines: F64, projected: F64, row: int, n_hard: int, n_lines: int, begin: int,
        radius: float, result: Vec2) -> Vec2:
    """RVO2's ``linearProgram3``: from line ``begin`` on, where the 2D program failed, the
    velocity that least violates the lines of ``lines[row]`` (the largest distance into a
    forbidden side made smallest), never the first ``n_hard`` (RVO2's obstacle lines; here the
    turn the walker can make); ``projected[row]`` is scratch."""
    rx, ry = result
    distance = 0.0
    for i in range(begin, n_lines):
        px, py = lines[row, i, 0], lines[row, i, 1]
        dx, dy = lines[row, i, 2], lines[row, i, 3]
        if det((dx, dy), (px - rx, py - ry)) <= distance:
            continue
        for j in range(n_hard):
            for q in range(4):
                projected[row, j, q] = lines[row, j, q]
        n_projected = n_hard
        for j in range(n_hard, i):
            qx, qy = lines[row, j, 0], lines[row, j, 1]
            ex, ey = lines[row, j, 2], lines[row, j, 3]
            determinant = dx * ey - dy * ex
            if abs(determinant) <= EPSILON:
                if dx * ex + dy * ey > 0.0:
                    continue  # same direction: line j is implied
                ax, ay = 0.5 * (px + qx), 0.5 * (py + qy)
            else:
                t = (ex * (py - qy) - ey * (px - qx)) / determinant
                ax, ay = px + t * dx, py + t * dy
            ux, uy = ex - dx, ey - dy
            length = max(math.sqrt(ux * ux + uy * uy), TINY)
            projected[row, n_projected, 0], projected[row, n_projected, 1] = ax, ay
            projected[row, n_projected, 2] = ux / length
            projected[row, n_projected, 3] = uy / length
            n_projected += 1
        failed, x, y = lp2(projected, row, n_projected, radius, (-dy, dx), True)
        if failed >= n_projected:  # else: a rounding failure; keep the last result
            rx, ry = x, y
        distance = det((dx, dy), (px - rx, py - ry))
    return rx, ry


@jit()
def at_least(lines: F64, row: int, n_lines: int, max_speed: float, min_speed: float, opt: Vec2,
             result: Vec2) -> Vec2:
    """A velocity of speed ``min_speed`` that the lines of ``lines[row]`` allow, between
    ``result`` (allowed, slower) and the fastest allowed one in its direction (or ``opt``'s,
    when ``result`` is 0), where there is one; else ``result``. A walker steps no slower than
    its slowest steps: where ORCA's nearest velocity is slower, it walks that slowly round
    what is in its way rather than stand behind it."""
    rx, ry = result
    speed = math.sqrt(rx * rx + ry * ry)
    if speed > TINY:
        ux, uy = rx / speed, ry / speed
    else:
        length = max(math.sqrt(opt[0] * opt[0] + opt[1] * opt[1]), TINY)
        ux, uy = opt[0] / length, opt[1] / length
    failed, fx, fy = lp2(lines, row, n_lines, max_speed, (ux, uy), True)
    if failed < n_lines or fx * fx + fy * fy < min_speed * min_speed:
        return result
    # |result + t (far - result)| = min_speed, t in [0, 1]: allowed, the lines being convex.
    dx, dy = fx - rx, fy - ry
    a = dx * dx + dy * dy
    b = rx * dx + ry * dy
    c = speed * speed - min_speed * min_speed
    t = (-b + math.sqrt(max(b * b - a * c, 0.0))) / max(a, TINY)
    return rx + t * dx, ry + t * dy


@jit()
def legs_apart(stride_m: float, feet_m: float, along_m: float, dist_sq: float) -> float:
    """How far apart two walkers one behind the other must be, in the direction they are now
    from each other, for their legs not to meet (m): their legs swept over a stride are a
    stadium (the points within ``feet_m`` of a segment ``stride_m`` either side of the one
    behind, along its facing; the sum of both bodies'), and this is its boundary's distance
    from its centre in the direction ``along_m`` m along that facing of ``sqrt(dist_sq)``."""
    dist = math.sqrt(max(dist_sq, TINY))
    along = abs(along_m) / dist
    across = math.sqrt(max(1.0 - along * along, 0.0))
    # Both ways out worked out and one chosen, not branched to: which one is taken changes
    # from one neighbour to the next, and a mispredicted branch cost more than the other way's
    # arithmetic (the bench's walkers: 10 % of avoidance's time).
    flat = feet_m / across
    cap = stride_m * along + math.sqrt(max(feet_m * feet_m - (stride_m * across) ** 2, 0.0))
    return flat if feet_m * along <= stride_m * across else cap  # out through a flat side


@jit(nogil=True)
def sort_by_cell(position: F64, cell_m: float, order: I64, sorted_xy: F64,
                 sorted_cell: I64) -> None:
    """The agents' positions and grid cells in the order of :func:`build_grid` (read in a row
    by the search, not gathered agent by agent).

    position : (k, 2) m; order : (k,) from :func:`build_grid`.
    sorted_xy : (k, 2) written: ``position[order]``.
    sorted_cell : (k, 2) written: the cell ``(ix, iy)`` of each, in that order (two cells may
        share a slot: the search keeps a cell's own).
    """
    for a in range(order.shape[0]):
        j = order[a]
        x, y = position[j, 0], position[j, 1]
        sorted_xy[a, 0], sorted_xy[a, 1] = x, y
        sorted_cell[a, 0] = math.floor(x / cell_m)
        sorted_cell[a, 1] = math.floor(y / cell_m)


@jit()
def insert_neighbours_of_cell(i: int, x: float, y: float, cx: int, cy: int, range_sq: float,
                              count: int, max_neighbours: int, mask: int, start: I64,
                              order: I64, sorted_xy: F64, sorted_cell: I64, row: int,
                              neighbour: I64, neighbour_d2: F64) -> tuple[int, float]:
    """Insert the agents of cell ``(cx, cy)`` nearer agent ``i`` at ``(x, y)`` than
    ``sqrt(range_sq)`` among its ``count`` nearest in ``neighbour[row]`` (and squared distances
    in ``neighbour_d2[row]``), nearest first (RVO2's ``insertAgentNeighbor``); the range shrinks
    to the farthest kept once ``max_neighbours`` are. Returns (count, range_sq)."""
    s = cell_hash(cx, cy, mask)
    for a in range(start[s], start[s + 1]):
        dx, dy = sorted_xy[a, 0] - x, sorted_xy[a, 1] - y
        d2 = dx * dx + dy * dy
        if d2 >= range_sq or sorted_cell[a, 0] != cx or sorted_cell[a, 1] != cy:
            continue
        j = order[a]
        if j == i:
            continue
        m = count if count < max_neighbours else max_neighbours - 1
        while m > 0 and neighbour_d2[row, m - 1] > d2:
            neighbour[row, m] = neighbour[row, m - 1]
            neighbour_d2[row, m] = neighbour_d2[row, m - 1]
            m -= 1
        neighbour[row, m] = j
        neighbour_d2[row, m] = d2
        if count < max_neighbours:
            count += 1
        if count == max_neighbours:
            range_sq = neighbour_d2[row, count - 1]
    return count, range_sq


def ring_order(rings: int) -> tuple[I64, I64, I64]:
    """The cells about an agent's own, ring by ring outward, each ring's nearest first for an
    agent in the low quarter of its cell (the search flips them to the agent's own quarter):
    (dx (c,), dy (c,), where ring r begins (rings + 2,)), c = (2 rings + 1)^2 cells."""
    offsets = [(dx, dy) for dx in range(-rings, rings + 1) for dy in range(-rings, rings + 1)]

    def gap(d: int) -> float:  # from a point a quarter into its cell, in cells
        return d - 0.25 if d > 0 else (-d - 1) + 0.25 if d < 0 else 0.0

    offsets.sort(key=lambda o: (max(abs(o[0]), abs(o[1])), gap(o[0]) ** 2 + gap(o[1]) ** 2))
    ring_of = np.array([max(abs(dx), abs(dy)) for dx, dy in offsets])
    begins = np.searchsorted(ring_of, np.arange(rings + 2))
    dx = np.array([o[0] for o in offsets], np.int64)
    dy = np.array([o[1] for o in offsets], np.int64)
    return dx, dy, begins.astype(np.int64)


#: :func:`ring_order` for the grid's :data:`CELLS_PER_RANGE` rings (constants in the kernels).
RING_DX, RING_DY, RING_BEGINS = ring_order(CELLS_PER_RANGE)


@jit()
def nearest_neighbours(i: int, position: F64, range_m: float, cell_m: float, mask: int,
                       start: I64, order: I64, sorted_xy: F64, sorted_cell: I64,
                       max_neighbours: int, row: int, neighbour: I64, neighbour_d2: F64) -> int:
    """Agent ``i``'s nearest ``max_neighbours`` other agents within ``range_m``, nearest first,
    into ``neighbour[row]`` and their squared distances into ``neighbour_d2[row]``; returns how
    many. The :data:`CELLS_PER_RANGE` rings of cells (of ``cell_m = range_m /
    CELLS_PER_RANGE``) about its own cover the range; they are looked at ring by ring outward,
    each ring's nearest cells first, a cell only while the nearest point of it is in range (the
    range shrinks as the nearest are found), the rings while the nearest of each is."""
    x, y = position[i, 0], position[i, 1]
    ix, iy = math.floor(x / cell_m), math.floor(y / cell_m)
    # Where it is in its cell (m from the cell's low edges), and which quarter: the ring
    # order's offsets are flipped to it. A cell's gap is taken a hair short, so that floor's
    # rounding at a cell's edge never skips an agent.
    in_x, in_y = x - ix * cell_m, y - iy * cell_m
    flip_x = 1 if in_x < 0.5 * cell_m else -1
    flip_y = 1 if in_y < 0.5 * cell_m else -1
    hair = 1e-9 * cell_m
    edge = min(in_x, cell_m - in_x, in_y, cell_m - in_y) - hair
    range_sq = range_m * range_m
    count = 0
    for ring in range(RING_BEGINS.shape[0] - 1):
        if ring > 0:
            ring_gap = max(edge + (ring - 1) * cell_m, 0.0)
            if ring_gap * ring_gap >= range_sq:
                break
        for t in range(RING_BEGINS[ring], RING_BEGINS[ring + 1]):
            dx, dy = flip_x * RING_DX[t], flip_y * RING_DY[t]
            gap_x = max(max(dx * cell_m - in_x, in_x - (dx + 1) * cell_m) - hair, 0.0)
            gap_y = max(max(dy * cell_m - in_y, in_y - (dy + 1) * cell_m) - hair, 0.0)
            if gap_x * gap_x + gap_y * gap_y >= range_sq:
                continue
            count, range_sq = insert_neighbours_of_cell(
                i, x, y, ix + dx, iy + dy, range_sq, count, max_neighbours, mask, start, order,
                sorted_xy, sorted_cell, row, neighbour, neighbour_d2)
    return count


@jit(nogil=True)
def orca_chunks(lo: int, hi: int, bounds: I64, position: F64, velocity: F64, preferred: F64,
                radius: F64, stride_m: F64, feet_m: F64, legs: bool, max_speed: F64,
                min_speed: F64, facing: F64, active: B, range_m: float, time_horizon_s: float,
                dt: float, cone_rad: float, cell_m: float, mask: int, start: I64, order: I64,
                sorted_xy: F64, sorted_cell: I64, neighbour: I64, neighbour_d2: F64, lines: F64,
                projected: F64, out: F64) -> None:
    """The new velocity (RVO2's ``computeNewVelocity``) of the agents of chunks ``lo..hi-1``
    into ``out`` ((k, 2), m/s), chunk ``c`` the agents ``bounds[c]..bounds[c + 1]-1``, worked
    out in the chunk's own row of the scratch arrays (a few lines' worth, kept in the
    nearest cache); a passive agent (``active`` false) gets its preferred velocity.

    position, velocity, preferred : (k, 2) m, m/s: where each agent is, how it moves now, how
        it would move with nobody about.
    radius, max_speed : (k,) m, m/s.
    stride_m, feet_m, legs : (k,) m, and whether to use them: each agent's legs, a stadium
        (:func:`legs_apart`) of half-length ``stride_m`` along its ``facing`` and radius
        ``feet_m``; without ``legs``, only the files below (whose stadium is then ``feet_m``).
    min_speed : (k,) m/s: an agent that the lines slow below this goes this fast where they
        allow it (:func:`at_least`); 0: none.
    facing, cone_rad : (k, 2) unit vectors, rad: which way each agent faces; an agent within
        45 degrees of behind another, both facing the same way, avoids it in full and the one
        ahead not at all (a file). With ``cone_rad``, an agent with neighbours keeps its velocity
        within ``cone_rad`` (at most pi / 2) of ``facing`` (two hard lines, as RVO2's
        obstacles': a walker does not step sideways); pi or more: no such limit.
    range_m, time_horizon_s, dt : the neighbour distance, how far ahead collisions are avoided,
        the tick (the time in which agents found overlapping are to separate).
    cell_m, mask, start, order, sorted_xy, sorted_cell : the grid of :func:`build_grid` and
        :func:`sort_by_cell`.
    neighbour, neighbour_d2 : (chunks, max_neighbours + 2) scratch (int64, float64).
    lines, projected : (chunks, max_neighbours + 2, 4) scratch.
    """
    max_neighbours = neighbour.shape[1] - 2
    coned = cone_rad < math.pi
    cone_cos, cone_sin = math.cos(cone_rad), math.sin(cone_rad)
    inv_horizon = 1.0 / time_horizon_s
    inv_dt = 1.0 / dt
    for chunk in range(lo, hi):
        for i in range(bounds[chunk], bounds[chunk + 1]):
            if not active[i]:
                out[i, 0], out[i, 1] = preferred[i, 0], preferred[i, 1]
                continue
            count = nearest_neighbours(i, position, range_m, cell_m, mask, start, order, sorted_xy,
                                       sorted_cell, max_neighbours, chunk, neighbour,
                                       neighbour_d2)
            vx, vy = velocity[i, 0], velocity[i, 1]
            n_hard = 2 if coned and count > 0 else 0
            fx, fy = facing[i, 0], facing[i, 1]
            if n_hard:
                # Left of the cone's right edge, right of its left edge (lines through 0).
                lines[chunk, 0, 0] = lines[chunk, 0, 1] = 0.0
                lines[chunk, 1, 0] = lines[chunk, 1, 1] = 0.0
                lines[chunk, 0, 2] = fx * cone_cos + fy * cone_sin
                lines[chunk, 0, 3] = fy * cone_cos - fx * cone_sin
                lines[chunk, 1, 2] = -(fx * cone_cos - fy * cone_sin)
                lines[chunk, 1, 3] = -(fy * cone_cos + fx * cone_sin)
            m = n_hard
            for n in range(count):
                j = neighbour[chunk, n]
                rel_x, rel_y = position[j, 0] - position[i, 0], position[j, 1] - position[i, 1]
                rv_x, rv_y = vx - velocity[j, 0], vy - velocity[j, 1]
                dist_sq = rel_x * rel_x + rel_y * rel_y
                combined = radius[i] + radius[j]
                share = 0.5 if active[j] else 1.0  # a passive neighbour leaves it all to this one
                # One behind the other (within 45 degrees of both facings, the same way): the one
                # behind avoids it all, the one ahead not at all, and their legs need their strides.
                ahead_of_i = fx * rel_x + fy * rel_y
                behind_j = facing[j, 0] * rel_x + facing[j, 1] * rel_y
                if (ahead_of_i * behind_j > 0.0
                        and min(ahead_of_i * ahead_of_i, behind_j * behind_j) > 0.5 * dist_sq):
                    if ahead_of_i < 0.0:
                        continue  # j follows i: j keeps clear
                    share = 1.0
                    combined = max(combined, legs_apart(
                        stride_m[i] + stride_m[j], feet_m[i] + feet_m[j], ahead_of_i, dist_sq))
                elif legs:  # each one's stride against the other's legs
                    feet = feet_m[i] + feet_m[j]
                    combined = max(combined, legs_apart(stride_m[i], feet, ahead_of_i, dist_sq),
                                   legs_apart(stride_m[j], feet, behind_j, dist_sq))
                combined_sq = combined * combined
                if dist_sq > combined_sq:
                    # No collision: the velocity obstacle's cut-off circle or one of its legs.
                    w_x, w_y = rv_x - inv_horizon * rel_x, rv_y - inv_horizon * rel_y
                    w_len_sq = w_x * w_x + w_y * w_y
                    dot1 = w_x * rel_x + w_y * rel_y
                    if dot1 < 0.0 and dot1 * dot1 > combined_sq * w_len_sq:
                        w_len = max(math.sqrt(w_len_sq), TINY)
                        unit_x, unit_y = w_x / w_len, w_y / w_len
                        dir_x, dir_y = unit_y, -unit_x
                        scale = combined * inv_horizon - w_len
                        u_x, u_y = scale * unit_x, scale * unit_y
                    else:
                        leg = math.sqrt(dist_sq - combined_sq)
                        # The left leg, or the right one (its terms in leg negated: exactly
                        # RVO2's figures, chosen by a sign rather than a branch).
                        side = 1.0 if det((rel_x, rel_y), (w_x, w_y)) > 0.0 else -1.0
                        dir_x = (side * rel_x * leg - rel_y * combined) / dist_sq
                        dir_y = (rel_x * combined + side * rel_y * leg) / dist_sq
                        dot2 = rv_x * dir_x + rv_y * dir_y
                        u_x, u_y = dot2 * dir_x - rv_x, dot2 * dir_y - rv_y
                else:
                    # Overlapping: separate within the tick (the cut-off circle of time dt).
                    w_x, w_y = rv_x - inv_dt * rel_x, rv_y - inv_dt * rel_y
                    w_len = math.sqrt(w_x * w_x + w_y * w_y)
                    if w_len > TINY:
                        unit_x, unit_y = w_x / w_len, w_y / w_len
                    else:  # on top of each other, at the same velocity: the lower index goes -x
                        unit_x, unit_y = (-1.0 if i < j else 1.0), 0.0
                    dir_x, dir_y = unit_y, -unit_x
                    scale = combined * inv_dt - w_len
                    u_x, u_y = scale * unit_x, scale * unit_y
                lines[chunk, m, 0], lines[chunk, m, 1] = vx + share * u_x, vy + share * u_y
                lines[chunk, m, 2], lines[chunk, m, 3] = dir_x, dir_y
                m += 1
            opt = (preferred[i, 0], preferred[i, 1])
            n_lines = m
            failed, rx, ry = lp2(lines, chunk, n_lines, max_speed[i], opt, False)
            if failed < n_lines:
                rx, ry = lp3(lines, projected, chunk, n_hard, n_lines, failed, max_speed[i],
                             (rx, ry))
            elif rx * rx + ry * ry < min_speed[i] * min_speed[i]:
                rx, ry = at_least(lines, chunk, n_lines, max_speed[i], min_speed[i], opt, (rx, ry))
            out[i, 0], out[i, 1] = rx, ry


def table_mask(n_agents: int) -> int:
    """The hash table's slots less one: the power of 2 at least twice the agents (at least 16)."""
    return int(1 << max(4, int(2 * max(n_agents, 1) - 1).bit_length())) - 1


def orca_velocities(position: F64, velocity: F64, preferred: F64, radius: F64, max_speed: F64,
                    active: B, *, range_m: float, time_horizon_s: float, max_neighbours: int,
                    dt: float, facing: F64 | None = None, cone_rad: float = math.pi,
                    stride_m: F64 | None = None, feet_m: F64 | None = None,
                    min_speed: F64 | None = None) -> F64:
    """Each agent's collision-avoiding velocity (k, 2) m/s (ORCA; see the module docstring):
    the grid built, then :func:`orca_chunks` over all agents, split over the kernels' threads.

    position, velocity, preferred : (k, 2) float64, m and m/s.
    radius, max_speed : (k,) float64, m and m/s.
    active : (k,) bool: the agents that avoid (the others are passive neighbours and get their
        preferred velocity back).
    range_m : neighbours farther than this are not looked at (m); the grid's cells are
        ``range_m / CELLS_PER_RANGE`` wide.
    time_horizon_s : collisions within this time are avoided (s).
    max_neighbours : at most this many nearest neighbours are avoided.
    dt : the tick (s).
    facing, cone_rad : (k, 2) unit vectors and rad: which way each agent faces (None: no
        files, see :func:`orca_chunks`), and each agent with neighbours keeps within
        ``cone_rad`` (at most pi / 2) of it (pi: anywhere).
    stride_m, feet_m : (k,) m: each agent's legs (:func:`orca_chunks`; None: discs only).
    min_speed : (k,) m/s: the slowest an agent goes but standing (:func:`at_least`; None: 0).
    """
    n = position.shape[0]
    out = np.empty((n, 2))
    if n == 0:
        return out
    legs = stride_m is not None and feet_m is not None
    if stride_m is None or feet_m is None:
        stride_m = feet_m = np.zeros(n)
    if min_speed is None:
        min_speed = np.zeros(n)
    mask = table_mask(n)
    position = np.ascontiguousarray(position, np.float64)
    slot, order = np.empty(n, np.int64), np.empty(n, np.int64)
    start = np.empty(mask + 2, np.int64)
    cell_m = range_m / CELLS_PER_RANGE
    build_grid(position, cell_m, mask, slot, start, order)
    sorted_xy, sorted_cell = np.empty((n, 2)), np.empty((n, 2), np.int64)
    sort_by_cell(position, cell_m, order, sorted_xy, sorted_cell)
    if facing is None:
        facing, cone_rad = np.zeros((n, 2)), math.pi
    # One chunk a thread, each with its own scratch rows.
    chunks = max(1, min(threads(), n // MIN_ROWS_PER_THREAD))
    bounds = np.arange(chunks + 1, dtype=np.int64) * n // chunks
    m = max(int(max_neighbours), 1) + 2  # and the cone's two lines
    neighbour, neighbour_d2 = np.empty((chunks, m), np.int64), np.empty((chunks, m))
    lines, projected = np.empty((chunks, m, 4)), np.empty((chunks, m, 4))
    over_chunks(orca_chunks, chunks, bounds, position, np.ascontiguousarray(velocity, np.float64),
                np.ascontiguousarray(preferred, np.float64),
                np.ascontiguousarray(radius, np.float64),
                np.ascontiguousarray(stride_m, np.float64),
                np.ascontiguousarray(feet_m, np.float64), legs,
                np.ascontiguousarray(max_speed, np.float64),
                np.ascontiguousarray(min_speed, np.float64),
                np.ascontiguousarray(facing, np.float64),
                np.ascontiguousarray(active, np.bool_), float(range_m), float(time_horizon_s),
                float(dt), min(float(cone_rad), math.pi), float(cell_m), mask, start, order,
                sorted_xy, sorted_cell, neighbour, neighbour_d2, lines, projected, out,
                rows_per_thread=1)
    return out
