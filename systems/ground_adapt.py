"""GroundAdapt: feet on the ground under each character (paper §7).

A foot entering contact gets a footprint: where the motion puts its ankle, on the ground under
it. The footprint stays locked in the world for the whole contact (no sliding), the pelvis is
lowered only as far as the legs in contact need (``min(h1, h2, h3)``), legs are re-aimed
analytically, free feet ride on the ground level of the supporting feet and are lifted clear of
steps, a heel the stretched leg would put under a step is lifted, and a planted foot whose toe
would go into a step is pitched up onto it.

Rows: every character, grouped by ground (``System.ground_groups``: its own GroundQuery or the
environment's).
Reads: store.poses (the pelvis and legs, decoded here on each body: MorphologyAdapt's scaling),
contact_weight, lengths, clip, footprint, locked, footprint_settled, ground_ref (the last
tick's), ground_index; the ground; the bank's ankle heights.
Writes: store.poses (root height, leg frames and fractions, foot directions), footprint, locked,
footprint_settled, ground_ref.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ecs_anim.core.ground import Ground, GroundDescription, describe
from ecs_anim.core.ground_adapt import (
    BALL_HEIGHT_PER_LEG,
    HEEL_TOLERANCE_M,
    MAX_LEG_EXTENSION,
    adapt_keeping_heels_up,
    heel_depth,
)
from ecs_anim.core.normalized import SIDE_LENGTHS, decode_legs
from ecs_anim.runtime.kernels import over_chunks
from ecs_anim.runtime.kernels.decode import leg_pose_arrays, pose_arrays
from ecs_anim.runtime.kernels.ground_adapt import ground_adapt_rows
from ecs_anim.runtime.kernels.playback import writable_poses
from ecs_anim.runtime.system_base import System

if TYPE_CHECKING:
    from ecs_anim.runtime.simulation import Simulation

#: Time constant (s) with which the motion's floor follows the ground under the supporting feet.
GROUND_SMOOTHING_S = 0.15

#: Passes lifting heels (``adapt_keeping_heels_up``) and pitching toes onto the ground.
HEEL_PASSES = 4
TOE_PASSES = 4

def _own(a: NDArray[Any]) -> NDArray[Any]:
    """``a`` if a kernel may write it in place, else a contiguous copy of it."""
    return a if a.flags.c_contiguous and a.flags.writeable and a.flags.owndata else a.copy()


class GroundAdapt(System):
    """Adapts with the compiled :mod:`ecs_anim.runtime.kernels.ground_adapt` on a built-in ground; a
    ground of the user's own (only its numpy ``height``) goes through :meth:`run_numpy`."""

    reads = ("poses", "contact_weight", "lengths", "clip", "footprint", "locked",
             "footprint_settled", "ground_ref", "ground_index")
    writes = ("footprint", "locked", "footprint_settled", "ground_ref", "poses")

    def __init__(self, sim: Simulation):
        super().__init__(sim)
        self._descriptions: dict[int, tuple[Ground, GroundDescription | None]] = {}

    def _description(self, ground: Ground) -> GroundDescription | None:
        """The ground's compiled description, made once per ground object."""
        known = self._descriptions.get(id(ground))
        if known is None or known[0] is not ground:
            known = self._descriptions[id(ground)] = ground, describe(ground)
        return known[1]

    def run(self, dt: float) -> None:
        sim, st = self.sim, self.sim.store
        groups = [(rows, self._description(ground)) for ground, rows in self.ground_groups()]
        if any(description is None for _, description in groups):
            self.run_numpy(dt)
            return
        pose = leg_pose_arrays(pose_arrays(writable_poses(st.poses, st.n)))
        st.footprint, st.locked = _own(st.footprint), _own(st.locked)
        st.footprint_settled, st.ground_ref = _own(st.footprint_settled), _own(st.ground_ref)
        lengths, leg = np.ascontiguousarray(st.lengths), sim.leg_length()
        contact_weight = np.ascontiguousarray(st.contact_weight)
        for rows, description in groups:
            assert description is not None
            ground = (description.kinds, description.params, description.grid)
            over_chunks(ground_adapt_rows, rows.size, rows.copy(), pose, lengths, leg,
                        contact_weight, st.clip, sim.bank.source_ankle_height, st.footprint,
                        st.locked, st.footprint_settled, st.ground_ref, ground, dt,
                        GROUND_SMOOTHING_S, BALL_HEIGHT_PER_LEG, MAX_LEG_EXTENSION,
                        HEEL_TOLERANCE_M, HEEL_PASSES, TOE_PASSES)

    def run_numpy(self, dt: float) -> None:
        """The numpy reference of :meth:`run` (any ground with a ``height``; each character on
        its own)."""
        sim, st = self.sim, self.sim.store
        ground = self.row_ground()
        motion_legs = decode_legs(st.poses, st.lengths, st.lengths)
        leg = sim.leg_length()
        ankle_height = st.lengths[:, SIDE_LENGTHS["ankle_height"]]  # (n, 2)
        motion_ankle_height = sim.bank.source_ankle_height[st.clip] * leg[:, None]
        ball = BALL_HEIGHT_PER_LEG * leg[:, None]
        ankles, toes = motion_legs.ankles, motion_legs.toes
        w = st.contact_weight
        # Footprints: where the motion's ankle is, standing on the ground under it (raised by as
        # much as the motion's ankle is above its standing height).
        ground_at_ankle = ground.height(ankles[..., :2])
        above_standing = np.maximum(ankles[..., 2] - motion_ankle_height, 0.0)
        landing = ankles.copy()
        landing[..., 2] = ground_at_ankle + ankle_height + above_standing
        starting = (w > 0.0) & ~st.locked
        st.footprint = np.where(starting[..., None], landing, st.footprint)
        # A contact is locked as it starts to ramp in, while the motion's foot is still coming
        # down: until its first fully planted tick the footprint goes down with it (it stood
        # 10-39 mm in the air on flat ground), never up; then its height is fixed too.
        settling = (w > 0.0) & ~starting & ~st.footprint_settled
        settled_z = ground.height(st.footprint[..., :2]) + ankle_height + above_standing
        st.footprint[..., 2] = np.where(settling, np.minimum(st.footprint[..., 2], settled_z),
                                        st.footprint[..., 2])
        st.locked = w > 0.0
        st.footprint_settled = st.locked & ((st.footprint_settled & ~starting) | (w >= 1.0))
        # The motion's floor follows the ground under the supporting feet, smoothly.
        support = w.sum(axis=1)
        under_feet = np.sum(w * (st.footprint[..., 2] - ankle_height), axis=1) / np.maximum(support, 1e-9)
        under_pelvis = ground.height(motion_legs.pelvis[:, :2])
        target = np.where(support > 0.0, under_feet, under_pelvis)
        st.ground_ref += (1.0 - np.exp(-dt / GROUND_SMOOTHING_S)) * (target - st.ground_ref)
        # Free feet ride on that floor, lifted where heel or toe would go under the ground.
        free = ankles.copy()
        free[..., 2] += st.ground_ref[:, None]
        need_heel = heel_depth(ground, free, ankle_height)
        need_toe = ground.height(toes[..., :2]) + ball - (toes[..., 2] + st.ground_ref[:, None])
        free[..., 2] += np.maximum(0.0, np.maximum(need_heel, need_toe))
        # A planted foot's target is its footprint (the kernel does not ask where it would be).
        targets = np.where((w == 1.0)[..., None], st.footprint,
                           free + w[..., None] * (st.footprint - free))
        # While a contact ramps in, the blend can cross a step edge: keep the heel above ground.
        targets[..., 2] += np.maximum(heel_depth(ground, targets, ankle_height), 0.0)
        root_height = motion_legs.pelvis[:, 2] + st.ground_ref
        poses, legs = adapt_keeping_heels_up(st.poses, st.lengths, targets, w, root_height, motion_legs,
                                             ground, HEEL_PASSES)
        st.poses = self._toes_onto_ground(poses, legs, ball, TOE_PASSES)

    def _toes_onto_ground(self, poses, legs, ball, passes: int = TOE_PASSES):  # type: ignore[no-untyped-def]
        """Pitch a foot up about its ankle where its toe joint would be under the ground
        (``legs``: the decoded legs of ``poses``).

        Raising the toe moves it horizontally too (onto the next step, say), so the ground is
        asked again at the new place, a few passes.
        """
        ground = self.row_ground()
        ankles, toes = legs.ankles, legs.toes
        deficit = ground.height(toes[..., :2]) + ball - toes[..., 2]
        if not np.any(deficit > 0.0):
            return poses
        foot = np.maximum(np.linalg.norm(toes - ankles, axis=-1), 1e-9)
        d = (toes - ankles) / foot[..., None]
        horizontal = d[..., :2] / np.maximum(np.linalg.norm(d[..., :2], axis=-1), 1e-9)[..., None]
        dz = d[..., 2]
        for _ in range(passes):
            dz = np.clip(dz + np.maximum(deficit, 0.0) / foot, -1.0, 1.0)
            toe = ankles + foot[..., None] * np.concatenate(
                [horizontal * np.sqrt(1.0 - dz**2)[..., None], dz[..., None]], -1)
            deficit = ground.height(toe[..., :2]) + ball - toe[..., 2]
        new_d = (toe - ankles) / foot[..., None]
        changed = np.abs(new_d - d).max(axis=-1) > 0.0
        in_shank = np.einsum("...ji,...j->...i", legs.shank2world, new_d)
        poses.foot_dir = np.where(changed[..., None], in_shank, poses.foot_dir)
        return poses
