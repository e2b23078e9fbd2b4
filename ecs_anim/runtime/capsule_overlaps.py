"""The numpy references of :mod:`ecs_anim.runtime.kernels.capsules`' calls (CollisionSeparate
runs them while the kernels compile aside on a first run; the tests compare them to 1e-9 m):
:func:`capsules` (every character's capsules and bounds), :func:`overlaps` (each
character's deepest overlap with another) and :func:`near_rows`. All characters at once: no
grid, the pairs whose bounds meet found from every pair's bounds (``(k, n)`` of them), then
every capsule pair of those at once."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.capsules import Capsules, Overlaps
from ecs_anim.solver.capsules import capsules_from_positions, closest_between_segments

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


def capsules(positions: F64, lengths: F64, out: Capsules, rows: I64 | None = None) -> Capsules:
    """:func:`ecs_anim.runtime.kernels.capsules.capsules` in numpy: the capsules of ``rows``
    (k,) (None: every character) from ``positions`` (n, N_JOINTS, 3) and ``lengths``
    (n, N_LENGTHS), written into ``out`` (the others' kept)."""
    rows = np.arange(positions.shape[0], dtype=np.int64) if rows is None else rows
    ends, radii = capsules_from_positions(positions[rows], lengths[rows])  # (k, C, 2, 3), (k, C)
    centre = positions[rows, 0]
    low = (ends - radii[..., None, None]).min(axis=2)  # (k, C, 3)
    high = (ends + radii[..., None, None]).max(axis=2)
    out.ends[rows], out.radii[rows], out.centre[rows] = ends, radii, centre
    out.capsule_box[rows] = np.stack([low, high], axis=2)
    out.box[rows] = np.stack([low.min(axis=1), high.max(axis=1)], axis=1)
    return out


#: Characters whose bounds are compared with everyone's together (memory: n bytes x 12 each).
ROWS_PER_BLOCK = 512


def meeting(body: Capsules, rows: I64) -> NDArray[np.bool_]:
    """(k, n) whether each of ``rows``' bounds meets each character's (itself excluded); bounds
    not finite (a body frozen or not yet posed) meet, as in the kernel (no test fails).
    :data:`ROWS_PER_BLOCK` rows at a time."""
    meet = np.empty((rows.size, body.box.shape[0]), bool)
    low, high = body.box[None, :, 0], body.box[None, :, 1]  # (1, n, 3) each
    for lo in range(0, rows.size, ROWS_PER_BLOCK):
        a = body.box[rows[lo:lo + ROWS_PER_BLOCK], None]  # (b, 1, 2, 3)
        apart = ((a[..., 1, :] < low) | (high < a[..., 0, :])).any(axis=-1)
        meet[lo:lo + ROWS_PER_BLOCK] = ~apart
    meet[np.arange(rows.size), rows] = False
    return meet


#: Pairs of characters whose capsule pairs are looked at together (memory: each pair's
#: C x C capsule pairs' nearest points, about 10 KB).
PAIRS_PER_BLOCK = 1024


def overlaps(body: Capsules, rows: I64 | None = None, out: Overlaps | None = None) -> Overlaps:
    """:func:`ecs_anim.runtime.kernels.capsules.overlaps` in numpy: each of ``rows``' (None:
    every character's) deepest overlap with another character, into ``out`` (new if None; the
    other rows' kept): of every pair of characters whose bounds meet, every pair of capsules,
    the nearest points of their axes (:data:`PAIRS_PER_BLOCK` pairs of characters at a time)."""
    n = body.radii.shape[0]
    if out is None:
        out = Overlaps.none(n)
    if n < 2:
        return out
    rows = np.arange(n, dtype=np.int64) if rows is None else rows
    depth, other, mine, theirs, normal, point = out
    depth[rows], other[rows], mine[rows], theirs[rows] = 0.0, -1, -1, -1
    normal[rows], point[rows] = 0.0, 0.0
    pair_row, j = np.nonzero(meeting(body, rows))
    if pair_row.size == 0:
        return out
    i = rows[pair_row]
    c = body.radii.shape[1]
    best = np.empty(i.size, np.int64)  # each pair's first deepest capsule pair (ki * C + kj)
    deepest = np.empty(i.size)
    for lo in range(0, i.size, PAIRS_PER_BLOCK):
        block = slice(lo, lo + PAIRS_PER_BLOCK)
        d = _depths(body, i[block], j[block]).reshape(-1, c * c)
        best[block] = np.argmax(d, axis=1)
        deepest[block] = d[np.arange(d.shape[0]), best[block]]
    # each row's deepest pair of characters (the first found of equal ones), if it overlaps
    order = np.lexsort((-deepest, pair_row))
    first = order[np.r_[True, pair_row[order][1:] != pair_row[order][:-1]]]
    first = first[deepest[first] > 0.0]
    r, them, ki, kj = i[first], j[first], best[first] // c, best[first] % c
    on_i, on_j = closest_between_segments(body.ends[r, ki, 0], body.ends[r, ki, 1],
                                          body.ends[them, kj, 0], body.ends[them, kj, 1])
    gap = on_i - on_j
    dist = np.linalg.norm(gap, axis=-1)
    depth[r], other[r], mine[r], theirs[r] = deepest[first], them, ki, kj
    flat = body.centre[r, :2] - body.centre[them, :2]
    h = np.hypot(flat[:, 0], flat[:, 1])
    sideways = np.where((h > 1e-9)[:, None],
                        np.column_stack([flat / np.maximum(h, 1e-300)[:, None], np.zeros(h.size)]),
                        np.array([1.0, 0.0, 0.0]))
    way = gap / np.maximum(dist, 1e-300)[:, None]
    normal[r] = np.where((dist > 1e-9)[:, None], way, sideways)  # axes crossing: horizontally
    point[r] = on_i
    return out


def _depths(body: Capsules, i: I64, j: I64) -> F64:
    """(p, C, C) how deep each capsule of character ``i`` (p,) is in each of ``j``'s (the sum
    of their radii less their axes' distance; -inf where not finite)."""
    ends_i = body.ends[i][:, :, None]  # (p, C, 1, 2, 3)
    ends_j = body.ends[j][:, None, :]  # (p, 1, C, 2, 3)
    on_i, on_j = closest_between_segments(ends_i[..., 0, :], ends_i[..., 1, :],
                                          ends_j[..., 0, :], ends_j[..., 1, :])  # (p, C, C, 3)
    d = body.radii[i][:, :, None] + body.radii[j][:, None, :] \
        - np.linalg.norm(on_i - on_j, axis=-1)
    depths: F64 = np.where(np.isnan(d), -np.inf, d)
    return depths


def near_rows(body: Capsules, rows: I64) -> I64:
    """:func:`ecs_anim.runtime.kernels.capsules.near_rows` in numpy: the characters other than
    ``rows`` (k,) whose bounds meet one of theirs."""
    near: NDArray[np.bool_] = np.asarray(meeting(body, rows).any(axis=0))
    near[rows] = False
    found: I64 = np.flatnonzero(near)
    return found
