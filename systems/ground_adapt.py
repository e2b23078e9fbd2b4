"""GroundAdapt: feet on the ground under each character (paper §7).

A foot in contact stands on one point of its sole, its footprint, on the ground: the heel or the
ball, as the motion plants it (its sole roll: heel strike, flat, heel off). The footprint is
laid where the motion puts that point when the contact starts and stays locked in the world (no
sliding); it moves to the other point only once the foot has rolled onto it, so a foot turns
about the point it stands on. The foot keeps the motion's pitch unless that would put its other
end under the ground. The pelvis is lowered only as far as the legs in contact need
(``min(h1, h2, h3)``), legs are re-aimed analytically, free feet ride on the ground level of
the supporting feet and are lifted clear of steps, a heel the stretched leg would put under a
step is lifted.

Rows: every character, grouped by ground (``System.ground_groups``: its own GroundQuery or the
environment's); under a frame budget that cannot hold otherwise, those due this tick
(:mod:`ecs_anim.runtime.update_rate`; a row last updated k ticks ago follows its ground over
k ticks, and is stopped at a rise after as many ticks of walking).
A character walking into a rise taller than it can step up stops in front of it
(:meth:`GroundAdapt.stop_at_rises`).

Reads: store.poses (the pelvis and legs, decoded here on each body: MorphologyAdapt's scaling),
contact_weight, sole_roll, lengths, clip, footprint, locked, pivot, ground_ref (the last
tick's), ground_index, positions (the last posture's pelvis), placement_xy, fade_placement_xy;
the ground; the bank's ankle heights.
Writes: store.poses (root position, leg frames and fractions, foot directions), footprint,
locked, pivot, ground_ref, placement_xy and fade_placement_xy (held back at a rise).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground import Ground, GroundDescription, describe, sheerest
from ecs_anim.core.ground_adapt import (
    BALL_HEIGHT_PER_LEG,
    GROUND_SMOOTHING_S,
    HEEL_TOLERANCE_M,
    MAX_LEG_EXTENSION,
    STEP_UP_PER_LEG,
    SWITCH_PER_LEG,
    adapt_keeping_heels_up,
    heel_depth,
    pitched,
    pivot_wanted,
    planted_foot,
)
from ecs_anim.core.normalized import SIDE_LENGTHS, decode_legs
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import leg_pose_arrays, pose_arrays
from ecs_anim.runtime.kernels.ground_adapt import ground_adapt_rows, ground_scratch
from ecs_anim.runtime.kernels.lanes import BLOCK
from ecs_anim.runtime.kernels.playback import writable_poses
from ecs_anim.runtime.system_base import System

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

#: How far ahead of the pelvis, along the way it goes, a rise too tall to step up stops a
#: character (per leg length): past the toes of a walking stride's front foot ...
STOP_AHEAD_PER_LEG = 1.0
#: ... looked at every this far (per leg length: 8.5 cm for a 0.85 m leg), closer than a stair's
#: run, so a rise is one riser's height, not a flight's.
STOP_SAMPLE_PER_LEG = 0.1
#: A root moving more than this since the last posture (per leg length) is no walk into a rise
#: (a first tick, a character placed anew): nothing is held back.
MAX_ADVANCE_PER_LEG = 0.2

#: Passes lifting heels (``adapt_keeping_heels_up``) and pitching toes onto the ground.
HEEL_PASSES = 4
TOE_PASSES = 4

def _own(a: NDArray[Any]) -> NDArray[Any]:
    """``a`` if a kernel may write it in place, else a contiguous copy of it."""
    return a if a.flags.c_contiguous and a.flags.writeable and a.flags.owndata else a.copy()


class GroundAdapt(System):
    """Adapts with the compiled :mod:`ecs_anim.runtime.kernels.ground_adapt` on a built-in ground; a
    ground of the user's own (only its numpy ``height``), or any while the kernels compile
    aside, goes through :meth:`run_numpy`."""

    follows_update_rate = True
    reads = ("poses", "contact_weight", "sole_roll", "lengths", "clip", "footprint", "locked",
             "pivot", "ground_ref", "ground_index", "positions", "placement_xy",
             "fade_placement_xy")
    writes = ("footprint", "locked", "pivot", "ground_ref", "poses", "placement_xy",
              "fade_placement_xy")

    def __init__(self, sim: Simulation):
        super().__init__(sim)
        self._descriptions: dict[int, tuple[Ground, GroundDescription | None]] = {}
        self._scratch = ground_scratch(0)  # the kernel's, kept for the next tick's rows

    def _description(self, ground: Ground) -> GroundDescription | None:
        """The ground's compiled description, made once per ground object."""
        known = self._descriptions.get(id(ground))
        if known is None or known[0] is not ground:
            known = self._descriptions[id(ground)] = ground, describe(ground)
        return known[1]

    def run(self, dt: float) -> None:
        sim, st = self.sim, self.sim.store
        leg = sim.leg_length()  # (once a tick: 0.05 ms at 4,000; the lengths stay meanwhile)
        self.stop_at_rises(leg)
        groups = [(rows, self._description(ground)) for ground, rows in self.ground_groups()]
        if not sim.compiled or any(description is None for _, description in groups):
            self.run_numpy(dt)  # (every row: the update rate rests none then)
            return
        pose = leg_pose_arrays(pose_arrays(writable_poses(st.poses, st.n)))
        st.footprint, st.locked = _own(st.footprint), _own(st.locked)
        st.pivot, st.ground_ref = _own(st.pivot), _own(st.ground_ref)
        lengths = np.ascontiguousarray(st.lengths)
        contact_weight = np.ascontiguousarray(st.contact_weight)
        roll = np.ascontiguousarray(st.sole_roll)
        for ground_rows, description in groups:
            assert description is not None
            ground = (description.kinds, description.params, description.grid)
            # (a row last updated k ticks ago follows its ground over k ticks)
            for ticks, rows in sim.update_rate.due_groups(sim, ground_rows):
                over_chunks(ground_adapt_rows, rows.size, rows.copy(), pose, lengths, leg,
                            contact_weight, roll, st.clip, sim.bank.source_ankle_height,
                            st.footprint, st.locked, st.pivot, st.ground_ref, ground,
                            ticks * dt, GROUND_SMOOTHING_S, BALL_HEIGHT_PER_LEG,
                            MAX_LEG_EXTENSION, HEEL_TOLERANCE_M, SWITCH_PER_LEG, HEEL_PASSES,
                            TOE_PASSES, self._scratch_for(rows.size), rows_per_thread=BLOCK)

    def _scratch_for(self, n: int) -> NDArray[np.float64]:
        """The kernel's scratch for ``n`` rows (:func:`.kernels.ground_adapt.ground_scratch`),
        kept from tick to tick (made anew only when more rows come)."""
        if self._scratch.shape[0] < n // BLOCK + 1:
            self._scratch = ground_scratch(n)
        return self._scratch

    def stop_at_rises(self, leg: NDArray[np.float64]) -> None:
        """Hold back each character walking into a rise taller than it can step up
        (:data:`~ecs_anim.core.ground_adapt.STEP_UP_PER_LEG` of its leg, between two points
        :data:`STOP_SAMPLE_PER_LEG` apart) within :data:`STOP_AHEAD_PER_LEG` ahead of its
        pelvis: its root does not advance this tick, nor its motion's origin (``placement_xy``,
        ``fade_placement_xy``) after it, so it treads where it is, its feet outside the rise,
        until its motion turns away. All characters at once (numpy); the advance is since the
        last posture (a character updated every few ticks only walks that many ticks' worth).
        ``leg`` (n,) each character's leg length (``sim.leg_length()``), m."""
        st = self.sim.store
        if st.n == 0 or st.positions.shape[0] != st.n:
            return
        if all(self._walkable(ground, float(leg.min())) for ground, _ in self.ground_groups()):
            return  # (the usual case: nothing to look at every tick)
        root_xy = st.poses.root_position[:, :2] * leg[:, None]  # the pelvis, world m
        advance = root_xy - st.positions[:, 0, :2]
        step = np.linalg.norm(advance, axis=1)
        ticks = self.sim.update_rate.elapsed_ticks(self.sim)
        walking = (step > 1e-9) & (step < MAX_ADVANCE_PER_LEG * leg * (1 if ticks is None else ticks))
        if not walking.any():
            return
        way = advance / np.maximum(step, 1e-9)[:, None]
        reach = np.arange(0.0, STOP_AHEAD_PER_LEG + 1e-9, STOP_SAMPLE_PER_LEG)  # (k,) per leg
        ahead = root_xy[:, None] + way[:, None] * (reach[None] * leg[:, None])[..., None]
        heights = self.row_ground().height(ahead)  # (n, k)
        rise = np.diff(heights, axis=1).max(axis=1)
        stopped = walking & (rise > STEP_UP_PER_LEG * leg)
        if stopped.any():
            back = advance[stopped]
            writable_poses(st.poses, st.n).root_position[stopped, :2] -= back / leg[stopped, None]
            st.placement_xy[stopped] -= back
            st.fade_placement_xy[stopped] -= back

    def _walkable(self, ground: Ground, shortest_leg_m: float) -> bool:
        """Whether no two points :data:`STOP_SAMPLE_PER_LEG` apart on a built-in ``ground`` can
        rise more than the shortest leg steps up (its :func:`~ecs_anim.core.ground.sheerest`
        bounds it; a ground of one's own may rise anywhere)."""
        if self._description(ground) is None:
            return False
        step_m, grade = sheerest(ground)
        return step_m + grade * STOP_SAMPLE_PER_LEG * shortest_leg_m \
            <= STEP_UP_PER_LEG * shortest_leg_m

    def run_numpy(self, dt: float) -> None:
        """The numpy reference of :meth:`run` (any ground with a ``height``; each character on
        its own)."""
        sim, st = self.sim, self.sim.store
        ground = self.row_ground()
        motion_legs = decode_legs(st.poses, st.lengths, st.lengths)
        leg = sim.leg_length()
        ankle_height = st.lengths[:, SIDE_LENGTHS["ankle_height"]]  # (n, 2)
        ball = np.broadcast_to(BALL_HEIGHT_PER_LEG * leg[:, None], ankle_height.shape)
        ankles, toes = motion_legs.ankles, motion_legs.toes
        foot = np.maximum(np.linalg.norm(toes - ankles, axis=-1), 1e-9)
        d = (toes - ankles) / foot[..., None]
        w = st.contact_weight
        # Footprints: laid on the sole point the motion plants (the lower of the two where it
        # plants both) as a contact starts, moved onto the other once the foot rolled onto it.
        starting = (w > 0.0) & ~st.locked
        heel_up = ankles[..., 2] - sim.bank.source_ankle_height[st.clip] * leg[:, None]
        lower = np.where(heel_up <= toes[..., 2] - ball, 0, 1)
        pivot = np.where(starting, pivot_wanted(st.sole_roll, lower), st.pivot)
        point = np.where((pivot == 0)[..., None], ankles, toes)
        laid = np.concatenate([point[..., :2], ground.height(point[..., :2])[..., None]], -1)
        footprint = np.where(starting[..., None], laid, st.footprint)
        stand, stand_d = planted_foot(ground, pivot, footprint, d, foot, ankle_height, ball,
                                      TOE_PASSES)
        want = pivot_wanted(st.sole_roll, pivot)
        other = np.where((want == 1)[..., None], stand + foot[..., None] * stand_d, stand)
        other_ground = ground.height(other[..., :2])
        above = other[..., 2] - np.where(want == 1, ball, ankle_height) - other_ground
        rolls = (w > 0.0) & (want != pivot) & (above <= SWITCH_PER_LEG * leg[:, None])
        pivot = np.where(rolls, want, pivot)
        footprint = np.where(rolls[..., None], np.concatenate(
            [other[..., :2], other_ground[..., None]], -1), footprint)
        rolled, rolled_d = planted_foot(ground, pivot, footprint, stand_d, foot, ankle_height,
                                        ball, TOE_PASSES)
        stand = np.where(rolls[..., None], rolled, stand)
        stand_d = np.where(rolls[..., None], rolled_d, stand_d)
        st.footprint, st.pivot, st.locked = footprint, pivot, w > 0.0
        # The motion's floor follows the ground under the supporting feet, smoothly.
        support = w.sum(axis=1)
        under_feet = np.sum(w * footprint[..., 2], axis=1) / np.maximum(support, 1e-9)
        under_pelvis = ground.height(motion_legs.pelvis[:, :2])
        target = np.where(support > 0.0, under_feet, under_pelvis)
        st.ground_ref += (1.0 - np.exp(-dt / GROUND_SMOOTHING_S)) * (target - st.ground_ref)
        # Free feet ride on that floor, lifted where heel or toe would go under the ground.
        free = ankles.copy()
        free[..., 2] += st.ground_ref[:, None]
        need_heel = heel_depth(ground, free, ankle_height)
        need_toe = ground.height(toes[..., :2]) + ball - (toes[..., 2] + st.ground_ref[:, None])
        free[..., 2] += np.maximum(0.0, np.maximum(need_heel, need_toe))
        # A planted foot's target is where it stands (the kernel does not ask where it would be).
        targets = np.where((w == 1.0)[..., None], stand, free + w[..., None] * (stand - free))
        # While a contact ramps in, the blend can cross a step edge: keep the heel above ground.
        targets[..., 2] += np.maximum(heel_depth(ground, targets, ankle_height), 0.0)
        root_height = motion_legs.pelvis[:, 2] + st.ground_ref
        poses, legs = adapt_keeping_heels_up(st.poses, st.lengths, targets, w, root_height, motion_legs,
                                             ground, HEEL_PASSES)
        # Feet: a planted one pitched as it stands (in the world, whatever the leg's new bend),
        # a ramping one as the motion has it in the world, a free one as in its shank; none
        # with its toe under the ground.
        new_foot = np.maximum(np.linalg.norm(legs.toes - legs.ankles, axis=-1), 1e-9)
        shank_d = (legs.toes - legs.ankles) / new_foot[..., None]
        wanted_d = np.where((w >= 1.0)[..., None], stand_d, np.where((w > 0.0)[..., None], d,
                                                                      shank_d))
        new_d = pitched(ground, legs.ankles, wanted_d, new_foot, 1.0, ball, TOE_PASSES)
        write = (w > 0.0) | (new_d[..., 2] != wanted_d[..., 2])
        in_shank = np.einsum("...ji,...j->...i", legs.shank2world, new_d)
        poses.foot_dir = np.where(write[..., None], in_shank, poses.foot_dir)
        st.poses = poses
