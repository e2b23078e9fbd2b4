"""MorphologyAdapt: the normalized poses on each character's own body (paper §6, eq. 2).

Rows: characters with a Morphology. A body replaced while playing (``Simulation.set_body``)
is taken in on the next tick, before the decode (:func:`ecs_anim.body_change.adopt_bodies`), or
blended into over ``blend_s`` tick by tick (:func:`ecs_anim.body_change.blend_bodies`).

Reads: store.poses, store.lengths; on a body change the Morphology (and BodyBlend) components, segment_mass_kg,
segment_com_fraction, placement_*, fade_placement_*, posture (whether the character has played).
Writes: on a body change lengths, segment_mass_kg, segment_com_fraction, placement_xy,
fade_placement_xy (it stays where it stands), the root of poses, locked (its feet re-plant; or,
while blending, footprint: a planted foot's height follows the ankle height);
store.scaled (joint positions and part frames on each body, before ground adaptation), in place
when the store's arrays still fit (compiled :func:`ecs_anim.kernels.decode.decode`).
"""

from __future__ import annotations

from ecs_anim.body_change import adopt_bodies, blend_bodies
from ecs_anim.components import Morphology
from ecs_anim.kernels.decode import decode, fits
from ecs_anim.system_base import System


class MorphologyAdapt(System):
    query = (Morphology,)
    on_structure_change = (adopt_bodies,)
    reads = ("poses", "lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
             "placement_heading", "fade_placement_xy", "fade_placement_heading", "posture")
    writes = ("lengths", "segment_mass_kg", "segment_com_fraction", "placement_xy",
              "fade_placement_xy", "poses", "locked", "footprint", "scaled")

    def run(self, dt: float) -> None:
        st = self.sim.store
        blend_bodies(self.sim)
        reuse = st.scaled if fits(st.scaled, st.n) else None
        st.scaled = decode(st.poses, st.lengths, reuse)
