"""MorphologyAdapt: the normalized poses on each character's own body (paper §6, eq. 2).

Rows: characters with a Morphology. A body replaced while playing (``Simulation.set_body``)
is taken in on the next tick, before the decode (:func:`ecs_anim.body_change.adopt_bodies`).

Reads: store.poses, store.lengths; on a body change the Morphology components, segment_mass_kg,
segment_com_fraction, placement_*, fade_placement_*, posture (whether the character has played).
Writes: on a body change lengths, segment_mass_kg, segment_com_fraction, placement_xy,
fade_placement_xy (it stays where it stands), the root of poses, locked (its feet re-plant);
store.scaled: the pelvis and legs on each body before ground adaptation (the pelvis and leg joint
positions, pelvis2world and leg2world: what GroundAdapt reads; the upper body is decoded once,
by PostureConvert), in place when the store's arrays still fit (compiled
:func:`ecs_anim.kernels.decode.decode_legs`).
"""

from __future__ import annotations

from ecs_anim.body_change import adopt_bodies
from ecs_anim.components import Morphology
from ecs_anim.kernels.decode import decode_legs, fits
from ecs_anim.system_base import System


class MorphologyAdapt(System):
    query = (Morphology,)
    on_structure_change = (adopt_bodies,)
    reads = ("poses", "lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
             "placement_heading", "fade_placement_xy", "fade_placement_heading", "posture")
    writes = ("lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
              "fade_placement_xy", "poses", "locked", "scaled")

    def run(self, dt: float) -> None:
        st = self.sim.store
        reuse = st.scaled if fits(st.scaled, st.n) else None
        st.scaled = decode_legs(st.poses, st.lengths, reuse)
