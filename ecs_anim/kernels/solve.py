"""The compiled constraint solver's shell (paper §9): the iteration loop of every character.

Mirrors :func:`ecs_anim.solver_shell.solve` (the numpy reference, which stays in the package
and which the tests compare this with to 1e-9 m). :func:`solve_rows` runs over the solved
characters in parallel (``prange``); per character, :func:`solve_character` owns the loop:
follow the goals on its own body, the limbs (:mod:`.solve_limbs`), the head
(:mod:`.solve_head`), the trunk (:mod:`.solve_trunk`, skipped when no goal's chain includes it;
it decodes the row again when it turns), the root (:mod:`.solve_root`), then the stopping rule
(every goal met or stalled and the centre of mass back; the budget ``iterations``), and the
final re-plant of the limbs and the head. Each character stops on its own goals: its result does
not depend on who else is solved, nor on the thread count.

The goals come from the numpy :func:`ecs_anim.solver_shell.tick_goals`; :func:`solve` sorts them
by character, precomputes the winners and calls the kernel.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit, prange
from numpy.typing import NDArray

from ..constraint_table import winners
from ..ground_adapt import MAX_LEG_EXTENSION
from ..normalized import DecodedPose, NormalizedPoses
from ..rotations import normalize
from ..solver_shell import (
    CONTACT_PRIORITY,
    DEFAULT_SETTINGS,
    LIMB_OF_GROUP,
    SolverSettings,
    TickGoals,
)
from .decode import DecodedArrays, PoseArrays
from .solve_head import solve_head
from .solve_limbs import solve_limbs
from .solve_points import (
    Bodies,
    Goals,
    Tables,
    Winners,
    goal_error,
    plain_point,
    point_position,
    tables,
)
from .solve_root import root_step
from .solve_trunk import solve_trunk
from .vec import F64, dot, load3, store3, sub

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]
_TRUNK = 5
TABLES = tables()


@njit(cache=True, inline="always")
def follow_own_targets(c: int, dec: DecodedArrays, g: Goals, t: Tables) -> None:
    """Mirrors ``ecs_anim.solver_shell._Solve.follow_own_targets`` for character ``c``: goals
    aiming at a point of the same body move with that point."""
    for j in range(g.start[c], g.start[c + 1]):
        if g.on_self[j]:
            now = point_position(dec, c, g.self_segment[j], g.self_fraction[j],
                                 load3(g.self_offset[j]), t)
            shift = sub(now, load3(g.self_at[j]))
            store3(g.self_at[j], now)
            if not g.orientation[j]:
                for i in range(3):
                    g.goal[j, i] += shift[i]


@njit(cache=True)
def solve_character(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners,
                    b: Bodies, t: Tables, err: F64, stalled: B8, previous: F64, slow_before: B8,
                    iterations: int, tolerance_m: float, tolerance_rad: float,
                    com_tolerance_m: float, max_ccd_step_rad: float, root_gain: float,
                    stall_fraction: float, leg_extension: float) -> int:
    """Solve character ``c``'s goals (its rows of ``pose`` and ``dec`` in place; ``err``,
    ``stalled``, ``previous``, ``slow_before`` (k,) per-goal scratch). Returns the iterations
    it used. Mirrors the loop of :func:`ecs_anim.solver_shell.solve` for one character."""
    start, stop = g.start[c], g.start[c + 1]
    uses_trunk = False
    on_self = False
    for j in range(start, stop):
        stalled[j] = False
        previous[j] = math.inf
        slow_before[j] = False
        if (g.chain[j] & (1 << _TRUNK)) > 0:
            uses_trunk = True
        on_self = on_self or g.on_self[j]
    # Steps with nothing to do are not called (passing the state tuples on costs a reference
    # count per array they hold), and the errors of points without offset are measured on the
    # arrays themselves (the same operations as goal_error).
    uses_head = w.first_head[c] >= 0 or w.orient_head[c] >= 0
    positions, seg_proximal, seg_distal = dec.positions, t.seg_proximal, t.seg_distal
    orientation, segment, fraction, offset = g.orientation, g.segment, g.fraction, g.offset
    goal, priority = g.goal, g.priority
    used = 0
    for _ in range(iterations):
        used += 1
        if on_self:
            follow_own_targets(c, dec, g, t)
        solve_limbs(c, pose, dec, g, w, b, t, tolerance_m, leg_extension)
        if uses_head:
            solve_head(c, pose, dec, g, w, b, t)
        if uses_trunk:
            for j in range(start, stop):
                err[j] = goal_error(dec, c, g, j, t)
            solve_trunk(c, pose, dec, b.lengths[c], g, err, stalled, t, tolerance_m, tolerance_rad,
                        max_ccd_step_rad)
        com_error = root_step(c, pose.root_position, positions, b.lengths, b.masses,
                              b.com_fraction, b.footprint, b.in_contact, b.com_desired, b.com_on,
                              t.mass_proximal, t.mass_distal, t.hip, t.thigh, t.shank,
                              com_tolerance_m, root_gain, leg_extension)
        # Done where every goal is met or has stalled (unchanged, or falling by less than a
        # share of itself twice running), and the centre of mass is back.
        any_open = False
        for j in range(start, stop):
            if (not orientation[j] and offset[j, 0] == 0.0 and offset[j, 1] == 0.0
                    and offset[j, 2] == 0.0):
                d = sub(plain_point(positions, c, seg_proximal[segment[j]],
                                    seg_distal[segment[j]], fraction[j]), load3(goal[j]))
                e = math.sqrt(dot(d, d))
            else:
                e = goal_error(dec, c, g, j, t)
            tol = tolerance_rad if orientation[j] else tolerance_m
            first = math.isinf(previous[j])
            unchanged = not first and abs(previous[j] - e) < tolerance_m
            slow = not first and previous[j] - e < stall_fraction * previous[j]
            planted = priority[j] == math.inf
            goal_open = (e > tol and not unchanged and not (slow and slow_before[j])
                         and not stalled[j] and not planted)
            if e > tol and not goal_open:
                stalled[j] = True
            previous[j] = e
            slow_before[j] = slow
            any_open = any_open or goal_open
        if not any_open and com_error <= com_tolerance_m:
            break
    # The last root move shifted the limbs: re-plant the feet, re-aim the head and the arms.
    if on_self:
        follow_own_targets(c, dec, g, t)
    solve_limbs(c, pose, dec, g, w, b, t, tolerance_m, leg_extension)
    if uses_head:
        solve_head(c, pose, dec, g, w, b, t)
    return used


@njit(cache=True, parallel=True)
def solve_rows(pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners, b: Bodies,
               t: Tables, used: I64, iterations: int, tolerance_m: float, tolerance_rad: float,
               com_tolerance_m: float, max_ccd_step_rad: float, root_gain: float,
               stall_fraction: float, leg_extension: float) -> None:
    """Solve every character (rows 0..r-1 of ``pose``, ``dec``, ``b``; goals ``g``) in
    parallel, in place; ``used`` (r,) the iterations each one took."""
    k = g.priority.shape[0]
    err = np.zeros(k)
    stalled = np.zeros(k, np.bool_)
    previous = np.zeros(k)
    slow_before = np.zeros(k, np.bool_)
    for c in prange(used.shape[0]):
        used[c] = solve_character(c, pose, dec, g, w, b, t, err, stalled, previous, slow_before,
                                  iterations, tolerance_m, tolerance_rad, com_tolerance_m,
                                  max_ccd_step_rad, root_gain, stall_fraction, leg_extension)


def sorted_goals(goals: TickGoals) -> tuple[Goals, Winners, I64]:
    """The goals sorted by character (stable: ties between priorities still go to the goal
    added last), their winners, and the order (k,) taking ``goals``' indices to the sorted."""
    r, k = int(goals.rows.size), goals.k
    order = np.argsort(goals.owner, kind="stable")
    owner = goals.owner[order]
    start = np.zeros(r + 1, np.int64)
    np.cumsum(np.bincount(owner, minlength=r), out=start[1:])
    on_self = np.zeros(k, bool)
    self_segment = np.zeros(k, np.int64)
    self_fraction = np.zeros(k)
    self_offset = np.zeros((k, 3))
    self_at = np.zeros((k, 3))
    if goals.on_self.size:
        on_self[goals.on_self] = True
        self_segment[goals.on_self] = goals.self_segment
        self_fraction[goals.on_self] = goals.self_fraction
        self_offset[goals.on_self] = goals.self_offset
        self_at[goals.on_self] = goals.self_start

    def take(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a[order])

    g = Goals(start=start, table_index=take(goals.table_index).astype(np.int64),
              orientation=take(goals.orientation).astype(np.bool_),
              group=take(goals.group).astype(np.int64), bone=take(goals.bone).astype(np.int64),
              segment=take(goals.segment).astype(np.int64),
              fraction=take(goals.fraction).astype(np.float64),
              offset=take(goals.offset).astype(np.float64), chain=take(goals.chain).astype(np.int64),
              priority=take(goals.priority).astype(np.float64),
              goal=take(goals.goal).astype(np.float64), axis=take(goals.axis).astype(np.float64),
              on_self=take(on_self), self_segment=take(self_segment),
              self_fraction=take(self_fraction), self_offset=take(self_offset),
              self_at=take(self_at))
    is_point = ~g.orientation
    limb = LIMB_OF_GROUP[g.group]
    on_limb = limb >= 0
    first_limb = winners(owner, limb, g.priority, on_limb & is_point, r, 4)
    taken = np.zeros(k, bool)
    taken[first_limb[first_limb >= 0]] = True
    zero = np.zeros(k, np.int64)
    on_head = g.group == 2
    w = Winners(first_limb=first_limb,
                second_limb=winners(owner, limb, g.priority, on_limb & is_point & ~taken, r, 4),
                orient_limb=winners(owner, limb, g.priority, on_limb & g.orientation, r, 4),
                first_head=np.ascontiguousarray(
                    winners(owner, zero, g.priority, on_head & is_point, r, 1)[:, 0]),
                orient_head=np.ascontiguousarray(
                    winners(owner, zero, g.priority, on_head & g.orientation, r, 1)[:, 0]))
    return g, w, order


