"""The compiled constraint solver's shell (paper §9): the iteration loop of every character.

Mirrors :func:`ecs_anim.solver.shell.solve` (the numpy reference, which stays in the package and
which the tests compare this with to 1e-9 m). :func:`solve_rows` runs over the solved characters
(a range of them per thread: :func:`ecs_anim.runtime.kernels.over_chunks`) and, per character,
owns the loop: a pass (follow the goals on its own body, the limbs
(:mod:`.solve_limbs`), the head (:mod:`.solve_head`)), then the stopping rule (no goal the trunk
or the body still moves left open, and the centre of mass so close that the root would not move;
or its budget of iterations spent: the pass is the result), else an iteration: the trunk
(:mod:`.solve_trunk`, skipped when no goal's chain includes it; it decodes the row again when it
turns) and the root (:mod:`.solve_root`), and the next pass. Each character stops on its own
goals: its result does not depend on who else is solved, nor on the thread count.

The goals come from :func:`ecs_anim.runtime.kernels.goals.tick_goals` (or its numpy reference),
already sorted by character (then nothing is copied); :func:`character_winners` picks the goal
each limb and the head serve, and the frame budget's caps (``Goals.iterations``,
``Bodies.iterations``) bound each
goal's and each character's iterations.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import HEAD
from ecs_anim.core.ground_adapt import MAX_LEG_EXTENSION
from ecs_anim.core.normalized import DecodedPose, NormalizedPoses
from ecs_anim.runtime.kernels import LIGHT_ROWS_PER_THREAD, over_chunks, wait_for_solver
from ecs_anim.runtime.kernels.decode import DecodedArrays, PoseArrays
from ecs_anim.runtime.kernels.decode import decode as decode_compiled
from ecs_anim.runtime.kernels.lanes import BLOCK, Column, at
from ecs_anim.runtime.kernels.solve_head import solve_head
from ecs_anim.runtime.kernels.solve_limbs import (
    A_WAITING,
    arm_lanes,
    arm_scratch,
    scatter_arm,
    solve_limbs,
)
from ecs_anim.runtime.kernels.solve_points import (
    Bodies,
    Goals,
    Tables,
    Winners,
    goal_error,
    plain_point,
    point_position,
    tables,
)
from ecs_anim.runtime.kernels.solve_root import (
    R_WAITING,
    com_shortfall,
    move_root,
    root_lanes,
    root_scratch,
    solve_root,
)
from ecs_anim.runtime.kernels.solve_trunk import solve_trunk
from ecs_anim.runtime.kernels.vec import (
    F64,
    dot,
    jit,
    load3,
    normalize,
    on_numba_import,
    store3,
    sub,
)
from ecs_anim.solver.goals import TickGoals
from ecs_anim.solver.shell import DEFAULT_SETTINGS, SolverSettings, iteration_caps

I64 = NDArray[np.int64]
B8 = NDArray[np.bool_]
_TRUNK = 5
#: Bits of a character's ``kinds`` (:func:`solve_rows`): what its goals ask of the solve.
_USES_TRUNK, _ON_SELF, _ITERATES, _PREDICTED = 1, 2, 4, 8
TABLES = tables()
#: How many characters ahead of the one it starts :func:`solve_rows` asks for the rows of
#: (:func:`prefetch_character`).
PREFETCH_AHEAD = 2


def prefetch(array: F64, index: int) -> None:
    """Ask the processor for the cache line of ``array``'s element ``index`` (flat, C order),
    to be read soon: compiled, LLVM's ``llvm.prefetch`` (no result, never a fault), put here
    as numba is imported (:func:`_compiled_prefetch`); in Python, nothing."""


def _prefetch_code(typingctx: Any, array: Any, index: Any) -> Any:
    """The typing and code of the compiled :func:`prefetch` (numba's ``intrinsic``)."""
    from llvmlite import ir  # type: ignore[import-untyped]
    from numba import types

    if not (isinstance(array, types.Array) and isinstance(index, types.Integer)):
        return None
    signature = types.void(array, index)

    def codegen(context: Any, builder: Any, sig: Any, args: Any) -> Any:
        data = context.make_array(sig.args[0])(context, builder, args[0]).data
        line = builder.bitcast(builder.gep(data, [args[1]]), ir.IntType(8).as_pointer())
        i32 = ir.IntType(32)
        # (named by llvmlite as its pointers are: `p0i8` typed, `p0` opaque)
        fetch = builder.module.declare_intrinsic(
            "llvm.prefetch", [line.type],
            ir.FunctionType(ir.VoidType(), [line.type, i32, i32, i32]))
        builder.call(fetch, [line, i32(0), i32(3), i32(1)])  # a read, kept close, data
        return context.get_dummy_value()

    return signature, codegen


def _compiled_prefetch() -> None:
    """Put numba's intrinsic in place of the Python :func:`prefetch` (an :func:`on_numba_import`
    hook); not where numba runs the kernels as Python (``NUMBA_DISABLE_JIT``), where an
    intrinsic cannot be called."""
    from numba import config
    from numba.extending import intrinsic

    if not config.DISABLE_JIT:  # type: ignore[attr-defined]  # (set from the environment)
        globals()["prefetch"] = intrinsic(_prefetch_code)


on_numba_import(_compiled_prefetch)


@jit(inline="always")
def prefetch_rows(array: F64, first: int, count: int) -> None:
    """:func:`prefetch` the ``count`` elements of ``array`` from ``first`` (flat; float64:
    every 8th, a 64-byte cache line's worth, and the last)."""
    for index in range(first, first + count, 8):
        prefetch(array, index)
    if count > 0:  # (its line, where ``first`` is not at a line's start)
        prefetch(array, first + count - 1)


# A call, not inlined by numba (its compile counted: inlined, solve_rows' took about 10 % longer).
@jit()
def prefetch_character(c: int, pose: PoseArrays, dec: DecodedArrays, g: Goals,
                       b: Bodies) -> None:
    """:func:`prefetch` the rows of character ``c`` the first pass reads first: its joints,
    limb, pelvis and thorax frames, lengths and masses, goals' points, and limbs' pose."""
    prefetch_rows(dec.positions, c * dec.positions[0].size, dec.positions[0].size)
    prefetch_rows(dec.leg2world, c * dec.leg2world[0].size, dec.leg2world[0].size)
    prefetch_rows(dec.arm2world, c * dec.arm2world[0].size, dec.arm2world[0].size)
    prefetch_rows(dec.pelvis2world, c * dec.pelvis2world[0].size, dec.pelvis2world[0].size)
    prefetch_rows(dec.thorax2world, c * dec.thorax2world[0].size, dec.thorax2world[0].size)
    for table in (b.lengths, b.masses, b.com_fraction):
        prefetch_rows(table, c * table.shape[1], table.shape[1])
    first, count = g.start[c] * 3, (g.start[c + 1] - g.start[c]) * 3
    for points in (g.goal, g.offset, g.self_offset, g.self_at):
        prefetch_rows(points, first, count)
    for limbs in (pose.foot_dir, pose.hand_dir, pose.leg_frame, pose.arm_frame):
        prefetch_rows(limbs, c * limbs[0].size, limbs[0].size)


@jit(inline="always")
def follow_own_targets(c: int, dec: DecodedArrays, g: Goals, t: Tables) -> None:
    """Mirrors ``ecs_anim.solver.shell._Solve.follow_own_targets`` for character ``c``: goals
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


@jit(inline="always")
def _iterative(g: Goals, t: Tables, j: int) -> bool:
    """Whether goal ``j`` needs iterations: the trunk turns for it (a step at a time), or it
    follows a point of its own body that a pass moves (``ecs_anim.solver.shell.solve``'s
    ``iterative``)."""
    return bool((g.chain[j] & (1 << _TRUNK)) > 0
                or (g.on_self[j] and t.seg_moved_by_pass[g.self_segment[j]] > 0))




@jit(nogil=True)
def solve_rows(lo: int, hi: int, pose: PoseArrays, dec: DecodedArrays, g: Goals, w: Winners,
               b: Bodies, t: Tables, iterations_used: I64, err: F64, stalled: B8, previous: F64,
               slow_before: B8, kinds: I64, arms: F64, scratch: F64, tolerance_m: float,
               tolerance_rad: float,
               com_tolerance_m: float, max_ccd_step_rad: float, root_gain: float,
               stall_fraction: float, leg_extension: float) -> None:
    """Solve the goals of each character ``c`` in ``lo..hi-1`` (its rows of ``pose`` and
    ``dec`` in place) in at most ``b.iterations[c]`` iterations, each goal keeping the loop
    going for at most ``g.iterations`` of them; ``iterations_used`` (r,) the iterations each one
    took. ``err``, ``stalled``, ``previous``, ``slow_before`` (k,): per-goal scratch (each
    character uses its own goals' entries, so the threads share them); ``kinds`` (r,): per
    character scratch (what its goals ask of the solve, found once); ``arms``, ``scratch``: a
    :func:`.solve_limbs.arm_scratch` and a :func:`.solve_root.root_scratch` of r rows (this
    chunk uses, and first zeroes, their block ``lo // BLOCK``). Mirrors the loop of
    :func:`ecs_anim.solver.shell.solve`, one character at a time.

    By blocks of :data:`.lanes.BLOCK` characters, in three rounds over each block: the first
    takes each character up to its first pass's arm where :func:`.solve_limbs.solve_limbs`
    gathers it into its column (the character waits), else up to its first root step where
    that is predicted (the step gathered into its column: it waits); the block's waiting arms
    are computed together on the vector units (:func:`.solve_limbs.arm_lanes`), and the second
    round takes each character whose arm waited on from there (to its first root step, as
    above); the block's waiting root steps are computed together
    (:func:`.solve_root.root_lanes`), and the third round takes each waiting character on from
    its root's move. Each character's steps run in the order of the scalar loop (a limb reads
    and writes only its own joints: the arm solved after the legs is the same). The rounds
    share one loop (one call site of each step: numba inlines a copy of a step's body at each,
    and the compile is counted)."""
    # The characters' loop is here, not in a call per character: a call passes the state
    # tuples on, a reference count up and down for each of their 74 arrays (0.25 us a
    # character); numba's inlining of such a call costs 14 s more of compile.
    arm_block, root_block = arms[lo // BLOCK], scratch[lo // BLOCK]
    # Zeroed here, not by the caller (the whole scratch, 1.8 MB each at 4,000 rows, zeroed
    # every tick for the one block a chunk uses), for speed only: the lanes compute every
    # column, and a column no character uses is better not left with whatever the reused memory
    # held (an integer read as a float is subnormal, slow to compute with); no result reads it.
    arm_block[:] = 0.0
    root_block[:] = 0.0
    for block_start in range(lo, hi, BLOCK):
        count = min(BLOCK, hi - block_start)
        for turn in range(3 * count):
            if turn == count:  # the first round done: the waiting characters' arms
                arm_lanes(arm_block, Column(0), Column(count))
            if turn == 2 * count:  # the second round done: the waiting characters' root steps
                root_lanes(root_block, Column(0), Column(count), root_gain, leg_extension)
            stage = turn // count  # 0 from the start, 1 after the arms, 2 after the root steps
            c = block_start + turn % count
            column = Column(turn % count)
            if stage == 1 and arm_block[at(A_WAITING, column)] == 0.0:
                continue
            if stage == 2 and root_block[at(R_WAITING, column)] == 0.0:
                continue
            arm_block[at(A_WAITING, column)] = 0.0
            root_block[at(R_WAITING, column)] = 0.0
            start, stop = g.start[c], g.start[c + 1]
            if stage == 0:
                # The first pass is where a character's rows are first read (about 2.5 kB over
                # some 40 arrays): from memory, at a third of the speed of the same pass on rows
                # in cache, the processor's own prefetch not keeping up with so many streams.
                if c + PREFETCH_AHEAD < hi:
                    prefetch_character(c + PREFETCH_AHEAD, pose, dec, g, b)
                uses_trunk = False
                on_self = False
                # a goal an iteration moves: the trunk's, or one following what a pass moves
                iterates = False
                # the root's step is predicted (``_Solve.predicted``): no goal iterates, and every
                # user goal follows the own body (none aims at the world or at another character)
                predicted = True
                for j in range(start, stop):
                    stalled[j] = False
                    previous[j] = math.inf
                    slow_before[j] = False
                    if (g.chain[j] & (1 << _TRUNK)) > 0:
                        uses_trunk = True
                    on_self = on_self or g.on_self[j]
                    iterates = iterates or _iterative(g, t, j)
                    predicted = predicted and (g.on_self[j] or g.table_index[j] < 0)
                # (kept for the later rounds, which would find the same)
                kinds[c] = (_USES_TRUNK * uses_trunk + _ON_SELF * on_self + _ITERATES * iterates
                            + _PREDICTED * predicted)
            else:
                uses_trunk = (kinds[c] & _USES_TRUNK) != 0
                on_self = (kinds[c] & _ON_SELF) != 0
                iterates = (kinds[c] & _ITERATES) != 0
                predicted = (kinds[c] & _PREDICTED) != 0
            # Steps with nothing to do are not called, and the errors of points without offset
            # are measured on the arrays themselves (the same operations as goal_error).
            uses_head = w.first_head[c] >= 0 or w.orient_head[c] >= 0
            positions, seg_proximal, seg_distal = dec.positions, t.seg_proximal, t.seg_distal
            orientation, segment, fraction, offset = g.orientation, g.segment, g.fraction, g.offset
            goal, goal_iterations = g.goal, g.iterations
            used = 0
            iterations = b.iterations[c]
            # A predicted character's first root step waits for its block's (no goal iterates:
            # the step ends its first iteration, and nothing is left open after it).
            waits = stage < 2 and predicted and not iterates
            any_open = iterates
            if stage == 2:
                move_root(c, pose, dec, b, root_block, column)
                used = 1
                any_open = False
            arm_solved = stage == 1  # its first pass's limbs done but an arm, now solved
            # Each pass follows the goals on the body, then re-plants the limbs and re-aims the
            # head (exact, analytic steps: a limb or head goal is where they leave it). The pass
            # ends the solve where no iteration would change anything: no goal left that the
            # trunk still turns for or that follows the body (open at the last measure; before
            # the first, any), and the centre of mass so close that the root step would not move
            # (a tenth of its tolerance); or the budget spent. It is then the result. Otherwise
            # an iteration: a trunk turn and a root move, then the next pass. One call site
            # each: numba inlines these steps' bodies at every site it compiles.
            while True:
                if arm_solved:
                    scatter_arm(c, pose, dec, t, arm_block, column)
                    arm_solved = False
                else:
                    if on_self:
                        follow_own_targets(c, dec, g, t)
                    # An arm of the first pass waits for its block's
                    # (:func:`.solve_limbs.arm_lanes`).
                    if solve_limbs(c, pose, dec, g, w, b, t, tolerance_m, leg_extension, arm_block,
                                   column, stage == 0 and used == 0):
                        arm_block[at(A_WAITING, column)] = 1.0
                        break
                if uses_head:
                    solve_head(c, pose, dec, g, w, b, t)
                if used >= iterations:
                    break
                # The centre of mass's error, measured once on these joints: the stopping
                # rule's, and the root step's unless the trunk turns in between.
                com_measured = not any_open
                ex = ey = 0.0
                if com_measured:
                    ex, ey = com_shortfall(c, positions, b.masses, b.com_fraction, b.com_desired,
                                           b.com_on, t.mass_proximal, t.mass_distal)
                    if math.sqrt(ex * ex + ey * ey) <= 0.1 * com_tolerance_m:  # the root stays
                        break
                used += 1
                if uses_trunk:
                    for j in range(start, stop):
                        err[j] = goal_error(dec, c, g, j, t)
                    solve_trunk(c, pose, dec, b.lengths[c], g, w, err, stalled, t, tolerance_m,
                                tolerance_rad, max_ccd_step_rad)
                    com_measured = False
                if not com_measured:
                    ex, ey = com_shortfall(c, positions, b.masses, b.com_fraction, b.com_desired,
                                           b.com_on, t.mass_proximal, t.mass_distal)
                size = solve_root(c, pose, dec, g, w, b, t, ex, ey, com_tolerance_m, tolerance_m,
                                  root_gain, leg_extension, predicted and not iterates,
                                  root_block, column, waits)
                if waits and size > 0.1 * com_tolerance_m:
                    root_block[at(R_WAITING, column)] = 1.0
                    break
                # Only goals an iteration still moves can keep the loop going (:func:`_iterative`;
                # the passes meet the others as well as they can be met): open where not met nor
                # stalled (unchanged, or falling by less than a share of itself twice running).
                any_open = False
                if iterates:
                    for j in range(start, stop):
                        if not _iterative(g, t, j):
                            continue
                        if (not orientation[j] and offset[j, 0] == 0.0 and offset[j, 1] == 0.0
                                and offset[j, 2] == 0.0):
                            d = sub(plain_point(positions, c, seg_proximal[segment[j]],
                                                seg_distal[segment[j]], fraction[j]),
                                    load3(goal[j]))
                            e = math.sqrt(dot(d, d))
                        else:
                            e = goal_error(dec, c, g, j, t)
                        tol = tolerance_rad if orientation[j] else tolerance_m
                        first_measure = math.isinf(previous[j])
                        unchanged = not first_measure and abs(previous[j] - e) < tolerance_m
                        slow = not first_measure and previous[j] - e < stall_fraction * previous[j]
                        # the frame budget gave it no more iterations
                        cut = used >= goal_iterations[j]
                        goal_open = (e > tol and not unchanged and not (slow and slow_before[j])
                                     and not stalled[j] and not cut)
                        if e > tol and not goal_open:
                            stalled[j] = True
                        previous[j] = e
                        slow_before[j] = slow
                        any_open = any_open or goal_open
            if arm_block[at(A_WAITING, column)] == 0.0 and root_block[at(R_WAITING, column)] == 0.0:
                iterations_used[c] = used


@jit(nogil=True)
def foot_directions_rows(lo: int, hi: int, positions: F64, t: Tables, out: F64) -> None:
    """``out[c, side]`` (r, 2, 3): the unit direction from ankle to toe of each foot of the
    characters ``lo..hi-1`` (``positions`` (r, N_JOINTS, 3) m)."""
    for c in range(lo, hi):
        for side in range(2):
            store3(out[c, side], normalize(sub(load3(positions[c, t.toe[side]]),
                                               load3(positions[c, t.ankle[side]]))))


@jit()
def character_winners(c: int, g: Goals, w: Winners, limb_of_group: I64, head_group: int) -> None:
    """Mirrors :func:`ecs_anim.motion.constraint_table.winners` as ``ecs_anim.solver.shell._Solve``
    uses it, for character ``c``: per limb its highest-priority point goal (``first_limb``),
    the next (``second_limb``) and its orientation goal; the head's point and orientation goal
    (-1: none). Ties go to the goal added last (the later index: the goals are sorted stably)."""
    first_limb, second_limb, orient_limb = w.first_limb, w.second_limb, w.orient_limb
    first_head, orient_head = w.first_head, w.orient_head
    group, orientation, priority = g.group, g.orientation, g.priority
    for slot in range(4):
        first_limb[c, slot] = -1
        second_limb[c, slot] = -1
        orient_limb[c, slot] = -1
    first_head[c] = -1
    orient_head[c] = -1
    start, stop = g.start[c], g.start[c + 1]
    for j in range(start, stop):
        slot = limb_of_group[group[j]]
        p = priority[j]
        if slot >= 0:
            if orientation[j]:
                if orient_limb[c, slot] < 0 or p >= priority[orient_limb[c, slot]]:
                    orient_limb[c, slot] = j
            elif first_limb[c, slot] < 0 or p >= priority[first_limb[c, slot]]:
                first_limb[c, slot] = j
        elif group[j] == head_group:
            if orientation[j]:
                if orient_head[c] < 0 or p >= priority[orient_head[c]]:
                    orient_head[c] = j
            elif first_head[c] < 0 or p >= priority[first_head[c]]:
                first_head[c] = j
    for j in range(start, stop):
        slot = limb_of_group[group[j]]
        if (slot >= 0 and not orientation[j] and j != first_limb[c, slot]
                and (second_limb[c, slot] < 0 or priority[j] >= priority[second_limb[c, slot]])):
            second_limb[c, slot] = j


@jit(nogil=True)
def winners_rows(lo: int, hi: int, g: Goals, w: Winners, limb_of_group: I64,
                 head_group: int) -> None:
    """:func:`character_winners` of every character ``lo..hi-1``, in place."""
    for c in range(lo, hi):
        character_winners(c, g, w, limb_of_group, head_group)


@jit(nogil=True)
def goal_starts(owner: I64, on_self: I64, self_segment: I64, self_fraction: F64,
                self_offset: F64, self_start: F64, start: I64, dense_on_self: B8,
                dense_segment: I64, dense_fraction: F64, dense_offset: F64,
                dense_at: F64) -> bool:
    """The goals following a point of their own body (``on_self`` (s,) their indices in
    ``owner`` (k,), that point ``self_segment``, ``self_fraction``, ``self_offset`` (s, 3),
    where it is ``self_start`` (s, 3)) laid out by goal: ``dense_on_self`` (k,),
    ``dense_segment``, ``dense_fraction``, ``dense_offset``, ``dense_at`` (k, 3), zero for the
    others; and whether ``owner`` is sorted (by character, each in ``0..r-1``; r + 1 =
    ``start``'s size), then ``start`` (r + 1,) where each character's goals begin
    (``np.cumsum(np.bincount(owner, minlength=r))`` after a 0; else not written). One pass
    where numpy took a call for each."""
    k, r = owner.shape[0], start.shape[0] - 1
    for j in range(k):
        dense_on_self[j] = False
        dense_segment[j] = 0
        dense_fraction[j] = 0.0
        for a in range(3):
            dense_offset[j, a] = 0.0
            dense_at[j, a] = 0.0
    for i in range(on_self.shape[0]):
        j = on_self[i]
        dense_on_self[j] = True
        dense_segment[j] = self_segment[i]
        dense_fraction[j] = self_fraction[i]
        for a in range(3):
            dense_offset[j, a] = self_offset[i, a]
            dense_at[j, a] = self_start[i, a]
    for j in range(k):
        if owner[j] < 0 or owner[j] >= r or (j > 0 and owner[j] < owner[j - 1]):
            return False
    c = 0
    start[0] = 0
    for j in range(k):
        while c < owner[j]:  # the characters after the last goal's, up to this one's, begin here
            c += 1
            start[c] = j
    while c < r:
        c += 1
        start[c] = k
    return True


def sorted_goals(goals: TickGoals, goal_iterations: I64) -> tuple[Goals, Winners, I64]:
    """The goals sorted by character (stable: ties between priorities still go to the goal
    added last), their winners, and the order (k,) taking ``goals``' indices to the sorted;
    ``goal_iterations`` (k,) each goal's cap (:func:`~ecs_anim.solver.shell.iteration_caps`).
    :func:`ecs_anim.solver.goals.tick_goals` makes them sorted already: then nothing is
    copied (``goal`` is the same array), and the characters' ranges come with the goals
    following their own body from one compiled pass (:func:`goal_starts`)."""
    r, k = int(goals.rows.size), goals.k
    start = np.empty(r + 1, np.int64)
    on_self = np.empty(k, np.bool_)
    self_segment = np.empty(k, np.int64)
    self_fraction = np.empty(k)
    self_offset = np.empty((k, 3))
    self_at = np.empty((k, 3))
    owner = np.ascontiguousarray(goals.owner, np.int64)
    already = goal_starts(owner, np.ascontiguousarray(goals.on_self, np.int64),
                          np.ascontiguousarray(goals.self_segment, np.int64),
                          np.ascontiguousarray(goals.self_fraction, np.float64),
                          np.ascontiguousarray(goals.self_offset, np.float64),
                          np.ascontiguousarray(goals.self_start, np.float64), start, on_self,
                          self_segment, self_fraction, self_offset, self_at)
    order = np.arange(k)
    if not already:  # (the numpy reference's goals)
        order = np.argsort(owner, kind="stable")
        start[0] = 0
        np.cumsum(np.bincount(owner[order], minlength=r), out=start[1:])
        on_self, self_segment, self_fraction, self_offset, self_at = (
            on_self[order], self_segment[order], self_fraction[order], self_offset[order],
            self_at[order])

    def take(a: np.ndarray, dtype: type) -> np.ndarray:
        return np.ascontiguousarray(a if already else a[order], dtype)

    g = Goals(start=start, table_index=take(goals.table_index, np.int64),
              orientation=take(goals.orientation, np.bool_), group=take(goals.group, np.int64),
              bone=take(goals.bone, np.int64), segment=take(goals.segment, np.int64),
              fraction=take(goals.fraction, np.float64), offset=take(goals.offset, np.float64),
              chain=take(goals.chain, np.int64), priority=take(goals.priority, np.float64),
              goal=take(goals.goal, np.float64), axis=take(goals.axis, np.float64),
              on_self=on_self, self_segment=self_segment, self_fraction=self_fraction,
              self_offset=self_offset, self_at=self_at,
              iterations=take(goal_iterations, np.int64))
    w = Winners(first_limb=np.empty((r, 4), np.int64), second_limb=np.empty((r, 4), np.int64),
                orient_limb=np.empty((r, 4), np.int64), first_head=np.empty(r, np.int64),
                orient_head=np.empty(r, np.int64))
    over_chunks(winners_rows, r, g, w, TABLES.limb_of_group, HEAD,
                rows_per_thread=LIGHT_ROWS_PER_THREAD)
    return g, w, order


class SolveState(NamedTuple):
    """What :func:`solve_rows` works on: the solved characters' pose and decoded rows
    (written in place), their goals sorted by character (``order`` (k,) takes the
    :class:`~ecs_anim.solver.goals.TickGoals` indices to the sorted ones), the winners and the
    bodies."""

    pose: PoseArrays
    dec: DecodedArrays
    goals: Goals
    winners: Winners
    bodies: Bodies
    order: I64


def prepare(poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64,
            com_fraction: F64, decoded: DecodedPose | None = None,
            settings: SolverSettings = DEFAULT_SETTINGS, in_place: bool = False) -> SolveState:
    """Gather the solve state of :func:`solve` (the arguments are the same): copies of
    ``poses`` and ``decoded``, or with ``in_place`` those arrays themselves (when already
    float64 and C-contiguous)."""
    goal_iterations, row_iterations = iteration_caps(goals, settings)
    g, w, order = sorted_goals(goals, goal_iterations)

    def own(a: np.ndarray) -> np.ndarray:
        return (np.ascontiguousarray(a, dtype=np.float64) if in_place
                else np.array(a, dtype=np.float64, order="C"))

    pose = PoseArrays(*(own(getattr(poses, name)) for name in PoseArrays._fields))
    lengths = np.ascontiguousarray(lengths, dtype=np.float64)
    if decoded is None:
        decoded = decode_compiled(poses, lengths)
    dec = DecodedArrays(*(own(getattr(decoded, name)) for name in DecodedArrays._fields))
    r = goals.rows.size
    foot_in_world = np.empty((r, 2, 3))
    over_chunks(foot_directions_rows, r, dec.positions, TABLES, foot_in_world,
                rows_per_thread=LIGHT_ROWS_PER_THREAD)
    b = Bodies(lengths=lengths, masses=np.ascontiguousarray(masses, dtype=np.float64),
               com_fraction=np.ascontiguousarray(com_fraction, dtype=np.float64),
               footprint=np.ascontiguousarray(goals.footprint, dtype=np.float64),
               in_contact=np.ascontiguousarray(goals.in_contact, dtype=np.bool_),
               com_desired=np.ascontiguousarray(goals.com_desired, dtype=np.float64),
               com_on=np.ascontiguousarray(goals.com_on, dtype=np.bool_),
               foot_in_world=foot_in_world,
               iterations=np.ascontiguousarray(row_iterations, dtype=np.int64))
    return SolveState(pose, dec, g, w, b, order)


def solve(poses: NormalizedPoses, lengths: F64, goals: TickGoals, masses: F64, com_fraction: F64,
          settings: SolverSettings = DEFAULT_SETTINGS, decoded: DecodedPose | None = None,
          in_place: bool = False) -> tuple[NormalizedPoses, I64, DecodedPose]:
    """Compiled :func:`ecs_anim.solver.shell.solve`: the same arguments and results (the new
    poses (r,), the iterations each character used (r,), the decoded result). ``goals.goal``
    ends where goals following a point of their own body have moved, as there. With
    ``in_place`` the given ``poses`` and ``decoded`` are the caller's scratch copies: they are
    solved in place (and returned) instead of copied."""
    state = prepare(poses, lengths, goals, masses, com_fraction, decoded, settings, in_place)
    used = np.zeros(goals.rows.size, np.int64)
    s = settings
    wait_for_solver()  # a first run may be compiling solve_rows in another process
    k = goals.k
    r = used.shape[0]
    # (the per-goal and per-character scratch is written by solve_rows before it is read)
    over_chunks(solve_rows, r, state.pose, state.dec, state.goals, state.winners,
                state.bodies, TABLES, used, np.empty(k), np.empty(k, np.bool_), np.empty(k),
                np.empty(k, np.bool_), np.empty(r, np.int64), arm_scratch(r), root_scratch(r),
                float(s.tolerance_m),
                float(s.tolerance_rad), float(s.com_tolerance_m), float(s.max_ccd_step_rad),
                float(s.root_gain), float(s.stall_fraction), float(MAX_LEG_EXTENSION),
                rows_per_thread=BLOCK)
    if state.goals.goal is not goals.goal:
        goals.goal[state.order] = state.goals.goal
    return (NormalizedPoses(**dict(zip(PoseArrays._fields, state.pose, strict=True))), used,
            DecodedPose(*state.dec))

