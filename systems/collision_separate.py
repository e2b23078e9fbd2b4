"""CollisionSeparate: every character's collision capsules, and bodies pushed apart (DESIGN §8b).

Each tick, after PostureConvert: every character's capsules from its posture (compiled over all
of them: :func:`ecs_anim.runtime.kernels.capsules.capsules`; the layout and radii in
:mod:`ecs_anim.solver.capsules`), and each one's deepest overlap with another character
(neighbours on a uniform grid: :func:`ecs_anim.runtime.kernels.capsules.overlaps`). Where two
characters overlap by more than :data:`SEPARATE_FROM_M`, the one of lower priority (the highest
priority of its active constraints; none: lowest) moves its chain that overlaps, if that chain is
free (no active constraint of its own claims it): a swinging limb turns about its hip or shoulder,
a planted leg swivels about its hip-ankle axis (its foot stays), a trunk or pelvis of a body with
no foot down steps aside. Equal priorities share the way; where the lower one's chain may not
move, the other's moves all of it; where neither may, the pair is reported once (a warning). A
moved character's posture is made again from its pose (the compiled PostureConvert kernel, only
its rows), and the search runs again, at most :data:`PASSES` times, while a round still takes
off :data:`STALL_SHARE` of the overlap left.

Rows: every character.
Reads: store.positions, lengths, poses, posture, contact_weight, frozen, local_rotations,
vertebrae; constraints.weight (which chains are claimed, and each character's priority).
Writes: store.poses, positions, posture, local_rotations, vertebrae (the moved characters);
capsule_ends, capsule_radii (every character's capsules, as they end), overlap_m (each
character's deepest overlap with another after the separation, m).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.body_points import ARM_L, HEAD, LEG_L, TRUNK, point_positions
from ecs_anim.core.ground_adapt import BALL_HEIGHT_PER_LEG, HEEL_TOLERANCE_M
from ecs_anim.core.morphology import leg_length
from ecs_anim.core.normalized import NormalizedPoses, decode_legs
from ecs_anim.core.rotations import axis_angle, normalize, quat_from_matrix
from ecs_anim.core.skeleton import JOINT_INDEX as J
from ecs_anim.core.skeleton import LENGTH_INDEX, N_JOINTS
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.capsules import Capsules, Overlaps, capsules, grid_of, overlaps
from ecs_anim.runtime.kernels.decode import decoded_arrays, fits, pose_arrays
from ecs_anim.runtime.kernels.posture import N_EXPORT, export_constants, posture_rows
from ecs_anim.runtime.system_base import System
from ecs_anim.solver.capsules import CAPSULES, N_CAPSULES
from ecs_anim.solver.steps import rotation_toward

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: Overlaps shallower than this are left (m).
SEPARATE_FROM_M = 0.5e-3
#: How far past touching a separated pair is pushed (m): the next tick's motion starts apart.
MARGIN_M = 0.5e-3
#: Most rounds of search and separation per tick.
PASSES = 8
#: A round that takes off less than this share of the overlap left ends the rounds.
STALL_SHARE = 0.1
#: The largest turn of a limb in one round (rad).
MAX_TURN_RAD = 0.25
#: A pinned limb whose point moves less than this per radian of swivel does not swivel (m).
MIN_LEVER_M = 0.03

# Per capsule: the chain that moves it: 0-3 a limb (leg_l, leg_r, arm_l, arm_r), 4 the head,
# 5 the root (trunk and pelvis); the group its claim is read from.
_CHAIN = {"shank_l": 0, "thigh_l": 0, "shank_r": 1, "thigh_r": 1, "upper_arm_l": 2,
          "forearm_l": 2, "hand_l": 2, "upper_arm_r": 3, "forearm_r": 3, "hand_r": 3,
          "head": 4, "pelvis": 5, "trunk": 5}
CAPSULE_CHAIN = np.array([_CHAIN[c] for c in CAPSULES], np.int64)
CHAIN_GROUP = np.array([LEG_L, LEG_L + 1, ARM_L, ARM_L + 1, HEAD, TRUNK], np.int64)
LIMB_OF_GROUP = np.array([0, 1, -1, 2, 3, -1], np.int64)  # group -> limb (-1: none)
LIMB_ROOT = np.array([J["hip_l"], J["hip_r"], J["shoulder_l"], J["shoulder_r"]], np.int64)
LIMB_END = np.array([J["ankle_l"], J["ankle_r"], J["wrist_l"], J["wrist_r"]], np.int64)
TOE = np.array([J["toe_l"], J["toe_r"]], np.int64)
ANKLE_HEIGHT = np.array([LENGTH_INDEX["ankle_height_l"], LENGTH_INDEX["ankle_height_r"]],
                        np.int64)
_EXPORT = export_constants()


class CollisionSeparate(System):
    reads = ("positions", "lengths", "poses", "posture", "contact_weight", "frozen",
             "local_rotations", "vertebrae", "constraints.weight")
    writes = ("poses", "positions", "posture", "local_rotations", "vertebrae", "capsule_ends",
              "capsule_radii", "overlap_m")

    def __init__(self, sim: Simulation) -> None:
        super().__init__(sim)
        #: Pairs reported as stuck (neither may move): (entity, entity, capsule, capsule).
        self.reported: set[tuple[int, int, str, str]] = set()

    def run(self, dt: float) -> None:
        st = self.sim.store
        n = st.n
        if st.capsule_ends.shape != (n, N_CAPSULES, 2, 3):
            st.capsule_ends = np.empty((n, N_CAPSULES, 2, 3))
            st.capsule_radii = np.empty((n, N_CAPSULES))
        body = capsules(st.positions, st.lengths,
                        Capsules(st.capsule_ends, st.capsule_radii, np.empty((n, 3)),
                                 np.empty(n), np.empty((n, 2, 3))))
        grid = grid_of(body)
        found = overlaps(body, grid)
        if n < 2 or not (found.depth > SEPARATE_FROM_M).any():
            st.overlap_m = found.depth
            return
        priority, claimed, pin = self._claims()
        left = float(found.depth.sum())
        # Only overlapping bodies move: their poses as the solve left them, kept (each the
        # first time it overlaps) to go back to.
        kept = np.zeros(n, bool)
        snapshots: list[tuple[I64, NormalizedPoses]] = []
        ever = np.zeros(n, bool)
        for _ in range(PASSES):
            fresh = np.flatnonzero((found.depth > SEPARATE_FROM_M) & ~kept)
            if fresh.size:
                kept[fresh] = True
                snapshots.append((fresh, st.poses.take(fresh)))
            moved = self._separate(found, priority, claimed, pin)
            if moved.size == 0:
                break
            ever[moved] = True
            self._posture(moved)
            # Only the moved bodies' capsules change; the overlaps found again are theirs and
            # those of the bodies that touched them (the grid holds: a turn or a step of a few
            # centimetres leaves every body within its cell's reach).
            capsules(st.positions, st.lengths, body, moved)
            touched = np.union1d(moved, np.flatnonzero(np.isin(found.other, moved)))
            overlaps(body, grid, touched, found)
            # Done when nothing overlaps, or a pass took off less than STALL_SHARE of what was
            # left (the rest is pairs that may not move, or limbs already at their turn).
            was, left = left, float(found.depth.sum())
            if not (found.depth > SEPARATE_FROM_M).any() or left > (1.0 - STALL_SHARE) * was:
                break
        self._undo_feet_in_ground(np.flatnonzero(ever), snapshots)
        # Every body's deepest overlap as the tick ends, for the metrics (a body the passes did
        # not look at again may touch one that moved into it).
        st.overlap_m = overlaps(body, grid_of(body)).depth

    def _claims(self) -> tuple[F64, NDArray[np.bool_], F64]:
        """(n,) each character's priority (its active constraints' highest; -inf: none),
        (n, 6) which of its groups an active constraint's chain claims, and (n, 4, 3) each
        limb's pin (NaN: none): the point of the limb's highest-priority active constraint, else
        a planted foot's ankle: a limb with a pin swivels about its root-pin axis."""
        st, table = self.sim.store, self.sim.constraints
        n = st.n
        priority = np.full(n, -np.inf)
        claimed = np.zeros((n, 6), bool)
        pin = np.full((n, 4, 3), np.nan)
        planted = st.contact_weight > 0
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
        return priority, claimed, pin

    def _turns(self, rows: I64, capsule: I64, at: F64, way: F64, distance: F64,
               claimed: NDArray[np.bool_], pin: F64) -> tuple[F64, NDArray[np.bool_]]:
        """The turn (k, 3, 3) that moves each row's limb of ``capsule`` so that its point ``at``
        (k, 3) goes ``distance`` (k,) along ``way`` (k, 3): about the limb's root, or, with a pin,
        about the root-pin axis (the pin stays); and whether it can (k,) (a limb; a trunk or
        pelvis: with no foot down and no claim on the trunk, by a step, not a turn)."""
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
            free_leg = limb[(li < 2) & ~np.isfinite(pin[r, li]).all(axis=1)]
            if free_leg.size:  # a swinging leg turned about its hip keeps its foot above ground
                can[free_leg] &= self._foot_clear(rows[free_leg], chain[free_leg],
                                                  turn[free_leg])
            pinned = np.isfinite(pin[r, li]).all(axis=1)
            if pinned.any():
                p = np.flatnonzero(pinned)
                axis = normalize(pin[r[p], li[p]] - root[p])
                rate = np.sum(np.cross(axis, arm[p]) * way[limb[p]], axis=1)
                lever = np.abs(rate) > MIN_LEVER_M
                angle = np.clip(distance[limb[p]] / np.where(lever, rate, np.inf),
                                -MAX_TURN_RAD, MAX_TURN_RAD)
                turn[limb[p]] = axis_angle(axis, angle)
                can[limb[p]] = lever
        core = chain == 5
        can[core] = ~claimed[rows[core], TRUNK] & ~(st.contact_weight[rows[core]] > 0).any(axis=1)
        can &= ~st.frozen[rows]
        return turn, can

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

    def _separate(self, found: Overlaps, priority: F64, claimed: NDArray[np.bool_],
                  pin: F64) -> I64:
        """Move the chains of this round's overlapping characters (see the module docstring);
        returns the rows moved."""
        st, sim = self.sim.store, self.sim
        depth, other, mine, theirs, normal, point = found
        rows = np.flatnonzero(depth > SEPARATE_FROM_M)
        them = other[rows]
        way, at = normal[rows], point[rows]
        full = depth[rows] + MARGIN_M
        _, can_me = self._turns(rows, mine[rows], at, way, full, claimed, pin)
        _, can_them = self._turns(them, theirs[rows], at, -way, full, claimed, pin)
        share = np.where(priority[rows] < priority[them], 1.0,
                         np.where(priority[rows] == priority[them], 0.5, 0.0))
        share = np.where(can_them, share, 1.0) * can_me
        stuck = ~can_me & ~can_them
        if stuck.any():
            names: list[str] | None = None  # made only when a pair is new (a list of every name)
            for i, j, a, b in zip(rows[stuck], them[stuck], mine[rows[stuck]],
                                  theirs[rows[stuck]], strict=True):
                key = (int(st.entity[min(i, j)]), int(st.entity[max(i, j)]),
                       CAPSULES[a if i < j else b], CAPSULES[b if i < j else a])
                if key not in self.reported:
                    self.reported.add(key)
                    names = sim.names() if names is None else names
                    sim.warn(f"{names[i]}'s {CAPSULES[a]} and {names[j]}'s {CAPSULES[b]} overlap "
                             f"by {depth[i] * 1e3:.0f} mm and neither may move")
        go = share > 0
        rows, share, way, at = rows[go], share[go], way[go], at[go]
        if rows.size == 0:
            return rows
        distance = depth[rows] * share + MARGIN_M
        capsule = mine[rows]
        turn, _ = self._turns(rows, capsule, at, way, distance, claimed, pin)
        chain = CAPSULE_CHAIN[capsule]
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
                self._keep_feet(rs, side, turn[sel], pin)
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

    def _undo_feet_in_ground(self, moved: I64,
                             snapshots: list[tuple[I64, NormalizedPoses]]) -> None:
        """A moved body whose heel or ball ended under the ground (a turn of a leg the checks
        did not foresee, several rounds adding up) goes back to its pose before the separation
        (``snapshots``: (rows, their poses) as each first overlapped): it may overlap, it never
        stands in the ground."""
        if moved.size == 0:
            return
        st = self.sim.store
        p = st.positions
        leg = leg_length(st.lengths)
        heel = p[:, LIMB_END[:2], 2] - st.lengths[:, ANKLE_HEIGHT]
        ball = p[:, TOE, 2] - BALL_HEIGHT_PER_LEG * leg[:, None]
        under = self.row_ground().height(np.concatenate([p[:, LIMB_END[:2], :2],
                                                         p[:, TOE, :2]], axis=1))
        sunk: NDArray[np.bool_] = np.any(np.concatenate([heel, ball], axis=1)
                                         < under - HEEL_TOLERANCE_M, axis=1)
        back = moved[sunk[moved]]
        if back.size == 0:
            return
        for rows, poses in snapshots:
            mine = np.isin(rows, back)
            for name, value in poses.take(np.flatnonzero(mine)).arrays().items():
                getattr(st.poses, name)[rows[mine]] = value
        self._posture(back)

    def _keep_feet(self, rows: I64, side: I64, turn: F64, pin: F64) -> None:
        """A pinned leg (its foot down) of ``rows`` turned by ``turn`` (k, 3, 3) about its
        hip-ankle axis keeps its foot's direction in the world (the ball it may stand on stays):
        the foot's direction in the shank frame is turned back. Call before the leg's frame is
        changed."""
        st = self.sim.store
        pinned = np.isfinite(pin[rows, side]).all(axis=1)
        if not pinned.any():
            return
        rs, sd, tn = rows[pinned], side[pinned], turn[pinned]
        legs = decode_legs(st.poses.take(rs), st.lengths[rs], st.lengths[rs])
        shank = legs.shank2world[np.arange(rs.size), sd]  # (k, 3, 3)
        foot_in_world = np.einsum("kij,kj->ki", shank, st.poses.foot_dir[rs, sd])
        st.poses.foot_dir[rs, sd] = np.einsum("kji,kj->ki", tn @ shank, foot_in_world)

    def _posture(self, rows: I64) -> None:
        """PostureConvert again for ``rows`` (the compiled kernel, only those rows)."""
        st, sim = self.sim.store, self.sim
        n = st.n
        posture = st.posture
        assert posture is not None and fits(posture, n)
        decoded = decoded_arrays(posture)._replace(positions=np.empty((n, N_JOINTS, 3)))
        rotations = bool(sim.rotations) and st.local_rotations.shape == (n, N_EXPORT, 3, 3)
        count = int(sim.vertebrae)
        spine = st.vertebrae if count and st.vertebrae is not None else np.empty((n, 0, 3))
        k = _EXPORT
        newly_bad = np.zeros(n, bool)
        over_chunks(posture_rows, rows.size, rows, pose_arrays(st.poses), st.lengths, decoded,
                    st.frozen, newly_bad, st.positions, rotations,
                    np.empty((n if rotations else 0, N_EXPORT, 3, 3)),
                    st.local_rotations if rotations else np.empty((0, N_EXPORT, 3, 3)),
                    k.rest_hips, k.bvh_from_world, k.rest2body, k.parents, spine, True)
        if newly_bad.any():
            sim.report_frozen(np.flatnonzero(newly_bad))