class SolveState(NamedTuple):
    """What :func:`solve_rows` works on: copies of the solved characters' pose and decoded rows
    (written in place), their goals sorted by character (``order`` (k,) takes the
    :class:`~ecs_anim.solver_shell.TickGoals` indices to the sorted ones), the winners and the
    bodies."""

    pose: PoseArrays
    dec: DecodedArrays
    goals: Goals
    winners: Winners
    bodies: Bodies
    order: I64


def prepare(poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64,
            com_fraction: F64, decoded: DecodedPose | None = None) -> SolveState:
    """Gather the solve state of :func:`solve` (the arguments are the same)."""
    from .decode import decode as decode_compiled

    g, w, order = sorted_goals(goals)
    pose = PoseArrays(*(np.array(getattr(poses, name), dtype=np.float64, order="C")
                        for name in PoseArrays._fields))
    lengths = np.ascontiguousarray(lengths, dtype=np.float64)
    if decoded is None:
        decoded = decode_compiled(poses, lengths)
    dec = DecodedArrays(*(np.array(getattr(decoded, name), dtype=np.float64, order="C")
                          for name in DecodedArrays._fields))
    p = dec.positions
    foot_in_world = normalize(p[:, TABLES.toe] - p[:, TABLES.ankle])
    b = Bodies(lengths=lengths, masses=np.ascontiguousarray(masses, dtype=np.float64),
               com_fraction=np.ascontiguousarray(com_fraction, dtype=np.float64),
               footprint=np.ascontiguousarray(goals.footprint, dtype=np.float64),
               in_contact=np.ascontiguousarray(goals.in_contact, dtype=np.bool_),
               com_desired=np.ascontiguousarray(goals.com_desired, dtype=np.float64),
               com_on=np.ascontiguousarray(goals.com_on, dtype=np.bool_),
               foot_in_world=np.ascontiguousarray(foot_in_world))
    return SolveState(pose, dec, g, w, b, order)


def solve(poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64, com_fraction: F64,
          settings: SolverSettings = DEFAULT_SETTINGS,
          decoded: DecodedPose | None = None) -> tuple[NormalizedPoses, I64, DecodedPose]:
    """Compiled :func:`ecs_anim.solver_shell.solve`: the same arguments and results (the new
    poses (r,), the iterations each character used (r,), the decoded result). ``goals.goal``
    ends where goals following a point of their own body have moved, as there."""
    state = prepare(poses, lengths, goals, masses, com_fraction, decoded)
    used = np.zeros(goals.rows.size, np.int64)
    s = settings
    solve_rows(state.pose, state.dec, state.goals, state.winners, state.bodies, TABLES, used,
               int(s.iterations), float(s.tolerance_m), float(s.tolerance_rad),
               float(s.com_tolerance_m), float(s.max_ccd_step_rad), float(s.root_gain),
               float(s.stall_fraction), float(MAX_LEG_EXTENSION))
    goals.goal[state.order] = state.goals.goal
    return (NormalizedPoses(**dict(zip(PoseArrays._fields, state.pose, strict=True))), used,
            DecodedPose(*state.dec))


assert CONTACT_PRIORITY == math.inf  # the kernel reads a planted foot's priority as inf
