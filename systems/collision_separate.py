"""CollisionSeparate: every character's collision capsules, and bodies pushed apart (DESIGN §8b).

Each tick, after PostureConvert: every character's bounds from its joints
(:func:`ecs_anim.runtime.kernels.capsules.bounds`), the bodies whose bounds meet another's
(:func:`ecs_anim.runtime.kernels.capsules.touching`, on a uniform grid: a crowd that keeps apart
costs the bounds and the grid; while no two meet, a tick whose bounds each moved less than
half its clearance then, :func:`~ecs_anim.runtime.kernels.capsules.drifted`, costs the bounds
alone), their capsules from their postures (compiled:
:func:`ecs_anim.runtime.kernels.capsules.capsules`; the layout and radii in
:mod:`ecs_anim.solver.capsules`) and each one's deepest overlap with another character
(:func:`ecs_anim.runtime.kernels.capsules.overlaps`); a body a round moves searches again with
those it then reaches. Where two
characters overlap by more than :data:`SEPARATE_FROM_M`, the one of lower priority (the highest
priority of its active constraints; none: lowest) moves the chain that overlaps:

- a free limb turns about its hip or shoulder, and a shank, forearm or hand folds or unfolds
  its limb for the part of the way along its root-end line (a kick's ankle in a chest comes
  back by bending the knee: no turn about the hip moves it that way);
- a limb held by a pin swivels about its root-pin axis, the pin staying: the ankle of a foot
  planted in full (a foot still rising or landing, contact weight below 1, is free: two
  walkers' feet, one lifting, would otherwise stay in each other), or the point of its
  constraint; but a limb whose constraint aims at the very body it
  overlaps is not held against it: it goes out to that body's surface, pin and all, which is
  what its target is (a kick at the chest, a ward-off at the shank: DESIGN §8b), so its error
  measured to the surface does not grow (the errors reported are the solve's);
- a trunk or pelvis of a body with no foot down steps aside.

Equal priorities share the way; where the lower one's chain may not move, the other's moves
all of it; where neither may, the pair is reported once (a warning). A push that would undo the
same chain's last one this tick (a limb between two others) goes square to it instead. A moved
character's posture is made again from its pose (the compiled PostureConvert kernel, only its
rows), and the search runs again, at most :data:`PASSES` times; a body whose overlap did not
shrink by :data:`STALL_SHARE` in :data:`PATIENCE` rounds in a row stops trying this tick (pairs
that may not move do not end the others' rounds), and the rounds end when the bodies still
trying, together, went no lower in as many.

With a frame budget (``SolverSettings.budget_ms``), the rounds also end before one that would
take the tick past the budget's aim (:data:`~ecs_anim.solver.budget.TARGET_SHARE` of it): the
CPU time the systems before this one took this tick, the rounds so far and one more at their
mean cost, and what the systems after it took last tick (:attr:`clock`, the process's CPU
clock per kernel thread; a test may set another). The first round always runs. ``rounds`` and
``rounds_cut`` say what this tick made and whether the budget ended the rounds.

Rows: every character.
Reads: store.positions, lengths, poses, posture, contact_weight, frozen, local_rotations,
vertebrae; constraints.weight (which chains are claimed, and each character's priority).
Writes: store.poses, positions, posture, local_rotations, vertebrae (the moved characters);
capsule_ends, capsule_radii (the capsules, as they end, of the characters whose bounds meet
another's, the only ones that can overlap; the other rows NaN), overlap_m (each character's
deepest overlap with another after the separation, m).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import ARM_L, HEAD, LEG_L, TRUNK, point_positions
from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG
from ecs_anim.core.morphology import leg_length
from ecs_anim.core.normalized import NormalizedPoses, decode_legs
from ecs_anim.core.rotations import axis_angle, normalize, quat_from_matrix
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX, N_JOINTS
from ecs_anim.motion.constraint_table import TARGET_BODY
from ecs_anim.runtime import capsule_overlaps as numpy_capsules
from ecs_anim.runtime.kernels import over_chunks, threads
from ecs_anim.runtime.kernels.capsules import (
    Capsules,
    Grid,
    Overlaps,
    bounds,
    capsules,
    drifted,
    grid_holds,
    grid_of,
    near_rows,
    overlaps,
    touching,
)
from ecs_anim.runtime.kernels.decode import decoded_arrays, fits, pose_arrays, spine_scratch
from ecs_anim.runtime.kernels.posture import N_EXPORT, export_constants, posture_rows
from ecs_anim.runtime.kernels.separate import share_and_push, try_rows
from ecs_anim.runtime.system_base import System
from ecs_anim.solver.budget import TARGET_SHARE
from ecs_anim.solver.capsules import CAPSULES, N_CAPSULES
from ecs_anim.solver.steps import rotation_toward
from ecs_anim.systems.posture_convert import posture_numpy

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Overlaps shallower than this are left (m).
SEPARATE_FROM_M = 0.5e-3
#: How far past touching a separated pair is pushed (m): the next tick's motion starts apart.
MARGIN_M = 0.5e-3
#: Most rounds of search and separation per tick.
PASSES = 16
#: A round that takes off less than this share of the overlap left ends the rounds.
STALL_SHARE = 0.1
#: A body whose overlap did not shrink by STALL_SHARE in this many rounds in a row stops
#: trying this tick.
PATIENCE = 3
#: How many new stuck pairs a warning names (the rest are counted).
STUCK_NAMED = 3
#: The largest turn of a limb in one round (rad).
MAX_TURN_RAD = 0.25
#: A pinned limb whose point moves less than this per radian of swivel does not swivel (m).
MIN_LEVER_M = 0.03
#: A limb folds (its end toward its root) down to this share of its length at most, and
#: unfolds up to MAX_REACH_SHARE of it (short of straight: a straight limb's bend is
#: undefined).
MIN_FOLD_SHARE = 0.3
MAX_REACH_SHARE = 0.95
#: A push that keeps off an earlier one of the same round's chain goes at most this many times
#: its depth (two pushes nearly opposed: a limb between two others).
MAX_DEFLECTION = 3.0

# Per capsule: the chain that moves it: 0-3 a limb (leg_l, leg_r, arm_l, arm_r), 4 the head,
# 5 the root (trunk and pelvis); the group its claim is read from.
_CHAIN = {"shank_l": 0, "thigh_l": 0, "shank_r": 1, "thigh_r": 1, "upper_arm_l": 2,
          "forearm_l": 2, "hand_l": 2, "upper_arm_r": 3, "forearm_r": 3, "hand_r": 3,
          "head": 4, "pelvis": 5, "trunk": 5}
CAPSULE_CHAIN = np.array([_CHAIN[c] for c in CAPSULES], np.int64)
CHAIN_GROUP = np.array([LEG_L, LEG_L + 1, ARM_L, ARM_L + 1, HEAD, TRUNK], np.int64)
LIMB_OF_GROUP = np.array([0, 1, -1, 2, 3, -1], np.int64)  # group -> limb (-1: none)
LIMB_ROOT = np.array([J["hip_l"], J["hip_r"], J["shoulder_l"], J["shoulder_r"]], np.int64)
LIMB_MIDDLE = np.array([J["knee_l"], J["knee_r"], J["elbow_l"], J["elbow_r"]], np.int64)
LIMB_END = np.array([J["ankle_l"], J["ankle_r"], J["wrist_l"], J["wrist_r"]], np.int64)
TOE = np.array([J["toe_l"], J["toe_r"]], np.int64)
#: Per limb, its two segments' LENGTHS indices (root's, end's).
LIMB_SEGMENTS = np.array([[LENGTH_INDEX[f"{a}_{s}"], LENGTH_INDEX[f"{b}_{s}"]]
                          for a, b, s in (("thigh", "shank", "l"), ("thigh", "shank", "r"),
                                          ("upper_arm", "forearm", "l"),
                                          ("upper_arm", "forearm", "r"))], np.int64)
#: Per capsule: whether it lies past a limb's middle joint (a fold brings it toward the root).
DISTAL = np.array([c.startswith(("shank", "forearm", "hand")) for c in CAPSULES])
ANKLE_HEIGHT = np.array([LENGTH_INDEX["ankle_height_l"], LENGTH_INDEX["ankle_height_r"]],
                        np.int64)
_EXPORT = export_constants()


#: How far (m) a moved body's heel or ball may end under the ground before its separation is
#: undone (half the soles' 1 mm bound; the report shows it as penetration): undone for 1.3 µm,
#: defender_3 stood 22.7 mm into its kicker in the fight, and for 0.17 mm a defender 15 mm
#: into a 1.1 m kicker.
SUNK_M = 5e-4


class Claims(NamedTuple):
    """What the active constraints hold, per character: ``priority`` (n,) their highest (-inf:
    none); ``claimed`` (n, 6) the groups their chains claim; ``pin`` (n, 4, 3) each limb's pin
    (NaN: none): the point of its highest-priority active constraint, else the ankle of a foot
    planted in full (contact weight 1); ``aims_at`` (n, 4) the row of the character that constraint's target lies on (-1:
    none, the world, itself)."""

    priority: F64
    claimed: NDArray[np.bool_]
    pin: F64
    aims_at: I64


class Pushes(NamedTuple):
    """Each row's last push this tick: ``way`` (n, 3) its unit direction, ``chain`` (n,) the
    chain it moved (-1: none yet)."""

    way: F64
    chain: I64


def marked(n: int, *rows: I64) -> NDArray[np.bool_]:
    """(n + 1,) whether each row (of ``n``) is in any of ``rows`` (each (k,)); the last, row -1
    (none), in none."""
    marks = np.zeros(n + 1, bool)
    for some in rows:
        marks[some] = True
    return marks


def rows_in(n: int, *rows: I64) -> I64:
    """The rows (of ``n``) in any of ``rows`` (each (k,)), sorted, each once: ``np.union1d`` of
    them by marks (a round's sets are a few rows: union1d's sorts were a tenth of a round)."""
    found: I64 = marked(n, *rows)[:n].nonzero()[0]
    return found


def held(claims: Claims, rows: I64, limb: I64, partner: I64) -> NDArray[np.bool_]:
    """Whether each of ``rows``' ``limb`` (k,) is held by its pin against the ``partner`` row
    (k,) it overlaps: it has a pin, and the pin is not a constraint aiming at ``partner`` (a
    limb reaching for a body goes out of it to its surface, pin and all: that surface is its
    constraint's target, so its error measured to the surface does not grow). -> (k,)."""
    pinned: NDArray[np.bool_] = np.isfinite(claims.pin[rows, limb]).all(axis=1) \
        & (claims.aims_at[rows, limb] != partner)
    return pinned


class CollisionSeparate(System):
    reads = ("positions", "lengths", "poses", "posture", "contact_weight", "frozen",
             "local_rotations", "vertebrae", "constraints.weight")
    writes = ("poses", "positions", "posture", "local_rotations", "vertebrae", "capsule_ends",
              "capsule_radii", "overlap_m")

    def __init__(self, sim: Simulation) -> None:
        super().__init__(sim)
        #: Pairs reported as stuck (neither may move): (entity, entity, capsule, capsule);
        #: and the same as the codes of :meth:`_stuck_codes`, sorted.
        self.reported: set[tuple[int, int, str, str]] = set()
        self._reported_codes = np.zeros(0, np.int64)
        self._names: tuple[int, list[str]] = (-1, [])
        #: The rounds compiled (off: the numpy methods, their reference, for the tests).
        self.compiled = True
        #: The frame budget's clock for the rounds (s of CPU; a test may give its own).
        self.clock: Callable[[], float] = time.process_time
        #: This tick's rounds of search and separation, and whether the budget ended them.
        self.rounds = 0
        self.rounds_cut = False
        #: The capsules' arrays, kept from tick to tick (the store's ends and radii among them),
        #: and the rows whose capsules they hold (the others': NaN).
        self._body = Capsules.empty(0)
        self._made = np.zeros(0, np.int64)
        #: When the bodies' bounds last met none (the kernels' search): (the structure version
        #: and rows then, their bounds (n, 2, 3), each one's slack: half its clearance (n,) m);
        #: while none has moved by its slack, none meet (None: some met).
        self._apart: tuple[tuple[int, int], F64, F64] | None = None
        #: :meth:`_posture`'s arrays this tick (made at its first call).
        self._posture_args: tuple[Any, ...] | None = None

    def _rounds_allowed_s(self) -> float:
        """The CPU seconds the rounds may take this tick by the frame budget (inf: none):
        its aim less what the systems before this one took this tick and what those after it
        took last tick, per kernel thread."""
        budget_ms = self.sim.solver_settings.budget_ms
        if budget_ms is None:
            return np.inf
        systems = self.sim.systems
        mine = systems.index(self)
        others = sum(s.last_cpu_seconds for s in systems[:mine]) \
            + sum(s.last_cpu_seconds for s in systems[mine + 1:])
        return budget_ms * 1e-3 * TARGET_SHARE - others / max(threads(), 1)

    def run(self, dt: float) -> None:
        st = self.sim.store
        n = st.n
        self.rounds, self.rounds_cut = 0, False
        self._posture_args = None
        start_s, allowed_s = self.clock(), self._rounds_allowed_s()
        if st.capsule_ends.shape != (n, N_CAPSULES, 2, 3):
            st.capsule_ends = np.full((n, N_CAPSULES, 2, 3), np.nan)
            st.capsule_radii = np.full((n, N_CAPSULES), np.nan)
            self._made = np.zeros(0, np.int64)
        if self._body.ends is not st.capsule_ends or self._body.radii is not st.capsule_radii:
            self._body = Capsules.empty(n)._replace(ends=st.capsule_ends, radii=st.capsule_radii)
            # Arrays given from outside, or the rows a removal kept (renumbered): the rows made
            # are those holding capsules.
            self._made = np.flatnonzero(np.isfinite(st.capsule_radii[:, 0]))
        # The kernels, or while they compile aside (a first run) their numpy references, which
        # need no grid (grid None). On the kernels, every body's bounds from its joints (no
        # capsule made); the capsules, each capsule's bounds (what the search reads) and the
        # search only for the bodies whose bounds meet another's: a crowd that keeps apart costs
        # the bounds and the grid alone.
        on_kernels = self.sim.compiled
        grid: Grid | None = None
        if on_kernels:
            body = bounds(st.positions, st.lengths, self._body)
            apart = self._apart
            if apart is not None and apart[0] == (self.sim.structure_version, n) \
                    and not drifted(body.box, apart[1], apart[2]):
                # every body's bounds within half its clearance of where they were when no
                # two met: none meet now either (the grid would find none)
                st.overlap_m = np.zeros(n)
                self._forget(np.zeros(n, bool))
                return
            grid = grid_of(body)
            clearance = np.empty(n)
            # The clearances are kept only when no two bounds meet: bounds that met last tick
            # (no _apart) likely meet now, so the search measures no gap, and runs again to
            # measure them only if none met (a crowd with a few bodies close enough to meet
            # every tick, the bench's lanes, spares the gaps: a third of the search).
            near = touching(body, grid, None if apart is None else clearance)
            if near.size == 0 and apart is None:
                near = touching(body, grid, clearance)
            complete = np.zeros(n, bool)
            if near.size == 0:
                self._apart = ((self.sim.structure_version, n), body.box.copy(), 0.5 * clearance)
                st.overlap_m = np.zeros(n)
                self._forget(complete)
                return
            self._apart = None
            capsules(st.positions, st.lengths, body, near)
            complete[near] = True
            found = overlaps(body, grid, near)
        else:
            self._apart = None
            body = numpy_capsules.capsules(st.positions, st.lengths, self._body)
            complete = np.ones(n, bool)
            found = numpy_capsules.overlaps(body)
        if n < 2 or not (found.depth > SEPARATE_FROM_M).any():
            st.overlap_m = found.depth
            self._forget(complete)
            return
        claims = self._claims()
        pushed = Pushes(np.zeros((n, 3)), np.full(n, -1, np.int64))
        # The rows any round looks at: those overlapping anyone (a row outside has depth 0 and
        # stays so unless a round searches it again: then it joins).
        watch = np.flatnonzero(found.depth > 0.0)
        # Only overlapping bodies move: their poses as the solve left them, kept (each the
        # first time it overlaps) to go back to.
        kept = np.zeros(n, bool)
        snapshots: list[tuple[I64, NormalizedPoses]] = []
        ever = np.zeros(n, bool)
        # Rounds in a row in which each body's overlap did not shrink by STALL_SHARE; a body
        # at PATIENCE stops trying this tick (limbs at their turn, pairs that may not move):
        # the others go on. And rounds in a row in which the overlap of all the bodies still
        # trying, together, did not go STALL_SHARE below its least: at PATIENCE the rounds end
        # (a crowd whose moves mostly push its bodies into others: the bench's walkers).
        stalled = np.zeros(n, np.int64)
        stalled_all, least_all = 0, np.inf
        leg = self.sim.leg_length()
        for done in range(PASSES):
            spent_s = (self.clock() - start_s) / max(threads(), 1)
            if done and spent_s * (done + 1) / done > allowed_s:
                self.rounds_cut = True
                break
            self.rounds = done + 1
            fresh = watch[(found.depth[watch] > SEPARATE_FROM_M) & ~kept[watch]]
            if fresh.size:
                kept[fresh] = True
                snapshots.append((fresh, st.poses.take(fresh)))
            moved = self._separate(found, claims, pushed, stalled, watch, leg)
            if moved.size == 0:
                break
            was = found.depth[moved]
            ever[moved] = True
            self._posture(moved)
            # Only the moved bodies' capsules change; the overlaps found again are theirs and
            # those of the bodies that touched them.
            make = capsules if on_kernels else numpy_capsules.capsules
            make(st.positions, st.lengths, body, moved)
            if grid is not None:
                if not grid_holds(body, grid, moved):  # limbs reach out further sideways
                    grid = grid_of(body)
                self._complete(near_rows(body, grid, moved), complete)
            touched = rows_in(n, moved, watch[marked(n, moved)[found.other[watch]]])
            self._overlaps(body, grid, touched, found)
            watch = rows_in(n, watch, touched[found.depth[touched] > 0.0])
            shrank = found.depth[moved] <= (1.0 - STALL_SHARE) * was
            stalled[moved] = np.where(shrank, 0, stalled[moved] + 1)
            left = float(found.depth[watch[stalled[watch] < PATIENCE]].sum())
            stalled_all = 0 if left <= (1.0 - STALL_SHARE) * least_all else stalled_all + 1
            least_all = min(least_all, left)
            if stalled_all >= PATIENCE:
                break
        moved_ever = np.flatnonzero(ever)
        back = self._undo_feet_in_ground(moved_ever, snapshots)
        if back.size:  # their capsules as they stand again
            (capsules if on_kernels else numpy_capsules.capsules)(st.positions, st.lengths, body,
                                                                  back)
            if grid is not None and not grid_holds(body, grid, back):
                grid = grid_of(body)
        # Every body's deepest overlap as the tick ends, for the metrics: the moved bodies' and
        # those of every body whose bounds meet one of theirs (it may touch one that moved into
        # it); the others' are as found.
        near = near_rows(body, grid, moved_ever) if grid is not None \
            else numpy_capsules.near_rows(body, moved_ever)
        self._overlaps(body, grid, rows_in(n, moved_ever, near), found)
        st.overlap_m = found.depth
        self._forget(complete)

    def _forget(self, complete: NDArray[np.bool_]) -> None:
        """The store's capsules NaN for the rows made last tick and not this one (``complete``
        (n,): made this tick): the store holds the capsules of this tick's bodies or none."""
        made = np.flatnonzero(complete) if complete.any() else np.zeros(0, np.int64)
        # (last tick's rows not made this tick: by marks, not setdiff1d, whose sort and isin
        # were a seventh of a tick in a crowd that keeps apart)
        stale = self._made[~complete[self._made]] if self._made.size else self._made
        if stale.size:
            self._body.ends[stale] = np.nan
            self._body.radii[stale] = np.nan
        self._made = made

    @staticmethod
    def _overlaps(body: Capsules, grid: Grid | None, rows: I64 | None = None,
                  out: Overlaps | None = None) -> Overlaps:
        """:func:`~ecs_anim.runtime.kernels.capsules.overlaps` on ``grid``, or without one (None)
        its numpy reference (:func:`ecs_anim.runtime.capsule_overlaps.overlaps`)."""
        if grid is None:
            return numpy_capsules.overlaps(body, rows, out)
        return overlaps(body, grid, rows, out)

    def _complete(self, rows: I64, complete: NDArray[np.bool_]) -> None:
        """Each capsule's bounds for those of ``rows`` (k,) that have none yet this tick
        (``complete`` (n,), updated): bodies a moved one now reaches, which the search is
        about to look at."""
        st = self.sim.store
        new = rows[~complete[rows]]
        if new.size:
            capsules(st.positions, st.lengths, self._body, new)
            complete[new] = True

    def _claims(self) -> Claims:
        """Each character's priority, claimed groups, limbs' pins and whom each pin aims at
        (see :class:`Claims`)."""
        st, table = self.sim.store, self.sim.constraints
        n = st.n
        priority = np.full(n, -np.inf)
        claimed = np.zeros((n, 6), bool)
        pin = np.full((n, 4, 3), np.nan)
        aims_at = np.full((n, 4), -1, np.int64)
        planted = st.contact_weight >= 1.0  # a foot rising or landing may be moved
        pin[:, :2][planted] = st.positions[:, LIMB_END[:2]][planted]
        if table.m:
            on = np.flatnonzero(table.weight > 0)
            if on.size:
                np.maximum.at(priority, table.owner[on], table.priority[on])
                bits = (table.chain[on, None] >> np.arange(6)) & 1
                np.logical_or.at(claimed, table.owner[on], bits.astype(bool))
                limb = LIMB_OF_GROUP[table.group[on]]
                on, limb = on[limb >= 0], limb[limb >= 0]
                order = np.argsort(table.priority[on], kind="stable")  # the highest written last
                on, limb = on[order], limb[order]
                assert st.posture is not None
                pin[table.owner[on], limb] = point_positions(
                    st.posture, table.owner[on], table.segment[on], table.fraction[on],
                    table.offset[on])
                aims_at[table.owner[on], limb] = np.where(
                    (table.target_kind[on] == TARGET_BODY)
                    & (table.target_row[on] != table.owner[on]), table.target_row[on], -1)
        aims_at[:, :2][planted] = -1  # a foot down stays, whatever its leg aims at
        return Claims(priority, claimed, pin, aims_at)

    def _turns(self, rows: I64, partner: I64, capsule: I64, at: F64, way: F64, distance: F64,
               claims: Claims) -> tuple[F64, NDArray[np.bool_]]:
        """The turn (k, 3, 3) that moves each row's limb of ``capsule`` so that its point ``at``
        (k, 3) goes ``distance`` (k,) along ``way`` (k, 3), away from the ``partner`` row (k,)
        it overlaps: about the limb's root, or, held by a pin (:func:`held`), about the
        root-pin axis (the pin stays); and whether it can (k,) (a limb; a trunk or pelvis: with
        no foot down and no claim on the trunk, by a step, not a turn)."""
        st = self.sim.store
        chain = CAPSULE_CHAIN[capsule]
        k = rows.size
        turn = np.broadcast_to(np.eye(3), (k, 3, 3)).copy()
        can = np.zeros(k, bool)
        limb = np.flatnonzero(chain < 4)
        if limb.size:
            r, li = rows[limb], chain[limb]
            root = st.positions[r, LIMB_ROOT[li]]
            arm = at[limb] - root
            turn[limb] = rotation_toward(arm, arm + way[limb] * distance[limb, None],
                                         MAX_TURN_RAD)
            can[limb] = np.linalg.norm(arm, axis=1) > 1e-3
            pinned = held(claims, r, li, partner[limb])
            free_leg = limb[(li < 2) & ~pinned]
            if free_leg.size:  # a swinging leg turned about its hip keeps its foot above ground
                can[free_leg] &= self._foot_clear(rows[free_leg], chain[free_leg],
                                                  turn[free_leg])
            if pinned.any():
                p = np.flatnonzero(pinned)
                axis = normalize(claims.pin[r[p], li[p]] - root[p])
                rate = np.sum(np.cross(axis, arm[p]) * way[limb[p]], axis=1)
                lever = np.abs(rate) > MIN_LEVER_M
                angle = np.clip(distance[limb[p]] / np.where(lever, rate, np.inf),
                                -MAX_TURN_RAD, MAX_TURN_RAD)
                turn[limb[p]] = axis_angle(axis, angle)
                can[limb[p]] = lever
        core = chain == 5
        can[core] = ~claims.claimed[rows[core], TRUNK] \
            & ~(st.contact_weight[rows[core]] > 0).any(axis=1)
        can &= ~st.frozen[rows]
        return turn, can

    @staticmethod
    def _deflect(rows: I64, chain: I64, way: F64, distance: F64, pushed: Pushes) -> F64:
        """Each row's push (k, 3) m: ``distance`` (k,) along ``way`` (k, 3), unless it goes
        back against the last push of the same chain this tick (a limb between two others,
        pushed from one into the other): then square to that one, as far as it takes to go
        ``distance`` along ``way``, at most :data:`MAX_DEFLECTION` times it. Writes ``pushed``
        for the rows."""
        last = pushed.way[rows]
        back = np.sum(way * last, axis=1)
        back = np.where((pushed.chain[rows] == chain) & (back < 0.0), back, 0.0)
        aside = way - back[:, None] * last
        square = np.sum(aside * aside, axis=1)  # 1 - back^2: how much of way it keeps
        scale = np.minimum(distance / np.maximum(square, 1e-12), MAX_DEFLECTION * distance)
        push: F64 = aside * scale[:, None]
        pushed.way[rows] = aside / np.sqrt(np.maximum(square, 1e-24))[:, None]
        pushed.chain[rows] = chain
        return push

    def _fold(self, rows: I64, partner: I64, capsule: I64, push: F64,
              claims: Claims) -> tuple[F64, F64]:
        """How far (k,) m each row's limb folds (its end toward its root: the knee or elbow
        bends; negative: it unfolds) for ``push`` (k, 3) m of a point on its shank, forearm or
        hand: the part of the push along the root-end line, its root-end distance kept within
        :data:`MIN_FOLD_SHARE` and :data:`MAX_REACH_SHARE` of the limb's length; none for a
        limb held by its pin or any other chain. And the move that makes (k, 3) m (the end's;
        a point nearer the knee or elbow moves less: the next round sees it)."""
        st = self.sim.store
        chain = CAPSULE_CHAIN[capsule]
        k = rows.size
        fold, moved = np.zeros(k), np.zeros((k, 3))
        limb = np.flatnonzero(DISTAL[capsule] & ~st.frozen[rows])
        limb = limb[~held(claims, rows[limb], chain[limb], partner[limb])]
        if limb.size == 0:
            return fold, moved
        r, li = rows[limb], chain[limb]
        root_to_end = st.positions[r, LIMB_END[li]] - st.positions[r, LIMB_ROOT[li]]
        reach = np.linalg.norm(root_to_end, axis=1)
        inward = -root_to_end / np.maximum(reach, 1e-12)[:, None]
        length = st.lengths[r[:, None], LIMB_SEGMENTS[li]].sum(axis=1)
        fold[limb] = np.clip(np.sum(push[limb] * inward, axis=1),
                             np.minimum(reach - MAX_REACH_SHARE * length, 0.0),
                             np.maximum(reach - MIN_FOLD_SHARE * length, 0.0))
        moved[limb] = inward * fold[limb, None]
        return fold, moved

    def _foot_clear(self, rows: I64, side: I64, turn: F64) -> NDArray[np.bool_]:
        """Whether each of ``rows``' leg ``side`` (0 left, 1 right), turned by ``turn``
        (k, 3, 3) about its hip, keeps its ankle and toe above the ground (its heel and ball
        not under it: the metrics' penetration). -> (k,)."""
        st = self.sim.store
        hip = st.positions[rows, LIMB_ROOT[side]]
        ends = np.stack([st.positions[rows, LIMB_END[side]],
                         st.positions[rows, TOE[side]]], axis=1)  # (k, 2, 3)
        moved = hip[:, None] + np.einsum("kij,kej->kei", turn, ends - hip[:, None])
        clearance = np.stack([st.lengths[rows, ANKLE_HEIGHT[side]],
                              BALL_HEIGHT_PER_LEG * leg_length(st.lengths[rows])], axis=1)
        # The ground answers for every store row at once: the others' own feet stand in.
        xy = np.repeat(st.positions[:, LIMB_END[:1], :2], 2, axis=1)
        xy[rows] = moved[..., :2]
        under = self.row_ground().height(xy)[rows]
        clear: NDArray[np.bool_] = np.all(moved[..., 2] >= under + clearance, axis=1)
        return clear

    def _separate(self, found: Overlaps, claims: Claims, pushed: Pushes, stalled: I64,
                  watch: I64, leg: F64) -> I64:
        """Move the chains of this round's overlapping characters (see the module docstring)
        among ``watch`` (k,) that are still trying (``stalled`` (n,) below :data:`PATIENCE`);
        returns the rows moved. ``pushed``: each row's last push this tick (read, then
        written); ``leg`` (n,) each body's leg length, m. Compiled
        (:meth:`_separate_compiled`) unless ``self.compiled`` is off: then the numpy methods
        here, its reference (and while the kernels compile aside)."""
        if self.compiled and self.sim.compiled:
            return self._separate_compiled(found, claims, pushed, stalled, watch, leg)
        st = self.sim.store
        depth, other, mine, theirs, normal, point = found
        rows = watch[(depth[watch] > SEPARATE_FROM_M) & (stalled[watch] < PATIENCE)]
        if rows.size == 0:  # (the round after the last that moved anyone)
            return rows
        them = other[rows]
        way, at = normal[rows], point[rows]
        full = depth[rows] + MARGIN_M
        _, can_me = self._turns(rows, them, mine[rows], at, way, full, claims)
        _, can_them = self._turns(them, rows, theirs[rows], at, -way, full, claims)
        priority = claims.priority
        share = np.where(priority[rows] < priority[them], 1.0,
                         np.where(priority[rows] == priority[them], 0.5, 0.0))
        share = np.where(can_them & (stalled[them] < PATIENCE), share, 1.0) * can_me
        stuck = ~can_me & ~can_them
        if stuck.any():
            self._report_stuck(rows[stuck], them[stuck], mine[rows[stuck]],
                               theirs[rows[stuck]], depth)
        go = share > 0
        rows, them, share, way, at = rows[go], them[go], share[go], way[go], at[go]
        if rows.size == 0:
            return rows
        capsule = mine[rows]
        distance = depth[rows] * share + MARGIN_M
        chain = CAPSULE_CHAIN[capsule]
        push = self._deflect(rows, chain, way, distance, pushed)
        fold, folded = self._fold(rows, them, capsule, push, claims)
        push -= folded
        distance = np.linalg.norm(push, axis=1)
        way = push / np.maximum(distance, 1e-12)[:, None]
        turn, _ = self._turns(rows, them, capsule, at, way, distance, claims)
        limb = np.flatnonzero(fold != 0.0)
        if limb.size:
            r, li = rows[limb], chain[limb]
            total = st.lengths[r[:, None], LIMB_SEGMENTS[li]].sum(axis=1)
            fraction = np.where((li < 2)[:, None], st.poses.leg_fraction[r],
                                st.poses.arm_fraction[r])[np.arange(limb.size), li % 2]
            is_leg = li < 2
            st.poses.leg_fraction[r[is_leg], li[is_leg]] = (fraction - fold[limb] / total)[is_leg]
            st.poses.arm_fraction[r[~is_leg], li[~is_leg] - 2] = \
                (fraction - fold[limb] / total)[~is_leg]
        posture = st.posture
        assert posture is not None
        for side_of, parent, frames, local in (
                ((0, 1), posture.pelvis2world, posture.leg2world, st.poses.leg_frame),
                ((2, 3), posture.thorax2world, posture.arm2world, st.poses.arm_frame)):
            sel = np.isin(chain, side_of)
            if not sel.any():
                continue
            rs, side = rows[sel], chain[sel] - side_of[0]
            if side_of == (0, 1):  # a planted leg's foot stays as it stands in the world
                self._keep_feet(rs, side, turn[sel], held(claims, rs, side, them[sel]))
            world = turn[sel] @ frames[rs, side]
            q = quat_from_matrix(np.swapaxes(parent[rs], -1, -2) @ world)
            local[rs, side] = q / np.linalg.norm(q, axis=-1, keepdims=True)
        core = np.flatnonzero(chain == 5)
        if core.size:
            r = rows[core]
            step = np.zeros((core.size, 3))
            flat = way[core, :2]
            flat_len = np.linalg.norm(flat, axis=1)
            step[:, :2] = np.where((flat_len > 1e-9)[:, None],
                                   flat / np.maximum(flat_len, 1e-12)[:, None], 0.0) \
                * distance[core, None]
            st.poses.root_position[r] += step / leg_length(st.lengths[r])[:, None]
        return np.unique(rows)

    def _separate_compiled(self, found: Overlaps, claims: Claims, pushed: Pushes,
                           stalled: I64, watch: I64, leg: F64) -> I64:
        """:meth:`_separate` on the kernels: the pairs and whether each side may move
        (:func:`~ecs_anim.runtime.kernels.separate.try_rows`, :meth:`_turns`' second result),
        the ground asked about the free legs' feet only, then the shares and the moves
        (:func:`~ecs_anim.runtime.kernels.separate.share_and_push`, the rest of the numpy
        methods). Two calls a round: the numpy between them was half a round's cost."""
        st = self.sim.store
        posture, poses = st.posture, st.poses
        assert posture is not None
        depth, other, mine, theirs, normal, point = found
        w = 2 * watch.size
        rows, partner, capsule = (np.empty(w, np.int64) for _ in range(3))
        at, way, distance = np.empty((w, 3)), np.empty((w, 3)), np.empty(w)
        can, ask_ground = np.empty(w, bool), np.empty(w, bool)
        feet, clearance = np.empty((w, 2, 3)), np.empty((w, 2))
        k = try_rows(watch, depth, other, mine, theirs, normal, point, stalled,
                     SEPARATE_FROM_M, MARGIN_M, PATIENCE, st.positions, st.lengths, leg,
                     claims.pin, claims.aims_at,
                     np.ascontiguousarray(claims.claimed[:, TRUNK]), st.contact_weight,
                     st.frozen, CAPSULE_CHAIN, LIMB_ROOT, LIMB_END, TOE, ANKLE_HEIGHT,
                     BALL_HEIGHT_PER_LEG, MAX_TURN_RAD, MIN_LEVER_M, rows, partner, capsule, at,
                     way, distance, can, feet, clearance, ask_ground)
        if k == 0:  # (the round after the last that moved anyone)
            return rows[:0]
        legs = np.flatnonzero(ask_ground[:2 * k])
        if legs.size:
            under = self.row_ground().height_of(rows[legs], feet[legs, :, :2])
            can[legs] &= np.all(feet[legs, :, 2] >= under + clearance[legs], axis=1)
        stuck = np.empty(k, bool)
        moving = share_and_push(
            k, rows, partner, capsule, at, way, can, claims.priority, stalled, depth, PATIENCE,
            MARGIN_M, stuck, st.positions, st.lengths, leg, claims.pin, claims.aims_at,
            st.frozen, pushed.way, pushed.chain, posture.pelvis2world, posture.thorax2world,
            posture.leg2world, posture.arm2world, poses.leg_fraction, poses.arm_fraction,
            poses.leg_frame, poses.arm_frame, poses.foot_dir, poses.root_position,
            CAPSULE_CHAIN, DISTAL, LIMB_ROOT, LIMB_MIDDLE, LIMB_END, LIMB_SEGMENTS,
            MAX_TURN_RAD, MIN_LEVER_M, MAX_DEFLECTION, MIN_FOLD_SHARE, MAX_REACH_SHARE,
            distance)
        if stuck.any():  # (entries 0..k-1 as try_rows made them)
            s = np.flatnonzero(stuck)
            self._report_stuck(rows[s], partner[s], mine[rows[s]], theirs[rows[s]], depth)
        return rows_in(st.n, rows[k:k + moving])

    @staticmethod
    def _stuck_codes(entity_lo: I64, entity_hi: I64, capsule_lo: I64, capsule_hi: I64) -> I64:
        """One int64 (k,) per pair of bodies' capsules (entities below 2**23, capsules below
        2**8): the pairs reported are told apart in numpy, not one by one."""
        codes: I64 = (entity_lo << 40) | (entity_hi << 16) | (capsule_lo << 8) | capsule_hi
        return codes

    def _report_stuck(self, rows: I64, them: I64, mine: I64, theirs: I64, depth: F64) -> None:
        """Warn once about each pair of ``rows``' capsule ``mine`` and ``them``'s ``theirs``
        (k,) that overlap (``depth`` (n,) m) where neither may move."""
        st, sim = self.sim.store, self.sim
        first = rows < them
        lo, hi = np.where(first, rows, them), np.where(first, them, rows)
        cap_lo, cap_hi = np.where(first, mine, theirs), np.where(first, theirs, mine)
        codes = self._stuck_codes(st.entity[lo], st.entity[hi], cap_lo, cap_hi)
        reported = self._reported_codes
        at = np.minimum(np.searchsorted(reported, codes), max(reported.size - 1, 0))
        new = np.flatnonzero(reported[at] != codes) if reported.size \
            else np.arange(codes.size)
        if new.size == 0:
            return
        self._reported_codes = np.union1d(self._reported_codes, codes[new])
        if self._names[0] != sim.structure_version:  # (a list of every name)
            self._names = (sim.structure_version, sim.names())
        names = self._names[1]
        pairs = []
        for i, j, a, b, k in zip(rows[new], them[new], mine[new], theirs[new], new,
                                 strict=True):
            key = (int(st.entity[lo[k]]), int(st.entity[hi[k]]), CAPSULES[cap_lo[k]],
                   CAPSULES[cap_hi[k]])
            if key not in self.reported:  # (a pair twice in one round: reported once)
                self.reported.add(key)
                pairs.append((f"{names[i]}'s {CAPSULES[a]} and {names[j]}'s {CAPSULES[b]}",
                              f"{depth[i] * 1e3:.0f} mm"))
        # One line a round, its first pairs named: a crowd that ignores itself (the bench's)
        # meets tens of new pairs a tick, and a line each cost 4 ms a tick at 4,000 and
        # buried the output.
        if len(pairs) == 1:
            sim.warn(f"{pairs[0][0]} overlap by {pairs[0][1]} and neither may move")
        elif pairs:
            more = f" and {len(pairs) - STUCK_NAMED} more" if len(pairs) > STUCK_NAMED else ""
            named = "; ".join(f"{who} by {depth}" for who, depth in pairs[:STUCK_NAMED])
            sim.warn(f"{len(pairs)} pairs overlap where neither may move: {named}{more}")

    def _undo_feet_in_ground(self, moved: I64,
                             snapshots: list[tuple[I64, NormalizedPoses]]) -> I64:
        """A moved body whose heel or ball ended under the ground (a turn of a leg the checks
        did not foresee, several rounds adding up) goes back to its pose before the separation
        (``snapshots``: (rows, their poses) as each first overlapped): it may overlap, it never
        stands in the ground. Returns the rows put back (their posture remade)."""
        if moved.size == 0:
            return moved
        st = self.sim.store
        p, lengths = st.positions[moved], st.lengths[moved]
        heel = p[:, LIMB_END[:2], 2] - lengths[:, ANKLE_HEIGHT]
        ball = p[:, TOE, 2] - BALL_HEIGHT_PER_LEG * leg_length(lengths)[:, None]
        under = self.row_ground().height_of(moved, np.concatenate([p[:, LIMB_END[:2], :2],
                                                                   p[:, TOE, :2]], axis=1))
        sunk: NDArray[np.bool_] = np.any(np.concatenate([heel, ball], axis=1)
                                         < under - SUNK_M, axis=1)
        back = moved[sunk]
        if back.size == 0:
            return back
        for rows, poses in snapshots:
            mine = np.isin(rows, back)
            for name, value in poses.take(np.flatnonzero(mine)).arrays().items():
                getattr(st.poses, name)[rows[mine]] = value
        self._posture(back)
        return back

    def _keep_feet(self, rows: I64, side: I64, turn: F64, pinned: NDArray[np.bool_]) -> None:
        """A leg of ``rows`` held by its pin (``pinned`` (k,): its foot down, or its constraint
        met) turned by ``turn`` (k, 3, 3) about its hip-ankle axis keeps its foot's direction in
        the world (the ball it may stand on stays): the foot's direction in the shank frame is
        turned back. Call before the leg's frame is changed."""
        st = self.sim.store
        if not pinned.any():
            return
        rs, sd, tn = rows[pinned], side[pinned], turn[pinned]
        legs = decode_legs(st.poses.take(rs), st.lengths[rs], st.lengths[rs])
        shank = legs.shank2world[np.arange(rs.size), sd]  # (k, 3, 3)
        foot_in_world = np.einsum("kij,kj->ki", shank, st.poses.foot_dir[rs, sd])
        st.poses.foot_dir[rs, sd] = np.einsum("kji,kj->ki", tn @ shank, foot_in_world)

    def _posture(self, rows: I64) -> None:
        """PostureConvert again for ``rows`` (the compiled kernel, only those rows)."""
        sim = self.sim
        newly_bad = np.zeros(sim.store.n, bool)
        if not sim.compiled:  # the kernels compile aside (a first run)
            st = sim.store
            assert st.posture is not None and fits(st.posture, st.n)
            decoded = decoded_arrays(st.posture)._replace(positions=np.empty(st.positions.shape))
            posture_numpy(sim, rows, decoded, newly_bad, True)
        else:
            if self._posture_args is None:
                self._posture_args = self._posture_arrays()
            (poses, lengths, decoded, frozen, positions, rotations, scratch, local, k,
             spine) = self._posture_args
            over_chunks(posture_rows, rows.size, rows, poses, lengths, decoded, frozen,
                        newly_bad, positions, rotations, scratch, local, k.rest_hips,
                        k.bvh_from_world, k.rest2body, k.parents, spine, True,
                        spine_scratch(rows.size))
        if newly_bad.any():
            sim.report_frozen(np.flatnonzero(newly_bad))

    def _posture_arrays(self) -> tuple[Any, ...]:
        """:func:`~ecs_anim.runtime.kernels.posture.posture_rows`' arrays but the rows' own,
        made once a tick (the store's arrays do not change during the rounds)."""
        st, sim = self.sim.store, self.sim
        n = st.n
        posture = st.posture
        assert posture is not None and fits(posture, n)
        decoded = decoded_arrays(posture)._replace(positions=np.empty((n, N_JOINTS, 3)))
        rotations = bool(sim.rotations) and st.local_rotations.shape == (n, N_EXPORT, 3, 3)
        count = int(sim.vertebrae)
        spine = st.vertebrae if count and st.vertebrae is not None else np.empty((n, 0, 3))
        return (pose_arrays(st.poses), st.lengths, decoded, st.frozen, st.positions, rotations,
                np.empty((n if rotations else 0, N_EXPORT, 3, 3)),
                st.local_rotations if rotations else np.empty((0, N_EXPORT, 3, 3)), _EXPORT,
                spine)
