"""CollisionSeparate's rounds, compiled over the overlapping rows only.

:func:`turn_rows` mirrors ``CollisionSeparate._turns`` (the turn of the chain a capsule lies in,
and whether it may move) but for the ground: a free leg's turned ankle and toe and the heights
they must keep above the ground are written, and the caller asks the ground about those points
only. :func:`push_rows` mirrors the rest of ``CollisionSeparate._separate`` for the rows that
move: the push kept off the chain's last one (``_deflect``), the fold of a limb (``_fold``), the
limb's turn, the foot of a held leg kept (``_keep_feet``), the new limb frames and the step of
a body with no foot down. Each entry is one row's own (the rows are distinct), so the entries'
order does not matter. A round calls them through :func:`try_rows` (its pairs picked, then
:func:`turn_rows` for both sides of each) and :func:`share_and_push` (each pair's shares, then
:func:`push_rows`), the ground asked between the two: the numpy that gathered and scattered the
entries between the kernels was half a round's cost. The numpy methods of
:class:`ecs_anim.systems.collision_separate.CollisionSeparate` are the reference (same results to 1e-9 m: tests/runtime/kernels/
test_kernels_separate.py).
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ecs_anim.runtime.kernels.decode import distal_frames
from ecs_anim.runtime.kernels.vec import (
    F64,
    Frame,
    Vec3,
    add,
    add_scaled,
    axis_angle,
    cross,
    dot,
    in_frame,
    jit,
    load3,
    load_frame,
    matmul,
    norm,
    normalize,
    quat_from_matrix,
    rotation_toward,
    scale,
    sub,
    to_world,
    transpose,
)

I64 = NDArray[np.int64]
B = NDArray[np.bool_]
IDENTITY: Frame = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


@jit(inline="always")
def _held(pin: F64, aims_at: I64, row: int, limb: int, partner: int) -> bool:
    """Mirrors ``collision_separate.held`` for one limb."""
    return (math.isfinite(pin[row, limb, 0]) and math.isfinite(pin[row, limb, 1])
            and math.isfinite(pin[row, limb, 2]) and aims_at[row, limb] != partner)


@jit()
def _turn(row: int, partner: int, chain: int, at: Vec3, way: Vec3, distance: float,
          positions: F64, pin: F64, aims_at: I64, limb_root: I64, max_turn_rad: float,
          min_lever_m: float) -> tuple[Frame, bool]:
    """The turn of ``row``'s ``chain`` that moves its point ``at`` ``distance`` m along
    ``way``, and whether it can (a limb's; the caller decides a trunk's, a pelvis's and a free
    leg's ground): ``CollisionSeparate._turns`` for one row."""
    if chain >= 4:
        return IDENTITY, False
    root = load3(positions[row, limb_root[chain]])
    arm = sub(at, root)
    if _held(pin, aims_at, row, chain, partner):
        axis = normalize(sub(load3(pin[row, chain]), root))
        rate = dot(cross(axis, arm), way)
        lever = abs(rate) > min_lever_m
        angle = min(max(distance / (rate if lever else math.inf), -max_turn_rad), max_turn_rad)
        return axis_angle(axis, angle), lever
    turn = rotation_toward(arm, add_scaled(arm, way, distance), max_turn_rad, 1.0)
    return turn, norm(arm) > 1e-3


@jit(nogil=True)
def turn_rows(lo: int, hi: int, rows: I64, partner: I64, capsule: I64, at: F64, way: F64,
              distance: F64, positions: F64, lengths: F64, leg_length: F64, pin: F64,
              aims_at: I64, trunk_claimed: B, contact_weight: F64, frozen: B,
              capsule_chain: I64, limb_root: I64, limb_end: I64, toe: I64, ankle_height: I64,
              ball_height_per_leg: float, max_turn_rad: float, min_lever_m: float, can: B,
              feet: F64, clearance: F64, ask_ground: B) -> None:
    """For entries ``lo..hi-1``: whether ``rows[e]``'s chain of ``capsule[e]`` may move its
    point ``at[e]`` (k, 3) ``distance[e]`` m along ``way[e]`` (k, 3), away from ``partner[e]``
    (``can`` (k,) written). A free leg's (``ask_ground[e]``) ankle and toe as the turn leaves
    them, ``feet[e]`` (2, 3), must stay ``clearance[e]`` (2,) m above the ground: the caller
    checks (``CollisionSeparate._foot_clear``). ``positions`` (n, N_JOINTS, 3), ``lengths``
    (n, N_LENGTHS), ``leg_length`` (n,) m, ``pin`` (n, 4, 3), ``aims_at`` (n, 4),
    ``trunk_claimed`` (n,), ``contact_weight`` (n, 2), ``frozen`` (n,): the store's and the
    claims' (``CollisionSeparate.Claims``); the rest the module's constants."""
    for e in range(lo, hi):
        r, chain = rows[e], capsule_chain[capsule[e]]
        ask_ground[e] = False
        turn, ok = _turn(r, partner[e], chain, load3(at[e]), load3(way[e]), distance[e],
                         positions, pin, aims_at, limb_root, max_turn_rad, min_lever_m)
        if chain < 2 and not _held(pin, aims_at, r, chain, partner[e]):
            hip = load3(positions[r, limb_root[chain]])
            for k, joint in enumerate((limb_end[chain], toe[chain])):
                p = add(hip, to_world(turn, sub(load3(positions[r, joint]), hip)))
                feet[e, k, 0], feet[e, k, 1], feet[e, k, 2] = p
            clearance[e, 0] = lengths[r, ankle_height[chain]]
            clearance[e, 1] = ball_height_per_leg * leg_length[r]
            ask_ground[e] = True
        if chain == 5:
            ok = not trunk_claimed[r] and not (contact_weight[r, 0] > 0.0
                                               or contact_weight[r, 1] > 0.0)
        can[e] = ok and not frozen[r]


@jit(nogil=True)
def push_rows(lo: int, hi: int, rows: I64, partner: I64, capsule: I64, at: F64, way: F64,
              distance: F64, positions: F64, lengths: F64, leg_length: F64, pin: F64,
              aims_at: I64, frozen: B, pushed_way: F64, pushed_chain: I64, pelvis2world: F64,
              thorax2world: F64, leg2world: F64, arm2world: F64, leg_fraction: F64,
              arm_fraction: F64, leg_frame: F64, arm_frame: F64, foot_dir: F64,
              root_position: F64, capsule_chain: I64, distal: B, limb_root: I64,
              limb_middle: I64, limb_end: I64, limb_segments: I64, max_turn_rad: float, min_lever_m: float,
              max_deflection: float, min_fold_share: float, max_reach_share: float) -> None:
    """Move ``rows[e]``'s chain of ``capsule[e]`` for entries ``lo..hi-1``: its point
    ``at[e]`` (k, 3) ``distance[e]`` m along ``way[e]`` (k, 3), away from ``partner[e]``.
    The push keeps off the chain's last one (``pushed_way`` (n, 3), ``pushed_chain`` (n,),
    read and written); a shank, forearm or hand folds or unfolds its limb for the part along
    its root-end line; the rest turns the limb (its leg or arm frame, from the posture's
    ``pelvis2world``, ``thorax2world`` (n, 3, 3), ``leg2world``, ``arm2world`` (n, 2, 3, 3));
    a held leg keeps its foot's direction in the world; a trunk or pelvis steps. Writes the
    pose's ``leg_fraction``, ``arm_fraction`` (n, 2), ``leg_frame``, ``arm_frame`` (n, 2, 4),
    ``foot_dir`` (n, 2, 3) and ``root_position`` (n, 3) (normalized by ``leg_length``)."""
    for e in range(lo, hi):
        r, c = rows[e], capsule[e]
        chain = capsule_chain[c]
        # the push, kept off the chain's last one (CollisionSeparate._deflect)
        w = load3(way[e])
        last = load3(pushed_way[r])
        back = dot(w, last)
        if not (pushed_chain[r] == chain and back < 0.0):
            back = 0.0
        aside = add_scaled(w, last, -back)
        square = dot(aside, aside)
        d = distance[e]
        push = scale(aside, min(d / max(square, 1e-12), max_deflection * d))
        unit = math.sqrt(max(square, 1e-24))
        pushed_way[r, 0], pushed_way[r, 1], pushed_way[r, 2] = scale(aside, 1.0 / unit)
        pushed_chain[r] = chain
        # the fold (CollisionSeparate._fold)
        fold = 0.0
        if distal[c] and not frozen[r] and not _held(pin, aims_at, r, chain, partner[e]):
            root_to_end = sub(load3(positions[r, limb_end[chain]]),
                              load3(positions[r, limb_root[chain]]))
            reach = norm(root_to_end)
            inward = scale(root_to_end, -1.0 / max(reach, 1e-12))
            length = lengths[r, limb_segments[chain, 0]] + lengths[r, limb_segments[chain, 1]]
            fold = min(max(dot(push, inward), min(reach - max_reach_share * length, 0.0)),
                       max(reach - min_fold_share * length, 0.0))
            push = add_scaled(push, inward, -fold)
        moved = norm(push)
        toward = scale(push, 1.0 / max(moved, 1e-12))
        turn, _ = _turn(r, partner[e], chain, load3(at[e]), toward, moved, positions, pin,
                        aims_at, limb_root, max_turn_rad, min_lever_m)
        if fold != 0.0:
            length = lengths[r, limb_segments[chain, 0]] + lengths[r, limb_segments[chain, 1]]
            if chain < 2:
                leg_fraction[r, chain] -= fold / length
            else:
                arm_fraction[r, chain - 2] -= fold / length
        if chain < 2:
            frame = load_frame(leg2world[r, chain])
            if _held(pin, aims_at, r, chain, partner[e]):
                # the foot's direction in the world kept (CollisionSeparate._keep_feet)
                shank = distal_frames(frame, load3(positions[r, limb_middle[chain]]),
                                      load3(positions[r, limb_end[chain]]))
                in_world = to_world(shank, load3(foot_dir[r, chain]))
                kept = in_frame(matmul(turn, shank), in_world)
                foot_dir[r, chain, 0], foot_dir[r, chain, 1], foot_dir[r, chain, 2] = kept
            q = quat_from_matrix(matmul(transpose(load_frame(pelvis2world[r])),
                                        matmul(turn, frame)))
            for x in range(4):
                leg_frame[r, chain, x] = q[x]
        elif chain < 4:
            side = chain - 2
            q = quat_from_matrix(matmul(transpose(load_frame(thorax2world[r])),
                                        matmul(turn, load_frame(arm2world[r, side]))))
            for x in range(4):
                arm_frame[r, side, x] = q[x]
        elif chain == 5:
            h = math.sqrt(toward[0] * toward[0] + toward[1] * toward[1])
            if h > 1e-9:
                step = moved / max(h, 1e-12) / leg_length[r]
                root_position[r, 0] += toward[0] * step
                root_position[r, 1] += toward[1] * step


@jit(nogil=True)
def try_rows(watch: I64, depth: F64, other: I64, mine: I64, theirs: I64, normal: F64,
             point: F64, stalled: I64, separate_from_m: float, margin_m: float, patience: int,
             positions: F64, lengths: F64, leg_length: F64, pin: F64, aims_at: I64,
             trunk_claimed: B, contact_weight: F64, frozen: B, capsule_chain: I64,
             limb_root: I64, limb_end: I64, toe: I64, ankle_height: I64,
             ball_height_per_leg: float, max_turn_rad: float, min_lever_m: float, rows: I64,
             partner: I64, capsule: I64, at: F64, way: F64, distance: F64, can: B, feet: F64,
             clearance: F64, ask_ground: B) -> int:
    """A round's pairs and whether each side may move (``CollisionSeparate._separate`` up to
    its shares, compiled): the ``k`` rows of ``watch`` (w,) overlapping deeper than
    ``separate_from_m`` m that still try (``stalled`` below ``patience``), in ``watch``'s
    order, as entries ``0..k-1`` (their capsule ``mine``, point ``point``, way ``normal``,
    ``depth`` + ``margin_m``) and their partners (``other``) as entries ``k..2k-1`` (capsule
    ``theirs``, the same point, the opposite way); then :func:`turn_rows` over the ``2k``
    entries (``can``, ``feet``, ``clearance``, ``ask_ground``: the caller asks the ground).
    The entry arrays (2w, ...) are written; returns ``k``."""
    k = 0
    for w in watch:
        if depth[w] > separate_from_m and stalled[w] < patience:
            rows[k] = w
            k += 1
    for e in range(k):
        r = rows[e]
        t = other[r]
        rows[k + e], partner[e], partner[k + e] = t, t, r
        capsule[e], capsule[k + e] = mine[r], theirs[r]
        full = depth[r] + margin_m
        distance[e], distance[k + e] = full, full
        for x in range(3):
            at[e, x], at[k + e, x] = point[r, x], point[r, x]
            way[e, x], way[k + e, x] = normal[r, x], -normal[r, x]
    turn_rows(0, 2 * k, rows, partner, capsule, at, way, distance, positions, lengths,
              leg_length, pin, aims_at, trunk_claimed, contact_weight, frozen, capsule_chain,
              limb_root, limb_end, toe, ankle_height, ball_height_per_leg, max_turn_rad,
              min_lever_m, can, feet, clearance, ask_ground)
    return k


@jit(nogil=True)
def share_and_push(k: int, rows: I64, partner: I64, capsule: I64, at: F64, way: F64,
                   can: B, priority: F64, stalled: I64, depth: F64, patience: int,
                   margin_m: float, stuck: B, positions: F64, lengths: F64, leg_length: F64,
                   pin: F64, aims_at: I64, frozen: B, pushed_way: F64, pushed_chain: I64,
                   pelvis2world: F64, thorax2world: F64, leg2world: F64, arm2world: F64,
                   leg_fraction: F64, arm_fraction: F64, leg_frame: F64, arm_frame: F64,
                   foot_dir: F64, root_position: F64, capsule_chain: I64, distal: B,
                   limb_root: I64, limb_middle: I64, limb_end: I64, limb_segments: I64,
                   max_turn_rad: float, min_lever_m: float, max_deflection: float,
                   min_fold_share: float, max_reach_share: float, distance: F64) -> int:
    """The rest of ``CollisionSeparate._separate`` for :func:`try_rows`' ``k`` pairs, compiled:
    each pair's share of the way (the lower priority moves; equal ones halve it; all of it
    when the partner may not move or stopped trying), ``stuck`` (k,) the pairs where neither
    may move (the caller warns; entries ``0..k-1`` are left as they are), and
    :func:`push_rows` over the rows that move, gathered in their order into the entries
    ``k..k+g-1`` of ``rows``, ``partner``, ``capsule``, ``at``, ``way`` and ``distance`` (their
    depth times the share, plus ``margin_m``). Returns ``g``."""
    g = 0
    for e in range(k):
        r, t = rows[e], partner[e]
        if priority[r] < priority[t]:
            share = 1.0
        elif priority[r] == priority[t]:
            share = 0.5
        else:
            share = 0.0
        if not (can[k + e] and stalled[t] < patience):
            share = 1.0
        share = share * can[e]
        stuck[e] = not can[e] and not can[k + e]
        if share > 0:  # (entry k + e, the partner's, is read: entries up to it are free)
            m = k + g
            rows[m], partner[m], capsule[m] = r, t, capsule[e]
            for x in range(3):
                at[m, x], way[m, x] = at[e, x], way[e, x]
            distance[m] = depth[r] * share + margin_m
            g += 1
    push_rows(k, k + g, rows, partner, capsule, at, way, distance, positions, lengths, leg_length,
              pin, aims_at, frozen, pushed_way, pushed_chain, pelvis2world, thorax2world,
              leg2world, arm2world, leg_fraction, arm_fraction, leg_frame, arm_frame, foot_dir,
              root_position, capsule_chain, distal, limb_root, limb_middle, limb_end,
              limb_segments, max_turn_rad, min_lever_m, max_deflection, min_fold_share,
              max_reach_share)
    return g
