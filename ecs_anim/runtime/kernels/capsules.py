"""Collision capsules and the deepest overlap between characters, compiled (CollisionSeparate).

:func:`capsule_rows` mirrors :func:`ecs_anim.solver.capsules.capsules_from_positions` (same
results to 1e-9 m) and adds each character's bounding sphere and bounds, and each capsule's
bounds; :func:`overlap_rows` finds, for each character, the deepest overlap of one of its
capsules with a capsule of another character: neighbours on a uniform grid
(:func:`build_cells`: its cells column by column where the crowd's extent allows, else hashed
into a table as the steering avoidance's), each looking at the 3 x 3 cells about its own (a
cell as wide as two bodies' bounds reach sideways), every capsule pair of two characters
whose bounds meet (each capsule first against the other body's bounds, then against the other
capsule's) tested by the nearest points of their axes (Ericson, Real-Time Collision Detection,
5.1.9;
:func:`ecs_anim.solver.capsules.closest_between_segments`). :func:`overlaps` is the
numpy-facing call. :func:`touching` finds first, on the same grid, the bodies whose bounds meet
another's (bounds from the joints, no capsule made: :func:`bounds`): only those can overlap
anyone, so their capsules are made for them alone and only they are searched.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.avoidance import cell_hash, sort_by_slot, table_mask
from ecs_anim.runtime.kernels.vec import F64, Vec3, add_scaled, dot, jit, load3, norm, sub
from ecs_anim.solver.capsules import CAPSULE_JOINTS, CAPSULE_SPAN, N_CAPSULES, RADIUS_WEIGHTS

I64 = NDArray[np.int64]

#: (C, 3) per capsule the lengths its radius weighs (:data:`~ecs_anim.solver.capsules.
#: RADIUS_WEIGHTS`' non-zero columns, in order; -1: none): three terms a capsule, not a row of
#: every length (that loop was most of a body's capsules' cost).
RADIUS_TERMS = np.full((N_CAPSULES, 3), -1, np.int64)
for _k, _row in enumerate(RADIUS_WEIGHTS):
    RADIUS_TERMS[_k, :np.count_nonzero(_row)] = np.flatnonzero(_row)
#: :data:`RADIUS_TERMS` with every term a length (the first where there is none) and its weight
#: (0 there): each radius as three products, no test (:func:`bound_rows`).
WIDEST_TERMS = np.maximum(RADIUS_TERMS, 0)
WIDEST_WEIGHTS = np.where(RADIUS_TERMS >= 0, np.take_along_axis(RADIUS_WEIGHTS, WIDEST_TERMS, 1),
                          0.0)


@jit(nogil=True)
def capsule_rows(lo: int, hi: int, rows: I64, positions: F64, lengths: F64, joints: I64,
                 span: F64, radius_weights: F64, radius_terms: I64, ends: F64, radii: F64,
                 centre: F64, box: F64, capsule_box: F64) -> None:
    """Capsules of characters ``rows[lo:hi]``: ``ends`` (n, C, 2, 3) and ``radii`` (n, C) written
    from ``positions`` (n, N_JOINTS, 3) and ``lengths`` (n, N_LENGTHS) (``joints`` (C, 2),
    ``span`` (C, 2), ``radius_weights`` (C, N_LENGTHS): :mod:`ecs_anim.solver.capsules`'s
    layout, ``radius_terms`` (C, 3) :data:`RADIUS_TERMS`); ``centre`` (n, 3) the pelvis,
    ``box`` (n, 2, 3) the body's bounds (lowest, highest corner) and ``capsule_box``
    (n, C, 2, 3) each capsule's. Mirrors
    :func:`ecs_anim.solver.capsules.capsules_from_positions`."""
    n_caps, n_terms = joints.shape[0], radius_terms.shape[1]
    for row in range(lo, hi):
        c = rows[row]
        for x in range(3):
            box[c, 0, x], box[c, 1, x] = math.inf, -math.inf
        for k in range(n_caps):
            a = load3(positions[c, joints[k, 0]])
            ab = sub(load3(positions[c, joints[k, 1]]), a)
            r = 0.0
            for t in range(n_terms):
                m = radius_terms[k, t]
                if m >= 0:
                    r += lengths[c, m] * radius_weights[k, m]
            radii[c, k] = r
            low = (math.inf, math.inf, math.inf)
            high = (-math.inf, -math.inf, -math.inf)
            for e in range(2):
                p = add_scaled(a, ab, span[k, e])
                ends[c, k, e, 0], ends[c, k, e, 1], ends[c, k, e, 2] = p
                low = (min(low[0], p[0] - r), min(low[1], p[1] - r), min(low[2], p[2] - r))
                high = (max(high[0], p[0] + r), max(high[1], p[1] + r), max(high[2], p[2] + r))
            for x in range(3):
                box[c, 0, x] = min(box[c, 0, x], low[x])
                box[c, 1, x] = max(box[c, 1, x], high[x])
                capsule_box[c, k, 0, x], capsule_box[c, k, 1, x] = low[x], high[x]
        centre[c, 0], centre[c, 1], centre[c, 2] = load3(positions[c, 0])


#: How far (m) :func:`bound_rows`' bounds reach past every joint besides the widest radius: a
#: capsule's far end, ``a + (b - a) * 1``, may lie a rounding past its joint ``b``.
BOUND_HAIR_M = 1e-9


@jit(inline="always")
def _widest_radius(lengths: F64, c: int, k: int) -> float:
    """Capsule ``k``'s radius on row ``c`` of ``lengths`` as :func:`bound_rows` widens by it
    (:data:`WIDEST_TERMS`, :data:`WIDEST_WEIGHTS`), m."""
    radius: float = (lengths[c, WIDEST_TERMS[k, 0]] * WIDEST_WEIGHTS[k, 0]
                     + lengths[c, WIDEST_TERMS[k, 1]] * WIDEST_WEIGHTS[k, 1]
                     + lengths[c, WIDEST_TERMS[k, 2]] * WIDEST_WEIGHTS[k, 2])
    return radius


@jit(nogil=True)
def bound_rows(lo: int, hi: int, positions: F64, lengths: F64, centre: F64, box: F64) -> None:
    """Bounds of characters ``lo..hi-1`` that hold every capsule without making one (the broad
    phase's, :func:`touching`): ``box`` (n, 2, 3) the lowest and highest corner of every joint
    of ``positions`` (n, N_JOINTS, 3) widened by the body's widest capsule radius (from
    ``lengths`` (n, N_LENGTHS): :data:`WIDEST_TERMS`, :data:`WIDEST_WEIGHTS`, constants of the
    compiled code: each length's column known, not read from a table) and
    :data:`BOUND_HAIR_M` (each capsule's axis lies between two joints); ``centre`` (n, 3) the
    pelvis. One contiguous pass over each body's joints, no capsule made.

    The joints are taken two at a time and the radii two capsules at a time, each its own
    running least or most, folded at the end (not one chain of compares through a body's 22
    joints and 13 radii: two chains half as long, side by side). The
    same bits as one chain: every running value starts at an infinity or 0 and a NaN never
    replaces one (``min(a, v)`` keeps ``a`` unless ``v < a``), so each is the least (most) of
    the values not NaN in any order; a zero's sign, which the order could choose, is gone once
    the radius is added."""
    n_joints = positions.shape[1]
    for c in range(lo, hi):
        widest_even = widest_odd = 0.0
        for k in range(0, N_CAPSULES, 2):
            widest_even = max(widest_even, _widest_radius(lengths, c, k))
        for k in range(1, N_CAPSULES, 2):
            widest_odd = max(widest_odd, _widest_radius(lengths, c, k))
        widest = max(widest_even, widest_odd) + BOUND_HAIR_M
        even_low_x = even_low_y = even_low_z = odd_low_x = odd_low_y = odd_low_z = math.inf
        even_high_x = even_high_y = even_high_z = -math.inf
        odd_high_x = odd_high_y = odd_high_z = -math.inf
        for j in range(0, n_joints, 2):
            x, y, z = positions[c, j, 0], positions[c, j, 1], positions[c, j, 2]
            even_low_x, even_low_y, even_low_z = min(even_low_x, x), min(even_low_y, y), \
                min(even_low_z, z)
            even_high_x, even_high_y, even_high_z = max(even_high_x, x), max(even_high_y, y), \
                max(even_high_z, z)
            odd = min(j + 1, n_joints - 1)  # (an odd count's last joint twice: the same bounds)
            x, y, z = positions[c, odd, 0], positions[c, odd, 1], positions[c, odd, 2]
            odd_low_x, odd_low_y, odd_low_z = min(odd_low_x, x), min(odd_low_y, y), \
                min(odd_low_z, z)
            odd_high_x, odd_high_y, odd_high_z = max(odd_high_x, x), max(odd_high_y, y), \
                max(odd_high_z, z)
        box[c, 0, 0] = min(even_low_x, odd_low_x) - widest
        box[c, 0, 1] = min(even_low_y, odd_low_y) - widest
        box[c, 0, 2] = min(even_low_z, odd_low_z) - widest
        box[c, 1, 0] = max(even_high_x, odd_high_x) + widest
        box[c, 1, 1] = max(even_high_y, odd_high_y) + widest
        box[c, 1, 2] = max(even_high_z, odd_high_z) + widest
        centre[c, 0], centre[c, 1], centre[c, 2] = positions[c, 0, 0], positions[c, 0, 1], \
            positions[c, 0, 2]


@jit(inline="always")
def cell_slot(ix: int, iy: int, mask: int, origin_x: int, origin_y: int,
              column_cells: int) -> int:
    """The slot of grid cell ``(ix, iy)`` (:func:`build_cells`): where the cells are laid out
    column by column (``column_cells`` > 0 cells a column, the first cell
    ``(origin_x, origin_y)``),
    its place there, a column's cells side by side and the next column's after them (the
    cells ``x + 1`` of a cell's neighbours in one run: the searches read them in order); else
    (``column_cells`` 0) hashed into a table of ``mask + 1`` slots
    (:func:`~.avoidance.cell_hash`)."""
    if column_cells > 0:
        return (ix - origin_x) * column_cells + (iy - origin_y)
    return cell_hash(ix, iy, mask)


@jit(nogil=True)
def build_cells(plane: F64, cell_m: float, mask: int, slot: I64, start: I64,
                order: I64) -> tuple[int, int, int]:
    """Sort the bodies by grid cell (cells ``cell_m`` wide, ``plane`` (n, 2) the centres):
    ``slot`` (n,), ``start`` (mask + 2,) and ``order`` (n,) written as
    :func:`~.avoidance.build_grid` writes them, the slots those of :func:`cell_slot`. Returns
    ``(origin_x, origin_y, column_cells)``: the cells laid out column by column, each cell's
    eight neighbours within, where they fit in the ``mask + 1`` slots (a crowd no wider than
    the table, the bench's: 2,000 cells for 8,192 slots), else ``column_cells`` 0: hashed (a
    crowd spread far, or a body not yet posed: :func:`plane_and_spread` puts those 1 km
    apart)."""
    low_x = low_y = math.inf
    high_x = high_y = -math.inf
    for i in range(plane.shape[0]):
        x, y = np.floor(plane[i, 0] / cell_m), np.floor(plane[i, 1] / cell_m)
        low_x, high_x = min(low_x, x), max(high_x, x)
        low_y, high_y = min(low_y, y), max(high_y, y)
    # A ring of empty cells about the crowd's (every body's neighbours have a place), decided
    # before a cell is an integer: a crowd far out (a cell past 2^52) or too wide is hashed,
    # never a product or an offset wrapped round.
    n_columns, n_cells_a_column = high_x - low_x + 3.0, high_y - low_y + 3.0
    origin_x = origin_y = column_cells = 0
    if (max(abs(low_x), abs(high_x), abs(low_y), abs(high_y)) < 2.0 ** 52
            and n_columns * n_cells_a_column <= mask + 1):
        origin_x, origin_y = int(low_x) - 1, int(low_y) - 1
        column_cells = int(n_cells_a_column)
    for i in range(plane.shape[0]):
        slot[i] = cell_slot(math.floor(plane[i, 0] / cell_m), math.floor(plane[i, 1] / cell_m),
                            mask, origin_x, origin_y, column_cells)
    sort_by_slot(slot, start, order)
    return origin_x, origin_y, column_cells


@jit()
def closest_between(p1: Vec3, q1: Vec3, p2: Vec3, q2: Vec3) -> tuple[Vec3, Vec3]:
    """Mirrors :func:`ecs_anim.solver.capsules.closest_between_segments` for one pair."""
    d1, d2, r = sub(q1, p1), sub(q2, p2), sub(p1, p2)
    a, e, f = dot(d1, d1), dot(d2, d2), dot(d2, r)
    c, b = dot(d1, r), dot(d1, d2)
    denom = a * e - b * b
    s = min(max((b * f - c * e) / max(denom, 1e-18), 0.0), 1.0) if denom > 1e-18 else 0.0
    if not a > 1e-18:
        s = 0.0
    t = (b * s + f) / max(e, 1e-18) if e > 1e-18 else 0.0
    t_clamped = min(max(t, 0.0), 1.0)
    if t != t_clamped and a > 1e-18:
        s = min(max((t_clamped * b - c) / max(a, 1e-18), 0.0), 1.0)
    return add_scaled(p1, d1, s), add_scaled(p2, d2, t_clamped)


@jit(inline="always")
def _apart(a: F64, b: F64) -> bool:
    """Whether the bounds ``a`` and ``b`` (2, 3: lowest, highest corner) do not meet (the six
    tests at once, one branch: mostly they do not, and a branch a test mispredicted half the
    search's time)."""
    return bool((a[1, 0] < b[0, 0]) | (b[1, 0] < a[0, 0]) | (a[1, 1] < b[0, 1])
                | (b[1, 1] < a[0, 1]) | (a[1, 2] < b[0, 2]) | (b[1, 2] < a[0, 2]))


@jit(inline="always")
def _gap(a: F64, b: F64, radius_a: float, radius_b: float) -> float:
    """How far apart (m) at least the axes of two capsules lie whose bounds are ``a`` and ``b``
    (2, 3), their radii ``radius_a`` and ``radius_b`` (the bounds of their axes' apart; less a
    hair for rounding)."""
    gap = 0.0
    for x in range(3):
        d = max(b[0, x] + radius_b - (a[1, x] - radius_a),
                a[0, x] + radius_a - (b[1, x] - radius_b), 0.0)
        gap += d * d
    return math.sqrt(gap) - 1e-9


@jit(nogil=True)
def overlap_rows(lo: int, hi: int, rows: I64, ends: F64, radii: F64, centre: F64, box: F64,
                 capsule_box: F64, plane: F64, cell_m: float, mask: int, origin_x: int,
                 origin_y: int, column_cells: int, start: I64, order: I64, depth: F64,
                 other: I64, mine: I64, theirs: I64, normal: F64, point: F64) -> None:
    """For each character ``i`` in ``rows[lo:hi]``, its deepest overlap with another character:
    ``depth[i]`` m (0: none), ``other[i]`` that character's row (-1: none), ``mine[i]`` and
    ``theirs[i]`` the two capsules, ``normal[i]`` (3,) the unit way out for ``i`` (from their
    axis toward its own), ``point[i]`` (3,) the nearest point of its own capsule's axis.
    ``plane`` (n, 2) the bodies' centres on the grid (built on it with cells ``cell_m`` wide:
    ``mask``, ``origin_x``, ``origin_y``, ``column_cells``, ``start``, ``order`` as
    :func:`build_cells`). Only bodies whose bounds
    ``box`` (n, 2, 3) meet are looked at further, and of those only the capsules whose bounds
    ``capsule_box`` (n, C, 2, 3) meet the other body's, then each other's, are tested."""
    n_caps = ends.shape[1]
    for row in range(lo, hi):
        i = rows[row]
        depth[i], other[i], mine[i], theirs[i] = 0.0, -1, -1, -1
        normal[i, 0], normal[i, 1], normal[i, 2] = 0.0, 0.0, 0.0
        point[i, 0], point[i, 1], point[i, 2] = 0.0, 0.0, 0.0
        ix, iy = math.floor(plane[i, 0] / cell_m), math.floor(plane[i, 1] / cell_m)
        box_i = box[i]
        for cell in range(9):
            s = cell_slot(ix + cell // 3 - 1, iy + cell % 3 - 1, mask, origin_x, origin_y,
                          column_cells)
            repeated = False
            for earlier in range(cell):
                repeated = repeated or s == cell_slot(ix + earlier // 3 - 1,
                                                      iy + earlier % 3 - 1, mask, origin_x,
                                                      origin_y, column_cells)
            if repeated:
                continue
            for a in range(start[s], start[s + 1]):
                j = order[a]
                if j == i or _apart(box_i, box[j]):
                    continue
                # j's capsules within i's bounds (bits of ``near``): the only ones any of i's
                # can reach
                near = 0
                for kj in range(n_caps):
                    if not _apart(capsule_box[j, kj], box_i):
                        near |= 1 << kj
                if near == 0:
                    continue
                for ki in range(n_caps):
                    box_ki = capsule_box[i, ki]
                    if _apart(box_ki, box[j]):
                        continue  # (two walkers side by side: most of their capsule pairs)
                    p1, q1 = load3(ends[i, ki, 0]), load3(ends[i, ki, 1])
                    for kj in range(n_caps):
                        if not (near >> kj) & 1 or _apart(box_ki, capsule_box[j, kj]) \
                                or _gap(box_ki, capsule_box[j, kj], radii[i, ki],
                                        radii[j, kj]) > radii[i, ki] + radii[j, kj] - depth[i]:
                            continue  # (its axes too far apart to be deeper than one found)
                        p2, q2 = load3(ends[j, kj, 0]), load3(ends[j, kj, 1])
                        on_i, on_j = closest_between(p1, q1, p2, q2)
                        gap = sub(on_i, on_j)
                        distance = norm(gap)
                        d = radii[i, ki] + radii[j, kj] - distance
                        if d > depth[i]:
                            depth[i], other[i], mine[i], theirs[i] = d, j, ki, kj
                            if distance > 1e-9:
                                way = (gap[0] / distance, gap[1] / distance, gap[2] / distance)
                            else:  # axes crossing: out horizontally, from their centre
                                flat = sub(load3(centre[i]), load3(centre[j]))
                                h = math.sqrt(flat[0] * flat[0] + flat[1] * flat[1])
                                way = (flat[0] / h, flat[1] / h, 0.0) if h > 1e-9 \
                                    else (1.0, 0.0, 0.0)
                            normal[i, 0], normal[i, 1], normal[i, 2] = way
                            point[i, 0], point[i, 1], point[i, 2] = on_i


@jit(nogil=True)
def near_kernel(rows: I64, box: F64, plane: F64, cell_m: float, mask: int, origin_x: int,
                origin_y: int, column_cells: int, start: I64, order: I64,
                near: NDArray[np.bool_]) -> None:
    """Mark ``near[j]`` (n,) for every other character ``j`` whose bounds ``box`` (n, 2, 3)
    meet those of one of ``rows`` (on the grid as :func:`overlap_rows`'s)."""
    for row in range(rows.size):
        i = rows[row]
        ix, iy = math.floor(plane[i, 0] / cell_m), math.floor(plane[i, 1] / cell_m)
        for cell in range(9):
            s = cell_slot(ix + cell // 3 - 1, iy + cell % 3 - 1, mask, origin_x, origin_y,
                          column_cells)
            for a in range(start[s], start[s + 1]):
                j = order[a]
                if j != i and not _apart(box[i], box[j]):
                    near[j] = True


#: The grid cells a search about a body's cell looks at besides its own, for a pair met once
#: (:func:`touching_kernel`): the four after it (the other four are the cells before theirs).
_FORWARD_CELLS = ((1, -1), (1, 0), (1, 1), (0, 1))


@jit(nogil=True)
def touching_kernel(box: F64, plane: F64, cell_m: float, mask: int, origin_x: int,
                    origin_y: int, column_cells: int, start: I64, order: I64,
                    box_in_order: F64, touching: NDArray[np.bool_], clearance: F64, gaps: bool) -> None:
    """Mark ``touching[i]`` (n,) for every character whose bounds ``box`` (n, 2, 3) meet
    another's (on the grid as :func:`overlap_rows`'s). Each pair is met once: in a body's own
    slot, with the bodies after it there; in the four cells after its own
    (:data:`_FORWARD_CELLS`), with every body (half the cells :func:`near_kernel` looks at; a
    slot two cells share is looked at twice, which marks nothing more). The bounds are read in
    the grid's order (copied first into ``box_in_order`` (n, 2, 3): a slot's bodies side by
    side; with the cells laid out by column, :func:`build_cells`, the next column's three
    cells too, one run of it: half the pass's time at 4,000 where hashed slots lay anywhere).
    Laid out by column, the bodies are walked in order with their slot, two runs a body (its
    slot's later bodies and the next cell up's; the next column's three cells), no centre read;
    hashed, each body's cell is found from its centre and the four cells' slots made once for
    the bodies of one cell in a row.
    ``clearance`` (n,), given as the least gap of two bodies in cells not side by side, is
    lowered to each body's least gap (m: the largest of the three axes' gaps between two
    bounds) to a body met whose bounds do not meet its own, if ``gaps`` (else not read nor
    written: the gaps were a third of the pass)."""
    n = order.shape[0]
    for a in range(n):
        i = order[a]
        for e in range(2):
            for x in range(3):
                box_in_order[a, e, x] = box[i, e, x]
    if column_cells > 0:
        # Laid out by column, a body's slot is its cell: its own slot's later bodies and the
        # next cell up (the slot after) are one run, the next column's three cells another; no
        # cell made from a centre. (A body's cell lies inside the ring of empty cells: both
        # runs end within the table.)
        s = 0
        for a in range(n):
            while start[s + 1] <= a:  # (the slots up to the last body's only)
                s += 1
            i = order[a]
            box_i = box_in_order[a]
            for b in range(a + 1, start[s + 2]):
                _meet(box_i, box_in_order[b], i, order[b], touching, clearance, gaps)
            for b in range(start[s + column_cells - 1], start[s + column_cells + 2]):
                _meet(box_i, box_in_order[b], i, order[b], touching, clearance, gaps)
        return
    last_x, last_y = 0, 0
    forward = (-1, -1, -1, -1)
    for a in range(n):
        i = order[a]
        box_i = box_in_order[a]
        ix, iy = math.floor(plane[i, 0] / cell_m), math.floor(plane[i, 1] / cell_m)
        own = cell_slot(ix, iy, mask, origin_x, origin_y, column_cells)
        for b in range(a + 1, start[own + 1]):
            _meet(box_i, box_in_order[b], i, order[b], touching, clearance, gaps)
        if a == 0 or ix != last_x or iy != last_y:
            last_x, last_y = ix, iy
            forward = (
                cell_slot(ix + _FORWARD_CELLS[0][0], iy + _FORWARD_CELLS[0][1], mask, origin_x,
                          origin_y, column_cells),
                cell_slot(ix + _FORWARD_CELLS[1][0], iy + _FORWARD_CELLS[1][1], mask, origin_x,
                          origin_y, column_cells),
                cell_slot(ix + _FORWARD_CELLS[2][0], iy + _FORWARD_CELLS[2][1], mask, origin_x,
                          origin_y, column_cells),
                cell_slot(ix + _FORWARD_CELLS[3][0], iy + _FORWARD_CELLS[3][1], mask, origin_x,
                          origin_y, column_cells))
        for s in forward:
            if s == own:
                continue  # (its bodies met above)
            for b in range(start[s], start[s + 1]):
                _meet(box_i, box_in_order[b], i, order[b], touching, clearance, gaps)


@jit(inline="always")
def _meet(box_i: F64, box_j: F64, i: int, j: int, touching: NDArray[np.bool_],
          clearance: F64, gaps: bool) -> None:
    """:func:`touching_kernel`'s test of bodies ``i`` and ``j`` (bounds ``box_i``, ``box_j``
    (2, 3)): both marked if their bounds meet, else (with ``gaps``) each one's clearance
    lowered to their gap."""
    if not _apart(box_i, box_j):
        touching[i] = touching[j] = True
        return
    if not gaps:
        return
    gap = 0.0
    for x in range(3):
        gap = max(gap, box_j[0, x] - box_i[1, x], box_i[0, x] - box_j[1, x])
    clearance[i] = min(clearance[i], gap)
    clearance[j] = min(clearance[j], gap)


@jit(nogil=True)
def drifted(box: F64, since: F64, slack: F64) -> bool:
    """Whether any body's bounds ``box`` (n, 2, 3) moved (a corner, along an axis) by its
    ``slack`` (n,) m or more from ``since`` (n, 2, 3), or are not finite. While none has, two
    bounds apart by both bodies' slacks twice then still are (each moved less than half)."""
    for c in range(box.shape[0]):
        for e in range(2):
            for x in range(3):
                if not abs(box[c, e, x] - since[c, e, x]) < slack[c]:
                    return True
    return False


@jit(nogil=True)
def plane_and_spread(centre: F64, box: F64, plane: F64) -> float:
    """Write ``plane`` (n, 2), each body's centre (n, 3) on the grid (a frozen or not yet posed
    body's, not finite: far away from everyone, 1 km apart in the order of the rows); returns
    how far sideways (x or y) the bounds ``box`` (n, 2, 3) reach from their centres at most,
    over the bodies whose reach is finite (0: none)."""
    far, widest = 0, 0.0
    for i in range(centre.shape[0]):
        x, y = centre[i, 0], centre[i, 1]
        if math.isfinite(x) and math.isfinite(y):
            plane[i, 0], plane[i, 1] = x, y
        else:
            plane[i, 0] = plane[i, 1] = 1e9 + far * 1e3
            far += 1
        spread = 0.0
        finite = True
        for corner in range(2):
            for axis in range(2):
                d = abs(box[i, corner, axis] - centre[i, axis])
                finite = finite and math.isfinite(d)
                spread = max(spread, d)
        if finite:
            widest = max(widest, spread)
    return widest


class Capsules(NamedTuple):
    """Every character's capsules (:func:`capsules`): ends (n, C, 2, 3) m, radii (n, C) m,
    centre (n, 3) the pelvis, box (n, 2, 3) the body's bounds (lowest, highest corner), m,
    capsule_box (n, C, 2, 3) each capsule's (written only for the bodies asked)."""

    ends: F64
    radii: F64
    centre: F64
    box: F64
    capsule_box: F64

    @staticmethod
    def empty(n: int) -> Capsules:
        """Arrays for ``n`` characters' capsules, to be written."""
        return Capsules(np.empty((n, N_CAPSULES, 2, 3)), np.empty((n, N_CAPSULES)),
                        np.empty((n, 3)), np.empty((n, 2, 3)), np.empty((n, N_CAPSULES, 2, 3)))


class Overlaps(NamedTuple):
    """Each character's deepest overlap with another (:func:`overlaps`; see
    :func:`overlap_rows`): depth (n,) m, other (n,) row or -1, mine, theirs (n,) capsules,
    normal (n, 3) unit way out, point (n, 3) on its own capsule's axis."""

    depth: F64
    other: I64
    mine: I64
    theirs: I64
    normal: F64
    point: F64

    @staticmethod
    def none(n: int) -> Overlaps:
        """``n`` characters overlapping no one (depth 0, rows and capsules -1)."""
        return Overlaps(np.zeros(n), np.full(n, -1, np.int64), np.full(n, -1, np.int64),
                        np.full(n, -1, np.int64), np.zeros((n, 3)), np.zeros((n, 3)))


class Grid(NamedTuple):
    """The bodies sorted by cell of a uniform grid (:func:`grid_of`): ``plane`` (n, 2) each
    body's centre on it, cells ``cell_m`` wide, ``mask``, ``origin_x``, ``origin_y``,
    ``column_cells`` (the cells' layout: :func:`cell_slot`), ``start``, ``order`` as
    :func:`build_cells` makes them."""

    plane: F64
    cell_m: float
    mask: int
    origin_x: int
    origin_y: int
    column_cells: int
    start: I64
    order: I64


def capsules(positions: F64, lengths: F64, out: Capsules | None = None,
             rows: I64 | None = None) -> Capsules:
    """Every character's capsules from its posture (n, N_JOINTS, 3) and lengths
    (n, N_LENGTHS), compiled over all of them (``out``: arrays to write, else new; ``rows``:
    only those characters', the others' kept)."""
    n = positions.shape[0]
    if out is None:
        out = Capsules.empty(n)
    rows = np.arange(n, dtype=np.int64) if rows is None else rows
    over_chunks(capsule_rows, rows.size, rows, np.ascontiguousarray(positions, np.float64),
                np.ascontiguousarray(lengths, np.float64), CAPSULE_JOINTS, CAPSULE_SPAN,
                RADIUS_WEIGHTS, RADIUS_TERMS, *out)
    return out


def bounds(positions: F64, lengths: F64, out: Capsules) -> Capsules:
    """Every character's centre and bounds in ``out`` (:func:`bound_rows`: wider than its
    capsules', none of them made; its ends, radii and each capsule's bounds left as they
    are), compiled over all of them: enough for :func:`grid_of` and :func:`touching`, which
    pick the bodies whose capsules are worth making."""
    over_chunks(bound_rows, positions.shape[0], np.ascontiguousarray(positions, np.float64),
                np.ascontiguousarray(lengths, np.float64), out.centre, out.box)
    return out


#: A grid's cells are this many times as wide as two bodies' bounds reach sideways from their
#: centres at most: limbs turned by the rounds may reach a little further before it is built
#: again (:func:`grid_holds`).
CELL_SLACK = 1.25


def _spread(body: Capsules, rows: I64 | slice) -> F64:
    """How far (m, (k,)) each of ``rows``' bounds reach sideways (x or y) from its centre."""
    centre = body.centre[rows, None, :2]
    spread: F64 = np.abs(body.box[rows, :, :2] - centre).max(axis=(1, 2))
    return spread


def grid_of(body: Capsules) -> Grid:
    """The bodies' centres sorted by cell of a grid of cells :data:`CELL_SLACK` times as wide as two
    bodies' bounds reach sideways from their centres: the 3 x 3 cells about a body's own hold
    every body whose bounds can meet its bounds (:func:`grid_holds` tells when that no longer
    holds)."""
    n = body.radii.shape[0]
    plane = np.empty((n, 2))
    cell_m = max(2.0 * CELL_SLACK * plane_and_spread(body.centre, body.box, plane), 0.1)
    mask = table_mask(n)
    slot, order = np.empty(n, np.int64), np.empty(n, np.int64)
    start = np.empty(mask + 2, np.int64)
    origin_x, origin_y, column_cells = build_cells(plane, cell_m, mask, slot, start, order)
    return Grid(plane, cell_m, mask, origin_x, origin_y, column_cells, start, order)


def grid_holds(body: Capsules, grid: Grid, rows: I64) -> bool:
    """Whether ``grid`` still finds every pair that can meet after ``rows`` (k,) moved: each
    one's bounds reach sideways from where it was put on the grid no further than half a cell (two
    bodies' bounds that meet then lie in neighbouring cells)."""
    drift = np.abs(body.centre[rows, :2] - grid.plane[rows]).max(axis=1, initial=0.0)
    return bool(np.all(_spread(body, rows) + drift <= 0.5 * grid.cell_m))


def overlaps(body: Capsules, grid: Grid | None = None, rows: I64 | None = None,
             out: Overlaps | None = None) -> Overlaps:
    """Each character's deepest overlap with another (see :func:`overlap_rows`) on ``grid``
    (:func:`grid_of`, made here if None), over all characters split over the kernels' threads;
    ``rows``: only those characters' found again, into ``out`` (the others' kept)."""
    n = body.radii.shape[0]
    if out is None:
        out = Overlaps.none(n)
    if n < 2:
        return out
    grid = grid_of(body) if grid is None else grid
    rows = np.arange(n, dtype=np.int64) if rows is None else rows
    over_chunks(overlap_rows, rows.size, rows, *body, *grid, *out)
    return out


def near_rows(body: Capsules, grid: Grid, rows: I64) -> I64:
    """The characters other than ``rows`` (k,) whose bounds meet one of theirs, on ``grid``."""
    near = np.zeros(body.radii.shape[0], bool)
    near_kernel(rows, body.box, *grid, near)
    near[rows] = False
    found: I64 = np.flatnonzero(near)
    return found


def touching(body: Capsules, grid: Grid, clearance: F64 | None = None) -> I64:
    """The characters whose bounds meet another's (k,), on ``grid``: the only ones that may
    overlap someone (each capsule's bounds lie within its body's). ``clearance`` (n,): written,
    each body's least gap (m, along the axis the bounds are furthest apart) to the bounds of
    any other body whose bounds do not meet its own (None: no gap is measured)."""
    n = body.radii.shape[0]
    marked = np.zeros(n, bool)
    gaps = clearance is not None
    if clearance is None:
        clearance = np.empty(0)
    else:
        # Bodies in cells not side by side: their centres more than a cell apart along an
        # axis, each one's bounds within half a cell over CELL_SLACK of its centre (grid_of).
        clearance[:] = grid.cell_m * (1.0 - 1.0 / CELL_SLACK)
    touching_kernel(body.box, *grid, np.empty((n, 2, 3)), marked, clearance, gaps)
    found: I64 = np.flatnonzero(marked)
    return found
