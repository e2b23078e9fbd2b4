"""PostureConvert: rebuild knees, elbows and vertebrae and give the world posture (paper §8).

Rows: every character.
Reads: store.poses, store.lengths, frozen, and the last good positions, local_rotations and
vertebrae (kept for a frozen character). Writes: store.positions (world joint positions), store.posture
(the same with the body frames, for next tick's targets on other characters), store.
local_rotations (the BVH export skeleton's local joint rotation matrices, when the simulation
asks for rotations), store.vertebrae (when it asks for a finer spine), store.frozen (a character
whose pose went non-finite keeps its last good posture and is reported once).
"""

from __future__ import annotations

import numpy as np

from ecs_anim.exporting import local_rotations
from ecs_anim.normalized import decode, vertebrae
from ecs_anim.system_base import System


class PostureConvert(System):
    reads = ("poses", "lengths", "frozen", "positions", "local_rotations", "vertebrae")
    writes = ("frozen", "positions", "posture", "local_rotations", "vertebrae")

    def run(self, dt: float) -> None:
        st = self.sim.store
        final = decode(st.poses, st.lengths)
        good = np.all(np.isfinite(final.positions), axis=(1, 2))
        # Joint rotations cost more than the positions; they are made when something uses them
        # (BVH export, a viewer drawing skinned meshes): ``Simulation(rotations=True)``.
        local = local_rotations(final) if self.sim.rotations else None
        if local is not None:
            good &= np.all(np.isfinite(local), axis=(1, 2, 3))
        newly_bad = ~good & ~st.frozen
        if newly_bad.any():
            self.sim.report_frozen(np.flatnonzero(newly_bad))
        st.frozen |= ~good
        keep = st.frozen[:, None, None]
        st.positions = np.where(keep, st.positions, final.positions)
        # Next tick's targets on other characters read this posture, frames included.
        final.positions = st.positions
        st.posture = final
        if local is not None:
            if st.local_rotations.shape != local.shape:
                st.local_rotations = np.broadcast_to(np.eye(3), local.shape).copy()
            st.local_rotations = np.where(keep[..., None], st.local_rotations, local)
        if self.sim.vertebrae:
            spine = vertebrae(st.poses, st.lengths, self.sim.vertebrae)
            previous = st.vertebrae if st.vertebrae is not None else spine
            st.vertebrae = np.where(keep, previous, spine)
